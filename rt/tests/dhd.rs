//! The DHD backend against a fake `libdhd.so` (`fixtures/fake_dhd.c`) that each test compiles with
//! `cc` into its own directory and the backend loads at run time, as it would the SDK: library
//! missing, no device, a call failing mid-run, the normal exchange, and the servo side allocating
//! nothing.

mod common;

use std::path::{Path, PathBuf};

use coop_model::body::Vec3;
use coop_rt::device::dhd::{probe, DhdConfig, DhdDevice, DhdError};
use coop_rt::device::{CartesianDevice, Command, DeviceFault};

use common::counting_alloc::allocations_during;
#[path = "common/fake_dhd.rs"]
mod fake_dhd;
use fake_dhd::Fake;

#[test]
fn library_missing_is_one_error_naming_the_file_and_the_field() {
    let c = DhdConfig {
        library: Some(PathBuf::from("/nonexistent/sdk/lib/libdhd.so.3")),
        ..DhdConfig::default()
    };
    let msg = DhdDevice::open(&c).expect_err("missing").to_string();
    assert!(msg.contains("/nonexistent/sdk/lib/libdhd.so.3"), "{msg}");
    assert!(msg.contains("device.dhd.library"), "{msg}");
    assert_eq!(msg.lines().count(), 1, "{msg}");
    // The default search, on a machine without the SDK, says what it looked for.
    match DhdDevice::open(&DhdConfig::default()) {
        Err(e @ DhdError::LibraryMissing { .. }) => {
            let msg = e.to_string();
            assert!(
                msg.contains("libdhd.so") && msg.contains("device.dhd.library"),
                "{msg}"
            );
        }
        Err(e) => panic!("{e}"),
        Ok(_) => eprintln!("SKIPPED the default-search check: a DHD SDK is installed here"),
    }
    // A library that is not the SDK: names the missing entry point.
    let not_dhd = Path::new("libc.so.6");
    let e = DhdDevice::open(&DhdConfig {
        library: Some(not_dhd.to_path_buf()),
        ..DhdConfig::default()
    })
    .expect_err("not the SDK");
    assert!(matches!(e, DhdError::MissingSymbol { .. }), "{e}");
}

