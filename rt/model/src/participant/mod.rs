//! A simulated participant: a person who acts on what their own site shows and feels, not on a
//! script. It follows a task plan of steps that name objects as its site displays them; sees the
//! display after a visual reaction time and feels its tool after a haptic one; reaches along
//! minimum-jerk paths in Fitts' time, retargeting as the copy moves; grips with a margin over the
//! slip limit and raises the grip after a slip; trembles. The impedance hand
//! (`device::HandParams`) carries out the target it produces, as it carries out a script's.
//!
//! Deterministic from its seed; after [`Participant::new`] nothing allocates, so a station's
//! servo can run one.

mod params;
mod plan;
mod reach;

pub use params::ParticipantSpec;
pub use plan::{Action, Step, StepSpec};
pub use reach::MinJerk;

use crate::body::Vec3;
use crate::rng::Rng;
use crate::shape::Shape;
use crate::task::View;
use crate::world::MAX_OBJECTS;

/// Snapshots kept of what the site showed: at [`SNAPSHOT_PERIOD_S`], enough for the slowest
/// reaction a drawn person has.
const SNAPSHOTS: usize = 128;
/// How often a snapshot is kept, s.
const SNAPSHOT_PERIOD_S: f64 = 0.005;
/// How long a grasp's felt force must stay at its goal before the next step, s.
const GRASP_SETTLE_S: f64 = 0.15;
/// The grip's integral gain, m of press per N of shortfall per s: slow enough to stay stable
/// behind the grip's reaction time against the hand's and the contact's springs in series.
const GRIP_GAIN: f64 = 0.02;
/// How far past a face a press may go, m: a person does not drive the hand through an object.
const MAX_PRESS_M: f64 = 0.03;
/// The farthest a carry's corrections take the hand from where the step planned it, m (about a
/// hand's width).
const MAX_CARRY_CORRECTION_M: f64 = 0.08;
/// A slip raises the grip's floor by this factor.
const SLIP_BOOST: f64 = 1.3;
/// Least time between two slips the grip answers, s.
const SLIP_REFRACTORY_S: f64 = 0.15;
/// How fast a grip raised by a slip relaxes, s (time constant).
const GRIP_RELAX_S: f64 = 2.0;
/// Motor noise across a reach's direction, relative to the noise along it (extent errors
/// dominate direction errors, Gordon et al. 1994).
const ACROSS_NOISE: f64 = 0.3;

/// What the participant knows of the world it acts in (from the scenario).
#[derive(Debug, Clone, Copy)]
pub struct Surroundings<'a> {
    /// Each object's shape, in the world's order.
    pub shapes: &'a [Shape],
    /// The tool's radius, m.
    pub tool_radius_m: f64,
    /// The tool–object static friction (learned on the first touch, as people do).
    pub friction: f64,
}

/// A grip held on an object's face.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Grip {
    object: usize,
    side: Vec3,
    /// The face's contact point when the grasp began (the tool's centre touching it), world.
    base: Vec3,
    /// How far past `base` the hand presses, m (negative: short of it).
    press: f64,
    /// The normal force the grasp asked for, N.
    force_n: f64,
    /// The floor slips have raised the grip to, N.
    floor_n: f64,
    /// The slip the grip last answered (its snapshot time), s.
    slip_seen: f64,
    /// Whether the contact slipped at the last reflex snapshot.
    was_slipping: bool,
    /// The carry's path (an offset from `base`).
    carry: MinJerk,
    /// Where the carry step planned to take the hand (an offset from `base`): corrections stay
    /// within [`MAX_CARRY_CORRECTION_M`] of it.
    carry_planned: Vec3,
    /// Felt at the goal since, s.
    settled_since: Option<f64>,
    /// The person's margin over the slip limit.
    margin: f64,
    /// The person's approach speed, m/s.
    approach_m_per_s: f64,
}

