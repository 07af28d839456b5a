//! What a motor-control lab computes from a recorded hand path, with nothing of the model in it:
//! the reach's movement time between the speed crossing a share of its peak and falling below it,
//! the speed profile's peak over its mean from rest to rest, when the peak comes, where the reach
//! ended; a least-squares line with its r²; and the instant two recordings of the same hand part.
//! Kept apart from the participant so the same code measures a synthetic minimum-jerk reach,
//! whose figures are known in closed form, and the tests can hold it to them.

use coop_model::body::Vec3;

/// The share of the peak speed at which a movement is taken to start and end: a common lab
/// criterion, low enough to keep most of the movement and high enough to stay clear of tremor.
pub const ONSET_SHARE: f64 = 0.05;

/// One sample of a hand path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// When, s.
    pub t_s: f64,
    /// Where, world, m.
    pub pos: Vec3,
    /// Velocity, m/s.
    pub vel: Vec3,
}

/// One reach as a lab measures it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReachFigures {
    /// Movement time: from the speed crossing [`ONSET_SHARE`] of its peak to falling below it, s.
    pub mt_s: f64,
    /// When the speed crossed [`ONSET_SHARE`] of its peak, s.
    pub onset_s: f64,
    /// The peak speed, m/s.
    pub peak_m_s: f64,
    /// The peak speed over the mean speed from rest to rest (minimum jerk: 1.875).
    pub peak_over_mean: f64,
    /// From the onset to the peak, as a share of the movement time (minimum jerk: 0.5).
    pub time_to_peak_share: f64,
    /// Where the hand was at rest again.
    pub end: Vec3,
}

/// The instant the speed crosses `level` between samples `a` and `b` (linear in between).
fn crossing(a: &Sample, b: &Sample, level: f64) -> f64 {
    let (sa, sb) = (a.vel.norm(), b.vel.norm());
    if (sb - sa).abs() < 1e-15 {
        return a.t_s;
    }
    a.t_s + (level - sa) / (sb - sa) * (b.t_s - a.t_s)
}

/// The figures of the one reach in `path` (samples in time order, the hand at rest before and
/// after); `None` when it holds no movement (no sample below the onset level on both sides of
/// the peak).
pub fn measure_reach(path: &[Sample]) -> Option<ReachFigures> {
    let speed = |k: usize| path[k].vel.norm();
    let peak_k = (0..path.len()).max_by(|&a, &b| speed(a).total_cmp(&speed(b)))?;
    let peak = speed(peak_k);
    if peak <= 0.0 {
        return None;
    }
    let level = ONSET_SHARE * peak;
    let before = (0..peak_k).rev().find(|&k| speed(k) < level)?;
    let after = (peak_k + 1..path.len()).find(|&k| speed(k) < level)?;
    let onset = crossing(&path[before], &path[before + 1], level);
    let offset = crossing(&path[after - 1], &path[after], level);
    // Rest to rest: on from the onset crossing back (and the offset forward) while the speed
    // still falls, to where the hand was still, or as still as its tremor lets it be.
    let mut from = before;
    while from > 0 && speed(from - 1) < speed(from) {
        from -= 1;
    }
    let mut to = after;
    while to + 1 < path.len() && speed(to + 1) < speed(to) {
        to += 1;
    }
    let travelled: f64 = path[from..=to]
        .windows(2)
        .map(|w| 0.5 * (w[0].vel.norm() + w[1].vel.norm()) * (w[1].t_s - w[0].t_s))
        .sum();
    let rest_to_rest = path[to].t_s - path[from].t_s;
    // The peak between samples: the vertex of the parabola through the three around it.
    let peak_t = if peak_k > 0 && peak_k + 1 < path.len() {
        let (l, c, r) = (speed(peak_k - 1), peak, speed(peak_k + 1));
        let curve = l - 2.0 * c + r;
        let dt = path[peak_k + 1].t_s - path[peak_k].t_s;
        if curve < 0.0 {
            path[peak_k].t_s + 0.5 * (l - r) / curve * dt
        } else {
            path[peak_k].t_s
        }
    } else {
        path[peak_k].t_s
    };
    let mt = offset - onset;
    Some(ReachFigures {
        mt_s: mt,
        onset_s: onset,
        peak_m_s: peak,
        peak_over_mean: peak * rest_to_rest / travelled.max(1e-12),
        time_to_peak_share: (peak_t - onset) / mt,
        end: path[to].pos,
    })
}

