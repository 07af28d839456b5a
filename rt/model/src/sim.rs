//! The deterministic multi-site simulator.
//!
//! N sites, each with its own plant (SCARA arm + scripted hand, or a recorded hand driving the tool by
//! position), servo, physics and report timers at
//! their own rates, and its own copy of the object kept by a consistency method; a virtual network
//! between every ordered pair of sites with delay (swinging between a minimum and a maximum), jitter,
//! loss and the reordering jitter causes, all drawn from seeded generators.
//!
//! **Virtual time** is an integer count of nanoseconds, so event order never depends on float
//! rounding. At each instant events run in a fixed order — deliveries (by send order), then per site
//! in index order: physics, servo — and plants are integrated up to the instant in sub-steps
//! of at most [`PLANT_STEP_NS`]. Same scenario and seed ⇒ the same floating-point operations in the
//! same order ⇒ byte-identical traces.
//!
//! **As a station runs it.** A site's method is stepped by the same [`SiteDrive`] a station's
//! physics loop steps it with: what arrived is handed over at the next physics tick (site reports,
//! then tool tracks, each in arrival order, as a station's two rings hold them), the tick takes
//! the own tool as the servo last sampled it, and the site reports at the first tick at or after
//! its report time. What a site puts goes through a [`Wire`] (the stations' codec in the `sim`
//! tool; [`Direct`] in the model's tests), each message (a state, a track) taking its own chance
//! on each link.
//!
//! **Reference run** ([`Mode::Reference`]): the same sites, devices and scripts, but one shared object
//! with every user's contact summed at once (Eq. 8 without delay), integrated at the fastest site's
//! physics rate: the "truth" the methods are measured against.

mod hand;
mod probe;
mod wire;

pub use probe::ProbedTick;
pub use wire::{Carried, Direct, Wire};

use std::collections::VecDeque;

use crate::body::{BodyState, Vec3};
use crate::contact::ContactForce;
use crate::device::{Plant, ScaraForceLoop};
use crate::drive::{ns_to_s, Put, SiteDrive, ToolAt};
use crate::link::DueQueue;
use crate::method::{integrate, Consistency, EnergyAccount, Report, WorldCopy};
use crate::rng::Rng;
use crate::scenario::{LinkSpec, MethodName, Scenario};
use crate::servo::{Servo, ServoInput};
use crate::world::{World, MAX_OBJECTS, MAX_SITES};
use hand::Hand;
pub use hand::SiteTask;

/// Largest plant integration step: 100 µs (the grip spring's period is ~20 ms).
pub const PLANT_STEP_NS: u64 = 100_000;

/// What to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Each site its own copy, kept by this method.
    Distributed(MethodName),
    /// One shared object, all forces summed at once, no network.
    Reference,
}

impl Mode {
    /// Its name in tables and files.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Distributed(m) => m.as_str(),
            Mode::Reference => "reference",
        }
    }
}

/// One site's trace: rows at the scenario's sample rate.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SiteTrace {
    /// Object centre of mass as this site believes it, m.
    pub obj_pos: Vec<Vec3>,
    /// Object velocity as this site believes it, m/s.
    pub obj_vel: Vec<Vec3>,
    /// Object orientation as this site believes it (unit quaternion w, x, y, z).
    pub obj_rot: Vec<[f64; 4]>,
    /// Tool position, m.
    pub tool_pos: Vec<Vec3>,
    /// Desired force at the hand F_h, N.
    pub f_desired: Vec<Vec3>,
    /// Measured force F_m, N.
    pub f_measured: Vec<Vec3>,
    /// Sum of the users' contact forces acting on this site's copy, N.
    pub f_on_object: Vec<Vec3>,
    /// Whether this site's user touches an object.
    pub touching: Vec<bool>,
    /// Which objects this site's user touches, bit `k` for object `k` (empty: not known per
    /// object, as in a station's recording of a one-object world: [`SiteTrace::touches`]).
    pub touched: Vec<u16>,
    /// The world's other objects (the second on), as this site believes them.
    pub others: Vec<ObjectTrace>,
    /// The messages this site put, as a station puts them: site reports (states, forces) and
    /// tool tracks (a `coupled` report with its tools is one of each).
    pub puts: [u64; 2],
    /// Their bytes, as the [`Wire`] the run was given put them (0 with [`Direct`]).
    pub sent_bytes: u64,
}

