//! A `timewarp` rollback that re-simulates only the objects a changed input reaches gives the
//! world a whole re-simulation gives, to the bit: the crowd (eight users, sixteen pucks) at a
//! constant 150 ms, run both ways.

use coop_model::scenario::MethodName;
use coop_model::sim::{self, Mode};
use coop_tests::load_scenario;
use coop_tools::sweep::scenario_at;

#[test]
fn the_crowd_rolled_back_by_islands_is_the_crowd_rolled_back_whole() {
    let base = load_scenario("crowd.toml");
    let mut sc = scenario_at(&base, 150.0, base.seed).expect("valid");
    sc.duration_s = 2.5;
    let run = |islands: bool| {
        let mut sc = sc.clone();
        sc.timewarp.islands = islands;
        sim::run(&sc, Mode::Distributed(MethodName::Timewarp), &mut |_| {})
    };
    let (islands, whole) = (run(true), run(false));
    let rollbacks: u64 = islands.rollback.iter().flatten().map(|s| s.rollbacks).sum();
    assert!(rollbacks > 100, "the crowd rolls back: {rollbacks}");
    assert_eq!(islands.rollback, whole.rollback, "the same rollbacks");
    assert!(
        islands.trace_csv() == whole.trace_csv(),
        "the traces differ"
    );
    assert_eq!(islands.adoptions_csv(), whole.adoptions_csv());
}
