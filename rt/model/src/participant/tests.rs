//! The reflexes, one test each: a participant reaches where its own copy shows the object, waits
//! when its plan says wait and moves a reaction time after what it waits for is shown, and a slip
//! raises its grip a grip reflex after it.

use super::*;
use crate::body::BodyState;
use crate::task::ConditionSpec;

const DISK: Shape = Shape::Cylinder {
    radius: 0.04,
    half_height: 0.01,
};

fn person(plan: &[StepSpec], start: Vec3, seed: u64) -> Participant {
    let plan = plan
        .iter()
        .enumerate()
        .map(|(k, s)| {
            s.resolve(&format!("plan[{k}]"), &["disk"])
                .expect("valid step")
        })
        .collect();
    Participant::new(
        &ParticipantSpec::default(),
        plan,
        Surroundings {
            shapes: &[DISK],
            tool_radius_m: 0.005,
            friction: 0.9,
        },
        start,
        Rng::new(seed),
    )
}

/// The site shows the disk at `at` (and the tool feels nothing).
fn showing(t_s: f64, at: Vec3, tool: Vec3) -> View {
    let mut v = View::empty(tool);
    v.t_s = t_s;
    v.objects = 1;
    v.shown[0] = BodyState::at_rest(at);
    v
}

fn reach_left_face() -> StepSpec {
    StepSpec {
        action: Action::Reach,
        object: Some("disk".into()),
        side: Some([-1.0, 0.0, 0.0]),
        gap_m: 0.01,
        ..StepSpec::default()
    }
}

/// Grasps the disk's left face with at least 1 N.
fn grasp_left_face() -> StepSpec {
    StepSpec {
        action: Action::Grasp,
        object: Some("disk".into()),
        side: Some([-1.0, 0.0, 0.0]),
        force_n: 1.0,
        ..StepSpec::default()
    }
}

/// Holds still for 10 s.
fn hold() -> StepSpec {
    StepSpec {
        action: Action::Wait,
        for_s: 10.0,
        ..StepSpec::default()
    }
}

#[test]
fn a_participant_reaches_where_its_own_copy_shows_the_object() {
    let start = Vec3::new(-0.2, 0.0, 0.01);
    for shown_at in [Vec3::new(-0.05, 0.0, 0.01), Vec3::new(0.02, 0.06, 0.01)] {
        let mut p = person(&[reach_left_face()], start, 3);
        for k in 0..3000 {
            let t = k as f64 * 1e-3;
            let v = showing(t, shown_at, p.target(t).0);
            p.perceive(&v);
        }
        // The left face's point, 1 cm short (the disk's radius, the tool's, the gap).
        let face = shown_at - Vec3::new(0.04 + 0.005 + 0.01, 0.0, 0.0);
        let end = p.target(3.0).0;
        assert!(
            (end - face).norm() < p.person.target_width_m,
            "shown at {shown_at:?}: the hand ended at {end:?}, the face is at {face:?}"
        );
        assert_eq!(p.step(), 1, "the reach is done");
    }
}

#[test]
fn a_participant_waits_until_what_it_waits_for_is_shown_and_moves_a_reaction_time_later() {
    let start = Vec3::new(-0.2, 0.0, 0.01);
    let wait = StepSpec {
        action: Action::Wait,
        until: Some(ConditionSpec {
            object: Some("disk".into()),
            moved_m: Some(0.02),
            ..ConditionSpec::default()
        }),
        ..StepSpec::default()
    };
    let mut p = person(&[wait, reach_left_face()], start, 5);
    let (before, moved_at) = (Vec3::new(-0.05, 0.0, 0.01), 1.0);
    let mut moved_early = false;
    for k in 0..2500 {
        let t = k as f64 * 1e-3;
        let at = if t < moved_at {
            before
        } else {
            before + Vec3::new(0.05, 0.0, 0.0)
        };
        p.perceive(&showing(t, at, p.target(t).0));
        // Beyond the tremor's reach (tens of micrometres) before it could have seen anything.
        moved_early |= t < moved_at + 0.1 && (p.target(t).0 - start).norm() > 1e-3;
    }
    assert!(!moved_early, "the hand held still while it waited");
    let started = p
        .step_time(1)
        .expect("the wait ended once the disk was seen to move");
    let reaction = p.person.visual_reaction_s;
    assert!(
        started >= moved_at + reaction && started <= moved_at + reaction + 0.006,
        "the reach began at {started} s: the disk moved at {moved_at} s, the reaction is {reaction} s"
    );
    assert!(
        (p.target(2.5).0 - start).norm() > 0.05,
        "and then it reached"
    );
}

