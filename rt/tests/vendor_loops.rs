//! The servo step with each vendor backend (Haply against its stand-in service, DHD against the fake
//! SDK, OpenHaptics against the mock HD library, its step run in the HD scheduler's callbacks),
//! through the station's device type and the safety layer, over real shared-memory rings with the
//! physics loop: it allocates nothing, and the device is commanded a force.

use coop_model::scenario::{KeyframeSpec, MethodName, Scenario, SiteSpec};
use coop_model::servo::Servo;
use coop_rt::device::dhd::DhdDevice;
use coop_rt::device::haply::{HaplyConfig, HaplyDevice};
use coop_rt::device::openhaptics::OpenHapticsDevice;
use coop_rt::device::safety::{Guarded, SafetyLimits};
use coop_rt::device::{CartesianDevice, Placement, StationDevice};
use coop_rt::msg::{ObjectSample, SiteReport, ToolSample};
use coop_rt::physics::{PhysicsLoop, PhysicsRings, PhysicsTiming};
use coop_rt::servo::ServoLoop;
use coop_rt::shm::{RingSegment, SegmentName};
use coop_rt::timer::monotonic_ns;

mod common;
use common::counting_alloc::allocations_during;
#[path = "common/fake_dhd.rs"]
mod fake_dhd;
#[path = "common/haply_service.rs"]
mod haply_service;
#[path = "common/mock_hd.rs"]
mod mock_hd;

const MS: u64 = 1_000_000;
/// Where the disk starts, and where both devices put the hand.
const OBJECT: [f64; 3] = [0.0, 0.0, 0.0099];

/// A servo and physics loop over real rings, the segments they live in kept with them.
struct Rig {
    servo: ServoLoop<StationDevice>,
    physics: PhysicsLoop,
    reports: coop_rt::shm::Consumer<SiteReport>,
    _segments: (
        RingSegment<ToolSample>,
        RingSegment<ObjectSample>,
        RingSegment<SiteReport>,
        RingSegment<SiteReport>,
    ),
}

impl Rig {
    /// One tick at `now`: physics, then the servo; the force commanded.
    fn step(&mut self, now: u64) -> f64 {
        // REAL-TIME: what a station's tick does (counted by the tests).
        self.physics.step(now);
        let f = self.servo.step(now, None).f_command.norm();
        while self.reports.pop().is_ok() {}
        f
    }
}

/// Steps servo and physics for `ticks` ms of `clock` time from `t0`, counting the servo's and
/// physics' allocations and the largest force commanded.
fn run(tag: &str, device: StationDevice, clock: impl Fn(u64) -> u64) -> (u64, f64) {
    let mut rig = rig(tag, device, clock(0));
    for k in 1..=10u64 {
        rig.step(clock(k));
    }
    let mut most = 0.0f64;
    let n = allocations_during(|| {
        for k in 11..=1500u64 {
            most = most.max(rig.step(clock(k)));
        }
    });
    rig.servo.guarded_mut().close(clock(1501));
    (n, most)
}

