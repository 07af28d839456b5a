//! The world every site shares: its object, gravity and the environment's planes, and the
//! geometry of the object against those planes that every method and the servo agree on.

use crate::body::{self, BodyState, HalfStep, MassProps, Vec3, Wrench};
use crate::contact::{
    environment_wrench, pair_wrench, ContactParams, EnvContactState, PairContactState, PairSide,
    Plane, MAX_PLANES,
};
use crate::shape::Shape;

/// Most sites a session may have.
pub const MAX_SITES: usize = 8;

/// The static world every site shares: the object's shape and mass, gravity, environment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct World {
    /// Object shape.
    pub shape: Shape,
    /// Object mass properties.
    pub mass: MassProps,
    /// Gravity, m/s².
    pub gravity: Vec3,
    /// Environment planes (first `plane_count` are used).
    pub planes: [Plane; MAX_PLANES],
    /// How many planes.
    pub plane_count: usize,
    /// Object–environment contact law.
    pub env_contact: ContactParams,
}

impl World {
    /// The planes in use.
    pub fn planes(&self) -> &[Plane] {
        &self.planes[..self.plane_count.min(MAX_PLANES)]
    }
}

/// Deepest penetration of `s` into `plane` (negative when clear of it).
pub fn plane_depth(world: &World, plane: &Plane, s: &BodyState) -> f64 {
    let n = plane.normal;
    match world.shape {
        Shape::Sphere { radius } => plane.offset - n.dot(&(s.pos - n * radius)),
        _ => {
            let mut probes = [Vec3::zeros(); 16];
            let count = world.shape.probe_points(&mut probes);
            // The plane normal in body coordinates: one rotation instead of one per probe point.
            let n_body = s.rot.inverse() * n;
            let centre = plane.offset - n.dot(&s.pos);
            probes[..count]
                .iter()
                .map(|p| centre - n_body.dot(p))
                .fold(f64::NEG_INFINITY, f64::max)
        }
    }
}

/// Gravity less what the environment planes the object rests on support: what a dead reckoner should
/// extrapolate with. Zero for a disk on a table, g in free flight, the slope component on an incline.
/// (The environment's *instantaneous* force is not used: on a stiff contact it oscillates around the
/// support, and extrapolating a spring's peak over tens of milliseconds kicks the receiver's copy.)
pub fn supported_gravity(world: &World, s: &BodyState) -> Vec3 {
    let mut a = world.gravity;
    for plane in world.planes() {
        if plane_depth(world, plane, s) > -1e-4 {
            let into = a.dot(&plane.normal);
            if into < 0.0 {
                a -= plane.normal * into;
            }
        }
    }
    a
}

/// Moves `s` out of any plane it penetrates and removes its velocity into that plane.
pub fn push_out_of_environment(world: &World, s: &mut BodyState) {
    for plane in world.planes() {
        let depth = plane_depth(world, plane, s);
        if depth > 0.0 {
            let n = plane.normal;
            s.pos += n * depth;
            let into = s.vel.dot(&n);
            if into < 0.0 {
                s.vel -= n * into;
            }
        }
    }
}

/// Most objects a world may have: every table of per-object and per-pair state is this long, so
/// stepping a world allocates nothing.
pub const MAX_OBJECTS: usize = 16;

/// Object pairs in a world of [`MAX_OBJECTS`].
pub const MAX_PAIRS: usize = MAX_OBJECTS * (MAX_OBJECTS - 1) / 2;

/// One object of a world: its shape, its mass, and whether it is a fixture (it does not move; it
/// still touches the others).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    /// Shape.
    pub shape: Shape,
    /// Mass properties.
    pub mass: MassProps,
    /// A fixture: never moved.
    pub fixed: bool,
}

impl Body {
    /// A movable solid of uniform density: `shape`, `mass_kg`.
    pub fn solid(shape: Shape, mass_kg: f64) -> Self {
        Self {
            shape,
            mass: MassProps {
                mass_kg,
                inertia_body: shape.inertia(mass_kg),
            },
            fixed: false,
        }
    }
}

/// `count` (at most [`MAX_OBJECTS`]) cubes of half size `half_m` and `mass_kg` set down on a
/// table through the origin (normal +z) in a heap: rows of four, two rows to a layer, 0.5 mm
/// apart, each layer resting on the one below (0.1 mm into it, as into the table); the rest of
/// the arrays such cubes at the origin. The scene the physics benchmark times and the allocation
/// and sleeping tests step.
pub fn cube_heap(
    count: usize,
    half_m: f64,
    mass_kg: f64,
) -> ([Body; MAX_OBJECTS], [BodyState; MAX_OBJECTS]) {
    let cube = Body::solid(
        Shape::Box {
            half: Vec3::repeat(half_m),
        },
        mass_kg,
    );
    let (pitch, layer) = (2.0 * half_m + 5e-4, 2.0 * half_m - 1e-4);
    let states = std::array::from_fn(|k| {
        if k >= count {
            return BodyState::at_rest(Vec3::zeros());
        }
        let (x, y, z) = (k % 4, k / 4 % 2, k / 8);
        BodyState::at_rest(Vec3::new(
            x as f64 * pitch,
            y as f64 * pitch,
            half_m - 1e-4 + z as f64 * layer,
        ))
    });
    ([cube; MAX_OBJECTS], states)
}

