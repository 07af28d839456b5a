//! The paradigms of a psychophysics lab, run on simulated participants through the same code a
//! site's hand runs: `Participant::perceive` fed a scripted view every servo tick, and
//! `Participant::target`, the path the impedance hand follows, recorded.
//!
//! - Reaches: blocks of discrete reaches back and forth over a distance D to a target of width W.
//! - Visual reaction: the hand waits for an object to move; the shown object jumps.
//! - Haptic reaction: the hand approaches a face until it feels it; the face is touched.
//! - Grip: a grasp holds an object whose load rises as in a lift, then a slip is induced.
//!
//! A reaction is timed from the stimulus to the first instant the hand's target moves otherwise
//! than in a control trial of the same person without the stimulus, which shares every draw until
//! then: what a lab estimates with a threshold on the recorded motion, here without the
//! threshold's delay, to the servo tick.

use anyhow::anyhow;
use coop_model::body::{BodyState, Vec3};
use coop_model::contact::ContactParams;
use coop_model::device::HandParams;
use coop_model::participant::{Action, Participant, ParticipantSpec, StepSpec, Surroundings};
use coop_model::rng::Rng;
use coop_model::shape::Shape;
use coop_model::task::{ConditionSpec, View};

use super::measure::{self, ReachFigures, Sample};

/// The servo tick the participant is run at, s (a scenario's default servo rate).
pub const TICK_S: f64 = 1e-3;
/// The random stream `Scenario::participant` draws site 0's person from, with the scenario's
/// seed: seed N here is the person a scenario with seed N puts at its first site.
const SITE0_STREAM: u64 = 2000;
/// The first of the streams the trials' motor noise and tremor come from (none the simulator
/// uses); each paradigm's trials count from its own multiple of [`PARADIGM_TRIALS`].
const TRIALS_STREAM: u64 = 10_000;
/// Room for each paradigm's trials among the streams.
const PARADIGM_TRIALS: u64 = 1000;
/// The stream the trials' random timing comes from.
const TIMING_STREAM: u64 = 9000;
/// Reach distances D, m.
pub const DISTANCES_M: [f64; 3] = [0.05, 0.1, 0.2];
/// Target widths W, m.
pub const WIDTHS_M: [f64; 3] = [0.005, 0.01, 0.02];
/// Reaches per participant and condition, half out and half back.
pub const REACHES: usize = 16;
/// Trials per participant for each reaction time and for the slip response.
pub const REACTION_TRIALS: usize = 10;
/// How long the hand rests between two reaches, s.
const REST_S: f64 = 0.2;
/// The object's radius, m.
const OBJECT_RADIUS_M: f64 = 0.03;
/// The object: a ball.
const OBJECT: Shape = Shape::Sphere {
    radius: OBJECT_RADIUS_M,
};
/// The object's name in the plans.
const NAMES: [&str; 1] = ["object"];
/// The tool's radius, m.
const TOOL_RADIUS_M: f64 = 0.005;
/// The normal force a grasp asks for at least, N: below what the held load needs, so the hold's
/// grip is the participant's regulation against slip, not the step's floor.
const GRASP_N: f64 = 0.5;
/// The held object's load, N (the weight of about 200 g).
pub const LOAD_N: f64 = 2.0;
/// When the load begins to rise, s (the grasp has settled by then).
const LOAD_AT_S: f64 = 1.0;
/// How long the load rises, s: about a lift's loading phase.
pub const LOAD_RISE_S: f64 = 0.3;
/// Where the window of the static hold the grip is averaged over begins, s after the load began
/// to rise (the grip raised by a slip during the rise has relaxed by then).
pub const HOLD_FROM_S: f64 = 3.0;
/// Where that window ends, s after the load began to rise.
pub const HOLD_TO_S: f64 = 5.0;
/// How long an induced slip lasts, s.
pub const SLIP_S: f64 = 0.02;
/// Two recordings part when their positions differ by more than this, m, or their velocities by
/// more than [`PART_M_S`] (far below any motion the model makes within a tick, far above
/// rounding). Both: a grip's press moves the target without entering its velocity.
const PART_M: f64 = 1e-9;
/// See [`PART_M`], m/s.
const PART_M_S: f64 = 1e-6;

