//! Two objects in contact: the separating-axis test of boxes, the contact points of a pair, and
//! the pair's wrenches with friction stuck between the two bodies.

use crate::body::{BodyState, MassProps, Vec3, Wrench};
use crate::shape::{Shape, MAX_CONTACT_POINTS};

use super::{across, friction, twist, ContactParams};

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
/// The environment's law (see [`environment_wrench`](super::environment_wrench)) between two moving
/// bodies. Each shape's contact points ([`Shape::contact_points`]) inside the other are the
/// touching points, each with its depth and the other's outward normal there; the normal force is K
/// times the *deepest* penetration along the depth-weighted mean normal, at the depth-weighted
/// centre of pressure; damping is shared by the touching points, each resisting the two bodies'
/// relative normal velocity there, and never pulls; friction is one stick spring between a point on
/// each body, set where the contact began (the touching points' centre). Whatever acts on `b` is
/// exactly the negative of what acts on `a`, at the same points: the pair's forces conserve
/// momentum, linear and angular.
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
