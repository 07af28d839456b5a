//! The energy bound every correction of a copy obeys: a copy never gains energy it was not given.
//!
//! A copy's energy ([`stored_energy`]) is what it can give back: kinetic (linear and angular),
//! gravity's potential, and the environment's penalty springs (½ K d², d the deepest penetration
//! of each plane, the same spring [`crate::contact::environment_wrench`] pushes with); where the own
//! tool is known, its contact spring too ([`ToolSpring`]). Physics alone changes it only by the work
//! of the users' contact forces and of the environment (passive: its dampers and friction take
//! energy, its springs give back at most what they stored). A *correction* — a state adopted from
//! another site — is not physics, and nothing in it says where its energy came from. So it is split
//! into a *base*, whose energy is accounted for (for `paper`: the sender's state dead-reckoned — its
//! energy is what the sender's copy got from its users — or the local copy's own), and the rest,
//! which may add at most a **budget** of real work done at this site. A correction that would exceed
//! it is scaled back along the line from the base ([`bound_gain`]) until it fits, and counted
//! ([`crate::method::Adoption::clipped_j`]).
//!
//! For `paper` the budget is an energy **tank** filled by the own user's positive work on the local
//! copy, step by step, and drained by what replays add: the own impulses the sender had not seen,
//! replayed on the adopted state, may add at most the work they did here, and each joule the user
//! put in is granted once. Why the work and not the impulses' kinetic energy: an impulse the user
//! gave while the table's friction or support held the object (a user pressing the disk down and
//! sideways in a squeeze) did no work on the local copy, and replayed on a state that is not held
//! the same way it throws the object. That is the `paper` blow-up at 300 ms, seed 3: a 3 N press
//! held by friction, replayed over 0.3 s into the left wall's penalty spring, 4.7 kJ and 98 m. Why
//! once: a replay's velocity along the user's force makes the force do positive work on the next
//! steps, and granting that work again to the next replay pumps the copy.
//!
//! Every step of the bound leaves a correction that fits alone, to the bit, so a method's figures
//! change only where it bites ([`crate::metrics::Metrics::bounded_corrections`] counts it).

use crate::body::{BodyState, Vec3};
use crate::contact::{pair_depth, PairSide};
use crate::world::{plane_depth, World};

use super::copy::WorldCopy;

/// Kinetic, gravitational and environment-spring energy of `s`, J (see the module docs).
pub fn stored_energy(world: &World, k: usize, s: &BodyState) -> f64 {
    s.mechanical_energy(&world.bodies[k].mass, world.gravity) + spring_energy(world, k, s)
}

/// The environment's penalty springs' energy at `s`: ½ K d² per plane, J.
pub fn spring_energy(world: &World, k: usize, s: &BodyState) -> f64 {
    let stiffness = world.env_contact.stiffness_n_per_m;
    world
        .planes()
        .iter()
        .map(|plane| plane_depth(&world.bodies[k].shape, plane, s).max(0.0))
        .fold(0.0, |e, d| e + 0.5 * stiffness * d * d)
}

/// The penalty springs between object `k` at `s` and the other objects of `copy` as they are
/// there: ½ K d² per pair, d the pair's depth, J.
pub fn pair_spring_energy(world: &World, copy: &WorldCopy, k: usize, s: &BodyState) -> f64 {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    let bodies = world.bodies();
    let stiffness = world.object_contact.stiffness_n_per_m;
    let me = PairSide {
        shape: &bodies[k].shape,
        body: s,
        mass: &bodies[k].mass,
    };
    let mut e = 0.0;
    for (j, o) in copy.objects().iter().enumerate().take(bodies.len()) {
        if j == k {
            continue;
        }
        let other = PairSide {
            shape: &bodies[j].shape,
            body: &o.state,
            mass: &bodies[j].mass,
        };
        let d = pair_depth(&me, &other);
        e += 0.5 * stiffness * d * d;
    }
    e
}

/// A correction of object `k` of a world of several (an adopted or pulled state), from `local`
/// to `new`, scaled back along the line between them until the springs between it and the
/// copy's other objects hold no more than they held at `local`: moved into another object, it
/// would load their spring with energy nobody gave (a cup pulled into the tray it stands on is
/// thrown off: `tray.toml`, `coupled`, 50 ms, 78 mJ beyond every user's work). `None` when `new`
/// fits (it is then used as it is, to the bit), else the bounded state and the spring energy the
/// bound kept out, J. A world of one object has no pairs: always `None`.
pub fn bound_pairs(
    world: &World,
    copy: &WorldCopy,
    k: usize,
    local: &BodyState,
    new: &BodyState,
) -> Option<(BodyState, f64)> {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    if copy.len() < 2 {
        return None;
    }
    bound_spring(local, new, 0.0, |s| pair_spring_energy(world, copy, k, s))
}

