//! The servo and physics loop bodies over real shared-memory rings, stepped with injected time (no
//! sleeping, no timing assertions): a push flows servo → ring → physics and moves the object; states
//! flow back; reports go out at the report rate; a hostile report is rejected and changes nothing;
//! when physics stops, the servo's commanded force ramps to zero within stale limit + ramp; and the
//! loop steps allocate nothing.

use coop_model::body::Vec3;
use coop_model::device::Plant;
use coop_model::replay::Trajectory;
use coop_model::scenario::{KeyframeSpec, MethodName, Scenario, SiteSpec};
use coop_model::servo::Servo;
use coop_rt::device::replay::Replay;
use coop_rt::device::safety::{Guarded, Limit, SafetyLimits};
use coop_rt::device::{CartesianDevice, Placement, SimScara, StationDevice};
use coop_rt::msg::{ObjectSample, SiteReport, ToolSample, TraceRecord};
use coop_rt::physics::{PhysicsLoop, PhysicsRings, PhysicsTiming};
use coop_rt::servo::ServoLoop;
use coop_rt::shm::{Producer, RingSegment, SegmentName};

mod common;
use common::counting_alloc::allocations_during;

const MS: u64 = 1_000_000;

/// The rig's rings, kept alive with it.
type Segments = (
    RingSegment<TraceRecord>,
    RingSegment<ToolSample>,
    RingSegment<ObjectSample>,
    RingSegment<SiteReport>,
    RingSegment<SiteReport>,
);

/// One site pushing a disk on a table, all four rings real segments.
struct Rig<D: CartesianDevice = SimScara> {
    servo: ServoLoop<D>,
    physics: PhysicsLoop,
    reports: coop_rt::shm::Consumer<SiteReport>,
    remote_in: Producer<SiteReport>,
    trace: coop_rt::shm::Consumer<TraceRecord>,
    _segments: Segments,
    stale_ms: f64,
    ramp_ms: f64,
    /// Its scenario.
    sc: Scenario,
}

impl<D: CartesianDevice> Rig<D> {
    /// Steps physics and the servo to tick `last` (1 ms apart, reports drained), the first ten
    /// outside the count (first contact, first adoption paths): the allocations of the rest.
    fn allocations_to(&mut self, last: u64) -> u64 {
        for k in 1..=10u64 {
            self.physics.step(k * MS);
            self.servo.step(k * MS, None);
        }
        allocations_during(|| {
            for k in 11..=last {
                self.physics.step(k * MS);
                self.servo.step(k * MS, None);
                while self.reports.pop().is_ok() {}
            }
        })
    }
}

/// With `wall`, a wall at x = 4.5 cm stops the disk so the user can press it against the wall.
fn rig(tag: &str, wall: bool) -> Rig {
    rig_with(tag, wall, sim_arm)
}

/// The simulated arm of the scenario's site 0, playing its script.
fn sim_arm(sc: &Scenario) -> SimScara {
    let script = sc.script(0);
    SimScara::new(
        Plant::at(sc.arm(0), sc.hand(0), script[0].target, 1.0),
        sc.force_loop(0),
        script,
        0,
    )
}

/// The default world on a table at z = 0 under g/3, with nothing of its own changed.
fn on_a_table() -> Scenario {
    let mut sc = Scenario::default();
    sc.world.planes[0].normal = [0.0, 0.0, 1.0];
    sc.world.planes[0].offset_m = 0.0;
    sc.world.gravity_m_per_s2 = [0.0, 0.0, -3.27];
    sc
}

/// Site `a` (100 Hz reports), whose tool rests at `from` until 0.2 s and moves to `to` by `by_s`.
fn pusher(from: [f64; 3], to: [f64; 3], by_s: f64) -> SiteSpec {
    let key = |t_s, target_m| KeyframeSpec { t_s, target_m };
    SiteSpec {
        name: "a".into(),
        device_base_m: [-0.3, -0.2, 0.0],
        report_rate_hz: 100.0,
        script: vec![key(0.0, from), key(0.2, from), key(by_s, to)],
        ..SiteSpec::default()
    }
}

