//! The phase checks, each failing on a small hand-made trace: the miss names what was measured,
//! the threshold and when.

use super::*;
use crate::scenario::{ObjectSpec, ShapeName, SiteSpec};
use crate::sim::Mode;

/// Two sites 500 ms apart; user 1 pushes in 0.5–1.05 s. Site 2's copy moves 2 cm at `moves_at`.
fn push_seen_at(moves_at: f64, mode: Mode) -> (Scenario, RunResult) {
    let mut sc = Scenario::default();
    for name in ["user1", "user2"] {
        sc.site.push(SiteSpec {
            name: name.into(),
            report_rate_hz: 20.0,
            ..SiteSpec::default()
        });
    }
    sc.network.delay_min_ms = 500.0;
    sc.network.delay_max_ms = 500.0;
    sc.network.jitter_ms = 10.0;
    sc.phase.push(PhaseSpec {
        name: "push".into(),
        from_s: 0.5,
        to_s: 1.05,
        contact: vec!["user1".into()],
        no_contact: vec!["user2".into()],
        object_moves_m: 0.02,
        ..PhaseSpec::default()
    });
    let t: Vec<f64> = (0..400).map(|k| f64::from(k) * 0.005).collect();
    let trace = |moves_at: f64, touching: bool| SiteTrace {
        obj_pos: t
            .iter()
            .map(|&s| Vec3::new(if s >= moves_at { 0.03 } else { 0.0 }, 0.0, 0.01))
            .collect(),
        f_desired: vec![Vec3::new(1.0, 0.0, 0.0); t.len()],
        touching: vec![touching; t.len()],
        ..SiteTrace::default()
    };
    let run = RunResult {
        sites: vec![trace(0.9, true), trace(moves_at, false)],
        t,
        ..RunResult::empty(mode)
    };
    (sc, run)
}

/// A far site sees a push when its news can arrive, not sooner: the push phase holds at the
/// observer if its copy moves within the delay, jitter and a report period after the window,
/// and fails if it moves later, or at all in the reference run (one world, no news to wait for).
#[test]
fn an_observer_may_see_the_motion_one_delay_late() {
    let paper = Mode::Distributed(crate::scenario::MethodName::Paper);
    let (sc, run) = push_seen_at(1.5, paper);
    assert!((observer_lag_s(&sc, &run, 1, &sc.phase[0]) - 0.56).abs() < 1e-9);
    assert_eq!(observer_lag_s(&sc, &run, 0, &sc.phase[0]), 0.0);
    assert!(phase_happened(&sc, &run, 1, &sc.phase[0]));
    assert!(phase_happened(&sc, &run, 0, &sc.phase[0]));
    let (sc, run) = push_seen_at(1.65, paper);
    assert!(!phase_happened(&sc, &run, 1, &sc.phase[0]));
    let miss = why_missed(&sc, &run, 1, &sc.phase[0]).expect("a miss");
    assert_eq!(
        miss.to_string(),
        "object moved 0.0 mm of 20.0 mm from 0.50 s to 1.61 s (the window's end plus 0.56 s observer lag)"
    );
    let (sc, run) = push_seen_at(1.5, Mode::Reference);
    assert!(!phase_happened(&sc, &run, 1, &sc.phase[0]));
}

/// A phase that names an object is about touching that object: a user touching another one
/// does not make it, nor break its `no_contact`; a phase that names none takes any object.
#[test]
fn a_phase_naming_an_object_is_about_touching_that_object() {
    let paper = Mode::Distributed(crate::scenario::MethodName::Paper);
    let (mut sc, mut run) = push_seen_at(1.5, paper);
    sc.objects = vec![
        crate::scenario::ObjectSpec {
            name: "a".into(),
            ..Default::default()
        },
        crate::scenario::ObjectSpec {
            name: "b".into(),
            start_m: [0.2, 0.0, 0.0],
            ..Default::default()
        },
    ];
    // User 1 touches object b only; user 2 touches nothing.
    let n = run.t.len();
    run.sites[0].touched = vec![0b10; n];
    run.sites[1].touched = vec![0; n];
    for s in &mut run.sites {
        s.others = vec![crate::sim::ObjectTrace {
            pos: vec![Vec3::new(0.2, 0.0, 0.0); n],
            vel: vec![Vec3::zeros(); n],
            rot: vec![[1.0, 0.0, 0.0, 0.0]; n],
        }];
    }
    let mut p = sc.phase[0].clone();
    p.object_moves_m = 0.0;
    assert!(phase_happened(&sc, &run, 0, &p), "any object: b is touched");
    p.object = "b".into();
    assert!(phase_happened(&sc, &run, 0, &p), "b is touched");
    p.object = "a".into();
    assert!(!phase_happened(&sc, &run, 0, &p), "a is not touched");
    // User 2 must not touch: touching b breaks a phase about b, not one about a.
    run.sites[1].touched = vec![0b10; n];
    run.sites[1].touching = vec![true; n];
    let mut q = p.clone();
    q.contact.clear();
    q.object = "a".into();
    assert!(
        phase_happened(&sc, &run, 1, &q),
        "a is not touched by user 2"
    );
    q.object = "b".into();
    assert!(!phase_happened(&sc, &run, 1, &q), "user 2 touches b");
}

