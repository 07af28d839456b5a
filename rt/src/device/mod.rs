//! Devices: what the servo loop reads and writes each tick.
//!
//! [`cartesian`] is the interface every backend implements (the simulated SCARA arm, a replayed hand,
//! vendor devices). The joint-space [`Device`] below is the simulated arm's own view, kept while the
//! servo moves to the Cartesian interface.

pub mod cartesian;
pub mod dhd;
pub mod haply;

pub use cartesian::{
    CartesianDevice, Command, ConfigError, DeviceFault, DeviceInfo, ProbeReport, Sample,
};

use coop_model::body::Vec3;
use coop_model::device::Plant;
use coop_model::user::{target_at, Keyframe};

/// One reading of a device.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// Joint positions.
    pub q: Vec3,
    /// Joint velocities.
    pub qd: Vec3,
    /// Force sensor: force on the hand, N.
    pub f_measured: Vec3,
}

/// A force-display device.
pub trait Device: Send {
    /// Reads the device at `now_ns`.
    fn read(&mut self, now_ns: u64) -> Reading;
    /// Commands joint torques (held until the next write).
    fn write(&mut self, tau: Vec3);
}

/// The simulated arm and hand: integrated up to each read, in steps of at most 100 µs, with the last
/// written torques held.
#[derive(Debug, Clone)]
pub struct SimDevice {
    plant: Plant,
    script: Vec<Keyframe>,
    start_ns: Option<u64>,
    plant_ns: u64,
    tau: Vec3,
}

impl SimDevice {
    /// A simulated device whose script's time 0 is `start_ns`; `now_ns` is when its plant starts.
    pub fn new(plant: Plant, script: Vec<Keyframe>, start_ns: u64) -> Self {
        let mut d = Self::waiting(plant, script, start_ns);
        d.start_ns = Some(start_ns);
        d
    }
    /// A simulated device whose hand holds the script's first pose until [`SimDevice::start_at`]
    /// gives the script's time 0 (a station waiting for its session to start).
    pub fn waiting(plant: Plant, script: Vec<Keyframe>, now_ns: u64) -> Self {
        Self {
            plant,
            script,
            start_ns: None,
            plant_ns: now_ns,
            tau: Vec3::zeros(),
        }
    }
    /// Sets the script's time 0 (the hand holds the first pose until then).
    pub fn start_at(&mut self, start_ns: u64) {
        self.start_ns = Some(start_ns);
    }
    /// The script's time 0, once known.
    pub fn start(&self) -> Option<u64> {
        self.start_ns
    }
    /// The plant (for tests and recordings).
    pub fn plant(&self) -> &Plant {
        &self.plant
    }
}

impl Device for SimDevice {
    fn read(&mut self, now_ns: u64) -> Reading {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        while self.plant_ns < now_ns {
            let step = (now_ns - self.plant_ns).min(100_000);
            let t = self.start_ns.map_or(0.0, |s| {
                (self.plant_ns + step).saturating_sub(s) as f64 * 1e-9
            });
            let (target, vel) = target_at(&self.script, t);
            self.plant.step(self.tau, target, vel, step as f64 * 1e-9);
            self.plant_ns += step;
        }
        Reading {
            q: self.plant.q,
            qd: self.plant.qd,
            f_measured: self.plant.grip_force,
        }
    }
    fn write(&mut self, tau: Vec3) {
        self.tau = tau;
    }
}
