//! The station's loop processes, with this test as their supervisor: it creates the segments, starts
//! `station servo` and `station physics` as real processes, reads their reports as the network
//! process will, stops them cooperatively, and checks they exit cleanly — the servo limp — leaving no
//! segment behind. Also: a child refuses to start without its supervisor, and a bad configuration is
//! a clear error.

use std::process::Command;
use std::time::Duration;

use coop_actors::station::config::StationConfig;
use coop_rt::shm::control::{Child, ControlBlock, Ring, RunState};
use coop_rt::shm::station::RingSlots;
use coop_rt::shm::station::{Names, StationSegments};
use coop_rt::sync::Ordering;
use coop_tests::{shm_entries, station_config, unique_session, wait_until, Reaped};

const STATION: &str = env!("CARGO_BIN_EXE_station");
const LIMIT: Duration = Duration::from_secs(60);

fn config_file(session: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("coop-station-{session}"));
    station_config(&dir, session, "user1", |_| {})
}

fn spawn(what: &str, config: &std::path::Path, parent: u32) -> Reaped {
    Reaped::spawn(
        Command::new(STATION)
            .arg(what)
            .arg("--config")
            .arg(config)
            .arg("--parent")
            .arg(parent.to_string()),
    )
}

#[test]
fn servo_and_physics_processes_run_report_and_stop_limp() {
    let session = unique_session();
    let config = config_file(&session);
    let names = Names::of(&session, "user1").expect("names");
    let segs = StationSegments::create(&names, &RingSlots::default()).expect("segments");
    segs.control.set_run_state(RunState::Running);
    let me = std::process::id();
    let mut physics = spawn("physics", &config, me);
    let mut servo = spawn("servo", &config, me);
    let mut reports = segs.report.consumer().expect("report consumer");
    let mut decoded = 0;
    wait_until("both loops running and exchanging", LIMIT, || {
        while let Ok(r) = reports.pop() {
            assert!(r.report().is_some(), "a report that does not decode: {r:?}");
            decoded += 1;
        }
        let hb = |c| segs.control.child(c).heartbeat.load(Ordering::Relaxed);
        (hb(Child::Servo) > 300
            && hb(Child::Physics) > 300
            && segs.tool.indices().1 > 300
            && segs.object.indices().1 > 300
            && decoded > 20)
            .then_some(())
    });
    let ctl: &ControlBlock = &segs.control;
    assert_eq!(
        ctl.child(Child::Servo).pid.load(Ordering::Relaxed),
        u64::from(servo.pid())
    );
    assert_eq!(
        ctl.child(Child::Physics).pid.load(Ordering::Relaxed),
        u64::from(physics.pid())
    );
    assert!(ctl.servo.stats.snapshot().cycles > 300 && ctl.physics.stats.snapshot().cycles > 300);
    assert_eq!(
        ctl.servo.stats.snapshot().period_ns,
        1_666_667,
        "600 Hz, user1's servo rate in the paper scenario"
    );

    ctl.set_run_state(RunState::Stopping);
    let exited = |c: &mut Reaped| {
        wait_until("child exits after the stop", LIMIT, || {
            c.0.as_mut().and_then(|p| p.try_wait().ok().flatten())
        })
    };
    assert!(exited(&mut physics).success());
    assert!(exited(&mut servo).success());
    assert_eq!(
        ControlBlock::load_f64(&ctl.servo.scale),
        0.0,
        "the servo left limp"
    );
    assert_eq!(ControlBlock::load_f64(&ctl.servo.command_n), 0.0);
    drop(reports);
    drop(segs);
    assert!(
        shm_entries(&format!("coop_{session}_")).is_empty(),
        "segments left behind"
    );
    let _ = std::fs::remove_dir_all(config.parent().expect("dir"));
}