/// Where every hand starts, world, m.
fn start() -> Vec3 {
    Vec3::new(-0.1, 0.0, 0.05)
}

/// The direction the reaches go and the object lies in.
fn ahead() -> Vec3 {
    Vec3::new(1.0, 0.0, 0.0)
}

/// The object's centre in the reaction and grip paradigms.
fn object_at() -> Vec3 {
    start() + ahead() * 0.1
}

/// The face the hand grasps: the tool's centre touching the object's −x side.
fn face() -> Vec3 {
    object_at() - ahead() * (OBJECT_RADIUS_M + TOOL_RADIUS_M)
}

/// How stiff the held object feels: the hand's arm spring in series with the tool–object
/// contact (both the scenario defaults), N/m.
fn felt_stiffness_n_per_m() -> f64 {
    let (h, c) = (
        HandParams::default().stiffness_n_per_m,
        ContactParams::default().stiffness_n_per_m,
    );
    h * c / (h + c)
}

/// The tool–object static friction of a scenario without a `[contact]` table.
pub fn friction() -> f64 {
    ContactParams::default().friction_static
}

/// Participant `seed` in trial `trial` of a paradigm, with `plan`, starting at rest at `from`:
/// the person [`drawn`], its motor noise and tremor from the trial's own random stream, so that
/// blocks and trials are independent draws of the same person, as a lab's are.
fn participant(
    seed: u64,
    trial: u64,
    plan: &[StepSpec],
    from: Vec3,
) -> anyhow::Result<Participant> {
    let plan = plan
        .iter()
        .enumerate()
        .map(|(k, s)| s.resolve(&format!("plan[{k}]"), &NAMES))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| anyhow!("a paradigm's plan: {e}"))?;
    // The person drawn has no spread left: drawing it again gives it back unchanged.
    Ok(Participant::new(
        &drawn(seed),
        plan,
        Surroundings {
            shapes: &[OBJECT],
            tool_radius_m: TOOL_RADIUS_M,
            friction: friction(),
        },
        from,
        Rng::derive(seed, TRIALS_STREAM + trial),
    ))
}

/// Participant `seed`: the person a scenario with that seed draws for its first site from the
/// default `[site.participant]`.
pub fn drawn(seed: u64) -> ParticipantSpec {
    ParticipantSpec::default().draw(&mut Rng::derive(seed, SITE0_STREAM))
}

/// What the site shows at `t_s`: the object at `at`, the tool at `tool`, nothing felt.
fn showing(t_s: f64, at: Vec3, tool: Vec3) -> View {
    let mut v = View::empty(tool);
    v.t_s = t_s;
    v.objects = 1;
    v.shown[0] = BodyState::at_rest(at);
    v
}

/// Runs `p` tick by tick until `until_s` or until `done`, the site showing what `scene` makes of
/// the time and the tool's position (the target, before the tick's perception), and records the
/// target after each tick.
fn record(
    p: &mut Participant,
    until_s: f64,
    done: impl Fn(&Participant) -> bool,
    mut scene: impl FnMut(f64, Vec3) -> View,
) -> Vec<Sample> {
    let ticks = (until_s / TICK_S).round() as usize;
    let mut out = Vec::with_capacity(ticks + 1);
    for k in 0..=ticks {
        let t = k as f64 * TICK_S;
        let tool = p.target(t).0;
        p.perceive(&scene(t, tool));
        let (pos, vel) = p.target(t);
        out.push(Sample { t_s: t, pos, vel });
        if done(p) {
            break;
        }
    }
    out
}

/// One reach of a block: its figures and how far past its target it ended along its direction,
/// m (negative: short).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reach {
    /// What the lab measures of it.
    pub figures: ReachFigures,
    /// Its end point's error along the reach, m.
    pub along_m: f64,
}

