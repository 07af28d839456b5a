//! The servo loop's body, in Cartesian space: sample the device (through the safety layer), place
//! the tool in the world, take the newest object state from physics, run the model's servo step
//! (contact Eq. 7, displayed force Eq. 6, stale ramp, display continuity and passivity), command the force in
//! the device's frame (through the safety layer, which releases on a stale world or a stop), send
//! the tool sample to physics, publish statistics. From the session's time 0, what the site shows
//! and the tool feels goes to the device (a simulated participant acts on it) and to the task's
//! live judge, as in the simulator's servo tick. The periodic timer and scheduling around it
//! belong to the station's servo process.

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::ContactForce;
use coop_model::servo::{Servo, ServoInput};
use coop_model::task::{TaskJudge, View};
use coop_model::world::{World, MAX_OBJECTS};

use crate::device::safety::{Guarded, Trip};
use crate::device::{CartesianDevice, Placement};
use crate::msg::{ObjectSample, ToolSample};
use crate::shm::control::{record_counted, ControlBlock, Ring, RunState, TaskState};
use crate::shm::{Consumer, Producer};

/// What one servo tick did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoTick {
    /// Desired force at the hand F_h (after the stale ramp and the adoption blend), world, N.
    pub f_desired: Vec3,
    /// The force commanded to the device after the safety layer, world, N (zero when released).
    pub f_command: Vec3,
    /// The force the device senses on the hand, world, N (zero without a sensor).
    pub f_measured: Vec3,
    /// The tool's contact on each object (force on the object), for physics; past the world's
    /// objects, none.
    pub contacts: [ContactForce; MAX_OBJECTS],
    /// Tool position, world.
    pub tool_pos: Vec3,
    /// Tool velocity, world.
    pub tool_vel: Vec3,
    /// Display scale: 1 fresh, 0 stale.
    pub scale: f64,
}

/// Everything one servo loop owns.
#[derive(Debug)]
pub struct ServoLoop<D: CartesianDevice> {
    servo: Servo,
    device: Guarded<D>,
    placement: Placement,
    /// The last good sample's tool position and velocity (world) and sensed force (device frame):
    /// kept through a faulty sample, while the device is released.
    last_tool: (Vec3, Vec3, Vec3),
    world: World,
    objects: Consumer<ObjectSample>,
    tools: Producer<ToolSample>,
    /// The world's objects (fixed at start).
    n: usize,
    /// The newest state of each object, and the time and adoption count of the newest sample.
    states: [BodyState; MAX_OBJECTS],
    latest: Option<(u64, u64)>,
    /// The objects whose state has come since the start (all of them: the world is fresh).
    have: u64,
    seq: u64,
    last_ns: u64,
    /// Tool samples dropped because physics did not keep up.
    pub dropped: u64,
    limp: bool,
    stale_state_ns: Option<u64>,
    stale_limp_recorded: bool,
    last_roundtrip_tool_ns: u64,
    /// The newest partner report's time the displayed states were computed with, ns.
    last_remote_ns: u64,
    /// The task's live judge (none: the scenario has no `[task]`).
    task: Option<TaskJudge>,
    /// The session's time 0, once known: the task and a simulated hand run from it.
    t0_ns: Option<u64>,
    /// The task's outcome last published (none yet): published again only when it changes.
    published_task: Option<coop_model::task::Outcome>,
    /// The study's trial this loop runs (0: none, a station not started for a study). A later
    /// one asked for in the control block, or this one's end, ramps the force to zero as a stop
    /// does.
    trial: u64,
}

impl<D: CartesianDevice> ServoLoop<D> {
    /// A servo loop over `device` placed in the world by `placement`, reading object states from
    /// `objects`, sending tool samples on `tools`.
    pub fn new(
        servo: Servo,
        device: Guarded<D>,
        placement: Placement,
        world: World,
        objects: Consumer<ObjectSample>,
        tools: Producer<ToolSample>,
        start_ns: u64,
    ) -> Self {
        Self {
            servo,
            device,
            placement,
            last_tool: (Vec3::new(1e3, 1e3, 1e3), Vec3::zeros(), Vec3::zeros()),
            n: world.bodies().len().clamp(1, MAX_OBJECTS),
            world,
            objects,
            tools,
            states: [BodyState::at_rest(Vec3::new(1e3, 1e3, 1e3)); MAX_OBJECTS],
            latest: None,
            have: 0,
            seq: 0,
            last_ns: start_ns,
            dropped: 0,
            limp: false,
            stale_state_ns: None,
            stale_limp_recorded: false,
            last_roundtrip_tool_ns: 0,
            last_remote_ns: 0,
            task: None,
            t0_ns: None,
            published_task: None,
            trial: 0,
        }
    }