#[test]
fn a_slip_raises_the_grip_a_grip_reflex_after_it() {
    let start = Vec3::new(-0.1, 0.0, 0.01);
    let mut p = person(&[grasp_left_face(), hold()], start, 7);
    let at = Vec3::new(-0.05, 0.0, 0.01);
    let slip_at = 1.0;
    let reflex = p.person.grip_reflex_s;
    let mut raised = None;
    for k in 0..2000 {
        let t = k as f64 * 1e-3;
        let mut v = showing(t, at, p.target(t).0);
        // Touching, pressed with the asked force; a slip for 20 ms at 1 s.
        v.touching[0] = true;
        v.felt[0] = Vec3::new(1.0, 0.0, 0.0);
        v.slipping[0] = (slip_at..slip_at + 0.02).contains(&t);
        p.perceive(&v);
        if raised.is_none() && p.grip_figures.slips > 0 {
            raised = Some(t);
        }
    }
    let raised = raised.expect("the slip raised the grip");
    assert!(
        raised >= slip_at + reflex && raised < slip_at + reflex + 0.01,
        "raised at {raised} s: slipped at {slip_at} s, the reflex is {reflex} s"
    );
    assert_eq!(p.grip_figures.slips, 1, "one slip, answered once");
    assert!(p.grip_figures.peak_n >= 1.0);
}

#[test]
fn a_carry_is_judged_along_its_direction_not_across_it() {
    // Carried 10 cm along +y while the disk shows 1.5 cm lower than when the carry began (a lift
    // that had not settled, a partner holding it lower): across the carry is not the carry's
    // business, so it is done once the disk is seen across.
    let start = Vec3::new(-0.1, 0.0, 0.01);
    let carry = StepSpec {
        action: Action::Carry,
        by_m: Some([0.0, 0.1, 0.0]),
        for_s: 1.0,
        ..StepSpec::default()
    };
    let mut p = person(&[grasp_left_face(), carry, hold()], start, 9);
    let at = Vec3::new(-0.05, 0.0, 0.01);
    for k in 0..4000 {
        let t = k as f64 * 1e-3;
        let hand = p.target(t).0;
        let carried = p.step_time(1).is_some();
        let shown = at + Vec3::new(0.0, hand.y - start.y, if carried { -0.015 } else { 0.0 });
        let mut v = showing(t, shown, hand);
        v.touching[0] = true;
        v.felt[0] = Vec3::new(1.0, 0.0, 0.0);
        p.perceive(&v);
    }
    let began = p.step_time(1).expect("the grasp was done");
    let done = p.step_time(2).expect("the carry was done");
    assert!(
        done < began + 1.0 + 0.5,
        "the carry began at {began} s and was done only at {done} s"
    );
    let end = p.target(4.0).0;
    assert!(
        (end.z - start.z).abs() < 1e-3,
        "the hand stayed at its height: {end:?}"
    );
}

#[test]
fn the_same_seed_is_the_same_person_and_the_same_hand() {
    let run = |seed| {
        let mut p = person(&[reach_left_face()], Vec3::new(-0.2, 0.0, 0.01), seed);
        let mut path = Vec::new();
        for k in 0..1500 {
            let t = k as f64 * 1e-3;
            p.perceive(&showing(t, Vec3::new(-0.05, 0.0, 0.01), p.target(t).0));
            path.push(p.target(t));
        }
        path
    };
    assert_eq!(run(11), run(11));
    assert_ne!(run(11), run(12));
}
