//! A station driving a Haply Inverse3 (`device = "haply"`) through the stand-in Inverse Service
//! (`rt/tests/fixtures/haply_service.py`, a real WebSocket server in its own process): the station
//! places the device's cursor in the world by its `[device.placement]`, displays the contact force
//! on it within the device's maximum, and when the service vanishes mid-run it releases the device
//! and `station status` names the fault. Skipped when python3 lacks `websockets` (CI requires it).

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::Duration;

use coop_rt::device::safety::Limit;
use coop_rt::shm::control::{ControlBlock, RunState};
use coop_rt::shm::{BlockSegment, SegmentName};
use coop_rt::sync::{AtomicU64, Ordering};
use coop_tests::{press_scenario, shm_entries, station_config, unique_session, wait_until, Reaped};
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;

const STATION: &str = env!("CARGO_BIN_EXE_station");
const SERVICE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../rt/tests/fixtures/haply_service.py"
);
const LIMIT: Duration = Duration::from_secs(60);

/// The mock service, its port, and the largest force it was sent (f64 bits), read by a thread.
fn service() -> Option<(Reaped, u16, Arc<AtomicU64>)> {
    let mut child = Command::new("python3")
        .arg(SERVICE)
        .args(["--position", "0.01,-0.12,0.15"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("python3 runs");
    let mut out = BufReader::new(child.stdout.take().expect("stdout"));
    let mut first = String::new();
    out.read_line(&mut first).expect("the mock's first line");
    let Some(port) = first.trim().strip_prefix("PORT ").map(str::to_owned) else {
        let _ = child.wait();
        assert!(
            std::env::var_os("COOP_REQUIRE_MCAP_PY").is_none(),
            "python3 with websockets is required (pip install websockets)"
        );
        eprintln!("SKIPPED: python3 -c 'import websockets' fails");
        return None;
    };
    let most = Arc::new(AtomicU64::new(0f64.to_bits()));
    let m = most.clone();
    std::thread::spawn(move || {
        for line in out.lines() {
            let Ok(line) = line else { break };
            if let Some(f) = line.strip_prefix("FORCE ") {
                let n = f
                    .split(' ')
                    .map(|x| x.parse::<f64>().unwrap_or(0.0).powi(2))
                    .sum::<f64>()
                    .sqrt();
                if n > f64::from_bits(m.load(Ordering::Relaxed)) {
                    m.store(n.to_bits(), Ordering::Relaxed);
                }
            }
        }
    });
    Some((Reaped(Some(child)), port.parse().expect("a port"), most))
}

#[test]
fn a_station_drives_a_haply_device_and_releases_it_when_the_service_vanishes() {
    let Some((mut svc, port, most)) = service() else {
        return;
    };
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-haply-{session}"));
    std::fs::create_dir_all(&dir).expect("dir");
    // A disk held against a wall at x = 4.5 cm; the cursor, placed in the world at x = -3 cm, keeps
    // pressing it there.
    std::fs::write(
        dir.join("press.toml"),
        press_scenario("", "", "[{ t_s = 0.0, target_m = [-0.12, 0.0, 0.01] }]"),
    )
    .expect("scenario");
    let cfg = station_config(&dir, &session, "user1", |c| {
        c.scenario = Some("press.toml".into());
        c.record = Some("user1.mcap".into());
        c.device.device = coop_actors::station::device::BackendName::Haply;
        // Device (0.01, -0.12, 0.15) m is world (-0.03, 0, 0.01) m.
        c.device.placement.translation_m = [-0.04, 0.12, -0.14];
        c.device.safety.ramp_in_ms = 50.0;
        let mut t = toml::Table::new();
        t.insert("url".into(), format!("ws://127.0.0.1:{port}").into());
        c.device.haply = Some(t);
    });
    let station = Reaped::spawn(Command::new(STATION).arg("run").arg("--config").arg(&cfg));
    let name = SegmentName::new(&session, "user1", "ctl").expect("name");
    let ctl = wait_until("the control block", LIMIT, || {
        BlockSegment::<ControlBlock>::open(&name, Duration::from_secs(1)).ok()
    });
    wait_until("the station running", LIMIT, || {
        (ctl.run_state() == RunState::Running).then_some(())
    });
    wait_until("the device displaying the contact", LIMIT, || {
        (f64::from_bits(most.load(Ordering::Relaxed)) > 0.5).then_some(())
    });
    let shown = f64::from_bits(most.load(Ordering::Relaxed));
    // The mock's Inverse3 reports 3 N as its maximum (HaplyConfig's default).
    assert!(
        shown <= 3.0 + 1e-9,
        "within the device's maximum: {shown} N"
    );
    // The service vanishes: the bridge's samples go stale and the safety layer releases.
    svc.kill();
    let _ = svc.wait_timeout(Duration::from_secs(5));
    wait_until("the device released for the fault", LIMIT, || {
        (Limit::from_code(ctl.servo.safety_limit.load(Ordering::Relaxed)) == Some(Limit::Fault)
            && ControlBlock::load_f64(&ctl.servo.command_n) == 0.0)
            .then_some(())
    });
    let v = coop_tests::station_status_json(STATION, &cfg);
    assert_eq!(v["servo"]["safety"]["limit"], "device fault", "{v}");
    assert_eq!(v["servo"]["safety"]["releases"], true);
    kill(Pid::from_raw(station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
    drop(ctl);
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    // The recording's tool is the cursor, placed in the world.
    let rec = coop_transport::recording::read(&dir.join("user1.mcap")).expect("recording");
    let placed = rec
        .samples
        .iter()
        .filter(|s| (s.tool_pos[0] + 0.03).abs() < 1e-9)
        .count();
    assert!(
        placed > 10 && (rec.samples[rec.samples.len() / 2].tool_pos[1]).abs() < 1e-9,
        "tool at the placed cursor in {placed} of {} samples",
        rec.samples.len()
    );
    let _ = std::fs::remove_dir_all(&dir);
}
