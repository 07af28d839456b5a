//! The safety contract, one test per limit: each drives a device into the limit through
//! [`Guarded`] and checks what the device itself was told (clamped, or released), and that the
//! limit is named with its time. The device is a recording fake (the contract is the wrapper's; the
//! backends only do their transport), plus the simulated arm for release on drop and a stale world.

use std::sync::{Arc, Mutex};

use coop_model::body::Vec3;
use coop_model::contact::ContactParams;
use coop_model::device::Plant;
use coop_model::scenario::Scenario;
use coop_rt::device::safety::{clamp_contact, Guarded, Limit, SafetyLimits};
use coop_rt::device::{CartesianDevice, Command, DeviceFault, DeviceInfo, Sample, SimScara};

const MS: u64 = 1_000_000;

/// What the fake device was told.
#[derive(Debug, Default)]
struct Log {
    commands: Vec<(u64, Command)>,
    gains: Vec<f64>,
    closed: bool,
}

/// How the fake device behaves.
#[derive(Debug, Clone, Copy)]
struct Behaviour {
    velocity: Vec3,
    /// The sample time stops at this time (a bridge that went silent).
    frozen_after_ns: Option<u64>,
    /// Sampling fails from this time on.
    fails_after_ns: Option<u64>,
}

#[derive(Debug)]
struct Fake {
    info: DeviceInfo,
    log: Arc<Mutex<Log>>,
    behaviour: Arc<Mutex<Behaviour>>,
}

fn fake(max_force_n: f64) -> (Fake, Arc<Mutex<Log>>, Arc<Mutex<Behaviour>>) {
    let log = Arc::new(Mutex::new(Log::default()));
    let behaviour = Arc::new(Mutex::new(Behaviour {
        velocity: Vec3::zeros(),
        frozen_after_ns: None,
        fails_after_ns: None,
    }));
    let d = Fake {
        info: DeviceInfo {
            backend: "fake",
            model: "recording fake".into(),
            serial: None,
            dof: 3,
            max_force_n,
            max_stiffness_n_per_m: 1000.0,
            max_damping_n_s_per_m: 5.0,
            workspace_radius_m: 0.1,
            native_rate_hz: 1000.0,
            senses_force: false,
        },
        log: log.clone(),
        behaviour: behaviour.clone(),
    };
    (d, log, behaviour)
}

impl CartesianDevice for Fake {
    fn info(&self) -> &DeviceInfo {
        &self.info
    }
    fn sample(&mut self, now_ns: u64) -> Result<Sample, DeviceFault> {
        let b = *self.behaviour.lock().expect("lock");
        if b.fails_after_ns.is_some_and(|t| now_ns >= t) {
            return Err(DeviceFault::CallFailed {
                call: "fakeGetPosition",
                code: -1,
            });
        }
        Ok(Sample {
            t_ns: b.frozen_after_ns.map_or(now_ns, |t| now_ns.min(t)),
            position_m: Vec3::zeros(),
            velocity_m_s: b.velocity,
            orientation: None,
            buttons: 0,
            force_sensed_n: None,
        })
    }
    fn command(&mut self, now_ns: u64, cmd: Command) -> Result<(), DeviceFault> {
        self.log.lock().expect("lock").commands.push((now_ns, cmd));
        Ok(())
    }
    fn set_output_gain(&mut self, gain: f64) {
        self.log.lock().expect("lock").gains.push(gain);
    }
    fn close(&mut self) {
        self.log.lock().expect("lock").closed = true;
    }
}

fn limits() -> SafetyLimits {
    SafetyLimits {
        ramp_in_s: 0.0,
        max_force_n: 8.0,
        max_velocity_m_s: 1.0,
        max_force_step_n: 100.0,
        watchdog_s: 0.05,
    }
}

/// One servo tick: sample, then display `f` with a fresh world.
fn tick<D: CartesianDevice>(g: &mut Guarded<D>, now: u64, f: Vec3) -> Vec3 {
    let _ = g.sample(now);
    g.display(now, f, 1.0)
}

fn last(log: &Arc<Mutex<Log>>) -> Command {
    log.lock()
        .expect("lock")
        .commands
        .last()
        .expect("a command")
        .1
}

