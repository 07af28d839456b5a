//! `study report DIR`: from a run's trial table, per condition the share of trials done (Wilson
//! 95 % interval) and the completion time (mean, SD, Student and within-subject 95 % intervals,
//! Cousineau–Morey), a repeated-measures ANOVA of the completion time on the within-group
//! factors, the per-group cell means for R's `afex` or Python's `pingouin` (`cells.csv`), and the
//! plots of success and completion time against a numeric factor (the delay), one line per
//! level of the others.
//!
//! A trial is the group's: it is done when every site saw the task done, and its completion time
//! is when the last site did. Practice trials are left out. The subject of the within-group
//! statistics is the group (its members are not independent of one another), and a group enters
//! them with its mean over its measured trials of a condition that it completed; a group that
//! completed no trial of some condition is left out of them (listwise), and the report says how
//! many were.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context};

use super::StudyFile;
use crate::stats::{cousineau_morey95, f_test_p, mean_ci95, sd, wilson95};

/// One measured trial of one group.
#[derive(Debug, Clone)]
struct TrialRow {
    /// The attempt these figures are of (the last one counts: an experimenter's repeat).
    attempt: u32,
    group: String,
    levels: Vec<String>,
    done: bool,
    completion_s: f64,
    phantom_ms: f64,
}

/// One condition's figures.
#[derive(Debug, Clone)]
pub struct ConditionFigures {
    /// Each factor's level.
    pub levels: Vec<String>,
    /// Measured trials, and those done at every site.
    pub trials: usize,
    /// See `trials`.
    pub done: usize,
    /// Share done, Wilson 95 %.
    pub success: (f64, f64, f64),
    /// Completion time of the trials done, s: mean and Student 95 %.
    pub completion_s: (f64, f64, f64),
    /// Its SD, s.
    pub completion_sd_s: f64,
    /// The mean of the groups' means with its within-subject 95 % interval (the groups with a
    /// trial done in every condition of their between-group cell; NaN otherwise).
    pub within_s: (f64, f64, f64),
    /// The largest phantom contact one site was shown, mean over trials, ms.
    pub phantom_ms: f64,
}

/// An ANOVA effect.
#[derive(Debug, Clone, PartialEq)]
pub struct Effect {
    /// The factors, joined by ×.
    pub name: String,
    /// F, its degrees of freedom and p.
    pub f: f64,
    /// See `f`.
    pub df: (f64, f64),
    /// See `f`.
    pub p: f64,
    /// Partial eta squared, SS_effect / (SS_effect + SS_error).
    pub eta_p2: f64,
}