/// The rig with the device `make` builds for its scenario.
fn rig_with<D: CartesianDevice>(
    tag: &str,
    wall: bool,
    make: impl FnOnce(&Scenario) -> D,
) -> Rig<D> {
    let mut sc = on_a_table();
    sc.objects[0].start_m = [0.0, 0.0, 0.0099];
    if wall {
        sc.world.planes.push(coop_model::scenario::PlaneSpec {
            normal: [-1.0, 0.0, 0.0],
            offset_m: -0.045,
        });
    }
    sc.site
        .push(pusher([-0.12, 0.0, 0.01], [-0.035, 0.0, 0.01], 0.7));
    sc.validate().expect("valid scenario");
    rig_in(tag, &sc, MethodName::Paper, make)
}

/// The rig of scenario `sc` under `method`, with the device `make` builds. Its rings have room
/// for a world of `sc`'s objects (a message per object a step).
fn rig_in<D: CartesianDevice>(
    tag: &str,
    sc: &Scenario,
    method: MethodName,
    make: impl FnOnce(&Scenario) -> D,
) -> Rig<D> {
    let per = sc.objects.len().next_power_of_two();
    let session = format!("lp{}{tag}", std::process::id());
    let name = |w: &str| SegmentName::new(&session, "a", w).expect("name");
    let tool = RingSegment::<ToolSample>::create(&name("tool"), 64).expect("tool ring");
    let obj = RingSegment::<ObjectSample>::create(&name("obj"), 64 * per).expect("object ring");
    let rep = RingSegment::<SiteReport>::create(&name("rep"), 64 * per).expect("report ring");
    let rem = RingSegment::<SiteReport>::create(&name("rem"), 64 * per).expect("remote ring");
    let trc = RingSegment::<TraceRecord>::create(&name("trc"), 4096 * per).expect("trace ring");
    let world = sc.world();
    let device = make(sc);
    let servo = ServoLoop::new(
        Servo::new(sc.servo_params(0)),
        Guarded::new(device, SafetyLimits::default(), 0),
        Placement::IDENTITY,
        world,
        obj.consumer().expect("c"),
        tool.producer().expect("p"),
        0,
    );
    let physics = PhysicsLoop::new(
        0,
        sc.method(0, method),
        world,
        sc.start_copy(),
        PhysicsRings {
            tools: tool.consumer().expect("c"),
            remote: rem.consumer().expect("c"),
            objects: obj.producer().expect("p"),
            reports: rep.producer().expect("p"),
            trace: Some(trc.producer().expect("p")),
            tracks_out: None,
            tracks_in: None,
        },
        PhysicsTiming {
            period_ns: MS,
            report_period_ns: 10 * MS,
            start_ns: 0,
            trace_period_ns: 5 * MS,
            report_seq: 0,
        },
    );
    Rig {
        servo,
        physics,
        reports: rep.consumer().expect("c"),
        remote_in: rem.producer().expect("p"),
        trace: trc.consumer().expect("c"),
        _segments: (trc, tool, obj, rep, rem),
        stale_ms: sc.site[0].stale_limit_ms,
        ramp_ms: sc.site[0].stale_ramp_ms,
        sc: sc.clone(),
    }
}