    /// The study's trial this loop runs (0: none).
    pub fn trial(&self) -> u64 {
        self.trial
    }

    /// Runs trial `trial` from now on: `servo`, `world` and `task` are the trial's, the device
    /// and rings are kept, and every object state physics sent before (of the last trial: it
    /// produces nothing more once it has stopped for this one) is dropped. The display starts
    /// ramped out and ramps in once the new world is fresh (the hand may be anywhere in it).
    /// Until its time 0 ([`ServoLoop::start_at`]) nothing is shown to a simulated hand or judged.
    /// Not real-time.
    pub fn begin_trial(
        &mut self,
        trial: u64,
        servo: Servo,
        world: World,
        task: Option<TaskJudge>,
        now_ns: u64,
    ) {
        while self.objects.pop().is_ok() {}
        self.servo = servo.ramped_out();
        self.n = world.bodies().len().clamp(1, MAX_OBJECTS);
        self.world = world;
        self.states = [BodyState::at_rest(Vec3::new(1e3, 1e3, 1e3)); MAX_OBJECTS];
        self.latest = None;
        self.have = 0;
        self.last_ns = now_ns;
        self.limp = false;
        self.stale_state_ns = None;
        self.stale_limp_recorded = false;
        self.last_remote_ns = 0;
        self.task = task;
        self.t0_ns = None;
        self.published_task = None;
        self.trial = trial;
    }

    /// Judges `task` live on what this site shows, from the session's time 0.
    pub fn set_task(&mut self, task: Option<TaskJudge>) {
        self.task = task;
    }

    /// The session's time 0: from then on each tick's view goes to the device and the task.
    pub fn start_at(&mut self, t0_ns: u64) {
        self.t0_ns = Some(t0_ns);
    }

    /// Whether the session's time 0 is known.
    pub fn started(&self) -> bool {
        self.t0_ns.is_some()
    }

    /// The task's judge, if the scenario has a task.
    pub fn task(&self) -> Option<&TaskJudge> {
        self.task.as_ref()
    }

    /// The device (setup only: the tick goes through the safety layer).
    pub fn device_mut(&mut self) -> &mut D {
        self.device.device_mut()
    }

    /// The device under its safety layer.
    pub fn guarded(&self) -> &Guarded<D> {
        &self.device
    }

    /// The device under its safety layer, mutably.
    pub fn guarded_mut(&mut self) -> &mut Guarded<D> {
        &mut self.device
    }