/// Where the pair of objects `i < j` keeps its friction memory among a world's [`MAX_PAIRS`]:
/// pairs in the order (0, 1), (0, 2), …, (1, 2), … — the order every site steps them in.
pub fn pair_index(i: usize, j: usize) -> usize {
    debug_assert!(i < j && j < MAX_OBJECTS);
    i * (2 * MAX_OBJECTS - i - 1) / 2 + (j - i - 1)
}

/// The memory of a world's contacts: the friction memory of every contact between the objects and
/// with the environment, and how long each object has been still (whether it sleeps). Part of the
/// world's state: a rollback restores it with the bodies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contacts {
    /// Per object, its contacts with the planes.
    pub env: [EnvContactState; MAX_OBJECTS],
    /// Per pair ([`pair_index`]), their contact.
    pub pairs: [PairContactState; MAX_PAIRS],
    /// Per object, the steps in a row it has been still ([`STILL_SPEED_M_PER_S`],
    /// [`STILL_SPIN_RAD_PER_S`]); at [`Physics::sleep_after_steps`] it sleeps.
    pub still: [u32; MAX_OBJECTS],
}

impl Default for Contacts {
    fn default() -> Self {
        Self {
            env: [EnvContactState::default(); MAX_OBJECTS],
            pairs: [PairContactState::default(); MAX_PAIRS],
            still: [0; MAX_OBJECTS],
        }
    }
}

/// An object slower than this, m/s...
pub const STILL_SPEED_M_PER_S: f64 = 1e-5;
/// ...and turning slower than this, rad/s, is still.
pub const STILL_SPIN_RAD_PER_S: f64 = 1e-3;
/// Steps an object must be still before it sleeps, by default (0.1 s at 1 kHz).
pub const SLEEP_AFTER_STEPS: u32 = 100;

/// The laws and fields several objects step under.
#[derive(Debug, Clone, Copy)]
pub struct Physics<'a> {
    /// Gravity, m/s².
    pub gravity: Vec3,
    /// The environment's planes.
    pub planes: &'a [Plane],
    /// Object–environment contact law.
    pub env_contact: &'a ContactParams,
    /// Object–object contact law.
    pub object_contact: &'a ContactParams,
    /// An object still for this many steps in a row sleeps: it is not stepped, nor its contacts
    /// with the planes or with other sleepers evaluated, until a wrench is applied to it or an
    /// object that moved touches it (0: nothing sleeps). A resting stack costs nothing then.
    pub sleep_after_steps: u32,
}

impl<'a> Physics<'a> {
    /// One contact law for the environment and between the objects.
    pub fn uniform(gravity: Vec3, planes: &'a [Plane], law: &'a ContactParams) -> Self {
        Self {
            gravity,
            planes,
            env_contact: law,
            object_contact: law,
            sleep_after_steps: SLEEP_AFTER_STEPS,
        }
    }
}

/// Every object's applied wrench at the poses `states`: the environment's on each object in
/// object order, then each pair's in [`pair_index`] order, then `applied` (the tools', held over
/// the step). The order is fixed, so every site sums the same floating-point terms in the same
/// order and gets the same bits.
fn wrenches(
    physics: &Physics<'_>,
    bodies: &[Body],
    states: &[BodyState],
    frozen: &[bool; MAX_OBJECTS],
    contacts: &mut Contacts,
    applied: &[Wrench],
    out: &mut [Wrench; MAX_OBJECTS],
) {
    let n = bodies.len().min(MAX_OBJECTS);
    for (k, w) in out.iter_mut().enumerate().take(n) {
        *w = if frozen[k] {
            Wrench::default()
        } else {
            environment_wrench(
                physics.env_contact,
                &mut contacts.env[k],
                physics.planes,
                &bodies[k].shape,
                &states[k],
                &bodies[k].mass,
            )
            .0
        };
    }
    for i in 0..n {
        for j in i + 1..n {
            let memory = &mut contacts.pairs[pair_index(i, j)];
            if bodies[i].fixed && bodies[j].fixed {
                *memory = PairContactState::default();
                continue;
            }
            if frozen[i] && frozen[j] {
                continue; // two sleepers (or a sleeper on a fixture): their contact as it was
            }
            let side = |k: usize| PairSide {
                shape: &bodies[k].shape,
                body: &states[k],
                mass: &bodies[k].mass,
            };
            let (on_i, on_j, _) = pair_wrench(physics.object_contact, memory, side(i), side(j));
            out[i] = out[i] + on_i;
            out[j] = out[j] + on_j;
        }
    }
    for (w, a) in out.iter_mut().zip(applied).take(n) {
        *w = *w + *a;
    }
}