/// A repeated-measures ANOVA of `y[s][cell]` (every subject a value in every cell), the cells
/// the product of `levels` (the last factor fastest): one [`Effect`] per non-empty set of factors,
/// each tested against its interaction with the subjects. No sphericity correction: for a factor
/// of more than two levels the p values are those of the uncorrected test (see `docs/study.md`
/// for the Greenhouse–Geisser correction `afex` and `pingouin` give).
pub fn rm_anova(names: &[String], levels: &[usize], y: &[Vec<f64>]) -> Vec<Effect> {
    let n = y.len();
    let k = levels.len();
    let cells: usize = levels.iter().product();
    if n < 2 || k == 0 || y.iter().any(|r| r.len() != cells) {
        return Vec::new();
    }
    // Dims: subject, then the factors; an observation's index in each.
    let dims: Vec<usize> = std::iter::once(n).chain(levels.iter().copied()).collect();
    let index = |s: usize, cell: usize| -> Vec<usize> {
        let mut idx = vec![s];
        let mut rest = cell;
        let mut f = vec![0; k];
        for d in (0..k).rev() {
            f[d] = rest % levels[d];
            rest /= levels[d];
        }
        idx.extend(f);
        idx
    };
    let obs: Vec<(Vec<usize>, f64)> = (0..n)
        .flat_map(|s| (0..cells).map(move |c| (s, c)))
        .map(|(s, c)| (index(s, c), y[s][c]))
        .collect();
    // The marginal means over every set of dims (bit d: dim d kept).
    let mut means: BTreeMap<(u32, Vec<usize>), (f64, usize)> = BTreeMap::new();
    for mask in 0..(1u32 << dims.len()) {
        for (idx, v) in &obs {
            let key: Vec<usize> = (0..dims.len())
                .map(|d| if mask >> d & 1 == 1 { idx[d] } else { 0 })
                .collect();
            let e = means.entry((mask, key)).or_insert((0.0, 0));
            e.0 += v;
            e.1 += 1;
        }
    }
    let mean = |mask: u32, idx: &[usize]| -> f64 {
        let key: Vec<usize> = (0..dims.len())
            .map(|d| if mask >> d & 1 == 1 { idx[d] } else { 0 })
            .collect();
        let (s, c) = means[&(mask, key)];
        s / c as f64
    };
    // The sum of squares of the effect of the dims in `mask` (inclusion–exclusion over its
    // subsets: each cell's mean less every lower-order effect).
    let ss = |mask: u32| -> f64 {
        obs.iter()
            .map(|(idx, _)| {
                let mut e = 0.0;
                let mut sub = mask;
                loop {
                    let sign = if (mask.count_ones() - sub.count_ones()).is_multiple_of(2) {
                        1.0
                    } else {
                        -1.0
                    };
                    e += sign * mean(sub, idx);
                    if sub == 0 {
                        break;
                    }
                    sub = (sub - 1) & mask;
                }
                e * e
            })
            .sum()
    };
    let mut out = Vec::new();
    for effect in 1..(1u32 << k) {
        let mask = effect << 1;
        let df1: f64 = (0..k)
            .filter(|d| effect >> d & 1 == 1)
            .map(|d| (levels[d] - 1) as f64)
            .product();
        let df2 = df1 * (n - 1) as f64;
        let (ss_e, ss_err) = (ss(mask), ss(mask | 1));
        let f = if ss_err > 0.0 {
            (ss_e / df1) / (ss_err / df2)
        } else {
            f64::NAN
        };
        out.push(Effect {
            name: (0..k)
                .filter(|d| effect >> d & 1 == 1)
                .map(|d| names[d].clone())
                .collect::<Vec<_>>()
                .join(" × "),
            f,
            df: (df1, df2),
            p: f_test_p(f, df1, df2),
            eta_p2: ss_e / (ss_e + ss_err),
        });
    }
    out
}

/// Per condition (its levels), a mean and its 95 % interval.
type Intervals = BTreeMap<Vec<String>, (f64, f64, f64)>;

/// A run's measured trials, read from its directory.
#[derive(Debug)]
struct Run {
    study: StudyFile,
    factors: Vec<String>,
    /// Per (group, trial).
    trials: BTreeMap<(String, usize), TrialRow>,
    /// Practice trials left out.
    practice: usize,
    /// The conditions, in the study file's order of levels.
    conditions: Vec<Vec<String>>,
    groups: Vec<String>,
}

