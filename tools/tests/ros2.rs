//! ROS 2 without ROS, checked by a ROS 2 user's own tools: `zenoh-ros2-sdk` (ROBOTIS) with the
//! message definitions inline and `rosbags`, in Python, against a real session of real stations
//! whose ROS 2 graph meets at a real zenoh router (`station router`, standing in for
//! `rmw_zenohd`).
//!
//! CI installs the packages and sets `COOP_REQUIRE_MCAP_PY=1` (see .ci/run): then a missing package
//! fails the test instead of skipping it.

use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use coop_tests::{repo, scenario_path, Reaped, TempDir};
use serde_json::Value;

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// A zenoh router on a free loopback port, as `rmw_zenohd` would be: its locator.
fn router(dir: &Path) -> (Reaped, String) {
    let locator = coop_transport::network::concrete_listen(&["tcp/127.0.0.1:0".into()]).remove(0);
    let config = dir.join("router.toml");
    std::fs::write(
        &config,
        format!(
            "name = \"ros\"\nlisten = [{locator:?}]\nstatus_file = {:?}\n",
            dir.join("router.json")
        ),
    )
    .expect("router config");
    let child = Command::new(env!("CARGO_BIN_EXE_station"))
        .args(["router", "run", "--config"])
        .arg(&config)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("router.log")).expect("log"))
        .spawn()
        .expect("station router starts");
    (Reaped(Some(child)), locator)
}

fn host_port(locator: &str) -> String {
    locator.trim_start_matches("tcp/").to_owned()
}

fn client() -> Command {
    let mut c = Command::new("python3");
    c.arg(repo().join("tools/tests/fixtures/ros2_client.py"));
    c
}

fn json_of(path: &Path) -> Value {
    let text =
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    serde_json::from_str(&text).expect("JSON")
}

#[test]
fn a_ros2_client_sees_every_site_s_poses_and_forces_as_recorded() {
    let _turn = ONE_AT_A_TIME.lock();
    if coop_tests::python_with(&["zenoh_ros2_sdk", "rosbags", "mcap"]).is_none() {
        return;
    }
    let dir = TempDir::new("ros2-session");
    let (_router, locator) = router(&dir);
    let stop = dir.join("stop");
    let got = dir.join("got.json");
    let session_name = "r2s";
    let namespace = "/coop/r2s_timewarp";
    let mut sub = Reaped(Some(
        client()
            .args(["subscribe", "--router", &host_port(&locator)])
            .args(["--namespace", namespace, "--sites", "user1,user2"])
            .arg("--until-file")
            .arg(&stop)
            .arg("--out")
            .arg(&got)
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(dir.join("client.log")).expect("log"))
            .spawn()
            .expect("python3 runs"),
    ));
    let out = Command::new(env!("CARGO_BIN_EXE_session"))
        .current_dir(repo())
        .args([
            "run",
            "scenarios/paper.toml",
            "--method",
            "timewarp",
            "--json",
        ])
        .args([
            "--session",
            session_name,
            "--ros2",
            "--ros2-router",
            &locator,
        ])
        .arg("--out")
        .arg(dir.join("session"))
        .output()
        .expect("session runs");
    assert!(
        out.status.success(),
        "session failed: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::write(&stop, "").expect("stop file");
    assert!(
        sub.wait_timeout(Duration::from_secs(60)).is_some(),
        "the ROS 2 client did not finish; its log: {}",
        std::fs::read_to_string(dir.join("client.log")).unwrap_or_default()
    );
    let g = json_of(&got);

    // The graph, as `ros2 topic list -t` shows it: our topics with their types.
    let topics: Vec<(String, String)> = g["topics"]
        .as_array()
        .expect("topics")
        .iter()
        .map(|t| {
            (
                t[0].as_str().unwrap_or("").into(),
                t[1][0].as_str().unwrap_or("").into(),
            )
        })
        .collect();
    for site in ["user1", "user2"] {
        for (topic, ty) in [
            ("tool", "geometry_msgs/msg/PoseStamped"),
            ("force", "geometry_msgs/msg/WrenchStamped"),
            ("object", "geometry_msgs/msg/PoseStamped"),
        ] {
            let want = (format!("{namespace}/{site}/{topic}"), ty.to_owned());
            assert!(topics.contains(&want), "{want:?} not listed: {topics:?}");
        }
    }
    assert!(topics.contains(&("/tf".into(), "tf2_msgs/msg/TFMessage".into())));
    assert!(topics.contains(&("/rosout".into(), "rcl_interfaces/msg/Log".into())));
    // The SDK computed the same type hashes from the definitions as we pinned.
    for t in coop_transport::ros2::graph::TYPES {
        assert_eq!(g["hashes"][t.name], t.hash, "{}", t.name);
    }
    // rosbags decoded the first raw sample of each type.
    for t in coop_transport::ros2::graph::TYPES {
        assert!(
            g["rosbags"][t.name].as_str().is_some_and(|s| !s.is_empty()),
            "rosbags did not decode {}: {}",
            t.name,
            g["rosbags"]
        );
    }
    // Frames on /tf, and the stations' events on /rosout.
    let frames = g["tf_frames"].to_string();
    for f in ["tool/user1", "object/user1", "tool/user2", "object/user2"] {
        assert!(
            frames.contains(&format!("[\"world\",\"{f}\"]")),
            "{f}: {frames}"
        );
    }
    let rosout = g["rosout"].to_string();
    assert!(
        rosout.contains("coop.r2s_timewarp.user1") && rosout.contains("joined"),
        "{rosout}"
    );

    // Every value received is one the station recorded, bit for bit, and there are many.
    let cmp = client()
        .arg("compare")
        .arg(&got)
        .arg("--recordings")
        .arg(dir.join("session/timewarp"))
        .args(["--sites", "user1,user2"])
        .output()
        .expect("python3 runs");
    assert!(
        cmp.status.success(),
        "compare failed: {}",
        String::from_utf8_lossy(&cmp.stderr)
    );
    let r: Value = serde_json::from_slice(&cmp.stdout).expect("JSON");
    assert_eq!(r["errors"], Value::Array(vec![]), "{r}");
    for site in ["user1", "user2"] {
        let s = &r["sites"][site];
        // 14 s at up to 100 Hz: at least a few hundred of each, with contact forces among them.
        for what in ["tool", "force", "object"] {
            assert!(s[what].as_u64() > Some(300), "{site} {what}: {s}");
        }
        assert!(s["nonzero_force"].as_u64() > Some(10), "{site}: {s}");
    }
}

