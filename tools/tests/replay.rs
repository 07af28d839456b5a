//! Recorded hands played back: a user's tool trajectory taken from one run drives that user's tool
//! by position in the next, in the simulator (`sim run` on a scenario whose site names a CSV) and on
//! real stations (`session run` on a scenario whose site names an earlier session's MCAP
//! recording). Each replayed tool trajectory must match the recorded one.

use std::path::Path;
use std::process::Command;

use coop_actors::scenario_file;
use coop_actors::trajectory_file::load_trajectory;
use coop_model::body::Vec3;
use coop_model::replay::Trajectory;
use coop_model::scenario::MethodName;
use coop_model::sim::{self, Mode};
use coop_tests::{load_scenario, repo, scenario_path, ScenarioToml, TempDir};

/// The paper's scenario with `hand_replay = file` on its first site (user1).
fn paper_with_replay(file: &str) -> ScenarioToml {
    let paper = ScenarioToml::paper();
    assert_eq!(
        paper.get("site.0.name").and_then(toml::Value::as_str),
        Some("user1")
    );
    paper.set("site.0.hand_replay", file)
}

/// Tool positions of `site` in a `sim run` trace.csv: (t, position).
fn trace_tool(csv: &str, site: usize) -> Vec<(f64, Vec3)> {
    csv.lines()
        .skip(1)
        .filter_map(|l| {
            let c: Vec<f64> = l
                .split(',')
                .map(|x| x.parse().unwrap_or(f64::NAN))
                .collect();
            (c[1] as usize == site).then(|| (c[0], Vec3::new(c[5], c[6], c[7])))
        })
        .collect()
}