impl SiteTrace {
    /// Object `k`'s positions (the world's order; 0 is the first), m.
    pub fn object_pos(&self, k: usize) -> &[Vec3] {
        match k {
            0 => &self.obj_pos,
            _ => &self.others[k - 1].pos,
        }
    }

    /// Whether this site's user touches object `k` at sample `i`.
    pub fn touches(&self, k: usize, i: usize) -> bool {
        match self.touched.get(i) {
            Some(bits) => bits & (1 << k) != 0,
            None => k == 0 && self.touching[i],
        }
    }

    /// How many objects it traces.
    pub fn objects(&self) -> usize {
        1 + self.others.len()
    }
}

/// One object's trace at a site: rows at the scenario's sample rate.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ObjectTrace {
    /// Centre of mass, m.
    pub pos: Vec<Vec3>,
    /// Velocity, m/s.
    pub vel: Vec<Vec3>,
    /// Orientation (unit quaternion w, x, y, z).
    pub rot: Vec<[f64; 4]>,
}

/// A site adopted a received state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdoptionEvent {
    /// When, s.
    pub t_s: f64,
    /// Adopting site.
    pub site: usize,
    /// Sender.
    pub from: usize,
    /// Position jump (before − after), m.
    pub jump_m: f64,
    /// How far the state was dead-reckoned, s.
    pub age_s: f64,
    /// Change of the displayed force at the next servo tick, N.
    pub force_step_n: f64,
    /// Mechanical energy the adoption gave the copy (negative: took), J; NaN if not known.
    pub energy_j: f64,
    /// The part of it the forces' work in the corrected history accounts for
    /// ([`crate::method::Adoption::work_j`]), J; NaN if not known.
    pub work_j: f64,
    /// Energy the no-gain bound took out of it ([`crate::method::tank`]), J; 0: it fitted; NaN if not known.
    pub clipped_j: f64,
}

/// One site's displayed-force steps, counted at every servo tick (the traces are sampled slower).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ForceSteps {
    /// Servo ticks counted (0: not measured, e.g. a station's recording).
    pub servo_ticks: u64,
    /// The largest |ΔF_h| from one servo tick to the next, N.
    pub max_step_n: f64,
    /// Ticks whose step exceeded the just-noticeable difference
    /// ([`crate::perception::force_jnd_n`] of the force before the step).
    pub over_jnd: u64,
    /// What the servo's display stages did ([`crate::display`]; default: not measured).
    pub display: crate::display::DisplayStats,
}

impl ForceSteps {
    /// Counts one servo tick's step from `before` to `after`, N.
    pub fn record(&mut self, before: Vec3, after: Vec3) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let step = (after - before).norm();
        self.servo_ticks += 1;
        self.max_step_n = self.max_step_n.max(step);
        if step > crate::perception::force_jnd_n(before.norm()) {
            self.over_jnd += 1;
        }
    }
}

/// Everything a run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct RunResult {
    /// What ran.
    pub mode: Mode,
    /// Sample times, s.
    pub t: Vec<f64>,
    /// Per site.
    pub sites: Vec<SiteTrace>,
    /// Adoptions, in time order.
    pub adoptions: Vec<AdoptionEvent>,
    /// Energy account per site at the end.
    pub energy: Vec<EnergyAccount>,
    /// Mechanical energy per site at the start and end, J.
    pub mech_energy: Vec<(f64, f64)>,
    /// Messages sent, delivered, lost.
    pub messages: (u64, u64, u64),
    /// Per site, for a method that rolls back: its rollbacks, depth, fallbacks, hash checks.
    pub rollback: Vec<Option<crate::method::RollbackStats>>,
    /// Per site: the displayed-force steps of every servo tick.
    pub force_steps: Vec<ForceSteps>,
    /// Per site: every servo tick's tool position and displayed force (kept only by
    /// [`run_keeping_servo_ticks`]; empty otherwise).
    pub servo_ticks: Vec<Vec<ServoTick>>,
    /// Puts a receiver's decoding refused ([`Carried::Refused`]).
    pub refused: u64,
    /// Each site's task and participant figures.
    pub tasks: Vec<SiteTask>,
    /// Whether the scenario has a `[task]` (else every outcome is `Running`).
    pub task: bool,
}

