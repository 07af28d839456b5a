//! The few statistics a pilot study's table needs: a mean with its 95 % confidence interval
//! (Student's t) and a proportion with its 95 % Wilson score interval, which stays inside [0, 1]
//! and does not collapse to a point at 0 % or 100 % as the normal approximation does (Wilson
//! 1927; Brown, Cai & DasGupta 2001 recommend it for small n).

/// The standard normal's 0.975 quantile.
const Z975: f64 = 1.959_964;

/// Student's t, two-sided 95 % (the 0.975 quantile), for 1 to 30 degrees of freedom.
const T975: [f64; 30] = [
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
    2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
    2.052, 2.048, 2.045, 2.042,
];

/// The 0.975 quantile of Student's t with `df` degrees of freedom (`df` ≥ 1; beyond 30 the
/// first two terms of its Cornish–Fisher series in 1/df, within 0.001 of the exact value there).
pub fn t975(df: usize) -> f64 {
    match df {
        0 => f64::NAN,
        1..=30 => T975[df - 1],
        _ => {
            let (z, n) = (Z975, df as f64);
            z + (z.powi(3) + z) / (4.0 * n)
                + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * n * n)
        }
    }
}

/// The mean of `xs` and its 95 % confidence interval `(mean, lo, hi)` (all NaN for an empty set;
/// the interval NaN for one value, whose spread cannot be estimated).
pub fn mean_ci95(xs: &[f64]) -> (f64, f64, f64) {
    let n = xs.len();
    if n == 0 {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let mean = xs.iter().sum::<f64>() / n as f64;
    if n == 1 {
        return (mean, f64::NAN, f64::NAN);
    }
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let half = t975(n - 1) * (var / n as f64).sqrt();
    (mean, mean - half, mean + half)
}

/// `k` successes of `n` as a proportion with its 95 % Wilson score interval `(p, lo, hi)`
/// (NaN for `n` = 0).
pub fn wilson95(k: usize, n: usize) -> (f64, f64, f64) {
    if n == 0 {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let z = Z975;
    let (nf, p) = (n as f64, k as f64 / n as f64);
    let denom = 1.0 + z * z / nf;
    let centre = (p + z * z / (2.0 * nf)) / denom;
    let half = z / denom * (p * (1.0 - p) / nf + z * z / (4.0 * nf * nf)).sqrt();
    (p, (centre - half).max(0.0), (centre + half).min(1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mean_interval_matches_a_worked_example() {
        // 5 values, mean 3, sd sqrt(2.5): half-width t(4) * sd / sqrt(5) = 2.776 * 0.7071.
        let (m, lo, hi) = mean_ci95(&[1.0, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(m, 3.0);
        assert!((hi - 3.0 - 2.776 * (2.5f64 / 5.0).sqrt()).abs() < 1e-9);
        assert!((3.0 - lo - (hi - 3.0)).abs() < 1e-12);
        assert!(mean_ci95(&[]).0.is_nan());
        let (m, lo, hi) = mean_ci95(&[7.0]);
        assert!(m == 7.0 && lo.is_nan() && hi.is_nan());
    }

    #[test]
    fn t_beyond_the_table_joins_it_and_tends_to_z() {
        // Exact: t(31) = 2.0395, t(60) = 2.0003.
        assert!((t975(31) - 2.0395).abs() < 1e-3, "{}", t975(31));
        assert!((t975(60) - 2.0003).abs() < 1e-3, "{}", t975(60));
        assert!((t975(1000) - 1.962).abs() < 1e-3);
        assert!(t975(0).is_nan());
    }

    #[test]
    fn wilson_stays_inside_zero_and_one_and_matches_published_values() {
        // 20 of 20: Wilson's lower bound 0.839 (Brown, Cai & DasGupta's tables give 0.8389).
        let (p, lo, hi) = wilson95(20, 20);
        assert_eq!(p, 1.0);
        assert!((lo - 0.8389).abs() < 1e-3, "{lo}");
        assert_eq!(hi, 1.0);
        let (p, lo, hi) = wilson95(0, 20);
        assert_eq!((p, lo), (0.0, 0.0));
        assert!((hi - 0.1611).abs() < 1e-3, "{hi}");
        let (_, lo, hi) = wilson95(10, 20);
        assert!(
            (lo - 0.2993).abs() < 1e-3 && (hi - 0.7007).abs() < 1e-3,
            "{lo} {hi}"
        );
        assert!(wilson95(0, 0).0.is_nan());
    }
}