/// The station's device through a ROS 2 driver: the Python driver publishes a pose at 1 kHz, down
/// onto a disk; the station shows it the contact as wrenches; when the driver goes silent, the
/// device is released (a zero wrench) and `station status` names the fault, in its device section
/// too.
#[test]
fn a_station_drives_a_device_through_its_ros2_driver_and_releases_it_when_silent() {
    use std::io::{BufRead, BufReader};

    use coop_rt::device::safety::Limit;
    use coop_rt::shm::control::{ControlBlock, RunState};
    use coop_rt::shm::{BlockSegment, SegmentName};
    use coop_tests::{press_scenario, shm_entries, station_config, unique_session, wait_until};

    const STATION: &str = env!("CARGO_BIN_EXE_station");
    const LIMIT: Duration = Duration::from_secs(60);
    let _turn = ONE_AT_A_TIME.lock();
    if coop_tests::python_with(&["zenoh_ros2_sdk", "rosbags", "mcap"]).is_none() {
        return;
    }
    let dir = TempDir::new("ros2-device");
    let (_router, locator) = router(&dir);
    let silent = dir.join("silent");
    let got = dir.join("device.json");
    let mut driver = client()
        .args([
            "device",
            "--router",
            &host_port(&locator),
            "--namespace",
            "/haptic",
        ])
        .args(["--rate-hz", "1000", "--z-start", "0.06", "--z-end", "0.012"])
        .arg("--silent-file")
        .arg(&silent)
        .arg("--out")
        .arg(&got)
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(dir.join("driver.log")).expect("log"))
        .spawn()
        .expect("python3 runs");
    let out = BufReader::new(driver.stdout.take().expect("stdout"));
    let mut driver = Reaped(Some(driver));
    // The largest force and the newest the driver was sent (f64 bits), read by a thread.
    let most = std::sync::Arc::new(coop_rt::sync::AtomicU64::new(0f64.to_bits()));
    let newest = std::sync::Arc::new(coop_rt::sync::AtomicU64::new(f64::NAN.to_bits()));
    let (m, n) = (most.clone(), newest.clone());
    std::thread::spawn(move || {
        for line in out.lines() {
            let Ok(line) = line else { break };
            if let Some(f) = line.strip_prefix("FORCE ") {
                let norm = f
                    .split(' ')
                    .map(|x| x.parse::<f64>().unwrap_or(0.0).powi(2))
                    .sum::<f64>()
                    .sqrt();
                n.store(norm.to_bits(), coop_rt::sync::Ordering::Relaxed);
                if norm > f64::from_bits(m.load(coop_rt::sync::Ordering::Relaxed)) {
                    m.store(norm.to_bits(), coop_rt::sync::Ordering::Relaxed);
                }
            }
        }
    });
    let force =
        |a: &coop_rt::sync::AtomicU64| f64::from_bits(a.load(coop_rt::sync::Ordering::Relaxed));

    let session = unique_session();
    // The disk of the press scenario rests on the floor (top at about 2 cm); the driver's end
    // effector comes down onto it from 6 cm, the device frame being the world's.
    std::fs::write(
        dir.join("press.toml"),
        press_scenario("", "", "[{ t_s = 0.0, target_m = [0.0, 0.0, 0.06] }]"),
    )
    .expect("scenario");
    let cfg = station_config(&dir, &session, "user1", |c| {
        c.scenario = Some("press.toml".into());
        c.device.device = coop_actors::station::device::BackendName::Ros2;
        c.device.safety.ramp_in_ms = 50.0;
        let mut t = toml::Table::new();
        t.insert("connect".into(), vec![locator.clone()].into());
        t.insert("pose_topic".into(), "/haptic/pose".into());
        t.insert("wrench_topic".into(), "/haptic/wrench_command".into());
        // A loaded 2-CPU machine delays a Python publisher's 1 kHz by tens of milliseconds at
        // times: the limit the release is checked against is not what this test is about.
        t.insert("stale_limit_ms".into(), 200.0.into());
        t.insert("first_pose_timeout_ms".into(), 30_000.into());
        c.device.ros2 = Some(t);
    });
    let station =
        coop_tests::Reaped::spawn(Command::new(STATION).arg("run").arg("--config").arg(&cfg));
    let name = SegmentName::new(&session, "user1", "ctl").expect("name");
    let ctl = wait_until("the control block", LIMIT, || {
        BlockSegment::<ControlBlock>::open(&name, Duration::from_secs(1)).ok()
    });
    wait_until("the station running", LIMIT, || {
        (ctl.run_state() == RunState::Running).then_some(())
    });
    wait_until("the driver sent the contact force", LIMIT, || {
        (force(&most) > 0.5).then_some(())
    });
    let shown = force(&most);
    // The ROS 2 device reports 3 N as its maximum (Ros2DeviceConfig's default).
    assert!(
        shown <= 3.0 + 1e-9,
        "within the device's maximum: {shown} N"
    );

    // Pressing on the disk, the driver goes silent: its poses go stale and the safety layer
    // releases.
    wait_until("the driver pressing on the disk", LIMIT, || {
        (force(&newest) > 1.0).then_some(())
    });
    std::fs::write(&silent, "").expect("silent file");
    wait_until("the device released for the fault", LIMIT, || {
        (Limit::from_code(
            ctl.servo
                .safety_limit
                .load(coop_rt::sync::Ordering::Relaxed),
        ) == Some(Limit::Fault)
            && ControlBlock::load_f64(&ctl.servo.command_n) == 0.0)
            .then_some(())
    });
    let v = coop_tests::station_status_json(STATION, &cfg);
    assert_eq!(v["servo"]["safety"]["limit"], "device fault", "{v}");
    assert_eq!(v["servo"]["safety"]["releases"], true);
    // Its device section: the driver's poses as the bridge took them, the silence as stale
    // samples, the last fault's kind, and the release among the safety trips.
    let dev = &v["device"];
    assert_eq!(dev["backend"], "ros2", "{v}");
    assert!(dev["bridge"]["received"].as_u64() > Some(100), "{dev}");
    assert!(dev["bridge"]["sent_forces"].as_u64() > Some(0), "{dev}");
    assert_eq!(dev["bridge"]["foreign"], 0, "one driver: {dev}");
    assert!(dev["stale"].as_u64() > Some(0), "{dev}");
    assert_eq!(dev["faults"]["last"]["kind"], "disconnected", "{dev}");
    assert!(dev["trips"]["device fault"].as_u64() >= Some(1), "{dev}");
    wait_until("the driver sent a zero wrench", LIMIT, || {
        (force(&newest) == 0.0).then_some(())
    });
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(station.pid() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
    drop(ctl);
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    assert!(
        driver.wait_timeout(LIMIT).is_some(),
        "the driver did not finish"
    );
    let d = json_of(&got);
    eprintln!("ROS 2 driver: {d}");
    assert!(d["nonzero"].as_u64() > Some(10), "{d}");
    // Pressing when it went silent, released after (how long after is the benchmark's figure).
    assert!(d["released_after_s"].as_f64().is_some(), "{d}");
}