#[test]
fn a_hand_recorded_in_one_simulator_run_replays_in_the_next() {
    let dir = TempDir::new("replay-sim");
    let paper = load_scenario("paper.toml");
    let first = sim::run(&paper, Mode::Distributed(MethodName::Paper), &mut |_| {});
    let recorded = Trajectory::new(
        first
            .t
            .iter()
            .copied()
            .zip(first.sites[0].tool_pos.iter().copied()),
    )
    .expect("the first run's user1 trajectory");
    std::fs::write(dir.join("user1.csv"), recorded.to_csv()).expect("write csv");
    // Relative to the scenario file.
    paper_with_replay("user1.csv").write(&dir.join("replay.toml"));
    let out = dir.join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_sim"))
        .arg("run")
        .arg(dir.join("replay.toml"))
        .args(["--method", "paper", "--out"])
        .arg(&out)
        .output()
        .expect("sim runs");
    assert!(
        o.status.success(),
        "sim failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let csv = std::fs::read_to_string(out.join("trace.csv")).expect("trace.csv");
    let replayed = trace_tool(&csv, 0);
    assert_eq!(replayed.len(), first.t.len(), "one row per sample");
    let mut worst = 0.0f64;
    let mut travel = 0.0;
    for (k, (t, p)) in replayed.iter().enumerate() {
        assert!((t - first.t[k]).abs() < 1e-6, "sample times line up");
        worst = worst.max((p - first.sites[0].tool_pos[k]).norm());
        if k > 0 {
            travel += (p - replayed[k - 1].1).norm();
        }
    }
    assert!(travel > 0.1, "the replayed hand moved ({travel} m)");
    eprintln!("replayed in the simulator: travel {travel:.3} m, worst error {worst:e} m");
    // At the sample times the replay is the recording (the trace prints 9 decimals).
    assert!(
        worst < 1e-6,
        "replayed tool off the recorded one by {worst} m"
    );
    // The other user still feels the disk the replayed hand pushes.
    let user2 = trace_tool(&csv, 1);
    assert_eq!(user2.len(), replayed.len());
}

fn session(scenario: &Path, out: &Path) {
    let o = Command::new(env!("CARGO_BIN_EXE_session"))
        .current_dir(repo())
        .arg("run")
        .arg(scenario)
        .args(["--method", "paper", "--no-emulation", "--json", "--out"])
        .arg(out)
        .output()
        .expect("session runs");
    assert!(
        o.status.success(),
        "session failed: {}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
}

/// One session on real stations records user1's hand; a second session replays that recording as
/// user1's hand (its station plays it through the replay device under the safety layer) while
/// user2 runs its script. The second run's recorded tool follows the first's.
#[test]
fn a_station_replays_the_hand_recorded_in_an_earlier_session() {
    let dir = TempDir::new("replay-session");
    let first = dir.join("first");
    session(&scenario_path("paper.toml"), &first);
    let recording = first.join("paper/user1.mcap");
    let recorded = load_trajectory(&recording).expect("the first session's user1 hand");
    paper_with_replay(&recording.display().to_string()).write(&dir.join("replay.toml"));
    let second = dir.join("second");
    session(&dir.join("replay.toml"), &second);
    let replayed = load_trajectory(&second.join("paper/user1.mcap")).expect("second user1");
    // Compare over the session (both are timed from their session's start).
    let (mut errors, mut off_path, mut travel, mut last) =
        (Vec::new(), Vec::new(), 0.0, None::<Vec3>);
    let end = recorded.end_s().min(replayed.end_s());
    let mut t = 0.0;
    while t <= end {
        let (a, b) = (recorded.at(t).0, replayed.at(t).0);
        errors.push((a - b).norm());
        // A station's trace samples the newest tool sample physics has: a servo period old, or
        // as old as the servo was kept from running on a loaded machine (a shared CPU stalls it
        // for tens of ms now and then). So where the replayed tool was, the recorded hand was at
        // most `STALE_S` before (or a few ms after: the two sessions' time 0s are each taken
        // with a measured clock offset): the distance to that stretch of the recorded path.
        const STALE_S: f64 = 0.1;
        let nearest = (-5..=100)
            .map(|ms| (recorded.at(t - STALE_S * f64::from(ms) / 100.0).0 - b).norm())
            .fold(f64::INFINITY, f64::min);
        off_path.push(nearest);
        if let Some(l) = last {
            travel += (b - l).norm();
        }
        last = Some(b);
        t += 0.01;
    }
    assert!(errors.len() > 500, "the sessions overlap ({end} s)");
    assert!(travel > 0.1, "the replayed hand moved ({travel} m)");
    errors.sort_by(f64::total_cmp);
    off_path.sort_by(f64::total_cmp);
    let (median, worst) = (errors[errors.len() / 2], errors[errors.len() - 1]);
    let farthest = off_path[off_path.len() - 1];
    eprintln!(
        "replayed on a station: {} points over {end:.1} s, travel {travel:.3} m, error median {:.3} mm, worst {:.3} mm at the same time, {:.3} mm off the recorded path",
        errors.len(),
        median * 1e3,
        worst * 1e3,
        farthest * 1e3
    );
    assert!(
        median < 1e-3 && farthest < 5e-3,
        "replayed tool off the recorded one: median {median} m, {farthest} m off the path \
         (worst at the same time {worst} m)"
    );
}

/// The A/B harness on human-like input: both users' hands, recorded once, replayed under every
/// simulated method at two delays. A replayed hand is position-driven, so every method and delay
/// gets the very same tool trajectories (what differs is only what the copies do with them), and
/// the object still moves under them.
#[test]
fn recorded_hands_replay_identically_under_every_method_and_delay() {
    let dir = TempDir::new("replay-ab");
    let paper = load_scenario("paper.toml");
    let first = sim::run(&paper, Mode::Reference, &mut |_| {});
    for (i, name) in ["user1", "user2"].iter().enumerate() {
        let recorded = Trajectory::new(
            first
                .t
                .iter()
                .copied()
                .zip(first.sites[i].tool_pos.iter().copied()),
        )
        .expect("a recorded trajectory");
        std::fs::write(dir.join(format!("{name}.csv")), recorded.to_csv()).expect("write csv");
    }
    // user2 replays too.
    paper_with_replay("user1.csv")
        .set("site.1.hand_replay", "user2.csv")
        .write(&dir.join("replay.toml"));
    let replay = scenario_file::load(&dir.join("replay.toml")).expect("the replay scenario");
    let mut runs = 0;
    for method in MethodName::ALL {
        for delay_ms in [0.0, 150.0] {
            let sc = coop_tools::sweep::scenario_at(&replay, delay_ms, 1).expect("scenario at");
            let r = sim::run(&sc, Mode::Distributed(method), &mut |_| {});
            for (i, site) in r.sites.iter().enumerate() {
                assert_eq!(site.tool_pos.len(), first.t.len());
                let worst = site
                    .tool_pos
                    .iter()
                    .zip(&first.sites[i].tool_pos)
                    .map(|(a, b)| (a - b).norm())
                    .fold(0.0f64, f64::max);
                assert!(
                    worst < 1e-9,
                    "{} at {delay_ms} ms: site {i}'s replayed tool is {worst} m off the recorded hand",
                    method.as_str()
                );
            }
            let moved =
                (r.sites[0].obj_pos.last().expect("samples") - r.sites[0].obj_pos[0]).norm();
            assert!(
                moved > 0.01,
                "{} at {delay_ms} ms: the replayed hands moved the object {moved} m",
                method.as_str()
            );
            runs += 1;
        }
    }
    assert_eq!(runs, 2 * MethodName::ALL.len());
}
