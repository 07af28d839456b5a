//! Penalty contact (Eq. 7) with damping and Coulomb friction with stick and slip.
//!
//! Normal force: F_n = K Δr − B ṙ_n (never pulling): Δr is the penetration at the point of deepest
//! penetration, ṙ_n the rate at which it grows. Friction follows the stick-point approach the paper
//! adopts from Yoshikawa et al. (1995): when a contact starts, its two surface points are stuck
//! together by a stiff tangential spring; while the spring force stays inside the static friction cone
//! (|F_t| ≤ μ_s F_n) the contact sticks, and when it leaves it the contact slips, the stick point is
//! dragged along so that |F_t| = μ_k F_n. The object's environment (floor, walls) uses the same law at
//! each of the shape's probe points.

use nalgebra::UnitQuaternion;

use crate::body::{BodyState, MassProps, Vec3, Wrench};
use crate::shape::{Shape, MAX_CONTACT_POINTS};

/// Contact law parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize),
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

/// Friction memory of one object–object contact: its stick point on each of the two objects, in
/// that object's body coordinates (both move with their objects; the friction spring stretches
/// between them).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PairContactState {
    anchors: Option<(Vec3, Vec3)>,
    /// With rotational friction: a reference direction on each, body coordinates.
    twist: Option<(Vec3, Vec3)>,
}

impl PairContactState {
    /// Whether the two objects touched at the last contact computation.
    pub fn touching(&self) -> bool {
        self.anchors.is_some()
    }

    /// The stick points, on the first object and on the second, body coordinates (`None`: not
    /// touching): what a snapshot of the world would carry.
    pub fn anchors(&self) -> Option<(Vec3, Vec3)> {
        self.anchors
    }

    /// The rotational friction memory: a reference direction on each object, body coordinates.
    pub fn twist(&self) -> Option<(Vec3, Vec3)> {
        self.twist
    }

    /// The memory with these stick points and reference directions (from a snapshot).
    pub fn from_parts(anchors: Option<(Vec3, Vec3)>, twist: Option<(Vec3, Vec3)>) -> Self {
        Self { anchors, twist }
    }
}

/// One object of a contact pair: its shape, state and mass.
#[derive(Debug, Clone, Copy)]
pub struct PairSide<'a> {
    /// Shape.
    pub shape: &'a Shape,
    /// State.
    pub body: &'a BodyState,
    /// Mass properties.
    pub mass: &'a MassProps,
}

/// What the separating-axis test of two boxes found.
#[derive(Debug, Clone, Copy, PartialEq)]
// NB: returned by value on the physics path, where nothing allocates: the points are not boxed.
#[allow(clippy::large_enum_variant)]
enum BoxOverlap {
    /// An axis separates them: they do not touch.
    Apart,
    /// They overlap least along a face's normal: the other box's face most against it, clipped
    /// to that face's sides, its points below the face (`count` of `points`: point, normal
    /// pushing the first box away from the second, depth).
    Faces {
        /// Touching points.
        points: [(Vec3, Vec3, f64); 8],
        /// How many.
        count: usize,
    },
    /// They overlap least along the cross product of an edge of each (two edges crossing): the
    /// contact is at the middle of the edges' closest points, `normal` pushing the first box away
    /// from the second, `depth` the overlap along it.
    Edges {
        /// World point.
        point: Vec3,
        /// Unit normal, from the second box towards the first.
        normal: Vec3,
        /// Overlap, m.
        depth: f64,
    },
}

/// An edge axis wins only where it overlaps less than every face axis by this share: near a tie
/// the face contact is the one that rests (and the choice does not flicker step to step).
const EDGE_AXIS_MARGIN: f64 = 0.95;