#[test]
fn ramp_in_raises_the_force_from_zero_over_the_ramp_time() {
    let (d, log, _) = fake(20.0);
    let mut g = Guarded::new(
        d,
        SafetyLimits {
            ramp_in_s: 0.1,
            ..limits()
        },
        0,
    );
    let f = Vec3::new(4.0, 0.0, 0.0);
    let first = tick(&mut g, MS, f);
    assert!(
        (first.x - 4.0 * 0.01).abs() < 1e-9,
        "1 ms into a 100 ms ramp: {first}"
    );
    let mut before = first.x;
    for k in 2..=95 {
        let now = tick(&mut g, k * MS, f).x;
        assert!(now > before, "rising at {k} ms: {now} after {before}");
        before = now;
    }
    for k in 96..=110 {
        tick(&mut g, k * MS, f);
    }
    assert_eq!(last(&log), Command::Force(f), "full force once ramped in");
}

#[test]
fn force_is_clamped_to_the_smaller_of_config_and_device_maximum() {
    for (device_max, expect) in [(20.0, 8.0), (5.0, 5.0)] {
        let (d, log, _) = fake(device_max);
        let mut g = Guarded::new(d, limits(), 0);
        assert_eq!(g.max_force_n(), expect);
        let out = tick(&mut g, MS, Vec3::new(0.0, 30.0, 40.0));
        let Command::Force(sent) = last(&log) else {
            panic!("a force")
        };
        assert!((sent.norm() - expect).abs() < 1e-9, "sent {sent}");
        assert!(
            (sent.normalize() - Vec3::new(0.0, 0.6, 0.8)).norm() < 1e-12,
            "same direction"
        );
        assert_eq!(out, sent);
        let trip = g.last_trip().expect("tripped");
        assert_eq!((trip.limit, trip.at_ns), (Limit::MaxForce, MS));
    }
}

#[test]
fn contact_stiffness_and_damping_are_clamped_to_the_device_scaled_by_the_workspace() {
    let (d, _, _) = fake(10.0);
    let c = ContactParams {
        stiffness_n_per_m: 2000.0,
        damping_n_s_per_m: 3.0,
        tangential_stiffness_n_per_m: 300.0,
        tangential_damping_n_s_per_m: 10.0,
        friction_static: 0.9,
        friction_kinetic: 0.7,
        rotational_friction_radius_m: 0.0,
    };
    // World metres are half device metres at scale 2: the device's 1000 N/m is 500 N/m of world.
    let (out, acted) = clamp_contact(c, d.info(), 2.0);
    assert_eq!(out.stiffness_n_per_m, 500.0);
    assert_eq!(
        out.tangential_stiffness_n_per_m, 300.0,
        "within the limit: kept"
    );
    assert_eq!(out.damping_n_s_per_m, 2.5);
    assert_eq!(out.tangential_damping_n_s_per_m, 2.5);
    assert_eq!(acted, [Some(Limit::Stiffness), Some(Limit::Damping)]);
    let (same, none) = clamp_contact(c, d.info(), 0.1);
    assert_eq!((same, none), (c, [None, None]), "a small scale leaves room");
}

#[test]
fn a_hand_faster_than_the_velocity_limit_releases_the_device_until_slow_again() {
    let (d, log, b) = fake(20.0);
    let mut g = Guarded::new(
        d,
        SafetyLimits {
            ramp_in_s: 0.01,
            ..limits()
        },
        0,
    );
    let f = Vec3::new(2.0, 0.0, 0.0);
    for k in 1..=20 {
        tick(&mut g, k * MS, f);
    }
    assert_eq!(last(&log), Command::Force(f));
    b.lock().expect("lock").velocity = Vec3::new(0.0, 1.5, 0.0);
    assert_eq!(tick(&mut g, 21 * MS, f), Vec3::zeros());
    assert_eq!(last(&log), Command::Release, "released");
    assert_eq!(log.lock().expect("lock").gains.last(), Some(&0.0));
    assert_eq!(g.holding(), Some(Limit::Velocity));
    let trip = g.last_trip().expect("tripped");
    assert_eq!((trip.limit, trip.at_ns), (Limit::Velocity, 21 * MS));
    // Slow again: the force comes back through a fresh ramp-in, not at once.
    b.lock().expect("lock").velocity = Vec3::new(0.0, 0.5, 0.0);
    let back = tick(&mut g, 22 * MS, f);
    assert!(
        back.norm() > 0.0 && back.norm() < f.norm() * 0.2,
        "ramping in again: {back}"
    );
    assert_eq!(g.holding(), None);
}