    /// One tick at `now_ns`. While the station is stopping (per `control`), the displayed force and the
    /// command ramp to zero as for a stale world; [`ServoLoop::is_limp`] says when they got there.
    pub fn step(&mut self, now_ns: u64, control: Option<&ControlBlock>) -> ServoTick {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls but clock_nanosleep (outside).
        let mut adopted = false;
        // The newest state's time and its newest partner report's, for the pipeline's figures.
        let (mut newest_state_ns, mut newest_remote_ns) = (None, self.last_remote_ns);
        // Every object's newest state (physics sends each of them every step).
        while let Ok(n) = self.objects.pop() {
            newest_state_ns = newest_state_ns.max(Some(n.t_ns));
            newest_remote_ns = newest_remote_ns.max(n.remote_t_ns);
            // The round trip of the tool sample this state was computed with, once per tool sample.
            if n.tool_t_ns > self.last_roundtrip_tool_ns && n.tool_t_ns <= now_ns {
                self.last_roundtrip_tool_ns = n.tool_t_ns;
                if let Some(c) = control {
                    let sv = &c.servo;
                    record_counted(&sv.roundtrip, &sv.roundtrip_count, now_ns - n.tool_t_ns);
                }
            }
            if let (Some(state), Some(k)) = (n.state(), n.object()) {
                if k < self.n {
                    adopted |= self.latest.is_some_and(|(_, a)| a != n.adoptions);
                    self.states[k] = state;
                    self.have |= 1 << k;
                    // The world is as fresh as its stalest object.
                    if self.have == (1 << self.n) - 1 && k == self.n - 1 {
                        self.latest = Some((n.t_ns, n.adoptions));
                    }
                }
            }
        }
        if let Some(c) = control {
            let sv = &c.servo;
            if let Some(w) = newest_state_ns.and_then(|t| now_ns.checked_sub(t)) {
                record_counted(&sv.state_wait, &sv.state_wait_count, w);
            }
            if newest_remote_ns > self.last_remote_ns && newest_remote_ns <= now_ns {
                let w = now_ns - newest_remote_ns;
                record_counted(&sv.remote_display, &sv.remote_display_count, w);
            }
        }
        self.last_remote_ns = newest_remote_ns;
        if let Ok(s) = self.device.sample(now_ns) {
            self.last_tool = (
                self.placement.position_to_world(s.position_m),
                self.placement.velocity_to_world(s.velocity_m_s),
                s.force_sensed_n.unwrap_or_default(),
            );
        }
        let (tool_pos, tool_vel, f_sensed) = self.last_tool;
        let dt = (now_ns.saturating_sub(self.last_ns)).max(1) as f64 * 1e-9;
        self.last_ns = now_ns;
        // No state yet: the world is stale from the start (the display stays at zero).
        let t_ns = self.latest.map_or(0, |(t, _)| t);
        let out = self.servo.step(
            &ServoInput {
                now_s: now_ns as f64 * 1e-9,
                dt_s: dt,
                tool_pos,
                tool_vel,
                objects: &self.states[..self.n],
                object_time_s: t_ns as f64 * 1e-9,
                adopted,
                // A stop, the next trial, or the end of this one: ramp to zero and go limp.
                stopping: control.is_some_and(|c| {
                    c.run_state() == RunState::Stopping
                        || c.trial.requested() > self.trial
                        || c.trial.is_ended(self.trial)
                }),
            },
            &self.world.bodies()[..self.n],
        );
        let f_device = self.placement.force_to_device(out.f_desired);
        let f_command = self.device.display(now_ns, f_device, out.scale);
        self.show(now_ns, &out.contacts, tool_pos, control);
        // Back to the world for the record (the identity placement computes nothing).
        let (f_command, f_measured) = if self.placement.is_identity() {
            (f_command, f_sensed)
        } else {
            let p = &self.placement;
            (p.force_to_world(f_command), p.force_to_world(f_sensed))
        };
        self.seq += 1;
        let a = |v: coop_model::body::Vec3| [v.x, v.y, v.z];
        let mut sample = ToolSample {
            t_ns: now_ns,
            seq: self.seq,
            tool_pos: a(out.tool_pos),
            tool_vel: a(out.tool_vel),
            f_desired: a(out.f_desired),
            f_measured: a(f_measured),
            f_command: a(f_command),
            ..ToolSample::default()
        };
        sample.set_contacts(&out.contacts[..self.n]);
        if self.tools.push(sample).is_err() {
            self.dropped += 1;
            if let Some(c) = control {
                c.servo.drops.set(Ring::Tool, self.dropped);
            }
        }
        // Record stale episodes: when the newest state was, and when the command reached zero.
        let stale = now_ns.saturating_sub(t_ns) as f64 * 1e-9 > self.servo.params.stale_limit_s;
        if stale && self.stale_state_ns != Some(t_ns) {
            self.stale_state_ns = Some(t_ns);
            self.stale_limp_recorded = false;
            if let Some(c) = control {
                c.servo
                    .stale_state_ns
                    .store(t_ns, crate::sync::Ordering::Relaxed);
                c.servo
                    .stale_limp_ns
                    .store(0, crate::sync::Ordering::Relaxed);
            }
        }
        if stale && !self.stale_limp_recorded && f_command.norm() == 0.0 {
            self.stale_limp_recorded = true;
            if let Some(c) = control {
                c.servo
                    .stale_limp_ns
                    .store(now_ns, crate::sync::Ordering::Relaxed);
            }
        }
        if let Some(c) = control {
            ControlBlock::store_f64(&c.servo.command_n, f_command.norm());
            ControlBlock::store_f64(&c.servo.scale, out.scale);
            if let Some(t) = self.device.last_trip() {
                publish_trip(c, t);
            }
            publish_display(c, self.servo.display_stats());
        }
        self.limp = out.scale == 0.0;
        ServoTick {
            f_desired: out.f_desired,
            f_command,
            f_measured,
            contacts: out.contacts,
            tool_pos,
            tool_vel,
            scale: out.scale,
        }
    }

