//! A station driving a Force Dimension device (`device = "dhd"`) through the fake DHD SDK
//! (`rt/tests/fixtures/fake_dhd.c`, compiled here with `cc`), whose `[device.dhd]` table names the
//! fake's file. The fake records every call the servo process makes (`COOP_FAKE_DHD_LOG`), and the
//! tests assert from that record: the firmware watchdog is armed before forces are enabled, the
//! contact force reaches the library, and a stop or a failing call releases the device. A device
//! that renders less stiffness than the scenario's contact shows the clamp in `station status`.

#[path = "../../rt/tests/common/fake_dhd.rs"]
mod fake_dhd;

use std::io::Read;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

use coop_rt::device::safety::Limit;
use coop_rt::shm::control::{ControlBlock, RunState};
use coop_rt::shm::{BlockSegment, SegmentName};
use coop_rt::sync::Ordering;
use coop_tests::{press_scenario, shm_entries, station_config, unique_session, wait_until, Reaped};
use fake_dhd::{record, Call, Fake};
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;

const STATION: &str = env!("CARGO_BIN_EXE_station");
const LIMIT: Duration = Duration::from_secs(60);

/// A running station on the fake DHD device, and what the test reads of it.
struct Run {
    dir: PathBuf,
    session: String,
    cfg: PathBuf,
    log: PathBuf,
    station: Reaped,
    ctl: BlockSegment<ControlBlock>,
    /// The station's stderr (its children's too), read to the end by a thread.
    stderr: std::thread::JoinHandle<String>,
    _fake: Fake,
}

/// Starts a station whose `[device.dhd]` points at a freshly built fake, the device placed so that
/// the fake's fixed position (0.01, -0.02, 0.03) m is `world` m; `env` steers the fake.
fn start(tag: &str, contact: &str, world: [f64; 3], env: &[(&str, String)]) -> Run {
    let fake = Fake::build(tag);
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-dhd-{session}"));
    std::fs::create_dir_all(&dir).expect("dir");
    // A disk held against a wall at x = 4.5 cm, `contact` added to the scenario (TOML lines).
    std::fs::write(
        dir.join("press.toml"),
        press_scenario(
            contact,
            "",
            "[{ t_s = 0.0, target_m = [-0.12, 0.0, 0.01] }]",
        ),
    )
    .expect("scenario");
    let log = dir.join("dhd-calls.log");
    let lib = fake.lib.clone();
    let cfg = station_config(&dir, &session, "user1", |c| {
        c.scenario = Some("press.toml".into());
        c.device.device = coop_actors::station::device::BackendName::Dhd;
        c.device.placement.translation_m = [world[0] - 0.01, world[1] + 0.02, world[2] - 0.03];
        c.device.safety.ramp_in_ms = 50.0;
        let mut t = toml::Table::new();
        t.insert("library".into(), lib.display().to_string().into());
        c.device.dhd = Some(t);
    });
    let mut cmd = Command::new(STATION);
    cmd.arg("run")
        .arg("--config")
        .arg(&cfg)
        .env("COOP_FAKE_DHD_LOG", &log)
        .stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
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
    let name = SegmentName::new(&session, "user1", "ctl").expect("name");
    let ctl = wait_until("the control block", LIMIT, || {
        BlockSegment::<ControlBlock>::open(&name, Duration::from_secs(1)).ok()
    });
    wait_until("the station running", LIMIT, || {
        (ctl.run_state() == RunState::Running).then_some(())
    });
    Run {
        dir,
        session,
        cfg,
        log,
        station,
        ctl,
        stderr,
        _fake: fake,
    }
}

impl Run {
    /// `station status --json`.
    fn status(&self) -> serde_json::Value {
        coop_tests::station_status_json(STATION, &self.cfg)
    }

