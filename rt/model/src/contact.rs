//! Penalty contact (Eq. 7) with damping and Coulomb friction with stick and slip.
//!
//! Normal force: F_n = K Δr − B ṙ_n (never pulling): Δr is the penetration at the point of deepest
//! penetration, ṙ_n the rate at which it grows. Friction follows the stick-point approach the paper
//! adopts from Yoshikawa et al. (1995): when a contact starts, its two surface points are stuck
//! together by a stiff tangential spring; while the spring force stays inside the static friction cone
//! (|F_t| ≤ μ_s F_n) the contact sticks, and when it leaves it the contact slips, the stick point is
//! dragged along so that |F_t| = μ_k F_n. The object's environment (floor, walls) uses the same law at
//! each of the shape's probe points.
//!
//! The law and what its three kinds of contact share sit here; each kind has its module: `tool` (a
//! user's tool on an object), `env` (an object on the environment's planes), `pair` (two objects).

use crate::body::{Vec3, Wrench};

mod env;
mod pair;
mod tool;

pub use env::{environment_wrench, EnvContactState, Plane, MAX_PLANES};
pub use pair::{pair_depth, pair_wrench, PairContactState, PairSide};
pub use tool::{tool_contact, ToolContactState};

/// Contact law parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct ContactParams {
    /// Normal stiffness K, N/m.
    pub stiffness_n_per_m: f64,
    /// Normal damping B, N·s/m.
    pub damping_n_s_per_m: f64,
    /// Tangential (stick) stiffness, N/m.
    pub tangential_stiffness_n_per_m: f64,
    /// Tangential damping while sticking, N·s/m.
    pub tangential_damping_n_s_per_m: f64,
    /// Static friction coefficient μ_s.
    pub friction_static: f64,
    /// Kinetic friction coefficient μ_k (≤ μ_s).
    pub friction_kinetic: f64,
    /// Rotational friction: the radius of the contact patch over which friction resists turning
    /// about the contact normal, m. The patch sticks by a torsional spring of the tangential
    /// stiffness and damping times r², and slips at μ F_n r. 0 (the default): none, as the paper
    /// neglects it; an object that carries another off its centre needs it (else nothing holds it
    /// from turning under the load). In the tool's law (`[contact]`) it is the fingertip's pad:
    /// the tool does not turn, the object's turn about the normal is resisted, and the device
    /// displays the force, not this torque (3-DOF); two fingertips without it hold an object as
    /// on an axle through them.
    pub rotational_friction_radius_m: f64,
}

impl Default for ContactParams {
    /// A firm tool–object contact: 800 N/m, lightly damped, grippy (μ_s 0.8, μ_k 0.6).
    fn default() -> Self {
        Self {
            stiffness_n_per_m: 800.0,
            damping_n_s_per_m: 4.0,
            tangential_stiffness_n_per_m: 800.0,
            tangential_damping_n_s_per_m: 4.0,
            friction_static: 0.8,
            friction_kinetic: 0.6,
            rotational_friction_radius_m: 0.0,
        }
    }
}

/// The force one contact puts on the object.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ContactForce {
    /// Force on the object, world, N.
    pub force: Vec3,
    /// Where it acts, world.
    pub point: Vec3,
    /// Penetration depth, m (0 when not in contact).
    pub depth: f64,
    /// Whether the surfaces touch.
    pub touching: bool,
    /// Whether the friction slipped this evaluation.
    pub slipping: bool,
    /// A torque on the object besides the force's moment, world, N·m: a fingertip's rotational
    /// friction (a 3-DOF device displays the force, not this).
    pub torque: Vec3,
}

impl ContactForce {
    /// Its generalized force on an object whose centre of mass is at `com` (Eq. 3).
    pub fn wrench(&self, com: Vec3) -> Wrench {
        let w = Wrench::at_point(self.force, self.point, com);
        // (Without a pad, the moment is left as it was to the bit: not even a zero's sign moves.)
        if self.torque == Vec3::zeros() {
            return w;
        }
        Wrench {
            force: w.force,
            torque: w.torque + self.torque,
        }
    }
}