#[test]
fn no_device_is_refused_and_leaves_nothing_open() {
    let fake = Fake::build("nodev");
    fake.set("devices", 0.0);
    let e = DhdDevice::open(&fake.config()).expect_err("no device");
    assert!(
        matches!(
            e,
            DhdError::NoDevice {
                index: 0,
                count: 0,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("device.dhd.device_index"), "{e}");
    fake.set("devices", 1.0);
    let mut c = fake.config();
    c.device_index = 1;
    let e = DhdDevice::open(&c).expect_err("only one device");
    assert!(
        matches!(
            e,
            DhdError::NoDevice {
                index: 1,
                count: 1,
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(fake.get("open"), 0.0);
}

#[test]
fn normal_exchange_reads_the_device_and_displays_the_force() {
    let fake = Fake::build("normal");
    fake.set("dx", 0.001);
    let mut c = fake.config();
    c.watchdog_ms = 2.0;
    let mut dev = DhdDevice::open(&c).expect("opens");
    assert_eq!(dev.info().backend, "dhd");
    assert_eq!(dev.info().model, "omega.3");
    assert_eq!(dev.info().serial.as_deref(), Some("11234"));
    assert_eq!(dev.info().max_force_n, 12.0);
    assert_eq!(fake.get("watchdog"), 16.0, "2 ms in 125 µs units");
    assert_eq!(fake.get("force_enabled"), 1.0);
    assert_eq!(fake.force(), Vec3::zeros(), "zero force before enabling");

    for n in 0..5 {
        let s = dev.sample(1_000 + n).expect("sample");
        assert_eq!(s.t_ns, 1_000 + n);
        assert!((s.position_m - Vec3::new(0.01 + 0.001 * n as f64, -0.02, 0.03)).norm() < 1e-12);
        assert_eq!(s.velocity_m_s, Vec3::new(4.0, 0.0, 0.0));
        assert_eq!(s.buttons, 0b10);
    }
    let f = Vec3::new(1.0, -2.0, 0.5);
    dev.command(0, Command::Force(f)).expect("force");
    assert_eq!(fake.force(), f);
    dev.command(0, Command::Release).expect("release");
    assert_eq!(fake.force(), Vec3::zeros());
    assert_eq!(
        dev.command(0, Command::Force(Vec3::new(f64::NAN, 0.0, 0.0))),
        Err(DeviceFault::BadValue {
            what: "force command"
        })
    );
    assert_eq!(fake.force(), Vec3::zeros());
    dev.close();
    assert_eq!(fake.get("closed"), 1.0);
    assert_eq!(fake.get("force_enabled"), 0.0);
    assert_eq!(dev.sample(0), Err(DeviceFault::Disconnected));
    drop(dev);
    assert_eq!(fake.get("closed"), 1.0, "close is idempotent");
}

#[test]
fn a_falcon_describes_itself_as_one() {
    let fake = Fake::build("falcon");
    fake.set("system_type", 60.0);
    let dev = DhdDevice::open(&fake.config()).expect("opens");
    assert!(
        dev.info().model.contains("Novint Falcon"),
        "{}",
        dev.info().model
    );
    assert_eq!(dev.info().max_force_n, 8.0);
    assert_eq!(dev.info().workspace_radius_m, 0.04);
}

#[test]
fn a_call_failing_mid_run_is_a_fault_and_the_force_is_released() {
    let fake = Fake::build("midrun");
    fake.set("fail_call", 1.0);
    fake.set("fail_after", 50.0);
    let mut dev = DhdDevice::open(&fake.config()).expect("opens");
    let f = Vec3::new(0.0, 3.0, 0.0);
    let mut fault = None;
    for t in 0..100 {
        match dev.sample(t) {
            Ok(_) => {
                dev.command(t, Command::Force(f)).expect("force");
                assert_eq!(fake.force(), f);
            }
            Err(e) => {
                fault = Some((t, e));
                break;
            }
        }
    }
    let (t, e) = fault.expect("the 51st dhdGetPosition fails");
    assert_eq!(t, 50);
    assert_eq!(
        e,
        DeviceFault::CallFailed {
            call: "dhdGetPosition",
            code: 2
        }
    );
    assert_eq!(fake.force(), Vec3::zeros(), "released on the fault");

    // dhdSetForce failing (the USB link gone): the fault names it; the firmware watchdog, set at
    // open, is what drops the force then.
    let fake = Fake::build("midrun-force");
    fake.set("fail_call", 2.0);
    fake.set("fail_after", 10.0);
    let mut dev = DhdDevice::open(&fake.config()).expect("opens");
    assert!(fake.get("watchdog") > 0.0);
    let e = (0..20)
        .find_map(|t| dev.command(t, Command::Force(f)).err())
        .expect("a failure");
    assert_eq!(
        e,
        DeviceFault::CallFailed {
            call: "dhdSetForce",
            code: 2
        }
    );
}

#[test]
fn probe_lists_the_devices_the_library_finds() {
    let fake = Fake::build("probe");
    fake.set("devices", 2.0);
    let p = probe(&fake.config());
    assert!(p.built_in);
    assert_eq!(p.devices.len(), 2, "{}", p.status);
    assert!(p.status.contains("2 device(s)"), "{}", p.status);
    assert_eq!(fake.get("open"), 0.0, "probe closes what it opened");
    assert_eq!(fake.get("force_enabled"), 0.0, "probe enables no force");
}

#[test]
fn servo_side_sample_and_command_do_not_allocate() {
    let fake = Fake::build("alloc");
    fake.set("dx", 1e-6);
    let mut dev = DhdDevice::open(&fake.config()).expect("opens");
    let n = allocations_during(|| {
        for t in 0..20_000u64 {
            let s = dev.sample(t).expect("sample");
            let f = -100.0 * s.position_m;
            dev.command(t, Command::Force(f)).expect("force");
        }
    });
    assert_eq!(n, 0, "the servo side allocated");
}