/// The separating-axis test of two boxes (half extents `ha`, `hb`): their 3 + 3 face normals and
/// the 9 cross products of an edge of each. Only `+ − × ÷ sqrt`.
fn box_box_axes(a: &BodyState, ha: Vec3, b: &BodyState, hb: Vec3) -> BoxOverlap {
    let (ra, rb) = (a.rot.to_rotation_matrix(), b.rot.to_rotation_matrix());
    let axes_a = [ra * Vec3::x(), ra * Vec3::y(), ra * Vec3::z()];
    let axes_b = [rb * Vec3::x(), rb * Vec3::y(), rb * Vec3::z()];
    let d = b.pos - a.pos;
    // The overlap of the boxes' projections on the unit axis `l`, and `l` turned to point from
    // `a` to `b`.
    let overlap = |l: Vec3| {
        let reach =
            |axes: &[Vec3; 3], h: Vec3| (0..3).map(|k| h[k] * axes[k].dot(&l).abs()).sum::<f64>();
        let along = l.dot(&d);
        let l = if along < 0.0 { -l } else { l };
        (reach(&axes_a, ha) + reach(&axes_b, hb) - along.abs(), l)
    };
    let mut best_face = f64::INFINITY;
    // (the first box's axis: 0-2, the second's: 3-5, the axis turned from `a` to `b`)
    let mut best_face_axis = (0, Vec3::zeros());
    for (k, l) in axes_a.iter().chain(&axes_b).enumerate() {
        let (o, l) = overlap(*l);
        if o <= 0.0 {
            return BoxOverlap::Apart;
        }
        if o < best_face {
            (best_face, best_face_axis) = (o, (k, l));
        }
    }
    let mut best_edge: Option<(f64, Vec3, usize, usize)> = None;
    for (i, ea) in axes_a.iter().enumerate() {
        for (j, eb) in axes_b.iter().enumerate() {
            let c = ea.cross(eb);
            let len = c.norm();
            if len < 1e-9 {
                continue; // parallel edges: a face axis covers them
            }
            let (o, l) = overlap(c / len);
            if o <= 0.0 {
                return BoxOverlap::Apart;
            }
            if best_edge.is_none_or(|(best, ..)| o < best) {
                best_edge = Some((o, l, i, j));
            }
        }
    }
    let Some((depth, l, i, j)) = best_edge.filter(|(o, ..)| *o < EDGE_AXIS_MARGIN * best_face)
    else {
        return faces(a.pos, &axes_a, ha, b.pos, &axes_b, hb, best_face_axis);
    };
    // The edge of each box along its axis i (j) nearest the other along `l`.
    let edge = |centre: Vec3, axes: &[Vec3; 3], h: Vec3, along: usize, towards: Vec3| {
        (0..3).filter(|&k| k != along).fold(centre, |p, k| {
            p + axes[k] * (h[k] * axes[k].dot(&towards).signum())
        })
    };
    let pa = edge(a.pos, &axes_a, ha, i, l);
    let pb = edge(b.pos, &axes_b, hb, j, -l);
    let (u, v) = (axes_a[i], axes_b[j]);
    // Closest points of the lines pa + s u and pb + t v (unit u, v, not parallel), each kept on
    // its edge.
    let w = pa - pb;
    let (uv, uw, vw) = (u.dot(&v), u.dot(&w), v.dot(&w));
    let den = 1.0 - uv * uv;
    // Each clamped in turn, the other recomputed from it, so both stay on their edges.
    let s = ((uv * vw - uw) / den).clamp(-ha[i], ha[i]);
    let t = (vw + s * uv).clamp(-hb[j], hb[j]);
    let s = (t * uv - uw).clamp(-ha[i], ha[i]);
    BoxOverlap::Edges {
        point: (pa + u * s + pb + v * t) * 0.5,
        normal: -l,
        depth,
    }
}

