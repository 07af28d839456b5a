//! The simulated user: a scripted target the hand's impedance follows (see `device::HandParams`), so
//! forces flow both ways as with a real person. Scripts are data: keyframes of (time, target).

use crate::body::Vec3;

/// One keyframe of a user's script: be at `target` at time `t_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keyframe {
    /// Time, s from the start of the run.
    pub t_s: f64,
    /// Hand target, world, m.
    pub target: Vec3,
}

/// Target position and velocity at `t`: smooth (cubic ease) motion between keyframes, held before
/// the first and after the last. Keyframes must be sorted by time (scenario validation checks).
pub fn target_at(script: &[Keyframe], t: f64) -> (Vec3, Vec3) {
    let Some(first) = script.first() else {
        return (Vec3::zeros(), Vec3::zeros());
    };
    if t <= first.t_s {
        return (first.target, Vec3::zeros());
    }
    for w in script.windows(2) {
        let (a, b) = (w[0], w[1]);
        if t < b.t_s {
            let span = b.t_s - a.t_s;
            if span <= 0.0 {
                return (b.target, Vec3::zeros());
            }
            let u = (t - a.t_s) / span;
            let s = u * u * (3.0 - 2.0 * u);
            let ds = 6.0 * u * (1.0 - u) / span;
            let d = b.target - a.target;
            return (a.target + d * s, d * ds);
        }
    }
    (script[script.len() - 1].target, Vec3::zeros())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eases_between_keyframes_and_holds_outside() {
        let s = [
            Keyframe {
                t_s: 1.0,
                target: Vec3::zeros(),
            },
            Keyframe {
                t_s: 2.0,
                target: Vec3::new(1.0, 0.0, 0.0),
            },
        ];
        assert_eq!(target_at(&s, 0.0).0, Vec3::zeros());
        let (p, v) = target_at(&s, 1.5);
        assert!((p.x - 0.5).abs() < 1e-12 && (v.x - 1.5).abs() < 1e-12);
        assert_eq!(
            target_at(&s, 3.0),
            (Vec3::new(1.0, 0.0, 0.0), Vec3::zeros())
        );
    }
}
