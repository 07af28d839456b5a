//! 3D Systems' Touch, Touch X and Phantom devices through OpenHaptics' HD API, loaded at run time
//! with `libloading`: the project builds and runs without the SDK, and only a station configured
//! with `device = "openhaptics"` looks for `libHD.so`.
//!
//! The HD API owns the servo thread: its scheduler calls the application back once per servo tick
//! (1 kHz by default), and the device's state may be read and its force set only inside such a
//! callback, between `hdBeginFrame` and `hdEndFrame`. So this backend runs with `loop = "vendor"`:
//! [`HdScheduler::run_hd`] schedules one callback that opens a frame, runs the station's whole servo
//! step in it (the same step, rings, safety contract and stop ladder as our own loop), and closes
//! the frame. [`OpenHapticsDevice`]'s `sample` and `command` are the HD calls made inside it.
//!
//! HD calls used (hd.h, hdScheduler.h): `hdInitDevice`, `hdDisableDevice`, `hdMakeCurrentDevice`,
//! `hdGetError`, `hdGetErrorString`, `hdEnable`, `hdDisable`, `hdGetDoublev`, `hdGetIntegerv`,
//! `hdGetString`, `hdSetDoublev`, `hdBeginFrame`, `hdEndFrame`, `hdCheckCalibration`,
//! `hdUpdateCalibration`, `hdScheduleAsynchronous`, `hdUnschedule`, `hdStartScheduler`,
//! `hdStopScheduler`, `hdSetSchedulerRate`. Units at the edge: the HD API's millimetres (and
//! N/mm, N·s/mm) are converted to metres here; forces are newtons on both sides.
//!
//! Every HD error (`hdGetError`) is a [`DeviceFault::CallFailed`] that releases the force; a
//! calibration the device loses mid-run releases it until the device is calibrated again; a
//! scheduler that stops calling back is caught by the thread that started it, which turns the
//! force output off. The vendor's own force ramping and maximum-force clamping are enabled as a
//! second line behind ours.
//!
//! The library stays loaded for the process's life, as CHAI3D keeps it: the vendor's driver does
//! not survive being loaded twice. `unsafe` is confined to the `ffi` module and the scheduler's
//! callback: calling into a C library loaded at run time cannot be checked by the compiler, so each
//! call states why it is sound.
#![allow(unsafe_code)]

mod ffi;
mod scheduler;

use std::ffi::CString;
use std::path::PathBuf;
use std::sync::Arc;

use coop_model::body::Vec3;

use crate::device::{
    CartesianDevice, Command, ConfigError, DeviceFault, DeviceInfo, ProbeReport, Sample,
};
use crate::sync::{AtomicU64, Ordering};
use ffi::{consts::*, Api};

pub use scheduler::HdScheduler;

/// Library names tried, in order, when `library` is not set (the dynamic loader's search path:
/// `LD_LIBRARY_PATH`, `/etc/ld.so.cache`, then [`DEFAULT_DIRS`]).
pub const DEFAULT_LIBRARIES: &[&str] = &["libHD.so", "libHD.so.3.4", "libHD.so.3.0"];
/// Directories tried after the loader's own search, where OpenHaptics' installers put the library.
pub const DEFAULT_DIRS: &[&str] = &[
    "/usr/lib",
    "/usr/lib64",
    "/usr/local/lib",
    "/opt/OpenHaptics/lib",
];

/// The station config's `[device.openhaptics]` table.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct OpenHapticsConfig {
    /// OpenHaptics' `libHD.so`; none: search [`DEFAULT_LIBRARIES`] on the loader's path, then
    /// [`DEFAULT_DIRS`].
    pub library: Option<PathBuf>,
    /// The device's name as the Touch Setup tool configured it (`hdInitDevice`); none: the
    /// default device.
    pub device_name: Option<String>,
    /// The HD scheduler's rate, Hz (`hdSetSchedulerRate`): 500, 1000 or 2000 (what the devices
    /// run; 1000 for a Touch).
    pub scheduler_rate_hz: u32,
    /// The scheduler's own watchdog: no servo tick for this long and the force output is turned
    /// off from the thread that started it (the vendor's thread may be the one that hangs), ms.
    pub stall_ms: f64,
}

