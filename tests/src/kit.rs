//! Where a test finds the repository's files and keeps its own: the repository root, the shipped
//! scenarios, and temporary directories unique to one test.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

use coop_model::scenario::Scenario;
use coop_rt::sync::{AtomicU64, Ordering};

/// The repository's root (the workspace folder), whichever crate's test asks.
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The path of the shipped scenario `scenarios/<file>`.
pub fn scenario_path(file: &str) -> PathBuf {
    repo().join("scenarios").join(file)
}

/// The shipped scenario `scenarios/<file>`, loaded and validated as `sim` loads it.
///
/// # Panics
/// If it cannot be read or is refused (the error is shown).
pub fn load_scenario(file: &str) -> Scenario {
    coop_actors::scenario_file::load(&scenario_path(file))
        .unwrap_or_else(|e| panic!("scenarios/{file}: {e:#}"))
}

/// A directory for one test's files under the system's temporary directory, named
/// `coop-<tag>-<pid>-<n>` so tests running in parallel (in one process or several) never share
/// one. Removed when dropped, unless the test is failing: then it is kept, and its path printed,
/// so what the programs under test wrote can be read.
///
/// Declare it before the child processes that write into it, so they are reaped before it goes.
#[derive(Debug)]
pub struct TempDir(PathBuf);

impl TempDir {
    /// A new, empty directory.
    ///
    /// # Panics
    /// If it cannot be made.
    pub fn new(tag: &str) -> Self {
        let d = Self::unmade(tag);
        std::fs::create_dir_all(&d.0).unwrap_or_else(|e| panic!("temp dir {}: {e}", d.0.display()));
        d
    }

    /// A fresh path that does not exist yet, for a test that checks what a program makes there
    /// (or that it makes nothing); removed on drop as [`TempDir::new`]'s.
    pub fn unmade(tag: &str) -> Self {
        static N: AtomicU64 = AtomicU64::new(0);
        let d = std::env::temp_dir().join(format!(
            "coop-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        // An earlier process with this pid may have left one behind.
        let _ = std::fs::remove_dir_all(&d);
        Self(d)
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<OsStr> for TempDir {
    fn as_ref(&self) -> &OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("kept for a look: {}", self.0.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}
