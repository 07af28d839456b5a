//! The force-display device: a 3-DOF SCARA arm as in the paper (Sec. 6.1), with a force sensor at the
//! handle, and the simulated plant it forms with the user's hand.
//!
//! Joints: shoulder θ₁ and elbow θ₂ turn about vertical axes (the horizontal x–y workspace, as in the
//! paper's planar task), joint 3 is a capstan-driven slide along z (42:1 onto a pulley), so the handle reaches 3-D points. The
//! motors drive through gears of 80:1, 50:1 and 42:1 as the paper's. Joint dynamics are decoupled —
//! I_j q̈_j = τ_j − friction_j(q̇_j) + (Jᵀ F_handle)_j — because the reflected motor inertia (J_m N²)
//! dominates the link inertia at these gear ratios; friction is viscous plus Coulomb (smoothed over
//! ±1 mrad/s so the plant stays deterministic and integrable).

use nalgebra::Matrix3;

use crate::body::Vec3;
use crate::controller::{ControllerParams, PiForceController};

/// Parameters of the SCARA arm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaraParams {
    /// Where joint 1's axis meets the z = 0 plane, world, m.
    pub base: Vec3,
    /// Shoulder-to-elbow length, m.
    pub link1_m: f64,
    /// Elbow-to-handle length, m.
    pub link2_m: f64,
    /// Gear ratios of joints 1, 2, 3 (80:1, 50:1, 42:1 in the paper).
    pub gear_ratio: [f64; 3],
    /// Motor rotor inertias, kg·m².
    pub motor_inertia_kg_m2: [f64; 3],
    /// Link inertia seen at joints 1 and 2 (kg·m²) and the slide's mass (kg).
    pub link_inertia: [f64; 3],
    /// Pulley radius of joint 3's capstan drive, m (joint-3 travel per pulley radian).
    pub pulley_radius_m: f64,
    /// Viscous friction at the joints (N·m·s/rad; N·s/m for joint 3).
    pub viscous: [f64; 3],
    /// Coulomb friction at the joints (N·m; N for joint 3).
    pub coulomb: [f64; 3],
    /// Torque (force for joint 3) limits at the joints.
    pub torque_limit: [f64; 3],
}

impl ScaraParams {
    /// The paper's arm with plausible link lengths and motor data, based at `base`.
    pub fn paper(base: Vec3) -> Self {
        Self {
            base,
            link1_m: 0.25,
            link2_m: 0.20,
            gear_ratio: [80.0, 50.0, 42.0],
            motor_inertia_kg_m2: [3.3e-6, 3.3e-6, 1.0e-6],
            link_inertia: [0.02, 0.006, 0.3],
            pulley_radius_m: 0.03,
            viscous: [0.05, 0.03, 2.0],
            coulomb: [0.02, 0.015, 0.5],
            torque_limit: [12.0, 8.0, 40.0],
        }
    }

    /// Transmission of each joint: motor radians per joint unit (rad, or m for the slide).
    fn transmission(&self) -> [f64; 3] {
        [
            self.gear_ratio[0],
            self.gear_ratio[1],
            self.gear_ratio[2] / self.pulley_radius_m,
        ]
    }

    /// Effective inertia at each joint: J_m N² + link inertia.
    pub fn joint_inertia(&self) -> [f64; 3] {
        let n = self.transmission();
        [0, 1, 2].map(|j| self.motor_inertia_kg_m2[j] * n[j] * n[j] + self.link_inertia[j])
    }

    /// Eq. 5: handle position r_h = f(q), world.
    pub fn forward(&self, q: &Vec3) -> Vec3 {
        let (l1, l2) = (self.link1_m, self.link2_m);
        self.base
            + Vec3::new(
                l1 * q[0].cos() + l2 * (q[0] + q[1]).cos(),
                l1 * q[0].sin() + l2 * (q[0] + q[1]).sin(),
                q[2],
            )
    }