/// One servo tick of a site, as kept by [`run_keeping_servo_ticks`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoTick {
    /// When, s.
    pub t_s: f64,
    /// The tool's position, m.
    pub tool_pos: Vec3,
    /// The displayed force F_h, N.
    pub f_desired: Vec3,
    /// The tool's deepest penetration into an object as the copy has it, m (0: it touches none).
    /// Times the contact stiffness it is the normal force's elastic part; the rest of the contact
    /// force is the normal damping and friction (and F_h is that after the display's stages).
    pub depth_m: f64,
}

impl RunResult {
    /// A run of `mode` with nothing recorded yet.
    pub fn empty(mode: Mode) -> Self {
        Self {
            mode,
            t: Vec::new(),
            sites: Vec::new(),
            adoptions: Vec::new(),
            energy: Vec::new(),
            mech_energy: Vec::new(),
            messages: (0, 0, 0),
            rollback: Vec::new(),
            force_steps: Vec::new(),
            servo_ticks: Vec::new(),
            refused: 0,
            tasks: Vec::new(),
            task: false,
        }
    }
}

/// A message in flight.
#[derive(Debug, Clone, Copy)]
struct InFlight {
    from: usize,
    to: usize,
    msg: Report,
}

/// Messages a probed site took at a tick: (sender, report), in arrival order.
type Received = Vec<(usize, Report)>;

/// What arrived at a site since its last physics tick, as a station's two rings hold it.
#[derive(Debug, Default)]
struct Inbox {
    /// Site reports: (sender, report), in arrival order.
    states: VecDeque<(usize, Report)>,
    /// Tool tracks, in arrival order.
    tracks: VecDeque<(usize, Report)>,
}

struct Site {
    plant: Plant,
    plant_ns: u64,
    /// The script or the participant the hand follows.
    hand: Hand,
    /// The site's task, judged live on what it shows.
    task: Option<crate::task::TaskJudge>,
    servo: Servo,
    force_loop: ScaraForceLoop,
    /// A recorded hand driving the tool by position, instead of the plant.
    replay: Option<crate::replay::Trajectory>,
    tau: Vec3,
    /// The own tool's contact with each object, from the last servo tick.
    own: [ContactForce; MAX_OBJECTS],
    /// The own tool at the last servo tick (what a station's physics is given).
    sampled_tool: ToolAt,
    /// The method and the site's copy, stepped as a station's physics loop steps them.
    drive: SiteDrive,
    /// What arrived since the last physics tick.
    inbox: Inbox,
    noise: Rng,
    period_servo: u64,
    period_physics: u64,
    next_servo: u64,
    next_physics: u64,
    pending_adoptions: Vec<usize>,
    last_f_desired: Vec3,
    last_f_measured: Vec3,
    sensor_noise: f64,
    force_steps: ForceSteps,
    /// Every servo tick's tool position and F_h, when kept.
    servo_ticks: Option<Vec<ServoTick>>,
}

impl Site {
    /// The tool's position at `t_ns`: the arm's handle, or the recorded hand.
    fn tool_pos(&self, t_ns: u64) -> Vec3 {
        match &self.replay {
            Some(r) => r.at(ns_to_s(t_ns)).0,
            None => self.force_loop.arm.forward(&self.plant.q),
        }
    }
}

/// A rate's period in the simulator's whole nanoseconds (at least 1).
pub fn period_ns(rate_hz: f64) -> u64 {
    ((1e9 / rate_hz).round() as u64).max(1)
}

/// Site `i`'s method in `mode`, built by [`Scenario::method`] as a station's is (the reference
/// run's one shared copy is stepped by `paper`: with one copy, no report is ever adopted).
pub fn site_method(scenario: &Scenario, mode: Mode, i: usize) -> Box<dyn Consistency> {
    match mode {
        Mode::Distributed(name) => scenario.method(i, name),
        Mode::Reference => scenario.method(i, MethodName::Paper),
    }
}

/// Runs `scenario` in `mode`, its puts handed over [`Direct`]ly. `progress(fraction)` is called
/// about a hundred times.
///
/// The scenario must be valid ([`Scenario::validate`]).
pub fn run(scenario: &Scenario, mode: Mode, progress: &mut dyn FnMut(f64)) -> RunResult {
    run_wired(scenario, mode, progress, &Direct)
}

