//! Devices: what the servo loop reads and writes each tick.
//!
//! [`cartesian`] is the interface every backend implements; [`safety`] wraps every backend in the
//! vendors' safety contract; [`placement`] maps a device's frame to the world. Backends here:
//! [`SimScara`], the simulated SCARA arm held by a scripted hand (it senses force, so the paper's
//! Eq. 12 PI loop runs inside it), and [`replay::Replay`], a recorded hand played back by position.
//! [`StationDevice`] is the one type a station's servo loop drives, whichever backend its config
//! selects.

pub mod cartesian;
pub mod dhd;
pub mod figures;
pub mod haply;
pub mod openhaptics;
pub mod placement;
pub mod replay;
pub mod safety;
mod scara;
mod slot;
mod station;
mod vendor_lib;

pub use cartesian::{
    CartesianDevice, Command, ConfigError, DeviceFault, DeviceInfo, ProbeReport, Sample,
};

pub use figures::DevicePublisher;
pub use placement::Placement;
pub use scara::SimScara;
pub use slot::{check_bridged, BridgedState, CommandSlot};
pub use station::{
    Backend, BridgeCounts, StationDevice, VendorDevice, VendorLoop, VendorLoopError,
    VendorLoopSummary,
};