#[test]
fn a_push_flows_through_the_rings_and_reports_go_out() {
    let mut r = rig("push", false);
    let mut touched = false;
    let mut reports = 0;
    let (mut samples, mut last_t, mut traced_touch) = (0, 0, false);
    for k in 1..=1500u64 {
        r.physics.step(k * MS);
        let out = r.servo.step(k * MS, None);
        touched |= out.contacts[0].touching && out.f_desired.norm() > 0.1;
        while let Ok(rep) = r.reports.pop() {
            assert!(rep.report().is_some(), "every report decodes");
            reports += 1;
        }
        while let Ok(t) = r.trace.pop() {
            assert_eq!(t.kind, TraceRecord::SAMPLE);
            assert!(t.t_ns > last_t, "trace records in time order");
            last_t = t.t_ns;
            samples += 1;
            traced_touch |= t.touching == 1 && t.f_object[0] > 0.0;
        }
    }
    assert_eq!(
        samples, 301,
        "one trace sample at the start and per 5 ms over 1.5 s"
    );
    assert!(traced_touch, "the trace shows the push on the object");
    assert!(touched, "the servo felt the disk");
    let x = r.physics.copy().first().state.pos.x;
    assert!(
        x > 0.005,
        "physics moved the disk with the servo's contact: x = {x}"
    );
    assert!(
        (140..=160).contains(&reports),
        "100 Hz over 1.5 s: {reports}"
    );
}

#[test]
fn a_hostile_report_is_rejected_and_changes_nothing() {
    let mut r = rig("hostile", false);
    for k in 1..=100u64 {
        r.physics.step(k * MS);
        r.servo.step(k * MS, None);
    }
    let before = r.physics.copy().first().state;
    let mut bad = SiteReport {
        kind: 1,
        t_ns: 200 * MS,
        site: 1,
        rot: [1.0, 0.0, 0.0, 0.0],
        ..SiteReport::default()
    };
    bad.pos = [f64::NAN, 0.0, 0.0];
    r.remote_in.push(bad).expect("room");
    let mut foreign = bad;
    foreign.pos = [5.0, 5.0, 5.0];
    foreign.site = 42;
    r.remote_in.push(foreign).expect("room");
    r.physics.step(101 * MS);
    assert_eq!(r.physics.rejected, 2);
    assert_eq!(r.physics.adoptions(), 0);
    let after = r.physics.copy().first().state;
    assert!(after.is_finite() && (after.pos - before.pos).norm() < 1e-3);
}

#[test]
fn when_physics_stops_the_commanded_force_ramps_to_zero() {
    let mut r = rig("stale", true);
    // Press the disk against the wall until the servo commands a clear force.
    let mut k = 0u64;
    let mut pressing = 0.0;
    while k < 1500 {
        k += 1;
        r.physics.step(k * MS);
        pressing = r.servo.step(k * MS, None).f_command.norm();
    }
    assert!(pressing > 0.3, "holding the disk: commanded {pressing} N");
    // Physics stops: no more object states.
    let stopped = k;
    let deadline = stopped + (r.stale_ms + r.ramp_ms) as u64 + 1;
    let mut last = f64::INFINITY;
    let mut zero_at = None;
    while k < deadline + 200 {
        k += 1;
        let out = r.servo.step(k * MS, None);
        let f = out.f_command.norm();
        if k > stopped + r.stale_ms as u64 + 1 {
            assert!(
                f <= last + 1e-9,
                "ramping down, not up: {f} after {last} at {k} ms"
            );
        }
        last = f;
        if f == 0.0 && zero_at.is_none() {
            zero_at = Some(k);
        }
        if k > deadline {
            assert_eq!(
                f,
                0.0,
                "still commanding {f} N {} ms after physics stopped",
                k - stopped
            );
            assert_eq!(r.servo.device().tau().norm(), 0.0, "torques too");
        }
    }
    let zero_at = zero_at.expect("reached zero");
    assert!(
        zero_at - stopped <= (r.stale_ms + r.ramp_ms) as u64 + 1,
        "zero after {} ms",
        zero_at - stopped
    );
}

#[test]
fn loop_steps_allocate_nothing() {
    let mut r = rig("alloc", true);
    let n = r.allocations_to(3000);
    assert_eq!(n, 0, "servo/physics loop steps allocated {n} times");
}