/// [`run`], every put carried by `wire` ([`SiteTrace::sent_bytes`] is what it put).
pub fn run_wired(
    scenario: &Scenario,
    mode: Mode,
    progress: &mut dyn FnMut(f64),
    wire: &dyn Wire,
) -> RunResult {
    drive(Run::new(scenario, mode), scenario, progress, wire)
}

/// [`run_wired`], keeping every servo tick's tool position and displayed force too
/// ([`RunResult::servo_ticks`]).
pub fn run_keeping_servo_ticks(
    scenario: &Scenario,
    mode: Mode,
    progress: &mut dyn FnMut(f64),
    wire: &dyn Wire,
) -> RunResult {
    let mut run = Run::new(scenario, mode);
    for (s, spec) in run.sites.iter_mut().zip(&scenario.site) {
        let ticks = (scenario.duration_s * spec.servo_rate_hz).ceil() as usize + 1;
        s.servo_ticks = Some(Vec::with_capacity(ticks));
    }
    drive(run, scenario, progress, wire)
}

/// [`run_wired`] in a distributed mode, recording every physics tick of site `site`: what its
/// method was given and what it put ([`ProbedTick`]), to replay through a station's loop.
pub fn run_probing_site(
    scenario: &Scenario,
    mode: Mode,
    site: usize,
    wire: &dyn Wire,
) -> (RunResult, Vec<ProbedTick>) {
    let mut run = Run::new(scenario, mode);
    run.probe = Some((site, Vec::new()));
    drive_to_end(&mut run, scenario, &mut |_| {}, wire);
    let probed = run.probe.take().map(|p| p.1).unwrap_or_default();
    (run.finish(), probed)
}

/// Steps `run` to the end of `scenario`.
fn drive(
    mut run: Run<'_>,
    scenario: &Scenario,
    progress: &mut dyn FnMut(f64),
    wire: &dyn Wire,
) -> RunResult {
    drive_to_end(&mut run, scenario, progress, wire);
    run.finish()
}

/// Steps `run` through every event of `scenario`.
fn drive_to_end(
    run: &mut Run<'_>,
    scenario: &Scenario,
    progress: &mut dyn FnMut(f64),
    wire: &dyn Wire,
) {
    let end_ns = (scenario.duration_s * 1e9).round() as u64;
    let mut next_progress = 0u64;
    loop {
        let t = run.next_event();
        if t > end_ns {
            break;
        }
        if t >= next_progress {
            progress(t as f64 / end_ns.max(1) as f64);
            next_progress = t + end_ns / 100 + 1;
        }
        run.step(t, wire);
    }
    for s in &mut run.sites {
        if let Some(j) = &mut s.task {
            j.finish(scenario.duration_s);
        }
    }
    progress(1.0);
}

/// A run under way: every site, the virtual network between them, and what is recorded so far.
struct Run<'a> {
    reference: bool,
    world: World,
    objects: usize,
    sites: Vec<Site>,
    /// Reference: one shared copy stepped at the fastest physics rate.
    shared: WorldCopy,
    ref_period: u64,
    next_ref: u64,
    /// Per ordered pair of sites `(from, to)`, at `from * n + to`: its link's generator.
    links: Vec<Rng>,
    net: &'a LinkSpec,
    in_flight: DueQueue<InFlight>,
    /// Messages sent, delivered, lost.
    messages: (u64, u64, u64),
    period_sample: u64,
    next_sample: u64,
    result: RunResult,
    /// The world's mechanical energy at the start, J.
    e0: f64,
    /// The site whose physics ticks are recorded, and the record ([`run_probing_site`]).
    probe: Option<(usize, Vec<ProbedTick>)>,
}

