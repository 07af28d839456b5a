//! `study run --stations`: a study's trials on live stations of this machine, started once for a
//! run (no process of theirs restarted between trials, each trial its own recordings), a runner
//! killed in the middle of a trial and resumed (no finished trial lost or repeated, the cut one
//! run again and marked), and a study whose conditions cannot share stations refused before
//! anything starts; with the experimenter's page, a trial repeated on the same stations while the
//! questionnaire is owed, and the run aborted there.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use coop_tests::{repo, TempDir};

const STUDY: &str = env!("CARGO_BIN_EXE_study");

/// The paper task (participants) at three constant delays, one group, one trial each, `method`;
/// `extra` appended.
fn study_file(dir: &Path, methods: &str, extra: &str) -> std::path::PathBuf {
    let scenario = repo().join("scenarios/participants/paper.toml");
    let file = dir.join("live.toml");
    std::fs::write(
        &file,
        format!(
            "name = \"live\"\nscenario = {scenario:?}\nseed = 3\ngroups = 1\nrepetitions = 1\npractice = 0\norder = \"fixed\"\ntimeout_s = 9.0\n\n[[factor]]\nname = \"method\"\nset = [\"method\"]\nlevels = {methods}\n\n[[factor]]\nname = \"delay_ms\"\nset = [\"network.delay_min_ms\", \"network.delay_max_ms\"]\nlevels = [0.0, 50.0, 100.0]\n{extra}"
        ),
    )
    .expect("write the study file");
    file
}

/// The data rows of a CSV file, split into cells, by the header's names.
fn table(path: &Path) -> Vec<std::collections::BTreeMap<String, String>> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let mut lines = text.lines();
    let head: Vec<String> = lines
        .next()
        .unwrap_or_default()
        .split(',')
        .map(str::to_owned)
        .collect();
    lines
        .map(|l| {
            head.iter()
                .cloned()
                .zip(l.split(',').map(str::to_owned))
                .collect()
        })
        .collect()
}

