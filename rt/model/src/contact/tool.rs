//! A user's tool (a sphere, or a fingertip pad with rotational friction) on an object.

use nalgebra::UnitQuaternion;

use crate::body::{BodyState, MassProps, Vec3};
use crate::shape::Shape;

use super::{across, friction, twist, ContactForce, ContactParams};

/// Friction memory of one tool contact: the stick point on the object, in body coordinates; with
/// rotational friction, a reference direction in the world (the tool does not turn) and on the
/// object.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ToolContactState {
    anchor_body: Option<Vec3>,
    twist: Option<(Vec3, Vec3)>,
}

impl ToolContactState {
    /// Whether the tool touched the object at its last contact computation.
    pub fn touching(&self) -> bool {
        self.anchor_body.is_some()
    }

    /// The stick point, body coordinates (`None`: not touching): what a snapshot carries.
    pub fn anchor(&self) -> Option<Vec3> {
        self.anchor_body
    }

    /// Turns the pad's world reference by `turn`: when a copy takes another pose (turned by
    /// `turn`), a pad's twist spring must not be stretched by the correction (the stick point,
    /// on the body, moves with it already).
    pub fn turn(&mut self, turn: UnitQuaternion<f64>) {
        if let Some((world_ref, _)) = self.twist.as_mut() {
            *world_ref = turn * *world_ref;
        }
    }

    /// The memory whose stick point is `anchor` (from a snapshot; no rotational friction memory).
    pub fn from_anchor(anchor: Option<Vec3>) -> Self {
        Self::from_parts(anchor, None)
    }

    /// The pad's rotational friction memory: its reference direction in the world and on the
    /// body (`None`: no pad, or not touching): what a snapshot carries besides the stick point.
    pub fn twist(&self) -> Option<(Vec3, Vec3)> {
        self.twist
    }

    /// The memory of a stick point and a pad's references (from a snapshot).
    pub fn from_parts(anchor: Option<Vec3>, twist: Option<(Vec3, Vec3)>) -> Self {
        Self {
            anchor_body: anchor,
            twist,
        }
    }
}