/// A least-squares line y = a + b·x.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Fit {
    /// Intercept.
    pub a: f64,
    /// Slope.
    pub b: f64,
    /// The share of the variance of y the line explains.
    pub r2: f64,
}

/// The least-squares line through `(x, y)` points (NaN with fewer than two distinct x).
pub fn fit_line(points: &[(f64, f64)]) -> Fit {
    let n = points.len() as f64;
    let (mx, my) = (
        points.iter().map(|p| p.0).sum::<f64>() / n,
        points.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = points.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let syy: f64 = points.iter().map(|p| (p.1 - my).powi(2)).sum();
    // Fewer than two distinct x (or NaN among them): no line.
    if sxx.is_nan() || sxx <= 0.0 {
        return Fit {
            a: f64::NAN,
            b: f64::NAN,
            r2: f64::NAN,
        };
    }
    let b = sxy / sxx;
    Fit {
        a: my - b * mx,
        b,
        r2: if syy > 0.0 {
            sxy * sxy / (sxx * syy)
        } else {
            1.0
        },
    }
}

/// The mean and the sample standard deviation of `xs` (NaN when there are too few).
pub fn mean_sd(xs: &[f64]) -> (f64, f64) {
    let n = xs.len();
    if n == 0 {
        return (f64::NAN, f64::NAN);
    }
    let mean = xs.iter().sum::<f64>() / n as f64;
    if n == 1 {
        return (mean, f64::NAN);
    }
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    (mean, var.sqrt())
}

/// The first sample time at which two recordings of the same hand, one perturbed and one not,
/// part: their positions differ by more than `tol_m` or their velocities by more than
/// `tol_m_s`. Both are sampled at the same instants.
pub fn first_divergence(
    perturbed: &[Sample],
    control: &[Sample],
    tol_m: f64,
    tol_m_s: f64,
) -> Option<f64> {
    perturbed
        .iter()
        .zip(control)
        .find(|(a, b)| (a.pos - b.pos).norm() > tol_m || (a.vel - b.vel).norm() > tol_m_s)
        .map(|(a, _)| a.t_s)
}

/// A mean and the standard deviation across participants (one value each).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MeanSd {
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation (NaN for one participant).
    pub sd: f64,
}

impl MeanSd {
    /// The mean and spread of `xs`.
    pub fn of(xs: &[f64]) -> Self {
        let (mean, sd) = mean_sd(xs);
        Self { mean, sd }
    }

    /// As printed: `mean ± sd` with `prec` decimals (`-` for no spread).
    pub fn show(&self, prec: usize) -> String {
        let sd = if self.sd.is_nan() {
            "-".to_owned()
        } else {
            format!("{:.prec$}", self.sd)
        };
        format!("{:.prec$} ± {sd}", self.mean)
    }
}

/// Minimum jerk's speed at τ = t/T, over its peak: 16 τ²(1 − τ)² (Flash & Hogan 1985).
pub fn min_jerk_bell(tau: f64) -> f64 {
    let tau = tau.clamp(0.0, 1.0);
    16.0 * tau * tau * (1.0 - tau) * (1.0 - tau)
}