/// The face contact of two boxes (centres `ca`, `cb`, axes, half extents) overlapping least along
/// face axis `axis` (0-2 the first box's, 3-5 the second's; `l` that axis turned from the first
/// towards the second): the reference face is that box's face towards the other, the incident
/// face the other box's face most against it; the incident face's corners are clipped to the
/// reference face's sides (Sutherland–Hodgman, at most 8 points), and those below the reference
/// face touch, as deep as they are below it.
fn faces(
    ca: Vec3,
    axes_a: &[Vec3; 3],
    ha: Vec3,
    cb: Vec3,
    axes_b: &[Vec3; 3],
    hb: Vec3,
    (axis, l): (usize, Vec3),
) -> BoxOverlap {
    // Reference box r, incident box i; `n` out of the reference face, towards the incident box.
    let a_is_reference = axis < 3;
    let (cr, axes_r, hr, ci, axes_i, hi, k, n) = if a_is_reference {
        (ca, axes_a, ha, cb, axes_b, hb, axis, l)
    } else {
        (cb, axes_b, hb, ca, axes_a, ha, axis - 3, -l)
    };
    let face_centre = cr + n * hr[k];
    let (u1, u2) = ((k + 1) % 3, (k + 2) % 3);
    // The incident face: the incident box's face whose outward normal is most against `n`.
    let m = (0..3).fold(0, |best, q| {
        if axes_i[q].dot(&n).abs() > axes_i[best].dot(&n).abs() {
            q
        } else {
            best
        }
    });
    let out_i = axes_i[m] * -axes_i[m].dot(&n).signum();
    let centre_i = ci + out_i * hi[m];
    let (m1, m2) = ((m + 1) % 3, (m + 2) % 3);
    let (e1, e2) = (axes_i[m1] * hi[m1], axes_i[m2] * hi[m2]);
    let mut poly = [Vec3::zeros(); 8];
    poly[..4].copy_from_slice(&[
        centre_i + e1 + e2,
        centre_i - e1 + e2,
        centre_i - e1 - e2,
        centre_i + e1 - e2,
    ]);
    let mut len = 4;
    // Clip to the four side planes of the reference face: side · (p − face centre) <= extent.
    for (side, extent) in [
        (axes_r[u1], hr[u1]),
        (-axes_r[u1], hr[u1]),
        (axes_r[u2], hr[u2]),
        (-axes_r[u2], hr[u2]),
    ] {
        let mut out = [Vec3::zeros(); 8];
        let mut kept = 0;
        let inside = |p: &Vec3| extent - side.dot(&(p - face_centre));
        for q in 0..len {
            let (p, next) = (poly[q], poly[(q + 1) % len]);
            let (dp, dn) = (inside(&p), inside(&next));
            if dp >= 0.0 && kept < 8 {
                out[kept] = p;
                kept += 1;
            }
            if (dp >= 0.0) != (dn >= 0.0) && kept < 8 {
                out[kept] = p + (next - p) * (dp / (dp - dn));
                kept += 1;
            }
        }
        poly = out;
        len = kept;
    }
    // Pushing the first box away from the second.
    let normal_a = if a_is_reference { -n } else { n };
    let mut points = [(Vec3::zeros(), Vec3::zeros(), 0.0); 8];
    let mut count = 0;
    for p in &poly[..len] {
        let depth = -n.dot(&(p - face_centre));
        if depth > 0.0 {
            points[count] = (*p, normal_a, depth);
            count += 1;
        }
    }
    BoxOverlap::Faces { points, count }
}

/// Most points an object–object contact weighs: every contact point of either shape, and the
/// point of each facing the other ([`Shape::facing_point`]).
const PAIR_POINTS: usize = 2 * (MAX_CONTACT_POINTS + 1);

/// Whether two objects' bounding spheres overlap (if not, they do not touch).
fn within_reach(a: &PairSide<'_>, b: &PairSide<'_>) -> bool {
    let reach = a.shape.bounding_radius() + b.shape.bounding_radius();
    (a.body.pos - b.body.pos).norm_squared() <= reach * reach
}

