//! `station run` with real processes: it comes up, keeps going through killed children,
//! stops on SIGTERM leaving nothing behind, its children die with it, a live station's name is
//! refused, a loop failing every start stops it, and a network that cannot come up leaves it running
//! degraded until it can; a recording station's restarts and device limits are in its recording's
//! `/log`, and a restarted network process continues the recording. Unique session names keep
//! parallel tests apart; every wait has a deadline; nothing asserts on timing.

use std::process::Command;
use std::time::Duration;

use coop_rt::shm::control::{Child, ControlBlock, RunState};
use coop_rt::shm::{BlockSegment, SegmentName};
use coop_rt::sync::Ordering;
use coop_tests::{press_scenario, shm_entries, station_config, unique_session, wait_until, Reaped};
use coop_transport::network::Tls;
use coop_transport::recording::{self, SampleMsg};
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;

const STATION: &str = env!("CARGO_BIN_EXE_station");
const LIMIT: Duration = Duration::from_secs(60);

fn config(session: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("coop-run-{session}"));
    station_config(&dir, session, "user1", |c| {
        c.supervisor.backoff_initial_ms = 20
    })
}

/// As [`config`], recording to `user1.mcap` next to the config; the config and the recording.
fn recording_config(session: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = std::env::temp_dir().join(format!("coop-run-{session}"));
    let rec = dir.join("user1.mcap");
    let cfg = station_config(&dir, session, "user1", |c| {
        c.supervisor.backoff_initial_ms = 20;
        c.record = Some(rec.clone());
    });
    (cfg, rec)
}

/// The recording at `rec` as it is now, once it holds a sample that passes `want` (read at most
/// every 100 ms: the station goes on writing it).
fn recorded_until(
    rec: &std::path::Path,
    what: &str,
    want: impl Fn(&SampleMsg) -> bool,
) -> coop_transport::recording::Recording {
    let mut last: Option<std::time::Instant> = None;
    wait_until(what, LIMIT, || {
        if last.is_some_and(|t| t.elapsed() < Duration::from_millis(100)) {
            return None;
        }
        last = Some(std::time::Instant::now());
        recording::read(rec)
            .ok()
            .filter(|r| r.samples.iter().any(&want))
    })
}

/// The `/log` lines of a recording that start with `prefix`.
fn logged<'a>(r: &'a coop_transport::recording::Recording, prefix: &str) -> Vec<&'a str> {
    r.logs
        .iter()
        .map(|l| l.text.as_str())
        .filter(|t| t.starts_with(prefix))
        .collect()
}

fn start(cfg: &std::path::Path) -> Reaped {
    Reaped::spawn(Command::new(STATION).arg("run").arg("--config").arg(cfg))
}

/// Opens the station's control block once it exists (read-only use: opening claims nothing).
fn control(session: &str) -> BlockSegment<ControlBlock> {
    let name = SegmentName::new(session, "user1", "ctl").expect("name");
    wait_until("the control block", LIMIT, || {
        BlockSegment::<ControlBlock>::open(&name, Duration::from_secs(1)).ok()
    })
}

fn beats(c: &ControlBlock, child: Child) -> u64 {
    c.child(child).heartbeat.load(Ordering::Relaxed)
}
fn pid(c: &ControlBlock, child: Child) -> u32 {
    c.child(child).pid.load(Ordering::Relaxed) as u32
}
fn alive(pid: u32) -> bool {
    kill(Pid::from_raw(pid as i32), None).is_ok()
        && !std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| s.contains(") Z "))
}
fn running(c: &ControlBlock) -> (u32, u32) {
    wait_until("servo and physics running", LIMIT, || {
        (c.run_state() == RunState::Running
            && beats(c, Child::Servo) > 50
            && beats(c, Child::Physics) > 50)
            .then(|| (pid(c, Child::Servo), pid(c, Child::Physics)))
    })
}

