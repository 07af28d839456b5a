//! A station driving a Touch through OpenHaptics (`device = "openhaptics"`, `loop = "vendor"`)
//! against the mock HD library (`rt/mock-hd`, compiled here with `rustc`), steered through
//! `COOP_MOCK_HD` and read back from the record it appends as the device is disabled
//! (`COOP_MOCK_HD_RECORD`): the servo step runs in the HD scheduler's frames, the contact force
//! reaches the device, a stop turns its force output off, and a scheduler that stalls is turned
//! off by the servo process, which the supervisor then restarts until it gives up.

#[path = "../../rt/tests/common/mock_hd.rs"]
mod mock_hd;

use std::collections::HashMap;
use std::io::Read;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

use coop_rt::shm::control::{ControlBlock, RunState};
use coop_rt::shm::{BlockSegment, SegmentName};
use coop_tests::{press_scenario, shm_entries, station_config, unique_session, wait_until, Reaped};
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;

const STATION: &str = env!("CARGO_BIN_EXE_station");
const LIMIT: Duration = Duration::from_secs(60);

/// A station on the mock Touch, its stylus held at (10, -20, 30) mm, placed so that this is world
/// (-0.03, 0, 0.01) m: inside the disk the wall holds.
struct Run {
    dir: PathBuf,
    session: String,
    cfg: PathBuf,
    record: PathBuf,
    station: Reaped,
    stderr: std::thread::JoinHandle<String>,
}

fn start(tag: &str, hooks: &str) -> Run {
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-hd-{tag}-{session}"));
    std::fs::create_dir_all(&dir).expect("dir");
    let lib = mock_hd::build_file(&dir);
    std::fs::write(
        dir.join("press.toml"),
        press_scenario("", "", "[{ t_s = 0.0, target_m = [-0.12, 0.0, 0.01] }]"),
    )
    .expect("scenario");
    let world = [-0.03, 0.0, 0.01];
    let cfg = station_config(&dir, &session, "user1", |c| {
        c.scenario = Some("press.toml".into());
        c.device.device = coop_actors::station::device::BackendName::Openhaptics;
        c.device.loop_owner = coop_actors::station::device::LoopOwner::Vendor;
        c.device.placement.translation_m = [world[0] - 0.01, world[1] + 0.02, world[2] - 0.03];
        c.device.safety.ramp_in_ms = 50.0;
        let mut t = toml::Table::new();
        t.insert("library".into(), lib.display().to_string().into());
        c.device.openhaptics = Some(t);
    });
    let record = dir.join("record.txt");
    let mut cmd = Command::new(STATION);
    cmd.arg("run")
        .arg("--config")
        .arg(&cfg)
        .env("COOP_MOCK_HD", format!("x0=10,y0=-20,z0=30,{hooks}"))
        .env("COOP_MOCK_HD_RECORD", &record)
        .stderr(Stdio::piped());
    let mut station = Reaped::spawn(&mut cmd);
    let mut err = station
        .0
        .as_mut()
        .and_then(|c| c.stderr.take())
        .expect("piped stderr");
    let stderr = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });
    Run {
        dir,
        session,
        cfg,
        record,
        station,
        stderr,
    }
}

/// The mock's records, one map per time the device was disabled.
fn records(path: &std::path::Path) -> Vec<HashMap<String, f64>> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .map(|l| {
            l.split_whitespace()
                .filter_map(|kv| kv.split_once('='))
                .map(|(k, v)| (k.to_owned(), v.parse().unwrap_or(f64::NAN)))
                .collect()
        })
        .collect()
}

