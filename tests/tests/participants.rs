//! Simulated participants in the simulator: the same seed gives the same bits (the people
//! included), another seed other people; each site's task is judged live; and a plan or a task
//! that names what is not there is refused with its field.

use coop_model::metrics;
use coop_model::scenario::MethodName;
use coop_model::sim::{self, Mode};
use coop_tests::load_scenario;

const FILE: &str = "participants/paper.toml";

#[test]
fn the_same_seed_gives_the_same_bits_and_another_seed_other_people() {
    let sc = load_scenario(FILE);
    let run = |seed: u64| {
        let mut sc = sc.clone();
        sc.seed = seed;
        sc.duration_s = 9.0;
        let r = sim::run(&sc, Mode::Distributed(MethodName::Timewarp), &mut |_| {});
        let reference = sim::run(&sc, Mode::Reference, &mut |_| {});
        let m = metrics::compute(&sc, &r, &reference);
        (
            r.trace_csv(),
            m.sites.iter().map(|s| s.task.clone()).collect::<Vec<_>>(),
        )
    };
    let (a, tasks) = run(7);
    let (b, again) = run(7);
    assert!(a == b, "seed 7 twice: the traces differ");
    assert_eq!(format!("{tasks:?}"), format!("{again:?}"));
    for t in &tasks {
        let t = t.as_ref().expect("a participant site has task figures");
        assert_ne!(t.outcome, "undecided", "the run's end decides every task");
        assert!(t.steps.1 > 0 && t.grip_peak_n > 0.0, "{t:?}: it gripped");
    }
    let (c, _) = run(8);
    assert!(
        a != c,
        "seeds 7 and 8 are other people: the traces must differ"
    );
}

#[test]
fn a_plan_or_a_task_naming_what_is_not_there_is_refused_with_its_field() {
    let text = std::fs::read_to_string(coop_tests::scenario_path(FILE)).unwrap();
    for (from, to, field) in [
        (
            r#"{ do = "reach", object = "disk", side = [-1.0, 0.0, 0.0], gap_m = 0.03 }"#,
            r#"{ do = "reach", object = "cup", side = [-1.0, 0.0, 0.0], gap_m = 0.03 }"#,
            "site[0].plan[1].object",
        ),
        (
            r#"{ do = "grasp", object = "disk", side = [1.0, 0.0, 0.0], force_n = 1.5 }"#,
            r#"{ do = "grasp", object = "disk", force_n = 1.5 }"#,
            "site[1].plan[4].side",
        ),
        (
            r#"below_m = -0.02"#,
            r#"below_m = nan"#,
            "task.fail[0].below_m",
        ),
        (
            r#"script = [{ t_s = 0.0, target_m = [-0.20, 0.0, 0.01] }]"#,
            r#"script = [{ t_s = 0.0, target_m = [-0.20, 0.0, 0.01] }, { t_s = 1.0, target_m = [-0.20, 0.0, 0.01] }]"#,
            "site[0].script",
        ),
    ] {
        assert!(text.contains(from), "the scenario holds {from}");
        let e =
            coop_actors::scenario_file::parse(&text.replacen(from, to, 1)).expect_err("refused");
        let shown = format!("{e:#}");
        assert!(shown.contains(field), "{field}: the error was {shown}");
    }
}

/// Every shipped participant scenario can be done: without delay, under `timewarp`, every site
/// sees its task done (a plan whose step can never finish, or a goal no plan reaches, fails here).
#[test]
fn every_participant_scenario_is_done_at_every_site_without_delay() {
    let dir = coop_tests::scenario_path("participants");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("scenarios/participants")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 4, "{files:?}");
    for file in files {
        let mut sc = coop_actors::scenario_file::load(&file).expect("a valid scenario");
        assert!(sc.task.done.is_some(), "{}: no [task]", file.display());
        sc.network.delay_min_ms = 0.0;
        sc.network.delay_max_ms = 0.0;
        sc.network.jitter_ms = 0.0;
        let r = sim::run(&sc, Mode::Distributed(MethodName::Timewarp), &mut |_| {});
        let reference = sim::run(&sc, Mode::Reference, &mut |_| {});
        let m = metrics::compute(&sc, &r, &reference);
        for s in &m.sites {
            let t = s.task.as_ref().expect("task figures");
            assert_eq!(t.outcome, "done", "{} at {}: {t:?}", file.display(), s.name);
        }
    }
}