/// One site, `user1`, and a sphere `puck` of radius 20 mm (the tool's is 5 mm) starting at
/// `start`; a 2 s trace at 100 Hz in which `at(t)` gives the puck's centre, the tool's
/// position, the displayed force (N, along x) and whether the user touches.
fn one_site(
    phase: PhaseSpec,
    start: [f64; 3],
    at: impl Fn(f64) -> (Vec3, Vec3, f64, bool),
) -> (Scenario, RunResult) {
    let sc = Scenario {
        site: vec![SiteSpec {
            name: "user1".into(),
            ..SiteSpec::default()
        }],
        objects: vec![ObjectSpec {
            name: "puck".into(),
            shape: ShapeName::Sphere,
            radius_m: 0.02,
            start_m: start,
            ..ObjectSpec::default()
        }],
        phase: vec![phase],
        ..Scenario::default()
    };
    let t: Vec<f64> = (0..=200).map(|k| f64::from(k) / 100.0).collect();
    let rows: Vec<_> = t.iter().map(|&t| at(t)).collect();
    let trace = SiteTrace {
        obj_pos: rows.iter().map(|r| r.0).collect(),
        obj_rot: vec![[1.0, 0.0, 0.0, 0.0]; t.len()],
        tool_pos: rows.iter().map(|r| r.1).collect(),
        f_desired: rows.iter().map(|r| Vec3::new(r.2, 0.0, 0.0)).collect(),
        touching: rows.iter().map(|r| r.3).collect(),
        ..SiteTrace::default()
    };
    let run = RunResult {
        sites: vec![trace],
        t,
        ..RunResult::empty(Mode::Distributed(crate::scenario::MethodName::Paper))
    };
    (sc, run)
}

/// A phase in 1.0–1.5 s.
fn window() -> PhaseSpec {
    PhaseSpec {
        name: "catch".into(),
        from_s: 1.0,
        to_s: 1.5,
        ..PhaseSpec::default()
    }
}

