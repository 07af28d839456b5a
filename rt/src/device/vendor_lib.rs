//! Finding and loading a vendor's shared library at run time (the DHD SDK, OpenHaptics' HD
//! library): the file a station's config names, or the vendor's own names on the dynamic loader's
//! path and then in the directories its installers use.
#![allow(unsafe_code)]

use std::path::{Path, PathBuf};

/// A library that did not load: the file (or the first name searched) and why.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Missing {
    /// The file, or the first of the names searched.
    pub(crate) file: String,
    /// The loader's words, or the list of what was searched.
    pub(crate) reason: String,
}

fn load_one(file: &Path) -> Result<libloading::Library, libloading::Error> {
    // Loading runs the library's initialisers. We load only the file the station's config names
    // (or the vendor's own names on the loader's path): the vendor's SDK, whose initialisers set
    // up its own state.
    // SAFETY: the trust any program linking the vendor's SDK gives it (above).
    unsafe { libloading::Library::new(file) }
}

/// Loads `configured`, or else the first of `names` that loads from the loader's path, then from
/// each of `dirs`; with the file it came from.
pub(crate) fn load(
    configured: Option<&Path>,
    names: &[&str],
    dirs: &[&str],
) -> Result<(libloading::Library, String), Missing> {
    if let Some(p) = configured {
        return load_one(p)
            .map(|l| (l, p.display().to_string()))
            .map_err(|e| Missing {
                file: p.display().to_string(),
                reason: e.to_string(),
            });
    }
    let candidates = names.iter().map(PathBuf::from).chain(
        dirs.iter()
            .flat_map(|d| names.iter().map(move |n| Path::new(d).join(n))),
    );
    let mut tried = Vec::new();
    for c in candidates {
        match load_one(&c) {
            Ok(l) => return Ok((l, c.display().to_string())),
            Err(_) => tried.push(c.display().to_string()),
        }
    }
    Err(Missing {
        file: names.first().copied().unwrap_or_default().to_owned(),
        reason: format!("searched {}", tried.join(", ")),
    })
}
