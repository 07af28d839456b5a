//! A reach: the minimum-jerk path (Flash & Hogan 1985) from the hand target's present position,
//! velocity and acceleration to a goal at rest, as a quintic in time. Retargeting starts a new
//! quintic from the present state, so a goal that moves while the hand is on its way bends the
//! path without a jump in position, velocity or acceleration.

use crate::body::Vec3;

/// One minimum-jerk segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MinJerk {
    /// When it starts, s.
    pub t0: f64,
    /// How long it takes, s (0: a hold at `c[0]`).
    pub duration: f64,
    /// Coefficients of the quintic in τ = t − t0.
    c: [Vec3; 6],
}

impl MinJerk {
    /// Holding still at `p`.
    pub fn hold(p: Vec3, t0: f64) -> Self {
        let mut c = [Vec3::zeros(); 6];
        c[0] = p;
        Self {
            t0,
            duration: 0.0,
            c,
        }
    }

    /// From position `p0`, velocity `v0` and acceleration `a0` at `t0` to rest at `goal` after
    /// `duration` s.
    pub fn new(t0: f64, p0: Vec3, v0: Vec3, a0: Vec3, goal: Vec3, duration: f64) -> Self {
        if duration <= 1e-6 {
            return Self::hold(goal, t0);
        }
        let (t, d) = (duration, goal - p0);
        let (t2, t3) = (t * t, t * t * t);
        let c3 = (d * 20.0 - v0 * (12.0 * t) - a0 * (3.0 * t2)) / (2.0 * t3);
        let c4 = (-d * 30.0 + v0 * (16.0 * t) + a0 * (3.0 * t2)) / (2.0 * t3 * t);
        let c5 = (d * 12.0 - v0 * (6.0 * t) - a0 * t2) / (2.0 * t3 * t2);
        Self {
            t0,
            duration,
            c: [p0, v0, a0 * 0.5, c3, c4, c5],
        }
    }

    /// When it ends, s.
    pub fn end(&self) -> f64 {
        self.t0 + self.duration
    }

    /// Where it ends.
    pub fn goal(&self) -> Vec3 {
        self.at(self.end()).0
    }

    /// Position, velocity and acceleration at `t` (held at the ends).
    pub fn at(&self, t: f64) -> (Vec3, Vec3, Vec3) {
        let tau = (t - self.t0).clamp(0.0, self.duration);
        let c = &self.c;
        let p = c[0] + (c[1] + (c[2] + (c[3] + (c[4] + c[5] * tau) * tau) * tau) * tau) * tau;
        if t >= self.end() || self.duration == 0.0 {
            return (p, Vec3::zeros(), Vec3::zeros());
        }
        let v = c[1]
            + (c[2] * 2.0 + (c[3] * 3.0 + (c[4] * 4.0 + c[5] * (5.0 * tau)) * tau) * tau) * tau;
        let a = c[2] * 2.0 + (c[3] * 6.0 + (c[4] * 12.0 + c[5] * (20.0 * tau)) * tau) * tau;
        (p, v, a)
    }

    /// A new segment from this one's state at `t` to `goal`, taking `duration` s.
    pub fn retarget(&self, t: f64, goal: Vec3, duration: f64) -> Self {
        let (p, v, a) = self.at(t);
        Self::new(t, p, v, a, goal, duration)
    }

    /// Whether it is done at `t`.
    pub fn done(&self, t: f64) -> bool {
        t >= self.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reach_from_rest_is_bell_shaped_and_ends_at_rest_on_its_goal() {
        let goal = Vec3::new(0.1, 0.0, 0.0);
        let m = MinJerk::new(1.0, Vec3::zeros(), Vec3::zeros(), Vec3::zeros(), goal, 0.5);
        assert_eq!(m.at(0.0).0, Vec3::zeros());
        assert!((m.at(1.5).0 - goal).norm() < 1e-12);
        // The peak speed is 1.875 D/T at the middle (Flash & Hogan's profile).
        let (_, v_mid, a_mid) = m.at(1.25);
        assert!((v_mid.x - 1.875 * 0.1 / 0.5).abs() < 1e-9);
        assert!(a_mid.norm() < 1e-9);
        assert!(m.at(1.05).1.x < v_mid.x && m.at(1.45).1.x < v_mid.x);
    }

    #[test]
    fn a_retarget_keeps_position_velocity_and_acceleration() {
        let m = MinJerk::new(
            0.0,
            Vec3::zeros(),
            Vec3::zeros(),
            Vec3::zeros(),
            Vec3::new(0.1, 0.0, 0.0),
            0.5,
        );
        let r = m.retarget(0.2, Vec3::new(0.1, 0.05, 0.0), 0.4);
        let (a, b) = (m.at(0.2), r.at(0.2));
        assert!((a.0 - b.0).norm() < 1e-12 && (a.1 - b.1).norm() < 1e-9);
        assert!((a.2 - b.2).norm() < 1e-6);
        assert!((r.goal() - Vec3::new(0.1, 0.05, 0.0)).norm() < 1e-12);
    }
}
