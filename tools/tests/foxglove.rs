//! A real session seen in Foxglove's terms, by readers that are not ours: its recordings' `/tf`,
//! `/scene` and `/log` channels read with the `mcap` Python package and decoded with the protobuf
//! FileDescriptorSet each file carries (the `protobuf` package).
//!
//! CI installs both packages and sets `COOP_REQUIRE_MCAP_PY=1` (see .ci/run): then a missing
//! package fails the test instead of skipping the check.

use std::path::PathBuf;
use std::process::Command;
use std::sync::Mutex;

use coop_tests::{repo, TempDir};
use serde_json::Value;

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The Foxglove summary of one site's recording (its parts, in order), as the fixture script
/// reads it.
fn foxglove_summary(parts: &[PathBuf]) -> Value {
    let script = repo().join("tools/tests/fixtures/foxglove_recording.py");
    let out = Command::new("python3")
        .arg(&script)
        .args(parts)
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "{} failed: {}",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("the script prints JSON")
}

#[test]
fn a_sessions_recordings_show_every_site_in_foxglove_terms() {
    let _turn = ONE_AT_A_TIME.lock();
    if coop_tests::python_with(&["mcap", "google.protobuf"]).is_none() {
        return;
    }
    let scenario_path = coop_tests::scenario_path("three-users.toml");
    let scenario = coop_actors::scenario_file::load(&scenario_path).expect("scenario");
    let out = TempDir::unmade("foxglove-recorded");
    let run = Command::new(env!("CARGO_BIN_EXE_session"))
        .current_dir(repo())
        .arg("run")
        .arg(&scenario_path)
        .args(["--method", "paper", "--record-max-file-s", "4", "--json"])
        .arg("--out")
        .arg(&out)
        .output()
        .expect("session runs");
    assert!(
        run.status.success(),
        "session failed: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let o = &scenario.objects[0];
    let (d, h) = (2.0 * o.radius_m, 2.0 * o.half_height_m);
    let mut arrows = 0;
    for site in &scenario.site {
        let first = out.join("paper").join(format!("{}.mcap", site.name));
        let parts = coop_transport::recording::read(&first)
            .expect("the recording reads")
            .files;
        assert!(parts.len() >= 2, "{}: rotated into parts", site.name);
        let v = foxglove_summary(&parts);
        assert_eq!(v["errors"], serde_json::json!([]), "{}", site.name);
        // Every part alone has frames and a scene.
        for p in v["parts"].as_array().expect("parts") {
            for t in ["/tf", "/scene"] {
                assert!(
                    p["counts"][t].as_u64() > Some(0),
                    "{}: {t} in {p}",
                    site.name
                );
            }
        }
        // This site's copy and tool, and nothing else, at the sample rate (200 Hz, about 10 s).
        let object = format!("object/{}", site.name);
        let tool = format!("tool/{}", site.name);
        let frames = v["frames"].as_object().expect("frames");
        let names: Vec<&str> = frames.keys().map(String::as_str).collect();
        let mut want = [format!("world>{object}"), format!("world>{tool}")];
        want.sort();
        assert_eq!(names, want, "{}", site.name);
        for (f, n) in frames {
            assert!(n.as_u64() > Some(1500), "{}: {f} {n}", site.name);
        }
        // The entities sit in `world` or in one of the frames, and have the scenario's sizes.
        for e in v["entity_frames"].as_array().expect("entity frames") {
            let frame = e[1].as_str().expect("frame");
            assert!(
                frame == "world" || frame == object || frame == tool,
                "{}: entity {e} in an unknown frame",
                site.name
            );
        }
        let entities = &v["entities"];
        assert_eq!(
            entities[&object]["cylinder_size"],
            serde_json::json!([d, d, h])
        );
        let r = 2.0 * site.tool_radius_m;
        assert_eq!(entities[&tool]["sphere_size"], serde_json::json!([r, r, r]));
        assert!(
            entities["environment"]["cubes"].as_u64() > Some(0),
            "the floor"
        );
        arrows += entities[format!("force/{}", site.name)]["arrows"]
            .as_u64()
            .unwrap_or(0);
        // The station's events, in its name: its start and every other site joining.
        let logs: Vec<&str> = v["logs"]
            .as_array()
            .expect("logs")
            .iter()
            .map(|l| {
                assert_eq!(l["name"], site.name.as_str());
                l["message"].as_str().expect("text")
            })
            .collect();
        assert!(
            logs.iter()
                .any(|l| l.starts_with(&format!("station {} started", site.name))),
            "{logs:?}"
        );
        assert!(
            logs.iter().any(|l| l.starts_with("station stopping")),
            "{logs:?}"
        );
        for other in scenario.site.iter().filter(|s| s.name != site.name) {
            assert!(
                logs.contains(&format!("{} joined", other.name).as_str()),
                "{}: {logs:?}",
                site.name
            );
        }
    }
    assert!(arrows > 0, "the users push the object: force arrows");
    // The real session's session file opens with the shipped layout too.
    let session_file = foxglove_summary(&[out.join("paper").join("session.mcap")]);
    assert_eq!(session_file["errors"], serde_json::json!([]));
    assert!(check_layout("foxglove-layout.json", &session_file) > 0);
}

/// `session run --live`: a Foxglove WebSocket client that is not ours (the `websockets` package,
/// `foxglove.websocket.v1`) gets the channels advertised, subscribes, and receives every site's
/// frames and scene while the session runs; the session ends as it would without a viewer.
#[test]
fn a_running_session_is_served_live_to_a_foxglove_websocket_client() {
    let _turn = ONE_AT_A_TIME.lock();
    if coop_tests::python_with(&["websockets", "google.protobuf"]).is_none() {
        return;
    }
    let scenario_path = coop_tests::scenario_path("three-users.toml");
    let scenario = coop_actors::scenario_file::load(&scenario_path).expect("scenario");
    let out = TempDir::unmade("foxglove-live");
    let (child, url, log) = live_session(&scenario_path, "paper", &out);
    assert!(url.starts_with("ws://127.0.0.1:"), "loopback: {url}");
    let sites: Vec<&str> = scenario.site.iter().map(|s| s.name.as_str()).collect();
    // The client waits (up to 60 s) until it has seen every site; it connects before the stations
    // are up, so what it sees is the session as it runs.
    let client = Command::new("python3")
        .arg(repo().join("tools/tests/fixtures/foxglove_live.py"))
        .args([url.as_str(), "60"])
        .args(&sites)
        .output()
        .expect("python3 runs");
    // A second viewer connects while the session runs and stays 2 s: it gets the whole scene
    // first (the last one, at once), then the turns' arrows as they change.
    let later = Command::new("python3")
        .arg(repo().join("tools/tests/fixtures/foxglove_live.py"))
        .args([url.as_str(), "60"])
        .args(&sites)
        .env("LISTEN_S", "2")
        .output()
        .expect("python3 runs");
    let session = child.wait_with_output().expect("session ends");
    let launcher_log = log.join().unwrap_or_default();
    assert!(
        client.status.success(),
        "the client failed: {}",
        String::from_utf8_lossy(&client.stderr)
    );
    assert!(session.status.success(), "session failed: {launcher_log}");
    let v: Value = serde_json::from_slice(&client.stdout).expect("the client prints JSON");
    assert_eq!(v["errors"], serde_json::json!([]), "{v}");
    assert_eq!(
        v["channels"],
        serde_json::json!({
            "/tf": "foxglove.FrameTransform",
            "/scene": "foxglove.SceneUpdate",
            "/log": "foxglove.Log",
        }),
        "advertised"
    );
    assert_eq!(v["complete"], true, "every site's frames and scene: {v}");
    // One scene with every site: the environment and three entities per site.
    assert_eq!(
        v["max_scene_entities"].as_u64(),
        Some(1 + 3 * sites.len() as u64),
        "{v}"
    );
    assert!(
        v["logs"][0]
            .as_str()
            .is_some_and(|l| l.contains("scenario three-users")),
        "{v}"
    );
    assert!(
        later.status.success(),
        "the later client failed: {}",
        String::from_utf8_lossy(&later.stderr)
    );
    let w: Value = serde_json::from_slice(&later.stdout).expect("the later client prints JSON");
    assert_eq!(
        (&w["errors"], &w["complete"]),
        (&serde_json::json!([]), &serde_json::json!(true)),
        "{w}"
    );
    let first = w["first_scene_ids"].as_array().map_or(0, Vec::len);
    assert_eq!(first, 1 + 3 * sites.len(), "the whole scene first: {w}");
    assert!(
        w["arrow_scenes"].as_u64() > Some(0),
        "between whole scenes, the arrows that changed alone: {w}"
    );
    // The session's own result is unaffected.
    let result: Value = serde_json::from_slice(&session.stdout).expect("the session's JSON");
    assert!(
        result["methods"]["paper"]["real"]["divergence_final_m"].as_f64() < Some(0.005),
        "{result}"
    );
}

/// `sim run scenarios/<file> <args> --out` into the test's directory `tag`: the scenario, and its
/// `session.mcap` as the foreign reader summarises it (read without errors), and the directory
/// (removed when dropped).
fn simulated_session(
    tag: &str,
    file: &str,
    args: &[&str],
) -> (coop_model::scenario::Scenario, Value, TempDir) {
    let scenario_path = coop_tests::scenario_path(file);
    let scenario = coop_actors::scenario_file::load(&scenario_path).expect("scenario");
    let out = TempDir::unmade(&format!("foxglove-{tag}"));
    let run = Command::new(env!("CARGO_BIN_EXE_sim"))
        .arg("run")
        .arg(&scenario_path)
        .args(args)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("sim runs");
    assert!(
        run.status.success(),
        "sim failed: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let v = foxglove_summary(&[out.join("session.mcap")]);
    assert_eq!(v["errors"], serde_json::json!([]), "{}", v["errors"]);
    (scenario, v, out)
}

/// `sim run --out` writes `session.mcap`: read by the same foreign reader as a station's
/// recording, it holds every site's frames, entities and JSON channels and the reference copy as
/// its own frame, entity and colour, with times increasing and frame ids that are all declared.
#[test]
fn a_simulated_runs_session_file_shows_every_site_and_the_reference_in_foxglove_terms() {
    if coop_tests::python_with(&["mcap", "google.protobuf"]).is_none() {
        return;
    }
    let (scenario, v, _out) = simulated_session("sim", "three-users.toml", &["--method", "paper"]);
    let samples = (scenario.duration_s * scenario.sample_rate_hz).round() as u64 + 1;
    let mut sites: Vec<&str> = scenario.site.iter().map(|s| s.name.as_str()).collect();
    // Every site's copy and tool and the reference copy, one frame each per sample, in `world`.
    let mut want: Vec<String> = sites
        .iter()
        .flat_map(|s| [format!("world>object/{s}"), format!("world>tool/{s}")])
        .chain(["world>object/reference".to_owned()])
        .collect();
    want.sort();
    let frames = v["frames"].as_object().expect("frames");
    assert_eq!(frames.keys().cloned().collect::<Vec<_>>(), want);
    for (f, n) in frames {
        assert_eq!(n.as_u64(), Some(samples), "{f}");
    }
    entities_sit_in_declared_frames(&v);
    // The reference copy: its own entity, the object's real size, its own (grey) colour.
    let o = &scenario.objects[0];
    let (d, h) = (2.0 * o.radius_m, 2.0 * o.half_height_m);
    let entities = &v["entities"];
    assert_eq!(
        entities["object/reference"]["cylinder_size"],
        serde_json::json!([d, d, h])
    );
    let grey = entities["object/reference"]["colour"].clone();
    for s in &sites {
        assert_eq!(
            entities[format!("object/{s}")]["cylinder_size"],
            serde_json::json!([d, d, h])
        );
        assert_ne!(entities[format!("object/{s}")]["colour"], grey, "{s}");
        assert!(
            entities[format!("tool/{s}")]["sphere_size"].is_array(),
            "{s}"
        );
    }
    assert!(
        entities["environment"]["cubes"].as_u64() > Some(0),
        "the floor"
    );
    // The JSON channels: every site (and the reference's /object) at every sample.
    let per_site = |topic: &str| -> Vec<(String, u64)> {
        v["json"][topic]
            .as_object()
            .unwrap_or_else(|| panic!("{topic} in {}", v["json"]))
            .iter()
            .map(|(k, n)| (k.clone(), n.as_u64().unwrap_or(0)))
            .collect()
    };
    sites.sort_unstable();
    let count = |names: &[&str]| -> Vec<(String, u64)> {
        names.iter().map(|s| ((*s).to_owned(), samples)).collect()
    };
    assert_eq!(per_site("/tool"), count(&sites));
    let mut with_reference = sites.clone();
    with_reference.push("reference");
    with_reference.sort_unstable();
    assert_eq!(per_site("/object"), count(&with_reference));
    assert_eq!(per_site("/divergence"), count(&[""]));
    let logs = v["logs"].as_array().expect("logs");
    assert!(
        logs[0]["message"]
            .as_str()
            .is_some_and(|m| m.contains("scenario three-users") && m.contains("simulated")),
        "{logs:?}"
    );
}

/// `station run --live`: the station serves its own live view (from its network process); a
/// Foxglove WebSocket client that is not ours subscribes and receives the station's frames, scene
/// and events while it runs, and the station stops cleanly with its recording whole.
#[test]
fn a_running_station_serves_its_own_live_view_to_a_foxglove_websocket_client() {
    let _turn = ONE_AT_A_TIME.lock();
    if coop_tests::python_with(&["websockets", "google.protobuf"]).is_none() {
        return;
    }
    let session = coop_tests::unique_session();
    let dir = TempDir::unmade("foxglove-station-live");
    let record = dir.join("user1.mcap");
    let cfg = coop_tests::station_config(&dir, &session, "user1", |c| {
        c.record = Some(record.clone());
    });
    let mut station = coop_tests::Reaped::spawn(
        Command::new(env!("CARGO_BIN_EXE_station"))
            .arg("run")
            .arg("--config")
            .arg(&cfg)
            .args(["--live", "127.0.0.1:0", "--duration-s", "120"])
            .stderr(std::process::Stdio::piped()),
    );
    let stderr = station
        .0
        .as_mut()
        .and_then(|c| c.stderr.take())
        .expect("stderr");
    let (url, log) = live_url(stderr, 60, "the network process");
    assert!(url.starts_with("ws://127.0.0.1:"), "loopback: {url}");
    let client = Command::new("python3")
        .arg(repo().join("tools/tests/fixtures/foxglove_live.py"))
        .args([url.as_str(), "60", "user1"])
        .output()
        .expect("python3 runs");
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(station.pid() as i32),
        nix::sys::signal::Signal::SIGTERM,
    );
    let status = station.wait_timeout(std::time::Duration::from_secs(30));
    drop(station);
    let station_log = log.join().unwrap_or_default();
    assert!(
        client.status.success(),
        "the client failed: {}",
        String::from_utf8_lossy(&client.stderr)
    );
    assert!(
        status.is_some_and(|s| s.success()),
        "the station did not stop cleanly ({status:?}): {station_log}"
    );
    let v: Value = serde_json::from_slice(&client.stdout).expect("the client prints JSON");
    assert_eq!(v["errors"], serde_json::json!([]), "{v}");
    assert_eq!(
        v["channels"],
        serde_json::json!({
            "/tf": "foxglove.FrameTransform",
            "/scene": "foxglove.SceneUpdate",
            "/log": "foxglove.Log",
        }),
        "advertised"
    );
    assert_eq!(v["complete"], true, "the station's frames and scene: {v}");
    assert_eq!(
        v["tf_children"],
        serde_json::json!(["object/user1", "tool/user1"]),
        "{v}"
    );
    assert_eq!(v["max_scene_entities"].as_u64(), Some(4), "{v}");
    assert_eq!(
        v["first_scene_ids"],
        serde_json::json!(["environment", "object/user1", "tool/user1", "force/user1"]),
        "the whole scene first: {v}"
    );
    assert!(
        v["logs"][0]
            .as_str()
            .is_some_and(|l| l.starts_with(&format!("station user1 of session {session}"))),
        "{v}"
    );
    let rec = coop_transport::recording::read(&record).expect("the recording reads");
    assert!(!rec.truncated && !rec.samples.is_empty() && rec.status.is_some());
}

/// The shipped layout (`docs/foxglove-layout.json`).
fn layout(file: &str) -> Value {
    let path = repo().join("docs").join(file);
    serde_json::from_str(&std::fs::read_to_string(&path).expect("the layout")).expect("JSON")
}

/// The panel ids a layout tree (a panel id, or `{first, second, direction}`) places.
fn placed(tree: &Value, out: &mut Vec<String>) {
    match tree {
        Value::String(id) => out.push(id.clone()),
        Value::Object(o) => {
            assert!(
                ["row", "column"].contains(&o["direction"].as_str().unwrap_or("")),
                "a split has a direction: {tree}"
            );
            placed(&o["first"], out);
            placed(&o["second"], out);
        }
        other => panic!("not a layout tree: {other}"),
    }
}

/// Checks message path `value` (`/topic{field=="x"}.a[0]`) against a file's summary: its topic is a
/// JSON channel of the file, the filter's field is a field and its value is one the file has, and
/// every field and index is in the channel's schema, ending at a number.
fn check_path(value: &str, v: &Value) -> Result<(), String> {
    let end = value.find(['{', '.', '[']).unwrap_or(value.len());
    let (topic, mut rest) = value.split_at(end);
    let root_schema = &v["json_schemas"][topic];
    if !root_schema.is_object() {
        return Err(format!("{value}: no JSON channel {topic} in the file"));
    }
    // Filters, one after the other (`{site=="user1"}{object=="top"}`): the reader counts messages
    // by site, and by `site/object` where a message names its object.
    let mut wanted_key = Vec::new();
    while let Some(r) = rest.strip_prefix('{') {
        let (filter, after) = r
            .split_once('}')
            .ok_or_else(|| format!("{value}: unclosed filter"))?;
        let (field, wanted) = filter
            .split_once("==")
            .ok_or_else(|| format!("{value}: filter {filter} is not field==value"))?;
        if !root_schema["properties"][field].is_object() {
            return Err(format!("{value}: {topic} has no field {field}"));
        }
        wanted_key.push(wanted.trim_matches('"'));
        rest = after;
    }
    if !wanted_key.is_empty() {
        let wanted = wanted_key.join("/");
        if !v["json"][topic][&wanted].is_u64() {
            return Err(format!("{value}: no {topic} message of {wanted:?}"));
        }
    }
    let mut schema = root_schema;
    while !rest.is_empty() {
        if let Some(r) = rest.strip_prefix('.') {
            let end = r.find(['.', '[']).unwrap_or(r.len());
            let (name, after) = r.split_at(end);
            schema = &schema["properties"][name];
            if !schema.is_object() {
                return Err(format!("{value}: no field {name}"));
            }
            rest = after;
        } else if let Some(r) = rest.strip_prefix('[') {
            let (index, after) = r
                .split_once(']')
                .ok_or_else(|| format!("{value}: unclosed index"))?;
            let i: u64 = index
                .parse()
                .map_err(|_| format!("{value}: index {index}"))?;
            if schema["type"] != "array" || schema["maxItems"].as_u64().is_some_and(|n| i >= n) {
                return Err(format!("{value}: [{i}] indexes no array item ({schema})"));
            }
            schema = &schema["items"];
            rest = after;
        } else {
            return Err(format!("{value}: cannot read {rest}"));
        }
    }
    if schema["type"] != "number" {
        return Err(format!("{value}: plots {schema}, not a number"));
    }
    Ok(())
}

/// Every panel of the shipped layout `file` (in `docs/`) is placed and configured, and every topic
/// and message path it refers to is in the file `v` summarises (a session file); returns the paths
/// checked.
fn check_layout(file: &str, v: &Value) -> usize {
    check_layout_value(&layout(file), v)
}

/// [`check_layout`] of a layout already read.
fn check_layout_value(l: &Value, v: &Value) -> usize {
    let file = "the layout";
    let config = l["configById"].as_object().expect("configById");
    let mut ids = Vec::new();
    placed(&l["layout"], &mut ids);
    for tabs in config.values().filter_map(|c| c["tabs"].as_array()) {
        for t in tabs {
            placed(&t["layout"], &mut ids);
        }
    }
    ids.sort();
    let mut configured: Vec<String> = config.keys().cloned().collect();
    configured.sort();
    assert_eq!(ids, configured, "every panel placed once and configured");
    let types: Vec<&str> = ids
        .iter()
        .map(|id| id.split('!').next().unwrap_or(""))
        .collect();
    for t in ["3D", "Plot", "RosOut", "Tab"] {
        assert!(types.contains(&t), "{file}: a {t} panel: {types:?}");
    }
    let counts = &v["parts"][0]["counts"];
    let mut checked = 0;
    let mut errors = Vec::new();
    for (id, c) in config {
        for topic in c["topics"].as_object().into_iter().flat_map(|t| t.keys()) {
            if counts[topic].as_u64().unwrap_or(0) == 0 {
                errors.push(format!("{id}: no {topic} messages"));
            }
        }
        if let Some(topic) = c["topicToRender"].as_str() {
            if counts[topic].as_u64().unwrap_or(0) == 0 {
                errors.push(format!("{id}: no {topic} messages"));
            }
        }
        for p in c["paths"].as_array().into_iter().flatten() {
            checked += 1;
            if let Err(e) = check_path(p["value"].as_str().expect("a path value"), v) {
                errors.push(format!("{id}: {e}"));
            }
        }
    }
    assert!(errors.is_empty(), "{file}: {errors:#?}");
    checked
}

/// The layout shipped in `docs/` names only topics and message paths a simulated run's session
/// file has, so it cannot rot when a channel or field is renamed.
#[test]
fn the_shipped_layout_refers_only_to_what_a_session_file_has() {
    if coop_tests::python_with(&["mcap", "google.protobuf"]).is_none() {
        return;
    }
    let out = TempDir::unmade("foxglove-layout");
    let run = Command::new(env!("CARGO_BIN_EXE_sim"))
        .arg("run")
        .arg(coop_tests::scenario_path("paper.toml"))
        .arg("--out")
        .arg(&out)
        .output()
        .expect("sim runs");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let v = foxglove_summary(&[out.join("session.mcap")]);
    assert!(
        check_layout("foxglove-layout.json", &v) >= 20,
        "the plots' paths were checked"
    );
    // The check itself fails on a path the file does not have.
    assert!(check_path("/tool{site==\"user1\"}.f_desired[0]", &v).is_ok());
    for bad in [
        "/tools{site==\"user1\"}.f_desired[0]",
        "/tool{site==\"nobody\"}.f_desired[0]",
        "/tool{sight==\"user1\"}.f_desired[0]",
        "/tool{site==\"user1\"}.f_wished[0]",
        "/tool{site==\"user1\"}.f_desired[3]",
        "/tool{site==\"user1\"}.f_desired",
        "/tool.site",
    ] {
        assert!(check_path(bad, &v).is_err(), "{bad} passed");
    }
}

/// The layout for a world of several objects (`docs/foxglove-layout-world.json`, written for
/// `scenarios/stack.toml`: each object's position as each site believes it) names only what a
/// session file of that world has.
#[test]
fn the_world_layout_refers_only_to_what_a_stack_session_file_has() {
    if coop_tests::python_with(&["mcap", "google.protobuf"]).is_none() {
        return;
    }
    let (_, v, _out) = simulated_session("layout-world", "stack.toml", &[]);
    assert!(
        check_layout("foxglove-layout-world.json", &v) >= 18,
        "every object's series were checked"
    );
    assert!(check_path("/object{site==\"user1\"}{object==\"base\"}.pos[2]", &v).is_ok());
    assert!(check_path("/object{site==\"user1\"}{object==\"cup\"}.pos[2]", &v).is_err());
}

/// The `layout.json` a run writes next to its session file, for worlds the shipped layouts were
/// not written for (the tray's two objects; three sites), names only what that session file has,
/// and every object of every site.
#[test]
fn the_layout_written_with_a_session_file_plots_every_object_of_every_site() {
    if coop_tests::python_with(&["mcap", "google.protobuf"]).is_none() {
        return;
    }
    for (file, sites, objects) in [("tray.toml", 2, 2), ("three-lift.toml", 3, 1)] {
        let (sc, v, out) = simulated_session("layout-written", file, &[]);
        assert_eq!(
            (sc.site.len(), sc.objects.len()),
            (sites, objects),
            "{file}"
        );
        let written: Value = serde_json::from_str(
            &std::fs::read_to_string(out.join("layout.json")).expect("layout.json written"),
        )
        .expect("JSON");
        // Each object's x, y, z for each site and the reference, the divergence per site and
        // between sites.
        let expected = 3 * objects * (sites + 1) + sites + 1;
        assert_eq!(check_layout_value(&written, &v), expected, "{file}");
    }
}

/// `session run SCENARIO --method METHOD --json --live 127.0.0.1:0 --out OUT`, running: the
/// launcher, its live view's address, and the thread gathering its log.
fn live_session(
    scenario: &std::path::Path,
    method: &str,
    out: &std::path::Path,
) -> (std::process::Child, String, std::thread::JoinHandle<String>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_session"))
        .current_dir(repo())
        .arg("run")
        .arg(scenario)
        .args(["--method", method, "--json", "--live", "127.0.0.1:0"])
        .arg("--out")
        .arg(out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("session starts");
    let stderr = child.stderr.take().expect("stderr");
    let (url, log) = live_url(stderr, 30, "the launcher");
    (child, url, log)
}

/// Follows a live-view server's stderr: the first `ws://` address it prints (within `limit_s`,
/// else the test fails naming `who`), and a thread that gathers the whole log.
fn live_url(
    stderr: std::process::ChildStderr,
    limit_s: u64,
    who: &str,
) -> (String, std::thread::JoinHandle<String>) {
    let (tx, rx) = std::sync::mpsc::channel();
    let log = std::thread::spawn(move || {
        use std::io::BufRead;
        let mut all = String::new();
        for line in std::io::BufReader::new(stderr)
            .lines()
            .map_while(Result::ok)
        {
            if let Some(url) = line.split_whitespace().find(|w| w.starts_with("ws://")) {
                let _ = tx.send(url.to_owned());
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let url = rx
        .recv_timeout(std::time::Duration::from_secs(limit_s))
        .unwrap_or_else(|_| panic!("{who} prints the live view's address"));
    (url, log)
}

/// A world of several objects in `sim run --out`'s `session.mcap`: read by the foreign reader,
/// every site has a frame and an entity for every object (`object/<name>/<site>`, the first's
/// too), and so has the reference copy, one frame per sample,
/// each entity in a declared frame, in the object's real size; and an `/object` message per
/// object per sample, named.
#[test]
fn a_simulated_world_of_several_objects_has_a_frame_and_an_entity_per_object_per_site() {
    if coop_tests::python_with(&["mcap", "google.protobuf"]).is_none() {
        return;
    }
    let (scenario, v, _out) = simulated_session("sim-objects", "billiards.toml", &[]);
    assert_eq!(scenario.objects.len(), 2);
    let samples = (scenario.duration_s * scenario.sample_rate_hz).round() as u64 + 1;
    let frames = v["frames"].as_object().expect("frames");
    let entities = &v["entities"];
    let target = &scenario.objects[1];
    let (d, h) = (2.0 * target.radius_m, 2.0 * target.half_height_m);
    let sites = scenario.site.iter().map(|s| s.name.as_str());
    let first = scenario.object_name(0);
    for s in sites.chain(["reference"]) {
        assert!(
            !frames.contains_key(&format!("world>object/{s}")),
            "no unnamed object frame in a world of several: {:?}",
            frames.keys().collect::<Vec<_>>()
        );
        for frame in [format!("object/{first}/{s}"), format!("object/target/{s}")] {
            assert_eq!(
                frames[&format!("world>{frame}")].as_u64(),
                Some(samples),
                "{frame} in {:?}",
                frames.keys().collect::<Vec<_>>()
            );
            assert!(entities[&frame].is_object(), "entity {frame}");
        }
        assert_eq!(
            entities[format!("object/target/{s}")]["cylinder_size"],
            serde_json::json!([d, d, h])
        );
        for o in &scenario.objects {
            let key = format!("{s}/{}", o.name);
            assert_eq!(
                v["json"]["/object"][&key].as_u64(),
                Some(samples),
                "/object of {key} in {}",
                v["json"]["/object"]
            );
        }
    }
    assert!(v["json_schemas"]["/object"]["properties"]["object"].is_object());
    entities_sit_in_declared_frames(&v);
}

/// Each entity of the reader's summary `v` sits in `world` or in a frame the file transforms.
fn entities_sit_in_declared_frames(v: &serde_json::Value) {
    let frames = v["frames"].as_object().expect("frames");
    let declared: Vec<&str> = frames
        .keys()
        .map(|k| k.split_once('>').expect("parent>child").1)
        .collect();
    for e in v["entity_frames"].as_array().expect("entity frames") {
        let frame = e[1].as_str().expect("frame");
        assert!(
            frame == "world" || declared.contains(&frame),
            "entity {e} in a frame no /tf declares"
        );
    }
}

/// A world of several objects on real stations (`scenarios/stack.toml`, `timewarp`): a Foxglove
/// WebSocket client gets every site's copy of every object live (a frame and an entity each), and
/// the Python `mcap` reader finds in each site's recording a frame, an entity in its real size and
/// `/object` messages per object.
#[test]
fn a_stack_on_stations_shows_a_frame_and_an_entity_per_object_per_site_live_and_recorded() {
    let _turn = ONE_AT_A_TIME.lock();
    if coop_tests::python_with(&["mcap", "google.protobuf", "websockets"]).is_none() {
        return;
    }
    let scenario_path = coop_tests::scenario_path("stack.toml");
    let scenario = coop_actors::scenario_file::load(&scenario_path).expect("scenario");
    assert_eq!(scenario.objects.len(), 2);
    let (first, second) = (scenario.object_name(0), scenario.object_name(1));
    let out = TempDir::unmade("foxglove-stack");
    let (child, url, log) = live_session(&scenario_path, "timewarp", &out);
    let sites: Vec<&str> = scenario.site.iter().map(|s| s.name.as_str()).collect();
    let others: Vec<String> = sites
        .iter()
        .flat_map(|s| {
            [
                format!("object/{first}/{s}"),
                format!("object/{second}/{s}"),
            ]
        })
        .collect();
    let client = Command::new("python3")
        .arg(repo().join("tools/tests/fixtures/foxglove_live.py"))
        .args([url.as_str(), "60"])
        .args(&sites)
        .env("WANT_TF", others.join(","))
        .env("FIRST_OBJECT", first)
        .output()
        .expect("python3 runs");
    let session = child.wait_with_output().expect("session ends");
    let launcher_log = log.join().unwrap_or_default();
    assert!(
        client.status.success(),
        "the client failed: {}",
        String::from_utf8_lossy(&client.stderr)
    );
    assert!(session.status.success(), "session failed: {launcher_log}");
    let v: Value = serde_json::from_slice(&client.stdout).expect("the client prints JSON");
    assert_eq!(v["errors"], serde_json::json!([]), "{v}");
    assert_eq!(v["complete"], true, "every object of every site live: {v}");
    for f in &others {
        let ids: Vec<&str> = v["scene_ids"]
            .as_array()
            .expect("scene ids")
            .iter()
            .filter_map(Value::as_str)
            .collect();
        assert!(ids.contains(&f.as_str()), "entity {f} live: {ids:?}");
    }
    // The recordings, read by the foreign reader.
    let half = scenario.objects[1].half_extents_m;
    for site in &sites {
        let parts =
            coop_transport::recording::read(&out.join("timewarp").join(format!("{site}.mcap")))
                .expect("the recording reads")
                .files;
        let r = foxglove_summary(&parts);
        assert_eq!(r["errors"], serde_json::json!([]), "{site}");
        let frames = r["frames"].as_object().expect("frames");
        for frame in [
            format!("object/{first}/{site}"),
            format!("object/{second}/{site}"),
        ] {
            assert!(
                frames[&format!("world>{frame}")].as_u64() > Some(1000),
                "{site}: {frame} in {:?}",
                frames.keys().collect::<Vec<_>>()
            );
            assert!(r["entities"][&frame].is_object(), "{site}: entity {frame}");
        }
        assert_eq!(
            r["entities"][format!("object/{second}/{site}")]["cube_size"],
            serde_json::json!([2.0 * half[0], 2.0 * half[1], 2.0 * half[2]]),
            "{site}: the second object in its real size"
        );
        for o in [first, second] {
            let key = format!("{site}/{o}");
            assert!(
                r["json"]["/object"][&key].as_u64() > Some(1000),
                "/object of {key}: {}",
                r["json"]["/object"]
            );
        }
        entities_sit_in_declared_frames(&r);
    }
    // The launcher's result names each object, in its figures and in each station's status.
    let result: Value = serde_json::from_slice(&session.stdout).expect("the session's JSON");
    let objects = &result["methods"]["timewarp"]["objects"];
    assert_eq!(objects[0]["name"], first, "{result}");
    assert_eq!(objects[1]["name"], second, "{result}");
    for site in &sites {
        let status = &result["methods"]["timewarp"]["stations"][site]["live"]["physics"]["objects"];
        let names: Vec<&str> = status
            .as_array()
            .map(|a| a.iter().filter_map(|o| o["name"].as_str()).collect())
            .unwrap_or_default();
        assert_eq!(names, [first, second], "{site}'s status: {status}");
        // What it put and got, counted by kind over its network process's life: tool tracks
        // only (timewarp sends no states), each within the wire's bounds for a track.
        let t = &result["methods"]["timewarp"]["stations"][site]["final"]["traffic"];
        let n = |f: &str, k: usize| t[f][k].as_u64().unwrap_or(0);
        let longest = coop_transport::wire::MAX_TRACK_ENCODED_LEN as u64;
        assert!(n("sent_msgs", 1) > 50, "{site} put its tracks: {t}");
        assert!(n("received_msgs", 1) > 50, "{site} got the other's: {t}");
        for (msgs, bytes) in [
            ("sent_msgs", "sent_bytes"),
            ("received_msgs", "received_bytes"),
        ] {
            let (m, b) = (n(msgs, 1), n(bytes, 1));
            assert!(b > m * 20 && b <= m * longest, "{site}: {bytes}: {t}");
        }
        assert_eq!(
            (n("sent_msgs", 0), n("received_msgs", 0)),
            (0, 0),
            "{site}: no states: {t}"
        );
        assert!(
            n("sent_msgs", 2) > 0 && n("received_bytes", 2) > 0,
            "{site}: clock: {t}"
        );
    }
    let wire = result["methods"]["timewarp"]["wire"]
        .as_array()
        .expect("wire rows");
    assert_eq!(wire.len(), sites.len(), "{result}");
}