impl Default for OpenHapticsConfig {
    fn default() -> Self {
        Self {
            library: None,
            device_name: None,
            scheduler_rate_hz: 1000,
            stall_ms: 10.0,
        }
    }
}

impl OpenHapticsConfig {
    /// The device's name for `hdInitDevice` (validated: no NUL), none for the default device.
    fn device_name_c(&self) -> Option<CString> {
        self.device_name
            .as_ref()
            .map(|n| CString::new(n.as_str()).unwrap_or_default())
    }

    /// Checks every field.
    ///
    /// # Errors
    /// The first field that breaks its rule, with its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |field: &str, value: String, rule: &str| ConfigError {
            field: field.into(),
            value,
            rule: rule.into(),
        };
        if self
            .library
            .as_ref()
            .is_some_and(|p| p.as_os_str().is_empty())
        {
            return Err(bad(
                "library",
                "\"\"".into(),
                "must be the path of libHD.so (or left out to search for it)",
            ));
        }
        if let Some(n) = &self.device_name {
            if n.is_empty() || n.contains('\0') {
                return Err(bad(
                    "device_name",
                    format!("{n:?}"),
                    "must be the device's name in Touch Setup (or left out for the default device)",
                ));
            }
        }
        if ![500, 1000, 2000].contains(&self.scheduler_rate_hz) {
            return Err(bad(
                "scheduler_rate_hz",
                self.scheduler_rate_hz.to_string(),
                "must be 500, 1000 or 2000 (the rates the HD scheduler runs devices at)",
            ));
        }
        let three_ticks_ms = 3e3 / f64::from(self.scheduler_rate_hz);
        if !((1.0..=100.0).contains(&self.stall_ms) && self.stall_ms >= three_ticks_ms) {
            return Err(bad(
                "stall_ms",
                self.stall_ms.to_string(),
                &format!("must be in 1..=100 ms and at least three scheduler ticks ({three_ticks_ms} ms at scheduler_rate_hz)"),
            ));
        }
        Ok(())
    }
}

/// Why [`OpenHapticsDevice::open`] (or a probe) failed. Nothing was left initialised.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OpenHapticsError {
    /// The config breaks a rule.
    #[error("device.openhaptics.{0}")]
    Config(ConfigError),
    /// No library at the configured path, or none found by the default search.
    #[error("OpenHaptics HD library {file} not found or not loadable ({reason}); set device.openhaptics.library to the SDK's libHD.so")]
    LibraryMissing {
        /// The file (or the names searched).
        file: String,
        /// The loader's words.
        reason: String,
    },
    /// The library lacks an entry point we call (not OpenHaptics' HD library, or too old).
    #[error(
        "{file} (device.openhaptics.library) has no {symbol}: not OpenHaptics' libHD, or too old"
    )]
    MissingSymbol {
        /// The library.
        file: String,
        /// The entry point.
        symbol: &'static str,
    },
    /// An HD call failed while opening, setting up or running.
    #[error("{call} failed (HD error {code:#06x}: {reason}){advice}")]
    CallFailed {
        /// The entry point.
        call: &'static str,
        /// `hdGetError().errorCode`.
        code: u32,
        /// `hdGetErrorString`.
        reason: String,
        /// What to do about it, where we know.
        advice: &'static str,
    },
    /// The servo step panicked inside the scheduler's callback (the force output was turned off).
    #[error("the servo step panicked inside the HD scheduler's callback; the force output was turned off")]
    ServoPanicked,
    /// The scheduler stopped calling back while the station ran.
    #[error("the HD scheduler stopped calling the servo for {ms} ms (device.openhaptics.stall_ms); the force output was turned off")]
    Stalled {
        /// How long it had been silent, ms.
        ms: u64,
    },
}

/// What the scheduler's callback and the device share: whether a frame is open, and what went
/// wrong outside the device's own calls. Atomics only: both sides are on the servo path.
#[derive(Debug, Default)]
pub(crate) struct FrameShared {
    /// 1 while a frame is open (the callback is running the servo step).
    in_frame: AtomicU64,
    /// An error `hdEndFrame` left (0: none); the next sample reports it.
    end_error: AtomicU64,
    /// The calibration state at the last tick (`HD_CALIBRATION_*`; 0 before the first).
    calibration: AtomicU64,
    /// Calibration updates made at the device's request.
    calibration_updates: AtomicU64,
    /// Scheduler ticks run.
    ticks: AtomicU64,
}