#[test]
fn the_force_changes_by_at_most_the_impulse_limit_per_tick() {
    let (d, log, _) = fake(20.0);
    let mut g = Guarded::new(
        d,
        SafetyLimits {
            max_force_step_n: 0.5,
            ..limits()
        },
        0,
    );
    let f = Vec3::new(0.0, 0.0, -3.0);
    let mut prev = Vec3::zeros();
    for k in 1..=6 {
        let out = tick(&mut g, k * MS, f);
        assert!(
            (out - prev).norm() <= 0.5 + 1e-12,
            "step {} at {k} ms",
            (out - prev).norm()
        );
        prev = out;
    }
    assert_eq!(
        last(&log),
        Command::Force(f),
        "there after 6 steps of 0.5 N"
    );
    let trip = g.last_trip().expect("tripped");
    assert_eq!(
        (trip.limit, trip.episodes),
        (Limit::Impulse, 1),
        "one episode over 5 ticks"
    );
    // Releasing is never limited: it takes energy out.
    assert_eq!(g.display(7 * MS, f, 0.0), Vec3::zeros());
    assert_eq!(last(&log), Command::Release);
}

#[test]
fn a_sample_time_that_stands_still_past_the_watchdog_releases_the_device() {
    let (d, log, b) = fake(20.0);
    let mut g = Guarded::new(d, limits(), 0);
    let f = Vec3::new(1.0, 1.0, 0.0);
    b.lock().expect("lock").frozen_after_ns = Some(10 * MS);
    let mut released_at = None;
    for k in 1..=100 {
        tick(&mut g, k * MS, f);
        if released_at.is_none() && last(&log) == Command::Release {
            released_at = Some(k);
        }
    }
    // Fresh up to 10 ms; 50 ms of watchdog later it is released, and stays so.
    assert_eq!(released_at, Some(61), "released once the watchdog ran out");
    assert_eq!(last(&log), Command::Release);
    assert_eq!(g.holding(), Some(Limit::Watchdog));
    assert_eq!(g.last_trip().map(|t| t.limit), Some(Limit::Watchdog));
}

#[test]
fn a_device_fault_releases_the_device() {
    let (d, log, b) = fake(20.0);
    let mut g = Guarded::new(d, limits(), 0);
    let f = Vec3::new(1.0, 0.0, 0.0);
    tick(&mut g, MS, f);
    assert_eq!(last(&log), Command::Force(f));
    b.lock().expect("lock").fails_after_ns = Some(2 * MS);
    assert_eq!(
        g.sample(2 * MS),
        Err(DeviceFault::CallFailed {
            call: "fakeGetPosition",
            code: -1
        })
    );
    assert_eq!(g.display(2 * MS, f, 1.0), Vec3::zeros());
    assert_eq!(last(&log), Command::Release);
    let trip = g.last_trip().expect("tripped");
    assert_eq!((trip.limit, trip.at_ns), (Limit::Fault, 2 * MS));
}

#[test]
fn a_stale_world_releases_and_close_and_drop_release_and_close() {
    let (d, log, _) = fake(20.0);
    let mut g = Guarded::new(d, limits(), 0);
    let f = Vec3::new(1.0, 0.0, 0.0);
    tick(&mut g, MS, f);
    let _ = g.sample(2 * MS);
    assert_eq!(
        g.display(2 * MS, f, 0.0),
        Vec3::zeros(),
        "scale 0: stale world"
    );
    assert_eq!(last(&log), Command::Release);
    tick(&mut g, 3 * MS, f);
    assert_eq!(last(&log), Command::Force(f), "fresh again");
    drop(g);
    let l = log.lock().expect("lock");
    assert_eq!(
        l.commands.last().map(|c| c.1),
        Some(Command::Release),
        "drop released"
    );
    assert!(l.closed, "and closed");
}

#[test]
fn the_simulated_arm_is_limp_after_its_guard_is_dropped_mid_push() {
    let sc = Scenario {
        site: vec![coop_model::scenario::SiteSpec {
            name: "a".into(),
            device_base_m: [-0.3, -0.2, 0.0],
            script: vec![coop_model::scenario::KeyframeSpec {
                t_s: 0.0,
                target_m: [-0.12, 0.0, 0.01],
            }],
            ..Default::default()
        }],
        ..Scenario::default()
    };
    let script = sc.script(0);
    let arm = SimScara::new(
        Plant::at(sc.arm(0), sc.hand(0), script[0].target, 1.0),
        sc.force_loop(0),
        script,
        0,
    );
    let mut g = Guarded::new(arm, limits(), 0);
    for k in 1..=200 {
        tick(&mut g, k * MS, Vec3::new(3.0, 0.0, 0.0));
    }
    assert!(g.device().tau().norm() > 0.1, "pushing");
    g.close(201 * MS);
    assert_eq!(g.device().tau(), Vec3::zeros(), "no torque once closed");
    assert_eq!(
        g.display(202 * MS, Vec3::new(3.0, 0.0, 0.0), 1.0),
        Vec3::zeros()
    );
    assert_eq!(g.device().tau(), Vec3::zeros(), "and none after");
}