/// The contact between a spherical tool tip (centre `tool_pos`, radius `tool_radius`, velocity
/// `tool_vel`) and the object, updating the friction memory.
#[allow(clippy::too_many_arguments)]
pub fn tool_contact(
    c: &ContactParams,
    state: &mut ToolContactState,
    shape: &Shape,
    body: &BodyState,
    mass: &MassProps,
    tool_pos: Vec3,
    tool_vel: Vec3,
    tool_radius: f64,
) -> ContactForce {
    // A tip beyond the shape's bounding sphere cannot touch: the same answer as below, without
    // the rotation and the distance (in a world of many objects most tools are far from most).
    let reach = shape.bounding_radius() + tool_radius;
    if (tool_pos - body.pos).norm_squared() > reach * reach {
        *state = ToolContactState::default();
        return ContactForce::default();
    }
    let inv: UnitQuaternion<f64> = body.rot.inverse();
    let (dist, n_body) = shape.signed_distance(inv * (tool_pos - body.pos));
    let depth = tool_radius - dist;
    if depth <= 0.0 {
        *state = ToolContactState::default();
        return ContactForce::default();
    }
    let n_out = body.rot * n_body; // out of the object, towards the tool
    let surface = tool_pos - n_out * dist; // object surface point under the tool
    let tool_point = tool_pos - n_out * tool_radius; // the tool's deepest point
    let v_obj = body.point_velocity(mass, surface);
    let v_rel = tool_vel - v_obj;
    let push = -n_out; // direction the tool pushes the object
    let f_n = (c.stiffness_n_per_m * depth + c.damping_n_s_per_m * v_rel.dot(&push)).max(0.0);
    let anchor_w = state
        .anchor_body
        .map_or(tool_point, |a| body.pos + body.rot * a);
    let (f_t, slipped, stretch) = friction(c, tool_point, anchor_w, v_rel, push, f_n);
    let new_anchor = if slipped {
        tool_point - stretch
    } else {
        anchor_w
    };
    state.anchor_body = Some(inv * (new_anchor - body.pos));
    // A fingertip's pad resists turning about the normal as a patch does (the tool itself
    // does not turn): without it two fingertips hold an object on the line between them as on
    // an axle, and it swings about it.
    let mut torque = Vec3::zeros();
    if c.rotational_friction_radius_m > 0.0 {
        let (world_ref, body_ref) = state.twist.unwrap_or_else(|| {
            let t = across(push);
            (t, inv * t)
        });
        let spin = -body.omega(mass).dot(&push);
        let (t, slipped_ref) = twist(c, world_ref, body.rot * body_ref, spin, push, f_n);
        state.twist = Some((slipped_ref.unwrap_or(world_ref), body_ref));
        torque = push * t;
    }
    ContactForce {
        force: push * f_n + f_t,
        point: surface,
        depth,
        touching: true,
        slipping: slipped,
        torque,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{step, Wrench};
    use crate::contact::tests::{disk, params};

    /// Two fingertips squeezing a box from both ends hold it as on an axle through them: a box
    /// spun about that line spins on between point grips, and is held between two pads (their
    /// torsional springs take the spin and turn it back), each with at most its slip limit
    /// (μ_s F_n r) and about that line only.
    #[test]
    fn fingertip_pads_stop_a_turn_about_the_line_between_them() {
        let shape = Shape::Box {
            half: Vec3::new(0.03, 0.05, 0.01),
        };
        let mass = MassProps {
            mass_kg: 0.25,
            inertia_body: shape.inertia(0.25),
        };
        let spin_after = |r: f64| {
            let c = ContactParams {
                rotational_friction_radius_m: r,
                ..params()
            };
            let tips = [Vec3::new(-0.032, 0.0, 0.0), Vec3::new(0.032, 0.0, 0.0)];
            let mut memory = [ToolContactState::default(); 2];
            let mut s = BodyState::at_rest(Vec3::zeros());
            s.ang_mom = s.rot * mass.inertia_body.component_mul(&Vec3::new(2.0, 0.0, 0.0));
            let mut most = 0.0f64;
            for _ in 0..1000 {
                s = step(&s, &mass, Vec3::zeros(), 1e-3, |b| {
                    let mut w = Wrench::default();
                    for (tip, m) in tips.iter().zip(memory.iter_mut()) {
                        let f = tool_contact(&c, m, &shape, b, &mass, *tip, Vec3::zeros(), 0.005);
                        let n = f.force.dot(&(b.pos - *tip).normalize()).abs();
                        most = most.max(f.torque.norm() / (c.friction_static * n * r).max(1e-30));
                        assert!(f.torque.cross(&Vec3::x()).norm() <= 1e-9 + 0.05 * f.torque.norm());
                        w = w + f.wrench(b.pos);
                    }
                    w
                });
            }
            (s.rot.angle(), most)
        };
        let (point, _) = spin_after(0.0);
        let (pad, most) = spin_after(0.005);
        assert!(point > 1.5, "point grips: turned {point} rad");
        assert!(pad < 0.3, "pads: turned {pad} rad");
        assert!(most <= 1.0 + 1e-9, "torque {most} × its slip limit");
    }

    /// Two equal and opposite tool pushes on a free disk (no gravity) leave it at rest where it was.
    #[test]
    fn static_squeeze_leaves_the_object_at_rest() {
        let (shape, m) = disk();
        let c = params();
        let (mut left, mut right) = (ToolContactState::default(), ToolContactState::default());
        let mut s = BodyState::at_rest(Vec3::zeros());
        let r = 0.005;
        for _ in 0..3000 {
            s = step(&s, &m, Vec3::zeros(), 1e-3, |b| {
                let l = tool_contact(
                    &c,
                    &mut left,
                    &shape,
                    b,
                    &m,
                    Vec3::new(-0.044, 0.0, 0.0),
                    Vec3::zeros(),
                    r,
                );
                let rr = tool_contact(
                    &c,
                    &mut right,
                    &shape,
                    b,
                    &m,
                    Vec3::new(0.044, 0.0, 0.0),
                    Vec3::zeros(),
                    r,
                );
                assert!(l.touching && rr.touching);
                l.wrench(b.pos) + rr.wrench(b.pos)
            });
        }
        assert!(s.pos.norm() < 1e-12, "moved to {:?}", s.pos);
        assert!(s.vel.norm() < 1e-12);
    }

    /// Friction holds a squeezed disk against gravity when μ F_n exceeds the weight, and lets it slip
    /// when it does not.
    #[test]
    fn friction_sticks_inside_the_cone_and_slips_outside() {
        let (shape, m) = disk();
        let c = params();
        let g = Vec3::new(0.0, -9.81 / 3.0, 0.0);
        let run = |squeeze_m: f64| {
            let (mut a, mut b) = (ToolContactState::default(), ToolContactState::default());
            let mut s = BodyState::at_rest(Vec3::zeros());
            let x = 0.045 - squeeze_m;
            for _ in 0..2000 {
                s = step(&s, &m, g, 1e-3, |bd| {
                    let tool = |st: &mut ToolContactState, x: f64| {
                        tool_contact(
                            &c,
                            st,
                            &shape,
                            bd,
                            &m,
                            Vec3::new(x, 0.0, 0.0),
                            Vec3::zeros(),
                            0.005,
                        )
                        .wrench(bd.pos)
                    };
                    tool(&mut a, -x) + tool(&mut b, x)
                });
            }
            s.pos.y
        };
        // 1 mm squeeze: F_n = 2 N per side, 2·0.6·2 = 2.4 N ≫ 0.33 N weight: held within a mm.
        assert!(run(0.001) > -0.001);
        // 0.05 mm squeeze: F_n = 0.1 N, 2·0.5·0.1 = 0.1 N < weight: slides away.
        assert!(run(0.00005) < -0.05);
    }
}