/// A device driven through the HD API.
#[derive(Debug)]
pub struct OpenHapticsDevice {
    api: &'static Api,
    handle: u32,
    info: DeviceInfo,
    config: OpenHapticsConfig,
    shared: Arc<FrameShared>,
    open: bool,
}

/// What the HD API's error stack holds now, as an open error naming `call`.
fn call_failed(api: &Api, call: &'static str, code: u32) -> OpenHapticsError {
    let advice = match code {
        HD_COMM_ERROR | HD_COMM_CONFIG_ERROR => {
            ": is the device plugged in and configured in Touch Setup, and is its driver running?"
        }
        HD_DEVICE_ALREADY_INITIATED => ": another process (or station) holds the device",
        HD_INVALID_LICENSE => ": OpenHaptics' license is missing",
        _ => "",
    };
    OpenHapticsError::CallFailed {
        call,
        code,
        reason: api.error_string(code),
        advice,
    }
}

/// What a device reports of itself (not on the servo path).
fn describe(api: &Api, rate_hz: u32) -> DeviceInfo {
    let model = api
        .string(HD_DEVICE_MODEL_TYPE)
        .unwrap_or_else(|| "OpenHaptics device".into());
    let vendor = api.string(HD_DEVICE_VENDOR);
    let d = |p| api.doubles::<1>(p)[0];
    let ws = api.doubles::<6>(HD_USABLE_WORKSPACE_DIMENSIONS);
    // The largest sphere in the usable box, mm to m.
    let radius_m = (0..3)
        .map(|k| (ws[k + 3] - ws[k]).abs() / 2.0)
        .fold(f64::INFINITY, f64::min)
        / 1e3;
    let clean = |v: f64, fallback: f64| {
        if v.is_finite() && v > 0.0 {
            v
        } else {
            fallback
        }
    };
    DeviceInfo {
        backend: "openhaptics",
        model: match vendor {
            Some(v) if !v.is_empty() => format!("{v} {model}"),
            _ => model,
        },
        serial: api
            .string(HD_DEVICE_SERIAL_NUMBER)
            .filter(|s| !s.is_empty()),
        dof: u8::try_from(api.integer(HD_OUTPUT_DOF).clamp(1, 6)).unwrap_or(3),
        // The force it holds continuously (a Touch's nominal peak is several times that, for
        // moments only): the safety layer clamps to this.
        max_force_n: clean(d(HD_NOMINAL_MAX_CONTINUOUS_FORCE), 0.5),
        max_stiffness_n_per_m: clean(d(HD_NOMINAL_MAX_STIFFNESS) * 1e3, 500.0),
        max_damping_n_s_per_m: clean(d(HD_NOMINAL_MAX_DAMPING) * 1e3, 1.0),
        workspace_radius_m: clean(radius_m, 0.03),
        native_rate_hz: f64::from(rate_hz),
        senses_force: false,
    }
}