    /// The manipulator Jacobian J(q) = ∂r_h/∂qᵀ.
    pub fn jacobian(&self, q: &Vec3) -> Matrix3<f64> {
        let (l1, l2) = (self.link1_m, self.link2_m);
        let (s1, c1) = q[0].sin_cos();
        let (s12, c12) = (q[0] + q[1]).sin_cos();
        Matrix3::new(
            -l1 * s1 - l2 * s12,
            -l2 * s12,
            0.0,
            l1 * c1 + l2 * c12,
            l2 * c12,
            0.0,
            0.0,
            0.0,
            1.0,
        )
    }

    /// Joint coordinates that put the handle at world point `p` (elbow on the side of `elbow_sign`),
    /// or `None` outside the reach.
    pub fn inverse(&self, p: Vec3, elbow_sign: f64) -> Option<Vec3> {
        let d = p - self.base;
        let (l1, l2) = (self.link1_m, self.link2_m);
        let c2 = (d.x * d.x + d.y * d.y - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
        if !(-1.0..=1.0).contains(&c2) {
            return None;
        }
        let q2 = elbow_sign.signum() * c2.acos();
        let q1 = d.y.atan2(d.x) - (l2 * q2.sin()).atan2(l1 + l2 * q2.cos());
        Some(Vec3::new(q1, q2, d.z))
    }

    /// Clamps joint torques to the limits.
    pub fn clamp_torque(&self, tau: Vec3) -> Vec3 {
        Vec3::from_fn(|j, _| tau[j].clamp(-self.torque_limit[j], self.torque_limit[j]))
    }

    fn friction(&self, qd: &Vec3) -> Vec3 {
        Vec3::from_fn(|j, _| self.viscous[j] * qd[j] + self.coulomb[j] * (qd[j] / 1e-3).tanh())
    }
}

/// The SCARA arm's own force loop: it senses the force at its handle, so it takes the force to
/// display and drives its joint torques itself with the paper's Eq. 12 PI controller.
#[derive(Debug, Clone, PartialEq)]
pub struct ScaraForceLoop {
    /// The arm.
    pub arm: ScaraParams,
    /// The controller's gains and limits.
    pub params: ControllerParams,
    controller: PiForceController,
}

impl ScaraForceLoop {
    /// The loop of `arm` with `params`, at rest.
    pub fn new(arm: ScaraParams, params: ControllerParams) -> Self {
        Self {
            arm,
            params,
            controller: PiForceController::default(),
        }
    }

    /// One control step of `dt` seconds towards the desired handle force `f_h` (world, N), with the
    /// sensed force `f_m` and the joints at `q`; `gain` (0..=1) is the share of the output applied
    /// (the servo's stale ramp: a fading world leaves the arm limp, not force-controlled to zero; at
    /// 0 the integral is forgotten). Returns (commanded handle force, joint torques clamped to the
    /// motors' limits).
    pub fn step(&mut self, f_h: Vec3, gain: f64, f_m: Vec3, q: &Vec3, dt: f64) -> (Vec3, Vec3) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        if gain == 0.0 {
            self.controller.reset_integral();
        }
        let j = self.arm.jacobian(q);
        let (f_command, tau) = self.controller.step(&self.params, f_h, f_m, &j, dt);
        let (f_command, tau) = (f_command * gain, tau * gain);
        (f_command, self.arm.clamp_torque(tau))
    }
}

/// The user's hand: a mass held by a spring and damper to a scripted target (an impedance), gripping
/// the handle through a stiff, damped grip.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct HandParams {
    /// Hand and forearm mass moving with the handle, kg.
    pub mass_kg: f64,
    /// Arm stiffness towards the target, N/m.
    pub stiffness_n_per_m: f64,
    /// Arm damping, N·s/m.
    pub damping_n_s_per_m: f64,
    /// Grip stiffness between hand and handle, N/m.
    pub grip_stiffness_n_per_m: f64,
    /// Grip damping, N·s/m.
    pub grip_damping_n_s_per_m: f64,
}