/// Where two objects touch (see [`pair_wrench`]): each touching point, the normal pushing `a`
/// away from `b` there and the depth, into `points`; how many. The two are within reach
/// ([`within_reach`]).
fn pair_points(
    a: &PairSide<'_>,
    b: &PairSide<'_>,
    points: &mut [(Vec3, Vec3, f64); PAIR_POINTS],
) -> usize {
    let mut n_touch = 0usize;
    // Two boxes: the separating-axis test, then the clipped face contact or the crossing of two
    // edges (which no corner or face centre of either finds: two bars crossed).
    if let (Shape::Box { half: ha }, Shape::Box { half: hb }) = (*a.shape, *b.shape) {
        match box_box_axes(a.body, ha, b.body, hb) {
            BoxOverlap::Apart => return 0,
            BoxOverlap::Edges {
                point,
                normal,
                depth,
            } => {
                points[0] = (point, normal, depth);
                n_touch = 1;
            }
            BoxOverlap::Faces {
                points: found,
                count,
            } => {
                points[..count].copy_from_slice(&found[..count]);
                n_touch = count;
            }
        }
    }
    // The points of `from` inside `into`; `sign` +1 where `from` is `a`, -1 where it is `b`.
    let mut gather = |from: &PairSide<'_>, into: &PairSide<'_>, sign: f64| {
        let mut fixed = [Vec3::zeros(); MAX_CONTACT_POINTS];
        let (count, margin) = from.shape.contact_points(&mut fixed);
        let (r_from, inv_into) = (from.body.rot, into.body.rot.inverse());
        let toward = r_from.inverse() * (into.body.pos - from.body.pos);
        let facing = from.shape.facing_point(toward);
        // A point farther from `into`'s centre than its bounding sphere and the margin is not
        // inside it: the same answer without the rotation and the distance (most of a shape's
        // points face away from its neighbour).
        // (Compared in `from`'s frame, where its points are: no rotation for the ones skipped.)
        let reach = into.shape.bounding_radius() + margin;
        for q in fixed[..count].iter().chain(facing.as_ref()) {
            if (q - toward).norm_squared() > reach * reach {
                continue;
            }
            let world = from.body.pos + r_from * q;
            let (d, n_body) = into
                .shape
                .signed_distance(inv_into * (world - into.body.pos));
            let depth = margin - d;
            if depth > 0.0 && n_touch < PAIR_POINTS {
                let out_of_into = into.body.rot * n_body;
                points[n_touch] = (world - out_of_into * margin, out_of_into * sign, depth);
                n_touch += 1;
            }
        }
    };
    if !matches!((a.shape, b.shape), (Shape::Box { .. }, Shape::Box { .. })) {
        gather(a, b, 1.0);
        gather(b, a, -1.0);
    }
    n_touch
}

/// How deep two objects overlap, m (0: apart): the depth of [`pair_wrench`]'s spring.
pub fn pair_depth(a: &PairSide<'_>, b: &PairSide<'_>) -> f64 {
    if !within_reach(a, b) {
        return 0.0;
    }
    let mut points = [(Vec3::zeros(), Vec3::zeros(), 0.0f64); PAIR_POINTS];
    let n = pair_points(a, b, &mut points);
    points[..n].iter().fold(0.0, |d, p| d.max(p.2))
}