impl Run {
    /// Reads `dir`'s study file and trial table.
    fn read(dir: &Path) -> anyhow::Result<Self> {
        let table = super::trials_file(dir)?;
        let study_path = dir.join("study.toml");
        let study: StudyFile = toml::from_str(
            &std::fs::read_to_string(&study_path)
                .with_context(|| format!("reading {}", study_path.display()))?,
        )
        .with_context(|| format!("{}", study_path.display()))?;
        let text = std::fs::read_to_string(&table)
            .with_context(|| format!("reading {}", table.display()))?;
        let mut lines = text.lines();
        let header = super::csv::Header::new(lines.next().unwrap_or_default(), &table);
        let head = &header.cells;
        let col = |name: &str| header.col(name);
        let factors: Vec<String> = study.factor.iter().map(|f| f.name.clone()).collect();
        let fcols: Vec<usize> = factors.iter().map(|f| col(f)).collect::<Result<_, _>>()?;
        let (c_group, c_trial, c_practice, c_done, c_completion, c_phantom) = (
            col("group")?,
            col("trial")?,
            col("practice")?,
            col("trial_done")?,
            col("completion_s")?,
            col("phantom_ms")?,
        );
        let c_attempt = col("attempt")?;
        // Per (group, trial): its last attempt's rows' figures.
        let mut trials: BTreeMap<(String, usize), TrialRow> = BTreeMap::new();
        let mut practice = std::collections::BTreeSet::new();
        for (k, line) in lines.enumerate() {
            let cells = super::csv::split(line);
            if cells.len() != head.len() {
                bail!(
                    "{} line {}: {} cells, the header has {}",
                    table.display(),
                    k + 2,
                    cells.len(),
                    head.len()
                );
            }
            let key = (
                cells[c_group].clone(),
                cells[c_trial].parse::<usize>().unwrap_or(0),
            );
            if cells[c_practice] == "1" {
                practice.insert(key);
                continue;
            }
            let phantom = cells[c_phantom].parse::<f64>().unwrap_or(f64::NAN);
            let attempt = cells[c_attempt].parse::<u32>().unwrap_or(1);
            let fresh = TrialRow {
                attempt,
                group: cells[c_group].clone(),
                levels: fcols.iter().map(|&c| cells[c].clone()).collect(),
                done: cells[c_done] == "1",
                completion_s: cells[c_completion].parse::<f64>().unwrap_or(f64::NAN),
                phantom_ms: 0.0,
            };
            let row = trials.entry(key).or_insert_with(|| fresh.clone());
            if attempt > row.attempt {
                *row = fresh;
            }
            if attempt == row.attempt {
                row.phantom_ms = row.phantom_ms.max(phantom);
            }
        }
        if trials.is_empty() {
            bail!("{}: no measured trial yet", table.display());
        }
        // The conditions, in the levels' order of the study file.
        let conditions =
            super::in_level_order(&study, trials.values().map(|t| t.levels.clone()).collect());
        let groups: Vec<String> = {
            let mut g: Vec<String> = trials.values().map(|t| t.group.clone()).collect();
            g.sort();
            g.dedup();
            g
        };
        Ok(Self {
            study,
            factors,
            trials,
            practice: practice.len(),
            conditions,
            groups,
        })
    }

    /// Group `g` in condition `c`: its measured trials, those done, their mean completion time
    /// (NaN: none done), and the mean of the largest phantom contact a site was shown.
    fn cell(&self, g: &str, c: &[String]) -> (usize, usize, f64, f64) {
        let of: Vec<&TrialRow> = self
            .trials
            .values()
            .filter(|t| t.group == g && t.levels == c)
            .collect();
        let done: Vec<f64> = of
            .iter()
            .filter(|t| t.done)
            .map(|t| t.completion_s)
            .collect();
        let mean = if done.is_empty() {
            f64::NAN
        } else {
            done.iter().sum::<f64>() / done.len() as f64
        };
        let phantom = of.iter().map(|t| t.phantom_ms).sum::<f64>() / of.len().max(1) as f64;
        (of.len(), done.len(), mean, phantom)
    }