#[test]
fn runs_then_stops_on_sigterm_leaving_nothing() {
    let session = unique_session();
    let cfg = config(&session);
    let station = start(&cfg);
    let ctl = control(&session);
    let (servo, physics) = running(&ctl);
    // About five seconds of servo cycles at user1's 600 Hz.
    wait_until("5 s of servo cycles", LIMIT, || {
        (ctl.servo.stats.snapshot().cycles >= 3000).then_some(())
    });
    kill(Pid::from_raw(station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
    assert!(
        !alive(servo) && !alive(physics),
        "children outlived the station"
    );
    assert_eq!(
        ControlBlock::load_f64(&ctl.servo.scale),
        0.0,
        "the servo stopped limp"
    );
    drop(ctl);
    assert!(
        shm_entries(&format!("coop_{session}_")).is_empty(),
        "segments left behind"
    );
    let _ = std::fs::remove_dir_all(cfg.parent().expect("dir"));
}

/// ... and each restart is a `/log` line of the station's recording, naming the child and why it
/// went down (the network's own told by its successor, which goes on with the recording).
#[test]
fn killed_children_are_restarted_and_the_station_goes_on() {
    let session = unique_session();
    let (cfg, rec) = recording_config(&session);
    let station = start(&cfg);
    let ctl = control(&session);
    running(&ctl);
    for child in [Child::Servo, Child::Physics, Child::Network] {
        let old = pid(&ctl, child);
        kill(Pid::from_raw(old as i32), Signal::SIGKILL).expect("SIGKILL child");
        let new = wait_until("a restarted child", LIMIT, || {
            let p = pid(&ctl, child);
            (p != old && p != 0 && ctl.child(child).restarts.load(Ordering::Relaxed) == 1)
                .then_some(p)
        });
        let before = beats(&ctl, child);
        wait_until("the restarted child's heartbeat", LIMIT, || {
            (beats(&ctl, child) > before + 50).then_some(())
        });
        assert!(alive(new));
    }
    kill(Pid::from_raw(station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
    drop(ctl);
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    let r = recording::read(&rec).expect("the recording reads as one");
    for child in ["servo", "physics", "network"] {
        let lines = logged(
            &r,
            &format!("restart: the supervisor restarted the {child} process (restart 1 of this station run) after: {child} (pid "),
        );
        assert_eq!(
            lines.len(),
            1,
            "one line for the {child}'s restart: {:?}",
            r.logs
        );
    }
    let _ = std::fs::remove_dir_all(rec.parent().expect("dir"));
}

/// A recording station whose network process is SIGKILLed mid-run: its successor goes on in the
/// recording's next part instead of creating it anew. After the stop the recording reads as one,
/// with every sample the killed process had got to the disk, samples from after the restart, and
/// `/log` lines for the restart; a new run of the station on the same path starts a new recording.
#[test]
fn a_restarted_network_process_continues_the_recording() {
    let session = unique_session();
    let (cfg, rec) = recording_config(&session);
    let station = start(&cfg);
    let ctl = control(&session);
    running(&ctl);
    let before = recorded_until(&rec, "a second of samples recorded", |s| {
        ctl.epoch().is_some_and(|e| s.t_ns > e + 1_000_000_000)
    });
    let old = pid(&ctl, Child::Network);
    kill(Pid::from_raw(old as i32), Signal::SIGKILL).expect("SIGKILL network");
    let killed_ns = coop_rt::timer::monotonic_ns();
    wait_until("the restarted network", LIMIT, || {
        (pid(&ctl, Child::Network) != old
            && ctl.child(Child::Network).restarts.load(Ordering::Relaxed) == 1)
            .then_some(())
    });
    recorded_until(&rec, "a second of samples after the restart", |s| {
        s.t_ns > killed_ns + 1_000_000_000
    });
    kill(Pid::from_raw(station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
    drop(ctl);

    let r = recording::read(&rec).expect("the recording reads as one");
    assert_eq!(r.files.first(), Some(&rec), "its first part is still there");
    assert!(
        r.files.len() >= 2,
        "the restart began a part: {:?}",
        r.files
    );
    // The newest sample read while the file was being written may have had only its `/object`
    // half on the disk (its `/tool` half follows it in the file, and a sample is the two read as
    // one): every sample before it is whole.
    let whole = before.samples.len() - 1;
    assert_eq!(
        r.samples[..whole],
        before.samples[..whole],
        "every sample recorded before the kill is still there"
    );
    assert!(
        r.samples.iter().any(|s| s.t_ns > killed_ns + 1_000_000_000),
        "and samples from after the restart"
    );
    assert!(
        r.samples.windows(2).all(|w| w[0].t_ns < w[1].t_ns),
        "in time order, none twice"
    );
    assert!(r.status.is_some(), "the successor finished it");
    let restart = logged(
        &r,
        "restart: the supervisor restarted the network process (restart 1 of this station run)",
    );
    assert_eq!(restart.len(), 1, "{:?}", r.logs);
    assert_eq!(
        logged(&r, "station user1 recording again in session").len(),
        1,
        "{:?}",
        r.logs
    );
    assert_eq!(logged(&r, "station user1 started").len(), 1, "{:?}", r.logs);

    // A new run of the station on the same path: a new recording.
    let last_ns = r.samples.last().expect("samples").t_ns;
    let again = start(&cfg);
    let ctl = control(&session);
    running(&ctl);
    recorded_until(&rec, "the new run's samples", |s| s.t_ns > last_ns);
    kill(Pid::from_raw(again.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = again.finish();
    assert!(status.success(), "exit {status}");
    drop(ctl);
    let r2 = recording::read(&rec).expect("the new recording");
    assert_eq!(r2.files, std::slice::from_ref(&rec));
    assert!(
        r2.samples.iter().all(|s| s.t_ns > last_ns),
        "nothing of the earlier run"
    );
    assert!(logged(&r2, "restart:").is_empty(), "{:?}", r2.logs);
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    let _ = std::fs::remove_dir_all(rec.parent().expect("dir"));
}

#[test]
fn a_killed_supervisor_takes_its_children_and_the_next_run_cleans_up() {
    let session = unique_session();
    let cfg = config(&session);
    let mut first = start(&cfg);
    let ctl = control(&session);
    let (servo, physics) = running(&ctl);

    // A second station of the same name is refused while the first lives.
    let out = Command::new(STATION)
        .arg("run")
        .arg("--config")
        .arg(&cfg)
        .output()
        .expect("run");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("station user1 of session") && err.contains("already running"),
        "{err}"
    );

    first.kill();
    let _ = first.finish();
    wait_until("children to die with their supervisor", LIMIT, || {
        (!alive(servo) && !alive(physics)).then_some(())
    });
    drop(ctl);
    assert!(
        !shm_entries(&format!("coop_{session}_")).is_empty(),
        "a crash leaves stale segments"
    );

    let second = start(&cfg);
    let ctl = control(&session);
    running(&ctl);
    kill(Pid::from_raw(second.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = second.finish();
    assert!(status.success(), "exit {status}");
    drop(ctl);
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    let _ = std::fs::remove_dir_all(cfg.parent().expect("dir"));
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .expect("bind")
        .local_addr()
        .expect("addr")
        .port()
}

/// Two stations started by hand in one session on loopback: each one's physics receives the
/// other's states over zenoh (and adopts them), through its network process and rings.
#[test]
fn two_stations_by_hand_see_each_other() {
    two_stations("tcp", |_| None);
}

/// The same over TLS, with the session CA and the sites' certificates made by `session certs`
/// (rcgen): each station listens and connects with its own site's certificate.
#[test]
fn two_stations_see_each_other_over_tls() {
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-tls-{session}"));
    let made = Command::new(env!("CARGO_BIN_EXE_session"))
        .arg("certs")
        .arg(coop_tests::scenario_path("paper.toml"))
        .args(["--session", &session, "--out"])
        .arg(&dir)
        .output()
        .expect("session certs");
    assert!(
        made.status.success(),
        "making the test certificates: {}",
        String::from_utf8_lossy(&made.stderr)
    );
    two_stations("tls", |me| {
        let (cert, key) = (dir.join(format!("{me}.pem")), dir.join(format!("{me}.key")));
        Some(Tls {
            root_ca_certificate: Some(dir.join("ca.pem")),
            listen_certificate: Some(cert.clone()),
            listen_private_key: Some(key.clone()),
            connect_certificate: Some(cert),
            connect_private_key: Some(key),
            ..Tls::default()
        })
    });
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two stations, `user2` connecting to `user1` with `scheme` (tcp or tls), each with the TLS files
/// `tls` gives for its name.
fn two_stations(scheme: &str, tls: impl Fn(&str) -> Option<Tls>) {
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-two-{session}"));
    std::fs::create_dir_all(&dir).expect("dir");
    let (pa, pb) = (free_port(), free_port());
    let write = |name: &str, listen: u16, connect: Option<u16>| {
        station_config(&dir, &session, name, |c| {
            c.network.listen = vec![format!("{scheme}/127.0.0.1:{listen}")];
            c.network.connect = connect
                .map(|c| format!("{scheme}/127.0.0.1:{c}"))
                .into_iter()
                .collect();
            c.network.tls = tls(name);
        })
    };
    let a = start(&write("user1", pa, None));
    let b = start(&write("user2", pb, Some(pa)));
    let open = |name: &str| {
        let n = SegmentName::new(&session, name, "ctl").expect("name");
        wait_until("a control block", LIMIT, || {
            BlockSegment::<ControlBlock>::open(&n, Duration::from_secs(1)).ok()
        })
    };
    let (ca, cb) = (open("user1"), open("user2"));
    wait_until("each physics to receive the other's states", LIMIT, || {
        let got = |c: &ControlBlock| {
            (
                c.network.received.load(Ordering::Relaxed),
                c.physics.received.load(Ordering::Relaxed),
                c.physics.adoptions.load(Ordering::Relaxed),
            )
        };
        let (ra, rb) = (got(&ca), got(&cb));
        (ra.0 > 20 && ra.1 > 20 && rb.0 > 20 && rb.1 > 20 && (ra.2 + rb.2) > 0).then_some(())
    });
    assert!(ca.network.refused.all().all(|(_, n)| n == 0));
    assert!(
        ca.network.published.load(Ordering::Relaxed) > 20
            && cb.network.published.load(Ordering::Relaxed) > 20
    );
    for s in [a, b] {
        kill(Pid::from_raw(s.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
        let (status, _) = s.finish();
        assert!(status.success(), "exit {status}");
    }
    drop((ca, cb));
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

/// While physics is down (SIGKILLed, then restarted by the supervisor), the servo's commanded force
/// ramps to zero within stale limit + ramp time of its newest object state — as the servo itself
/// recorded it, not as the test timed it.
#[test]
fn while_physics_is_down_the_servo_force_ramps_to_zero_in_time() {
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-stale-{session}"));
    std::fs::create_dir_all(&dir).expect("dir");
    // One user pressing a disk against a wall for the whole run.
    std::fs::write(
        dir.join("press.toml"),
        press_scenario(
            "",
            "stale_limit_ms = 100.0\nstale_ramp_ms = 50.0\n",
            "[{ t_s = 0.0, target_m = [-0.12, 0.0, 0.01] }, { t_s = 0.5, target_m = [-0.035, 0.0, 0.01] }]",
        ),
    )
    .expect("scenario");
    let cfg = station_config(&dir, &session, "user1", |c| {
        c.scenario = Some("press.toml".into());
        c.supervisor.backoff_initial_ms = 300;
    });
    let station = start(&cfg);
    let ctl = control(&session);
    let (_, physics) = running(&ctl);
    wait_until("the user pressing the disk", LIMIT, || {
        (ControlBlock::load_f64(&ctl.servo.command_n) > 0.3).then_some(())
    });
    kill(Pid::from_raw(physics as i32), Signal::SIGKILL).expect("SIGKILL physics");
    let (state_ns, limp_ns) = wait_until("the servo to record going limp", LIMIT, || {
        let (s, l) = (
            ctl.servo.stale_state_ns.load(Ordering::Relaxed),
            ctl.servo.stale_limp_ns.load(Ordering::Relaxed),
        );
        (s > 0 && l > 0).then_some((s, l))
    });
    // Stale limit 100 ms + ramp 50 ms, to the servo's tick: the stale state is seen at the first
    // tick (1 ms) past the limit, the ramp is 50 ticks of 1/50 (a 51st when the sum of the binary
    // fractions falls short of 1), and the tick that records zero wakes late by at most the
    // servo's largest wake-up lateness, as its own statistics have it.
    let took_ms = (limp_ns - state_ns) as f64 / 1e6;
    let late_ms = ctl.servo.stats.wake.max_ns.load(Ordering::Relaxed) as f64 / 1e6;
    assert!(
        took_ms <= 100.0 + 50.0 + 2.0 + late_ms,
        "force reached zero {took_ms} ms after the newest state (the servo woke late by up to {late_ms} ms)"
    );
    assert!(
        took_ms >= 100.0,
        "and not before the stale limit: {took_ms} ms"
    );
    wait_until("physics restarted", LIMIT, || {
        (pid(&ctl, Child::Physics) != physics
            && ctl.child(Child::Physics).restarts.load(Ordering::Relaxed) == 1)
            .then_some(())
    });
    kill(Pid::from_raw(station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
    drop(ctl);
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A loop child that fails on every start is restarted per policy, then the station stops with an
/// error naming the child and the policy, and leaves nothing behind. Here physics: once the station
/// runs its configuration file is gone (children read it at every start), and physics is killed.
#[test]
fn a_child_failing_every_start_stops_the_station_with_a_clear_error() {
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-crash-{session}"));
    let cfg = station_config(&dir, &session, "user1", |c| {
        c.supervisor.max_restarts = 2;
        c.supervisor.backoff_initial_ms = 20;
    });
    let mut station = Reaped::spawn(
        Command::new(STATION)
            .arg("run")
            .arg("--config")
            .arg(&cfg)
            .stderr(std::process::Stdio::piped()),
    );
    let ctl = control(&session);
    let (_, physics) = running(&ctl);
    std::fs::remove_file(&cfg).expect("remove the config");
    kill(Pid::from_raw(physics as i32), Signal::SIGKILL).expect("SIGKILL physics");
    let status = wait_until("the station to stop", LIMIT, || {
        station.0.as_mut().and_then(|p| p.try_wait().ok().flatten())
    });
    let mut err = String::new();
    if let Some(e) = station.0.as_mut().and_then(|p| p.stderr.as_mut()) {
        use std::io::Read;
        e.read_to_string(&mut err).expect("stderr");
    }
    assert!(!status.success(), "the station should fail: {err}");
    assert!(err.contains("reading station config"), "{err}");
    assert!(err.contains("child physics failed 3 times"), "{err}");
    assert!(
        err.contains("restart on-failure, at most 2 restarts"),
        "{err}"
    );
    drop(ctl);
    assert!(
        shm_entries(&format!("coop_{session}_")).is_empty(),
        "segments left behind"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A listen port that is taken is refused before anything starts, naming the field, the value and
/// the file (it used to crash-loop the network process until the policy stopped the station).
#[test]
fn a_taken_listen_port_is_refused_before_start() {
    let session = unique_session();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = taken.local_addr().expect("addr").port();
    let dir = std::env::temp_dir().join(format!("coop-taken-{session}"));
    let cfg = station_config(&dir, &session, "user1", |c| {
        c.network.listen = vec![format!("tcp/127.0.0.1:{port}")];
    });
    let out = Command::new(STATION)
        .arg("run")
        .arg("--config")
        .arg(&cfg)
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "accepted: {err}");
    assert!(
        err.contains(&format!(
            "network.listen contains \"tcp/127.0.0.1:{port}\": cannot listen there now"
        )) && err.contains(&cfg.display().to_string()),
        "{err}"
    );
    assert!(
        !err.contains("running servo"),
        "refused before anything started: {err}"
    );
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    drop(taken);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The network cannot come up (client mode, its router not there yet: zenoh's open fails): the
/// station runs on locally, degraded — servo and physics running, their cycles going on — while
/// the network process is restarted; status and stderr say so. Once something a client can reach
/// listens on that locator (a second station, a zenoh peer), the network comes up: heartbeat moving,
/// locators shown, restarts no longer growing, and the stations see each other.
#[test]
fn a_network_that_cannot_come_up_degrades_the_station_until_it_can() {
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-degraded-{session}"));
    let port = free_port();
    let locator = format!("tcp/127.0.0.1:{port}");
    let a_cfg = station_config(&dir, &session, "user1", |c| {
        c.network.mode = coop_transport::network::Mode::Client;
        c.network.connect = vec![locator.clone()];
        c.supervisor.backoff_initial_ms = 20;
        c.supervisor.network_backoff_max_ms = 200;
    });
    let a_err = dir.join("user1.err");
    let a = Reaped::spawn(
        Command::new(STATION)
            .arg("run")
            .arg("--config")
            .arg(&a_cfg)
            .stderr(std::fs::File::create(&a_err).expect("stderr file")),
    );
    let ctl = control(&session);
    running(&ctl);
    let net = ctl.child(Child::Network);
    wait_until("the network restarted a few times", LIMIT, || {
        (net.restarts.load(Ordering::Relaxed) >= 3).then_some(())
    });
    let sites = ["user1".to_owned(), "user2".to_owned()];
    let read = || coop_actors::station::status::read(&session, "user1", &sites).expect("status");
    let s0 = wait_until("status showing the station degraded", LIMIT, || {
        Some(read()).filter(|s| s.degraded)
    });
    assert!(s0.running && s0.run_state == "running", "{s0}");
    assert!(
        s0.loops.servo.rate_hz > 0.0 && s0.loops.physics.rate_hz > 0.0,
        "{s0}"
    );
    let n = &s0.children[2];
    assert_eq!((n.name, n.health), ("network", "down"), "{s0}");
    assert!(n.restarts >= 3 && n.down_s.is_some(), "{s0}");
    assert!(
        n.last_failure
            .as_deref()
            .is_some_and(|f| f.contains("network (pid")),
        "{s0}"
    );
    assert_eq!(s0.children[0].health, "up", "{s0}");
    let printed = s0.to_string();
    assert!(
        printed.contains("DEGRADED") && printed.contains("network down for"),
        "{printed}"
    );
    let json = s0.to_json();
    assert_eq!(json["degraded"], true);
    assert_eq!(json["children"][2]["health"], "down");
    let s1 = wait_until("servo and physics cycles going on", LIMIT, || {
        Some(read()).filter(|s| {
            s.loops.servo.cycles > s0.loops.servo.cycles + 100
                && s.loops.physics.cycles > s0.loops.physics.cycles + 100
        })
    });
    assert!(s1.degraded && s1.running, "{s1}");
    assert_eq!(s1.children[0].restarts + s1.children[1].restarts, 0, "{s1}");

    // Now a peer a client can connect to listens there.
    let b_cfg = station_config(&dir, &session, "user2", |c| {
        c.network.listen = vec![locator.clone()];
    });
    let b = start(&b_cfg);
    let up = wait_until("the network up: healthy, locators shown", LIMIT, || {
        let s = read();
        (!s.degraded && s.children[2].health == "up" && !s.network.locators.is_empty()).then_some(s)
    });
    assert!(up.network.locators.contains(&locator), "{up}");
    let restarts = net.restarts.load(Ordering::Relaxed);
    let beat = net.heartbeat.load(Ordering::Relaxed);
    wait_until("the stations to see each other", LIMIT, || {
        (ctl.network.received.load(Ordering::Relaxed) > 20
            && ctl.physics.received.load(Ordering::Relaxed) > 20)
            .then_some(())
    });
    wait_until("the network's heartbeat moving", LIMIT, || {
        (net.heartbeat.load(Ordering::Relaxed) > beat + 50).then_some(())
    });
    assert_eq!(
        net.restarts.load(Ordering::Relaxed),
        restarts,
        "restarts stopped growing"
    );
    for s in [a, b] {
        kill(Pid::from_raw(s.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
        let (status, _) = s.finish();
        assert!(status.success(), "exit {status}");
    }
    let err = std::fs::read_to_string(&a_err).expect("stderr");
    let entered = err.find("station user1: DEGRADED: the network process is down");
    let left = err.find("station user1: no longer degraded: the network process is up again");
    assert!(
        entered.is_some() && left.is_some() && entered < left,
        "one line entering, one leaving degraded mode:\n{err}"
    );
    assert_eq!(err.matches("DEGRADED").count(), 1, "{err}");
    drop(ctl);
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_restarted_physics_resumes_from_its_last_state_and_report_sequence() {
    let session = unique_session();
    let cfg = config(&session);
    let station = start(&cfg);
    let ctl = control(&session);
    running(&ctl);
    let epoch = wait_until("the session's time 0", LIMIT, || ctl.epoch());
    // The embedded paper scenario: user1 pushes the disk from x = -5 cm at 1 s; it slides and comes
    // to rest before user1 comes back at 3 s.
    let (before, seq) = wait_until("the pushed disk at rest", LIMIT, || {
        let s = ctl.resume()?.samples[0];
        let t = s.t_ns.saturating_sub(epoch) as f64 * 1e-9;
        (t > 2.2 && s.pos[0] > 0.0).then(|| (s, ctl.physics.report_seq.load(Ordering::Relaxed)))
    });
    let old = pid(&ctl, Child::Physics);
    kill(Pid::from_raw(old as i32), Signal::SIGKILL).expect("SIGKILL physics");
    let killed_at = coop_rt::timer::monotonic_ns();
    let after = wait_until("a state from the restarted physics", LIMIT, || {
        ctl.resume()
            .map(|r| r.samples[0])
            .filter(|s| s.t_ns > killed_at && pid(&ctl, Child::Physics) != old)
    });
    assert!(
        (after.pos[0] - before.pos[0]).abs() < 0.01,
        "resumed at x = {} m, not where it was (x = {} m; the scenario starts it at -0.05)",
        after.pos[0],
        before.pos[0]
    );
    assert!(
        ctl.physics.report_seq.load(Ordering::Relaxed) > seq,
        "the report sequence continued"
    );
    kill(Pid::from_raw(station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
    let _ = std::fs::remove_dir_all(cfg.parent().expect("dir"));
}

/// A device safety limit that acts on a real station is named by `station status`, with when it
/// acted: here the force clamp, set below what the user pressing a disk against a wall asks for.
/// Its device section says what the device is and did: the simulated arm's samples at the servo's
/// rate, its commands, and the clamp among its safety trips.
#[test]
fn station_status_names_the_device_limit_that_acted_last() {
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-limit-{session}"));
    std::fs::create_dir_all(&dir).expect("dir");
    std::fs::write(
        dir.join("press.toml"),
        press_scenario(
            "[display]\nenabled = true\n",
            "",
            "[{ t_s = 0.0, target_m = [-0.12, 0.0, 0.01] }, { t_s = 0.5, target_m = [-0.035, 0.0, 0.01] }]",
        ),
    )
    .expect("scenario");
    let rec = dir.join("user1.mcap");
    let cfg = station_config(&dir, &session, "user1", |c| {
        c.scenario = Some("press.toml".into());
        c.device.safety.max_force_n = 0.2;
        c.record = Some(rec.clone());
    });
    let station = start(&cfg);
    let ctl = control(&session);
    running(&ctl);
    wait_until("the force clamp to act", LIMIT, || {
        (ctl.servo.safety_limit.load(Ordering::Relaxed) != 0).then_some(())
    });
    wait_until("the device's rates measured", LIMIT, || {
        (ControlBlock::load_f64(&ctl.device.sample_rate_hz) > 0.0).then_some(())
    });
    let v = coop_tests::station_status_json(STATION, &cfg);
    let s = &v["servo"]["safety"];
    assert_eq!(s["limit"], "max_force_n", "{v}");
    assert_eq!(s["releases"], false);
    assert!(
        s["at_ns"].as_u64() > Some(0) && s["ago_s"].as_f64() >= Some(0.0),
        "{s}"
    );
    assert!(
        ControlBlock::load_f64(&ctl.servo.command_n) <= 0.2 + 1e-9,
        "the command stays within the clamp"
    );
    let dev = &v["device"];
    assert_eq!(dev["backend"], "sim", "{v}");
    assert_eq!(dev["model"], "SCARA (simulated)", "{dev}");
    assert!(dev["samples"].as_u64() > Some(0), "{dev}");
    assert!(dev["new_samples"].as_u64() > Some(0), "{dev}");
    assert!(dev["commands"].as_u64() > Some(0), "{dev}");
    assert!(dev["sample_rate_hz"].as_f64() > Some(0.0), "{dev}");
    assert_eq!(dev["faults"]["total"], 0, "{dev}");
    assert!(dev["faults"]["last"].is_null(), "{dev}");
    assert!(
        dev["bridge"].is_null(),
        "the simulated arm has no bridge: {dev}"
    );
    assert!(dev["trips"]["max_force_n"].as_u64() >= Some(1), "{dev}");
    // The display stages (on in this scenario) publish too: the press stepped the force.
    let d = &v["servo"]["display"];
    assert!(d["max_step_n"].as_f64() > Some(0.0), "{d}");
    for key in [
        "corrections",
        "ticks_limited",
        "ticks_damped",
        "energy_j",
        "max_energy_j",
    ] {
        assert!(d[key].is_number(), "{key} missing: {d}");
    }
    let text = Command::new(STATION)
        .args(["status", "--config"])
        .arg(&cfg)
        .output()
        .expect("status");
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(
        text.contains("safety: limit max_force_n clamped last"),
        "{text}"
    );
    assert!(
        text.contains(" corrections blended; step limiter held "),
        "{text}"
    );
    assert!(text.contains("\ndevice: sim SCARA (simulated)"), "{text}");
    assert!(
        text.contains("safety trips (episodes): max_force_n "),
        "{text}"
    );
    kill(Pid::from_raw(station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
    drop(ctl);
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    // The station's recording logged the clamp acting, as a warning.
    let r = recording::read(&rec).expect("the recording");
    let clamp: Vec<_> = r
        .logs
        .iter()
        .filter(|l| l.text.starts_with("safety limit max_force_n clamped ("))
        .collect();
    assert!(!clamp.is_empty(), "{:?}", r.logs);
    assert!(
        clamp.iter().all(|l| l.level == recording::Level::Warning),
        "{clamp:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Without the privileges its loops ask for (here as `nobody`, through setpriv), a station says so
/// in one warning naming every missing privilege and its fix; its servo and physics do not say it
/// again, and run anyway. Only root can become `nobody` here: skipped otherwise.
#[test]
fn unprivileged_it_warns_once_naming_every_missing_privilege() {
    use std::os::unix::fs::PermissionsExt;
    if !nix::unistd::geteuid().is_root() {
        eprintln!("SKIPPED: not root, so it cannot run a station as nobody");
        return;
    }
    if Command::new("setpriv").arg("--version").output().is_err() {
        eprintln!("SKIPPED: setpriv is not installed (util-linux); cannot drop root here");
        return;
    }
    let session = unique_session();
    let dir = std::env::temp_dir().join(format!("coop-unprivileged-{session}"));
    // Everything it asks for: memory locked, /dev/cpu_dma_latency held, SCHED_FIFO (at the
    // default priorities).
    let cfg = station_config(&dir, &session, "user1", |c| {
        c.mlockall = true;
        c.cpu_dma_latency_zero = true;
        for l in [&mut c.servo, &mut c.physics] {
            l.policy = "fifo".into();
            l.priority = None;
        }
    });
    // The build tree may not be reachable by nobody: a copy of the binary, next to the
    // configuration, in a directory nobody may use.
    let bin = dir.join("station");
    std::fs::copy(STATION, &bin).expect("copy the station binary");
    for (p, mode) in [(&dir, 0o777), (&bin, 0o755), (&cfg, 0o644)] {
        std::fs::set_permissions(p, std::fs::Permissions::from_mode(mode)).expect("chmod");
    }
    // Root's limits pass down through setpriv: on a machine set up for real time (memlock
    // unlimited, rtprio 99) an unprivileged user could lock and run FIFO after all. The limits
    // of a user nobody set up make the case this tests.
    let out = Command::new("prlimit")
        .args(["--memlock=0", "--rtprio=0", "--", "setpriv"])
        .args([
            "--reuid=65534",
            "--regid=65534",
            "--clear-groups",
            "--inh-caps=-all",
        ])
        .arg(&bin)
        .args(["run", "--duration-s", "2", "--config"])
        .arg(&cfg)
        .current_dir(&dir)
        .output()
        .expect("setpriv runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "exit {}: {err}", out.status);
    let warns: Vec<&str> = err.lines().filter(|l| l.contains("WARN")).collect();
    assert_eq!(warns.len(), 1, "one warning for the station: {err}");
    for what in [
        "cannot lock memory",
        "cannot hold /dev/cpu_dma_latency at 0",
        "cannot set SCHED_FIFO",
        "CAP_IPC_LOCK",
        "CAP_SYS_NICE",
        "write access to /dev/cpu_dma_latency",
    ] {
        assert!(warns[0].contains(what), "{what} missing: {}", warns[0]);
    }
    assert!(
        shm_entries(&format!("coop_{session}_")).is_empty(),
        "segments left behind"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
