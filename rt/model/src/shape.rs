//! Object shapes and the signed distance a contact needs (Eq. 7's penetration Δr).
//!
//! All queries are in the body frame; callers transform the world point in. The distance is negative
//! inside; the normal points out of the object at the closest surface point, so the deepest
//! penetration of a tool tip of radius ρ is `ρ − distance` along that normal.

use crate::body::Vec3;

/// Most points [`Shape::contact_points`] gives (a cylinder's 18).
pub const MAX_CONTACT_POINTS: usize = 18;

/// A convex object shape, centred on its centre of mass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// A sphere of this radius, m.
    Sphere {
        /// Radius, m.
        radius: f64,
    },
    /// A cylinder (disk) along the body z axis.
    Cylinder {
        /// Radius, m.
        radius: f64,
        /// Half the height, m.
        half_height: f64,
    },
    /// A box with these half extents along the body axes, m.
    Box {
        /// Half extents, m.
        half: Vec3,
    },
}

impl Shape {
    /// Signed distance from body-frame point `p` to the surface, and the outward unit normal there.
    pub fn signed_distance(&self, p: Vec3) -> (f64, Vec3) {
        match *self {
            Shape::Sphere { radius } => {
                let d = p.norm();
                let n = if d > 1e-12 { p / d } else { Vec3::x() };
                (d - radius, n)
            }
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                let rho = (p.x * p.x + p.y * p.y).sqrt();
                let radial = if rho > 1e-12 {
                    Vec3::new(p.x / rho, p.y / rho, 0.0)
                } else {
                    Vec3::x()
                };
                let axial = Vec3::new(0.0, 0.0, if p.z >= 0.0 { 1.0 } else { -1.0 });
                let (dr, dz) = (rho - radius, p.z.abs() - half_height);
                if dr <= 0.0 && dz <= 0.0 {
                    // Inside: nearest face.
                    if dr > dz {
                        (dr, radial)
                    } else {
                        (dz, axial)
                    }
                } else {
                    let (er, ez) = (dr.max(0.0), dz.max(0.0));
                    let n = (radial * er + axial * ez).normalize();
                    ((er * er + ez * ez).sqrt(), n)
                }
            }
            Shape::Box { half } => {
                let q = p.abs() - half;
                let sign = p.map(|v| if v >= 0.0 { 1.0 } else { -1.0 });
                if q.max() <= 0.0 {
                    let axis = q.imax();
                    let mut n = Vec3::zeros();
                    n[axis] = sign[axis];
                    (q[axis], n)
                } else {
                    let out = q.map(|v| v.max(0.0));
                    (out.norm(), out.component_mul(&sign).normalize())
                }
            }
        }
    }

    /// The body-frame points that can touch a flat environment surface: the one support point of a
    /// sphere, the 8 corners of a box, 8 rim points on each cap of a cylinder. A fixed set, so an
    /// environment contact needs no allocation.
    pub fn probe_points(&self, out: &mut [Vec3; 16]) -> usize {
        match *self {
            Shape::Sphere { .. } => 0,
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                for (i, o) in out.iter_mut().enumerate() {
                    let a = (i % 8) as f64 * std::f64::consts::FRAC_PI_4;
                    let z = if i < 8 { half_height } else { -half_height };
                    *o = Vec3::new(radius * a.cos(), radius * a.sin(), z);
                }
                16
            }
            Shape::Box { half } => {
                for (i, o) in out.iter_mut().take(8).enumerate() {
                    let s = |bit: usize| if i & bit == 0 { -1.0 } else { 1.0 };
                    *o = Vec3::new(s(1) * half.x, s(2) * half.y, s(4) * half.z);
                }
                8
            }
        }
    }

    /// The body-frame points that can touch another object, and the margin around them: a sphere
    /// is its centre with its radius; a box its corners and its faces' centres, a cylinder its
    /// [`Shape::probe_points`] and its caps' centres, with none. The deepest point of the shape
    /// into another lies `margin` from a point, against that other's surface normal. (A face
    /// lying flat on another of the same size has its corners on the other's side faces, at
    /// depth 0: its centre is the point that finds it.)
    pub fn contact_points(&self, out: &mut [Vec3; MAX_CONTACT_POINTS]) -> (usize, f64) {
        let mut probes = [Vec3::zeros(); 16];
        match *self {
            Shape::Sphere { radius } => {
                out[0] = Vec3::zeros();
                (1, radius)
            }
            Shape::Cylinder { half_height, .. } => {
                let n = self.probe_points(&mut probes);
                out[..n].copy_from_slice(&probes[..n]);
                out[n] = Vec3::new(0.0, 0.0, half_height);
                out[n + 1] = Vec3::new(0.0, 0.0, -half_height);
                (n + 2, 0.0)
            }
            Shape::Box { half } => {
                let n = self.probe_points(&mut probes);
                out[..n].copy_from_slice(&probes[..n]);
                for axis in 0..3 {
                    for (k, sign) in [1.0, -1.0].into_iter().enumerate() {
                        let mut c = Vec3::zeros();
                        c[axis] = sign * half[axis];
                        out[n + 2 * axis + k] = c;
                    }
                }
                (n + 6, 0.0)
            }
        }
    }

    /// The body-frame point of the shape that faces a point `toward` (body frame) beyond the
    /// fixed [`Shape::contact_points`]: for a cylinder whose side faces it (it lies farther from
    /// the axis than along it), the point of its side facing it at its height, clamped to the side
    /// (a rim point when it lies beyond a cap). Two upright cylinders side by side touch along
    /// their sides, between the rim points sampled (which lie in the other's cap planes, at depth
    /// 0): this finds them, and a cylinder's rim crossing another's. None for the other shapes (a
    /// sphere's centre, a box's corners and faces do).
    pub fn facing_point(&self, toward: Vec3) -> Option<Vec3> {
        match *self {
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                let across = (toward.x * toward.x + toward.y * toward.y).sqrt();
                // Nearer the axis than the side (a cup on a tray): the caps' rims and centres face
                // it; one more rim point, at an azimuth the least sideways offset picks, would
                // tilt the contact's centre of pressure towards it.
                (across > toward.z.abs()).then(|| {
                    let (x, y) = (radius * toward.x / across, radius * toward.y / across);
                    Vec3::new(x, y, toward.z.clamp(-half_height, half_height))
                })
            }
            Shape::Sphere { .. } | Shape::Box { .. } => None,
        }
    }

    /// The radius of the smallest sphere about the centre of mass that holds the shape, m: two
    /// objects farther apart than the sum of theirs cannot touch.
    pub fn bounding_radius(&self) -> f64 {
        match *self {
            Shape::Sphere { radius } => radius,
            Shape::Cylinder {
                radius,
                half_height,
            } => (radius * radius + half_height * half_height).sqrt(),
            Shape::Box { half } => half.norm(),
        }
    }

    /// Principal moments of inertia of the solid shape of mass `m`, kg·m².
    pub fn inertia(&self, m: f64) -> Vec3 {
        match *self {
            Shape::Sphere { radius } => Vec3::repeat(0.4 * m * radius * radius),
            Shape::Cylinder {
                radius,
                half_height,
            } => {
                let h = 2.0 * half_height;
                let side = m * (3.0 * radius * radius + h * h) / 12.0;
                Vec3::new(side, side, 0.5 * m * radius * radius)
            }
            Shape::Box { half } => {
                let d = half * 2.0;
                Vec3::new(
                    m * (d.y * d.y + d.z * d.z) / 12.0,
                    m * (d.x * d.x + d.z * d.z) / 12.0,
                    m * (d.x * d.x + d.y * d.y) / 12.0,
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_and_normals() {
        let s = Shape::Sphere { radius: 0.04 };
        let (d, n) = s.signed_distance(Vec3::new(0.03, 0.0, 0.0));
        assert!((d + 0.01).abs() < 1e-12 && n == Vec3::x());
        let c = Shape::Cylinder {
            radius: 0.04,
            half_height: 0.01,
        };
        let (d, n) = c.signed_distance(Vec3::new(0.0, 0.035, 0.0));
        assert!((d + 0.005).abs() < 1e-12 && (n - Vec3::y()).norm() < 1e-12);
        let (d, n) = c.signed_distance(Vec3::new(0.0, 0.0, 0.02));
        assert!((d - 0.01).abs() < 1e-12 && n == Vec3::z());
        let b = Shape::Box {
            half: Vec3::new(0.05, 0.02, 0.02),
        };
        let (d, n) = b.signed_distance(Vec3::new(0.0, -0.015, 0.0));
        assert!((d + 0.005).abs() < 1e-12 && n == -Vec3::y());
        let (d, _) = b.signed_distance(Vec3::new(0.06, 0.0, 0.0));
        assert!((d - 0.01).abs() < 1e-12);
    }
}
