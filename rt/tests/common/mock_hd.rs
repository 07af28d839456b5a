//! The mock OpenHaptics HD library (`rt/mock-hd`, a workspace crate) compiled with `rustc` into a
//! `libHD.so` once per test process, with its control entry points, for the tests that load it
//! (`#[path]`-included, by coop-rt's tests and by the station tests in tools). The HD API is one
//! device per process and the library stays loaded for the process's life, as the backend keeps
//! it: tests that use it take [`Mock::lock`] and start from [`Mock::reset`].
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command as Proc;
use std::sync::{Mutex, MutexGuard, OnceLock};

use coop_rt::device::openhaptics::OpenHapticsConfig;

// `rt/../rt`, so the path holds from any crate beside rt that includes this file.
pub const SOURCE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../rt/mock-hd/src/lib.rs");

/// The compiled mock and its control entry points.
pub struct Mock {
    pub lib: PathBuf,
    handle: libloading::Library,
}

type Set = unsafe extern "C" fn(*const std::ffi::c_char, f64);
type Get = unsafe extern "C" fn(*const std::ffi::c_char) -> f64;
type Reset = unsafe extern "C" fn();

static MOCK: OnceLock<Mock> = OnceLock::new();
static IN_USE: Mutex<()> = Mutex::new(());

/// Compiles the mock into `dir/libHD.so` for another process to load (a station's servo, steered
/// by `COOP_MOCK_HD` and recording into `COOP_MOCK_HD_RECORD`), and returns its path.
pub fn build_file(dir: &std::path::Path) -> PathBuf {
    let lib = dir.join("libHD.so");
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let out = Proc::new(rustc)
        .args(["--edition", "2021", "--crate-type", "cdylib", "-O", "-o"])
        .arg(&lib)
        .arg(SOURCE)
        .output()
        .expect("rustc runs (it builds the mock HD library)");
    assert!(
        out.status.success(),
        "rustc failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    lib
}

impl Mock {
    /// The mock, built on first use (into cargo's scratch directory for tests, under target/).
    pub fn get_or_build() -> &'static Mock {
        MOCK.get_or_init(|| {
            let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
                .join(format!("coop-mock-hd-{}", std::process::id()));
            std::fs::create_dir_all(&dir).expect("scratch dir");
            let lib = build_file(&dir);
            // SAFETY: our own mock, whose initialisers only set static values.
            let handle = unsafe { libloading::Library::new(&lib) }.expect("loads");
            // Loaded now (and by the backend at this same path): the file is not needed again.
            let _ = std::fs::remove_dir_all(&dir);
            Mock { lib, handle }
        })
    }

    /// The mock for this test alone, reset to its defaults.
    pub fn lock() -> (&'static Mock, MutexGuard<'static, ()>) {
        let guard = IN_USE
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let m = Self::get_or_build();
        m.reset();
        (m, guard)
    }

    pub fn set(&self, key: &str, v: f64) {
        let k = std::ffi::CString::new(key).expect("key");
        // SAFETY: mock_hd_set(const char*, double) as the mock declares it; k outlives the call.
        unsafe {
            let f: libloading::Symbol<Set> = self.handle.get(b"mock_hd_set\0").expect("symbol");
            f(k.as_ptr(), v);
        }
    }

    pub fn get(&self, key: &str) -> f64 {
        let k = std::ffi::CString::new(key).expect("key");
        // SAFETY: mock_hd_get(const char*) -> double as the mock declares it.
        unsafe {
            let f: libloading::Symbol<Get> = self.handle.get(b"mock_hd_get\0").expect("symbol");
            f(k.as_ptr())
        }
    }

    pub fn reset(&self) {
        // SAFETY: mock_hd_reset() takes nothing.
        unsafe {
            let f: libloading::Symbol<Reset> = self.handle.get(b"mock_hd_reset\0").expect("symbol");
            f();
        }
    }

    /// The force the mock displayed at its last frame, N.
    pub fn force(&self) -> [f64; 3] {
        [self.get("fx"), self.get("fy"), self.get("fz")]
    }

    pub fn config(&self) -> OpenHapticsConfig {
        OpenHapticsConfig {
            library: Some(self.lib.clone()),
            ..OpenHapticsConfig::default()
        }
    }
}