impl OpenHapticsDevice {
    /// Loads the HD library (once per process), initialises the device, checks its calibration
    /// (updating it where the device asks), reads what it is, sets the scheduler's rate and
    /// enables the force output with the vendor's ramping and clamping. The scheduler is not
    /// started: [`HdScheduler::run_hd`] does that.
    ///
    /// # Errors
    /// A bad config, no library, a library without the HD entry points, no device, or a setup
    /// call failing (the output is turned off and the device disabled again).
    pub fn open(config: &OpenHapticsConfig) -> Result<Self, OpenHapticsError> {
        config.validate().map_err(OpenHapticsError::Config)?;
        let api = Api::load(config.library.as_deref())?;
        // Whatever an earlier user of this process left on the stack is not ours.
        api.drain_errors();
        let name = config.device_name_c();
        let handle = api.init_device(name.as_deref());
        if let Some(code) = api.take_error() {
            if handle != HD_INVALID_HANDLE {
                api.disable_device(handle);
            }
            return Err(call_failed(api, "hdInitDevice", code));
        }
        if handle == HD_INVALID_HANDLE {
            return Err(call_failed(api, "hdInitDevice", HD_COMM_CONFIG_ERROR));
        }
        let fail = |e: OpenHapticsError| {
            api.disable(HD_FORCE_OUTPUT);
            api.disable_device(handle);
            api.drain_errors();
            e
        };
        let check = |call: &'static str| match api.take_error() {
            Some(code) => Err(fail(call_failed(api, call, code))),
            None => Ok(()),
        };
        api.make_current(handle);
        check("hdMakeCurrentDevice")?;
        // Updated where the device asks in a style that needs no pose of the arm. A device that
        // wants its stylus in the inkwell opens: the inkwell calibrates it once the scheduler
        // runs (as the vendor's own examples do), and until then every tick is a calibration
        // fault, the force held released.
        if api.check_calibration() == HD_CALIBRATION_NEEDS_UPDATE {
            if let Some(style) = calibration_style(api) {
                api.update_calibration(style);
                check("hdUpdateCalibration")?;
            }
        }
        api.drain_errors();
        // A parameter a device does not have is left at its fallback (`describe`).
        let info = describe(api, config.scheduler_rate_hz);
        api.drain_errors();
        api.set_scheduler_rate(config.scheduler_rate_hz);
        check("hdSetSchedulerRate")?;
        // The vendor's ramp on enable and its clamp to the device's maximum, behind ours.
        api.enable(HD_FORCE_RAMPING);
        api.enable(HD_MAX_FORCE_CLAMPING);
        check("hdEnable")?;
        api.enable(HD_FORCE_OUTPUT);
        check("hdEnable")?;
        Ok(Self {
            api,
            handle,
            info,
            config: config.clone(),
            shared: Arc::new(FrameShared::default()),
            open: true,
        })
    }

    /// The library it was loaded from.
    pub fn library(&self) -> &str {
        &self.api.file
    }

    /// The scheduler that runs this device's servo loop (see [`HdScheduler::run_hd`]).
    pub fn scheduler(&self) -> HdScheduler {
        HdScheduler::new(self.api, self.handle, self.shared.clone(), &self.config)
    }

    /// Calibration updates made at the device's request while running.
    pub fn calibration_updates(&self) -> u64 {
        self.shared.calibration_updates.load(Ordering::Relaxed)
    }

    /// Releases the force inside the open frame, best effort, and names the fault.
    fn failed(&self, call: &'static str, code: impl Into<u64>) -> DeviceFault {
        self.api.set_force(Vec3::zeros());
        self.api.drain_errors();
        DeviceFault::CallFailed {
            call,
            code: i32::try_from(code.into()).unwrap_or(i32::MAX),
        }
    }
}

/// The calibration style to update with: automatic, or the inkwell; none where the device has
/// only the encoder reset, which needs the arm held at its reset pose (a person's doing).
fn calibration_style(api: &Api) -> Option<u32> {
    let styles = u32::try_from(api.integer(HD_CALIBRATION_STYLE)).unwrap_or(0);
    [HD_CALIBRATION_AUTO, HD_CALIBRATION_INKWELL]
        .into_iter()
        .find(|s| styles & s != 0)
}

impl CartesianDevice for OpenHapticsDevice {
    fn info(&self) -> &DeviceInfo {
        &self.info
    }