impl<'a> Run<'a> {
    /// Every site at its script's first target, nothing sent, nothing recorded.
    fn new(scenario: &'a Scenario, mode: Mode) -> Self {
        let world = scenario.world();
        let start = scenario.start_copy();
        let objects = start.len();
        let sites: Vec<Site> = (0..scenario.site.len())
            .map(|i| {
                let spec = &scenario.site[i];
                let script = scenario.script(i);
                let arm = scenario.arm(i);
                let p0 = script[0].target;
                let mut site = Site {
                    plant: Plant::at(arm, scenario.hand(i), p0, spec.elbow),
                    plant_ns: 0,
                    hand: match scenario.participant(i) {
                        Some(p) => Hand::Person(Box::new(p)),
                        None => Hand::Script(script),
                    },
                    task: scenario.task_judge().ok().flatten(),
                    servo: Servo::new(scenario.servo_params(i)),
                    force_loop: scenario.force_loop(i),
                    replay: spec.hand_trajectory.clone(),
                    tau: Vec3::zeros(),
                    own: [ContactForce::default(); MAX_OBJECTS],
                    sampled_tool: ToolAt::default(),
                    drive: SiteDrive::new(
                        i,
                        site_method(scenario, mode, i),
                        start.clone(),
                        period_ns(spec.report_rate_hz),
                        0,
                        0,
                    ),
                    inbox: Inbox::default(),
                    noise: Rng::derive(scenario.seed, 1000 + i as u64),
                    period_servo: period_ns(spec.servo_rate_hz),
                    period_physics: period_ns(spec.physics_rate_hz),
                    next_servo: 0,
                    next_physics: 0,
                    pending_adoptions: Vec::new(),
                    last_f_desired: Vec3::zeros(),
                    last_f_measured: Vec3::zeros(),
                    sensor_noise: spec.sensor_noise_n,
                    force_steps: ForceSteps::default(),
                    servo_ticks: None,
                };
                // Before the servo's first sample, the tool where the hand starts.
                site.sampled_tool.pos = site.tool_pos(0);
                site
            })
            .collect();
        let n = sites.len();
        // Reference: one shared copy stepped at the fastest physics rate.
        let shared = start.clone();
        let ref_period = sites
            .iter()
            .map(|s| s.period_physics)
            .min()
            .unwrap_or(1_000_000);
        let links: Vec<Rng> = (0..n * n)
            .map(|k| Rng::derive(scenario.seed, k as u64))
            .collect();
        let result = RunResult {
            sites: vec![
                SiteTrace {
                    others: vec![ObjectTrace::default(); objects - 1],
                    ..SiteTrace::default()
                };
                n
            ],
            ..RunResult::empty(mode)
        };
        let e0 = start.mechanical_energy(&world);
        Self {
            reference: mode == Mode::Reference,
            world,
            objects,
            sites,
            shared,
            ref_period,
            next_ref: 0,
            links,
            net: &scenario.network,
            in_flight: DueQueue::new(),
            messages: (0, 0, 0),
            period_sample: period_ns(scenario.sample_rate_hz),
            next_sample: 0,
            result,
            e0,
            probe: None,
        }
    }

    /// The earliest instant anything happens: a sample, a site's timer, a delivery.
    fn next_event(&self) -> u64 {
        let mut t = self.next_sample;
        for s in &self.sites {
            t = t.min(s.next_servo).min(s.next_physics);
        }
        if self.reference {
            t = t.min(self.next_ref);
        }
        if let Some(at_ns) = self.in_flight.next_at() {
            t = t.min(at_ns);
        }
        t
    }

    /// Everything due at `t`, in the fixed order: plants up to now, deliveries, the reference's
    /// shared step, then per site in index order physics (with its reports), servo; then the
    /// sample.
    fn step(&mut self, t: u64, wire: &dyn Wire) {
        self.plants_to(t);
        self.deliver(t);
        if self.reference && self.next_ref == t {
            self.reference_step(t);
        }
        for i in 0..self.sites.len() {
            self.physics(i, t, wire);
            self.servo(i, t);
        }
        if self.next_sample == t {
            self.sample(t);
            self.next_sample += self.period_sample;
        }
    }

    /// Plants up to now.
    fn plants_to(&mut self, t: u64) {
        for s in &mut self.sites {
            while s.replay.is_none() && s.plant_ns < t {
                let step = (t - s.plant_ns).min(PLANT_STEP_NS);
                let mid = ns_to_s(s.plant_ns + step);
                let (target, target_vel) = s.hand.target(mid);
                s.plant.step(s.tau, target, target_vel, ns_to_s(step));
                s.plant_ns += step;
            }
        }
    }

    /// Deliveries: into each receiver's inbox, taken at its next physics tick.
    fn deliver(&mut self, t: u64) {
        // Nothing is due before `t` (it is the earliest event), so due means due now.
        while let Some(m) = self.in_flight.pop_due(t) {
            self.messages.1 += 1;
            let inbox = &mut self.sites[m.to].inbox;
            match m.msg {
                Report::Tools(_) => inbox.tracks.push_back((m.from, m.msg)),
                _ => inbox.states.push_back((m.from, m.msg)),
            }
        }
    }

