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

/// The standard deviation of `xs` (n − 1 in the denominator; NaN for fewer than two values).
pub fn sd(xs: &[f64]) -> f64 {
    let n = xs.len();
    if n < 2 {
        return f64::NAN;
    }
    let mean = xs.iter().sum::<f64>() / n as f64;
    (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
}

/// Within-subject 95 % intervals of condition means (Cousineau 2005, with Morey 2008's
/// correction): `by_subject[s][c]` is subject `s`'s value in condition `c`, every subject having
/// one in every condition. Each value is normalized by removing its subject's mean and adding
/// the grand mean, so the interval shows the conditions' differences without the spread between
/// subjects; Morey's factor √(C/(C−1)) undoes the normalization's shrinking of the variance.
/// Returns, per condition, `(mean, lo, hi)` (intervals NaN with fewer than two subjects or
/// conditions).
pub fn cousineau_morey95(by_subject: &[Vec<f64>]) -> Vec<(f64, f64, f64)> {
    let n = by_subject.len();
    let c = by_subject.first().map_or(0, Vec::len);
    if n == 0 || c == 0 || by_subject.iter().any(|row| row.len() != c) {
        return Vec::new();
    }
    let grand = by_subject.iter().flatten().sum::<f64>() / (n * c) as f64;
    let normalized: Vec<Vec<f64>> = by_subject
        .iter()
        .map(|row| {
            let own = row.iter().sum::<f64>() / c as f64;
            row.iter().map(|y| y - own + grand).collect()
        })
        .collect();
    let morey = if c > 1 {
        (c as f64 / (c - 1) as f64).sqrt()
    } else {
        f64::NAN
    };
    (0..c)
        .map(|k| {
            let col: Vec<f64> = normalized.iter().map(|row| row[k]).collect();
            let raw: Vec<f64> = by_subject.iter().map(|row| row[k]).collect();
            let mean = raw.iter().sum::<f64>() / n as f64;
            let half = t975(n.saturating_sub(1)) * sd(&col) / (n as f64).sqrt() * morey;
            (mean, mean - half, mean + half)
        })
        .collect()
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7, nine terms: about 15 digits).
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x) Γ(1 − x) = π / sin(πx).
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let t = x + 7.5;
    let sum = G[1..]
        .iter()
        .enumerate()
        .fold(G[0], |acc, (k, g)| acc + g / (x + k as f64 + 1.0));
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

/// The regularized incomplete beta function I_x(a, b), by its continued fraction (Lentz's
/// method, as Numerical Recipes §6.4 evaluates it).
fn incomplete_beta(x: f64, a: f64, b: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let front =
        (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln()).exp();
    // The fraction converges fast for x below (a + 1) / (a + b + 2); above, by symmetry.
    if x > (a + 1.0) / (a + b + 2.0) {
        return 1.0 - incomplete_beta(1.0 - x, b, a);
    }
    let tiny = 1e-300;
    let (mut c, mut d) = (1.0, 1.0 - (a + b) * x / (a + 1.0));
    d = if d.abs() < tiny { tiny } else { d };
    d = 1.0 / d;
    let mut f = d;
    for m in 1..300 {
        let m = f64::from(m);
        for num in [
            m * (b - m) * x / ((a + 2.0 * m - 1.0) * (a + 2.0 * m)),
            -(a + m) * (a + b + m) * x / ((a + 2.0 * m) * (a + 2.0 * m + 1.0)),
        ] {
            d = 1.0 + num * d;
            d = if d.abs() < tiny { tiny } else { d };
            c = 1.0 + num / c;
            c = if c.abs() < tiny { tiny } else { c };
            d = 1.0 / d;
            f *= d * c;
        }
        if (d * c - 1.0).abs() < 1e-15 {
            break;
        }
    }
    front * f / a
}

/// The probability that an F(`df1`, `df2`) variable exceeds `f`: an F test's p value (NaN for
/// a non-finite `f` or a degree of freedom of 0).
pub fn f_test_p(f: f64, df1: f64, df2: f64) -> f64 {
    if !(f.is_finite() && df1 > 0.0 && df2 > 0.0) {
        return f64::NAN;
    }
    if f <= 0.0 {
        return 1.0;
    }
    incomplete_beta(df2 / (df2 + df1 * f), df2 / 2.0, df1 / 2.0)
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

    #[test]
    fn f_test_p_values_match_the_tables() {
        // The 5 % critical values of F: F(1, 10) = 4.965, F(2, 20) = 3.493, F(3, 33) = 2.892;
        // the 1 % one of F(1, 11) = 9.646.
        for (f, d1, d2, p) in [
            (4.965, 1.0, 10.0, 0.05),
            (3.493, 2.0, 20.0, 0.05),
            (2.892, 3.0, 33.0, 0.05),
            (9.646, 1.0, 11.0, 0.01),
        ] {
            let got = f_test_p(f, d1, d2);
            assert!(
                (got - p).abs() < 2e-4,
                "F({d1}, {d2}) = {f}: p {got}, tables {p}"
            );
        }
        assert_eq!(f_test_p(0.0, 1.0, 10.0), 1.0);
        assert!(f_test_p(f64::NAN, 1.0, 10.0).is_nan());
        assert!(f_test_p(1.0, 0.0, 10.0).is_nan());
    }

    #[test]
    fn within_subject_intervals_remove_the_spread_between_subjects() {
        // Three subjects, each 1 s slower in condition 2 than 1, with very different baselines:
        // the plain interval is wide, the within-subject one has no width (a constant effect).
        let by = vec![vec![5.0, 6.0], vec![10.0, 11.0], vec![20.0, 21.0]];
        let cm = cousineau_morey95(&by);
        assert_eq!(cm.len(), 2);
        assert!((cm[0].0 - 35.0 / 3.0).abs() < 1e-12 && (cm[1].0 - 38.0 / 3.0).abs() < 1e-12);
        assert!((cm[0].2 - cm[0].1).abs() < 1e-9, "{cm:?}");
        let plain = mean_ci95(&[5.0, 10.0, 20.0]);
        assert!(plain.2 - plain.1 > 10.0);
        // A worked example: normalized values of condition 1 are 11/3 ± (−1, +1, 0)... of 2:
        // subject effects vary, so the interval is t(2) · sd / √3 · √2.
        let by = vec![vec![1.0, 3.0], vec![2.0, 2.0], vec![3.0, 4.0]];
        let cm = cousineau_morey95(&by);
        // Grand mean 2.5; normalized condition 1: 1 − 2 + 2.5, 2 − 2 + 2.5, 3 − 3.5 + 2.5.
        let col = [1.5, 2.5, 2.0];
        let half = t975(2) * sd(&col) / 3f64.sqrt() * 2f64.sqrt();
        assert!((cm[0].2 - 2.0 - half).abs() < 1e-12, "{cm:?}");
        assert!(cousineau_morey95(&[vec![1.0], vec![1.0, 2.0]]).is_empty());
    }
}