/// A station's servo with a simulated participant as its hand and the task judged live: the
/// participant reaches for the disk where the station shows it, pushes it and lets go, the task
/// (the disk in a region, released) is judged done, and no step allocates once warmed up.
#[test]
fn a_participant_hand_acts_on_what_the_station_shows_and_the_task_is_judged_allocation_free() {
    use coop_model::participant::{Action, StepSpec};
    use coop_model::task::{ConditionSpec, Outcome};
    let mut sc = on_a_table();
    sc.objects[0].start_m = [0.0, 0.0, 0.0099];
    let mut site = pusher([-0.12, 0.0, 0.01], [-0.12, 0.0, 0.01], 0.5);
    site.script.truncate(1);
    let step = |action, side: Option<[f64; 3]>| StepSpec {
        action,
        object: Some("object".into()),
        side,
        ..StepSpec::default()
    };
    site.plan = vec![
        StepSpec {
            gap_m: 0.02,
            ..step(Action::Reach, Some([-1.0, 0.0, 0.0]))
        },
        StepSpec {
            depth_m: 0.04,
            ..step(Action::Push, Some([-1.0, 0.0, 0.0]))
        },
        StepSpec {
            object: None,
            away_m: 0.05,
            ..step(Action::Release, Some([-1.0, 0.0, 0.0]))
        },
    ];
    sc.site.push(site);
    sc.task.done = Some(ConditionSpec {
        object: Some("object".into()),
        in_region_m: Some([[0.02, -0.05, -0.01], [0.2, 0.05, 0.05]]),
        released: true,
        ..ConditionSpec::default()
    });
    sc.task.hold_s = 0.2;
    sc.validate().expect("valid scenario");
    let mut r = rig_in("person", &sc, MethodName::Paper, |sc| {
        sim_arm(sc).with_participant(sc.participant(0).expect("a participant"))
    });
    r.servo.set_task(sc.task_judge().expect("task"));
    r.servo.start_at(0);
    let n = r.allocations_to(6000);
    assert_eq!(
        n, 0,
        "servo steps with a participant and a task allocated {n} times"
    );
    let person = r
        .servo
        .device()
        .participant()
        .expect("the hand is a participant");
    assert_eq!(person.step(), person.plan_len(), "the plan was carried out");
    let outcome = r.servo.task().expect("judged").outcome();
    assert!(
        matches!(outcome, Outcome::Done(t) if t > 0.5),
        "{outcome:?}"
    );
}

/// The largest world a station takes ([`coop_model::world::MAX_OBJECTS`] pucks in a 4 × 4 grid,
/// touching their neighbours' gaps), one pushed by the tool into the others: under every method
/// that steps it on a station, the servo's and physics' steps allocate nothing, every object's
/// state reaches the servo, and the trace carries every object.
#[test]
fn loop_steps_in_the_largest_world_allocate_nothing() {
    use coop_model::world::MAX_OBJECTS;
    let mut sc = on_a_table();
    let puck = sc.objects[0].clone();
    sc.objects = (0..MAX_OBJECTS)
        .map(|k| coop_model::scenario::ObjectSpec {
            name: format!("puck{k}"),
            start_m: [
                -0.04 + 0.085 * (k % 4) as f64,
                -0.13 + 0.085 * (k / 4) as f64,
                puck.half_height_m - 1e-4,
            ],
            ..puck.clone()
        })
        .collect();
    sc.site
        .push(pusher([-0.12, -0.13, 0.01], [0.02, -0.13, 0.01], 0.9));
    sc.validate().expect("valid scenario");
    for method in [
        MethodName::Paper,
        MethodName::Naive,
        MethodName::Timewarp,
        MethodName::Coupled,
    ] {
        let mut r = rig_in(&format!("big{}", method.as_str()), &sc, method, sim_arm);
        // On the grid from time 0 (methods that step on it).
        r.physics.set_tick_origin(0);
        let step = |r: &mut Rig, k: u64| {
            r.physics.step(k * MS);
            r.servo.step(k * MS, None);
        };
        for k in 1..=10u64 {
            step(&mut r, k);
        }
        let mut records = Vec::with_capacity(4096 * MAX_OBJECTS);
        let n = allocations_during(|| {
            for k in 11..=1500u64 {
                step(&mut r, k);
                while r.reports.pop().is_ok() {}
                while let Ok(t) = r.trace.pop() {
                    if records.len() < records.capacity() {
                        records.push(t);
                    }
                }
            }
        });
        assert_eq!(
            n,
            0,
            "{}: steps in a world of {MAX_OBJECTS} allocated {n} times",
            method.as_str()
        );
        let objects: std::collections::BTreeSet<u64> = records.iter().map(|t| t.object).collect();
        assert_eq!(
            objects.len(),
            MAX_OBJECTS,
            "{}: the trace has every object",
            method.as_str()
        );
        let touched: std::collections::BTreeSet<u64> = records
            .iter()
            .filter(|t| t.touching != 0)
            .map(|t| t.object)
            .collect();
        assert!(
            touched.contains(&0),
            "{}: the tool pushed the first puck: {touched:?}",
            method.as_str()
        );
        assert_eq!(
            r.physics.object_drops,
            0,
            "{}: the object ring had room",
            method.as_str()
        );
        // The servo's world is fresh only once every object's state has come.
        r.physics.step(1501 * MS);
        let last = r.servo.step(1501 * MS, None);
        assert_eq!(
            last.scale,
            1.0,
            "{}: the servo has every object",
            method.as_str()
        );
    }
}

