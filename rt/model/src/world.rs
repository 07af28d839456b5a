//! The world every site shares: its object, gravity and the environment's planes, and the
//! geometry of the object against those planes that every method and the servo agree on.

use crate::body::{BodyState, MassProps, Vec3};
use crate::contact::{ContactParams, Plane, MAX_PLANES};
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
            env_contact: ContactParams {
                stiffness_n_per_m: 2000.0,
                damping_n_s_per_m: 5.0,
                tangential_stiffness_n_per_m: 2000.0,
                tangential_damping_n_s_per_m: 5.0,
                friction_static: 0.6,
                friction_kinetic: 0.5,
            },
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