/// Where minimum jerk's speed crosses `share` of its peak, as a share of its duration (the
/// earlier root; the later one is 1 minus it).
pub fn min_jerk_crossing(share: f64) -> f64 {
    // 16 τ²(1 − τ)² = share, so τ(1 − τ) = √share / 4.
    let q = share.sqrt() / 4.0;
    0.5 - (0.25 - q).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use coop_model::participant::MinJerk;

    /// A minimum-jerk reach of `d_m` along x lasting `duration_s`, starting at `t0_s`, sampled
    /// every millisecond with `rest_s` of stillness on either side.
    fn reach(d_m: f64, duration_s: f64, t0_s: f64, rest_s: f64) -> Vec<Sample> {
        let m = MinJerk::new(
            t0_s,
            Vec3::zeros(),
            Vec3::zeros(),
            Vec3::zeros(),
            Vec3::new(d_m, 0.0, 0.0),
            duration_s,
        );
        let n = ((duration_s + 2.0 * rest_s) / 1e-3).round() as usize;
        (0..=n)
            .map(|k| {
                let t = t0_s - rest_s + k as f64 * 1e-3;
                let (pos, vel, _) = m.at(t);
                Sample { t_s: t, pos, vel }
            })
            .collect()
    }

    #[test]
    fn a_pure_minimum_jerk_profile_peaks_at_1_875_times_its_mean_speed() {
        // Off the sampling grid too: the reach starts between two samples.
        for (d, dur, t0) in [(0.1, 0.5, 1.0), (0.05, 0.3137, 0.2004), (0.2, 0.83, 0.0)] {
            let f = measure_reach(&reach(d, dur, t0, 0.2)).expect("a reach");
            assert!(
                (f.peak_over_mean / 1.875 - 1.0).abs() < 0.01,
                "D {d} m in {dur} s: peak/mean {}",
                f.peak_over_mean
            );
            assert!((f.time_to_peak_share - 0.5).abs() < 0.005, "{f:?}");
            assert!((f.end.x - d).abs() < 1e-9, "it ended where it went");
            // The 5 % criterion leaves out the two tails.
            let tails = 2.0 * min_jerk_crossing(ONSET_SHARE);
            assert!(
                (f.mt_s / (dur * (1.0 - tails)) - 1.0).abs() < 0.005,
                "{f:?}"
            );
        }
    }

    /// Reaches planned so that their measured movement times follow MT = a + b·ID exactly give
    /// back a and b; the same reaches measured from rest to rest would not (their times are
    /// longer by the tails the 5 % criterion leaves out), so a measurement that took the wrong
    /// span fails here.
    #[test]
    fn the_fit_recovers_a_known_intercept_and_slope_from_synthetic_reaches() {
        let (a, b) = (0.08, 0.11);
        let kept = 1.0 - 2.0 * min_jerk_crossing(ONSET_SHARE);
        let mut points = Vec::new();
        for d in [0.05, 0.1, 0.2] {
            for w in [0.005, 0.01, 0.02] {
                let id = (d / w + 1.0_f64).log2();
                let planned = (a + b * id) / kept;
                let f = measure_reach(&reach(d, planned, 0.3, 0.25)).expect("a reach");
                points.push((id, f.mt_s));
            }
        }
        let fit = fit_line(&points);
        assert!((fit.a - a).abs() < 0.01 * a, "a {} (planned {a})", fit.a);
        assert!((fit.b - b).abs() < 0.01 * b, "b {} (planned {b})", fit.b);
        assert!(fit.r2 > 0.999, "r² {}", fit.r2);
    }

    #[test]
    fn the_line_fit_and_the_spread_match_worked_values() {
        let f = fit_line(&[(0.0, 1.0), (1.0, 3.0), (2.0, 5.0)]);
        assert!((f.a - 1.0).abs() < 1e-12 && (f.b - 2.0).abs() < 1e-12 && f.r2 == 1.0);
        assert!(fit_line(&[(1.0, 1.0), (1.0, 2.0)]).b.is_nan());
        let (m, sd) = mean_sd(&[2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]);
        assert_eq!(m, 5.0);
        assert!((sd - (32.0f64 / 7.0).sqrt()).abs() < 1e-12);
        assert!(mean_sd(&[1.0]).1.is_nan());
    }

    #[test]
    fn the_bell_and_its_crossings_agree() {
        assert!((min_jerk_bell(0.5) - 1.0).abs() < 1e-12);
        let tau = min_jerk_crossing(ONSET_SHARE);
        assert!((min_jerk_bell(tau) - ONSET_SHARE).abs() < 1e-12);
        assert!((min_jerk_bell(1.0 - tau) - ONSET_SHARE).abs() < 1e-12);
    }
}