    /// The within-group statistics: each condition's Cousineau–Morey interval (per between-group
    /// cell, over its groups with a trial done in every condition), the ANOVAs' text, and the
    /// group cells left out.
    fn within(&self) -> (Intervals, String, usize) {
        let between: Vec<bool> = self.study.factor.iter().map(|f| f.between).collect();
        let within_idx: Vec<usize> = (0..self.factors.len()).filter(|&f| !between[f]).collect();
        let between_key = |c: &[String]| -> Vec<String> {
            (0..c.len())
                .filter(|&f| between[f])
                .map(|f| c[f].clone())
                .collect()
        };
        // Within-subject intervals per between-group cell, over its complete groups.
        let mut within: Intervals = BTreeMap::new();
        let mut left_out = 0usize;
        let mut anova_text = String::new();
        let mut bcells: Vec<Vec<String>> = self.conditions.iter().map(|c| between_key(c)).collect();
        bcells.dedup();
        bcells.sort();
        bcells.dedup();
        for b in &bcells {
            let conds: Vec<&Vec<String>> = self
                .conditions
                .iter()
                .filter(|c| &between_key(c) == b)
                .collect();
            let mut y: Vec<Vec<f64>> = Vec::new();
            // Each group's share of trials done per condition (every group that did them all).
            let mut shares: Vec<Vec<f64>> = Vec::new();
            for g in &self.groups {
                let row: Vec<(usize, f64)> = conds
                    .iter()
                    .map(|c| {
                        let (n, _, m, _) = self.cell(g, c);
                        (n, m)
                    })
                    .collect();
                if row.iter().all(|(n, _)| *n == 0) {
                    continue;
                }
                if row.iter().all(|(n, _)| *n > 0) {
                    shares.push(
                        conds
                            .iter()
                            .map(|c| {
                                let (n, k, _, _) = self.cell(g, c);
                                k as f64 / n as f64
                            })
                            .collect(),
                    );
                }
                if row.iter().all(|(_, m)| m.is_finite()) {
                    y.push(row.into_iter().map(|(_, m)| m).collect());
                } else {
                    left_out += 1;
                }
            }
            for (c, ci) in conds.iter().zip(cousineau_morey95(&y)) {
                within.insert((*c).clone(), ci);
            }
            // The ANOVA needs the conditions to be the full product of the within factors' levels.
            let levels: Vec<usize> = within_idx
                .iter()
                .map(|&f| {
                    let mut l: Vec<&String> = conds.iter().map(|c| &c[f]).collect();
                    l.sort();
                    l.dedup();
                    l.len()
                })
                .collect();
            let names: Vec<String> = within_idx
                .iter()
                .map(|&f| self.factors[f].clone())
                .collect();
            if conds.len() == levels.iter().product::<usize>() {
                if !b.is_empty() {
                    let _ = writeln!(anova_text, "# between-group cell {}", b.join(", "));
                }
                for (what, data) in [
                    (
                        "the completion time (groups that completed a trial in every condition)",
                        &y,
                    ),
                    (
                        "the share of trials done (groups that did every condition)",
                        &shares,
                    ),
                ] {
                    let effects = rm_anova(&names, &levels, data);
                    if effects.is_empty() {
                        let _ = writeln!(
                            anova_text,
                            "# no repeated-measures ANOVA of {what}: {} groups (at least 2 needed)",
                            data.len()
                        );
                        continue;
                    }
                    let _ = writeln!(
                        anova_text,
                        "# repeated-measures ANOVA of {what}, {} groups, no sphericity correction",
                        data.len()
                    );
                    for e in effects {
                        let _ = writeln!(
                            anova_text,
                            "{:<28} F({:.0}, {:.0}) = {:>8.3}  p {}  partial eta² = {}",
                            e.name,
                            e.df.0,
                            e.df.1,
                            e.f,
                            if e.p < 1e-4 {
                                "< 0.0001".to_owned()
                            } else {
                                format!("= {}", crate::figures::or_dash(e.p, 4))
                            },
                            crate::figures::or_dash(e.eta_p2, 3)
                        );
                    }
                }
            }
        }
        (within, anova_text, left_out)
    }

    /// Each condition's figures, with the within-group intervals `within`.
    fn figures(&self, within: &Intervals) -> Vec<ConditionFigures> {
        self.conditions
            .iter()
            .map(|c| {
                let of: Vec<&TrialRow> = self.trials.values().filter(|t| &t.levels == c).collect();
                let done: Vec<f64> = of
                    .iter()
                    .filter(|t| t.done)
                    .map(|t| t.completion_s)
                    .collect();
                ConditionFigures {
                    levels: c.clone(),
                    trials: of.len(),
                    done: done.len(),
                    success: wilson95(done.len(), of.len()),
                    completion_s: mean_ci95(&done),
                    completion_sd_s: sd(&done),
                    within_s: within
                        .get(c)
                        .copied()
                        .unwrap_or((f64::NAN, f64::NAN, f64::NAN)),
                    phantom_ms: of.iter().map(|t| t.phantom_ms).sum::<f64>() / of.len() as f64,
                }
            })
            .collect()
    }

