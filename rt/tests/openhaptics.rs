//! The OpenHaptics backend against the mock HD library (`rt/mock-hd`): what it refuses at open, its
//! servo step run in the HD scheduler's frames, the safety contract through [`Guarded`] with each
//! fault the mock can inject ending in zero force within the watchdog, a stalled scheduler turned
//! off by the thread that started it, and a servo path that allocates nothing.

use coop_model::body::Vec3;
use coop_rt::device::openhaptics::{probe, OpenHapticsDevice, OpenHapticsError};
use coop_rt::device::safety::{Guarded, Limit, SafetyLimits};
use coop_rt::device::{CartesianDevice, Command, DeviceFault};
use coop_rt::shm::{BlockSegment, SegmentName};
use coop_rt::stats::LoopStats;

mod common;
use common::counting_alloc::allocations_during;
#[path = "common/mock_hd.rs"]
mod mock_hd;
use mock_hd::Mock;

const HD_COMM_ERROR: f64 = 770.0; // 0x0302
const HD_CALIBRATION_NEEDS_UPDATE: f64 = 20481.0; // 0x5001
const HD_CALIBRATION_NEEDS_MANUAL_INPUT: f64 = 20482.0; // 0x5002

fn limits() -> SafetyLimits {
    SafetyLimits {
        ramp_in_s: 0.0,
        max_force_n: 8.0,
        max_velocity_m_s: 1.0,
        max_force_step_n: 100.0,
        watchdog_s: 0.05,
    }
}

#[test]
fn no_device_and_a_device_wanting_its_inkwell_are_refused_and_leave_nothing_initialised() {
    let (mock, _g) = Mock::lock();
    mock.set("devices", 0.0);
    let e = OpenHapticsDevice::open(&mock.config()).expect_err("no device");
    let msg = e.to_string();
    assert!(
        matches!(
            e,
            OpenHapticsError::CallFailed {
                call: "hdInitDevice",
                ..
            }
        ),
        "{msg}"
    );
    assert!(msg.contains("Touch Setup"), "the advice: {msg}");
    assert_eq!(mock.get("initialized"), 0.0);

    // A device that wants its stylus in the inkwell opens (the inkwell calibrates it once the
    // scheduler runs), and every tick is a calibration fault until it has.
    mock.reset();
    mock.set("calibration", HD_CALIBRATION_NEEDS_MANUAL_INPUT);
    let mut dev = OpenHapticsDevice::open(&mock.config()).expect("opens uncalibrated");
    let sched = dev.scheduler();
    let mut seen = Vec::new();
    let mut k = 0;
    sched
        .run_hd(None, &mut |now| {
            k += 1;
            if k == 10 {
                mock.set("calibration", 20480.0); // HD_CALIBRATION_OK: in the inkwell
            }
            seen.push(dev.sample(now).map(|_| ()));
            k < 20
        })
        .expect("runs");
    let uncalibrated = Err(DeviceFault::CallFailed {
        call: "hdCheckCalibration",
        code: 0x5002,
    });
    assert!(seen[..9].iter().all(|r| *r == uncalibrated), "{seen:?}");
    assert!(seen[10..].iter().all(Result::is_ok), "{seen:?}");
    drop(dev);

    // A device that asks for an update gets it, and opens.
    mock.reset();
    mock.set("calibration", HD_CALIBRATION_NEEDS_UPDATE);
    let dev = OpenHapticsDevice::open(&mock.config()).expect("opens after the update");
    assert_eq!(mock.get("calibration_updates"), 1.0);
    drop(dev);
    assert_eq!(mock.get("initialized"), 0.0, "dropped: disabled");
}