/// A block of [`REACHES`] reaches of participant `seed` over `d_m` to a target of `w_m`: the
/// reaches measured, and the first one's recording.
///
/// # Errors
/// A plan the model refuses (a bug here).
pub fn reach_block(
    seed: u64,
    block: u64,
    d_m: f64,
    w_m: f64,
) -> anyhow::Result<(Vec<Reach>, Vec<Sample>)> {
    let goal = |i: usize| start() + ahead() * if i.is_multiple_of(2) { d_m } else { 0.0 };
    let mut plan = Vec::with_capacity(2 * REACHES);
    for i in 0..REACHES {
        plan.push(StepSpec {
            action: Action::Reach,
            to_m: Some(goal(i).into()),
            ..StepSpec::default()
        });
        plan.push(StepSpec {
            action: Action::Wait,
            for_s: REST_S,
            ..StepSpec::default()
        });
    }
    let mut p = participant(seed, block, &plan, start())?;
    // The lab shows the target: W is the task's, not the width the person is content with
    // elsewhere; everything else stays the person drawn.
    p.person.target_width_m = w_m;
    let longest = p.person.movement_time(d_m) + REST_S + 1.0;
    let n = plan.len();
    let path = record(
        &mut p,
        REACHES as f64 * longest,
        |p| p.step() >= n,
        |t, tool| showing(t, Vec3::new(1.0, 1.0, 0.0), tool),
    );
    let mut reaches = Vec::with_capacity(REACHES);
    let mut first = Vec::new();
    for i in 0..REACHES {
        let from = p.step_time(2 * i).unwrap_or(f64::INFINITY);
        let to = p.step_time(2 * i + 2).unwrap_or(f64::INFINITY);
        let part: Vec<Sample> = path
            .iter()
            .filter(|s| s.t_s >= from && s.t_s < to)
            .copied()
            .collect();
        let Some(figures) = measure::measure_reach(&part) else {
            continue;
        };
        let dir = (goal(i) - goal(i + 1)).normalize();
        reaches.push(Reach {
            figures,
            along_m: (figures.end - goal(i)).dot(&dir),
        });
        if i == 0 {
            first = part;
        }
    }
    Ok((reaches, first))
}

/// The trials' random timing for participant `seed`: uniform in `[lo, hi)`, one per trial.
fn timings(seed: u64, which: u64, lo: f64, hi: f64) -> Vec<f64> {
    let mut rng = Rng::derive(seed, TIMING_STREAM + which);
    (0..REACTION_TRIALS).map(|_| rng.range(lo, hi)).collect()
}

/// Visual reaction times of participant `seed`, s: the hand waits for the object to move, and
/// reaches for it once it has; the shown object jumps 5 cm at a random moment, and the time runs
/// to the hand's first move.
///
/// # Errors
/// A plan the model refuses (a bug here).
pub fn visual_reactions(seed: u64) -> anyhow::Result<Vec<f64>> {
    let plan = [
        StepSpec {
            action: Action::Wait,
            until: Some(ConditionSpec {
                object: Some(NAMES[0].into()),
                moved_m: Some(0.02),
                ..ConditionSpec::default()
            }),
            ..StepSpec::default()
        },
        StepSpec {
            action: Action::Reach,
            object: Some(NAMES[0].into()),
            side: Some([-1.0, 0.0, 0.0]),
            gap_m: 0.01,
            ..StepSpec::default()
        },
    ];
    let mut out = Vec::new();
    for (k, jump_s) in (0..).zip(timings(seed, 0, 0.5, 1.0)) {
        let run = |jumps: bool| -> anyhow::Result<Vec<Sample>> {
            let mut p = participant(seed, PARADIGM_TRIALS + k, &plan, start())?;
            Ok(record(
                &mut p,
                jump_s + 0.6,
                |_| false,
                |t, tool| {
                    let moved = if jumps && t >= jump_s { 0.05 } else { 0.0 };
                    showing(t, object_at() + ahead() * moved, tool)
                },
            ))
        };
        if let Some(t) = measure::first_divergence(&run(true)?, &run(false)?, PART_M, PART_M_S) {
            out.push(t - jump_s);
        }
    }
    Ok(out)
}

/// What the hand feels of the held object when the tool's centre is at `tool`: whether it
/// touches the face, the normal force, N (the face as a spring of [`felt_stiffness_n_per_m`]).
fn pressed(tool: Vec3) -> (bool, f64) {
    let depth = (tool - face()).dot(&ahead());
    (depth > 0.0, felt_stiffness_n_per_m() * depth.max(0.0))
}