    /// `cells.csv`: one row per group and condition, as afex and pingouin read it.
    fn cells_csv(&self) -> String {
        // cells.csv: one row per group and condition, as afex and pingouin read it.
        let mut cells_csv = format!(
            "group,{},trials,done,success_rate,completion_s,phantom_ms\n",
            self.factors.join(",")
        );
        for g in &self.groups {
            for c in &self.conditions {
                let (n, k, m, ph) = self.cell(g, c);
                if n == 0 {
                    continue;
                }
                let _ = writeln!(
                    cells_csv,
                    "{g},{},{n},{k},{:.4},{},{:.1}",
                    c.iter()
                        .map(|l| super::csv::cell(l))
                        .collect::<Vec<_>>()
                        .join(","),
                    k as f64 / n as f64,
                    if m.is_finite() {
                        format!("{m:.4}")
                    } else {
                        String::new()
                    },
                    ph
                );
            }
        }
        cells_csv
    }
}

/// The report's table and notes.
fn text(run: &Run, figures: &[ConditionFigures], left_out: usize, anova_text: &str) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# study {}: {} groups, {} measured trials ({} practice trials left out), {} conditions",
        run.study.name,
        run.groups.len(),
        run.trials.len(),
        run.practice,
        run.conditions.len()
    );
    let w = run
        .factors
        .iter()
        .map(String::len)
        .max()
        .unwrap_or(6)
        .max(8);
    let _ = write!(
        out,
        "{}",
        run.factors
            .iter()
            .map(|f| format!("{f:<w$} "))
            .collect::<String>()
    );
    let _ = writeln!(
        out,
        "{:>7} {:>6} {:>11} {:>8} {:>7} {:>15} {:>15} {:>9}",
        "trials", "done %", "95 % CI", "time s", "SD s", "95 % CI", "within 95 % CI", "phantom"
    );
    let range = |lo: f64, hi: f64, prec: usize| {
        if lo.is_nan() {
            "-".to_owned()
        } else {
            format!("[{lo:.prec$}, {hi:.prec$}]")
        }
    };
    for c in figures {
        let _ = write!(
            out,
            "{}",
            c.levels
                .iter()
                .map(|l| format!("{l:<w$} "))
                .collect::<String>()
        );
        let _ = writeln!(
            out,
            "{:>7} {:>6.0} {:>11} {:>8} {:>7} {:>15} {:>15} {:>9.0}",
            format!("{}/{}", c.done, c.trials),
            c.success.0 * 100.0,
            range(c.success.1 * 100.0, c.success.2 * 100.0, 0),
            crate::figures::or_dash(c.completion_s.0, 2),
            crate::figures::or_dash(c.completion_sd_s, 2),
            range(c.completion_s.1, c.completion_s.2, 2),
            range(c.within_s.1, c.within_s.2, 2),
            c.phantom_ms
        );
    }
    let _ = writeln!(
        out,
        "# done = trials done at every site (Wilson 95 % interval); time = mean completion time of those (when the last site saw it done) with its SD and Student 95 % interval; within = Cousineau–Morey within-group 95 % interval of the groups' means ({left_out} group cells left out: no trial done in some condition); phantom = the largest phantom contact one site was shown, mean over trials, ms"
    );
    out.push_str(anova_text);
    out
}

/// The plots against the first numeric factor, if any; the line saying so.
fn plot(dir: &Path, run: &Run, figures: &[ConditionFigures]) -> anyhow::Result<Option<String>> {
    // The plot: against the first factor whose levels are all numbers, a line per level of the
    // others.
    let numeric = (0..run.factors.len()).find(|&f| {
        run.study.factor[f]
            .levels
            .iter()
            .all(|v| matches!(v, toml::Value::Integer(_) | toml::Value::Float(_)))
    });
    if let Some(x) = numeric {
        let mut lines: Vec<crate::plots::TaskLine> = Vec::new();
        for c in figures {
            let label: Vec<String> = (0..run.factors.len())
                .filter(|&f| f != x)
                .map(|f| c.levels[f].clone())
                .collect();
            let label = if label.is_empty() {
                run.factors[x].clone()
            } else {
                label.join(", ")
            };
            let xv: f64 = c.levels[x].parse().unwrap_or(f64::NAN);
            let i = match lines.iter().position(|l| l.label == label) {
                Some(i) => i,
                None => {
                    lines.push(crate::plots::TaskLine {
                        label,
                        success_pct: Vec::new(),
                        completion_s: Vec::new(),
                    });
                    lines.len() - 1
                }
            };
            lines[i].success_pct.push((
                xv,
                c.success.0 * 100.0,
                c.success.1 * 100.0,
                c.success.2 * 100.0,
            ));
            if c.done > 0 {
                let (m, lo, hi) = if c.within_s.1.is_finite() {
                    c.within_s
                } else {
                    c.completion_s
                };
                lines[i].completion_s.push((xv, m, lo, hi));
            }
        }
        crate::plots::task_against(
            dir,
            &format!("study {}: trials done and completion time", run.study.name),
            &run.factors[x],
            &lines,
        )?;
        return Ok(Some(format!(
            "# plots: task.svg, task.png (against {}; completion time with the within-group interval where every group has one); cells.csv: one row per group and condition",
            run.factors[x]
        )));
    }
    Ok(None)
}