    /// Hands site `i`'s inbox to its method at its physics tick `t`: site reports, then tracks.
    fn take_inbox(&mut self, i: usize, t: u64) -> (Received, Received) {
        let probing = matches!(self.probe, Some((p, _)) if p == i);
        let s = &mut self.sites[i];
        let mut taken = (Vec::new(), Vec::new());
        let Inbox { states, tracks } = &mut s.inbox;
        for (queue, kept) in [(states, &mut taken.0), (tracks, &mut taken.1)] {
            while let Some((from, msg)) = queue.pop_front() {
                if probing {
                    kept.push((from, msg));
                }
                let Ok(Some(a)) = s.drive.receive(&self.world, from, &msg, t) else {
                    continue;
                };
                s.pending_adoptions.push(self.result.adoptions.len());
                self.result.adoptions.push(AdoptionEvent {
                    t_s: ns_to_s(t),
                    site: i,
                    from,
                    jump_m: a.jump.norm(),
                    age_s: a.age_s,
                    force_step_n: 0.0,
                    energy_j: a.energy_j,
                    work_j: a.work_j,
                    clipped_j: a.clipped_j,
                });
            }
        }
        taken
    }

    /// The reference's one shared copy, every user's contact summed at once.
    fn reference_step(&mut self, t: u64) {
        let (objects, n) = (self.objects, self.sites.len());
        let mut users = [ContactForce::default(); MAX_SITES * MAX_OBJECTS];
        for k in 0..objects {
            for (i, s) in self.sites.iter().enumerate() {
                users[k * n + i] = s.own[k];
            }
        }
        let users = &users[..objects * n];
        integrate(
            &self.world,
            &mut self.shared,
            users,
            n,
            n,
            ns_to_s(self.ref_period),
            &mut [],
        );
        self.shared.set_time(ns_to_s(t));
        self.next_ref += self.ref_period;
    }

    /// Site `i`'s physics tick, if due: what arrived, the step, and the reports due.
    fn physics(&mut self, i: usize, t: u64, wire: &dyn Wire) {
        if self.sites[i].next_physics != t {
            return;
        }
        let period = self.sites[i].period_physics;
        self.sites[i].next_physics += period;
        if self.reference {
            return;
        }
        let (states, tracks) = self.take_inbox(i, t);
        let n = self.sites.len();
        let s = &mut self.sites[i];
        s.drive.tick(&self.world, &s.sampled_tool, t, period);
        let mut puts = Vec::new();
        let (links, in_flight, messages, net) = (
            &mut self.links,
            &mut self.in_flight,
            &mut self.messages,
            self.net,
        );
        let trace = &mut self.result.sites[i];
        let refused = &mut self.result.refused;
        let probing = matches!(self.probe, Some((p, _)) if p == i);
        s.drive.report(t, &mut |put| {
            if probing {
                puts.push(put);
            }
            trace.puts[usize::from(matches!(put, Put::Track(_)))] += 1;
            let msg = match wire.carry(i, t, &put) {
                Carried::Taken { report, bytes } => {
                    trace.sent_bytes += bytes;
                    report
                }
                Carried::Refused { bytes } => {
                    trace.sent_bytes += bytes;
                    *refused += 1;
                    messages.0 += (n - 1) as u64;
                    messages.2 += (n - 1) as u64;
                    return;
                }
            };
            // Each message takes its own chance on each link.
            for to in (0..n).filter(|&to| to != i) {
                messages.0 += 1;
                let Some(delay_ns) = net.transmit(&mut links[i * n + to], ns_to_s(t)) else {
                    messages.2 += 1;
                    continue;
                };
                in_flight.push(t + delay_ns, InFlight { from: i, to, msg });
            }
        });
        if let Some((_, probed)) = self.probe.as_mut().filter(|(p, _)| *p == i) {
            let mut own = [ContactForce::default(); MAX_OBJECTS];
            own[..s.drive.objects()].copy_from_slice(s.drive.own());
            probed.push(ProbedTick {
                t_ns: t,
                period_ns: period,
                tool: s.sampled_tool,
                own,
                states,
                tracks,
                copy: s.drive.copy().clone(),
                puts,
            });
        }
    }