/// Haptic reaction times of participant `seed`, s: the hand approaches the face at its careful
/// speed until it feels it, from a random gap of 5 to 15 mm; the time runs from the touch to the
/// approach's first change.
///
/// # Errors
/// A plan the model refuses (a bug here).
pub fn haptic_reactions(seed: u64) -> anyhow::Result<Vec<f64>> {
    let plan = [grasp(), hold()];
    let mut out = Vec::new();
    for (k, gap_m) in (0..).zip(timings(seed, 1, 0.005, 0.015)) {
        let mut touched = None;
        let mut run = |touches: bool| -> anyhow::Result<Vec<Sample>> {
            let from = face() - ahead() * gap_m;
            let mut p = participant(seed, 2 * PARADIGM_TRIALS + k, &plan, from)?;
            Ok(record(
                &mut p,
                1.0,
                |_| false,
                |t, tool| {
                    let mut v = showing(t, object_at(), tool);
                    let (touching, normal_n) = pressed(tool);
                    if touches && touching {
                        touched.get_or_insert(t);
                        v.touching[0] = true;
                        v.felt[0] = ahead() * normal_n;
                    }
                    v
                },
            ))
        };
        let (felt, control) = (run(true)?, run(false)?);
        if let (Some(t), Some(t0)) = (
            measure::first_divergence(&felt, &control, PART_M, PART_M_S),
            touched,
        ) {
            out.push(t - t0);
        }
    }
    Ok(out)
}

/// A grasp of the object's −x face.
fn grasp() -> StepSpec {
    StepSpec {
        action: Action::Grasp,
        object: Some(NAMES[0].into()),
        side: Some([-1.0, 0.0, 0.0]),
        force_n: GRASP_N,
        ..StepSpec::default()
    }
}

/// Holding on (the grip keeps regulating while the plan waits).
fn hold() -> StepSpec {
    StepSpec {
        action: Action::Wait,
        for_s: 60.0,
        ..StepSpec::default()
    }
}

/// A held object's trial.
struct HoldRun {
    samples: Vec<Sample>,
    /// The normal force the hand pressed with and the load, N, at every sample.
    forces: Vec<(f64, f64)>,
    /// Slips the participant answered.
    slips: u64,
}

/// The load at `t_s`: rising linearly from [`LOAD_AT_S`] over [`LOAD_RISE_S`] to [`LOAD_N`].
fn load_n(t_s: f64) -> f64 {
    LOAD_N * ((t_s - LOAD_AT_S) / LOAD_RISE_S).clamp(0.0, 1.0)
}

/// Participant `seed` grasps the object from 5 mm away and holds it while its load rises and
/// stays; the contact slips while the load exceeds what friction holds, and at `slip_at_s` for
/// [`SLIP_S`] whatever the grip.
fn hold_run(seed: u64, slip_at_s: Option<f64>) -> anyhow::Result<HoldRun> {
    // Every slip trial is the control trial until its slip: the same stream.
    let trial = 3 * PARADIGM_TRIALS;
    let mut p = participant(seed, trial, &[grasp(), hold()], face() - ahead() * 0.005)?;
    let mu = friction();
    let mut forces = Vec::new();
    let samples = record(
        &mut p,
        LOAD_AT_S + HOLD_TO_S,
        |_| false,
        |t, tool| {
            let mut v = showing(t, object_at(), tool);
            let (touching, normal_n) = pressed(tool);
            let load = if touching { load_n(t) } else { 0.0 };
            let induced = slip_at_s.is_some_and(|s| (s..s + SLIP_S).contains(&t));
            v.touching[0] = touching;
            // The force the tool puts on the object: pressing it along the face's normal and
            // bearing its load (upwards).
            v.felt[0] = ahead() * normal_n + Vec3::z() * load;
            v.slipping[0] = touching && (load > mu * normal_n || induced);
            forces.push((normal_n, load));
            v
        },
    );
    Ok(HoldRun {
        samples,
        forces,
        slips: p.grip_figures.slips,
    })
}

/// How participant `seed` holds a load: the grip force over the load and the margin over the
/// slip limit, averaged over the static hold, and the slips answered while the load rose.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Grip {
    /// Grip (normal) force over load force in the static hold.
    pub grip_over_load: f64,
    /// Grip force over the least that holds the load, less one.
    pub margin: f64,
    /// Slips the participant answered before the static hold.
    pub slips_while_loading: u64,
}