/// A servo on `device` and a physics loop at `t0`, a disk where the device puts the hand.
fn rig(tag: &str, device: StationDevice, t0: u64) -> Rig {
    let mut sc = Scenario::default();
    // A disk on a table, centred where the device's hand is (placement identity): the hand is in
    // contact from the start, so the servo commands a force.
    sc.objects[0].start_m = OBJECT;
    sc.world.planes[0].normal = [0.0, 0.0, 1.0];
    sc.world.planes[0].offset_m = 0.0;
    sc.site.push(SiteSpec {
        name: "a".into(),
        // The simulated arm's base, only for the scenario's own reach check: these devices ignore it.
        device_base_m: [-0.3, -0.2, 0.0],
        script: vec![KeyframeSpec {
            t_s: 0.0,
            target_m: OBJECT,
        }],
        ..SiteSpec::default()
    });
    sc.validate().expect("valid scenario");
    let session = format!("vl{}{tag}", std::process::id());
    let name = |w: &str| SegmentName::new(&session, "a", w).expect("name");
    let tool = RingSegment::<ToolSample>::create(&name("tool"), 64).expect("tool ring");
    let obj = RingSegment::<ObjectSample>::create(&name("obj"), 64).expect("object ring");
    let rep = RingSegment::<SiteReport>::create(&name("rep"), 64).expect("report ring");
    let rem = RingSegment::<SiteReport>::create(&name("rem"), 64).expect("remote ring");
    let world = sc.world();
    let servo = ServoLoop::new(
        Servo::new(sc.servo_params(0)),
        Guarded::new(device, SafetyLimits::default(), t0),
        Placement::IDENTITY,
        world,
        obj.consumer().expect("c"),
        tool.producer().expect("p"),
        t0,
    );
    let physics = PhysicsLoop::new(
        0,
        sc.method(0, MethodName::Paper),
        world,
        sc.start_copy(),
        PhysicsRings {
            tools: tool.consumer().expect("c"),
            remote: rem.consumer().expect("c"),
            objects: obj.producer().expect("p"),
            reports: rep.producer().expect("p"),
            trace: None,
            tracks_out: None,
            tracks_in: None,
        },
        PhysicsTiming {
            period_ns: MS,
            report_period_ns: 10 * MS,
            start_ns: t0,
            trace_period_ns: 5 * MS,
            report_seq: 0,
        },
    );
    let reports = rep.consumer().expect("c");
    Rig {
        servo,
        physics,
        reports,
        _segments: (tool, obj, rep, rem),
    }
}

#[test]
fn servo_steps_with_the_dhd_backend_allocate_nothing() {
    let fake = fake_dhd::Fake::build("vendorloop");
    for (k, v) in ["x0", "y0", "z0"].iter().zip(OBJECT) {
        fake.set(k, v);
    }
    let dev = DhdDevice::open(&fake.config()).expect("opens");
    let (n, most) = run("dhd", StationDevice::Other(Box::new(dev)), |k| k * MS);
    assert_eq!(n, 0, "dhd: servo/physics steps allocated {n} times");
    assert!(
        most > 0.0,
        "dhd: the device was commanded a force ({most} N)"
    );
    assert_eq!(fake.get("force_enabled"), 0.0, "closed at the end");
}

#[test]
fn servo_steps_with_the_haply_backend_allocate_nothing() {
    let Some(svc) = haply_service::Service::start(&["--quiet", "--position", "0,0,0.0099"]) else {
        return;
    };
    let cfg = HaplyConfig {
        url: svc.url(),
        ..HaplyConfig::default()
    };
    let mut dev = HaplyDevice::open(&cfg).expect("opens");
    assert!(dev.sample(monotonic_ns()).is_ok());
    // Real time, paced at 1 ms, so the bridge's samples stay fresh as on a station.
    let start = monotonic_ns();
    let (n, most) = run("haply", StationDevice::Other(Box::new(dev)), |k| {
        let t = start + k * MS;
        coop_rt::timer::sleep_until(t);
        t
    });
    assert_eq!(n, 0, "haply: servo/physics steps allocated {n} times");
    assert!(
        most > 0.0,
        "haply: the device was commanded a force ({most} N)"
    );
}

#[test]
fn servo_steps_in_the_hd_schedulers_callbacks_allocate_nothing() {
    let (mock, _g) = mock_hd::Mock::lock();
    // The stylus where the disk is (mm).
    for (k, v) in ["x0", "y0", "z0"].iter().zip(OBJECT) {
        mock.set(k, v * 1e3);
    }
    let dev = OpenHapticsDevice::open(&mock.config()).expect("opens");
    let sched = dev.scheduler();
    let mut rig = rig("hd", StationDevice::Other(Box::new(dev)), monotonic_ns());
    let (mut k, mut n, mut most) = (0u64, 0u64, 0.0f64);
    sched
        .run_hd(None, &mut |now| {
            k += 1;
            if k <= 10 {
                rig.step(now);
            } else {
                // Counted on the scheduler's thread, where the step runs.
                n += allocations_during(|| most = most.max(rig.step(now)));
            }
            k < 1500
        })
        .expect("the scheduler ran");
    assert_eq!(n, 0, "openhaptics: servo/physics steps allocated {n} times");
    assert!(
        most > 0.0,
        "openhaptics: the device was commanded a force ({most} N)"
    );
    rig.servo.guarded_mut().close(monotonic_ns());
    assert_eq!(mock.get("force_output"), 0.0, "closed at the end");
}