/// What the participant did, for the metrics and the tests.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GripFigures {
    /// Servo ticks with a grip that felt its object.
    pub ticks: u64,
    /// Sum of the felt normal force over those ticks, N.
    pub sum_n: f64,
    /// The largest felt normal force, N.
    pub peak_n: f64,
    /// Sum of the margin over the slip limit (normal over what friction needs, less one) over
    /// ticks with a load.
    pub sum_margin: f64,
    /// Ticks with a load.
    pub loaded_ticks: u64,
    /// Slips answered.
    pub slips: u64,
    /// When the grip's floor last rose for a slip, s.
    pub last_boost_s: f64,
}

/// A simulated participant.
#[derive(Debug, Clone)]
pub struct Participant {
    /// The person drawn.
    pub person: ParticipantSpec,
    plan: Vec<Step>,
    step: usize,
    step_started: f64,
    /// The objects' centres when the step began (its conditions' `moved_m` origin).
    origin: [Vec3; MAX_OBJECTS],
    /// The free hand's path.
    motion: MinJerk,
    grip: Option<Grip>,
    snapshots: Vec<View>,
    newest: usize,
    kept: usize,
    next_snapshot: f64,
    shapes: [Shape; MAX_OBJECTS],
    tool_radius_m: f64,
    friction: f64,
    rng: Rng,
    tremor_phase: [f64; 3],
    /// The grip's figures so far.
    pub grip_figures: GripFigures,
    /// When each step began, s (NaN: not yet).
    step_times: [f64; MAX_STEPS],
    /// The step began at this tick: it sets its motion up.
    fresh: bool,
    /// The last tick's time, s.
    last_t: f64,
}

/// Most steps a plan may have.
pub const MAX_STEPS: usize = 32;

impl Participant {
    /// A person drawn from `mean` with `rng`, starting at rest at `start` with `plan`.
    pub fn new(
        mean: &ParticipantSpec,
        plan: Vec<Step>,
        around: Surroundings<'_>,
        start: Vec3,
        mut rng: Rng,
    ) -> Self {
        let person = mean.draw(&mut rng);
        let tremor_phase = [0; 3].map(|_| rng.range(0.0, std::f64::consts::TAU));
        let mut shapes = [Shape::Sphere { radius: 0.0 }; MAX_OBJECTS];
        shapes[..around.shapes.len()].copy_from_slice(around.shapes);
        let mut step_times = [f64::NAN; MAX_STEPS];
        step_times[0] = 0.0;
        Self {
            person,
            plan,
            step: 0,
            step_started: 0.0,
            origin: [Vec3::zeros(); MAX_OBJECTS],
            motion: MinJerk::hold(start, 0.0),
            grip: None,
            snapshots: vec![View::empty(start); SNAPSHOTS],
            newest: 0,
            kept: 0,
            next_snapshot: 0.0,
            shapes,
            tool_radius_m: around.tool_radius_m,
            friction: around.friction.max(1e-3),
            rng,
            tremor_phase,
            grip_figures: GripFigures::default(),
            step_times,
            fresh: true,
            last_t: 0.0,
        }
    }

    /// The step it is on (the plan's length when done).
    pub fn step(&self) -> usize {
        self.step
    }

    /// How many steps its plan has.
    pub fn plan_len(&self) -> usize {
        self.plan.len()
    }

    /// When step `k` began, s (`None`: not yet).
    pub fn step_time(&self, k: usize) -> Option<f64> {
        self.step_times.get(k).copied().filter(|t| !t.is_nan())
    }