/// A station whose device's ROS 2 driver is not running ends, failing, with the backend's own
/// error said once (the topic, the wait, the field to look at, the fix): its servo waits for the
/// first pose within its start limit, and is not restarted as hung until the policy gives up. No
/// driver and no router here: nothing listens on the port it connects to.
#[test]
fn a_station_without_its_ros2_driver_ends_with_the_device_error() {
    let dir = TempDir::new("ros2-no-driver");
    let session = coop_tests::unique_session();
    let cfg = coop_tests::station_config(&dir, &session, "user1", |c| {
        c.device.device = coop_actors::station::device::BackendName::Ros2;
        let mut t = toml::Table::new();
        t.insert("connect".into(), vec!["tcp/127.0.0.1:1".to_owned()].into());
        t.insert("first_pose_timeout_ms".into(), 300.into());
        c.device.ros2 = Some(t);
    });
    // Bounded by its own duration should it not end by itself.
    let out = Command::new(env!("CARGO_BIN_EXE_station"))
        .args(["run", "--duration-s", "120", "--config"])
        .arg(&cfg)
        .stdin(Stdio::null())
        .output()
        .expect("station runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the station should fail: {err}");
    let said = "device.ros2: no geometry_msgs/msg/PoseStamped on /haptic/pose";
    assert_eq!(err.matches(said).count(), 1, "said once: {err}");
    assert!(
        err.contains("within 300 ms (device.ros2.first_pose_timeout_ms): is the driver running"),
        "{err}"
    );
    assert!(!err.contains("hung"), "{err}");
    assert!(!err.contains("failed 4 times"), "{err}");
    assert!(
        coop_tests::shm_entries(&format!("coop_{session}_")).is_empty(),
        "segments left behind"
    );
}