/// A correction of object `k` from `local` to `new`, scaled back along the line between them
/// until the own tool's spring holds no more than it held at `local` plus `budget_j`: a received
/// state pressed onto the own tool (the sender's copy had no such contact: the own tool is not
/// there) would make the tool throw it with energy nobody gave (`paper.toml`, `paper`, 50 ms,
/// seed 2: a disk adopted 23 mm onto user 1's tool, thrown 0.7 m by its 4.6 N). `None` when it
/// fits.
pub fn bound_tool(
    world: &World,
    k: usize,
    tool: &ToolSpring,
    (local, new): (&BodyState, &BodyState),
    budget_j: f64,
) -> Option<(BodyState, f64)> {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    bound_spring(local, new, budget_j, |s| tool.energy(world, k, s))
}

/// `local → new` scaled back until `spring` holds no more than at `local` plus `budget_j` (see
/// [`bound_pairs`]).
fn bound_spring(
    local: &BodyState,
    new: &BodyState,
    budget_j: f64,
    spring: impl Fn(&BodyState) -> f64,
) -> Option<(BodyState, f64)> {
    let held = spring(local) + budget_j.max(0.0);
    let e_new = spring(new);
    if e_new <= held {
        return None;
    }
    let bounded = scale_back(local, new, |s| spring(s) <= held);
    Some((bounded, e_new - spring(&bounded)))
}

/// The largest fraction of the way from `base` to `full` whose state `fits` (`base`, the fraction
/// 0, is taken to fit): [`BISECTIONS`] halvings of plain arithmetic, the same bits everywhere.
fn scale_back(base: &BodyState, full: &BodyState, fits: impl Fn(&BodyState) -> bool) -> BodyState {
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for _ in 0..BISECTIONS {
        let mid = 0.5 * (lo + hi);
        if fits(&blend(base, full, mid)) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    blend(base, full, lo)
}

/// The states a `paper` adoption is made of.
#[derive(Debug, Clone, Copy)]
pub struct Adopted {
    /// The local copy before it.
    pub local: BodyState,
    /// The sender's state dead-reckoned to now: its energy is the sender's copy's.
    pub given: BodyState,
    /// `given` with the local position and velocity along the normals of the planes the local copy
    /// rests on.
    pub base: BodyState,
    /// `base` with the own user's impulses the sender had not seen replayed on it.
    pub full: BodyState,
    /// The own tool, if known.
    pub tool: Option<ToolSpring>,
}

/// `paper`'s adoption bounded (see the module docs): the state to adopt, the energy the bound
/// took out, J, and the energy the replay added over the base (what it spent of `own_work_j`), J. Two steps, each left alone (to the bit) when it fits:
///
/// 1. Keeping the local contact along a plane's normal must not press the adopted object deeper
///    into the environment than either copy was (the sender's tilt on the local height puts a rim
///    into the table): if it does, `base` is scaled back towards `given` to the larger of the two
///    copies' energies.
/// 2. The replayed impulses may add at most `own_work_j`, the work they did on the local copy.
///
/// Energies count the own tool's spring when it is known: an adoption that moves the object onto
/// the tool is a gain.
pub fn bound_adoption(
    world: &World,
    k: usize,
    a: &Adopted,
    own_work_j: f64,
) -> (BodyState, f64, f64) {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    let tool = a.tool.as_ref();
    let e_full = energy(world, k, &a.full, tool);
    let deepest_held = spring_energy(world, k, &a.local).max(spring_energy(world, k, &a.given));
    let (base, full) = if spring_energy(world, k, &a.base) > deepest_held {
        let held = energy(world, k, &a.local, tool).max(energy(world, k, &a.given, tool));
        let budget = held - energy(world, k, &a.given, tool) + own_work_j.max(0.0);
        match bound_gain(world, k, &a.given, &a.base, budget, tool) {
            Some((base, _)) => {
                // The replay moves the bounded base as it moved the unbounded one.
                let full = BodyState {
                    pos: base.pos + (a.full.pos - a.base.pos),
                    vel: base.vel + (a.full.vel - a.base.vel),
                    ang_mom: base.ang_mom + (a.full.ang_mom - a.base.ang_mom),
                    rot: a.full.rot * a.base.rot.inverse() * base.rot,
                };
                (base, full)
            }
            None => (a.base, a.full),
        }
    } else {
        (a.base, a.full)
    };
    let out = bound_gain(world, k, &base, &full, own_work_j, tool).map_or(full, |(s, _)| s);
    let clipped = e_full - energy(world, k, &out, tool);
    // What the replay spent is the larger of its two gains, as the bound limits both: counted with
    // the tool's spring alone, a base adopted onto the own tool (its spring loaded) would make a
    // replay that throws the object off it look free, and the same joules would be granted again
    // at every adoption (`stack.toml`, 0 ms: a box kept sliding at 0.68 m/s, 1.1 m, out of reach).
    let spent = (energy(world, k, &out, tool) - energy(world, k, &base, tool))
        .max(stored_energy(world, k, &out) - stored_energy(world, k, &base));
    (out, clipped.max(0.0), spent.max(0.0))
}

/// The own user's tool as the spring it is on the object (the contact law's normal stiffness): a
/// correction that moves the object onto the tool loads that spring, and its release would count as
/// the user's work though the user did nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolSpring {
    /// Tool centre, world, m.
    pub pos: Vec3,
    /// Tool radius, m.
    pub radius_m: f64,
    /// Normal stiffness of the tool contact, N/m.
    pub stiffness_n_per_m: f64,
}