    /// The hand's target and its velocity at `t` (what the impedance hand follows).
    pub fn target(&self, t: f64) -> (Vec3, Vec3) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let (p, v) = match &self.grip {
            Some(g) => {
                let (off, vel, _) = g.carry.at(t);
                (g.base + off - g.side * g.press, vel)
            }
            None => {
                let (p, v, _) = self.motion.at(t);
                (p, v)
            }
        };
        let w = std::f64::consts::TAU * self.person.tremor_hz;
        let a = self.person.tremor_m;
        let tremor = Vec3::from_fn(|k, _| a * (w * t + self.tremor_phase[k]).sin());
        let tremor_v = Vec3::from_fn(|k, _| a * w * (w * t + self.tremor_phase[k]).cos());
        (p + tremor, v + tremor_v)
    }

    /// The newest snapshot at or before `t` (the oldest kept when none is).
    fn seen_at(&self, t: f64) -> &View {
        let mut k = self.newest;
        for _ in 0..self.kept.max(1) {
            if self.snapshots[k].t_s <= t {
                return &self.snapshots[k];
            }
            k = (k + SNAPSHOTS - 1) % SNAPSHOTS;
        }
        &self.snapshots[(self.newest + SNAPSHOTS + 1 - self.kept.max(1)) % SNAPSHOTS]
    }

    /// Where the tool's centre touches object `k`'s face `side` as `view` shows it.
    fn face(&self, view: &View, k: usize, side: Vec3) -> Vec3 {
        let s = &view.shown[k];
        let local = s.rot.inverse() * side;
        let support = match self.shapes[k] {
            Shape::Sphere { radius } => radius,
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                radius * (local.x * local.x + local.y * local.y).sqrt()
                    + half_height * local.z.abs()
            }
            Shape::Box { half } => {
                half.x * local.x.abs() + half.y * local.y.abs() + half.z * local.z.abs()
            }
        };
        s.pos + side * (support + self.tool_radius_m)
    }

    /// A reach's duration to `goal` from the free hand's state at `t`, with its end point's motor
    /// noise drawn.
    fn aim(&mut self, t: f64, goal: Vec3) -> (Vec3, f64) {
        let from = self.motion.at(t).0;
        let d = (goal - from).norm();
        let sd = self.person.endpoint_noise * d;
        let draw = Vec3::from_fn(|_, _| self.rng.normal()) * sd;
        let noise = if d > 1e-9 {
            let along = (goal - from) / d;
            let extent = along * draw.dot(&along);
            extent + (draw - extent) * ACROSS_NOISE
        } else {
            Vec3::zeros()
        };
        (goal + noise, self.person.movement_time(d))
    }

    /// One servo tick: what the site shows and the tool feels now goes into the participant's
    /// memory; it acts on what it saw a reaction time ago.
    pub fn perceive(&mut self, now: &View) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        if now.t_s >= self.next_snapshot || self.kept == 0 {
            self.newest = (self.newest + 1) % SNAPSHOTS;
            self.snapshots[self.newest] = *now;
            self.kept = (self.kept + 1).min(SNAPSHOTS);
            self.next_snapshot = now.t_s + SNAPSHOT_PERIOD_S;
        }
        let t = now.t_s;
        let seen = *self.seen_at(t - self.person.visual_reaction_s);
        let felt = *self.seen_at(t - self.person.haptic_reaction_s);
        let reflex = *self.seen_at(t - self.person.grip_reflex_s);
        let dt = (t - self.last_t).clamp(0.0, 0.01);
        self.last_t = t;
        if let Some(g) = &mut self.grip {
            Self::regulate(g, &felt, &reflex, self.friction, dt, &mut self.grip_figures);
        }
        let Some(step) = self.plan.get(self.step).copied() else {
            return;
        };
        if self.fresh {
            self.origin = seen.centres();
        }
        let done = self.act(step, t, &seen, &felt);
        self.fresh = false;
        if done {
            self.step += 1;
            self.step_started = t;
            self.fresh = true;
            if let Some(s) = self.step_times.get_mut(self.step) {
                *s = t;
            }
        }
    }

    /// The grip against what the hand feels: press until the felt normal force has the margin
    /// over what friction needs for the felt load, and more after a slip.
    fn regulate(
        g: &mut Grip,
        felt: &View,
        reflex: &View,
        friction: f64,
        dt: f64,
        figures: &mut GripFigures,
    ) {
        let k = g.object;
        // A slip's onset, once per refractory period: the grip answers it once, not every tick
        // it lasts.
        let onset = reflex.slipping[k] && reflex.touching[k] && !g.was_slipping;
        g.was_slipping = reflex.slipping[k] && reflex.touching[k];
        if onset && reflex.t_s - g.slip_seen >= SLIP_REFRACTORY_S {
            g.slip_seen = reflex.t_s;
            let normal = (-reflex.felt[k].dot(&g.side)).max(g.force_n);
            g.floor_n = g.floor_n.max(normal * SLIP_BOOST);
            figures.slips += 1;
            figures.last_boost_s = reflex.t_s;
        }
        // The raised grip relaxes back over seconds once nothing slips.
        g.floor_n *= (-dt / GRIP_RELAX_S).exp();
        if !felt.touching[k] {
            // Not felt yet: approach the face at a careful speed.
            g.press = (g.press + g.approach_m_per_s * dt).min(MAX_PRESS_M);
            return;
        }
        let f = felt.felt[k];
        let normal = -f.dot(&g.side);
        let load = (f + g.side * normal).norm();
        let needed = load / friction;
        let goal = g.force_n.max(g.floor_n).max(needed * (1.0 + g.margin));
        g.press = (g.press + GRIP_GAIN * (goal - normal) * dt).clamp(-MAX_PRESS_M, MAX_PRESS_M);
        figures.ticks += 1;
        figures.sum_n += normal;
        figures.peak_n = figures.peak_n.max(normal);
        if needed > 1e-3 {
            figures.loaded_ticks += 1;
            figures.sum_margin += normal / needed - 1.0;
        }
    }

    /// Carries out step `step` at `t`; true when it is done.
    fn act(&mut self, step: Step, t: f64, seen: &View, felt: &View) -> bool {
        let width = self.person.target_width_m;
        match step.action {
            Action::Reach => {
                let goal = match (step.to, step.object) {
                    (Some(p), _) => p,
                    (None, Some(k)) => self.face(seen, k, step.side) + step.side * step.gap_m,
                    (None, None) => return true,
                };
                self.drop_grip(t);
                self.head_for(t, goal, width);
                self.motion.done(t) && (self.motion.goal() - goal).norm() < width
            }
            Action::Push => {
                let k = step.object.unwrap_or(0);
                self.drop_grip(t);
                let until = step.until.map(|c| c.holds(seen, &self.origin));
                if until == Some(true) {
                    self.motion = MinJerk::hold(self.motion.at(t).0, t);
                    return true;
                }
                if self.fresh || (self.motion.done(t) && until == Some(false)) {
                    let goal = self.face(seen, k, step.side) - step.side * step.depth_m;
                    let (goal, dur) = self.aim(t, goal);
                    self.motion = self.motion.retarget(t, goal, dur);
                }
                until.is_none() && self.motion.done(t) && !self.fresh
            }
            Action::Grasp => {
                let k = step.object.unwrap_or(0);
                if self
                    .grip
                    .is_none_or(|g| g.object != k || g.side != step.side)
                {
                    self.drop_grip(t);
                    let here = self.motion.at(t).0;
                    let face = self.face(seen, k, step.side);
                    // On the face's plane, off its centre as the hand is: no jump of the target.
                    let press = -(here - face).dot(&step.side);
                    self.grip = Some(Grip {
                        object: k,
                        side: step.side,
                        base: here + step.side * press,
                        press,
                        force_n: step.force_n,
                        floor_n: 0.0,
                        slip_seen: f64::NEG_INFINITY,
                        was_slipping: false,
                        carry: MinJerk::hold(Vec3::zeros(), t),
                        carry_planned: Vec3::zeros(),
                        settled_since: None,
                        margin: self.person.grip_margin,
                        approach_m_per_s: self.person.approach_m_per_s,
                    });
                }
                let Some(g) = self.grip.as_mut() else {
                    return false;
                };
                let at_goal = felt.touching[k] && -felt.felt[k].dot(&g.side) >= 0.9 * g.force_n;
                if !at_goal {
                    g.settled_since = None;
                    return false;
                }
                let since = *g.settled_since.get_or_insert(t);
                t - since >= GRASP_SETTLE_S
            }
            Action::Carry => {
                let Some(g) = self.grip.as_mut() else {
                    return true;
                };
                let k = g.object;
                if self.fresh {
                    let d = step.by.norm();
                    let dur = if step.for_s > 0.0 {
                        step.for_s
                    } else {
                        self.person.movement_time(d)
                    };
                    let from = g.carry.at(t).0;
                    g.carry =
                        MinJerk::new(t, from, Vec3::zeros(), Vec3::zeros(), from + step.by, dur);
                    g.carry_planned = from + step.by;
                }
                // Judged along the carry: how far across it the object sits is no business of
                // this step (a carry across a lift that has not quite settled).
                let along = step.by.try_normalize(1e-9).unwrap_or_else(Vec3::zeros);
                let there = self.origin[k] + step.by;
                let short = along * (there - seen.shown[k].pos).dot(&along);
                if short.norm() < width {
                    return g.carry.done(t);
                }
                // The move ended with the object short of where it should be (it slipped in the
                // grip, or a partner held back): once the eye has seen the move's end, move on by
                // what is missing, at the step's own pace, as a person corrects a reach. An object
                // no longer felt is not in the grip, and the hand goes no farther than a hand's
                // width from where the step planned it: what holds the object back then is not
                // the grip.
                let seen_end = t - g.carry.end() >= self.person.visual_reaction_s;
                let from = g.carry.at(t).0;
                let within = (from + short - g.carry_planned).norm() <= MAX_CARRY_CORRECTION_M;
                if seen_end && felt.touching[k] && within {
                    let d = short.norm();
                    let paced = if step.for_s > 0.0 && step.by.norm() > 1e-9 {
                        step.for_s * d / step.by.norm()
                    } else {
                        0.0
                    };
                    let dur = self.person.movement_time(d).max(paced);
                    g.carry =
                        MinJerk::new(t, from, Vec3::zeros(), Vec3::zeros(), from + short, dur);
                }
                false
            }
            Action::Release => {
                let (side, from) = match self.grip {
                    Some(g) => (g.side, self.target(t).0),
                    None => (step.side, self.motion.at(t).0),
                };
                if self.fresh || self.grip.is_some() {
                    self.grip = None;
                    let goal = from + side * step.away_m;
                    let dur = self.person.movement_time(step.away_m);
                    self.motion = MinJerk::new(t, from, Vec3::zeros(), Vec3::zeros(), goal, dur);
                }
                self.motion.done(t)
            }
            Action::Wait => {
                let timed = step.for_s > 0.0 && t - self.step_started >= step.for_s;
                let until = step.until.is_some_and(|c| c.holds(seen, &self.origin));
                timed || until
            }
        }
    }

    /// Lets go of a grip (a free motion starts where the hand is).
    fn drop_grip(&mut self, t: f64) {
        if self.grip.is_some() {
            let p = self.target(t).0;
            self.grip = None;
            self.motion = MinJerk::hold(p, t);
        }
    }

    /// Starts or bends a reach towards `goal` when the goal has moved by more than half the
    /// target's width from where the reach is headed.
    fn head_for(&mut self, t: f64, goal: Vec3, width: f64) {
        if (self.motion.goal() - goal).norm() <= width * 0.5 {
            return;
        }
        let (aimed, dur) = self.aim(t, goal);
        let dur = dur.max(self.motion.end() - t);
        self.motion = self.motion.retarget(t, aimed, dur);
    }
}

#[cfg(test)]
mod tests;
