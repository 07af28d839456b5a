//! Where a device sits in the world: world = translation + rotation · (scale · device), for
//! positions; velocities turn and scale alike; forces go back to the device frame by the inverse
//! rotation only (a workspace scale moves the hand further, it does not change the newtons — as
//! CHAI3D's workspace scale factor). The identity placement computes nothing, so a device whose
//! frame is the world (the simulated arm) gets exactly its own numbers.

use coop_model::body::Vec3;
use nalgebra::UnitQuaternion;

/// A device-to-world transform and workspace scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    translation_m: Vec3,
    rotation: UnitQuaternion<f64>,
    scale: f64,
    identity: bool,
}

impl Default for Placement {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Placement {
    /// The device frame is the world.
    pub const IDENTITY: Self = Self {
        translation_m: Vec3::new(0.0, 0.0, 0.0),
        rotation: UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(1.0, 0.0, 0.0, 0.0)),
        scale: 1.0,
        identity: true,
    };

    /// World = `translation_m` + `rotation` · (`scale` · device). `scale` must be finite and
    /// positive (the station config checks).
    pub fn new(translation_m: Vec3, rotation: UnitQuaternion<f64>, scale: f64) -> Self {
        let identity = translation_m == Vec3::zeros() && rotation.angle() == 0.0 && scale == 1.0;
        Self {
            translation_m,
            rotation,
            scale,
            identity,
        }
    }

    /// Whether it is the identity.
    pub fn is_identity(&self) -> bool {
        self.identity
    }

    /// The workspace scale: world metres per device metre.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// A device-frame position in the world, m.
    pub fn position_to_world(&self, p: Vec3) -> Vec3 {
        if self.identity {
            p
        } else {
            self.translation_m + self.rotation * (p * self.scale)
        }
    }

    /// A device-frame velocity in the world, m/s.
    pub fn velocity_to_world(&self, v: Vec3) -> Vec3 {
        if self.identity {
            v
        } else {
            self.rotation * (v * self.scale)
        }
    }

    /// A world position in the device frame, m (the inverse of [`Placement::position_to_world`]).
    pub fn position_to_device(&self, p: Vec3) -> Vec3 {
        if self.identity {
            p
        } else {
            self.rotation.inverse() * (p - self.translation_m) / self.scale
        }
    }

    /// A device-frame force in the world, N.
    pub fn force_to_world(&self, f: Vec3) -> Vec3 {
        if self.identity {
            f
        } else {
            self.rotation * f
        }
    }

    /// A world force in the device frame, N.
    pub fn force_to_device(&self, f: Vec3) -> Vec3 {
        if self.identity {
            f
        } else {
            self.rotation.inverse() * f
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_positions_both_ways_and_turns_forces_without_scaling_them() {
        let rot = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let p = Placement::new(Vec3::new(0.1, 0.0, 0.0), rot, 2.0);
        let w = p.position_to_world(Vec3::new(0.01, 0.0, 0.0));
        assert!((w - Vec3::new(0.1, 0.02, 0.0)).norm() < 1e-12, "{w}");
        assert!((p.position_to_device(w) - Vec3::new(0.01, 0.0, 0.0)).norm() < 1e-12);
        let f = p.force_to_device(Vec3::new(0.0, 1.0, 0.0));
        assert!((f - Vec3::new(1.0, 0.0, 0.0)).norm() < 1e-12, "{f}");
        assert!(!p.is_identity());
        let id = Placement::new(Vec3::zeros(), UnitQuaternion::identity(), 1.0);
        assert!(id.is_identity());
        let v = Vec3::new(-0.0, 1e-300, 3.0);
        assert_eq!(id.position_to_world(v).x.to_bits(), v.x.to_bits());
    }
}