/// Ring drops are published where the producer counts them and shown by `station status`: a real
/// physics process pushing into a two-slot object ring that no servo drains drops nearly every
/// state, and status says so (it used to show 0 object and report drops whatever happened).
#[test]
fn a_full_ring_shows_as_drops_in_station_status() {
    let session = unique_session();
    let config = config_file(&session);
    let names = Names::of(&session, "user1").expect("names");
    let rings = RingSlots {
        object_slots: 2,
        ..RingSlots::default()
    };
    let segs = StationSegments::create(&names, &rings).expect("segments");
    segs.control.set_run_state(RunState::Running);
    let mut physics = spawn("physics", &config, std::process::id());
    let status = wait_until("status to show object drops", LIMIT, || {
        let s = coop_actors::station::status::read(&session, "user1", &[]).ok()?;
        (s.rings.drops["object"] > 50).then_some(s)
    });
    let drops = segs.control.physics.drops.get(Ring::Object);
    assert!(drops >= status.rings.drops["object"], "{drops}");
    assert_eq!(status.rings.drops["tool"], 0, "nothing pushed tool samples");
    let printed = status.to_string();
    assert!(printed.contains("drops: object "), "{printed}");
    segs.control.set_run_state(RunState::Stopping);
    wait_until("physics exits after the stop", LIMIT, || {
        physics.0.as_mut().and_then(|p| p.try_wait().ok().flatten())
    });
    drop(segs);
    let _ = std::fs::remove_dir_all(config.parent().expect("dir"));
}

/// `station status` without `--config` looks for the defaults' station; when it is not there, the
/// error says which it looked for and lists the stations that do run here.
#[test]
fn station_status_without_a_config_names_what_it_looked_for_and_what_runs() {
    let session = unique_session();
    let names = Names::of(&session, "user2").expect("names");
    let segs = StationSegments::create(&names, &RingSlots::default()).expect("segments");
    let o = Command::new(STATION)
        .arg("status")
        .output()
        .expect("station status");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success(),
        "the defaults' station does not run here"
    );
    assert!(
        err.contains("looked for station user1 of session local (the defaults)")
            && err.contains(&format!("session {session}: user2"))
            && err.contains("--config"),
        "{err}"
    );
    drop(segs);
}

#[test]
fn a_child_refuses_to_start_without_its_supervisor() {
    let session = unique_session();
    let config = config_file(&session);
    // Pid 1 is not our parent: the child must see that its supervisor is gone.
    let out = Command::new(STATION)
        .args(["physics", "--parent", "1", "--config"])
        .arg(&config)
        .output()
        .expect("run station");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("supervisor (pid 1) is gone"), "{err}");
    let _ = std::fs::remove_dir_all(config.parent().expect("dir"));
}

#[test]
fn a_bad_configuration_is_a_clear_error_and_creates_nothing() {
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-station-bad-{session}"));
    std::fs::create_dir_all(&dir).expect("dir");
    let path = dir.join("bad.toml");
    std::fs::write(
        &path,
        format!("session = \"{session}\"\nstation = \"nobody\"\n"),
    )
    .expect("write");
    let out = Command::new(STATION)
        .args(["servo", "--config"])
        .arg(&path)
        .output()
        .expect("run");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("station = \"nobody\": names no site") && err.contains("bad.toml"),
        "{err}"
    );
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    assert!(StationConfig::load(Some(&path)).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

/// One fixture per configuration rule: `station run` refuses it, naming the file, the field and the
/// value, and creates no segment (H8).
#[test]
fn every_bad_configuration_fixture_is_refused_with_its_field() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/station");
    let expected: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("expected.json")).expect("expected.json"),
    )
    .expect("json");
    let before = shm_entries("coop_local_");
    for (file, needle) in expected.as_object().expect("object") {
        let out = Command::new(STATION)
            .arg("run")
            .arg("--config")
            .arg(dir.join(file))
            .output()
            .expect("run");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{file}: accepted");
        assert!(
            err.contains(needle.as_str().expect("string")),
            "{file}: stderr lacks {needle}:\n{err}"
        );
        assert!(
            err.contains(file.as_str()),
            "{file}: the message names the file:\n{err}"
        );
    }
    assert_eq!(
        shm_entries("coop_local_"),
        before,
        "a refused configuration created segments"
    );
}
