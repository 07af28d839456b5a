//! An object on the environment's planes (floor, walls), at each of its shape's probe points.

use nalgebra::UnitQuaternion;

use crate::body::{BodyState, MassProps, Vec3, Wrench};
use crate::shape::Shape;

use super::{across, friction, twist, ContactParams};

/// A flat environment surface: points x with `normal · x ≥ offset` are free space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Unit normal pointing into free space.
    pub normal: Vec3,
    /// Offset along the normal, m.
    pub offset: f64,
}

/// Most environment planes a scene may have.
pub const MAX_PLANES: usize = 6;

/// Friction memory of the environment contacts: one world stick point per plane, and with
/// rotational friction a reference direction per plane, in the world and on the body.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnvContactState {
    anchors: [Option<Vec3>; MAX_PLANES],
    twist: [Option<(Vec3, Vec3)>; MAX_PLANES],
}

impl EnvContactState {
    /// Moves every stick point by `delta` and turns every rotational friction reference by `turn`:
    /// when a copy adopts another pose (moved by `delta`, turned by `turn`), its contacts' memory
    /// must move with the object, or the friction springs would drag it back to where it was.
    pub fn shift(&mut self, delta: Vec3, turn: UnitQuaternion<f64>) {
        for a in self.anchors.iter_mut().flatten() {
            *a += delta;
        }
        for (world_ref, _) in self.twist.iter_mut().flatten() {
            *world_ref = turn * *world_ref;
        }
    }

    /// The stick points, per plane (`None`: not touching): what a snapshot carries.
    pub fn anchors(&self) -> [Option<Vec3>; MAX_PLANES] {
        self.anchors
    }

    /// The memory with these stick points (from a snapshot; no rotational friction memory).
    pub fn from_anchors(anchors: [Option<Vec3>; MAX_PLANES]) -> Self {
        Self::from_parts(anchors, [None; MAX_PLANES])
    }

    /// The rotational friction memory, per plane: a reference direction in the world and on the
    /// body (`None`: none kept): what a snapshot carries besides the stick points.
    pub fn twists(&self) -> [Option<(Vec3, Vec3)>; MAX_PLANES] {
        self.twist
    }

    /// The memory of these stick points and rotational references (from a snapshot).
    pub fn from_parts(
        anchors: [Option<Vec3>; MAX_PLANES],
        twist: [Option<(Vec3, Vec3)>; MAX_PLANES],
    ) -> Self {
        Self { anchors, twist }
    }
}