/// The servo step through the station's device type with each backend built in (the simulated
/// arm, a replayed hand pressing the disk against the wall far harder than the limits allow, so the
/// force clamp and the impulse limit act), under the safety layer, allocates nothing.
#[test]
fn servo_steps_with_each_backend_under_the_safety_layer_allocate_nothing() {
    let sim = rig_with("allocsim", true, |sc| {
        let script = sc.script(0);
        StationDevice::Sim(SimScara::new(
            Plant::at(sc.arm(0), sc.hand(0), script[0].target, 1.0),
            sc.force_loop(0),
            script,
            0,
        ))
    });
    let replay = rig_with("allocrep", true, |sc| {
        // The script's path, ending 2 cm further into the disk held by the wall.
        let script = sc.script(0);
        let end = script.len() - 1;
        let t = Trajectory::new(script.iter().enumerate().map(|(i, k)| {
            let deeper = if i == end {
                Vec3::new(0.02, 0.0, 0.0)
            } else {
                Vec3::zeros()
            };
            (k.t_s, k.target + deeper)
        }))
        .expect("a trajectory");
        let mut d = Replay::new(t, "the script's keyframes");
        d.start_at(0);
        StationDevice::Replay(d)
    });
    for (what, mut r) in [("sim", sim), ("replay", replay)] {
        for k in 1..=10u64 {
            r.physics.step(k * MS);
            r.servo.step(k * MS, None);
        }
        let mut most = 0.0f64;
        let n = allocations_during(|| {
            for k in 11..=3000u64 {
                r.physics.step(k * MS);
                most = most.max(r.servo.step(k * MS, None).f_command.norm());
                while r.reports.pop().is_ok() {}
            }
        });
        assert_eq!(n, 0, "{what}: servo/physics loop steps allocated {n} times");
        assert!(
            most > 0.3,
            "{what}: the device was commanded a force ({most} N)"
        );
        if what == "replay" {
            let trip = r.servo.guarded().last_trip().expect("a limit acted");
            assert!(
                matches!(trip.limit, Limit::MaxForce | Limit::Impulse),
                "the replayed hand pressing hard trips the force limits: {trip:?}"
            );
            // The servo publishes the trip for `station status`.
            use coop_rt::shm::control::ControlBlock;
            use coop_rt::shm::BlockSegment;
            let name = SegmentName::new(&format!("lp{}trip", std::process::id()), "a", "ctl")
                .expect("name");
            let ctl = BlockSegment::<ControlBlock>::create(&name).expect("control");
            r.physics.step(3001 * MS);
            r.servo.step(3001 * MS, Some(&ctl));
            let load = |a: &coop_rt::sync::AtomicU64| a.load(coop_rt::sync::Ordering::Relaxed);
            let now = r.servo.guarded().last_trip().expect("still acting");
            assert_eq!(
                Limit::from_code(load(&ctl.servo.safety_limit)),
                Some(now.limit)
            );
            assert_eq!(load(&ctl.servo.safety_at_ns), now.at_ns);
            assert!(load(&ctl.servo.safety_episodes) >= 1);
        }
    }
}