#[test]
fn a_station_runs_its_servo_in_the_hd_scheduler_and_turns_the_force_off_on_sigterm() {
    let run = start("press", "");
    let name = SegmentName::new(&run.session, "user1", "ctl").expect("name");
    let ctl = wait_until("the control block", LIMIT, || {
        BlockSegment::<ControlBlock>::open(&name, Duration::from_secs(1)).ok()
    });
    wait_until("the station running", LIMIT, || {
        (ctl.run_state() == RunState::Running).then_some(())
    });
    wait_until("the device displaying the contact", LIMIT, || {
        (ControlBlock::load_f64(&ctl.servo.command_n) > 0.5).then_some(())
    });
    let v = coop_tests::station_status_json(STATION, &run.cfg);
    assert_eq!(v["device"]["backend"], "openhaptics", "{v}");
    assert!(
        v["device"]["model"]
            .as_str()
            .is_some_and(|m| m.contains("Touch")),
        "{v}"
    );
    // The scheduler's ticks are the servo's cycles, at its period.
    let stats = ctl.servo.stats.snapshot();
    assert!(
        stats.cycles > 0 && stats.period_ns == 1_000_000,
        "{stats:?}"
    );

    kill(Pid::from_raw(run.station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = run.station.finish();
    let stderr = run.stderr.join().expect("stderr reader");
    assert!(status.success(), "exit {status}; stderr:\n{stderr}");
    drop(ctl);
    assert!(shm_entries(&format!("coop_{}_", run.session)).is_empty());
    let recs = records(&run.record);
    assert_eq!(recs.len(), 1, "one servo, one device: {recs:?}\n{stderr}");
    let r = &recs[0];
    assert!(r["frames"] > 100.0, "{r:?}");
    assert_eq!(r["force_output"], 0.0, "turned off at the stop: {r:?}");
    assert_eq!([r["fx"], r["fy"], r["fz"]], [0.0; 3], "{r:?}");
    assert_eq!(r["writes_outside_frame"], 0.0, "{r:?}");
    assert_eq!(r["reads_outside_frame"], 0.0, "{r:?}");
    assert_eq!(
        (r["max_force_clamping"], r["force_ramping"]),
        (1.0, 1.0),
        "{r:?}"
    );
    let _ = std::fs::remove_dir_all(&run.dir);
}

#[test]
fn a_stalled_scheduler_is_turned_off_and_the_supervisor_gives_up_naming_it() {
    // Every servo's scheduler stalls after 200 frames (a hook applied at each start).
    let run = start("stall", "stall_at_frame=200");
    let (status, _) = run.station.finish();
    let stderr = run.stderr.join().expect("stderr reader");
    assert!(!status.success(), "the station gives up; stderr:\n{stderr}");
    assert!(
        stderr.contains("HD scheduler stopped calling the servo") && stderr.contains("stall_ms"),
        "{stderr}"
    );
    let recs = records(&run.record);
    assert!(recs.len() >= 2, "restarted: {recs:?}");
    for r in &recs {
        assert_eq!(r["force_output"], 0.0, "off after each stall: {r:?}");
        assert_eq!([r["fx"], r["fy"], r["fz"]], [0.0; 3], "{r:?}");
    }
    assert!(shm_entries(&format!("coop_{}_", run.session)).is_empty());
    let _ = std::fs::remove_dir_all(&run.dir);
}

/// `latency vendor` runs the HD scheduler of the mock's device beside our own loop and prints both
/// loops' figures (and the same as JSON): assertions on what is printed, never on timing.
#[test]
fn latency_vendor_measures_the_hd_scheduler_beside_our_loop() {
    let dir = std::env::temp_dir().join(format!("coop-hd-latency-{}", unique_session()));
    std::fs::create_dir_all(&dir).expect("dir");
    let lib = mock_hd::build_file(&dir);
    let json = dir.join("out.json");
    let out = Command::new(env!("CARGO_BIN_EXE_latency"))
        .args(["vendor", "-D", "1s", "--library"])
        .arg(&lib)
        .arg("--json")
        .arg(&json)
        .output()
        .expect("latency runs");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{stdout}\n{stderr}");
    for name in ["HD scheduler", "ours (clock_nanosleep)"] {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(name))
            .unwrap_or_else(|| panic!("no {name} line: {stdout}"));
        let ticks: u64 = line[name.len()..]
            .split_whitespace()
            .next()
            .and_then(|t| t.parse().ok())
            .expect("ticks");
        assert!(ticks > 0, "{line}");
    }
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("parses");
    assert_eq!(v[0]["loop"], "HD scheduler", "{v}");
    assert!(v[1]["late_us"]["p999"].is_u64(), "{v}");
    let _ = std::fs::remove_dir_all(&dir);
}