impl ToolSpring {
    /// ½ K d², d the tool's penetration into the object at `s`, J.
    pub fn energy(&self, world: &World, k: usize, s: &BodyState) -> f64 {
        let (dist, _) = world.bodies[k]
            .shape
            .signed_distance(s.rot.inverse() * (self.pos - s.pos));
        let d = (self.radius_m - dist).max(0.0);
        0.5 * self.stiffness_n_per_m * d * d
    }
}

/// [`stored_energy`] plus the own tool's spring, if known, J.
fn energy(world: &World, k: usize, s: &BodyState, tool: Option<&ToolSpring>) -> f64 {
    stored_energy(world, k, s) + tool.map_or(0.0, |t| t.energy(world, k, s))
}

/// `base` moved the fraction `s` of the way to `full` (position, velocity and angular momentum
/// linearly, orientation normalised-linearly).
pub fn blend(base: &BodyState, full: &BodyState, s: f64) -> BodyState {
    BodyState {
        pos: base.pos + (full.pos - base.pos) * s,
        vel: base.vel + (full.vel - base.vel) * s,
        ang_mom: base.ang_mom + (full.ang_mom - base.ang_mom) * s,
        rot: base.rot.nlerp(&full.rot, s),
    }
}

/// Bisection steps of [`bound_gain`]: the fraction is found to 2⁻³⁰.
const BISECTIONS: u32 = 30;

