//! The station's loop processes, as the supervisor starts them (`station servo|physics`, hidden
//! subcommands of the one `station` binary, so `ps` shows which station a child belongs to).
//!
//! Each child dies with its supervisor (parent-death signal), applies its scheduling (what it lacks
//! the supervisor has said once for the station, then it runs anyway), opens the segments the
//! supervisor created, and runs its loop body under [`coop_rt::run::run_periodic`] until the run
//! state asks it to stop — the servo only once its force has ramped to zero.

use std::time::Duration;

use coop_model::method::{Consistency, ObjectCopy};
use coop_model::scenario::Scenario;
use coop_model::servo::Servo;
use coop_rt::device::safety::{clamp_contact, Guarded};
use coop_rt::device::{CartesianDevice, DevicePublisher};
use coop_rt::physics::{PhysicsLoop, PhysicsRings, PhysicsTiming};
use coop_rt::run::{run_periodic, run_vendor};
use coop_rt::sched::{self, Request};
use coop_rt::servo::ServoLoop;
use coop_rt::shm::control::{Child, ControlBlock, RunState};
use coop_rt::shm::{BlockSegment, Consumer, Producer, RingOpenOptions};
use coop_rt::sync::Ordering;
use coop_rt::timer::monotonic_ns;

use super::config::Resolved;
use super::device::DeviceOpenError;
use super::trials;
use coop_rt::shm::station::Names;

