//! Force Dimension devices (delta, omega, sigma, lambda) and the Novint Falcon through Force
//! Dimension's DHD SDK, loaded at run time with `libloading`: the project builds and runs without
//! the SDK, and only a station configured with `device = "dhd"` looks for `libdhd.so`.
//!
//! The DHD C API calls used (dhdc.h; each takes the device `char ID` last, -1 meaning the default
//! device): `dhdGetDeviceCount`, `dhdOpenID`, `dhdGetSystemType`, `dhdGetSystemName`,
//! `dhdGetSerialNumber`, `dhdSetWatchdog` (units of 125 µs: the firmware drops forces if no command
//! arrives in time), `dhdEnableForce`, `dhdGetPosition`, `dhdGetLinearVelocity`,
//! `dhdGetButtonMask`, `dhdSetForce`, `dhdErrorGetLast`, `dhdErrorGetLastStr`, `dhdClose`.
//!
//! We own this device's loop: `sample` and `command` call the SDK in the servo tick, as CHAI3D's
//! haptic thread does. Those calls do the SDK's USB I/O (the one exception to "no system calls" on
//! the servo path, and the reason the vendor's watchdog is set); they allocate nothing on our side.
//! A failed call is reported as [`DeviceFault::CallFailed`] with the SDK's error number, and the
//! backend releases the force at once (the safety layer releases too).
//!
//! `unsafe` is confined to this file's `ffi` section: calling into a C library loaded at run time
//! cannot be checked by the compiler, so each call states why it is sound.
#![allow(unsafe_code)]

use std::ffi::{c_char, c_int, c_uchar, c_uint, c_ushort, CStr};
use std::path::{Path, PathBuf};

use coop_model::body::Vec3;

use crate::device::{
    CartesianDevice, Command, ConfigError, DeviceFault, DeviceInfo, ProbeReport, Sample,
};

/// Library names tried, in order, when `library` is not set (the dynamic loader's search path:
/// `LD_LIBRARY_PATH`, `/etc/ld.so.cache`, then these directories).
pub const DEFAULT_LIBRARIES: &[&str] = &["libdhd.so", "libdhd.so.3"];
/// Directories tried after the loader's own search, where the SDK's installer puts the library.
pub const DEFAULT_DIRS: &[&str] = &["/usr/local/lib", "/opt/forcedimension/lib", "/usr/lib"];

/// The station config's `[device.dhd]` table.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct DhdConfig {
    /// The SDK's `libdhd.so`; none: search [`DEFAULT_LIBRARIES`] on the loader's path, then
    /// [`DEFAULT_DIRS`].
    pub library: Option<PathBuf>,
    /// Which device, in the SDK's enumeration order (`dhdOpenID`): 0 is the first.
    pub device_index: u8,
    /// The firmware watchdog: no force command within this, and the device drops its forces.
    /// 0 disables it; else 0.125..=31.875 ms (the SDK counts 125 µs units in one byte).
    pub watchdog_ms: f64,
}

impl Default for DhdConfig {
    fn default() -> Self {
        Self {
            library: None,
            device_index: 0,
            watchdog_ms: 4.0,
        }
    }
}

/// `dhdSetWatchdog`'s unit.
const WATCHDOG_UNIT_MS: f64 = 0.125;
/// `DHD_MAX_DEVICE` in current SDKs.
const MAX_DEVICES: u8 = 16;

