//! `study` as a lab uses it: a study file checked with errors that name the field, every group's
//! order counterbalanced, a pilot in the simulator whose table holds every trial once, a runner
//! killed mid-run and resumed without losing or repeating a finished trial, the same people in
//! every trial of a group, and the report's figures from the table.

use std::path::Path;
use std::process::{Command, Output, Stdio};

use coop_tests::{repo, Reaped, TempDir};

const STUDY: &str = env!("CARGO_BIN_EXE_study");

/// A small study of the paper task (participants): two groups, two delays, one practice and
/// one measured trial per condition, short trials; `extra` appended.
fn small_study(dir: &Path, extra: &str) -> std::path::PathBuf {
    let scenario = repo().join("scenarios/participants/paper.toml");
    let file = dir.join("small.toml");
    std::fs::write(
        &file,
        format!(
            "name = \"small\"\nscenario = {scenario:?}\nseed = 5\ngroups = 2\nrepetitions = 1\npractice = 1\ntimeout_s = 8.0\n{extra}\n[[factor]]\nname = \"delay_ms\"\nset = [\"network.delay_min_ms\", \"network.delay_max_ms\"]\nlevels = [0.0, 100.0]\n"
        ),
    )
    .expect("write the study file");
    file
}

fn study(args: &[&str]) -> Output {
    Command::new(STUDY).args(args).output().expect("run study")
}

fn text(o: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// The table's data rows, as (group, trial, the rest of the row).
fn rows(dir: &Path) -> Vec<(String, usize, String)> {
    std::fs::read_to_string(dir.join("trials.csv"))
        .expect("trials.csv")
        .lines()
        .skip(1)
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            (
                c[1].to_owned(),
                c[5].parse().expect("a trial number"),
                l.to_owned(),
            )
        })
        .collect()
}

#[test]
fn the_plan_counterbalances_and_bad_files_are_refused_by_field() {
    let d = TempDir::new("study-plan");
    let file = small_study(&d, "");
    let o = study(&["plan", file.to_str().expect("utf-8")]);
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}");
    // Two conditions, a practice and a measured trial each: 4 trials per group; the two
    // groups take the Williams square's two rows, so their orders are each other's reverse.
    assert!(out.contains("2 groups of 2"), "{out}");
    let order = |g: &str| -> Vec<String> {
        out.lines()
            .filter(|l| l.starts_with(g))
            .map(|l| l.split_whitespace().last().expect("a condition").to_owned())
            .collect()
    };
    assert_eq!(
        order("g01"),
        [
            "delay_ms=0.0",
            "delay_ms=0.0",
            "delay_ms=100.0",
            "delay_ms=100.0"
        ]
    );
    assert_eq!(
        order("g02"),
        [
            "delay_ms=100.0",
            "delay_ms=100.0",
            "delay_ms=0.0",
            "delay_ms=0.0"
        ]
    );
    assert_eq!(out.matches("practice").count(), 4 + 1, "{out}");
    for (bad, says) in [
        (
            "[[factor]]\nname = \"m\"\nset = [\"netwrk.delay_ms\"]\nlevels = [1.0]\n",
            "netwrk",
        ),
        (
            "[[factor]]\nname = \"m\"\nset = [\"method\"]\nlevels = [\"fastest\"]\n",
            "fastest",
        ),
        (
            "[[factor]]\nname = \"m\"\nset = [\"site.5.elbow\"]\nlevels = [1.0]\n",
            "past the array's 2",
        ),
        (
            "[[factor]]\nname = \"m\"\nset = [\"method\"]\nlevels = [\"paper\", \"paper\"]\n",
            "levels must differ",
        ),
        (
            "[[factor]]\nname = \"trial\"\nset = [\"method\"]\nlevels = [\"paper\"]\n",
            "column of the trial table",
        ),
        (
            "[[factor]]\nname = \"m\"\nset = [\"description\"]\nlevels = [\"two\\nlines\"]\n",
            "one line",
        ),
        (
            "[[group]]\nid = \"a\"\nparticipants = [\"p1\"]\n",
            "not both",
        ),
    ] {
        let file = small_study(&d, bad);
        let o = study(&["plan", file.to_str().expect("utf-8")]);
        let (_, err) = text(&o);
        assert!(!o.status.success(), "accepted: {bad}");
        assert!(
            err.contains(says) && err.contains("small.toml"),
            "{bad}: {err}"
        );
    }
}