/// Why a loop process could not start or run.
#[derive(Debug, thiserror::Error)]
pub enum ChildError {
    /// The parent-death signal could not be set.
    #[error("setting the parent-death signal")]
    ParentDeathSignal(#[source] nix::Error),
    /// The supervisor died before this child started.
    #[error("the supervisor (pid {parent}) is gone (parent is now {now}); not starting")]
    ParentGone {
        /// The supervisor's pid, as it was given.
        parent: u32,
        /// This process's parent now.
        now: i32,
    },
    /// The session or station name cannot make segment names.
    #[error(transparent)]
    Name(#[from] coop_rt::shm::NameError),
    /// The station's control block does not open.
    #[error(transparent)]
    Control(#[from] coop_rt::shm::OpenError),
    /// One of the station's rings does not open.
    #[error("opening the {ring} ring")]
    Ring {
        /// Which ring.
        ring: &'static str,
        /// Why.
        #[source]
        error: coop_rt::shm::RingOpenError,
    },
    /// The scheduling request can never be honoured.
    #[error(transparent)]
    Sched(#[from] sched::RequestError),
    /// The device does not open.
    #[error(transparent)]
    Device(#[from] DeviceOpenError),
    /// The scenario has no site of this station's index.
    #[error("the scenario has no site {0}")]
    NoSite(usize),
    /// The network process could not be set up or closed.
    #[error(transparent)]
    Network(#[from] coop_transport::network::NetworkError),
    /// The vendor's servo loop (OpenHaptics' scheduler) could not start, or stopped calling back.
    #[error("the device's own servo loop: {0}")]
    VendorLoop(#[from] coop_rt::device::VendorLoopError),
}

impl ChildError {
    /// Whether `station run` says this failure itself: links that fail, which it probes and says
    /// once however often the network process is restarted (see `station::link`); the network
    /// process then exits failing without a word.
    pub fn said_by_the_station(&self) -> bool {
        matches!(
            self,
            Self::Network(coop_transport::network::NetworkError::Link(_))
        )
    }

    /// Whether this failure is one a restart would meet again: the device does not open (no
    /// driver, no service, no library). The servo has written its words into the control block
    /// (`device.open_error`), and the station ends with them instead of restarting it.
    pub fn cannot_start(&self) -> bool {
        matches!(self, Self::Device(_))
    }
}

/// Names the ring a failed open was of.
fn opening(ring: &'static str) -> impl FnOnce(coop_rt::shm::RingOpenError) -> ChildError {
    move |error| ChildError::Ring { ring, error }
}

/// How long a child waits for its supervisor's segments to be ready.
const OPEN_TIMEOUT: Duration = Duration::from_secs(2);

/// Dies with `parent` (SIGTERM on its death) and refuses to start if it is already gone.
///
/// # Errors
/// The signal cannot be set, or `parent` is no longer this process's parent.
pub fn die_with_parent(parent: Option<u32>) -> Result<(), ChildError> {
    nix::sys::prctl::set_pdeathsig(nix::sys::signal::Signal::SIGTERM)
        .map_err(ChildError::ParentDeathSignal)?;
    if let Some(p) = parent {
        let now = nix::unistd::getppid().as_raw();
        if u32::try_from(now).ok() != Some(p) {
            return Err(ChildError::ParentGone { parent: p, now });
        }
    }
    Ok(())
}

/// Pins the calling process's thread (and the threads it starts later) to the housekeeping CPUs.
pub fn keep_off_the_servo(cfg: &Resolved) {
    let req = Request {
        policy: sched::Policy::Other,
        priority: 0,
        cpus: Some(cfg.housekeeping_cpus.clone()),
        prefault_stack_bytes: 0,
    };
    if let Ok((_, warnings)) = sched::apply_to_current_thread(&req) {
        for w in warnings {
            eprintln!("station {}: {w}", cfg.name);
        }
    }
}

/// What every child does first: die with the supervisor, then open the station's control block.
fn attach(
    cfg: &Resolved,
    parent: Option<u32>,
) -> Result<(Names, RingOpenOptions, BlockSegment<ControlBlock>), ChildError> {
    die_with_parent(parent)?;
    let names = Names::of(&cfg.config.session, &cfg.name)?;
    let opts = RingOpenOptions {
        capacity: None,
        ready_timeout: OPEN_TIMEOUT,
    };
    let ctl = BlockSegment::<ControlBlock>::open(&names.control, OPEN_TIMEOUT)?;
    Ok((names, opts, ctl))
}

/// The environment variable through which the supervisor tells its loop processes which missing
/// privileges it has already warned of (the [`sched::Warning::key`]s, comma-separated), so that a
/// station without them says so once, not once per process and privilege.
pub const PRIVILEGES_SAID_ENV: &str = "COOP_PRIVILEGES_SAID";

/// Whether the supervisor has already warned of the privilege of warning `key`.
fn said_by_the_supervisor(key: &str) -> bool {
    std::env::var(PRIVILEGES_SAID_ENV).is_ok_and(|said| said.split(',').any(|k| k == key))
}

/// Applies scheduling and memory locking, printing each missing privilege once (unless the
/// supervisor already did); holds `/dev/cpu_dma_latency` at 0 while the returned guard lives (when
/// configured). What is in force goes to status either way.
fn setup(
    cfg: &Resolved,
    req: &Request,
    child: Child,
) -> Result<(sched::InForce, Option<sched::DmaLatencyGuard>), ChildError> {
    let what = child.name();
    let say = |w: &sched::Warning| {
        if !said_by_the_supervisor(w.key) {
            eprintln!("station {what} {}: {w}", cfg.name);
        }
    };
    if cfg.config.mlockall {
        if let Err(w) = sched::lock_memory() {
            say(&w);
        }
    }
    // Without it the idle governor may halt the CPU between cycles, and every wake-up pays the way
    // back (on this VM's haltpoll: the servo's wake-up p99 was 4x the latency tool's, which holds
    // it as cyclictest does).
    let dma = if cfg.config.cpu_dma_latency_zero {
        match sched::hold_cpu_dma_latency_zero() {
            Ok(g) => Some(g),
            Err(e) => {
                say(&sched::Warning {
                    key: "cpu_dma_latency",
                    message: format!("cannot hold /dev/cpu_dma_latency at 0 ({e}); CPUs may enter deep idle states between cycles. Fix: run as root (or give write access to /dev/cpu_dma_latency)"),
                });
                None
            }
        }
    } else {
        None
    };
    let (in_force, warnings) = sched::apply_to_current_thread(req)?;
    for w in &warnings {
        say(w);
    }
    Ok((in_force, dma))
}

fn period(rate_hz: f64) -> Duration {
    Duration::from_secs_f64(1.0 / rate_hz)
}

/// Runs the servo process of the configured station until a cooperative stop leaves it limp.
///
/// # Errors
/// The segments cannot be opened, or the scheduling request is impossible.
pub fn run_servo(cfg: &Resolved, parent: Option<u32>) -> Result<(), ChildError> {
    let (names, opts, ctl) = attach(cfg, parent)?;
    let objects = Consumer::open(&names.object, &opts).map_err(opening("object"))?;
    let tools = Producer::open(&names.tool, &opts).map_err(opening("tool"))?;
    let i = cfg.site;
    // A study's station restarted in the middle of a trial runs that trial's scenario.
    let (mut trial, trial_sc, refused) = trials::current(cfg, &ctl);
    let (sc, refused) = (&trial_sc, refused.as_str());
    let start = monotonic_ns();
    // A script or a recording runs on the session's clock: a restarted servo picks it up where it
    // is, and a station waiting for its session holds the first pose until the session starts.
    // A restarted servo opens its device afresh and counts from zero: until it has, status shows
    // no device rather than its predecessor's.
    ctl.device.open.store(0, Ordering::Release);
    let mut device = match crate::station::device::open(&cfg.device, sc, i, start) {
        Ok(d) => d,
        Err(e) => {
            // The station ends with these words (see `ChildError::cannot_start`).
            ctl.device.open_error.store_fmt(format_args!("{e}"));
            return Err(e.into());
        }
    };
    if let Some(epoch) = ctl.epoch() {
        device.start_at(epoch);
    }
    // A device whose vendor owns the servo thread (OpenHaptics' scheduler) runs the same step in
    // its callbacks.
    let vendor = device.vendor_loop();
    let dev = &cfg.device;
    let params = servo_params(cfg, sc, device.info());
    let mut guarded = Guarded::new(device, dev.limits, start);
    for l in params.1.into_iter().flatten() {
        guarded.record(l, start);
    }
    let mut servo = ServoLoop::new(
        Servo::new(params.0),
        guarded,
        dev.placement,
        sc.world(),
        objects,
        tools,
        start,
    );
    if trial > 0 {
        let judge = sc.task_judge().ok().flatten();
        servo.begin_trial(trial, Servo::new(params.0), sc.world(), judge, start);
        trials::joined(&ctl, Child::Servo, trial, refused);
        if ctl.epoch().is_none() {
            trials::wait_network(&ctl, Child::Servo, trial);
        }
    }
    // The task is judged on what this site shows, as the simulator judges it (a restarted servo
    // judges it afresh, and a simulated participant starts its plan again).
    // (Validation judged the task's conditions: the scenario has one or none.)
    servo.set_task(sc.task_judge().ok().flatten());
    // This servo's judge starts afresh: no outcome of its predecessor stays shown.
    ctl.task
        .publish(coop_rt::shm::control::TaskState::None, 0.0, 0);
    let mut figures = DevicePublisher::new(&ctl.device, servo.guarded(), start);
    let (in_force, _dma) = setup(cfg, &cfg.servo_sched, Child::Servo)?;
    let mut servo_rate_hz = sc.site[i].servo_rate_hz;
    loop {
        let mut step = |now| {
            if !servo.started() {
                if let Some(epoch) = ctl.epoch() {
                    servo.device_mut().start_at(epoch);
                    servo.start_at(epoch);
                }
            }
            servo.step(now, Some(&ctl));
            figures.publish(&ctl.device, now, servo.guarded());
            match ctl.run_state() {
                // A study's next trial: leave once nothing is displayed or commanded any more.
                RunState::Starting | RunState::Running => {
                    ctl.trial.requested() <= servo.trial() || !servo.is_limp()
                }
                // Stop only once nothing is displayed or commanded any more.
                RunState::Stopping | RunState::Stopped => !servo.is_limp(),
            }
        };
        let ended = match &vendor {
            Some(v) => run_vendor(
                &ctl,
                Child::Servo,
                &ctl.servo.stats,
                &in_force,
                v.as_ref(),
                &mut step,
            )
            .map(|_| ()),
            None => {
                run_periodic(
                    &ctl,
                    Child::Servo,
                    &ctl.servo.stats,
                    period(servo_rate_hz),
                    &in_force,
                    step,
                );
                Ok(())
            }
        };
        if ended.is_err() || !trials::next(&ctl, Child::Servo, &mut trial) {
            // Stopped: release and close the device (dropping it would too, also on an error
            // path).
            let now = monotonic_ns();
            figures.publish_now(&ctl.device, now, servo.guarded());
            servo.close(now);
            return ended.map_err(Into::into);
        }
        // Limp, and physics sends nothing more of the last trial: rebuild for this one.
        let (rate_hz, refused) = rebuild_servo(cfg, &ctl, &mut servo, trial);
        servo_rate_hz = rate_hz;
        ctl.task
            .publish(coop_rt::shm::control::TaskState::None, 0.0, 0);
        trials::rebuilt(&ctl, Child::Servo, trial, &refused);
    }
}

/// Rebuilds `servo` for study trial `trial` from its scenario (on its open device; a simulated
/// hand made again as the trial's participant): its servo rate, and why it cannot run the trial
/// (empty: it can). Refused, it holds the station's own world, judged by nobody (no time 0 comes
/// for a refused trial).
fn rebuild_servo(
    cfg: &Resolved,
    ctl: &ControlBlock,
    servo: &mut ServoLoop<coop_rt::device::StationDevice>,
    trial: u64,
) -> (f64, String) {
    let now = monotonic_ns();
    let (sc, mut refused) = trials::scenario_or_own(cfg, ctl);
    if refused.is_empty() && crate::station::device::made_per_trial(&cfg.device) {
        match crate::station::device::open(&cfg.device, &sc, cfg.site, now) {
            Ok(d) => *servo.device_mut() = d,
            Err(e) => refused = format!("trial {trial}: its device: {e}"),
        }
    }
    let (params, clamped) = servo_params(cfg, &sc, servo.device().info());
    for l in clamped.into_iter().flatten() {
        servo.guarded_mut().record(l, now);
    }
    let judge = if refused.is_empty() {
        sc.task_judge().ok().flatten()
    } else {
        None
    };
    servo.begin_trial(trial, Servo::new(params), sc.world(), judge, now);
    (sc.site[cfg.site].servo_rate_hz, refused)
}

/// The servo's parameters for site `cfg.site` of `sc`, its contact rendered no stiffer nor more
/// damped than the device `info` can (CHAI3D's scaling), and the limits that clamped it.
fn servo_params(
    cfg: &Resolved,
    sc: &Scenario,
    info: &coop_rt::device::DeviceInfo,
) -> (
    coop_model::servo::ServoParams,
    [Option<coop_rt::device::safety::Limit>; 2],
) {
    let dev = &cfg.device;
    let mut params = sc.servo_params(cfg.site);
    let (contact, clamped) = clamp_contact(params.contact, info, dev.placement.scale());
    if contact != params.contact {
        eprintln!(
            "station servo {}: contact stiffness {:.0} N/m, damping {:.1} N·s/m clamped to the device's {:.0} N/m, {:.1} N·s/m (at workspace scale {})",
            cfg.name,
            params.contact.stiffness_n_per_m,
            params.contact.damping_n_s_per_m,
            contact.stiffness_n_per_m,
            contact.damping_n_s_per_m,
            dev.placement.scale()
        );
    }
    params.contact = contact;
    (params, clamped)
}

/// Runs the physics process of the configured station until the run state asks it to stop.
///
/// # Errors
/// The segments cannot be opened, or the scheduling request is impossible.
pub fn run_physics(cfg: &Resolved, parent: Option<u32>) -> Result<(), ChildError> {
    let (names, opts, ctl) = attach(cfg, parent)?;
    let rings = PhysicsRings {
        tools: Consumer::open(&names.tool, &opts).map_err(opening("tool"))?,
        remote: Consumer::open(&names.remote, &opts).map_err(opening("remote"))?,
        objects: Producer::open(&names.object, &opts).map_err(opening("object"))?,
        reports: Producer::open(&names.report, &opts).map_err(opening("report"))?,
        trace: Some(Producer::open(&names.trace, &opts).map_err(opening("trace"))?),
        tracks_out: None,
        tracks_in: None,
    };
    let i = cfg.site;
    // A study's station restarted in the middle of a trial runs that trial's scenario.
    let (mut trial, trial_sc, refused) = trials::current(cfg, &ctl);
    let (sc, refused) = (&trial_sc, refused.as_str());
    let (method, join_after) = physics_method(sc, i);
    let mut rings = rings;
    // A method on the session's tick grid exchanges tool tracks (it says so: `join_after`).
    if join_after.is_some() {
        rings.tracks_out =
            Some(Producer::open(&names.track_out, &opts).map_err(opening("track-out"))?);
        rings.tracks_in =
            Some(Consumer::open(&names.track_in, &opts).map_err(opening("track-in"))?);
    }
    // A restarted physics resumes from the newest state its predecessor published, not from the
    // scenario's start (the servo kept displaying that state; a jump back would be felt). On the
    // grid (timewarp, coupled) only if it joins late; started with the session, it steps from
    // tick 0 like every other site.
    // (Of this scenario's world: a block another world's physics wrote is not resumed from.)
    // (A study's trial not started yet starts from its scenario: the block may hold the last
    // trial's end.)
    let resumed = ctl
        .resume()
        .filter(|r| r.objects == sc.objects.len())
        .filter(|_| trial == 0 || ctl.epoch().is_some())
        .map(|r| r.states());
    if resumed.is_some() {
        eprintln!(
            "station physics {}: resuming from the last published state{}",
            cfg.name,
            if join_after.is_some() {
                " if it joins the session's tick grid late"
            } else {
                ""
            }
        );
    }
    let copy = match (join_after, resumed) {
        (None, Some(states)) => {
            // The scenario's world with every object where it was.
            let mut copy = sc.start_copy();
            for (o, s) in copy.objects_mut().iter_mut().zip(states) {
                *o = ObjectCopy::new(s);
            }
            copy
        }
        _ => sc.start_copy(),
    };
    if trial > 0 && ctl.epoch().is_none() {
        // A study's trial not started yet: nothing its predecessor left in the rings is taken.
        rings.drain_inputs();
    }
    let (mut step, timing) = physics_timing(sc, i, &ctl);
    let mut physics = PhysicsLoop::new(i, method, sc.world(), copy, rings, timing);
    if let Some(after) = join_after {
        physics.join_late(after, resumed);
    }
    trials::joined(&ctl, Child::Physics, trial, refused);
    if trial > 0 && ctl.epoch().is_none() {
        trials::wait_network(&ctl, Child::Physics, trial);
    }
    let (in_force, _dma) = setup(cfg, &cfg.physics_sched, Child::Physics)?;
    let mut last_report_seq = timing.report_seq;
    ctl.physics
        .report_period_ns
        .store(timing.report_period_ns, Ordering::Relaxed);
    loop {
        run_periodic(
            &ctl,
            Child::Physics,
            &ctl.physics.stats,
            step,
            &in_force,
            |now| {
                if let Some(epoch) = ctl.epoch() {
                    // The session's time 0 is tick 0 of the grid (methods that step on it).
                    physics.set_tick_origin(epoch);
                }
                physics.step(now);
                physics.publish_counters(&ctl);
                if physics.report_seq() != last_report_seq {
                    // At the report rate: what a successor resumes from.
                    last_report_seq = physics.report_seq();
                    ctl.physics.last_report_ns.store(now, Ordering::Relaxed);
                    ctl.physics
                        .report_seq
                        .store(last_report_seq, Ordering::Relaxed);
                    ctl.store_resume(physics.objects(), |k| physics.object_sample(now, k));
                }
                // A study's next trial ends this one.
                matches!(ctl.run_state(), RunState::Starting | RunState::Running)
                    && ctl.trial.requested() <= trial
            },
        );
        if !trials::next(&ctl, Child::Physics, &mut trial) {
            return Ok(());
        }
        // The servo and the network send nothing more of the last trial: what they sent is
        // dropped with the last trial's loop, and the next one starts from its scenario at its
        // time 0 (no state of the last trial crosses over).
        let rings = physics.into_rings();
        let (sc, refused) = trials::scenario_or_own(cfg, &ctl);
        let (p, timing) = physics_timing(&sc, i, &ctl);
        step = p;
        last_report_seq = timing.report_seq;
        ctl.physics
            .report_period_ns
            .store(timing.report_period_ns, Ordering::Relaxed);
        let (method, _) = physics_method(&sc, i);
        physics = PhysicsLoop::new(i, method, sc.world(), sc.start_copy(), rings, timing);
        // A physics process restarted in this trial resumes from its world, not the last one's.
        let now = monotonic_ns();
        ctl.store_resume(physics.objects(), |k| physics.object_sample(now, k));
        trials::rebuilt(&ctl, Child::Physics, trial, &refused);
    }
}

/// Site `i`'s physics period under `sc`, and its clock from now (the report sequence going on
/// from the control block's).
fn physics_timing(sc: &Scenario, i: usize, ctl: &ControlBlock) -> (Duration, PhysicsTiming) {
    let step = period(sc.site[i].physics_rate_hz);
    let timing = PhysicsTiming {
        period_ns: u64::try_from(step.as_nanos()).unwrap_or(1_000_000),
        report_period_ns: u64::try_from(period(sc.site[i].report_rate_hz).as_nanos())
            .unwrap_or(10_000_000),
        start_ns: monotonic_ns(),
        trace_period_ns: u64::try_from(period(sc.sample_rate_hz).as_nanos()).unwrap_or(5_000_000),
        report_seq: ctl.physics.report_seq.load(Ordering::Relaxed),
    };
    (step, timing)
}

/// Runs the network process of the configured station until the run state asks it to stop.
///
/// # Errors
/// The segments cannot be opened, or the zenoh session cannot be set up.
pub fn run_network(cfg: &Resolved, parent: Option<u32>) -> Result<(), ChildError> {
    let (names, opts, ctl) = attach(cfg, parent)?;
    let sc = &cfg.scenario;
    let net = &cfg.config.network;
    // What the scenario sets of the network process: as each of a study's trials sets it.
    let own = trial_network(cfg, sc).map_err(|_| ChildError::NoSite(cfg.site))?;
    let args = coop_transport::network::NetworkArgs {
        session: &cfg.config.session,
        sites: sc.site.iter().map(|s| s.name.clone()).collect(),
        site_index: cfg.site,
        scenario: own.names.0,
        scenario_hash: own.scenario_hash,
        method: own.names.1,
        endpoints: net.clone(),
        control: &ctl,
        reports: Consumer::open(&names.report, &opts).map_err(opening("report"))?,
        remote: Producer::open(&names.remote, &opts).map_err(opening("remote"))?,
        trace: Consumer::open(&names.trace, &opts).map_err(opening("trace"))?,
        tracks: if sc.steps_on_grid(sc.method) {
            Some((
                Consumer::open(&names.track_out, &opts).map_err(opening("track-out"))?,
                Producer::open(&names.track_in, &opts).map_err(opening("track-in"))?,
            ))
        } else {
            None
        },
        record: cfg.config.record.clone(),
        // The supervisor that made this run's control block: a restarted network process
        // continues the recording its predecessor in the same run wrote.
        station_run: ctl.creator().map(|t| t.raw().to_string()),
        record_rotation: cfg.config.record_rotation(),
        emulation: own.emulation,
        bounds: own.bounds,
        silence_ns: own.silence_ns,
        scene: own.scene,
        record_foxglove: cfg.config.record_foxglove,
        live_view: cfg.config.live.clone(),
        ros2: cfg.config.ros2.publish.then(|| cfg.config.ros2.clone()),
        trials: cfg.config.trials.then(|| {
            let cfg = cfg.clone();
            coop_transport::network::trial::TrialSetupFn(Box::new(move |text: &str| {
                trial_network(&cfg, &trials::parse(&cfg.scenario, text)?)
            }))
        }),
    };
    // Normal priority, off the servo's CPU: the network is not a real-time loop, and its threads
    // (zenoh's, which inherit this affinity) must not run where the servo wakes.
    keep_off_the_servo(cfg);
    // Its loop sleeps until just after physics' next report is due (`next_wake`): under
    // SCHED_OTHER the kernel may defer that wake by the thread's timer slack, 50 µs by default,
    // which every state would wait on the way out. 1 ns (what SCHED_FIFO threads get) for this
    // thread and those it starts (zenoh's inherit it).
    if let Err(e) = nix::sys::prctl::set_timerslack(1) {
        eprintln!(
            "station network {}: timer slack stays at the default ({e})",
            cfg.name
        );
    }
    coop_transport::network::run(args)?;
    Ok(())
}

/// What the network process takes from scenario `sc`: the station's own, or a study's trial's.
fn trial_network(
    cfg: &Resolved,
    sc: &Scenario,
) -> Result<coop_transport::network::trial::TrialSetup, String> {
    let net = &cfg.config.network;
    let emulation = net.emulate.then(|| coop_transport::network::Emulation {
        link: sc.network.clone(),
        seed: sc.seed,
    });
    Ok(coop_transport::network::trial::TrialSetup {
        names: (sc.name.clone(), sc.method.as_str().to_owned()),
        scenario_hash: coop_transport::network::figures::scenario_hash(sc),
        emulation_text: emulation
            .as_ref()
            .map_or("none".into(), coop_transport::network::Emulation::describe),
        emulation,
        bounds: coop_transport::admit::Bounds::from_scenario(sc, net.max_state_age_ms),
        silence_ns: sc
            .site
            .iter()
            .map(|s| net.silence_ns(s.report_rate_hz))
            .collect(),
        scene: coop_transport::recording::Scene::from_scenario(sc, cfg.site)
            .ok_or_else(|| format!("the scenario has no site {}", cfg.site))?,
    })
}

/// Site `i`'s method for its physics process, built by the scenario's one factory as the
/// simulator's is, and the ticks after the session's time 0 past which a process on the tick
/// grid joins late.
///
/// Every site starts its copy at the scenario's start on tick 0 (the session's time 0): the
/// confirmed state is the same bits everywhere only from the same start. A physics process whose
/// first step falls a method's history or more after it (a restart, a late station: the time 0
/// may only be learnt then) has no history before it and cannot have the positions the others no
/// longer keep: it joins the grid where it is, from the newest state its predecessor published
/// (see `PhysicsLoop::join_late`), and yields to the sites that were there (see
/// `coop_model::method::timewarp`'s docs on healing), adopting a confirmed state of theirs.
/// Stations started together, a few hundred ms apart, are all there from the start.
pub(crate) fn physics_method(sc: &Scenario, i: usize) -> (Box<dyn Consistency>, Option<u64>) {
    let method = sc.method(i, sc.method);
    let join_after = method.grid_history_ticks();
    (method, join_after)
}

#[cfg(test)]
mod tests {
    use super::*;
    use coop_model::scenario::MethodName;
    use coop_model::sim::{site_method, Mode};

    /// A station's physics process and the simulator run the same method: the same type with the
    /// same parameters (a `paper` without its tool's spring in its no-gain bound, say, differs in
    /// its `Debug`), for every committed scenario, method and site.
    #[test]
    fn a_station_builds_every_method_as_the_simulator_does() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let mut files: Vec<_> = std::fs::read_dir(&dir)
            .expect("scenarios/")
            .map(|e| e.expect("entry").path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        files.sort();
        assert!(files.len() >= 5, "{files:?}");
        let mut compared = 0;
        for file in &files {
            let mut sc = crate::scenario_file::load(file).expect("a committed scenario loads");
            for name in MethodName::ALL {
                sc.method = name;
                for i in 0..sc.site.len() {
                    let (station, _) = physics_method(&sc, i);
                    let sim = site_method(&sc, Mode::Distributed(name), i);
                    assert_eq!(station.name(), name.as_str());
                    assert!(
                        format!("{station:?}") == format!("{sim:?}"),
                        "{}: {} at site {i}: the station's method differs from the simulator's",
                        file.display(),
                        name.as_str()
                    );
                    compared += 1;
                }
            }
        }
        assert!(compared >= 40, "{compared}");
    }
}