impl DhdConfig {
    /// Checks every field.
    ///
    /// # Errors
    /// The first field that breaks its rule, with its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if let Some(p) = &self.library {
            if p.as_os_str().is_empty() {
                return Err(ConfigError {
                    field: "library".into(),
                    value: "\"\"".into(),
                    rule: "must be the path of libdhd.so (or left out to search for it)".into(),
                });
            }
        }
        if self.device_index >= MAX_DEVICES {
            return Err(ConfigError {
                field: "device_index".into(),
                value: self.device_index.to_string(),
                rule: format!(
                    "must be in 0..{MAX_DEVICES} (the SDK opens at most {MAX_DEVICES} devices)"
                ),
            });
        }
        let w = self.watchdog_ms;
        if !(w == 0.0 || (WATCHDOG_UNIT_MS..=255.0 * WATCHDOG_UNIT_MS).contains(&w)) {
            return Err(ConfigError {
                field: "watchdog_ms".into(),
                value: w.to_string(),
                rule: "must be 0 (off) or in 0.125..=31.875 ms (dhdSetWatchdog's 125 µs units)"
                    .into(),
            });
        }
        Ok(())
    }

    fn watchdog_units(&self) -> c_uchar {
        // In 0..=255 after validate.
        (self.watchdog_ms / WATCHDOG_UNIT_MS)
            .round()
            .clamp(0.0, 255.0) as c_uchar
    }
}

/// Why [`DhdDevice::open`] (or a probe) failed. Nothing was left open.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DhdError {
    /// The config breaks a rule.
    #[error("device.dhd.{0}")]
    Config(ConfigError),
    /// No library at the configured path, or none found by the default search.
    #[error("Force Dimension DHD library {file} not found or not loadable ({reason}); set device.dhd.library to the SDK's libdhd.so")]
    LibraryMissing {
        /// The file (or the names searched).
        file: String,
        /// The loader's words.
        reason: String,
    },
    /// The library lacks an entry point we call (not the DHD SDK, or too old).
    #[error("{file} (device.dhd.library) has no {symbol}: not a DHD SDK library, or too old")]
    MissingSymbol {
        /// The library.
        file: String,
        /// The entry point.
        symbol: &'static str,
    },
    /// Fewer devices than `device_index` + 1.
    #[error("device.dhd.device_index = {index}: the DHD SDK ({file}) finds {count} device(s)")]
    NoDevice {
        /// What the config asked for.
        index: u8,
        /// What `dhdGetDeviceCount` says.
        count: i32,
        /// The library.
        file: String,
    },
    /// An SDK call failed while opening or setting up.
    #[error("{call} failed (error {code}: {reason})")]
    CallFailed {
        /// The entry point.
        call: &'static str,
        /// `dhdErrorGetLast()`.
        code: i32,
        /// `dhdErrorGetLastStr()`.
        reason: String,
    },
}

mod ffi {
    //! The loaded library and its entry points, as raw function pointers copied out of it.

    use super::*;

    pub(super) type GetDeviceCount = unsafe extern "C" fn() -> c_int;
    pub(super) type OpenId = unsafe extern "C" fn(c_char) -> c_int;
    pub(super) type ById = unsafe extern "C" fn(c_char) -> c_int;
    pub(super) type GetName = unsafe extern "C" fn(c_char) -> *const c_char;
    pub(super) type GetSerial = unsafe extern "C" fn(*mut c_ushort, c_char) -> c_int;
    pub(super) type SetByte = unsafe extern "C" fn(c_uchar, c_char) -> c_int;
    pub(super) type GetVec = unsafe extern "C" fn(*mut f64, *mut f64, *mut f64, c_char) -> c_int;
    pub(super) type SetVec = unsafe extern "C" fn(f64, f64, f64, c_char) -> c_int;
    pub(super) type GetMask = unsafe extern "C" fn(c_char) -> c_uint;
    pub(super) type ErrorLast = unsafe extern "C" fn() -> c_int;
    pub(super) type ErrorLastStr = unsafe extern "C" fn() -> *const c_char;

    /// The DHD entry points we use. The function pointers stay valid while `_lib` is loaded, and it
    /// lives as long as they do (same struct, never moved out).
    #[derive(Debug)]
    pub(super) struct Api {
        pub(super) file: String,
        pub(super) get_device_count: GetDeviceCount,
        pub(super) open_id: OpenId,
        pub(super) close: ById,
        pub(super) get_system_type: ById,
        pub(super) get_system_name: GetName,
        pub(super) get_serial_number: GetSerial,
        pub(super) set_watchdog: SetByte,
        pub(super) enable_force: SetByte,
        pub(super) get_position: GetVec,
        pub(super) get_linear_velocity: GetVec,
        pub(super) get_button_mask: GetMask,
        pub(super) set_force: SetVec,
        pub(super) error_get_last: ErrorLast,
        pub(super) error_get_last_str: ErrorLastStr,
        _lib: libloading::Library,
    }

