//! The Haply backend against a stand-in for the Inverse Service: `fixtures/haply_service.py`, a real
//! WebSocket server (the `websockets` package) on loopback speaking the service's JSON, run as its
//! own process. Covers the normal exchange, the service vanishing and coming back, a hung service
//! (stale samples), and a service answering garbage.
//!
//! CI installs `websockets` and sets `COOP_REQUIRE_MCAP_PY=1` (see .ci/run): then a missing package
//! fails these tests instead of skipping them.

mod common;

use std::time::{Duration, Instant};

use coop_model::body::Vec3;
use coop_rt::device::haply::{probe, HaplyConfig, HaplyDevice, HaplyOpenError};
use coop_rt::device::{CartesianDevice, Command, DeviceFault};
use coop_rt::timer::monotonic_ns;

use common::counting_alloc::allocations_during;
#[path = "common/haply_service.rs"]
mod haply_service;
use haply_service::{Event, Service, WAIT};

fn config(url: String) -> HaplyConfig {
    HaplyConfig {
        url,
        rate_hz: 500.0,
        ..HaplyConfig::default()
    }
}

/// Polls `f` (each poll is a servo tick at the current time) until it returns `Some`, or fails.
fn until<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let end = Instant::now() + WAIT;
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(Instant::now() < end, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn commanded_force_reaches_the_service_and_its_position_reaches_samples() {
    let Some(svc) = Service::start(&["--grip", "--position", "0.02,-0.11,0.16"]) else {
        return;
    };
    let mut dev = HaplyDevice::open(&config(svc.url())).expect("opens");
    assert_eq!(dev.info().backend, "haply");
    assert_eq!(dev.info().serial.as_deref(), Some("049D"));
    let s = dev.sample(monotonic_ns()).expect("fresh sample");
    assert_eq!(s.position_m, Vec3::new(0.02, -0.11, 0.16));
    assert_eq!(s.velocity_m_s, Vec3::new(0.001, 0.0, -0.002));
    assert_eq!(s.buttons, 0b101, "buttons a and c");
    assert!(s.orientation.is_some());

    // Before the servo commands anything, the bridge sends zero force.
    assert_eq!(svc.next(), Event::Force(Vec3::zeros()));
    let f = Vec3::new(1.0, -0.5, 0.25);
    dev.command(monotonic_ns(), Command::Force(f))
        .expect("fresh");
    let before = svc.wait_force(f);
    assert!(before.iter().all(|g| *g == Vec3::zeros()), "{before:?}");
    // The service reports it displays the force: the next samples carry it back.
    until("the displayed force to come back", || {
        dev.sample(monotonic_ns()).expect("fresh");
        (dev.displayed_force_n() == Some(f)).then_some(())
    });
    // Newest wins: the last of a burst of commands is what the service gets.
    for i in 1..=50 {
        let g = Vec3::new(f64::from(i) * 0.01, 0.0, 0.0);
        dev.command(monotonic_ns(), Command::Force(g))
            .expect("fresh");
    }
    svc.wait_force(Vec3::new(0.5, 0.0, 0.0));
    dev.command(monotonic_ns(), Command::Release)
        .expect("release");
    svc.wait_force(Vec3::zeros());
    assert!(
        dev.stats()
            .frames
            .load(std::sync::atomic::Ordering::Relaxed)
            > 0
    );
    dev.close();
}

#[test]
fn the_service_vanishing_reports_disconnected_and_a_return_starts_at_zero_force() {
    let Some(mut svc) = Service::start(&[]) else {
        return;
    };
    let port = svc.port.to_string();
    let mut cfg = config(svc.url());
    cfg.reconnect_ms = 50;
    let mut dev = HaplyDevice::open(&cfg).expect("opens");
    let f = Vec3::new(0.0, 0.0, 2.0);
    dev.command(monotonic_ns(), Command::Force(f))
        .expect("fresh");
    svc.wait_force(f);

    svc.kill();
    let fault = until("Disconnected", || dev.sample(monotonic_ns()).err());
    assert_eq!(fault, DeviceFault::Disconnected);
    // A force on a device we have lost is refused, and the slot holds a release.
    assert_eq!(
        dev.command(monotonic_ns(), Command::Force(f)),
        Err(DeviceFault::Disconnected)
    );
    // The bridge says why (the socket closed or reset), whether or not staleness told the servo first.
    let why = until("the bridge's account of the loss", || {
        dev.stats().last_error()
    });
    assert!(why.contains("service"), "{why}");
    assert!(!dev.stats().connected());

    // The service comes back on the same port: the bridge reconnects and sends zero force until the
    // servo commands again (the refused command above left a release in the slot; the bridge also
    // ignores whatever the slot held at the reconnection, a force included: see bridge.rs).
    let Some(svc2) = Service::start(&["--port", &port]) else {
        return;
    };
    until("samples again", || dev.sample(monotonic_ns()).ok());
    for _ in 0..20 {
        assert_eq!(svc2.next(), Event::Force(Vec3::zeros()));
    }
    // A servo samples before it commands: the command is checked against the newest sample.
    until("a fresh sample", || dev.sample(monotonic_ns()).ok());
    dev.command(monotonic_ns(), Command::Force(f))
        .expect("fresh again");
    let before = svc2.wait_force(f);
    assert!(before.iter().all(|g| *g == Vec3::zeros()), "{before:?}");
    assert!(
        dev.stats()
            .reconnects
            .load(std::sync::atomic::Ordering::Relaxed)
            >= 1
    );
}

#[test]
fn a_hung_service_goes_stale_exactly_at_the_stale_limit() {
    let Some(svc) = Service::start(&[]) else {
        return;
    };
    let mut cfg = config(svc.url());
    // Long enough that the bridge's own timeout does not fire first: staleness alone must tell.
    cfg.io_timeout_ms = 30_000;
    let mut dev = HaplyDevice::open(&cfg).expect("opens");
    until("a fresh sample", || dev.sample(monotonic_ns()).ok());
    svc.signal("-STOP");
    let fault = until("staleness", || dev.sample(monotonic_ns()).err());
    assert_eq!(fault, DeviceFault::Disconnected);
    // The service is stopped, so no frame arrives now: the verdict depends only on the clock given.
    let last = dev.last_sample();
    let limit = dev.stale_limit_ns();
    assert_eq!(dev.sample(last.t_ns + limit), Ok(last));
    assert_eq!(
        dev.sample(last.t_ns + limit + 1),
        Err(DeviceFault::Disconnected)
    );
    svc.signal("-CONT");
}

#[test]
fn garbage_from_the_service_is_refused_and_nothing_is_applied() {
    for kind in ["text", "nan", "schema"] {
        let Some(svc) = Service::start(&["--garbage-after", "30", "--garbage", kind]) else {
            return;
        };
        let mut dev = HaplyDevice::open(&config(svc.url())).expect("the snapshot is good");
        let f = Vec3::new(0.3, 0.0, 0.0);
        dev.command(monotonic_ns(), Command::Force(f))
            .expect("fresh");
        // Keep commanding the force, as a servo would, until the garbage shows as a fault.
        let fault = until("a refusal", || {
            let now = monotonic_ns();
            let _ = dev.command(now, Command::Force(f));
            dev.sample(now).err()
        });
        assert!(
            matches!(fault, DeviceFault::BadValue { .. }),
            "{kind}: {fault:?}"
        );
        // From the first garbage frame on, the service is sent zero force only.
        loop {
            if svc.next() == Event::Garbage {
                break;
            }
        }
        let mut after = 0;
        while after < 20 {
            let _ = dev.command(monotonic_ns(), Command::Force(f));
            if let Event::Force(g) = svc.next() {
                assert_eq!(g, Vec3::zeros(), "{kind}: a force after garbage");
                after += 1;
            }
        }
        assert!(
            dev.stats()
                .bad_frames
                .load(std::sync::atomic::Ordering::Relaxed)
                > 0
        );
        assert!(dev.stats().last_error().is_some_and(|e| !e.is_empty()));
    }
}

#[test]
fn a_garbage_snapshot_or_a_missing_device_refuses_to_open() {
    let Some(svc) = Service::start(&["--garbage-after", "0"]) else {
        return;
    };
    let e = HaplyDevice::open(&config(svc.url())).expect_err("garbage snapshot");
    assert!(matches!(e, HaplyOpenError::BadSnapshot { .. }), "{e}");
    assert!(
        svc.events
            .recv_timeout(Duration::from_millis(200))
            .map_or(true, |e| e == Event::Garbage),
        "nothing was commanded"
    );

    let Some(none) = Service::start(&["--no-devices"]) else {
        return;
    };
    let e = HaplyDevice::open(&config(none.url())).expect_err("no device");
    assert!(matches!(e, HaplyOpenError::NoDevice { .. }), "{e}");

    let Some(two) = Service::start(&["--second-device", "04A1"]) else {
        return;
    };
    let e = HaplyDevice::open(&config(two.url())).expect_err("ambiguous");
    assert!(matches!(e, HaplyOpenError::Ambiguous { .. }), "{e}");
    let mut cfg = config(two.url());
    cfg.device_id = Some("0FFF".into());
    let e = HaplyDevice::open(&cfg).expect_err("not listed");
    assert!(e.to_string().contains("device.haply.device_id"), "{e}");
    cfg.device_id = Some("04A1".into());
    let dev = HaplyDevice::open(&cfg).expect("the named one");
    assert_eq!(dev.info().serial.as_deref(), Some("04A1"));
    drop(dev);
    let p = probe(&config(two.url()));
    assert_eq!(p.devices.len(), 2, "{}", p.status);
    assert!(
        p.status.contains("049D") && p.status.contains("04A1"),
        "{}",
        p.status
    );
}

#[test]
fn servo_side_sample_and_command_do_not_allocate() {
    let Some(svc) = Service::start(&["--quiet"]) else {
        return;
    };
    let mut dev = HaplyDevice::open(&config(svc.url())).expect("opens");
    until("a fresh sample", || dev.sample(monotonic_ns()).ok());
    let mut ok = 0u32;
    let n = allocations_during(|| {
        for i in 0..20_000u32 {
            let now = monotonic_ns();
            if dev.sample(now).is_ok() {
                ok += 1;
            }
            let f = Vec3::new(f64::from(i % 7) * 0.01, 0.0, 0.0);
            let _ = dev.command(now, Command::Force(f));
            if i % 100 == 0 {
                std::hint::spin_loop();
            }
        }
    });
    assert_eq!(n, 0, "the servo side allocated");
    assert!(ok > 0);
    drop(svc);
}
