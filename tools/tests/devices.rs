//! `station devices`: every backend is listed with what it finds, the configuration's marked, in
//! text and JSON; a config selecting a recorded hand shows that recording.

use std::process::Command;

use coop_tests::TempDir;

fn station(args: &[&str]) -> (String, String, bool) {
    let o = Command::new(env!("CARGO_BIN_EXE_station"))
        .args(args)
        .output()
        .expect("station runs");
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        o.status.success(),
    )
}

#[test]
fn lists_every_backend_with_what_it_finds_and_marks_the_configured_one() {
    let (out, err, ok) = station(&["devices", "--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("json");
    let list = v.as_array().expect("a list");
    let names: Vec<&str> = list.iter().filter_map(|b| b["backend"].as_str()).collect();
    assert_eq!(
        names,
        ["sim", "replay", "haply", "dhd", "openhaptics", "ros2"]
    );
    let sim = &list[0];
    assert_eq!(
        sim["selected"], true,
        "the default config drives the simulated arm"
    );
    assert_eq!(sim["built_in"], true);
    assert_eq!(sim["devices"][0]["model"], "SCARA (simulated)");
    assert_eq!(sim["devices"][0]["senses_force"], true);
    assert_eq!(sim["devices"][0]["max_force_n"], 10.0);
    for b in &list[1..] {
        assert_eq!(b["selected"], false);
        assert!(b["status"].as_str().is_some_and(|s| !s.is_empty()), "{b}");
    }

    let (text, _, ok) = station(&["devices"]);
    assert!(ok);
    assert!(text.lines().any(|l| l.starts_with("* sim")), "{text}");
    assert!(
        text.contains("SCARA (simulated) (3 DOF), max 10.0 N"),
        "{text}"
    );

    let dir = TempDir::new("devices-replay");
    std::fs::write(
        dir.join("hand.csv"),
        "t_s,x,y,z\n0,-0.1,0,0.01\n1.5,-0.05,0,0.01\n",
    )
    .expect("csv");
    std::fs::write(
        dir.join("station.toml"),
        "[device]\ndevice = \"replay\"\n[device.replay]\nfile = \"hand.csv\"\n",
    )
    .expect("config");
    let config = dir.join("station.toml");
    let (text, err, ok) = station(&["devices", "--config", config.to_str().expect("utf-8")]);
    assert!(ok, "{err}");
    let replay = text
        .lines()
        .find(|l| l.starts_with("* replay"))
        .unwrap_or_else(|| panic!("replay selected: {text}"));
    assert!(
        replay.contains("device.replay.file: 2 samples from 0.000 s to 1.500 s"),
        "{replay}"
    );
    // A bad value is refused naming the field, the value, the rule and the file.
    std::fs::write(
        dir.join("bad.toml"),
        "[device.safety]\nmax_force_step_n = -1\n",
    )
    .expect("bad");
    let bad = dir.join("bad.toml");
    let (_, err, ok) = station(&["devices", "--config", bad.to_str().expect("utf-8")]);
    assert!(!ok);
    assert!(
        err.contains("device.safety.max_force_step_n = -1: must be above 0 and at most 100 N")
            && err.contains("bad.toml"),
        "{err}"
    );
}