#[test]
fn the_servo_step_runs_in_the_schedulers_frames_and_its_force_is_displayed() {
    let (mock, _g) = Mock::lock();
    for (k, v) in [("x0", 10.0), ("y0", -20.0), ("z0", 5.0)] {
        mock.set(k, v);
    }
    let mut dev = OpenHapticsDevice::open(&mock.config()).expect("opens");
    let info = dev.info().clone();
    assert_eq!(info.backend, "openhaptics");
    assert!(info.model.contains("Touch"), "{}", info.model);
    assert_eq!(info.max_force_n, 0.88, "the continuous force, not the peak");
    assert!(
        (info.max_stiffness_n_per_m - 1260.0).abs() < 1e-9,
        "N/mm to N/m"
    );
    assert!(
        (info.workspace_radius_m - 0.035).abs() < 1e-9,
        "{}",
        info.workspace_radius_m
    );
    assert_eq!(info.native_rate_hz, 1000.0);
    assert_eq!(
        mock.get("force_ramping"),
        1.0,
        "the vendor's ramp behind ours"
    );
    assert_eq!(
        mock.get("max_force_clamping"),
        1.0,
        "the vendor's clamp behind ours"
    );
    assert_eq!(mock.get("force_output"), 1.0);
    // Outside the scheduler's frame the device is not ours to touch.
    assert_eq!(dev.sample(0), Err(DeviceFault::Disconnected));

    let sched = dev.scheduler();
    let name = SegmentName::new(&format!("ohs{}", std::process::id()), "t", "stats").expect("name");
    let stats = BlockSegment::<LoopStats>::create(&name).expect("stats segment");
    let f = Vec3::new(0.3, 0.0, -0.2);
    let mut seen = None;
    let mut ticks = 0u64;
    let mut allocations = 0;
    let summary = sched
        .run_hd(Some(&stats), &mut |now| {
            ticks += 1;
            allocations += allocations_during(|| {
                let s = dev.sample(now).expect("a sample in the frame");
                seen = Some(s.position_m);
                dev.command(now, Command::Force(f)).expect("force");
            });
            ticks < 200
        })
        .expect("runs");
    assert_eq!(summary.ticks, 200);
    assert_eq!(allocations, 0, "sample and command allocated");
    let p = seen.expect("sampled");
    assert!(
        (p - Vec3::new(0.010, -0.020, 0.005)).norm() < 1e-12,
        "mm to m: {p}"
    );
    assert_eq!(mock.force(), [0.3, 0.0, -0.2]);
    assert!(mock.get("frames") >= 200.0);
    assert_eq!(mock.get("reads_outside_frame"), 0.0);
    assert_eq!(mock.get("writes_outside_frame"), 0.0);
    assert_eq!(mock.get("scheduler_running"), 0.0, "stopped at the end");
    assert_eq!(mock.get("scheduled"), 0.0, "unscheduled at the end");
    let s = stats.snapshot();
    assert_eq!((s.cycles, s.period_ns), (200, 1_000_000));
    dev.close();
    assert_eq!(mock.get("force_output"), 0.0);
    assert_eq!(mock.get("initialized"), 0.0);
}

/// What a fault run left: the ticks from the injection to zero displayed force, the guard's last
/// fault and limit, and how the scheduler's run ended.
type FaultRun = (
    Option<u64>,
    Option<DeviceFault>,
    Option<Limit>,
    Result<(), OpenHapticsError>,
);

/// Runs the device under the safety contract, pushing 0.5 N each tick; `inject` is called once at
/// tick 100.
fn fault_run(mock: &Mock, inject: impl Fn(&Mock) + Sync) -> FaultRun {
    let dev = OpenHapticsDevice::open(&mock.config()).expect("opens");
    let sched = dev.scheduler();
    let mut g = Guarded::new(dev, limits(), 0);
    let f = Vec3::new(0.5, 0.0, 0.0);
    let (mut k, mut zero_at) = (0u64, None);
    let run = sched.run_hd(None, &mut |now| {
        k += 1;
        if k == 100 {
            assert_eq!(mock.force(), [0.5, 0.0, 0.0], "displayed before the fault");
            inject(mock);
        }
        let _ = g.sample(now);
        g.display(now, f, 1.0);
        if k > 100 && zero_at.is_none() && mock.force() == [0.0; 3] {
            zero_at = Some(k - 100);
        }
        k < 200
    });
    let fault = g.last_fault().map(|(f, _)| f);
    let trip = g.last_trip().map(|t| t.limit);
    g.close(0);
    (zero_at, fault, trip, run.map(|_| ()))
}