/// The rig pressing the disk against the wall, stepped under a running station's control block
/// for 1.5 s: the rig, the block, the last tick, the force commanded then (checked to hold).
fn pressing_the_disk(
    tag: &str,
) -> (
    Rig,
    coop_rt::shm::BlockSegment<coop_rt::shm::control::ControlBlock>,
    u64,
    f64,
) {
    use coop_rt::shm::control::{ControlBlock, RunState};
    let mut r = rig(tag, true);
    let name =
        SegmentName::new(&format!("lp{}{tag}", std::process::id()), "a", "ctl").expect("name");
    let ctl = coop_rt::shm::BlockSegment::<ControlBlock>::create(&name).expect("control");
    ctl.set_run_state(RunState::Running);
    let mut k = 0u64;
    let mut pressing = 0.0;
    while k < 1500 {
        k += 1;
        r.physics.step(k * MS);
        pressing = r.servo.step(k * MS, Some(&ctl)).f_command.norm();
    }
    assert!(pressing > 0.3, "holding the disk: {pressing} N");
    (r, ctl, k, pressing)
}

/// A cooperative stop (run state Stopping) ramps the commanded force to zero within the ramp time
/// even while physics keeps running; only then is the servo limp and free to exit.
#[test]
fn a_cooperative_stop_ramps_the_force_to_zero_first() {
    use coop_rt::shm::control::{ControlBlock, RunState};
    let (mut r, ctl, mut k, pressing) = pressing_the_disk("coop");
    assert!(!r.servo.is_limp());
    assert!(
        (ControlBlock::load_f64(&ctl.servo.command_n) - pressing).abs() < 1e-12,
        "published"
    );
    ctl.set_run_state(RunState::Stopping);
    let stop = k;
    while !r.servo.is_limp() {
        k += 1;
        r.physics.step(k * MS);
        r.servo.step(k * MS, Some(&ctl));
        assert!(
            k - stop <= r.ramp_ms as u64 + 1,
            "not limp {} ms after the stop",
            k - stop
        );
    }
    assert_eq!(ControlBlock::load_f64(&ctl.servo.command_n), 0.0);
    assert_eq!(ControlBlock::load_f64(&ctl.servo.scale), 0.0);
}

