//! What a user study would publish from a sweep of a scenario with a live `[task]`: per method and
//! delay, the share of trials done at every site (Wilson 95 % interval), the mean completion time
//! of the trials done (Student 95 % interval) and its ratio to the method's own at the smallest
//! delay, and the phantom contact the worst site was shown; then the method that does best at
//! each delay (the most trials done, then the shortest mean time). With participants drawn per
//! seed, N seeds are N simulated people (pairs, groups) per cell.

use std::fmt::Write;

use serde::Serialize;

use crate::stats::{mean_ci95, wilson95};
use crate::sweep::Row;

/// One method at one delay.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Cell {
    /// Method name.
    pub method: String,
    /// Constant one-way delay, ms.
    pub delay_ms: f64,
    /// Trials (seeds).
    pub trials: usize,
    /// Trials done at every site.
    pub done: usize,
    /// Their share, and its 95 % Wilson interval.
    pub success: (f64, f64, f64),
    /// Mean completion time of the trials done, s, and its 95 % interval (NaN: none done).
    pub completion_s: (f64, f64, f64),
    /// The mean completion time over the method's own at its smallest delay (NaN: either
    /// undefined).
    pub vs_first_delay: f64,
    /// The largest phantom contact one site was shown, ms: mean over trials, and the largest.
    pub phantom_site_ms: (f64, f64),
}

/// The cells of `rows` (rows of a scenario with a `[task]`), by method then delay, in the rows'
/// order.
pub fn cells(rows: &[Row]) -> Vec<Cell> {
    let mut keys: Vec<(String, f64)> = Vec::new();
    for r in rows {
        if !keys.iter().any(|(m, d)| *m == r.method && *d == r.delay_ms) {
            keys.push((r.method.clone(), r.delay_ms));
        }
    }
    let mut out: Vec<Cell> = Vec::new();
    for (method, delay_ms) in keys {
        let of: Vec<&Row> = rows
            .iter()
            .filter(|r| r.method == method && r.delay_ms == delay_ms)
            .collect();
        let times: Vec<f64> = of
            .iter()
            .filter(|r| r.task_done == Some(true))
            .map(|r| r.completion_s)
            .collect();
        let phantom: Vec<f64> = of.iter().map(|r| r.phantom_contact_site_max_ms).collect();
        let completion_s = mean_ci95(&times);
        let first = out
            .iter()
            .find(|c| c.method == method)
            .map_or(completion_s.0, |c| c.completion_s.0);
        out.push(Cell {
            trials: of.len(),
            done: times.len(),
            success: wilson95(times.len(), of.len()),
            completion_s,
            vs_first_delay: completion_s.0 / first,
            phantom_site_ms: (
                phantom.iter().sum::<f64>() / phantom.len().max(1) as f64,
                phantom.iter().copied().fold(0.0, f64::max),
            ),
            method,
            delay_ms,
        });
    }
    out
}

/// At each delay, the method that does best: the most trials done, then the shortest mean
/// completion time (`None` at a delay where no method finished a trial).
pub fn best(cells: &[Cell]) -> Vec<(f64, Option<String>)> {
    let mut delays: Vec<f64> = cells.iter().map(|c| c.delay_ms).collect();
    delays.sort_by(f64::total_cmp);
    delays.dedup();
    delays
        .into_iter()
        .map(|d| {
            let winner = cells
                .iter()
                .filter(|c| c.delay_ms == d && c.done > 0)
                .min_by(|a, b| {
                    b.done
                        .cmp(&a.done)
                        .then(a.completion_s.0.total_cmp(&b.completion_s.0))
                })
                .map(|c| c.method.clone());
            (d, winner)
        })
        .collect()
}

fn num(v: f64, prec: usize) -> String {
    if v.is_nan() {
        "-".to_owned()
    } else {
        format!("{v:.prec$}")
    }
}

