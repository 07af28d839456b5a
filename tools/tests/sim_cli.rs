//! The simulator as a user runs it: bad scenario files are refused with the field, value and
//! rule and create nothing; runs are deterministic to the byte; on the paper's experiment the naive
//! Eq. 8 method diverges far beyond the disk while the paper's method keeps the copies together once
//! contacts end; with zero delay and equal rates both match the reference run; a phase that did
//! not happen says why.

use std::process::Command;

use coop_model::metrics;
use coop_model::scenario::MethodName;
use coop_model::sim::{self, Mode};
use coop_tests::{load_scenario, repo, TempDir};

const SIM: &str = env!("CARGO_BIN_EXE_sim");

#[test]
fn bad_scenarios_name_the_field_and_create_nothing() {
    let dir = repo().join("tools/tests/fixtures/scenarios");
    let expected: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("expected.json")).expect("expected.json"),
    )
    .expect("json");
    let expected = expected.as_object().expect("object");
    assert!(expected.len() >= 10, "one fixture per rule");
    let bad = TempDir::unmade("sim-bad");
    for (file, needle) in expected {
        let out = bad.join(file);
        let o = Command::new(SIM)
            .arg("run")
            .arg(dir.join(file))
            .arg("--out")
            .arg(&out)
            .output()
            .expect("run sim");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{file}: accepted");
        let needle = needle.as_str().expect("string");
        assert!(
            err.contains(needle),
            "{file}: stderr lacks {needle:?}:\n{err}"
        );
        assert!(
            err.contains(file.as_str()),
            "{file}: the error names the file:\n{err}"
        );
        assert!(!out.exists(), "{file}: created {}", out.display());
    }
}

