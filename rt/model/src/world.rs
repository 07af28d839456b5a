//! The world every site shares: its objects, gravity, the environment's planes and the contact
//! laws, and the geometry of an object against those planes that every method and the servo
//! agree on. A site's copy of it, and the step that advances one, are [`crate::method::copy`]'s.

use crate::body::{BodyState, MassProps, Vec3};
use crate::contact::{ContactParams, Plane, MAX_PLANES};
use crate::shape::Shape;

/// Most sites a session may have.
pub const MAX_SITES: usize = 8;

/// The static world every site shares: its objects, gravity, the environment, the contact laws.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct World {
    /// The objects (the first [`World::object_count`]), in the order every site steps them.
    pub bodies: [Body; MAX_OBJECTS],
    /// How many objects (1 to [`MAX_OBJECTS`]).
    pub object_count: usize,
    /// Gravity, m/s².
    pub gravity: Vec3,
    /// Environment planes (first `plane_count` are used).
    pub planes: [Plane; MAX_PLANES],
    /// How many planes.
    pub plane_count: usize,
    /// Object–environment contact law.
    pub env_contact: ContactParams,
    /// Object–object contact law.
    pub object_contact: ContactParams,
    /// An object still for this many steps in a row sleeps: it is not stepped, nor its contacts
    /// with the planes or with other sleepers evaluated, until a wrench is applied to it or an
    /// object that moved touches it (0: nothing sleeps). A resting stack costs nothing then.
    pub sleep_after_steps: u32,
}

impl World {
    /// A world of the objects `bodies` (at most [`MAX_OBJECTS`]), gravity, the environment's
    /// `planes` (at most [`MAX_PLANES`]) and one contact law for the planes and between the
    /// objects. Objects sleep after [`SLEEP_AFTER_STEPS`] when there are several (one alone has
    /// nothing to save).
    pub fn new(bodies: &[Body], gravity: Vec3, planes: &[Plane], law: ContactParams) -> Self {
        let count = bodies.len().clamp(1, MAX_OBJECTS);
        let mut all = [bodies
            .first()
            .copied()
            .unwrap_or(Body::solid(Shape::Sphere { radius: 0.01 }, 0.1));
            MAX_OBJECTS];
        all[..count].copy_from_slice(&bodies[..count]);
        let mut p = [Plane {
            normal: Vec3::y(),
            offset: f64::NEG_INFINITY,
        }; MAX_PLANES];
        let plane_count = planes.len().min(MAX_PLANES);
        p[..plane_count].copy_from_slice(&planes[..plane_count]);
        Self {
            bodies: all,
            object_count: count,
            gravity,
            planes: p,
            plane_count,
            env_contact: law,
            object_contact: law,
            sleep_after_steps: if count > 1 { SLEEP_AFTER_STEPS } else { 0 },
        }
    }

    /// The planes in use.
    pub fn planes(&self) -> &[Plane] {
        &self.planes[..self.plane_count.min(MAX_PLANES)]
    }

    /// The objects.
    pub fn bodies(&self) -> &[Body] {
        &self.bodies[..self.object_count.clamp(1, MAX_OBJECTS)]
    }
}

/// Deepest penetration of `s` into `plane` (negative when clear of it).
pub fn plane_depth(shape: &Shape, plane: &Plane, s: &BodyState) -> f64 {
    let n = plane.normal;
    match *shape {
        Shape::Sphere { radius } => plane.offset - n.dot(&(s.pos - n * radius)),
        _ => {
            let mut probes = [Vec3::zeros(); 16];
            let count = shape.probe_points(&mut probes);
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
pub fn supported_gravity(world: &World, shape: &Shape, s: &BodyState) -> Vec3 {
    let mut a = world.gravity;
    for plane in world.planes() {
        if plane_depth(shape, plane, s) > -1e-4 {
            let into = a.dot(&plane.normal);
            if into < 0.0 {
                a -= plane.normal * into;
            }
        }
    }
    a
}

/// Moves `s` out of any plane it penetrates and removes its velocity into that plane.
pub fn push_out_of_environment(world: &World, shape: &Shape, s: &mut BodyState) {
    for plane in world.planes() {
        let depth = plane_depth(shape, plane, s);
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

/// Most objects a world may have: a world's copy is sized for its objects when made, and the
/// scratch tables of a step are this long, so stepping a world allocates nothing.
pub const MAX_OBJECTS: usize = 16;

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

/// Where the pair of objects `i < j` of a world of `n` keeps its friction memory: pairs in the
/// order (0, 1), (0, 2), …, (1, 2), … — the order every site steps them in.
pub fn pair_index(i: usize, j: usize, n: usize) -> usize {
    debug_assert!(i < j && j < n);
    i * (2 * n - i - 1) / 2 + (j - i - 1)
}

/// An object slower than this, m/s...
pub const STILL_SPEED_M_PER_S: f64 = 1e-5;
/// ...and turning slower than this, rad/s, is still.
pub const STILL_SPIN_RAD_PER_S: f64 = 1e-3;
/// Steps an object must be still before it sleeps, by default (0.1 s at 1 kHz).
pub const SLEEP_AFTER_STEPS: u32 = 100;

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
        World::new(
            &[Body::solid(shape, 0.1)],
            Vec3::new(0.0, -9.81 / 3.0, 0.0),
            &[Plane {
                normal: Vec3::y(),
                offset: -0.1,
            }],
            crate::contact::tests::params(),
        )
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