    /// `station status` as text.
    fn status_text(&self) -> String {
        let out = Command::new(STATION)
            .args(["status", "--config"])
            .arg(&self.cfg)
            .output()
            .expect("status");
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    fn command_n(&self) -> f64 {
        ControlBlock::load_f64(&self.ctl.servo.command_n)
    }

    /// SIGTERM; the station exits cleanly, leaving no segment. Its stderr and the fake's record.
    fn stop(self) -> (String, Vec<Call>) {
        kill(Pid::from_raw(self.station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
        let (status, _) = self.station.finish();
        let stderr = self.stderr.join().expect("stderr reader");
        assert!(status.success(), "exit {status}; stderr:\n{stderr}");
        drop(self.ctl);
        assert!(shm_entries(&format!("coop_{}_", self.session)).is_empty());
        let calls = record(&self.log);
        let _ = std::fs::remove_dir_all(&self.dir);
        (stderr, calls)
    }
}

fn position(calls: &[Call], what: impl Fn(&Call) -> bool, about: &str) -> usize {
    calls
        .iter()
        .position(what)
        .unwrap_or_else(|| panic!("no {about} in the record: {:?}", head(calls)))
}

/// The first calls, for a failure message.
fn head(calls: &[Call]) -> &[Call] {
    &calls[..calls.len().min(12)]
}

/// The record ends with the device released and closed: zero force, forces disabled, closed (what
/// `DhdDevice::close` calls), after the safety layer's own zero-force release; nothing after.
fn assert_released_and_closed(calls: &[Call]) {
    let n = calls.len();
    assert!(n >= 4, "too short a record: {calls:?}");
    let tail: Vec<(&str, &[f64])> = calls[n - 3..]
        .iter()
        .map(|c| (c.name.as_str(), &c.args[..]))
        .collect();
    assert_eq!(
        tail,
        [
            ("dhdSetForce", &[0.0, 0.0, 0.0, 0.0][..]),
            ("dhdEnableForce", &[0.0, 0.0][..]),
            ("dhdClose", &[0.0][..]),
        ],
        "the record's end: {:?}",
        &calls[n.saturating_sub(6)..]
    );
    let last_force = calls
        .iter()
        .rposition(|c| c.name == "dhdSetForce" && c.result == 0)
        .expect("a force was set");
    assert!(
        !calls[last_force].is_nonzero_force(),
        "the last force the device kept is zero"
    );
    let opens = calls.iter().filter(|c| c.name == "dhdOpenID").count();
    let closes = calls.iter().filter(|c| c.name == "dhdClose").count();
    assert_eq!((opens, closes), (1, 1), "one servo opened and closed it");
}

/// The firmware watchdog (`dhdSetWatchdog`, 4 ms = 32 units by default) is armed before forces are
/// enabled, and no force but zero is sent before either: a servo killed at any point after enabling
/// leaves a device whose firmware drops the force.
fn assert_watchdog_armed_before_forces(calls: &[Call]) {
    let watchdog = position(calls, |c| c.name == "dhdSetWatchdog", "dhdSetWatchdog");
    assert_eq!(
        (calls[watchdog].args[0], calls[watchdog].result),
        (32.0, 0),
        "armed at 4 ms"
    );
    let enable = position(
        calls,
        |c| c.name == "dhdEnableForce" && c.args[0] == 1.0,
        "dhdEnableForce 1",
    );
    assert!(
        watchdog < enable,
        "watchdog armed (call {watchdog}) before forces enabled (call {enable})"
    );
    let first_force = position(calls, Call::is_nonzero_force, "a nonzero force");
    assert!(enable < first_force, "forces enabled before one is sent");
    assert!(
        !calls
            .iter()
            .any(|c| c.name == "dhdSetWatchdog" && c.args[0] == 0.0),
        "the watchdog is never disarmed"
    );
}

/// Pressing the disk against the wall, the device displays the contact force through the library,
/// and on SIGTERM the station releases and closes it.
#[test]
fn a_station_displays_contact_through_libdhd_and_releases_it_on_sigterm() {
    // The cursor sits at world (-0.03, 0, 0.01), in the disk the wall holds.
    let run = start("press", "", [-0.03, 0.0, 0.01], &[]);
    wait_until("the device displaying the contact", LIMIT, || {
        (run.command_n() > 0.5).then_some(())
    });
    let (stderr, calls) = run.stop();
    assert_watchdog_armed_before_forces(&calls);
    let forces: Vec<_> = calls
        .iter()
        .filter(|c| c.name == "dhdSetForce" && c.result == 0)
        .map(Call::force)
        .collect();
    let most = forces.iter().map(|f| f.norm()).fold(0.0, f64::max);
    // omega.3 (the fake's default system type): 12 N; the config's max_force_n: 10 N.
    assert!(
        most > 0.5 && most <= 10.0 + 1e-9,
        "the library got the contact force within the maxima: {most} N; stderr:\n{stderr}"
    );
    // The cursor sits inside the disk resting on the table: the contact pushes it up and out (+z
    // in the device frame, which is the world's rotated by nothing).
    let pressing: Vec<_> = forces.iter().filter(|f| f.norm() > 0.5).collect();
    assert!(
        pressing.iter().all(|f| f.z > f.x.abs().max(f.y.abs())),
        "{} pressing forces, all mostly +z: {:?}",
        pressing.len(),
        &pressing[..pressing.len().min(5)]
    );
    assert_released_and_closed(&calls);
}

/// `dhdGetPosition` starts failing mid-run (while the device displays a force): the backend and the
/// safety layer release it at once, `station status` names the device fault, and on SIGTERM the
/// device is still closed.
#[test]
fn a_call_failing_mid_run_releases_the_device_and_status_names_the_fault() {
    let fail = std::env::temp_dir().join(format!(
        "coop-dhd-fail-{}-{}",
        std::process::id(),
        unique_session()
    ));
    let _ = std::fs::remove_file(&fail);
    let run = start(
        "fault",
        "",
        [-0.03, 0.0, 0.01],
        &[
            ("COOP_FAKE_DHD_SET", "fail_call=1,fail_after=0".to_owned()),
            ("COOP_FAKE_DHD_FAIL_IF", fail.display().to_string()),
        ],
    );
    wait_until("the device displaying the contact", LIMIT, || {
        (run.command_n() > 0.5).then_some(())
    });
    std::fs::write(&fail, "").expect("fail the calls from now on");
    wait_until("the device released for the fault", LIMIT, || {
        (Limit::from_code(run.ctl.servo.safety_limit.load(Ordering::Relaxed)) == Some(Limit::Fault)
            && run.command_n() == 0.0)
            .then_some(())
    });
    let v = run.status();
    assert_eq!(v["servo"]["safety"]["limit"], "device fault", "{v}");
    assert_eq!(v["servo"]["safety"]["releases"], true, "{v}");
    assert_eq!(v["servo"]["command_n"], 0.0, "{v}");
    let text = run.status_text();
    assert!(
        text.contains("safety: limit device fault released the device last"),
        "{text}"
    );
    let (_, calls) = run.stop();
    let _ = std::fs::remove_file(&fail);
    let failed = position(
        &calls,
        |c| c.name == "dhdGetPosition" && c.result < 0,
        "a failed dhdGetPosition",
    );
    assert!(
        calls[..failed].iter().any(Call::is_nonzero_force),
        "a force was displayed before the failure"
    );
    let after: Vec<&Call> = calls[failed..]
        .iter()
        .filter(|c| c.name == "dhdSetForce")
        .collect();
    assert!(
        !after.is_empty() && after.iter().all(|c| !c.is_nonzero_force()),
        "only zero forces after the failure: {:?}",
        after.iter().find(|c| c.is_nonzero_force())
    );
    // In the failing call's tick, before the next dhdGetPosition: the backend releases at once, and
    // the safety layer, holding the device for the fault, releases it too.
    let tick = calls[failed + 1..]
        .iter()
        .position(|c| c.name == "dhdGetPosition")
        .map_or(&calls[failed + 1..], |n| &calls[failed + 1..failed + 1 + n]);
    assert!(
        tick.len() >= 2
            && tick
                .iter()
                .all(|c| c.name == "dhdSetForce" && !c.is_nonzero_force()),
        "the backend's and the safety layer's releases in the failing tick: {tick:?}"
    );
    assert_released_and_closed(&calls);
}

/// The fake reports a Novint Falcon (system type 60: 3000 N/m), stiffer than the scenario's contact
/// (4000 N/m): the servo renders the contact at the device's maximum, and `station status` names
/// the stiffness limit as clamped (the hand stays in free space, so no later limit replaces it).
#[test]
fn a_device_softer_than_the_contact_shows_the_stiffness_clamp_in_status() {
    let contact = "[contact]\nstiffness_n_per_m = 4000.0\ntangential_stiffness_n_per_m = 4000.0\n";
    let run = start(
        "falcon",
        contact,
        [-0.15, 0.0, 0.05],
        &[("COOP_FAKE_DHD_SET", "system_type=60".to_owned())],
    );
    wait_until("the stiffness clamp published", LIMIT, || {
        (run.ctl.servo.safety_limit.load(Ordering::Relaxed) != 0).then_some(())
    });
    let v = run.status();
    let s = &v["servo"]["safety"];
    assert_eq!(s["limit"], "max_stiffness", "{v}");
    assert_eq!(s["releases"], false, "{v}");
    assert!(s["at_ns"].as_u64() > Some(0), "{s}");
    let text = run.status_text();
    assert!(
        text.contains("safety: limit max_stiffness clamped last"),
        "{text}"
    );
    let (stderr, calls) = run.stop();
    assert!(
        stderr.contains(
            "contact stiffness 4000 N/m, damping 4.0 N·s/m clamped to the device's 3000 N/m, 4.0 N·s/m"
        ),
        "the servo says what it clamped to the Falcon's maximum:\n{stderr}"
    );
    assert!(
        calls
            .iter()
            .any(|c| c.name == "dhdGetSystemType" && c.result == 60),
        "the device's maxima came from the library's system type"
    );
    assert_released_and_closed(&calls);
}
