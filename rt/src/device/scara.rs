//! The simulated SCARA arm held by a scripted hand, as a Cartesian device: the model's plant,
//! integrated up to each sample in steps of at most 100 µs under the last torques, and the arm's own
//! Eq. 12 PI force loop ([`ScaraForceLoop`]), which turns each force command into joint torques with
//! the handle's force sensor. Its frame is the world (the arm's base and the script are in world
//! coordinates), so its placement is the identity. The hand follows the site's script, or is a
//! simulated participant acting on what the site shows ([`SimScara::with_participant`]): the
//! same person the simulator draws for the site.

use coop_model::body::Vec3;
use coop_model::device::{Plant, ScaraForceLoop};
use coop_model::participant::Participant;
use coop_model::task::View;
use coop_model::user::{target_at, Keyframe};

use super::cartesian::{CartesianDevice, Command, DeviceFault, DeviceInfo, Sample};

/// The longest plant integration step, ns (as the simulator's).
const PLANT_STEP_NS: u64 = coop_model::sim::PLANT_STEP_NS;

/// The simulated arm and hand.
#[derive(Debug, Clone)]
pub struct SimScara {
    plant: Plant,
    script: Vec<Keyframe>,
    /// A participant instead of the script (which then only placed the hand at the start).
    person: Option<Box<Participant>>,
    start_ns: Option<u64>,
    plant_ns: u64,
    tau: Vec3,
    force_loop: ScaraForceLoop,
    gain: f64,
    last_command_ns: u64,
    f_command: Vec3,
    info: DeviceInfo,
}

impl SimScara {
    /// A simulated device whose script's time 0 is `start_ns`; its plant starts then too.
    pub fn new(
        plant: Plant,
        force_loop: ScaraForceLoop,
        script: Vec<Keyframe>,
        start_ns: u64,
    ) -> Self {
        let mut d = Self::waiting(plant, force_loop, script, start_ns);
        d.start_ns = Some(start_ns);
        d
    }

    /// A simulated device whose hand holds the script's first pose until [`SimScara::start_at`]
    /// gives the script's time 0 (a station waiting for its session to start); its plant starts at
    /// `now_ns`.
    pub fn waiting(
        plant: Plant,
        force_loop: ScaraForceLoop,
        script: Vec<Keyframe>,
        now_ns: u64,
    ) -> Self {
        let arm = force_loop.arm;
        let info = DeviceInfo {
            backend: "sim",
            model: "SCARA (simulated)".into(),
            serial: None,
            dof: 3,
            max_force_n: force_loop.params.max_force_n,
            // The plant is integrated in 100 µs steps under a ≥ 500 Hz servo; these bound what
            // it renders without ringing (the committed scenarios use 2 kN/m and 3 N·s/m).
            max_stiffness_n_per_m: 10_000.0,
            max_damping_n_s_per_m: 100.0,
            workspace_radius_m: arm.link1_m + arm.link2_m,
            native_rate_hz: 1e9 / PLANT_STEP_NS as f64,
            senses_force: true,
        };
        Self {
            plant,
            script,
            person: None,
            start_ns: None,
            plant_ns: now_ns,
            tau: Vec3::zeros(),
            force_loop,
            gain: 1.0,
            last_command_ns: now_ns,
            f_command: Vec3::zeros(),
            info,
        }
    }

    /// The hand is `person`, acting on what the site shows (given by [`CartesianDevice::observe`]
    /// each servo tick), instead of the script.
    #[must_use]
    pub fn with_participant(mut self, person: Participant) -> Self {
        self.person = Some(Box::new(person));
        self
    }

    /// The participant, if the hand is one.
    pub fn participant(&self) -> Option<&Participant> {
        self.person.as_deref()
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

    /// The joint torques it applies, clamped.
    pub fn tau(&self) -> Vec3 {
        self.tau
    }

    /// The handle force its PI loop commanded last, N.
    pub fn f_command(&self) -> Vec3 {
        self.f_command
    }
}

impl CartesianDevice for SimScara {
    fn info(&self) -> &DeviceInfo {
        &self.info
    }

    fn sample(&mut self, now_ns: u64) -> Result<Sample, DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        while self.plant_ns < now_ns {
            let step = (now_ns - self.plant_ns).min(PLANT_STEP_NS);
            let t = self.start_ns.map_or(0.0, |s| {
                (self.plant_ns + step).saturating_sub(s) as f64 * 1e-9
            });
            let (target, vel) = match &self.person {
                Some(p) => p.target(t),
                None => target_at(&self.script, t),
            };
            self.plant.step(self.tau, target, vel, step as f64 * 1e-9);
            self.plant_ns += step;
        }
        let arm = &self.force_loop.arm;
        Ok(Sample {
            t_ns: self.plant_ns,
            position_m: arm.forward(&self.plant.q),
            velocity_m_s: arm.jacobian(&self.plant.q) * self.plant.qd,
            orientation: None,
            buttons: 0,
            force_sensed_n: Some(self.plant.grip_force),
        })
    }

    fn command(&mut self, now_ns: u64, cmd: Command) -> Result<(), DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let dt = now_ns.saturating_sub(self.last_command_ns).max(1) as f64 * 1e-9;
        self.last_command_ns = now_ns;
        let (f, gain) = match cmd {
            Command::Force(f) => (f, self.gain),
            // Motors off: the loop runs with no output (its integral forgotten).
            Command::Release => (Vec3::zeros(), 0.0),
        };
        let (f_command, tau) =
            self.force_loop
                .step(f, gain, self.plant.grip_force, &self.plant.q, dt);
        self.f_command = f_command;
        self.tau = tau;
        Ok(())
    }

    fn set_output_gain(&mut self, gain: f64) {
        self.gain = gain.clamp(0.0, 1.0);
    }

    fn observe(&mut self, view: &View) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        if let Some(p) = &mut self.person {
            p.perceive(view);
        }
    }

    fn close(&mut self) {
        self.tau = Vec3::zeros();
        self.f_command = Vec3::zeros();
    }
}
