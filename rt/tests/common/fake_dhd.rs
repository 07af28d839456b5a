//! The fake DHD SDK (`fixtures/fake_dhd.c`) compiled with `cc` into a directory of its own, with
//! its control entry points, for the tests that load it (`#[path]`-included).
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command as Proc;

use coop_model::body::Vec3;
use coop_rt::device::dhd::DhdConfig;

pub const SOURCE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/fake_dhd.c");

/// A compiled fake in a directory of its own (removed on drop), with its control entry points.
pub struct Fake {
    dir: PathBuf,
    pub lib: PathBuf,
    handle: libloading::Library,
}

type Set = unsafe extern "C" fn(*const std::ffi::c_char, f64);
type Get = unsafe extern "C" fn(*const std::ffi::c_char) -> f64;

impl Fake {
    pub fn build(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("coop-fake-dhd-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let lib = dir.join("libdhd.so");
        let out = Proc::new("cc")
            .args(["-shared", "-fPIC", "-O1", "-o"])
            .arg(&lib)
            .arg(SOURCE)
            .output()
            .expect("cc runs (a C compiler is needed to build the fake DHD library)");
        assert!(
            out.status.success(),
            "cc failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        // SAFETY: our own fixture, whose only initialisers are static variable values.
        let handle = unsafe { libloading::Library::new(&lib) }.expect("loads");
        Self { dir, lib, handle }
    }

    pub fn set(&self, key: &str, v: f64) {
        let k = std::ffi::CString::new(key).expect("key");
        // SAFETY: fake_dhd_set(const char*, double) as the fixture declares it; k outlives the call.
        unsafe {
            let f: libloading::Symbol<Set> = self.handle.get(b"fake_dhd_set\0").expect("symbol");
            f(k.as_ptr(), v);
        }
    }

    pub fn get(&self, key: &str) -> f64 {
        let k = std::ffi::CString::new(key).expect("key");
        // SAFETY: fake_dhd_get(const char*) -> double as the fixture declares it.
        unsafe {
            let f: libloading::Symbol<Get> = self.handle.get(b"fake_dhd_get\0").expect("symbol");
            f(k.as_ptr())
        }
    }

    pub fn force(&self) -> Vec3 {
        Vec3::new(self.get("fx"), self.get("fy"), self.get("fz"))
    }

    pub fn config(&self) -> DhdConfig {
        DhdConfig {
            library: Some(self.lib.clone()),
            ..DhdConfig::default()
        }
    }
}

impl Drop for Fake {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