    impl Api {
        /// Loads the library at `configured`, or searches the default names and directories.
        pub(super) fn load(configured: Option<&Path>) -> Result<Self, DhdError> {
            let (lib, file) =
                crate::device::vendor_lib::load(configured, DEFAULT_LIBRARIES, DEFAULT_DIRS)
                    .map_err(|m| DhdError::LibraryMissing {
                        file: m.file,
                        reason: m.reason,
                    })?;
            macro_rules! sym {
                ($name:literal) => {{
                    // The symbol's type is the DHD SDK's declaration of that function in dhdc.h
                    // (argument and return types as C declares them); the pointer is copied out
                    // and used only while `_lib` keeps the library loaded.
                    // SAFETY: the type matches the C declaration and the library outlives it (above).
                    let s = unsafe { lib.get(concat!($name, "\0").as_bytes()) };
                    *s.map_err(|_| DhdError::MissingSymbol {
                        file: file.clone(),
                        symbol: $name,
                    })?
                }};
            }
            Ok(Self {
                get_device_count: sym!("dhdGetDeviceCount"),
                open_id: sym!("dhdOpenID"),
                close: sym!("dhdClose"),
                get_system_type: sym!("dhdGetSystemType"),
                get_system_name: sym!("dhdGetSystemName"),
                get_serial_number: sym!("dhdGetSerialNumber"),
                set_watchdog: sym!("dhdSetWatchdog"),
                enable_force: sym!("dhdEnableForce"),
                get_position: sym!("dhdGetPosition"),
                get_linear_velocity: sym!("dhdGetLinearVelocity"),
                get_button_mask: sym!("dhdGetButtonMask"),
                set_force: sym!("dhdSetForce"),
                error_get_last: sym!("dhdErrorGetLast"),
                error_get_last_str: sym!("dhdErrorGetLastStr"),
                file: file.clone(),
                _lib: lib,
            })
        }

        pub(super) fn device_count(&self) -> c_int {
            // SAFETY: dhdGetDeviceCount takes nothing and returns an int; the library is loaded.
            unsafe { (self.get_device_count)() }
        }

        pub(super) fn open(&self, index: u8) -> c_int {
            // SAFETY: dhdOpenID(char) with an index below DHD_MAX_DEVICE.
            unsafe { (self.open_id)(index as c_char) }
        }

        pub(super) fn close(&self, id: c_char) -> c_int {
            // SAFETY: dhdClose(char) on an id dhdOpenID returned.
            unsafe { (self.close)(id) }
        }

        pub(super) fn system_type(&self, id: c_char) -> c_int {
            // SAFETY: dhdGetSystemType(char) on an open id.
            unsafe { (self.get_system_type)(id) }
        }

        pub(super) fn system_name(&self, id: c_char) -> Option<String> {
            // SAFETY: dhdGetSystemName(char) returns NULL or a NUL-terminated string the SDK owns
            // (static); we copy it before the next call.
            let p = unsafe { (self.get_system_name)(id) };
            if p.is_null() {
                return None;
            }
            // SAFETY: non-null, NUL-terminated, valid until the next SDK call (see above).
            Some(unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned())
        }

        pub(super) fn serial(&self, id: c_char) -> Option<u16> {
            let mut sn: c_ushort = 0;
            // SAFETY: dhdGetSerialNumber(ushort*, char) writes one ushort through a valid pointer.
            let r = unsafe { (self.get_serial_number)(&mut sn, id) };
            (r >= 0).then_some(sn)
        }