/// Shared-memory segments of sessions named `study-<pid>-…` left in /dev/shm.
fn segments_of(pid: u32) -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.contains(&format!("study-{pid}-")))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_study_on_stations_started_once_resumes_after_its_runner_is_killed_mid_trial() {
    let d = TempDir::new("study-stations");
    let file = study_file(&d, "[\"timewarp\"]", "");
    let out = d.join("run");
    let (file_s, out_s) = (file.to_str().expect("utf-8"), out.to_str().expect("utf-8"));
    let mut runner = Command::new(STUDY)
        .args(["run", "--stations", file_s, "--out", out_s])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start study run --stations");
    let pid = runner.id();
    // Killed once the second trial has begun (the first one's rows are in the table).
    let begun = out.join("begun.txt");
    let waited = Instant::now();
    while std::fs::read_to_string(&begun).map_or(0, |t| t.lines().count()) < 2 {
        assert!(
            runner.try_wait().expect("poll the runner").is_none(),
            "the runner ended before its second trial"
        );
        assert!(
            waited.elapsed() < Duration::from_secs(120),
            "no second trial begun in 120 s"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    runner.kill().expect("kill the runner");
    let _ = runner.wait();
    let before = table(&out.join("trials.csv"));
    assert_eq!(before.len(), 2, "the first trial's two rows: {before:?}");
    // Its stations die with it and leave nothing behind.
    let waited = Instant::now();
    while !segments_of(pid).is_empty() {
        assert!(
            waited.elapsed() < Duration::from_secs(30),
            "segments left: {:?}",
            segments_of(pid)
        );
        std::thread::sleep(Duration::from_millis(50));
    }

    let resumed = std::time::SystemTime::now();
    let o = Command::new(STUDY)
        .args(["run", "--stations", file_s, "--out", out_s, "--resume"])
        .output()
        .expect("resume");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("between trials"), "{err}");
    let after = table(&out.join("trials.csv"));
    assert_eq!(
        after.len(),
        3 * 2,
        "three trials, two sites each: {after:?}"
    );
    for (r, b) in after.iter().zip(&before) {
        assert_eq!(r, b, "a finished trial kept as it was");
    }
    for r in &after {
        let trial = &r["trial"];
        assert_eq!(
            r["cut"],
            if trial == "2" { "1" } else { "0" },
            "only the cut trial is marked: {r:?}"
        );
        assert!(
            matches!(r["outcome"].as_str(), "done" | "failed"),
            "each site judged its task: {r:?}"
        );
        assert_eq!(r["site_done"] == "1", !r["site_time_s"].is_empty(), "{r:?}");
        assert!(r["sent_bytes"].parse::<u64>().expect("bytes") > 0, "{r:?}");
        // From the trial's recordings and its rollbacks (timewarp): measured, not left empty.
        for col in ["co_divergence_max_mm", "phantom_ms", "unfelt_ms"] {
            let v: f64 = r[col]
                .parse()
                .unwrap_or_else(|_| panic!("{col} measured: {r:?}"));
            assert!(v >= 0.0, "{col}: {r:?}");
        }
    }
    // Every trial left each station's recording of it; the cut trial's and the last are the
    // resumed run's.
    for t in 1..=3 {
        for site in ["user1", "user2"] {
            let p = out.join(format!("stations/{site}-g01-t{t:03}.mcap"));
            let m = std::fs::metadata(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            assert!(m.len() > 0, "{}", p.display());
            let written = m.modified().expect("mtime");
            assert_eq!(written >= resumed, t > 1, "{}", p.display());
        }
    }
    // The resumed run's stations ran trials 2 and 3 with the same processes.
    let log = table(&out.join("stations/trials.csv"));
    for site in ["user1", "user2"] {
        let pids = |trial: &str| {
            log.iter()
                .rev()
                .find(|r| r["site"] == site && r["trial"] == trial)
                .map(|r| {
                    (
                        r["servo_pid"].clone(),
                        r["physics_pid"].clone(),
                        r["network_pid"].clone(),
                    )
                })
                .expect("a trial in the stations' log")
        };
        let (two, three) = (pids("2"), pids("3"));
        assert_eq!(two, three, "{site}: a process restarted between trials");
        assert!(two.0 != "0" && two.1 != "0" && two.2 != "0", "{two:?}");
    }
}

#[test]
fn conditions_that_cannot_share_stations_are_refused_before_anything_starts() {
    let d = TempDir::new("study-stations-mixed");
    let file = study_file(&d, "[\"timewarp\", \"paper\"]", "");
    let out = d.join("run");
    let o = Command::new(STUDY)
        .args([
            "run",
            "--stations",
            file.to_str().expect("utf-8"),
            "--out",
            out.to_str().expect("utf-8"),
        ])
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("method=paper") && err.contains("tool tracks"),
        "{err}"
    );
    assert!(!out.join("stations").exists(), "nothing started");
}

/// `POST /control` with `action` and the experimenter's `key`: the reply's status line.
fn control(url: &str, key: &str, action: &str) -> String {
    use std::io::{Read, Write};
    let addr = url.trim_start_matches("http://");
    let body = format!("action={action}&key={key}");
    let mut s = std::net::TcpStream::connect(addr).expect("connect to the page");
    write!(
        s,
        "POST /control HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
    .expect("send");
    let mut reply = String::new();
    let _ = s.read_to_string(&mut reply);
    reply.lines().next().unwrap_or_default().to_owned()
}

/// Waits (at most 120 s) until `path` has `rows` data rows.
fn wait_rows(path: &Path, rows: usize, runner: &mut std::process::Child) {
    let waited = Instant::now();
    while table(path).len() < rows {
        assert!(
            runner.try_wait().expect("poll the runner").is_none(),
            "the runner ended early"
        );
        assert!(
            waited.elapsed() < Duration::from_secs(120),
            "no {rows} rows in 120 s"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn the_experimenter_repeats_a_trial_on_the_same_stations_and_aborts_the_run() {
    use std::io::BufRead;
    let d = TempDir::new("study-stations-served");
    // A questionnaire after each block: the run waits there for the experimenter's repeat.
    let extra = "\n[questionnaire]\nnasa_tlx = false\n\n[[questionnaire.item]]\nname = \"ease\"\ntext = \"It was easy\"\npoints = 7\nlow = \"no\"\nhigh = \"yes\"\n";
    let file = study_file(&d, "[\"timewarp\"]", extra);
    let out = d.join("run");
    let mut runner = Command::new(STUDY)
        .args(["run", "--stations"])
        .arg(&file)
        .arg("--out")
        .arg(&out)
        .args(["--serve", "127.0.0.1:0"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start study run --stations --serve");
    let pid = runner.id();
    let mut err = std::io::BufReader::new(runner.stderr.take().expect("stderr"));
    let (url, key) = {
        let mut line = String::new();
        loop {
            line.clear();
            assert!(
                err.read_line(&mut line).expect("stderr") > 0,
                "no address printed"
            );
            if let Some(rest) = line.split("serving ").nth(1) {
                let url = rest.split_whitespace().next().expect("url");
                let key = line
                    .split("?key=")
                    .nth(1)
                    .and_then(|k| k.split_whitespace().next());
                break (
                    url.trim_end_matches('/').to_owned(),
                    key.expect("key").to_owned(),
                );
            }
        }
    };
    let log = std::thread::spawn(move || {
        let mut rest = String::new();
        let _ = std::io::Read::read_to_string(&mut err, &mut rest);
        rest
    });
    let table_path = out.join("trials.csv");
    // The first block's trial; then the questionnaire is owed, and the trial is repeated.
    wait_rows(&table_path, 2, &mut runner);
    assert!(
        control(&url, &key, "repeat").contains("303"),
        "repeat taken"
    );
    wait_rows(&table_path, 4, &mut runner);
    assert!(control(&url, &key, "abort").contains("303"), "abort taken");
    // Aborted while the questionnaire is owed: the run ends there, its stations stop, and the
    // page waits to be closed.
    let waited = Instant::now();
    loop {
        let r = control(&url, &key, "close");
        if r.contains("200") {
            break;
        }
        assert!(r.contains("409"), "{r}");
        assert!(
            waited.elapsed() < Duration::from_secs(60),
            "the run never finished"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let status = runner.wait().expect("the runner exits once closed");
    let said = log.join().unwrap_or_default();
    assert!(status.success(), "{said}");
    assert!(said.contains("(none restarted)"), "{said}");
    let rows = table(&table_path);
    assert_eq!(rows.len(), 4, "trial 1 twice, nothing else: {rows:?}");
    for (r, attempt) in rows.iter().zip(["1", "1", "2", "2"]) {
        assert_eq!(r["trial"], "1", "{r:?}");
        assert_eq!(r["attempt"], attempt, "{r:?}");
    }
    for name in ["g01-t001", "g01-t001-a2"] {
        for site in ["user1", "user2"] {
            let p = out.join(format!("stations/{site}-{name}.mcap"));
            assert!(p.is_file(), "{}", p.display());
        }
    }
    assert!(segments_of(pid).is_empty(), "{:?}", segments_of(pid));
}