#[test]
fn each_injected_fault_ends_in_zero_force_within_the_watchdog() {
    let (mock, _g) = Mock::lock();
    let watchdog_ticks = (limits().watchdog_s * 1e3) as u64;
    // An HD error at the end of a frame (the link to the device lost): the device drops its
    // output, and the run ends with the output off (the station restarts the servo).
    let (_, _, _, run) = fault_run(mock, |m| {
        m.set("error_code", HD_COMM_ERROR);
        m.set("error_at_frame", m.get("frames") + 1.0);
    });
    let e = run.expect_err("the run ends");
    assert!(
        matches!(
            e,
            OpenHapticsError::CallFailed {
                call: "hdEndFrame",
                code: 0x0302,
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(mock.get("force_output"), 0.0);
    assert_eq!(mock.force(), [0.0; 3]);

    // An HD error the device keeps its output through (an invalid value) is the next sample's
    // fault: the safety layer releases, and the run goes on.
    mock.reset();
    let (zero, fault, trip, run) = fault_run(mock, |m| {
        m.set("error_code", 257.0); // HD_INVALID_VALUE
        m.set("error_at_frame", m.get("frames") + 1.0);
    });
    run.expect("the run goes on");
    assert!(
        zero.is_some_and(|t| t <= watchdog_ticks),
        "invalid value: zero at {zero:?}"
    );
    let invalid = DeviceFault::CallFailed {
        call: "hdEndFrame",
        code: 0x0101,
    };
    assert_eq!(fault, Some(invalid));
    assert_eq!(trip, Some(Limit::Fault));

    // The calibration lost mid-run (the stylus must go back in its inkwell).
    mock.reset();
    let (zero, fault, _, run) = fault_run(mock, |m| {
        m.set("calibration", HD_CALIBRATION_NEEDS_MANUAL_INPUT)
    });
    run.expect("the run goes on");
    assert!(
        zero.is_some_and(|t| t <= watchdog_ticks),
        "calibration: zero at {zero:?}"
    );
    let uncalibrated = DeviceFault::CallFailed {
        call: "hdCheckCalibration",
        code: 0x5002,
    };
    assert_eq!(fault, Some(uncalibrated));

    // The device's own over-force error: its output goes off, and the run ends.
    mock.reset();
    let (_, _, _, run) = fault_run(mock, |m| m.set("over_force", 1.0));
    let e = run.expect_err("the run ends");
    assert!(
        matches!(
            e,
            OpenHapticsError::CallFailed {
                call: "hdEndFrame",
                code: 0x0201,
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(mock.get("force_output"), 0.0);
    assert_eq!(mock.force(), [0.0; 3]);

    // The servo step panicking in the callback: caught there, the output off, the run ended.
    mock.reset();
    let (_, _, _, run) = fault_run(mock, |_| panic!("a servo step's bug"));
    assert_eq!(run, Err(OpenHapticsError::ServoPanicked));
    assert_eq!(mock.get("force_output"), 0.0);
    assert_eq!(mock.force(), [0.0; 3]);
    assert_eq!(mock.get("scheduler_running"), 0.0);
}

#[test]
fn a_stalled_scheduler_is_turned_off_by_the_thread_that_started_it() {
    let (mock, _g) = Mock::lock();
    let dev = OpenHapticsDevice::open(&mock.config()).expect("opens");
    let sched = dev.scheduler();
    let mut g = Guarded::new(dev, limits(), 0);
    let mut k = 0u64;
    let started = std::time::Instant::now();
    let e = sched
        .run_hd(None, &mut |now| {
            k += 1;
            if k == 50 {
                mock.set("stall", 1.0);
            }
            let _ = g.sample(now);
            g.display(now, Vec3::new(0.0, 0.5, 0.0), 1.0);
            true
        })
        .expect_err("stalled");
    assert!(matches!(e, OpenHapticsError::Stalled { .. }), "{e}");
    assert!(e.to_string().contains("stall_ms"), "{e}");
    assert_eq!(mock.get("force_output"), 0.0, "turned off");
    assert_eq!(mock.force(), [0.0; 3]);
    // It ended (no assertion on how fast: the machine may be loaded), and left nothing running.
    assert!(started.elapsed().as_secs() < 60);
    assert_eq!(mock.get("scheduler_running"), 0.0);
    g.close(0);
}

#[test]
fn probe_lists_the_device_and_enables_no_force() {
    let (mock, _g) = Mock::lock();
    let p = probe(&mock.config());
    assert!(p.built_in);
    assert_eq!(p.devices.len(), 1, "{}", p.status);
    assert!(p.devices[0].model.contains("Touch"), "{:?}", p.devices[0]);
    assert_eq!(
        mock.get("initialized"),
        0.0,
        "probe disables what it initialised"
    );
    assert_eq!(mock.get("force_output"), 0.0, "probe enables no force");
    mock.set("devices", 0.0);
    let p = probe(&mock.config());
    assert!(
        p.devices.is_empty() && p.status.contains("no device"),
        "{}",
        p.status
    );
}