/// The environment's wrench on the object (J_eᵀ F_e), updating the friction memory. Returns the
/// wrench and whether any plane touches.
///
/// Per plane, Eq. 7 as the paper states it: the normal force is K times the *deepest* penetration,
/// and it acts at the centre of pressure of the shape's touching probe points (weighted by their
/// depth). A flat face resting on a floor is thus one contact of stiffness K, not one spring per
/// corner, and does not rock between corners.
pub fn environment_wrench(
    c: &ContactParams,
    state: &mut EnvContactState,
    planes: &[Plane],
    shape: &Shape,
    body: &BodyState,
    mass: &MassProps,
) -> (Wrench, bool) {
    let mut total = Wrench::default();
    let mut touching = false;
    // Invariants of this evaluation, computed once for every plane: the probe points in the world and
    // the body's angular velocity (the world inertia is a 3x3 product per call).
    let mut world_probes = [Vec3::zeros(); 16];
    let count = shape.probe_points(&mut world_probes);
    let r = body.rot.to_rotation_matrix();
    for p in world_probes.iter_mut().take(count) {
        *p = body.pos + r * *p;
    }
    let omega = body.omega(mass);
    let velocity_at = |q: Vec3| body.vel + omega.cross(&(q - body.pos));
    let spin_of = |n: Vec3| omega.dot(&n);
    for ((plane, anchor), twist_memory) in planes
        .iter()
        .zip(state.anchors.iter_mut())
        .zip(state.twist.iter_mut())
        .take(MAX_PLANES)
    {
        let n = plane.normal;
        let (mut deepest, mut weight, mut centre) = (0.0f64, 0.0, Vec3::zeros());
        let mut touching_points = [Vec3::zeros(); 16];
        let mut n_touch = 0usize;
        let mut probe = |p: Vec3| {
            let depth = plane.offset - n.dot(&p);
            if depth > 0.0 {
                deepest = deepest.max(depth);
                weight += depth;
                centre += p * depth;
                touching_points[n_touch.min(15)] = p;
                n_touch += 1;
            }
        };
        if let Shape::Sphere { radius } = *shape {
            probe(body.pos - n * radius);
        } else {
            for p in world_probes.iter().take(count) {
                probe(*p);
            }
        }
        if deepest <= 0.0 {
            *anchor = None;
            *twist_memory = None;
            continue;
        }
        touching = true;
        let p = centre / weight;
        // Stiffness: K times the deepest penetration at the centre of pressure. Damping: shared by the
        // touching points, each resisting its own normal velocity, so rocking is damped as well as
        // bouncing (for pure translation it is exactly −B ṙ_n).
        let f_spring = c.stiffness_n_per_m * deepest;
        let share = c.damping_n_s_per_m / n_touch as f64;
        let mut damping = Wrench::default();
        let mut f_damp_total = 0.0;
        for q in &touching_points[..n_touch.min(16)] {
            let f = -share * velocity_at(*q).dot(&n);
            f_damp_total += f;
            damping = damping + Wrench::at_point(n * f, *q, body.pos);
        }
        // Never pulling: limit the damping so the total normal force stays >= 0.
        let scale = if f_spring + f_damp_total < 0.0 && f_damp_total < 0.0 {
            -f_spring / f_damp_total
        } else {
            1.0
        };
        let f_n = f_spring + f_damp_total * scale;
        // Friction acts at the centre of the touching patch (unweighted): for a flat face that is its
        // centre whatever the micro-tilt, so a spinning disk's spin does not leak into translation.
        let patch =
            touching_points[..n_touch.min(16)].iter().sum::<Vec3>() / n_touch.min(16) as f64;
        let v = velocity_at(patch);
        let a = anchor.unwrap_or(patch);
        let (f_t, slipped, stretch) = friction(c, a, patch, -v, n, f_n);
        *anchor = Some(if slipped { patch + stretch } else { a });
        let mut turning = Wrench::default();
        if c.rotational_friction_radius_m > 0.0 {
            let (world_ref, body_ref) = twist_memory.unwrap_or_else(|| {
                let t = across(n);
                (t, body.rot.inverse() * t)
            });
            let (torque, slipped_ref) =
                twist(c, world_ref, body.rot * body_ref, -spin_of(n), n, f_n);
            *twist_memory = Some((slipped_ref.unwrap_or(world_ref), body_ref));
            turning.torque = n * torque;
        }
        total = total
            + Wrench::at_point(n * f_spring, p, body.pos)
            + Wrench::at_point(f_t, patch, body.pos)
            + Wrench {
                force: damping.force * scale,
                torque: damping.torque * scale,
            };
        if c.rotational_friction_radius_m > 0.0 {
            total = total + turning;
        }
    }
    (total, touching)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::step;
    use crate::contact::tests::{disk, params};

    /// An adoption that turns the copy turns its rotational friction memory with it: the twist
    /// spring is as stretched after as before (none), where memory left behind would pull the
    /// copy back towards its old orientation.
    #[test]
    fn an_adopted_turn_carries_the_twist_memory_along() {
        let law = ContactParams {
            rotational_friction_radius_m: 0.02,
            ..params()
        };
        let (shape, mass) = disk();
        let plane = [Plane {
            normal: Vec3::z(),
            offset: 0.0,
        }];
        let resting = BodyState::at_rest(Vec3::new(0.0, 0.0, 0.0099));
        let mut memory = EnvContactState::default();
        let (before, _) = environment_wrench(&law, &mut memory, &plane, &shape, &resting, &mass);
        let turn = UnitQuaternion::from_axis_angle(&Vec3::z_axis(), 0.5);
        let turned = BodyState {
            rot: turn * resting.rot,
            ..resting
        };
        let torque_after = |memory: &mut EnvContactState| {
            environment_wrench(&law, memory, &plane, &shape, &turned, &mass)
                .0
                .torque
                .z
        };
        let (mut carried, mut left) = (memory, memory);
        carried.shift(Vec3::zeros(), turn);
        left.shift(Vec3::zeros(), UnitQuaternion::identity());
        assert!((torque_after(&mut carried) - before.torque.z).abs() < 1e-12);
        assert!(
            torque_after(&mut left).abs() > 1e-3,
            "left behind, it pulls back"
        );
    }

    /// A disk resting on a floor under g/3 settles with penetration weight / K, to 1 %.
    #[test]
    fn penetration_at_equilibrium_is_weight_over_k() {
        let (shape, m) = disk();
        let c = params();
        let g = Vec3::new(0.0, -9.81 / 3.0, 0.0);
        let floor = [Plane {
            normal: Vec3::y(),
            offset: 0.0,
        }];
        let mut env = EnvContactState::default();
        let mut s = BodyState::at_rest(Vec3::new(0.0, 0.041, 0.0));
        for _ in 0..5000 {
            s = step(&s, &m, g, 1e-3, |b| {
                environment_wrench(&c, &mut env, &floor, &shape, b, &m).0
            });
        }
        // The rim touches with two probe points at the bottom (angle 270° on both caps).
        let depth = -(s.pos.y - 0.04);
        let expected = m.mass_kg * 9.81 / 3.0 / c.stiffness_n_per_m;
        assert!(
            (depth - expected).abs() / expected < 0.01,
            "depth {depth} vs {expected}"
        );
        assert!(s.vel.norm() < 1e-6);
    }
}