impl Default for HandParams {
    fn default() -> Self {
        Self {
            mass_kg: 0.4,
            stiffness_n_per_m: 300.0,
            damping_n_s_per_m: 15.0,
            grip_stiffness_n_per_m: 3000.0,
            grip_damping_n_s_per_m: 20.0,
        }
    }
}

/// The simulated arm plus hand: what a real device and a real person would be.
#[derive(Debug, Clone, PartialEq)]
pub struct Plant {
    /// Arm parameters.
    pub arm: ScaraParams,
    /// Hand parameters.
    pub hand: HandParams,
    /// Joint positions.
    pub q: Vec3,
    /// Joint velocities.
    pub qd: Vec3,
    /// Hand position, world.
    pub hand_pos: Vec3,
    /// Hand velocity, world.
    pub hand_vel: Vec3,
    /// The force the device applies to the hand through the grip (what the sensor measures), N.
    pub grip_force: Vec3,
}

impl Plant {
    /// A plant at rest with the handle and hand at `p`.
    ///
    /// # Panics
    /// If `p` is outside the arm's reach (scenario validation checks this first).
    pub fn at(arm: ScaraParams, hand: HandParams, p: Vec3, elbow_sign: f64) -> Self {
        let q = arm
            .inverse(p, elbow_sign)
            .expect("start point within reach");
        Self {
            arm,
            hand,
            q,
            qd: Vec3::zeros(),
            hand_pos: arm.forward(&q),
            hand_vel: Vec3::zeros(),
            grip_force: Vec3::zeros(),
        }
    }

    /// Handle position, world.
    pub fn handle_pos(&self) -> Vec3 {
        self.arm.forward(&self.q)
    }

    /// Handle velocity, world.
    pub fn handle_vel(&self) -> Vec3 {
        self.arm.jacobian(&self.q) * self.qd
    }

    /// Advances arm and hand by `dt` (semi-implicit Euler) under motor torques `tau` (already clamped)
    /// with the hand pulled towards `target` moving at `target_vel`.
    pub fn step(&mut self, tau: Vec3, target: Vec3, target_vel: Vec3, dt: f64) {
        let h = &self.hand;
        let j = self.arm.jacobian(&self.q);
        let (x, xd) = (self.arm.forward(&self.q), j * self.qd);
        // Force of the hand on the handle through the grip; the device pushes back with its opposite.
        let on_handle = (self.hand_pos - x) * h.grip_stiffness_n_per_m
            + (self.hand_vel - xd) * h.grip_damping_n_s_per_m;
        self.grip_force = -on_handle;
        let inertia = self.arm.joint_inertia();
        let qdd_rhs = tau - self.arm.friction(&self.qd) + j.transpose() * on_handle;
        let qdd = Vec3::from_fn(|k, _| qdd_rhs[k] / inertia[k]);
        let hand_acc = ((target - self.hand_pos) * h.stiffness_n_per_m
            + (target_vel - self.hand_vel) * h.damping_n_s_per_m
            - on_handle)
            / h.mass_kg;
        self.qd += qdd * dt;
        self.q += self.qd * dt;
        self.hand_vel += hand_acc * dt;
        self.hand_pos += self.hand_vel * dt;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinematics_round_trip_and_jacobian_matches_finite_differences() {
        let arm = ScaraParams::paper(Vec3::new(-0.3, -0.2, 0.0));
        let p = Vec3::new(-0.1, 0.05, 0.02);
        let q = arm.inverse(p, 1.0).expect("reachable");
        assert!((arm.forward(&q) - p).norm() < 1e-12);
        let j = arm.jacobian(&q);
        for k in 0..3 {
            let mut dq = Vec3::zeros();
            dq[k] = 1e-7;
            let fd = (arm.forward(&(q + dq)) - arm.forward(&(q - dq))) / 2e-7;
            assert!((fd - j.column(k)).norm() < 1e-6);
        }
        assert!(arm.inverse(Vec3::new(1.0, 0.0, 0.0), 1.0).is_none());
    }
}