/// The correction `base → full` bounded so the energy gained over `base` is at most `budget_j`
/// (negative budgets count as 0), counted with the own tool's spring and without it (the object's
/// own: the spring at `base` cannot pay for the object's motion): `None` when `full` already fits
/// (it is then used as it is, to the bit), else the largest fraction of it that fits and the
/// energy the bound removed, J.
///
/// `base` always fits (it is the fraction 0), so the result exists; a `full` that is not finite
/// gives `base`. Deterministic: a fixed number of bisection steps of plain arithmetic.
pub fn bound_gain(
    world: &World,
    k: usize,
    base: &BodyState,
    full: &BodyState,
    budget_j: f64,
    tool: Option<&ToolSpring>,
) -> Option<(BodyState, f64)> {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    let budget = budget_j.max(0.0);
    let limit = energy(world, k, base, tool) + budget;
    // The object's own energy may not grow beyond the budget either: the tool's spring at `base`
    // is where the correction put the object against the tool, not energy the object has (a
    // sender's state adopted onto a squeezing tool would otherwise fund a throw with it).
    let limit_object = stored_energy(world, k, base) + budget;
    let fits = |s: &BodyState| {
        let object = stored_energy(world, k, s);
        object <= limit_object && object + tool.map_or(0.0, |t| t.energy(world, k, s)) <= limit
    };
    if fits(full) {
        return None;
    }
    if !full.is_finite() {
        return Some((*base, f64::INFINITY));
    }
    let e_full = energy(world, k, full, tool);
    let bounded = scale_back(base, full, fits);
    Some((bounded, e_full - energy(world, k, &bounded, tool)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::Vec3;
    use crate::contact::{ContactParams, Plane};
    use crate::shape::Shape;

    fn world() -> World {
        let shape = Shape::Sphere { radius: 0.05 };
        let planes = [
            Plane {
                normal: Vec3::z(),
                offset: 0.0,
            },
            Plane {
                normal: Vec3::x(),
                offset: -0.25,
            },
        ];
        World::new(
            &[crate::world::Body::solid(shape, 0.1)],
            Vec3::new(0.0, 0.0, -3.27),
            &planes,
            ContactParams {
                stiffness_n_per_m: 3000.0,
                damping_n_s_per_m: 30.0,
                tangential_stiffness_n_per_m: 3000.0,
                tangential_damping_n_s_per_m: 15.0,
                friction_static: 0.35,
                friction_kinetic: 0.3,
                rotational_friction_radius_m: 0.0,
            },
        )
    }

    /// A state inside a wall holds the wall's spring energy; moving there is a gain.
    #[test]
    fn a_wall_penetration_stores_its_spring_energy() {
        let w = world();
        let out = BodyState::at_rest(Vec3::new(0.0, 0.0, 0.05));
        let inside = BodyState::at_rest(Vec3::new(-0.30, 0.0, 0.05));
        let de = stored_energy(&w, 0, &inside) - stored_energy(&w, 0, &out);
        assert!((de - 0.5 * 3000.0 * 0.1 * 0.1).abs() < 1e-9, "{de}");
    }

    /// A correction whose base puts the object deep onto the own tool (a sender's state adopted
    /// against a squeezing tool) may not spend that spring on the object: a throw out of the grasp
    /// is bounded to the budget. `paper` on `lift.toml` at 300 ms flung a lifted disk 19 cm up
    /// that way (54 mJ beyond the users' work).
    #[test]
    fn the_tools_spring_at_the_base_does_not_fund_the_object() {
        let w = world();
        let tool = ToolSpring {
            pos: Vec3::new(0.0, 0.0, 0.2),
            radius_m: 0.005,
            stiffness_n_per_m: 800.0,
        };
        // 25 mm onto the tool (0.25 J in its spring), at rest in the air.
        let base = BodyState::at_rest(Vec3::new(0.03, 0.0, 0.2));
        // Off the tool, thrown up at 1 m/s (50 mJ).
        let full = BodyState {
            vel: Vec3::new(0.0, 0.0, 1.0),
            ..BodyState::at_rest(Vec3::new(0.08, 0.0, 0.2))
        };
        assert!(energy(&w, 0, &full, Some(&tool)) < energy(&w, 0, &base, Some(&tool)));
        let budget = 1e-3;
        let (out, removed) = bound_gain(&w, 0, &base, &full, budget, Some(&tool)).expect("bounded");
        assert!(stored_energy(&w, 0, &out) <= stored_energy(&w, 0, &base) + budget + 1e-9);
        assert!(removed > 0.0 || stored_energy(&w, 0, &out) < stored_energy(&w, 0, &full));
    }

    /// Within the budget a correction is left alone; beyond it, it is scaled to the budget exactly
    /// (to the bisection's precision) and what it would have added beyond is reported.
    #[test]
    fn a_correction_beyond_its_budget_is_scaled_to_it() {
        let w = world();
        let base = BodyState::at_rest(Vec3::new(0.0, 0.0, 0.05));
        let full = BodyState {
            vel: Vec3::new(3.0, 0.0, 0.0),
            ..base
        };
        // ½ m v² = 0.45 J.
        assert!(bound_gain(&w, 0, &base, &full, 0.5, None).is_none());
        let (s, clipped) = bound_gain(&w, 0, &base, &full, 0.05, None).expect("bounded");
        let gained = stored_energy(&w, 0, &s) - stored_energy(&w, 0, &base);
        assert!(gained <= 0.05 && gained > 0.05 - 1e-6, "{gained}");
        assert!((clipped - (0.45 - gained)).abs() < 1e-9, "{clipped}");
        assert!(s.vel.x > 0.0 && s.vel.x < 3.0, "{:?}", s.vel);
        // No budget: the base.
        let (s, _) = bound_gain(&w, 0, &base, &full, -1.0, None).expect("bounded");
        assert!(s.vel.norm() < 1e-8, "{:?}", s.vel);
    }
}