/// A study's next trial, asked for in the control block, ramps the commanded force to zero as a
/// stop does; the loops then rebuilt on the same rings (physics' emptied of the last trial, the
/// servo's too) start from the new trial's world, with no state of the last one shown.
#[test]
fn the_next_trial_ramps_the_force_out_and_nothing_of_the_last_one_crosses_over() {
    let (mut r, ctl, mut k, _) = pressing_the_disk("trial");
    let pushed = r.physics.copy().first().state.pos.x;
    assert!(
        pushed > 0.004,
        "the disk was pushed to the wall: x = {pushed}"
    );
    assert!(ctl.trial.request(1, "t1", "# the trial's scenario"));
    let asked = k;
    while !r.servo.is_limp() {
        k += 1;
        r.physics.step(k * MS);
        r.servo.step(k * MS, Some(&ctl));
        assert!(
            k - asked <= r.ramp_ms as u64 + 1,
            "not limp {} ms after the next trial was asked for",
            k - asked
        );
    }
    // Physics sends states the servo has not taken yet; the next trial's loops are built on the
    // same rings.
    for _ in 0..3 {
        k += 1;
        r.physics.step(k * MS);
    }
    let rings = r.physics.into_rings();
    let sc = r.sc.clone();
    r.physics = PhysicsLoop::new(
        0,
        sc.method(0, MethodName::Paper),
        sc.world(),
        sc.start_copy(),
        rings,
        PhysicsTiming {
            period_ns: MS,
            report_period_ns: 10 * MS,
            start_ns: k * MS,
            trace_period_ns: 5 * MS,
            report_seq: 0,
        },
    );
    r.servo
        .begin_trial(1, Servo::new(sc.servo_params(0)), sc.world(), None, k * MS);
    assert_eq!(r.servo.trial(), 1);
    // No state of the last trial is shown (the tool is still where it pressed the disk against
    // the wall): until the new physics sends one, nothing is touched and nothing displayed.
    for _ in 0..20 {
        k += 1;
        let out = r.servo.step(k * MS, Some(&ctl));
        assert!(!out.contacts[0].touching, "a state of the last trial shown");
        assert_eq!(out.scale, 0.0, "the display starts ramped out");
        assert_eq!(out.f_command.norm(), 0.0);
    }
    // Physics' first state of the new trial comes late (the processes set themselves up between
    // trials): the servo's first fresh tick after the gap ramps in by one short tick, no more.
    k += 200;
    r.physics.step(k * MS);
    let first = r.servo.step(k * MS, Some(&ctl)).scale;
    let tick_ms = coop_model::servo::ramp_in_tick_s(r.sc.site[0].servo_rate_hz) * 1e3;
    assert!(
        first > 0.0 && first <= tick_ms / r.ramp_ms + 1e-9,
        "the ramp-in skipped after a gap, or did not begin: scale {first}"
    );
    // And runs: the states of the new trial reach the servo, whose display ramps in (never a
    // step to full force).
    let (mut scale, mut last) = (first, first);
    for _ in 0..200 {
        k += 1;
        r.physics.step(k * MS);
        scale = r.servo.step(k * MS, Some(&ctl)).scale;
        assert!(
            scale - last <= 1.0 / r.ramp_ms + 1e-9,
            "ramped in: {last} to {scale}"
        );
        last = scale;
    }
    assert!(scale > 0.0, "the new trial's world is displayed");
    // Its end announced: the force ramps out and stays out until the next trial.
    ctl.trial.set_ended(1);
    let ended = k;
    for _ in 0..300 {
        k += 1;
        r.physics.step(k * MS);
        let out = r.servo.step(k * MS, Some(&ctl));
        if k - ended > r.ramp_ms as u64 + 1 {
            assert_eq!(out.f_command.norm(), 0.0, "a force after the trial's end");
        }
    }
    assert!(r.servo.is_limp());
}

/// A report that passes every check a ring conversion makes (finite, unit quaternion) but whose
/// adoption would make the copy non-finite (an angular momentum of 1e308: infinite energy, a NaN
/// rotation one step later) is not adopted: the copy keeps its state, and it is counted.
#[test]
fn an_adoption_that_would_make_the_copy_non_finite_keeps_the_copy() {
    let mut r = rig("nonfinite", false);
    for k in 1..=100u64 {
        r.physics.step(k * MS);
        r.servo.step(k * MS, None);
    }
    let before = r.physics.copy().first().state;
    let mut absurd = SiteReport {
        kind: 1,
        t_ns: 100 * MS,
        site: 1,
        rot: [1.0, 0.0, 0.0, 0.0],
        ..SiteReport::default()
    };
    absurd.pos = before.pos.into();
    absurd.ang_mom = [0.0, 0.0, 1e308];
    absurd.included = [-1.0; coop_model::MAX_SITES];
    absurd.included[1] = 0.09; // newer contributions of site 1: the paper method adopts it
    assert!(absurd.report().is_some(), "the ring conversion accepts it");
    r.remote_in.push(absurd).expect("room");
    for k in 101..=200u64 {
        r.physics.step(k * MS);
    }
    assert_eq!(r.physics.nonfinite_kept(), 1);
    assert_eq!(r.physics.adoptions(), 0);
    let after = r.physics.copy().first().state;
    assert!(
        after.is_finite() && (after.pos - before.pos).norm() < 1e-2,
        "{after:?}"
    );
}