/// The tangential friction force on the object, given the other body's stick point `p_other`, the
/// object's stick point `p_obj`, their velocities, the unit normal `n` and the normal force `f_n`.
/// Returns (force, slipped, the tangential stretch the spring should have after a slip).
fn friction(
    c: &ContactParams,
    p_other: Vec3,
    p_obj: Vec3,
    v_rel: Vec3,
    n: Vec3,
    f_n: f64,
) -> (Vec3, bool, Vec3) {
    let tangential = |v: Vec3| v - n * v.dot(&n);
    let stretch = tangential(p_other - p_obj);
    let f_t = stretch * c.tangential_stiffness_n_per_m
        + tangential(v_rel) * c.tangential_damping_n_s_per_m;
    let limit = c.friction_static * f_n;
    if f_t.norm() <= limit {
        return (f_t, false, stretch);
    }
    let dir = if f_t.norm() > 1e-15 {
        f_t.normalize()
    } else {
        Vec3::zeros()
    };
    let slip_force = dir * (c.friction_kinetic * f_n);
    (
        slip_force,
        true,
        dir * (c.friction_kinetic * f_n / c.tangential_stiffness_n_per_m),
    )
}

/// A unit vector at right angles to the unit vector `n`, the same bits wherever it is computed:
/// along `n` × the world axis least aligned with `n`.
fn across(n: Vec3) -> Vec3 {
    let (x, y, z) = (n.x.abs(), n.y.abs(), n.z.abs());
    let axis = if x <= y && x <= z {
        Vec3::x()
    } else if y <= z {
        Vec3::y()
    } else {
        Vec3::z()
    };
    n.cross(&axis).normalize()
}

/// `t` in the plane at right angles to the unit `n`, unit length (`None`: `t` is along `n`).
fn in_plane(t: Vec3, n: Vec3) -> Option<Vec3> {
    let p = t - n * t.dot(&n);
    let len = p.norm();
    (len > 1e-9).then(|| p / len)
}

/// Rotational friction about the unit normal `n` ([`ContactParams::rotational_friction_radius_m`]):
/// the torque about `n` on the object whose reference direction is now `t_obj` (world), held by
/// its stick spring to the other body's reference `t_other` (world), with `spin` the other's
/// angular velocity about `n` less the object's and `f_n` the normal force. Returns the torque, N·m,
/// and the other's reference after a slip (the spring stretched to hold the kinetic torque), or
/// `None` while it sticks.
///
/// The spring's stretch is measured by 2 tan(θ/2) of the angle θ between the references, which
/// is θ for small angles and grows without bound towards half a turn: the spring holds any torque
/// up to the static limit (a sine would hold at most its stiffness, and past a quarter turn
/// less). Only `+ − × ÷ sqrt`: the same bits at every site.
fn twist(
    c: &ContactParams,
    t_other: Vec3,
    t_obj: Vec3,
    spin: f64,
    n: Vec3,
    f_n: f64,
) -> (f64, Option<Vec3>) {
    let r = c.rotational_friction_radius_m;
    let (Some(u), Some(v)) = (in_plane(t_other, n), in_plane(t_obj, n)) else {
        return (0.0, None);
    };
    let k = c.tangential_stiffness_n_per_m * r * r;
    // tan(θ/2) of the angle the object must turn about n to line up with the other's reference.
    let (sin, cos) = (v.cross(&u).dot(&n), v.dot(&u));
    let half_turned = 1.0 + cos <= 1e-12;
    let torque = if half_turned {
        f64::INFINITY.copysign(sin)
    } else {
        2.0 * k * sin / (1.0 + cos) + c.tangential_damping_n_s_per_m * r * r * spin
    };
    if torque.abs() <= c.friction_static * f_n * r {
        return (torque, None);
    }
    let slip = (c.friction_kinetic * f_n * r).copysign(if half_turned { sin } else { torque });
    // The other's reference turned so that the spring alone holds the slipping torque:
    // tan(θ/2) = slip / 2k.
    let t = slip / (2.0 * k);
    let (cos_new, sin_new) = ((1.0 - t * t) / (1.0 + t * t), 2.0 * t / (1.0 + t * t));
    (slip, Some(v * cos_new + n.cross(&v) * sin_new))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::body::MassProps;
    use crate::shape::Shape;

    /// A firm, damped law with grippy friction: the model's tests' table.
    pub(crate) fn params() -> ContactParams {
        ContactParams {
            stiffness_n_per_m: 2000.0,
            damping_n_s_per_m: 5.0,
            tangential_stiffness_n_per_m: 2000.0,
            tangential_damping_n_s_per_m: 5.0,
            friction_static: 0.6,
            friction_kinetic: 0.5,
            rotational_friction_radius_m: 0.0,
        }
    }

    pub(super) fn disk() -> (Shape, MassProps) {
        let s = Shape::Cylinder {
            radius: 0.04,
            half_height: 0.01,
        };
        (
            s,
            MassProps {
                mass_kg: 0.1,
                inertia_body: s.inertia(0.1),
            },
        )
    }
}
