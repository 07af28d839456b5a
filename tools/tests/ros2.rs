//! ROS 2 without ROS, checked by a ROS 2 user's own tools: `zenoh-ros2-sdk` (ROBOTIS) with the
//! message definitions inline and `rosbags`, in Python, against a real session of real stations
//! whose ROS 2 graph meets at a real zenoh router (`station router`, standing in for
//! `rmw_zenohd`).
//!
//! CI installs the packages and sets `COOP_REQUIRE_MCAP_PY=1` (see .ci/run): then a missing package
//! fails the test instead of skipping it.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use serde_json::Value;

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn out_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("coop-ros2-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("out dir");
    d
}

/// Python with the ROS 2 client's packages, or `None` (skip) when one is missing and CI does not
/// require them.
fn python_ready() -> Option<()> {
    let ok = Command::new("python3")
        .args(["-c", "import zenoh_ros2_sdk, rosbags, mcap"])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(());
    }
    if std::env::var_os("COOP_REQUIRE_MCAP_PY").is_some() {
        panic!("python3 with zenoh-ros2-sdk, rosbags and mcap is required (pip install zenoh-ros2-sdk rosbags mcap)");
    }
    eprintln!(
        "SKIPPED the ROS 2 client check: python3 -c 'import zenoh_ros2_sdk, rosbags, mcap' fails"
    );
    None
}

/// A child process killed (and reaped) when dropped, whatever the test's outcome.
struct Reaped(Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

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
    (Reaped(child), locator)
}

fn host_port(locator: &str) -> String {
    locator.trim_start_matches("tcp/").to_owned()
}

fn client() -> Command {
    let mut c = Command::new("python3");
    c.arg(root().join("tools/tests/fixtures/ros2_client.py"));
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
    if python_ready().is_none() {
        return;
    }
    let dir = out_dir("session");
    let (_router, locator) = router(&dir);
    let stop = dir.join("stop");
    let got = dir.join("got.json");
    let session_name = "r2s";
    let namespace = "/coop/r2s_timewarp";
    let mut sub = Reaped(
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
    );
    let out = Command::new(env!("CARGO_BIN_EXE_session"))
        .current_dir(root())
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
    let waited = Instant::now();
    while sub.0.try_wait().expect("client").is_none() {
        assert!(
            waited.elapsed() < Duration::from_secs(60),
            "the ROS 2 client did not finish; its log: {}",
            std::fs::read_to_string(dir.join("client.log")).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
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