    fn sample(&mut self, now_ns: u64) -> Result<Sample, DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging; the HD API's own calls only, inside the
        // scheduler's frame.
        if !self.open || self.shared.in_frame.load(Ordering::Acquire) == 0 {
            // Outside the scheduler's frame the device's state is not ours to read.
            return Err(DeviceFault::Disconnected);
        }
        // Written by the callback on this same thread, after the previous frame.
        let end = self.shared.end_error.load(Ordering::Acquire);
        if end != 0 {
            self.shared.end_error.store(0, Ordering::Release);
            return Err(self.failed("hdEndFrame", end));
        }
        let cal = self.shared.calibration.load(Ordering::Acquire);
        if cal != u64::from(HD_CALIBRATION_OK) {
            return Err(self.failed("hdCheckCalibration", cal));
        }
        let p = self.api.doubles::<3>(HD_CURRENT_POSITION);
        let v = self.api.doubles::<3>(HD_CURRENT_VELOCITY);
        let buttons = self.api.integer(HD_CURRENT_BUTTONS);
        if let Some(code) = self.api.take_error() {
            return Err(self.failed("hdGetDoublev", code));
        }
        // mm and mm/s to m and m/s.
        let position_m = Vec3::new(p[0], p[1], p[2]) / 1e3;
        let velocity_m_s = Vec3::new(v[0], v[1], v[2]) / 1e3;
        if !position_m.iter().all(|c| c.is_finite() && c.abs() < 10.0) {
            self.api.set_force(Vec3::zeros());
            return Err(DeviceFault::BadValue { what: "position" });
        }
        if !velocity_m_s.iter().all(|c| c.is_finite()) {
            self.api.set_force(Vec3::zeros());
            return Err(DeviceFault::BadValue { what: "velocity" });
        }
        Ok(Sample {
            t_ns: now_ns,
            position_m,
            velocity_m_s,
            orientation: None,
            buttons: u32::try_from(buttons).unwrap_or(0),
            force_sensed_n: None,
        })
    }

    fn command(&mut self, _now_ns: u64, cmd: Command) -> Result<(), DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging; the HD API's own calls only, inside the
        // scheduler's frame.
        if !self.open {
            return Err(DeviceFault::Disconnected);
        }
        if self.shared.in_frame.load(Ordering::Acquire) == 0 {
            // Outside a frame a force cannot be set: a release turns the output off instead.
            return match cmd {
                Command::Release => {
                    self.api.disable(HD_FORCE_OUTPUT);
                    self.api.drain_errors();
                    Ok(())
                }
                Command::Force(_) => Err(DeviceFault::Disconnected),
            };
        }
        let f = match cmd {
            Command::Force(f) if f.iter().all(|c| c.is_finite()) => f,
            Command::Force(_) => {
                self.api.set_force(Vec3::zeros());
                return Err(DeviceFault::BadValue {
                    what: "force command",
                });
            }
            Command::Release => Vec3::zeros(),
        };
        self.api.set_force(f);
        if let Some(code) = self.api.take_error() {
            return Err(self.failed("hdSetDoublev", code));
        }
        Ok(())
    }

    fn close(&mut self) {
        if !self.open {
            return;
        }
        self.open = false;
        // The scheduler has stopped (its runner returned first): turn the output off, then let the
        // device go, so that another process (or a restarted servo) can initialise it.
        self.api.disable(HD_FORCE_OUTPUT);
        self.api.disable_device(self.handle);
        self.api.drain_errors();
    }
}

impl crate::device::VendorDevice for OpenHapticsDevice {
    fn vendor_loop(&self) -> Option<Box<dyn crate::device::VendorLoop>> {
        Some(Box::new(self.scheduler()))
    }
}

impl Drop for OpenHapticsDevice {
    fn drop(&mut self) {
        self.close();
    }
}

/// What `station devices` says of the OpenHaptics backend: whether the library loads, and the
/// device it finds (initialised, described and disabled again; no force is enabled).
pub fn probe(config: &OpenHapticsConfig) -> ProbeReport {
    let mut report = ProbeReport {
        backend: "openhaptics",
        built_in: true,
        status: String::new(),
        devices: Vec::new(),
    };
    if let Err(e) = config.validate() {
        report.status = format!("device.openhaptics.{e}");
        return report;
    }
    let api = match Api::load(config.library.as_deref()) {
        Ok(a) => a,
        Err(e) => {
            report.status = e.to_string();
            return report;
        }
    };
    api.drain_errors();
    let name = config.device_name_c();
    let handle = api.init_device(name.as_deref());
    match api.take_error() {
        None if handle != HD_INVALID_HANDLE => {
            report.devices.push(describe(api, config.scheduler_rate_hz));
            api.disable_device(handle);
            report.status = format!("OpenHaptics HD library loaded from {}: 1 device", api.file);
        }
        code => {
            if handle != HD_INVALID_HANDLE {
                api.disable_device(handle);
            }
            let e = call_failed(api, "hdInitDevice", code.unwrap_or(HD_COMM_CONFIG_ERROR));
            report.status = format!(
                "OpenHaptics HD library loaded from {}: no device ({e})",
                api.file
            );
        }
    }
    api.drain_errors();
    report
}

#[cfg(test)]
mod tests;