        pub(super) fn set_watchdog(&self, units: c_uchar, id: c_char) -> c_int {
            // SAFETY: dhdSetWatchdog(uchar, char) on an open id.
            unsafe { (self.set_watchdog)(units, id) }
        }

        pub(super) fn enable_force(&self, on: bool, id: c_char) -> c_int {
            // SAFETY: dhdEnableForce(uchar DHD_ON/DHD_OFF, char) on an open id.
            unsafe { (self.enable_force)(c_uchar::from(on), id) }
        }

        pub(super) fn position(&self, id: c_char) -> (c_int, Vec3) {
            let (mut x, mut y, mut z) = (0.0, 0.0, 0.0);
            // SAFETY: dhdGetPosition(double*, double*, double*, char) writes three doubles through
            // valid, distinct pointers to locals.
            let r = unsafe { (self.get_position)(&mut x, &mut y, &mut z, id) };
            (r, Vec3::new(x, y, z))
        }

        pub(super) fn velocity(&self, id: c_char) -> (c_int, Vec3) {
            let (mut x, mut y, mut z) = (0.0, 0.0, 0.0);
            // SAFETY: dhdGetLinearVelocity has dhdGetPosition's signature; same pointers.
            let r = unsafe { (self.get_linear_velocity)(&mut x, &mut y, &mut z, id) };
            (r, Vec3::new(x, y, z))
        }

        pub(super) fn buttons(&self, id: c_char) -> u32 {
            // SAFETY: dhdGetButtonMask(char) returns an unsigned int.
            unsafe { (self.get_button_mask)(id) }
        }

        pub(super) fn set_force(&self, f: Vec3, id: c_char) -> c_int {
            // SAFETY: dhdSetForce(double, double, double, char) on an open id.
            unsafe { (self.set_force)(f.x, f.y, f.z, id) }
        }

        pub(super) fn last_error(&self) -> c_int {
            // SAFETY: dhdErrorGetLast() reads the calling thread's last error.
            unsafe { (self.error_get_last)() }
        }

        pub(super) fn last_error_str(&self) -> String {
            // SAFETY: dhdErrorGetLastStr() returns NULL or a static NUL-terminated string.
            let p = unsafe { (self.error_get_last_str)() };
            if p.is_null() {
                return String::from("no description");
            }
            // SAFETY: non-null and NUL-terminated (see above).
            unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
        }
    }
}

use ffi::Api;

/// What we know of a system type (CHAI3D's `cDeltaDevice` specifications). Unknown types get the
/// smallest device's figures: the safety layer clamps to these, so erring small is erring safe.
fn specs(system_type: c_int) -> (&'static str, u8, f64, f64, f64, f64, f64) {
    // (model, dof, max force N, stiffness N/m, damping N·s/m, workspace radius m, native rate Hz)
    match system_type {
        31 => ("delta.3", 3, 20.0, 5000.0, 40.0, 0.15, 4000.0),
        61 | 62 => ("delta.6", 6, 20.0, 4000.0, 40.0, 0.15, 4000.0),
        32 | 33 => ("omega.3", 3, 12.0, 5000.0, 40.0, 0.075, 4000.0),
        34 | 36 => ("omega.6", 3, 12.0, 4000.0, 40.0, 0.075, 4000.0),
        35 | 37 => ("omega.7", 3, 12.0, 4000.0, 40.0, 0.075, 4000.0),
        60 => ("Novint Falcon", 3, 8.0, 3000.0, 20.0, 0.04, 1000.0),
        _ => ("unknown DHD device", 3, 8.0, 3000.0, 20.0, 0.04, 1000.0),
    }
}

fn describe(api: &Api, id: c_char) -> DeviceInfo {
    let ty = api.system_type(id);
    let (model, dof, force, k, b, r, hz) = specs(ty);
    DeviceInfo {
        backend: "dhd",
        model: api.system_name(id).map_or_else(
            || model.to_owned(),
            |n| {
                if n == model {
                    n
                } else {
                    format!("{n} ({model})")
                }
            },
        ),
        serial: api.serial(id).map(|s| s.to_string()),
        dof,
        max_force_n: force,
        max_stiffness_n_per_m: k,
        max_damping_n_s_per_m: b,
        workspace_radius_m: r,
        native_rate_hz: hz,
        senses_force: false,
    }
}