    /// Site `i`'s servo tick, if due: the displayed force, and the arm's force loop.
    fn servo(&mut self, i: usize, t: u64) {
        let objects = self.objects;
        let s = &mut self.sites[i];
        if s.next_servo != t {
            return;
        }
        // A recorded hand has no force sensor.
        let f_measured = if s.replay.is_some() {
            Vec3::zeros()
        } else {
            let noise = Vec3::from_fn(|_, _| s.noise.normal()) * s.sensor_noise;
            s.plant.grip_force + noise
        };
        let copy = if self.reference {
            &self.shared
        } else {
            s.drive.copy()
        };
        // What the user is shown: the copy, or a missed contact replayed (timewarp).
        let mut shown = [BodyState::at_rest(Vec3::zeros()); MAX_OBJECTS];
        for (k, o) in shown.iter_mut().enumerate().take(objects) {
            *o = if self.reference {
                copy.objects()[k].state
            } else {
                s.drive.shown(k)
            };
        }
        let (tool_pos, tool_vel) = match &s.replay {
            Some(r) => r.at(ns_to_s(t)),
            None => {
                let arm = &s.force_loop.arm;
                (
                    arm.forward(&s.plant.q),
                    arm.jacobian(&s.plant.q) * s.plant.qd,
                )
            }
        };
        let out = s.servo.step(
            &ServoInput {
                now_s: ns_to_s(t),
                dt_s: ns_to_s(s.period_servo),
                tool_pos,
                tool_vel,
                objects: &shown[..objects],
                object_time_s: copy.first().time_s,
                adopted: !s.pending_adoptions.is_empty(),
                stopping: false,
            },
            self.world.bodies(),
        );
        let step_n = (out.f_desired - s.last_f_desired).norm();
        for k in s.pending_adoptions.drain(..) {
            self.result.adoptions[k].force_step_n = step_n;
        }
        s.force_steps.record(s.last_f_desired, out.f_desired);
        if let Some(k) = &mut s.servo_ticks {
            k.push(ServoTick {
                t_s: ns_to_s(t),
                tool_pos,
                f_desired: out.f_desired,
                depth_m: out.contacts[..objects].iter().fold(0.0, |d, c| {
                    if c.touching {
                        d.max(c.depth)
                    } else {
                        d
                    }
                }),
            });
        }
        // The arm's own force loop (a recorded hand displays nothing).
        let (_, tau) = s.force_loop.step(
            out.f_desired,
            out.scale,
            f_measured,
            &s.plant.q,
            ns_to_s(s.period_servo),
        );
        s.tau = tau;
        let view = crate::task::View::of(
            ns_to_s(t),
            &shown[..objects],
            &out.contacts[..objects],
            tool_pos,
        );
        hand::tick(&mut s.hand, s.task.as_mut(), &view);
        s.own = out.contacts;
        // What a station's servo puts in its tool sample for physics.
        s.drive.set_own(&out.contacts);
        s.sampled_tool = ToolAt {
            pos: tool_pos,
            vel: tool_vel,
            t_ns: t,
        };
        s.last_f_desired = out.f_desired;
        s.last_f_measured = f_measured;
        s.next_servo += s.period_servo;
    }

    /// A row of every site's trace.
    fn sample(&mut self, t: u64) {
        let objects = self.objects;
        let reference = self.reference;
        let sites = &self.sites;
        self.result.t.push(ns_to_s(t));
        for (i, s) in sites.iter().enumerate() {
            let copy = if reference {
                &self.shared
            } else {
                s.drive.copy()
            };
            let tr = &mut self.result.sites[i];
            let first = &copy.first().state;
            tr.obj_pos.push(first.pos);
            tr.obj_vel.push(first.vel);
            let q = first.rot.quaternion();
            tr.obj_rot.push([q.w, q.i, q.j, q.k]);
            for (o, c) in tr.others.iter_mut().zip(&copy.objects()[1..]) {
                o.pos.push(c.state.pos);
                o.vel.push(c.state.vel);
                let q = c.state.rot.quaternion();
                o.rot.push([q.w, q.i, q.j, q.k]);
            }
            tr.tool_pos.push(s.tool_pos(t));
            tr.f_desired.push(s.last_f_desired);
            tr.f_measured.push(s.last_f_measured);
            tr.touching.push(s.own.iter().any(|c| c.touching));
            let bits = (0..objects).fold(0u16, |b, k| b | (u16::from(s.own[k].touching) << k));
            tr.touched.push(bits);
            let own = |s: &Site| {
                s.own[1..objects]
                    .iter()
                    .fold(s.own[0].force, |a, c| a + c.force)
            };
            let on_object = if reference {
                sites.iter().map(own).sum()
            } else {
                own(s) + s.drive.remote_force()
            };
            tr.f_on_object.push(on_object);
        }
    }