/// A sample a subscriber got: its key and payload.
type Seen = (String, Vec<u8>);

/// The ROS 2 side through a router with mutual TLS and the session's access control (`session
/// certs --ros2-domain 0 --ros2-viewer rviz`): a viewer holding the `rviz` certificate receives a
/// station's ROS 2 topics; neither it nor another site's certificate can put on that station's
/// topics (the router refuses and says so), while a site's put on its own namespace goes through.
#[test]
fn through_the_router_only_a_site_speaks_on_its_ros2_topics() {
    use coop_transport::network::{Mode, NetworkConfig, Tls};
    use coop_transport::ros2::graph;
    use zenoh::Wait;

    const LIMIT: Duration = Duration::from_secs(60);
    let _turn = ONE_AT_A_TIME.lock();
    let dir = TempDir::new("ros2-acl");
    let session = coop_tests::unique_session();
    let certs = dir.join("certs");
    let made = Command::new(env!("CARGO_BIN_EXE_session"))
        .current_dir(repo())
        .args(["certs", "scenarios/paper.toml", "--session", &session])
        .args([
            "--router",
            "r1",
            "--ros2-domain",
            "0",
            "--ros2-viewer",
            "rviz",
        ])
        .arg("--out")
        .arg(&certs)
        .output()
        .expect("session certs");
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    let locator = coop_transport::network::concrete_listen(&["tcp/127.0.0.1:0".into()])
        .remove(0)
        .replacen("tcp/", "tls/", 1);
    let status_file = dir.join("r1.json");
    let cfg = dir.join("r1.toml");
    std::fs::write(
        &cfg,
        format!(
            "name = \"r1\"\nlisten = [{locator:?}]\naccess_control = {acl:?}\nstatus_file = {status:?}\n\
             [tls]\nroot_ca_certificate = {ca:?}\nlisten_certificate = {c:?}\nlisten_private_key = {k:?}\nenable_mtls = true\n",
            acl = certs.join("acl.json5"),
            status = status_file,
            ca = certs.join("ca.pem"),
            c = certs.join("r1.pem"),
            k = certs.join("r1.key"),
        ),
    )
    .expect("router config");
    let _router = Reaped(Some(
        Command::new(env!("CARGO_BIN_EXE_station"))
            .args(["router", "run", "--config"])
            .arg(&cfg)
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(dir.join("router.log")).expect("log"))
            .spawn()
            .expect("router"),
    ));
    let tls = |who: &str| Tls {
        root_ca_certificate: Some(certs.join("ca.pem")),
        connect_certificate: Some(certs.join(format!("{who}.pem"))),
        connect_private_key: Some(certs.join(format!("{who}.key"))),
        enable_mtls: true,
        ..Tls::default()
    };
    // The station: user1, a client of the router, publishing its ROS 2 topics.
    let station_cfg = coop_tests::station_config(&dir, &session, "user1", |c| {
        c.scenario = Some(scenario_path("paper.toml"));
        c.network = NetworkConfig {
            mode: Mode::Client,
            listen: Vec::new(),
            connect: vec![locator.clone()],
            tls: Some(tls("user1")),
            access_control: Some(certs.join("acl.json5")),
            ..NetworkConfig::default()
        };
        c.ros2.publish = true;
    });
    let station = coop_tests::Reaped::spawn(
        Command::new(env!("CARGO_BIN_EXE_station"))
            .arg("run")
            .arg("--config")
            .arg(&station_cfg),
    );
    let client = |who: &str| {
        let net = NetworkConfig {
            mode: Mode::Client,
            listen: Vec::new(),
            connect: vec![locator.clone()],
            tls: Some(tls(who)),
            ..NetworkConfig::default()
        };
        let waited = Instant::now();
        loop {
            match zenoh::open(coop_transport::network::config(&net).expect("config")).wait() {
                Ok(z) => break z,
                Err(e) => {
                    assert!(waited.elapsed() < LIMIT, "{who} cannot connect: {e}");
                    std::thread::sleep(Duration::from_millis(100));
                }
            }
        }
    };
    let viewer = client("rviz");
    let seen: std::sync::Arc<Mutex<Vec<Seen>>> = std::sync::Arc::default();
    let s2 = seen.clone();
    let _sub = viewer
        .declare_subscriber("0/**")
        .callback(move |s| {
            s2.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .push((s.key_expr().to_string(), s.payload().to_bytes().to_vec()));
        })
        .wait()
        .expect("the viewer may subscribe");
    let ns = |site: &str| coop_transport::ros2::namespace(&session, site);
    let user1_tool = graph::topic_key(0, &format!("{}/tool", ns("user1")), &graph::POSE_STAMPED);
    let user2_tool = graph::topic_key(0, &format!("{}/tool", ns("user2")), &graph::POSE_STAMPED);
    let got = |pred: &dyn Fn(&Seen) -> bool| {
        seen.lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
            .any(pred)
    };
    coop_tests::wait_until("the viewer receiving user1's tool", LIMIT, || {
        got(&|(k, b)| *k == user1_tool && coop_transport::ros2::cdr::PoseStamped::decode(b).is_ok())
            .then_some(())
    });

    // Forgeries on user1's tool, by a viewer (another session holding the viewer's certificate:
    // a session's own subscriber would get its put without the router) and by user2, then user2
    // on its own namespace.
    // Each put goes once its session knows a subscriber waits for the key: a client drops a put
    // nobody is known to want, and the router would then have nothing to refuse.
    let put_when_heard = |z: &zenoh::Session, key: &str, bytes: Vec<u8>| {
        let p = z
            .declare_publisher(key.to_owned())
            .wait()
            .expect("publisher");
        coop_tests::wait_until("a subscriber known to the putting session", LIMIT, || {
            p.matching_status()
                .wait()
                .ok()
                .filter(|m| m.matching())
                .map(drop)
        });
        p.put(bytes)
            .wait()
            .expect("put (refused at the router, not here)");
    };
    let forged = b"forged".to_vec();
    let viewer2 = client("rviz");
    put_when_heard(&viewer2, &user1_tool, forged.clone());
    let impostor = client("user2");
    put_when_heard(&impostor, &user1_tool, forged.clone());
    put_when_heard(&impostor, &user2_tool, b"own".to_vec());
    coop_tests::wait_until(
        "the viewer receiving user2's put on its own topic",
        LIMIT,
        || got(&|(k, b)| *k == user2_tool && b == b"own").then_some(()),
    );
    // The router's refusal of both forgeries is what proves them kept out; that none reached the
    // viewer by then is what a user sees.
    let refused = coop_tests::wait_until("the router's refusals of both puts", LIMIT, || {
        let v: Value = serde_json::from_str(&std::fs::read_to_string(&status_file).ok()?).ok()?;
        let on_user1 = v["recent_refusals"]
            .as_array()?
            .iter()
            .filter(|r| r["key"].as_str() == Some(user1_tool.as_str()))
            .count();
        (on_user1 >= 2).then_some(v)
    });
    eprintln!("router refusals: {}", refused["recent_refusals"]);
    assert!(
        !got(&|(_, b)| *b == forged),
        "a forgery on user1's ROS 2 topic reached the viewer"
    );
    drop(impostor);
    drop(viewer2);
    drop(viewer);
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(station.pid() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
}
