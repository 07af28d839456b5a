//! The fake DHD SDK (`fixtures/fake_dhd.c`) compiled with `cc` into a directory of its own, with
//! its control entry points, for the tests that load it, and the record of calls it keeps when a
//! process it runs in is given `COOP_FAKE_DHD_LOG` (`#[path]`-included, by coop-rt's tests and by
//! the station tests in tools).
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command as Proc;

use coop_model::body::Vec3;
use coop_rt::device::dhd::DhdConfig;

// `rt/../rt`, so the path holds from any crate beside rt that includes this file.
pub const SOURCE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../rt/tests/fixtures/fake_dhd.c"
);

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

/// One DHD call in the fake's record (`COOP_FAKE_DHD_LOG`): `dhdSetForce 0.5 0 0 0 -> 0` is
/// `{ name: "dhdSetForce", args: [0.5, 0.0, 0.0, 0.0], result: 0 }` (the device ID is the last
/// argument).
#[derive(Debug, Clone, PartialEq)]
pub struct Call {
    pub name: String,
    pub args: Vec<f64>,
    pub result: i64,
}

impl Call {
    /// A `dhdSetForce` that commanded a nonzero force.
    pub fn is_nonzero_force(&self) -> bool {
        self.name == "dhdSetForce" && self.args[..3].iter().any(|&c| c != 0.0)
    }

    /// The force a `dhdSetForce` commanded, N.
    pub fn force(&self) -> Vec3 {
        assert_eq!(self.name, "dhdSetForce", "{self:?}");
        Vec3::new(self.args[0], self.args[1], self.args[2])
    }
}

/// The calls recorded in `log`, in order (none when the file does not exist yet; a line still being
/// written, without its newline, is left for the next read).
///
/// # Panics
/// On a line that is not `name args... -> result` (the fake writes each line with one `write`, so
/// even a killed process leaves whole lines).
pub fn record(log: &std::path::Path) -> Vec<Call> {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    text.split_inclusive('\n')
        .filter_map(|l| l.strip_suffix('\n'))
        .map(|l| {
            let (call, result) = l.split_once(" -> ").unwrap_or_else(|| panic!("line {l:?}"));
            let mut words = call.split(' ');
            let name = words.next().unwrap_or_default().to_owned();
            let args = words
                .map(|w| {
                    w.parse()
                        .unwrap_or_else(|_| panic!("argument {w:?} in {l:?}"))
                })
                .collect();
            Call {
                name,
                args,
                result: result.parse().unwrap_or_else(|_| panic!("result in {l:?}")),
            }
        })
        .collect()
}