/// The grip of participant `seed` holding [`LOAD_N`], and its grip's latencies after induced
/// slips at random moments of the static hold, s.
///
/// # Errors
/// A plan the model refuses (a bug here).
pub fn grip(seed: u64) -> anyhow::Result<(Grip, Vec<f64>)> {
    let control = hold_run(seed, None)?;
    let mu = friction();
    let window: Vec<(f64, f64)> = control
        .samples
        .iter()
        .zip(&control.forces)
        .filter(|(s, _)| (LOAD_AT_S + HOLD_FROM_S..LOAD_AT_S + HOLD_TO_S).contains(&s.t_s))
        .map(|(_, &f)| f)
        .collect();
    let ratio: Vec<f64> = window.iter().map(|(n, l)| n / l).collect();
    let grip_over_load = measure::mean_sd(&ratio).0;
    let held = Grip {
        grip_over_load,
        margin: grip_over_load * mu - 1.0,
        slips_while_loading: control.slips,
    };
    let mut latencies = Vec::new();
    let from = LOAD_AT_S + HOLD_FROM_S;
    for slip_s in timings(seed, 2, from, from + 1.0) {
        let run = hold_run(seed, Some(slip_s))?;
        if let Some(t) = measure::first_divergence(&run.samples, &control.samples, PART_M, PART_M_S)
        {
            latencies.push(t - slip_s);
        }
    }
    Ok((held, latencies))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_trial_runs_the_person_drawn_with_its_own_noise() {
        let plan = [hold()];
        let a = participant(4, 0, &plan, start()).unwrap();
        assert_eq!(a.person, drawn(4));
        assert_ne!(drawn(4), drawn(5));
    }

    /// The paradigms time what the model was drawn with: a reaction is the person's own, late by
    /// no more than the participant's memory's sampling (a snapshot every 5 ms) and the few
    /// ticks from the stimulus to the first motion (shown, looked back at, the step changed, the
    /// motion begun); a grip holds the person's margin.
    #[test]
    fn the_paradigms_measure_the_reactions_and_the_margin_the_person_has() {
        for seed in [1, 6] {
            let who = drawn(seed);
            let late = |measured: &[f64], drawn_s: f64, what: &str| {
                assert_eq!(measured.len(), REACTION_TRIALS, "{what}: every trial timed");
                for &m in measured {
                    assert!(
                        m >= drawn_s && m <= drawn_s + 0.005 + 5.0 * TICK_S,
                        "seed {seed} {what}: measured {m} s, drawn {drawn_s} s"
                    );
                }
            };
            late(
                &visual_reactions(seed).unwrap(),
                who.visual_reaction_s,
                "visual",
            );
            late(
                &haptic_reactions(seed).unwrap(),
                who.haptic_reaction_s,
                "haptic",
            );
            let (grip, latencies) = grip(seed).unwrap();
            late(&latencies, who.grip_reflex_s, "slip");
            assert!(
                (grip.margin - who.grip_margin).abs() < 0.02,
                "seed {seed}: margin {} held, {} drawn",
                grip.margin,
                who.grip_margin
            );
        }
    }

    #[test]
    fn a_block_measures_every_reach_near_its_planned_time() {
        let (d, w) = (DISTANCES_M[1], WIDTHS_M[1]);
        let (reaches, first) = reach_block(2, 0, d, w).unwrap();
        assert_eq!(reaches.len(), REACHES);
        assert!(!first.is_empty());
        let mut person = drawn(2);
        person.target_width_m = w;
        // The 5 % criterion leaves out minimum jerk's two tails.
        let kept = 1.0 - 2.0 * measure::min_jerk_crossing(measure::ONSET_SHARE);
        let planned = person.movement_time(d) * kept;
        for r in &reaches {
            assert!(
                (r.figures.mt_s / planned - 1.0).abs() < 0.05,
                "MT {} s, planned {planned} s",
                r.figures.mt_s
            );
            assert!(r.along_m.abs() <= w / 2.0 + 1e-3, "{r:?}");
        }
    }
}
