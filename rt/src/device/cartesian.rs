//! The Cartesian device interface every backend implements (the simulated SCARA arm, a replayed
//! hand, the Haply Inverse3, Force Dimension's DHD devices): a device says what it is once
//! ([`DeviceInfo`], CHAI3D's `cHapticDeviceInfo`), and per servo tick gives a [`Sample`] in its own
//! frame and takes a [`Command`]. The station's placement maps the device frame to the world; the
//! safety layer (`device::safety`) sits between the servo and every backend, so a backend only does
//! its transport faithfully and reports faults.

use coop_model::body::Vec3;
use nalgebra::UnitQuaternion;

/// What a device says of itself once it is open (CHAI3D's `cHapticDeviceInfo`). Not on the servo
/// path.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceInfo {
    /// The backend's name: `"sim"`, `"replay"`, `"haply"`, `"dhd"`, `"ros2"`.
    pub backend: &'static str,
    /// The model, e.g. `"Inverse3"`, `"omega.3"`, `"Novint Falcon"`, `"SCARA (simulated)"`.
    pub model: String,
    /// The serial number, where the device tells it.
    pub serial: Option<String>,
    /// Degrees of freedom actuated (translational, plus rotational where there are).
    pub dof: u8,
    /// Largest force the device displays continuously, N.
    pub max_force_n: f64,
    /// Stiffest contact it renders stably, N/m (device frame).
    pub max_stiffness_n_per_m: f64,
    /// Largest damping it renders stably, N·s/m (device frame).
    pub max_damping_n_s_per_m: f64,
    /// Radius of the sphere its workspace contains, m.
    pub workspace_radius_m: f64,
    /// The rate its own loop or firmware runs at, Hz.
    pub native_rate_hz: f64,
    /// Whether it measures the force on the hand ([`Sample::force_sensed_n`]).
    pub senses_force: bool,
}

/// One Cartesian sample, in the DEVICE frame (the station's placement maps it to the world).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// CLOCK_MONOTONIC when the device measured it, ns (a bridged device's is older than now). The
    /// safety layer's watchdog releases the device when it stops advancing.
    pub t_ns: u64,
    /// Handle position, m.
    pub position_m: Vec3,
    /// Handle velocity, m/s.
    pub velocity_m_s: Vec3,
    /// Handle orientation, where the device senses it.
    pub orientation: Option<UnitQuaternion<f64>>,
    /// Buttons: bit i set while button i is pressed.
    pub buttons: u32,
    /// Force the device applies to the hand, N, where it has a sensor ([`DeviceInfo::senses_force`]).
    pub force_sensed_n: Option<Vec3>,
}

/// What the servo asks the device to display this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// A force on the user's hand, N, device frame (already clamped by the safety layer).
    Force(Vec3),
    /// Zero force, motors off (brakes where the device has them).
    Release,
}

/// Why a device call failed. `Copy` and allocation-free: it is made on the servo path.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DeviceFault {
    /// No fresh sample (bridge or service gone, USB unplugged).
    #[error("device disconnected (no fresh sample)")]
    Disconnected,
    /// A vendor call returned an error code.
    #[error("device call {call} failed with code {code}")]
    CallFailed {
        /// The vendor function, e.g. `"dhdGetPosition"`.
        call: &'static str,
        /// What it returned.
        code: i32,
    },
    /// The device returned a non-finite or out-of-range value.
    #[error("device returned a bad value for {what}")]
    BadValue {
        /// Which value, e.g. `"position"`.
        what: &'static str,
    },
}

/// A force-display device in Cartesian space.
///
/// `sample` and `command` are on the servo path: no allocation, no lock, no logging, no blocking on
/// a socket (a bridged device exchanges with its bridge through lock-free rings). Everything else is
/// setup.
pub trait CartesianDevice: Send {
    /// What the device is.
    fn info(&self) -> &DeviceInfo;
    /// The newest sample at `now_ns` (CLOCK_MONOTONIC).
    ///
    /// # Errors
    /// The device is gone, a call failed, or it returned a bad value.
    fn sample(&mut self, now_ns: u64) -> Result<Sample, DeviceFault>;
    /// Displays `cmd` until the next call.
    ///
    /// # Errors
    /// As [`CartesianDevice::sample`].
    fn command(&mut self, now_ns: u64, cmd: Command) -> Result<(), DeviceFault>;
    /// For a device that closes a force loop itself (it senses force and servoes its motors to the
    /// commanded force, like the simulated SCARA arm's Eq. 12 PI controller): the share, 0..=1, of
    /// its loop's output it may apply from now on. The servo's stale-world ramp and the safety
    /// layer's ramp-in set it, so a fading world leaves such a device limp instead of
    /// force-controlled to zero. A device that displays the commanded force open-loop ignores it
    /// (the default): the force it is given already carries the ramp.
    fn set_output_gain(&mut self, _gain: f64) {}
    /// What the site shows and the tool feels at this servo tick (from the session's time 0): a
    /// device whose hand is simulated (a participant acting on what its site shows) takes it in;
    /// a device a person holds has nothing to do with it (the default). On the servo path: no
    /// allocation, no lock, no logging.
    fn observe(&mut self, _view: &coop_model::task::View) {}
    /// Called once when the station stops or the servo exits (also on error paths): release and
    /// close.
    fn close(&mut self) {}
}

impl<D: CartesianDevice + ?Sized> CartesianDevice for Box<D> {
    fn info(&self) -> &DeviceInfo {
        (**self).info()
    }
    fn sample(&mut self, now_ns: u64) -> Result<Sample, DeviceFault> {
        (**self).sample(now_ns)
    }
    fn command(&mut self, now_ns: u64, cmd: Command) -> Result<(), DeviceFault> {
        (**self).command(now_ns, cmd)
    }
    fn set_output_gain(&mut self, gain: f64) {
        (**self).set_output_gain(gain);
    }
    fn observe(&mut self, view: &coop_model::task::View) {
        (**self).observe(view);
    }
    fn close(&mut self) {
        (**self).close();
    }
}

/// A config value that breaks a rule: what a backend's table's `validate()` returns. The station
/// config adds the table's name to `field` and the file it was read from.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field} = {value}: {rule}")]
pub struct ConfigError {
    /// The field, as written in the file, e.g. `"url"` (the station makes it `"device.haply.url"`).
    pub field: String,
    /// Its value as written (strings quoted).
    pub value: String,
    /// The rule it breaks, e.g. `"must be a ws:// URL"`.
    pub rule: String,
}

/// What `station devices` says of one backend: whether it is built in and what it finds.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeReport {
    /// The backend's name, as in the config's `device = "…"`.
    pub backend: &'static str,
    /// Whether this build carries it.
    pub built_in: bool,
    /// One line on what was looked for and found, e.g. `"libdhd.so found at /usr/lib"`,
    /// `"Haply Inverse Service not reachable at ws://localhost:10001"`.
    pub status: String,
    /// The devices it found, with their info.
    pub devices: Vec<DeviceInfo>,
}