/// Steps `states` (one per body of `bodies`) by `dt` together: velocity Verlet ([`body::step`])
/// with every object's wrench evaluated at every object's start poses, every object drifted, and
/// every wrench evaluated again at the end poses, so a contact between two objects acts on both
/// from the same poses. Fixtures do not move. `applied` adds a wrench per object (a tool's,
/// held over the step). Allocates nothing.
pub fn step_objects(
    physics: &Physics<'_>,
    bodies: &[Body],
    states: &mut [BodyState],
    contacts: &mut Contacts,
    applied: &[Wrench],
    dt: f64,
) {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    let n = bodies.len().min(states.len()).min(MAX_OBJECTS);
    let bodies = &bodies[..n];
    let frozen = sleepers(physics, bodies, contacts, applied);
    let mut w = [Wrench::default(); MAX_OBJECTS];
    let mut half = [HalfStep::default(); MAX_OBJECTS];
    let evaluate =
        |states: &[BodyState], contacts: &mut Contacts, w: &mut [Wrench; MAX_OBJECTS]| {
            wrenches(physics, bodies, states, &frozen, contacts, applied, w);
        };
    evaluate(&states[..n], contacts, &mut w);
    for k in (0..n).filter(|&k| !frozen[k]) {
        (states[k], half[k]) =
            body::kick_drift(&states[k], &bodies[k].mass, physics.gravity, dt, &w[k]);
    }
    evaluate(&states[..n], contacts, &mut w);
    for k in (0..n).filter(|&k| !frozen[k]) {
        body::kick(
            &mut states[k],
            &bodies[k].mass,
            physics.gravity,
            dt,
            &half[k],
            &w[k],
        );
        let still = states[k].vel.norm() < STILL_SPEED_M_PER_S
            && states[k].omega(&bodies[k].mass).norm() < STILL_SPIN_RAD_PER_S;
        contacts.still[k] = if still {
            contacts.still[k].saturating_add(1)
        } else {
            0
        };
    }
}

/// Which objects do not move this step: the fixtures and the sleepers. An object sleeps once it
/// has been still for `physics.sleep_after_steps` steps. A wrench applied to it wakes it and its
/// count starts again; an awake object touching it (as the contact memory of the last step has
/// it) wakes it until it has been still for one step again: a row pushed at one end wakes down
/// the row, a box set down on a sleeping one wakes it until both rest, and a resting stack falls
/// asleep when its last member has been still long enough. A sleeper newly touched holds like a
/// fixture for that one step (its reaction is not applied to it). Every site decides the same
/// from the same state.
fn sleepers(
    physics: &Physics<'_>,
    bodies: &[Body],
    contacts: &mut Contacts,
    applied: &[Wrench],
) -> [bool; MAX_OBJECTS] {
    let n = bodies.len();
    let after = physics.sleep_after_steps;
    for (still, a) in contacts.still.iter_mut().zip(applied).take(n) {
        if *a != Wrench::default() {
            *still = 0;
        }
    }
    for i in 0..n {
        for j in i + 1..n {
            if !contacts.pairs[pair_index(i, j)].touching() {
                continue;
            }
            let moved = |k: usize| !bodies[k].fixed && contacts.still[k] < after;
            let (wake_i, wake_j) = (moved(j), moved(i));
            if wake_i {
                contacts.still[i] = contacts.still[i].min(after.saturating_sub(1));
            }
            if wake_j {
                contacts.still[j] = contacts.still[j].min(after.saturating_sub(1));
            }
        }
    }
    std::array::from_fn(|k| k < n && (bodies[k].fixed || (after > 0 && contacts.still[k] >= after)))
}

/// Worlds for the model's unit tests.
#[cfg(test)]
pub(crate) mod fixtures {
    use super::*;

    /// The paper's disk over a plane 0.1 m below the origin, `y` up, at a third of g.
    pub(crate) fn world() -> World {
        let shape = Shape::Cylinder {
            radius: 0.04,
            half_height: 0.01,
        };
        let mut planes = [Plane {
            normal: Vec3::y(),
            offset: 0.0,
        }; MAX_PLANES];
        planes[0] = Plane {
            normal: Vec3::y(),
            offset: -0.1,
        };
        World {
            shape,
            mass: MassProps {
                mass_kg: 0.1,
                inertia_body: shape.inertia(0.1),
            },
            gravity: Vec3::new(0.0, -9.81 / 3.0, 0.0),
            planes,
            plane_count: 1,
            env_contact: crate::contact::tests::params(),
        }
    }

    /// [`world`] with its plane through the origin (a table, `y` up), and the disk resting on it
    /// (within the support's band) moving at `vel`.
    pub(crate) fn on_a_table(vel: Vec3) -> (World, BodyState) {
        let mut w = world();
        w.planes[0] = Plane {
            normal: Vec3::y(),
            offset: 0.0,
        };
        let s = BodyState {
            vel,
            ..BodyState::at_rest(Vec3::new(0.0, 0.0399, 0.0))
        };
        (w, s)
    }
}