/// Reads `DIR`'s trial table and study, writes `cells.csv`, `report.txt` and the plots
/// (`task.svg`, `task.png`) into it, and returns the report's text.
///
/// # Errors
/// No trial table or study file in `dir`, or one that cannot be read; a file cannot be written.
pub fn report(dir: &Path) -> anyhow::Result<String> {
    let run = Run::read(dir)?;
    let (within, anova_text, left_out) = run.within();
    let figures = run.figures(&within);
    std::fs::write(dir.join("cells.csv"), run.cells_csv())?;
    let mut out = text(&run, &figures, left_out, &anova_text);
    if let Some(line) = plot(dir, &run, &figures)? {
        out.push_str(&line);
        out.push('\n');
    }
    if let Some((table, panels, x)) = super::scores::scores(dir, &run.study)? {
        out.push_str(&table);
        if !panels.is_empty() {
            crate::plots::intervals_against(
                dir,
                "questionnaire",
                &format!("study {}: questionnaire scores", run.study.name),
                &run.factors[x],
                &panels,
            )?;
            out.push_str("# plots: questionnaire.svg, questionnaire.png\n");
        }
    }
    std::fs::write(dir.join("report.txt"), &out)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_way_anova_matches_a_worked_example() {
        // Three subjects × three conditions: SS_A = 6, SS_error = 4/3, F(2, 4) = 9; for two
        // numerator degrees of freedom p = (1 + 2F/df2)^(−df2/2) = 5.5^−2.
        let y = vec![
            vec![1.0, 2.0, 3.0],
            vec![2.0, 3.0, 5.0],
            vec![3.0, 4.0, 4.0],
        ];
        let e = rm_anova(&["a".into()], &[3], &y);
        assert_eq!(e.len(), 1);
        assert!((e[0].f - 9.0).abs() < 1e-9, "{e:?}");
        assert_eq!(e[0].df, (2.0, 4.0));
        assert!((e[0].p - 5.5f64.powi(-2)).abs() < 1e-6, "{e:?}");
        assert!((e[0].eta_p2 - 6.0 / (6.0 + 4.0 / 3.0)).abs() < 1e-9);
    }

    #[test]
    fn two_way_effects_are_found_where_they_are() {
        // Four subjects, factor a (2 levels) adds 1 s, factor b (3 levels) nothing, no
        // interaction; small subject-specific noise.
        let noise = [0.01, -0.02, 0.015, -0.005, 0.02, -0.01];
        let y: Vec<Vec<f64>> = (0..4)
            .map(|s| {
                (0..6)
                    .map(|c| {
                        5.0 + s as f64 + if c / 3 == 1 { 1.0 } else { 0.0 } + noise[(c + s) % 6]
                    })
                    .collect()
            })
            .collect();
        let e = rm_anova(&["a".into(), "b".into()], &[2, 3], &y);
        let names: Vec<&str> = e.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["a", "b", "a × b"]);
        assert!(e[0].p < 1e-4, "{e:?}");
        assert!(e[1].p > 0.05 && e[2].p > 0.05, "{e:?}");
        assert_eq!(
            (e[0].df, e[1].df, e[2].df),
            ((1.0, 3.0), (2.0, 6.0), (2.0, 6.0))
        );
    }
}