    /// The result: the traces, and per site its energy account, rollbacks and force steps.
    fn finish(self) -> RunResult {
        let Self {
            reference,
            world,
            sites,
            shared,
            mut messages,
            mut result,
            e0,
            ..
        } = self;
        messages.1 = messages.1.min(messages.0);
        result.messages = messages;
        for s in &sites {
            let copy = if reference { &shared } else { s.drive.copy() };
            result.energy.push(
                copy.objects()
                    .iter()
                    .map(|o| o.energy)
                    .reduce(|a, b| a.plus(&b))
                    .unwrap_or_default(),
            );
            result
                .mech_energy
                .push((e0, copy.mechanical_energy(&world)));
            result.rollback.push(s.drive.stats().rollback().copied());
            result.force_steps.push(ForceSteps {
                display: *s.servo.display_stats(),
                ..s.force_steps
            });
            result.tasks.push(hand::figures(&s.hand, s.task.as_ref()));
            result.task |= s.task.is_some();
        }
        if sites.iter().any(|s| s.servo_ticks.is_some()) {
            result.servo_ticks = sites
                .into_iter()
                .map(|s| s.servo_ticks.unwrap_or_default())
                .collect();
        }
        result
    }
}

impl RunResult {
    /// The trace as CSV: one row per sample and site, fixed formatting (byte-identical across runs).
    /// Columns: time, site, object position, tool position, desired force, measured force, sum of the
    /// users' forces on this copy, touching, object velocity, object orientation quaternion.
    pub fn trace_csv(&self) -> String {
        use std::fmt::Write;
        let mut out = String::from(
            "t_s,site,obj_x,obj_y,obj_z,tool_x,tool_y,tool_z,fd_x,fd_y,fd_z,fm_x,fm_y,fm_z,fobj_x,fobj_y,fobj_z,touching,vel_x,vel_y,vel_z,q_w,q_x,q_y,q_z",
        );
        // A world of several objects: each other object's position, velocity and orientation.
        let others = self.sites.first().map_or(0, |s| s.others.len());
        for k in 1..=others {
            for c in ["x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz"] {
                let _ = write!(out, ",obj{k}_{c}");
            }
        }
        out.push('\n');
        for (k, t) in self.t.iter().enumerate() {
            for (i, s) in self.sites.iter().enumerate() {
                let _ = write!(out, "{t:.6},{i}");
                for v in [
                    s.obj_pos[k],
                    s.tool_pos[k],
                    s.f_desired[k],
                    s.f_measured[k],
                    s.f_on_object[k],
                ] {
                    let _ = write!(out, ",{:.9},{:.9},{:.9}", v.x, v.y, v.z);
                }
                let _ = write!(out, ",{}", u8::from(s.touching[k]));
                let (v, q) = (s.obj_vel[k], s.obj_rot[k]);
                let _ = write!(
                    out,
                    ",{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9}",
                    v.x, v.y, v.z, q[0], q[1], q[2], q[3]
                );
                for o in &s.others {
                    let (p, v, q) = (o.pos[k], o.vel[k], o.rot[k]);
                    let _ = write!(
                        out,
                        ",{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9},{:.9}",
                        p.x, p.y, p.z, v.x, v.y, v.z, q[0], q[1], q[2], q[3]
                    );
                }
                out.push('\n');
            }
        }
        out
    }

    /// Adoption events as CSV.
    pub fn adoptions_csv(&self) -> String {
        use std::fmt::Write;
        let mut out = String::from("t_s,site,from,jump_m,age_s,force_step_n\n");
        for a in &self.adoptions {
            let _ = writeln!(
                out,
                "{:.6},{},{},{:.9},{:.6},{:.9}",
                a.t_s, a.site, a.from, a.jump_m, a.age_s, a.force_step_n
            );
        }
        out
    }
}
