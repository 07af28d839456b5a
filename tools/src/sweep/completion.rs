//! What a user study would publish from a sweep of a scenario with a live `[task]`: per method and
//! delay, the share of trials done at every site (Wilson 95 % interval), the mean completion time
//! of the trials done (Student 95 % interval) and its ratio to the method's own at its smallest
//! delay with trials done, over the same participants (the seeds done at both), and the phantom
//! contact the worst site was shown; then the method that does best at each delay on the point
//! estimates (the most trials done, then the shortest mean time). With participants drawn per
//! seed, N seeds are N simulated people (pairs, groups) per cell, the same N at every delay.

use std::fmt::Write;

use serde::Serialize;

use super::Row;
use crate::figures::or_dash as num;
use crate::stats::{mean_ci95, wilson95};

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
    /// The mean completion time over the method's own at its smallest delay with trials done,
    /// both over the seeds done at both delays: the same participants (NaN: no such seed).
    pub vs_least_delay: f64,
    /// The largest phantom contact one site was shown, ms: mean over trials, and the largest.
    pub phantom_site_ms: (f64, f64),
}

/// Names in the order they first appear.
pub fn first_seen<'a>(names: impl IntoIterator<Item = &'a str>) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for n in names {
        if !out.contains(&n) {
            out.push(n);
        }
    }
    out
}

/// The cells of `rows` (rows of a scenario with a `[task]`), by method (in the rows' order)
/// then by delay (ascending).
pub fn cells(rows: &[Row]) -> Vec<Cell> {
    let mut out: Vec<Cell> = Vec::new();
    for method in first_seen(rows.iter().map(|r| r.method.as_str())) {
        let of_method: Vec<&Row> = rows.iter().filter(|r| r.method == method).collect();
        let mut delays: Vec<f64> = of_method.iter().map(|r| r.delay_ms).collect();
        delays.sort_by(f64::total_cmp);
        delays.dedup();
        // (seed, completion time) of the trials done at a delay.
        let done_at = |d: f64| -> Vec<(u64, f64)> {
            of_method
                .iter()
                .filter(|r| r.delay_ms == d && r.task_done == Some(true))
                .map(|r| (r.seed, r.completion_s))
                .collect()
        };
        let least = delays.iter().copied().find(|&d| !done_at(d).is_empty());
        for &delay_ms in &delays {
            let of: Vec<&&Row> = of_method
                .iter()
                .filter(|r| r.delay_ms == delay_ms)
                .collect();
            let done = done_at(delay_ms);
            let times: Vec<f64> = done.iter().map(|d| d.1).collect();
            let phantom: Vec<f64> = of.iter().map(|r| r.phantom_contact_site_max_ms).collect();
            // The same participants at both delays: the seeds done at both.
            let vs_least_delay = least.map_or(f64::NAN, |l| {
                let base = done_at(l);
                let (mut here, mut there) = (0.0, 0.0);
                for &(seed, t) in &done {
                    if let Some(&(_, t0)) = base.iter().find(|b| b.0 == seed) {
                        here += t;
                        there += t0;
                    }
                }
                if there > 0.0 {
                    here / there
                } else {
                    f64::NAN
                }
            });
            out.push(Cell {
                method: method.to_owned(),
                delay_ms,
                trials: of.len(),
                done: times.len(),
                success: wilson95(times.len(), of.len()),
                completion_s: mean_ci95(&times),
                vs_least_delay,
                phantom_site_ms: (
                    phantom.iter().sum::<f64>() / phantom.len().max(1) as f64,
                    phantom.iter().copied().fold(0.0, f64::max),
                ),
            });
        }
    }
    out
}

/// At each delay, the method that does best on the point estimates: the most trials done, then
/// the shortest mean completion time (`None` at a delay where no method finished a trial). The
/// intervals say whether the difference means anything.
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
        "method", "ms", "trials", "%", "%", "mean s", "s", "least", "mean/max ms"
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
            num(c.vs_least_delay, 2),
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
        "# best on the point estimates (most trials done, then shortest mean time; see the intervals): {}",
        best.join("; ")
    );
    let _ = writeln!(
        out,
        "# done = trials in which every site saw the task done, with the Wilson 95 % interval; time = mean over those trials of when the last site saw it done, with the Student 95 % interval ('-' for one trial); vs least = the mean time over the method's own at its smallest delay with trials done, both over the seeds (participants) done at both; phantom/site = the most contact one site was shown live that the confirmed history took back, mean over trials / largest"
    );
    out
}

/// The plot's lines: per method, (delay, share done %, its interval) and (delay, mean time, its
/// interval).
pub fn lines(cells: &[Cell]) -> Vec<crate::plots::TaskLine> {
    first_seen(cells.iter().map(|c| c.method.as_str()))
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

    fn row(method: &str, delay_ms: f64, seed: u64, done: bool, t: f64, phantom: f64) -> Row {
        Row {
            method: method.to_owned(),
            delay_ms,
            seed,
            task_done: Some(done),
            completion_s: if done { t } else { f64::NAN },
            phantom_contact_site_max_ms: phantom,
            ..Row::default()
        }
    }

    #[test]
    fn cells_count_only_trials_done_everywhere_and_rank_by_success_then_time() {
        // Given out of delay order: the cells come sorted.
        let rows = vec![
            row("a", 300.0, 1, true, 12.0, 40.0),
            row("a", 300.0, 2, false, 99.0, 80.0),
            row("a", 0.0, 1, true, 8.0, 0.0),
            row("a", 0.0, 2, true, 10.0, 0.0),
            row("b", 0.0, 1, true, 9.5, 0.0),
            row("b", 0.0, 2, true, 9.5, 0.0),
            row("b", 300.0, 1, true, 20.0, 0.0),
            row("b", 300.0, 2, true, 22.0, 0.0),
        ];
        let c = cells(&rows);
        assert_eq!(c.len(), 4);
        assert_eq!((c[0].delay_ms, c[1].delay_ms), (0.0, 300.0));
        assert_eq!((c[0].done, c[0].trials), (2, 2));
        assert_eq!(c[0].completion_s.0, 9.0);
        assert_eq!((c[1].done, c[1].trials), (1, 2));
        // The failed trial's time is not averaged in, and one trial has no interval.
        assert_eq!(c[1].completion_s.0, 12.0);
        assert!(c[1].completion_s.1.is_nan());
        // Against the same participant at 0 ms (seed 1: 8 s), not the mean of both (9 s).
        assert!((c[1].vs_least_delay - 12.0 / 8.0).abs() < 1e-12);
        assert!((c[3].vs_least_delay - 42.0 / 19.0).abs() < 1e-12);
        assert_eq!(c[1].phantom_site_ms, (60.0, 80.0));
        let b = best(&c);
        // At 0 both finish every trial: the faster wins; at 300 ms the one that finished both.
        assert_eq!(b[0], (0.0, Some("a".to_owned())));
        assert_eq!(b[1], (300.0, Some("b".to_owned())));
        assert!(table(&c).contains("0 ms: a; 300 ms: b"));
    }
}
