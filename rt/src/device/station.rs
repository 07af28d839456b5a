//! The device a station's servo drives: one of the backends, chosen by its config.

use super::cartesian::{CartesianDevice, Command, DeviceFault, DeviceInfo, Sample};
use super::replay::Replay;
use super::scara::SimScara;

/// The backends a station config can select (`[device] device = "…"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// The simulated SCARA arm and scripted hand.
    Sim,
    /// A recorded hand.
    Replay,
    /// Haply Inverse3 through the Haply Inverse Service.
    Haply,
    /// Force Dimension (and Novint Falcon) through the DHD SDK.
    Dhd,
    /// 3D Systems' Touch and Phantom devices through OpenHaptics' HD API, in its scheduler.
    OpenHaptics,
    /// Any device whose ROS 2 driver publishes its end effector's pose (a bridge over zenoh,
    /// `coop_transport::ros2_device`).
    Ros2,
}

impl Backend {
    /// Every backend.
    pub const ALL: [Backend; 6] = [
        Backend::Sim,
        Backend::Replay,
        Backend::Haply,
        Backend::Dhd,
        Backend::OpenHaptics,
        Backend::Ros2,
    ];

    /// Its name in the config.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Sim => "sim",
            Backend::Replay => "replay",
            Backend::Haply => "haply",
            Backend::Dhd => "dhd",
            Backend::OpenHaptics => "openhaptics",
            Backend::Ros2 => "ros2",
        }
    }
}

/// A station's device.
// One per servo process, held for its whole run: the size difference costs nothing, a box would
// cost an indirection each tick.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
pub enum StationDevice {
    /// The simulated arm.
    Sim(SimScara),
    /// A recorded hand.
    Replay(Replay),
    /// A vendor backend.
    Other(Box<dyn VendorDevice>),
}

/// What a device's bridge thread counted (a device behind one: ROS 2, Haply), as the backend
/// reads them from its bridge's atomics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct BridgeCounts {
    /// Messages taken from the driver or service.
    pub received: u64,
    /// ... refused as not a sample.
    pub refused: u64,
    /// ... refused for coming from another publisher than the driver's.
    pub foreign: u64,
    /// Force commands put that were not zero.
    pub sent_forces: u64,
    /// Connections lost.
    pub losses: u64,
    /// Reconnections after a loss.
    pub reconnects: u64,
}

/// A vendor backend as a station drives it: a [`CartesianDevice`] that can be printed, and that
/// says what its bridge thread counted, if it has one.
pub trait VendorDevice: CartesianDevice + std::fmt::Debug {
    /// Its bridge's counts (none: no bridge, the servo calls the device itself). Atomic loads
    /// only: the servo reads them on its thread.
    fn bridge_counts(&self) -> Option<BridgeCounts> {
        None
    }

    /// The vendor's loop, for a device whose vendor runs the servo thread and calls us back
    /// (`loop = "vendor"`); none: the station's loop calls the device.
    fn vendor_loop(&self) -> Option<Box<dyn VendorLoop>> {
        None
    }
}

/// A vendor's servo loop (OpenHaptics' scheduler): it calls the station's servo step once per
/// its own tick, on its own thread.
pub trait VendorLoop: Send + std::fmt::Debug {
    /// Calls `tick(now_ns)` once per vendor tick, with the device's state valid inside it, until
    /// `tick` returns false; records each tick in `stats` (lateness against the vendor's period,
    /// compute time). The calling thread waits, and watches the vendor's thread.
    ///
    /// # Errors
    /// The loop could not start, or stopped calling back (its output is then off).
    fn run(
        &self,
        stats: Option<&crate::stats::LoopStats>,
        tick: &mut (dyn FnMut(u64) -> bool + Send),
    ) -> Result<VendorLoopSummary, VendorLoopError>;
}

/// How a vendor loop's run went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VendorLoopSummary {
    /// Ticks the vendor called back.
    pub ticks: u64,
}

/// Why a vendor loop ended other than by the servo's say.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct VendorLoopError(pub String);

impl StationDevice {
    /// Sets the session's time 0 for a device that plays a script or a recording.
    pub fn start_at(&mut self, start_ns: u64) {
        match self {
            StationDevice::Sim(d) => d.start_at(start_ns),
            StationDevice::Replay(d) => d.start_at(start_ns),
            StationDevice::Other(_) => {}
        }
    }

    /// The vendor's loop, where the vendor runs the servo thread.
    pub fn vendor_loop(&self) -> Option<Box<dyn VendorLoop>> {
        match self {
            StationDevice::Other(d) => d.vendor_loop(),
            StationDevice::Sim(_) | StationDevice::Replay(_) => None,
        }
    }

    /// What its bridge thread counted (a vendor backend behind one).
    pub fn bridge_counts(&self) -> Option<BridgeCounts> {
        match self {
            StationDevice::Other(d) => d.bridge_counts(),
            StationDevice::Sim(_) | StationDevice::Replay(_) => None,
        }
    }
}

impl CartesianDevice for StationDevice {
    fn info(&self) -> &DeviceInfo {
        match self {
            StationDevice::Sim(d) => d.info(),
            StationDevice::Replay(d) => d.info(),
            StationDevice::Other(d) => d.info(),
        }
    }
    fn sample(&mut self, now_ns: u64) -> Result<Sample, DeviceFault> {
        match self {
            StationDevice::Sim(d) => d.sample(now_ns),
            StationDevice::Replay(d) => d.sample(now_ns),
            StationDevice::Other(d) => d.sample(now_ns),
        }
    }
    fn command(&mut self, now_ns: u64, cmd: Command) -> Result<(), DeviceFault> {
        match self {
            StationDevice::Sim(d) => d.command(now_ns, cmd),
            StationDevice::Replay(d) => d.command(now_ns, cmd),
            StationDevice::Other(d) => d.command(now_ns, cmd),
        }
    }
    fn set_output_gain(&mut self, gain: f64) {
        match self {
            StationDevice::Sim(d) => d.set_output_gain(gain),
            StationDevice::Replay(d) => d.set_output_gain(gain),
            StationDevice::Other(d) => d.set_output_gain(gain),
        }
    }
    fn observe(&mut self, view: &coop_model::task::View) {
        match self {
            StationDevice::Sim(d) => d.observe(view),
            StationDevice::Replay(d) => d.observe(view),
            StationDevice::Other(d) => d.observe(view),
        }
    }
    fn close(&mut self) {
        match self {
            StationDevice::Sim(d) => d.close(),
            StationDevice::Replay(d) => d.close(),
            StationDevice::Other(d) => d.close(),
        }
    }
}