#[test]
fn a_pilot_killed_mid_run_resumes_without_losing_or_repeating_a_trial_and_reports() {
    let d = TempDir::new("study-run");
    let file = small_study(&d, "");
    let out = d.join("run");
    let (file_s, out_s) = (file.to_str().expect("utf-8"), out.to_str().expect("utf-8"));
    // The whole run, for comparison.
    let whole = d.join("whole");
    let o = study(&[
        "run",
        "--sim",
        file_s,
        "--out",
        whole.to_str().expect("utf-8"),
    ]);
    assert!(o.status.success(), "{}", text(&o).1);
    let all = rows(&whole);
    assert_eq!(all.len(), 2 * 4 * 2, "2 groups × 4 trials × 2 sites");
    // Killed once its first batch is in the table.
    let mut child = Command::new(STUDY)
        .args(["run", "--sim", file_s, "--out", out_s])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start study run");
    let table = out.join("trials.csv");
    while std::fs::read_to_string(&table).map_or(0, |t| t.lines().count()) < 2 {
        if child.try_wait().expect("poll study run").is_some() {
            break;
        }
        std::thread::yield_now();
    }
    let _ = child.kill();
    let _ = child.wait();
    let before = rows(&out);
    // Not over an existing run without --resume.
    let o = study(&["run", "--sim", file_s, "--out", out_s]);
    assert!(!o.status.success() && text(&o).1.contains("--resume"));
    let o = study(&["run", "--sim", file_s, "--out", out_s, "--resume"]);
    assert!(o.status.success(), "{}", text(&o).1);
    let after = rows(&out);
    // Every trial once, each site's row as the uncut run's (the cut mark aside), and every row
    // kept from before the kill still there.
    let mut keys: Vec<(String, usize)> = after.iter().map(|r| (r.0.clone(), r.1)).collect();
    keys.sort();
    keys.dedup();
    assert_eq!(keys.len(), 8);
    assert_eq!(after.len(), all.len());
    // The row without its `cut` mark (the last cell but one; the last is the attempt).
    let unmark = |l: &str| {
        let mut c: Vec<&str> = l.split(',').collect();
        let n = c.len();
        c.remove(n - 2);
        c.join(",")
    };
    let cut = |l: &str| l.split(',').rev().nth(1) == Some("1");
    let mut a: Vec<String> = after.iter().map(|r| unmark(&r.2)).collect();
    let mut w: Vec<String> = all.iter().map(|r| unmark(&r.2)).collect();
    a.sort();
    w.sort();
    assert_eq!(a, w, "the resumed run's rows are the uncut run's");
    for r in &before {
        if before.iter().filter(|b| b.0 == r.0 && b.1 == r.1).count() == 2 {
            assert!(
                after.iter().any(|a| a.2 == r.2),
                "a finished trial was lost or changed"
            );
        }
    }
    // A trial marked cut was begun before the kill and not finished then.
    for r in after.iter().filter(|r| cut(&r.2)) {
        assert!(!before
            .iter()
            .any(|b| b.0 == r.0 && b.1 == r.1 && !cut(&b.2)));
    }
    // The report: every measured trial, practice left out, and the files it writes.
    let o = study(&["report", out_s]);
    let (rep, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        rep.contains("2 groups, 4 measured trials (4 practice trials left out)"),
        "{rep}"
    );
    for f in [
        "cells.csv",
        "report.txt",
        "task.svg",
        "meta.json",
        "study.toml",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let cells = std::fs::read_to_string(out.join("cells.csv")).unwrap();
    assert_eq!(cells.lines().count(), 1 + 2 * 2, "{cells}");
}

#[test]
fn a_group_keeps_its_people_through_trials_whose_runs_differ() {
    let d = TempDir::new("study-people");
    let file = small_study(&d, "");
    let s = coop_tools::study::Study::load(&file).expect("load the study");
    let plan = s.plan();
    let g0: Vec<_> = plan.iter().filter(|t| t.group == 0).collect();
    let sc = |t: &coop_tools::study::Trial| {
        s.scenario_for(&t.levels, t.seed, s.people_seed(t.group))
            .expect("a condition's scenario")
    };
    let (a, b) = (sc(g0[0]), sc(g0[1]));
    assert_ne!(a.seed, b.seed, "each trial its own run");
    let person =
        |sc: &coop_model::scenario::Scenario| sc.participant(0).expect("a participant").person;
    assert_eq!(person(&a), person(&b), "the same person in both");
    let other = plan.iter().find(|t| t.group == 1).expect("group 2");
    assert_ne!(
        person(&a),
        person(&sc(other)),
        "another group, other people"
    );
    // Without a people seed, the person is drawn from the run's seed as before.
    let mut c = a.clone();
    c.people_seed = None;
    let mut e = a.clone();
    e.people_seed = None;
    e.seed += 1;
    assert_ne!(person(&c), person(&e));
}

#[test]
fn run_needs_sim_and_report_needs_a_run() {
    let d = TempDir::new("study-misuse");
    let file = small_study(&d, "");
    let o = study(&[
        "run",
        file.to_str().expect("utf-8"),
        "--out",
        d.join("x").to_str().expect("utf-8"),
    ]);
    assert!(!o.status.success() && text(&o).1.contains("--sim"));
    let o = study(&["report", d.to_str().expect("utf-8")]);
    assert!(
        !o.status.success() && text(&o).1.contains("no trials.csv"),
        "{}",
        text(&o).1
    );
}

/// Every shipped study file (`scenarios/studies/`) is valid, its every condition a valid
/// scenario, so none rots unnoticed.
#[test]
fn every_shipped_study_is_valid() {
    let mut checked = 0;
    for e in std::fs::read_dir(repo().join("scenarios/studies")).expect("scenarios/studies") {
        let path = e.expect("entry").path();
        if path.extension().is_some_and(|x| x == "toml") {
            let s = coop_tools::study::Study::load(&path)
                .unwrap_or_else(|err| panic!("{}: {err:#}", path.display()));
            assert!(!s.plan().is_empty());
            checked += 1;
        }
    }
    assert!(checked >= 1, "the shipped studies were found");
}

/// The experimenter's page and the questionnaires in a real browser (headless Chromium through
/// WebDriver): the run paused and resumed from the page, each participant's questionnaire
/// answered after each block, an off-scale answer refused, the answers kept as sent, and the
/// report's questionnaire scores from them.
#[test]
fn questionnaires_are_answered_in_a_browser_between_blocks() {
    if coop_tests::python_with(&["selenium"]).is_none() {
        return;
    }
    let d = TempDir::new("study-browser");
    let file = small_study(
        &d,
        "[questionnaire]\nnasa_tlx = true\n[[questionnaire.item]]\nname = \"copresence\"\ntext = \"I felt my partner was there with me\"\n",
    );
    // Without practice trials: two blocks per group, four questionnaires per group.
    let written = std::fs::read_to_string(&file).expect("study file");
    std::fs::write(&file, written.replace("practice = 1", "practice = 0")).expect("study file");
    let out = d.join("run");
    let (mut run, url, key) = serve(&file, &out);
    let browser = Command::new("python3")
        .arg(repo().join("tools/tests/fixtures/study_browser.py"))
        .args([url.as_str(), key.as_str(), "120"])
        // Chromium's own temporary files, into the test's directory (removed with it).
        .env("TMPDIR", d.path())
        .output()
        .expect("python3 runs");
    if browser.status.code() == Some(2) && std::env::var_os("COOP_REQUIRE_MCAP_PY").is_none() {
        eprintln!(
            "SKIPPED the browser check: {}",
            String::from_utf8_lossy(&browser.stderr)
        );
        return;
    }
    assert!(
        browser.status.success(),
        "the browser failed: {}",
        String::from_utf8_lossy(&browser.stderr)
    );
    let status = run
        .wait_timeout(std::time::Duration::from_secs(60))
        .expect("study run ends once its page is closed");
    assert!(status.success(), "study run failed");
    let v: serde_json::Value = serde_json::from_slice(&browser.stdout).expect("JSON");
    assert_eq!(v["paused_seen"], true, "{v}");
    assert_eq!(v["status_paused"], "paused", "{v}");
    assert_eq!(v["resumed_seen"], true, "{v}");
    assert_eq!(
        v["buttons_without_key"], 0,
        "no control without the key: {v}"
    );
    assert_eq!(v["refused_off_scale"], true, "{v}");
    assert_eq!(v["last_progress"], "trial 4 of 4 — finished", "{v}");
    assert_eq!(v["closed"], "The study runner has exited.", "{v}");
    // The repeat: the first trial's second attempt, its rows beside the first's, and the report
    // counting the trial once (its last attempt).
    assert_eq!(v["repeated"].as_array().map(Vec::len), Some(1), "{v}");
    let table = std::fs::read_to_string(out.join("trials.csv")).expect("trials.csv");
    let second: Vec<&str> = table.lines().filter(|l| l.ends_with(",0,2")).collect();
    assert_eq!(second.len(), 2, "one trial's two sites, attempt 2: {table}");
    assert!(
        second
            .iter()
            .all(|l| l.starts_with("small,g01,") && l.contains(",1,1,0,1,")),
        "{table}"
    );
    let answers = v["answers"].as_array().expect("answers");
    // 2 groups × 2 blocks × 2 participants.
    assert_eq!(answers.len(), 8, "{v}");
    // Every answer kept as sent: one row per item.
    let kept = std::fs::read_to_string(out.join("questionnaires.csv")).expect("answers kept");
    let rows: Vec<Vec<&str>> = kept
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 8 * 7, "{kept}");
    for a in answers {
        let who = a["participant"].as_str().expect("who");
        let block = a["block"].as_u64().expect("block").to_string();
        for (item, value) in a["sent"].as_object().expect("sent") {
            let row = rows
                .iter()
                .find(|r| r[2] == who && r[4] == block && r[6] == item)
                .unwrap_or_else(|| panic!("{who} block {block} {item}: not kept"));
            assert_eq!(row[7], value.to_string(), "{who} block {block} {item}");
        }
    }
    // The report's questionnaire scores.
    let o = study(&["report", out.to_str().expect("utf-8")]);
    let (rep, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(rep.contains("questionnaires: 8 answered"), "{rep}");
    assert!(rep.contains("2 groups, 4 measured trials"), "{rep}");
    assert!(
        rep.contains("tlx_raw") && rep.contains("copresence"),
        "{rep}"
    );
    assert!(out.join("questionnaire.svg").is_file());
}

/// `study run --sim FILE --out OUT --serve` on any free port: the run (killed and reaped if
/// the test fails on the way), its base address and the experimenter's key.
fn serve(file: &Path, out: &Path) -> (Reaped, String, String) {
    let mut run = Command::new(STUDY)
        .args(["run", "--sim"])
        .arg(file)
        .arg("--out")
        .arg(out)
        .args(["--serve", "127.0.0.1:0"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start study run");
    let mut err = std::io::BufReader::new(run.stderr.take().expect("stderr"));
    let run = Reaped(Some(run));
    let (url, key) = served(&mut err);
    // The rest of its stderr read to the end: a closed pipe would fail its later lines.
    std::thread::spawn(move || std::io::copy(&mut err, &mut std::io::sink()));
    (run, url, key)
}

/// The base address and the experimenter's key `study run --serve` prints on its stderr.
fn served(err: &mut impl std::io::BufRead) -> (String, String) {
    let mut line = String::new();
    while err.read_line(&mut line).expect("stderr") > 0 {
        if let Some(rest) = line.split("serving ").nth(1) {
            let url = rest
                .split_whitespace()
                .next()
                .expect("url")
                .trim_end_matches('/');
            let key = line
                .split("?key=")
                .nth(1)
                .and_then(|k| k.split_whitespace().next())
                .expect("the experimenter's key");
            assert!(url.starts_with("http://127.0.0.1:"), "{line}");
            return (url.to_owned(), key.to_owned());
        }
        line.clear();
    }
    panic!("no address printed");
}

/// The page refuses what a broken or hostile client sends, with a status and a reason, and
/// nothing changes.
#[test]
fn the_page_refuses_malformed_requests() {
    use std::io::{Read, Write};
    let d = TempDir::new("study-hostile");
    let file = small_study(&d, "[questionnaire]\nnasa_tlx = true\n");
    let out = d.join("run");
    let (mut run, url, key) = serve(&file, &out);
    let addr = url.trim_start_matches("http://").to_owned();
    let ask = |raw: &[u8]| -> String {
        let mut c = std::net::TcpStream::connect(&addr).expect("connect");
        c.write_all(raw).expect("send");
        let _ = c.shutdown(std::net::Shutdown::Write);
        let mut s = String::new();
        let _ = c.read_to_string(&mut s);
        s
    };
    for (raw, status) in [
        (b"GARBAGE\r\n\r\n".to_vec(), "400"),
        (b"GET /nowhere HTTP/1.1\r\nHost: x\r\n\r\n".to_vec(), "404"),
        (b"DELETE / HTTP/1.1\r\nHost: x\r\n\r\n".to_vec(), "405"),
        (b"POST /control HTTP/1.1\r\nHost: x\r\n\r\n".to_vec(), "411"),
        (
            b"POST /control HTTP/1.1\r\nContent-Length: 99999999\r\n\r\n".to_vec(),
            "413",
        ),
        (
            b"POST /control HTTP/1.1\r\nContent-Length: 12\r\n\r\naction=abort".to_vec(),
            "403",
        ),
        (
            format!(
                "POST /control HTTP/1.1\r\nContent-Length: {}\r\n\r\nkey={key}&action=zap",
                15 + key.len()
            )
            .into_bytes(),
            "400",
        ),
        (
            b"POST /q/nobody HTTP/1.1\r\nContent-Length: 3\r\n\r\na=1".to_vec(),
            "409",
        ),
        (
            [
                b"GET / HTTP/1.1\r\n".to_vec(),
                b"X: y\r\n".repeat(2000),
                b"\r\n".to_vec(),
            ]
            .concat(),
            "431",
        ),
    ] {
        let reply = ask(&raw);
        assert!(
            reply.starts_with(&format!("HTTP/1.1 {status}")),
            "{}: {reply}",
            String::from_utf8_lossy(&raw[..raw.len().min(40)])
        );
    }
    // Still serving, still running, nothing paused or aborted by any of it.
    let page = ask(b"GET /status.json HTTP/1.1\r\nHost: x\r\n\r\n");
    assert!(page.contains("\"control\":\"running\""), "{page}");
    // Not closed while it runs; aborted, then closed.
    let control = |action: &str| {
        let body = format!("key={key}&action={action}");
        let request = format!(
            "POST /control HTTP/1.1\r\nContent-Length: {}\r\n\r\n{body}",
            body.len()
        );
        ask(request.as_bytes())
    };
    let early = control("close");
    assert!(early.starts_with("HTTP/1.1 409"), "{early}");
    let _ = control("abort");
    let until = std::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let s = ask(b"GET /status.json HTTP/1.1\r\nHost: x\r\n\r\n");
        if s.contains("\"finished\":true") {
            break;
        }
        assert!(
            std::time::Instant::now() < until,
            "the abort did not end the run: {s}"
        );
        // Polled, as a page would.
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let _ = control("close");
    let status = run
        .wait_timeout(std::time::Duration::from_secs(60))
        .expect("study run ends once its page is closed");
    assert!(status.success(), "an aborted run ends cleanly");
    let page_gone = std::net::TcpStream::connect(&addr).is_err();
    assert!(page_gone, "the page ends with the run");
}