/// Its miss at the one site, checking that the bool agrees.
fn miss(sc: &Scenario, run: &RunResult) -> PhaseMiss {
    assert!(!phase_happened(sc, run, 0, &sc.phase[0]));
    why_missed(sc, run, 0, &sc.phase[0]).expect("the phase fails")
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

/// A tool that stops short says how short, and when: the smallest gap between the tool tip
/// and the object's surface in the window, in the object's own frame (a turned box is
/// measured turned); without poses in the trace, that no sample touched.
#[test]
fn a_missed_contact_names_the_closest_approach() {
    let p = PhaseSpec {
        contact: vec!["user1".into()],
        ..window()
    };
    // Nearest at 1.2 s: 26.6 mm from the centre, 1.6 mm beyond the 20 + 5 mm of contact.
    let (sc, run) = one_site(p.clone(), [0.0; 3], |t| {
        let x = 0.0266 + 0.05 * (t - 1.2) * (t - 1.2);
        (Vec3::zeros(), Vec3::new(x, 0.0, 0.0), 0.0, false)
    });
    let PhaseMiss::Contact {
        object,
        from_s,
        to_s,
        closest: Some(a),
    } = miss(&sc, &run)
    else {
        panic!("{:?}", miss(&sc, &run))
    };
    assert_eq!((object.as_str(), from_s, to_s), ("puck", 1.0, 1.5));
    assert!(close(a.gap_m, 0.0016) && close(a.at_s, 1.2), "{a:?}");
    assert_eq!(
        miss(&sc, &run).to_string(),
        "no contact with puck in 1.00–1.50 s; closest approach 1.6 mm beyond contact at 1.20 s"
    );
    // A box 80 mm long turned a quarter about z lies along y: 2 mm beyond its end, not
    // 32 mm beyond its side.
    let (mut sc, mut run) = one_site(p, [0.0; 3], |_| {
        (Vec3::zeros(), Vec3::new(0.0, 0.047, 0.0), 0.0, false)
    });
    sc.objects[0].shape = ShapeName::Box;
    sc.objects[0].half_extents_m = [0.04, 0.01, 0.01];
    let h = std::f64::consts::FRAC_1_SQRT_2;
    run.sites[0].obj_rot = vec![[h, 0.0, 0.0, h]; run.t.len()];
    let Some(PhaseMiss::Contact {
        closest: Some(a), ..
    }) = why_missed(&sc, &run, 0, &sc.phase[0])
    else {
        panic!("a missed contact")
    };
    assert!(close(a.gap_m, 0.002), "{a:?}");
    // Under a millimetre the gap is told in µm.
    run.sites[0].tool_pos = vec![Vec3::new(0.0, 0.04503, 0.0); run.t.len()];
    assert!(
        miss(&sc, &run)
            .to_string()
            .ends_with("closest approach 30 µm beyond contact at 1.00 s"),
        "{}",
        miss(&sc, &run)
    );
    // No tool positions: nothing to measure.
    run.sites[0].tool_pos.clear();
    let m = miss(&sc, &run);
    assert!(matches!(m, PhaseMiss::Contact { closest: None, .. }));
    assert_eq!(
        m.to_string(),
        "no contact with puck in 1.00–1.50 s (no sample touched it; the trace holds no tool or object pose to tell how close it came)"
    );
}

/// A contact too soft names its peak displayed force, the threshold and when.
#[test]
fn a_weak_contact_names_its_peak_force() {
    let p = PhaseSpec {
        contact: vec!["user1".into()],
        min_force_n: 2.0,
        ..window()
    };
    let (sc, run) = one_site(p, [0.0; 3], |t| {
        let f = 1.2 * (-((t - 1.3) / 0.05).powi(2)).exp();
        (Vec3::zeros(), Vec3::new(0.025, 0.0, 0.0), f, true)
    });
    let m = miss(&sc, &run);
    assert_eq!(
        m,
        PhaseMiss::MinForce {
            peak_n: 1.2,
            min_force_n: 2.0,
            at_s: 1.3
        }
    );
    assert_eq!(
        m.to_string(),
        "peak displayed force 1.20 N of 2.00 N at 1.30 s"
    );
}

/// A touch where none is allowed names its first sample.
#[test]
fn a_forbidden_touch_names_when() {
    let p = PhaseSpec {
        no_contact: vec!["user1".into()],
        ..window()
    };
    let (sc, run) = one_site(p, [0.0; 3], |t| {
        (Vec3::zeros(), Vec3::new(0.025, 0.0, 0.0), 0.0, t >= 1.1)
    });
    let m = miss(&sc, &run);
    assert!(
        matches!(&m, PhaseMiss::NoContact { object, at_s, .. } if object == "puck" && close(*at_s, 1.1)),
        "{m:?}"
    );
    assert_eq!(
        m.to_string(),
        "touched puck at 1.10 s (no contact allowed in 1.00–1.50 s)"
    );
}

/// Too little motion names how far the object moved of how far it must, over which samples.
#[test]
fn too_little_motion_names_the_distance() {
    let p = PhaseSpec {
        object_moves_m: 0.02,
        ..window()
    };
    let (sc, run) = one_site(p, [0.0; 3], |t| {
        let x = 0.018 * ((t - 1.0) / 0.5).clamp(0.0, 1.0);
        (Vec3::new(x, 0.0, 0.0), Vec3::zeros(), 0.0, false)
    });
    let m = miss(&sc, &run);
    let PhaseMiss::ObjectMoves {
        moved_m,
        object_moves_m,
        from_s,
        to_s,
        lag_s,
        ..
    } = m
    else {
        panic!("{m:?}")
    };
    assert!(close(moved_m, 0.018), "{moved_m}");
    assert_eq!((object_moves_m, from_s, to_s, lag_s), (0.02, 1.0, 1.5, 0.0));
    assert_eq!(
        m.to_string(),
        "puck moved 18.0 mm of 20.0 mm from 1.00 s to 1.50 s"
    );
}

/// Leaving the region names when, the axis, the coordinate and the bound it crossed; an
/// object outside from the window's start says so.
#[test]
fn leaving_the_region_names_the_axis_and_bound() {
    let p = PhaseSpec {
        region_m: Some([[0.0, -1.0, -1.0], [0.3, 1.0, 1.0]]),
        ..window()
    };
    let (sc, run) = one_site(p, [0.0; 3], |t| {
        let x = if t < 1.2 { 0.29 } else { 0.312 };
        (Vec3::new(x, 0.0, 0.0), Vec3::zeros(), 0.0, false)
    });
    let m = miss(&sc, &run);
    assert!(
        matches!(
            &m,
            PhaseMiss::Region { at_s, at_start: false, axis: 'x', value_m, bounds_m, .. }
                if close(*at_s, 1.2) && *value_m == 0.312 && *bounds_m == [0.0, 0.3]
        ),
        "{m:?}"
    );
    assert_eq!(
        m.to_string(),
        "puck left the region at 1.20 s (x 0.312 m, 12.0 mm above 0.300 m)"
    );
    let p = PhaseSpec {
        region_m: Some([[-1.0, -1.0, 0.01], [1.0, 1.0, 1.0]]),
        ..window()
    };
    let (sc, run) = one_site(p, [0.0; 3], |_| (Vec3::zeros(), Vec3::zeros(), 0.0, false));
    assert_eq!(
        miss(&sc, &run).to_string(),
        "puck was outside the region at 1.00 s, the window's start (z 0.000 m, 10.0 mm below 0.010 m)"
    );
}

/// Too low a lift names the rise over the start height, the threshold and the peak's time.
#[test]
fn too_low_a_lift_names_the_rise() {
    let p = PhaseSpec {
        lifted_m: 0.01,
        ..window()
    };
    let (sc, run) = one_site(p, [0.0, 0.0, 0.02], |t| {
        let z = 0.02 + 0.0075 * (-((t - 1.3) / 0.1).powi(2)).exp();
        (Vec3::new(0.0, 0.0, z), Vec3::zeros(), 0.0, false)
    });
    let m = miss(&sc, &run);
    let PhaseMiss::Lifted {
        rose_m,
        lifted_m,
        peak_at_s,
        ..
    } = m
    else {
        panic!("{m:?}")
    };
    assert!(close(rose_m, 0.0075), "{rose_m}");
    assert_eq!((lifted_m, peak_at_s), (0.01, Some(1.3)));
    assert_eq!(
        m.to_string(),
        "puck rose 7.5 mm of 10.0 mm above its start height (peak at 1.30 s)"
    );
    // Settled 0.2 mm lower (into the table), it never rose.
    let p = PhaseSpec {
        lifted_m: 0.01,
        ..window()
    };
    let (sc, run) = one_site(p, [0.0, 0.0, 0.02], |_| {
        (Vec3::new(0.0, 0.0, 0.0198), Vec3::zeros(), 0.0, false)
    });
    assert_eq!(
        miss(&sc, &run).to_string(),
        "puck never rose above its start height, of 10.0 mm (highest 0.2 mm below it, at 1.00 s)"
    );
}

/// A window the run never reaches says so, with the span the run has.
#[test]
fn a_window_without_samples_names_the_runs_span() {
    let p = PhaseSpec {
        from_s: 5.0,
        to_s: 6.0,
        ..window()
    };
    let (sc, run) = one_site(p, [0.0; 3], |_| (Vec3::zeros(), Vec3::zeros(), 0.0, false));
    let m = miss(&sc, &run);
    assert_eq!(
        m,
        PhaseMiss::EmptyWindow {
            from_s: 5.0,
            to_s: 6.0,
            samples_s: Some([0.0, 2.0])
        }
    );
    assert_eq!(
        m.to_string(),
        "no sample in 5.00–6.00 s; the run's samples span 0.00–2.00 s"
    );
}

/// Of several failed checks the first in the module docs' order is named: a contact missed
/// before a motion too short.
#[test]
fn the_first_failed_check_is_named() {
    let p = PhaseSpec {
        contact: vec!["user1".into()],
        object_moves_m: 0.02,
        ..window()
    };
    let (sc, run) = one_site(p, [0.0; 3], |_| {
        (Vec3::zeros(), Vec3::new(0.1, 0.0, 0.0), 0.0, false)
    });
    assert!(matches!(miss(&sc, &run), PhaseMiss::Contact { .. }));
}