/// A DHD device we own the loop of.
#[derive(Debug)]
pub struct DhdDevice {
    api: Api,
    id: c_char,
    info: DeviceInfo,
    open: bool,
}

impl DhdDevice {
    /// Loads the SDK, opens device `config.device_index`, sets the firmware watchdog, commands zero
    /// force and enables force output.
    ///
    /// # Errors
    /// A bad config, no library, a library without the DHD entry points, no such device, or a
    /// setup call failing (the device is closed again).
    pub fn open(config: &DhdConfig) -> Result<Self, DhdError> {
        config.validate().map_err(DhdError::Config)?;
        let api = Api::load(config.library.as_deref())?;
        let count = api.device_count();
        if count <= c_int::from(config.device_index) {
            return Err(DhdError::NoDevice {
                index: config.device_index,
                count: count.max(0),
                file: api.file.clone(),
            });
        }
        let id = api.open(config.device_index);
        if id < 0 {
            return Err(DhdError::CallFailed {
                call: "dhdOpenID",
                code: api.last_error(),
                reason: api.last_error_str(),
            });
        }
        let id = id as c_char;
        let info = describe(&api, id);
        let fail = |api: &Api, call: &'static str| {
            let e = DhdError::CallFailed {
                call,
                code: api.last_error(),
                reason: api.last_error_str(),
            };
            api.close(id);
            e
        };
        if api.set_force(Vec3::zeros(), id) < 0 {
            return Err(fail(&api, "dhdSetForce"));
        }
        if api.set_watchdog(config.watchdog_units(), id) < 0 {
            return Err(fail(&api, "dhdSetWatchdog"));
        }
        if api.enable_force(true, id) < 0 {
            return Err(fail(&api, "dhdEnableForce"));
        }
        Ok(Self {
            api,
            id,
            info,
            open: true,
        })
    }

    /// The library it was loaded from.
    pub fn library(&self) -> &str {
        &self.api.file
    }

    fn failed(&self, call: &'static str) -> DeviceFault {
        let code = self.api.last_error();
        // Release at once, best effort: the link may be gone, and then the watchdog releases.
        self.api.set_force(Vec3::zeros(), self.id);
        DeviceFault::CallFailed { call, code }
    }
}

impl CartesianDevice for DhdDevice {
    fn info(&self) -> &DeviceInfo {
        &self.info
    }

    fn sample(&mut self, now_ns: u64) -> Result<Sample, DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging; the SDK's own USB I/O only.
        if !self.open {
            return Err(DeviceFault::Disconnected);
        }
        let (r, position_m) = self.api.position(self.id);
        if r < 0 {
            return Err(self.failed("dhdGetPosition"));
        }
        let (r, velocity_m_s) = self.api.velocity(self.id);
        if r < 0 {
            return Err(self.failed("dhdGetLinearVelocity"));
        }
        if !position_m.iter().all(|c| c.is_finite() && c.abs() < 10.0) {
            self.api.set_force(Vec3::zeros(), self.id);
            return Err(DeviceFault::BadValue { what: "position" });
        }
        if !velocity_m_s.iter().all(|c| c.is_finite()) {
            self.api.set_force(Vec3::zeros(), self.id);
            return Err(DeviceFault::BadValue { what: "velocity" });
        }
        Ok(Sample {
            t_ns: now_ns,
            position_m,
            velocity_m_s,
            orientation: None,
            buttons: self.api.buttons(self.id),
            force_sensed_n: None,
        })
    }

    fn command(&mut self, _now_ns: u64, cmd: Command) -> Result<(), DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging; the SDK's own USB I/O only.
        if !self.open {
            return Err(DeviceFault::Disconnected);
        }
        let f = match cmd {
            Command::Force(f) if f.iter().all(|c| c.is_finite()) => f,
            Command::Force(_) => {
                self.api.set_force(Vec3::zeros(), self.id);
                return Err(DeviceFault::BadValue {
                    what: "force command",
                });
            }
            Command::Release => Vec3::zeros(),
        };
        // >= 0 is success (DHD_MOTOR_SATURATED = 2 included: the SDK clipped it).
        if self.api.set_force(f, self.id) < 0 {
            return Err(self.failed("dhdSetForce"));
        }
        Ok(())
    }

    fn close(&mut self) {
        if !self.open {
            return;
        }
        self.open = false;
        self.api.set_force(Vec3::zeros(), self.id);
        self.api.enable_force(false, self.id);
        self.api.close(self.id);
    }
}