/// Determinism contract (H9): the same scenario and seed give byte-identical traces and metrics; a
/// different seed gives a different trace (so the comparison can fail).
#[test]
fn same_seed_gives_byte_identical_outputs() {
    let sc = load_scenario("paper.toml");
    let a = sim::run(&sc, Mode::Distributed(MethodName::Paper), &mut |_| {});
    let b = sim::run(&sc, Mode::Distributed(MethodName::Paper), &mut |_| {});
    assert_eq!(a.trace_csv(), b.trace_csv());
    assert_eq!(a.adoptions_csv(), b.adoptions_csv());
    let mut other = sc.clone();
    other.seed += 1;
    let c = sim::run(&other, Mode::Distributed(MethodName::Paper), &mut |_| {});
    assert_ne!(a.trace_csv(), c.trace_csv(), "the seed must matter");

    // And through the CLI, every output file.
    let (d1, d2) = (TempDir::unmade("sim-det1"), TempDir::unmade("sim-det2"));
    for d in [&d1, &d2] {
        let o = Command::new(SIM)
            .args(["run", "scenarios/paper.toml", "--method", "naive", "--out"])
            .arg(d)
            .current_dir(repo())
            .output()
            .expect("run sim");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    for f in [
        "trace.csv",
        "reference_trace.csv",
        "adoptions.csv",
        "metrics.json",
        "fig_x.svg",
        "session.mcap",
    ] {
        let (x, y) = (
            std::fs::read(d1.join(f)).expect(f),
            std::fs::read(d2.join(f)).expect(f),
        );
        assert!(x == y, "{f} differs between two runs");
    }
    let png = std::fs::read(d1.join("fig_x.png")).expect("png");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    for f in ["fig_y.png", "fig_y.svg", "divergence.png", "divergence.svg"] {
        assert!(std::fs::metadata(d1.join(f)).expect(f).len() > 1000, "{f}");
    }
}

/// The paper's experiment: naive diverges beyond the disk's radius, stays apart by a large part
/// of it, and the cooperative phases (grasp, squeeze, carry) cannot be done at either site, as in
/// the paper's Figs. 9-10; the paper's method brings the copies together once contacts end (under
/// 1 mm). (Before its received forces were stopped as soon as they had done what their users
/// gave, naive could push a copy on for a delay beyond that, and parted by 253 mm.)
#[test]
fn paper_scenario_naive_diverges_and_paper_keeps_copies_together() {
    let sc = load_scenario("paper.toml");
    let radius = sc.objects[0].radius_m;
    let reference = sim::run(&sc, Mode::Reference, &mut |_| {});
    let naive = metrics::compute(
        &sc,
        &sim::run(&sc, Mode::Distributed(MethodName::Naive), &mut |_| {}),
        &reference,
    );
    let paper = metrics::compute(
        &sc,
        &sim::run(&sc, Mode::Distributed(MethodName::Paper), &mut |_| {}),
        &reference,
    );
    assert!(
        naive.divergence_max_m > radius,
        "naive max {}",
        naive.divergence_max_m
    );
    assert!(
        naive.divergence_after_contact_m > 0.5 * radius,
        "naive after contact {}",
        naive.divergence_after_contact_m
    );
    assert!(
        naive.divergence_final_m > 0.5 * radius,
        "naive final {}",
        naive.divergence_final_m
    );
    for s in &naive.sites {
        let failed: Vec<&str> = s
            .phases
            .iter()
            .filter(|(_, ok)| !ok)
            .map(|(p, _)| p.as_str())
            .collect();
        for p in ["grasp", "squeeze", "carry"] {
            assert!(
                failed.contains(&p),
                "naive at {}: {p} should fail: {:?}",
                s.name,
                s.phases
            );
        }
    }
    assert!(
        paper.divergence_after_contact_m < 1e-3,
        "paper after contact {}",
        paper.divergence_after_contact_m
    );
    assert!(paper.divergence_final_m < 1e-3);
    // Adoptions are bounded at the servo by the configured step.
    for s in &paper.sites {
        assert!(s.adoptions > 0);
        assert!(s.max_adoption_force_step_n <= sc.site[0].max_adoption_step_n + 1e-9);
    }
    // The reference does every task phase at every site.
    let r = metrics::compute(&sc, &reference, &reference);
    assert!(
        r.sites.iter().all(|s| s.phases.iter().all(|(_, ok)| *ok)),
        "{:?}",
        r.sites
    );
}

/// A phase that did not happen says why, the same in the table as in `metrics.json`: one line per
/// site and phase, `#   <site> <phase>: <reason>`, and in the JSON the check that failed with its
/// figures. Naive on the paper's task misses the grasp at both sites (the test above), and a grasp
/// has only its contact to miss: the reason is how close each tool came.
#[test]
fn a_missed_phase_says_why_in_the_table_and_the_json() {
    let out = TempDir::unmade("sim-why");
    let o = Command::new(SIM)
        .args(["run", "scenarios/paper.toml", "--method", "naive", "--out"])
        .arg(&out)
        .current_dir(repo())
        .output()
        .expect("run sim");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let table = String::from_utf8_lossy(&o.stdout);
    let m: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("metrics.json")).expect("metrics.json"),
    )
    .expect("json");
    for site in m["sites"].as_array().expect("sites") {
        let name = site["name"].as_str().expect("name");
        let failed: Vec<&str> = site["phases"]
            .as_array()
            .expect("phases")
            .iter()
            .filter(|p| p[1] == false)
            .filter_map(|p| p[0].as_str())
            .collect();
        let missed = site["missed_phases"].as_array().expect("missed_phases");
        let named: Vec<&str> = missed.iter().filter_map(|p| p["phase"].as_str()).collect();
        assert_eq!(
            named, failed,
            "{name}: one reason per phase that did not happen"
        );
        for p in missed {
            let line = format!(
                "#   {name} {}: {}",
                p["phase"].as_str().expect("phase"),
                p["reason"].as_str().expect("reason")
            );
            assert!(
                table.lines().any(|l| l == line),
                "{line:?} not in:\n{table}"
            );
        }
        let grasp = missed
            .iter()
            .find(|p| p["phase"] == "grasp")
            .expect("naive misses the grasp");
        assert_eq!(grasp["miss"]["check"], "contact", "{grasp}");
        assert!(
            grasp["miss"]["closest"]["gap_m"].as_f64() > Some(0.0),
            "the tool stayed out of reach, by a measured gap: {grasp}"
        );
        assert!(
            grasp["reason"].as_str().is_some_and(
                |r| r.starts_with("no contact with object in 4.00–5.00 s; closest approach ")
            ),
            "{grasp}"
        );
    }
}