/// The contact between two objects `a` and `b`, updating the pair's friction memory: the wrench on
/// `a`, the wrench on `b`, and whether they touch.
///
/// The environment's law (see [`environment_wrench`]) between two moving bodies. Each shape's
/// contact points ([`Shape::contact_points`]) inside the other are the touching points, each with
/// its depth and the other's outward normal there; the normal force is K times the *deepest*
/// penetration along the depth-weighted mean normal, at the depth-weighted centre of pressure;
/// damping is shared by the touching points, each resisting the two bodies' relative normal
/// velocity there, and never pulls; friction is one stick spring between a point on each body, set
/// where the contact began (the touching points' centre). Whatever acts on `b` is exactly the
/// negative of what acts on `a`, at the same points: the pair's forces conserve momentum, linear
/// and angular.
///
/// Two boxes' touching points come from the separating-axis test instead: the other box's face
/// clipped to the face they overlap least across, or where two edges cross (two bars crossed,
/// which no corner of either finds). A cylinder adds the point of its side facing the other's
/// centre ([`Shape::facing_point`]); a cylinder's side crossing a box's edge between its
/// ends, or another cylinder's side at an angle away from both centres, is still not found.
pub fn pair_wrench(
    c: &ContactParams,
    state: &mut PairContactState,
    a: PairSide<'_>,
    b: PairSide<'_>,
) -> (Wrench, Wrench, bool) {
    let none = (Wrench::default(), Wrench::default(), false);
    // Most pairs are apart: answered before the points' table is even made (its zeroing cost
    // more than the test: a third of a crowd's step).
    if !within_reach(&a, &b) {
        *state = PairContactState::default();
        return none;
    }
    // (point, normal pushing `a` away from `b`, depth)
    let mut points = [(Vec3::zeros(), Vec3::zeros(), 0.0f64); PAIR_POINTS];
    let n_touch = pair_points(&a, &b, &mut points);
    if n_touch == 0 {
        *state = PairContactState::default();
        return none;
    }
    let touching = &points[..n_touch];
    let (mut deepest, mut weight) = (0.0f64, 0.0);
    let (mut centre, mut normal, mut patch) = (Vec3::zeros(), Vec3::zeros(), Vec3::zeros());
    for &(p, n, depth) in touching {
        deepest = deepest.max(depth);
        weight += depth;
        centre += p * depth;
        normal += n * depth;
        patch += p;
    }
    let p = centre / weight;
    // Opposite normals of equal depth (two faces flush, rounding leaving points of each a hair
    // inside the other) sum to nothing: the deepest point's own normal then.
    let n = if normal.norm() > 1e-9 * weight {
        normal.normalize()
    } else {
        touching
            .iter()
            .fold(touching[0], |best, t| if t.2 > best.2 { *t } else { best })
            .1
    };
    let patch = patch / n_touch as f64;
    let (omega_a, omega_b) = (a.body.omega(a.mass), b.body.omega(b.mass));
    // The velocity of `a` relative to `b` at world point `q`.
    let relative = |q: Vec3| {
        a.body.vel + omega_a.cross(&(q - a.body.pos))
            - b.body.vel
            - omega_b.cross(&(q - b.body.pos))
    };
    let f_spring = c.stiffness_n_per_m * deepest;
    let share = c.damping_n_s_per_m / n_touch as f64;
    let (mut damp_a, mut damp_b, mut f_damp_total) = (Wrench::default(), Wrench::default(), 0.0);
    for &(q, _, _) in touching {
        let f = -share * relative(q).dot(&n);
        f_damp_total += f;
        damp_a = damp_a + Wrench::at_point(n * f, q, a.body.pos);
        damp_b = damp_b + Wrench::at_point(-(n * f), q, b.body.pos);
    }
    // Never pulling: limit the damping so the total normal force stays >= 0.
    let scale = if f_spring + f_damp_total < 0.0 && f_damp_total < 0.0 {
        -f_spring / f_damp_total
    } else {
        1.0
    };
    let f_n = f_spring + f_damp_total * scale;
    let (on_a, on_b) = state.anchors.map_or((patch, patch), |(qa, qb)| {
        (a.body.pos + a.body.rot * qa, b.body.pos + b.body.rot * qb)
    });
    let (f_t, slipped, stretch) = friction(c, on_b, on_a, -relative(patch), n, f_n);
    let on_a = if slipped { on_b - stretch } else { on_a };
    let stuck = Some((
        a.body.rot.inverse() * (on_a - a.body.pos),
        b.body.rot.inverse() * (on_b - b.body.pos),
    ));
    state.anchors = stuck;
    // Rotational friction: a couple, equal and opposite.
    let mut turning = Vec3::zeros();
    if c.rotational_friction_radius_m > 0.0 {
        let (ref_a, ref_b) = state.twist.unwrap_or_else(|| {
            let t = across(n);
            (a.body.rot.inverse() * t, b.body.rot.inverse() * t)
        });
        let spin = (omega_b - omega_a).dot(&n);
        let (torque, slipped_ref) = twist(c, b.body.rot * ref_b, a.body.rot * ref_a, spin, n, f_n);
        let ref_b = slipped_ref.map_or(ref_b, |t| b.body.rot.inverse() * t);
        state.twist = Some((ref_a, ref_b));
        turning = n * torque;
    }
    let scaled = |w: Wrench| Wrench {
        force: w.force * scale,
        torque: w.torque * scale,
    };
    // Friction acts on both at one point, the touching points' centre, as the environment's does:
    // equal and opposite at the same point, so angular momentum is conserved too.
    let w_a = Wrench::at_point(n * f_spring, p, a.body.pos)
        + Wrench::at_point(f_t, patch, a.body.pos)
        + Wrench {
            force: Vec3::zeros(),
            torque: turning,
        }
        + scaled(damp_a);
    let w_b = Wrench::at_point(-(n * f_spring), p, b.body.pos)
        + Wrench::at_point(-f_t, patch, b.body.pos)
        + Wrench {
            force: Vec3::zeros(),
            torque: -turning,
        }
        + scaled(damp_b);
    (w_a, w_b, true)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::body::step;

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

    fn disk() -> (Shape, MassProps) {
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