/// The summary as a table, with the best method per delay.
pub fn table(cells: &[Cell]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<10}{:>7}{:>8}{:>7}{:>13}{:>11}{:>17}{:>8}{:>14}",
        "task", "delay", "done", "", "95 % CI", "time", "95 % CI", "vs", "phantom/site"
    );
    let _ = writeln!(
        out,
        "{:<10}{:>7}{:>8}{:>7}{:>13}{:>11}{:>17}{:>8}{:>14}",
        "method", "ms", "trials", "%", "%", "mean s", "s", "first", "mean/max ms"
    );
    for c in cells {
        let _ = writeln!(
            out,
            "{:<10}{:>7}{:>8}{:>7}{:>13}{:>11}{:>17}{:>8}{:>14}",
            c.method,
            c.delay_ms,
            format!("{}/{}", c.done, c.trials),
            num(c.success.0 * 100.0, 0),
            format!(
                "[{}, {}]",
                num(c.success.1 * 100.0, 0),
                num(c.success.2 * 100.0, 0)
            ),
            num(c.completion_s.0, 2),
            format!(
                "[{}, {}]",
                num(c.completion_s.1, 2),
                num(c.completion_s.2, 2)
            ),
            num(c.vs_first_delay, 2),
            format!(
                "{}/{}",
                num(c.phantom_site_ms.0, 0),
                num(c.phantom_site_ms.1, 0)
            ),
        );
    }
    let best: Vec<String> = best(cells)
        .into_iter()
        .map(|(d, m)| format!("{d} ms: {}", m.as_deref().unwrap_or("none")))
        .collect();
    let _ = writeln!(
        out,
        "# best (most trials done, then shortest mean time): {}",
        best.join("; ")
    );
    let _ = writeln!(
        out,
        "# done = trials in which every site saw the task done, with the Wilson 95 % interval; time = mean over those trials of when the last site saw it done, with the Student 95 % interval; vs first = that mean over the method's own at its smallest delay; phantom/site = the most contact one site was shown live that the confirmed history took back, mean over trials / largest"
    );
    out
}

/// The plot's lines: per method, (delay, share done %, its interval) and (delay, mean time, its
/// interval).
pub fn lines(cells: &[Cell]) -> Vec<crate::plots::TaskLine> {
    let mut methods: Vec<&str> = Vec::new();
    for c in cells {
        if !methods.contains(&c.method.as_str()) {
            methods.push(&c.method);
        }
    }
    methods
        .into_iter()
        .map(|m| {
            let of = cells.iter().filter(|c| c.method == m);
            crate::plots::TaskLine {
                label: m.to_owned(),
                success_pct: of
                    .clone()
                    .map(|c| {
                        (
                            c.delay_ms,
                            c.success.0 * 100.0,
                            c.success.1 * 100.0,
                            c.success.2 * 100.0,
                        )
                    })
                    .collect(),
                completion_s: of
                    .filter(|c| c.done > 0)
                    .map(|c| {
                        (
                            c.delay_ms,
                            c.completion_s.0,
                            c.completion_s.1,
                            c.completion_s.2,
                        )
                    })
                    .collect(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(method: &str, delay_ms: f64, done: bool, t: f64, phantom: f64) -> Row {
        Row {
            method: method.to_owned(),
            delay_ms,
            task_done: Some(done),
            completion_s: if done { t } else { f64::NAN },
            phantom_contact_site_max_ms: phantom,
            ..Row::default()
        }
    }

    #[test]
    fn cells_count_only_trials_done_everywhere_and_rank_by_success_then_time() {
        let rows = vec![
            row("a", 0.0, true, 8.0, 0.0),
            row("a", 0.0, true, 10.0, 0.0),
            row("a", 300.0, true, 12.0, 40.0),
            row("a", 300.0, false, 99.0, 80.0),
            row("b", 0.0, true, 9.5, 0.0),
            row("b", 0.0, true, 9.5, 0.0),
            row("b", 300.0, true, 20.0, 0.0),
            row("b", 300.0, true, 22.0, 0.0),
        ];
        let c = cells(&rows);
        assert_eq!(c.len(), 4);
        assert_eq!((c[0].done, c[0].trials), (2, 2));
        assert_eq!(c[0].completion_s.0, 9.0);
        assert_eq!((c[1].done, c[1].trials), (1, 2));
        // The failed trial's time is not averaged in.
        assert_eq!(c[1].completion_s.0, 12.0);
        assert!((c[1].vs_first_delay - 12.0 / 9.0).abs() < 1e-12);
        assert_eq!(c[1].phantom_site_ms, (60.0, 80.0));
        let b = best(&c);
        // At 0 both finish every trial: the faster wins; at 300 ms the one that finished both.
        assert_eq!(b[0], (0.0, Some("a".to_owned())));
        assert_eq!(b[1], (300.0, Some("b".to_owned())));
        assert!(table(&c).contains("0 ms: a; 300 ms: b"));
    }
}