/// Zero delay and equal 1 kHz rates: the paper's method matches the reference run within 1 mm
/// rms.
/// Naive does not, even here: as on a station, a site reports the contact its physics last
/// took, which the others apply a physics tick later than their own (one millisecond), and
/// Eq. 8 summed that way loses the carry. (The simulator used to report the contact of the
/// servo tick at the same instant, before physics had seen it, and naive matched.)
#[test]
fn zero_delay_paper_matches_the_reference_and_naive_does_not() {
    let sc = load_scenario("zero-delay.toml");
    let reference = sim::run(&sc, Mode::Reference, &mut |_| {});
    let naive = metrics::compute(
        &sc,
        &sim::run(&sc, Mode::Distributed(MethodName::Naive), &mut |_| {}),
        &reference,
    );
    assert!(
        naive
            .sites
            .iter()
            .any(|s| s.error_vs_reference_max_m > 0.01),
        "naive, one tick apart, departs from the reference: {:?}",
        naive.sites
    );
    // (`MethodName::ALL` also holds timewarp and coupled: they predict or play the partner's
    // tool late, and the sweep tests judge them.)
    for method in [MethodName::Paper] {
        let m = metrics::compute(
            &sc,
            &sim::run(&sc, Mode::Distributed(method), &mut |_| {}),
            &reference,
        );
        // Within 1 mm rms, 2 mm at worst: each site adopts the other's state a physics tick
        // after it was made, as a station does.
        for s in &m.sites {
            assert!(
                s.error_vs_reference_rms_m < 1e-3 && s.error_vs_reference_max_m < 2e-3,
                "{}: {} off the reference by {} m",
                m.method,
                s.name,
                s.error_vs_reference_max_m
            );
            assert!(
                s.phases.iter().all(|(_, ok)| *ok),
                "{}: {:?}",
                m.method,
                s.phases
            );
        }
    }
}

#[test]
fn compare_prints_one_table_and_json() {
    let o = Command::new(SIM)
        .args(["compare", "scenarios/space-box.toml"])
        .current_dir(repo())
        .output()
        .expect("sim");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for row in ["reference", "naive", "paper", "timewarp"] {
        assert!(
            out.lines().any(|l| l.starts_with(row)),
            "{row} row missing:\n{out}"
        );
    }
    let o = Command::new(SIM)
        .args(["compare", "scenarios/space-box.toml", "--json"])
        .current_dir(repo())
        .output()
        .expect("sim");
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    // The reference and every simulated method (timewarp made it four).
    assert_eq!(
        v["methods"].as_array().map(Vec::len),
        Some(1 + MethodName::ALL.len())
    );
    assert!(v["methods"][1]["divergence_max_m"].as_f64().is_some());
    for m in v["methods"].as_array().expect("methods") {
        let key = "co_contact_divergence_max_m";
        assert!(m.get(key).is_some(), "{key} missing: {m}");
    }
    assert!(
        out.lines().any(|l| l.contains("co-div")),
        "co-contact column missing:\n{out}"
    );
    // --methods narrows it to those (the reference always runs: the error is against it).
    let o = Command::new(SIM)
        .args([
            "compare",
            "scenarios/space-box.toml",
            "--methods",
            "timewarp,paper",
            "--json",
        ])
        .current_dir(repo())
        .output()
        .expect("sim");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    let names: Vec<&str> = v["methods"]
        .as_array()
        .expect("methods")
        .iter()
        .filter_map(|m| m["method"].as_str())
        .collect();
    assert_eq!(names, ["reference", "timewarp", "paper"], "{v}");
    for (args, needle) in [
        ("naive,bogus", "unknown method \"bogus\""),
        ("paper,paper", "paper is given twice"),
    ] {
        let o = Command::new(SIM)
            .args(["compare", "scenarios/space-box.toml", "--methods", args])
            .current_dir(repo())
            .output()
            .expect("sim");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args} accepted");
        assert!(err.contains(needle), "{args}: {err}");
    }
}