// No bridge: the servo calls the SDK itself.
impl crate::device::VendorDevice for DhdDevice {}

impl Drop for DhdDevice {
    fn drop(&mut self) {
        self.close();
    }
}

/// What `station devices` says of the DHD backend: whether the library loads, and each device it
/// finds (opened, described and closed again; no force is enabled).
pub fn probe(config: &DhdConfig) -> ProbeReport {
    let mut report = ProbeReport {
        backend: "dhd",
        built_in: true,
        status: String::new(),
        devices: Vec::new(),
    };
    if let Err(e) = config.validate() {
        report.status = format!("device.dhd.{e}");
        return report;
    }
    let api = match Api::load(config.library.as_deref()) {
        Ok(a) => a,
        Err(e) => {
            report.status = e.to_string();
            return report;
        }
    };
    let count = api.device_count().max(0);
    for i in 0..count.min(c_int::from(MAX_DEVICES)) {
        let id = api.open(i as u8);
        if id >= 0 {
            report.devices.push(describe(&api, id as c_char));
            api.close(id as c_char);
        }
    }
    report.status = format!("DHD SDK loaded from {}: {count} device(s)", api.file);
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_config_is_valid_and_each_rule_names_its_field() {
        assert_eq!(DhdConfig::default().validate(), Ok(()));
        let bad = [
            (
                DhdConfig {
                    library: Some(PathBuf::new()),
                    ..Default::default()
                },
                "library",
            ),
            (
                DhdConfig {
                    device_index: 16,
                    ..Default::default()
                },
                "device_index",
            ),
            (
                DhdConfig {
                    watchdog_ms: 0.1,
                    ..Default::default()
                },
                "watchdog_ms",
            ),
            (
                DhdConfig {
                    watchdog_ms: 40.0,
                    ..Default::default()
                },
                "watchdog_ms",
            ),
            (
                DhdConfig {
                    watchdog_ms: f64::NAN,
                    ..Default::default()
                },
                "watchdog_ms",
            ),
        ];
        for (c, field) in bad {
            assert_eq!(c.validate().expect_err(field).field, field);
        }
        assert_eq!(
            DhdConfig {
                watchdog_ms: 31.875,
                ..Default::default()
            }
            .watchdog_units(),
            255
        );
        assert_eq!(DhdConfig::default().watchdog_units(), 32);
    }

    #[test]
    fn a_missing_library_is_one_error_naming_the_file_and_the_field() {
        let c = DhdConfig {
            library: Some(PathBuf::from("/nonexistent/coop/libdhd.so")),
            ..Default::default()
        };
        let e = DhdDevice::open(&c).expect_err("no such file");
        let msg = e.to_string();
        assert!(matches!(e, DhdError::LibraryMissing { .. }), "{msg}");
        assert!(msg.contains("/nonexistent/coop/libdhd.so"), "{msg}");
        assert!(msg.contains("device.dhd.library"), "{msg}");
        let p = probe(&c);
        assert!(
            p.built_in && p.devices.is_empty() && p.status.contains("not found"),
            "{}",
            p.status
        );
    }
}
