//! `study` as a lab uses it: a study file checked with errors that name the field, every group's
//! order counterbalanced, a pilot in the simulator whose table holds every trial once, a runner
//! killed mid-run and resumed without losing or repeating a finished trial, the same people in
//! every trial of a group, and the report's figures from the table.

use std::path::Path;
use std::process::{Command, Output, Stdio};

use coop_tests::{repo, TempDir};

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
    let unmark = |l: &str| l.rsplit_once(',').expect("cells").0.to_owned();
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
    for r in after.iter().filter(|r| r.2.ends_with(",1")) {
        assert!(!before
            .iter()
            .any(|b| b.0 == r.0 && b.1 == r.1 && b.2.ends_with(",0")));
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
