//! A recorded hand as a device: it plays a [`Trajectory`] by position from its time 0 (the
//! session's start), ignores the forces it is commanded (a recorded hand does not yield) and counts
//! them. Its frame is the recording's (the world, for a station's recording).

use coop_model::body::Vec3;
use coop_model::replay::Trajectory;

use super::cartesian::{CartesianDevice, Command, DeviceFault, DeviceInfo, Sample};

/// A recorded hand.
#[derive(Debug, Clone)]
pub struct Replay {
    trajectory: Trajectory,
    start_ns: Option<u64>,
    commands: u64,
    last_force: Vec3,
    info: DeviceInfo,
}

impl Replay {
    /// Plays `trajectory` (its time 0 at [`Replay::start_at`]; it holds its first position until
    /// then). `what` names the source, e.g. the file.
    pub fn new(trajectory: Trajectory, what: &str) -> Self {
        Self {
            trajectory,
            start_ns: None,
            commands: 0,
            last_force: Vec3::zeros(),
            info: DeviceInfo {
                backend: "replay",
                model: format!("recorded hand ({what})"),
                serial: None,
                dof: 3,
                // It displays nothing, so nothing bounds what it is commanded.
                max_force_n: f64::INFINITY,
                max_stiffness_n_per_m: f64::INFINITY,
                max_damping_n_s_per_m: f64::INFINITY,
                workspace_radius_m: f64::INFINITY,
                native_rate_hz: f64::INFINITY,
                senses_force: false,
            },
        }
    }

    /// Sets the recording's time 0.
    pub fn start_at(&mut self, start_ns: u64) {
        self.start_ns = Some(start_ns);
    }

    /// Its time 0, once known.
    pub fn start(&self) -> Option<u64> {
        self.start_ns
    }

    /// The trajectory.
    pub fn trajectory(&self) -> &Trajectory {
        &self.trajectory
    }

    /// Force commands taken, and the last force.
    pub fn commanded(&self) -> (u64, Vec3) {
        (self.commands, self.last_force)
    }
}

impl CartesianDevice for Replay {
    fn info(&self) -> &DeviceInfo {
        &self.info
    }

    fn sample(&mut self, now_ns: u64) -> Result<Sample, DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let t = self.start_ns.map_or(f64::NEG_INFINITY, |s| {
            now_ns as f64 * 1e-9 - s as f64 * 1e-9
        });
        let (p, v) = self.trajectory.at(t);
        Ok(Sample {
            t_ns: now_ns,
            position_m: p,
            velocity_m_s: v,
            orientation: None,
            buttons: 0,
            force_sensed_n: None,
        })
    }

    fn command(&mut self, _now_ns: u64, cmd: Command) -> Result<(), DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        self.commands += 1;
        self.last_force = match cmd {
            Command::Force(f) => f,
            Command::Release => Vec3::zeros(),
        };
        Ok(())
    }
}