    /// What the user is shown and feels at `now_ns` (the objects as they are displayed, the own
    /// tool at `tool_pos` and its `contacts`), for a simulated hand and the task, as the
    /// simulator's servo tick gives them: from the session's time 0, once the world is fresh.
    fn show(
        &mut self,
        now_ns: u64,
        contacts: &[ContactForce; MAX_OBJECTS],
        tool_pos: coop_model::body::Vec3,
        control: Option<&ControlBlock>,
    ) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let Some(t0) = self
            .t0_ns
            .filter(|&t0| now_ns >= t0 && self.latest.is_some())
        else {
            return;
        };
        let view = View::of(
            (now_ns - t0) as f64 * 1e-9,
            &self.states[..self.n],
            &contacts[..self.n],
            tool_pos,
        );
        self.device.device_mut().observe(&view);
        if let Some(j) = &mut self.task {
            j.judge(&view);
            let o = j.outcome();
            if let Some(c) = control.filter(|_| self.published_task != Some(o)) {
                publish_task(c, o);
                self.published_task = Some(o);
            }
        }
    }

    /// Releases and closes the device (the station stopped or the servo exits).
    pub fn close(&mut self, now_ns: u64) {
        self.device.close(now_ns);
    }

    /// Whether the last tick displayed and commanded nothing (scale 0): safe to exit on a stop.
    pub fn is_limp(&self) -> bool {
        self.limp
    }

    /// The device.
    pub fn device(&self) -> &D {
        self.device.device()
    }
}

/// Publishes the safety layer's last trip in the control block's servo group.
pub fn publish_trip(c: &ControlBlock, t: Trip) {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    use crate::sync::Ordering::Relaxed;
    let s = &c.servo;
    if s.safety_at_ns.load(Relaxed) != t.at_ns || s.safety_limit.load(Relaxed) != t.limit.code() {
        s.safety_limit.store(t.limit.code(), Relaxed);
        s.safety_at_ns.store(t.at_ns, Relaxed);
        s.safety_episodes.store(t.episodes, Relaxed);
    }
}

/// Publishes the task's outcome in the control block's task group.
pub fn publish_task(c: &ControlBlock, o: coop_model::task::Outcome) {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    use coop_model::task::Outcome;
    let (state, at_s, by) = match o {
        Outcome::Running => (TaskState::Running, 0.0, 0),
        Outcome::Done(at) => (TaskState::Done, at, 0),
        Outcome::Failed(at, None) => (TaskState::Failed, at, 0),
        Outcome::Failed(at, Some(k)) => (TaskState::Failed, at, k as u64 + 1),
    };
    c.task.publish(state, at_s, by);
}

/// Publishes the display stages' figures in the control block's servo group.
pub fn publish_display(c: &ControlBlock, d: &coop_model::display::DisplayStats) {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    use crate::sync::Ordering::Relaxed;
    let s = &c.servo.display;
    s.corrections.store(d.corrections, Relaxed);
    s.ticks_limited.store(d.ticks_limited, Relaxed);
    ControlBlock::store_f64(&s.max_step_n, d.max_step_n);
    ControlBlock::store_f64(&s.max_correction_step_n, d.max_correction_step_n);
    s.ticks_damped.store(d.ticks_damped, Relaxed);
    ControlBlock::store_f64(&s.max_damping_n_s_per_m, d.max_damping_n_s_per_m);
    ControlBlock::store_f64(&s.energy_j, d.energy_j);
    ControlBlock::store_f64(&s.max_energy_j, d.max_energy_j);
}
