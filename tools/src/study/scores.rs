//! The questionnaires' scores per condition, from a run's `questionnaires.csv`: the raw TLX (the
//! mean of its six scales, 0–100; Hart 2006) and each Likert item, per participant and block,
//! then per condition their mean with its Student 95 % interval over the participants.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;

use super::questionnaire::TLX;
use super::StudyFile;
use crate::plots::LinePanel;
use crate::stats::mean_ci95;

/// One measure per condition: its name, and per condition (levels) the values.
type Measures = BTreeMap<String, BTreeMap<Vec<String>, Vec<f64>>>;

/// Per (participant, block): its condition's levels and its answers by item.
type Sheets = BTreeMap<(String, String), (Vec<String>, BTreeMap<String, f64>)>;

/// The answers `dir` holds, one sheet per participant and block (`None`: no file).
///
/// # Errors
/// `questionnaires.csv` cannot be read or is malformed.
fn read_sheets(dir: &Path, study: &StudyFile) -> anyhow::Result<Option<Sheets>> {
    let path = dir.join("questionnaires.csv");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(None);
    };
    let mut lines = text.lines();
    let header = super::csv::Header::new(lines.next().unwrap_or_default(), &path);
    let head = &header.cells;
    let col = |name: &str| header.col(name);
    let factors: Vec<usize> = study
        .factor
        .iter()
        .map(|f| col(&f.name))
        .collect::<Result<_, _>>()?;
    let (c_who, c_block, c_item, c_value) = (
        col("participant")?,
        col("block")?,
        col("item")?,
        col("value")?,
    );
    let mut sheets: Sheets = BTreeMap::new();
    let complete = text.ends_with('\n');
    let count = text.lines().count();
    for (k, line) in lines.enumerate() {
        // A last line without its newline was cut by a crash (that questionnaire is asked
        // again when the run resumes).
        if !complete && k + 2 == count {
            continue;
        }
        let c = super::csv::split(line);
        if c.len() != head.len() {
            anyhow::bail!(
                "{} line {}: {} cells, the header has {}",
                path.display(),
                k + 2,
                c.len(),
                head.len()
            );
        }
        let value: f64 = c[c_value].parse().with_context(|| {
            format!("{} line {}: value {:?}", path.display(), k + 2, c[c_value])
        })?;
        let sheet = sheets
            .entry((c[c_who].clone(), c[c_block].clone()))
            .or_insert_with(|| {
                (
                    factors.iter().map(|&f| c[f].clone()).collect(),
                    BTreeMap::new(),
                )
            });
        sheet.1.insert(c[c_item].clone(), value);
    }
    Ok(Some(sheets))
}

/// The measures of `sheets`: the raw TLX of every complete TLX, and each other item.
fn measures_of(sheets: &Sheets) -> Measures {
    let mut measures: Measures = BTreeMap::new();
    for (levels, answers) in sheets.values() {
        let tlx: Vec<f64> = TLX
            .iter()
            .filter_map(|t| answers.get(t.0).copied())
            .collect();
        if tlx.len() == TLX.len() {
            let raw = tlx.iter().sum::<f64>() / tlx.len() as f64;
            measures
                .entry("tlx_raw".into())
                .or_default()
                .entry(levels.clone())
                .or_default()
                .push(raw);
        }
        for (item, v) in answers.iter().filter(|(i, _)| !i.starts_with("tlx_")) {
            measures
                .entry(item.clone())
                .or_default()
                .entry(levels.clone())
                .or_default()
                .push(*v);
        }
    }
    measures
}

/// The scores' table and plot panels, and the factor the panels are against (`None`: no
/// answers in `dir`).
///
/// # Errors
/// `questionnaires.csv` cannot be read or is malformed.
pub fn scores(
    dir: &Path,
    study: &StudyFile,
) -> anyhow::Result<Option<(String, Vec<LinePanel>, usize)>> {
    let Some(sheets) = read_sheets(dir, study)? else {
        return Ok(None);
    };
    if sheets.is_empty() {
        return Ok(None);
    }
    let measures = measures_of(&sheets);
    let conditions = super::in_level_order(
        study,
        measures.values().flat_map(|m| m.keys().cloned()).collect(),
    );
    let names: Vec<&String> = measures.keys().collect();
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# questionnaires: {} answered; per condition the mean over the participants with its Student 95 % interval",
        sheets.len()
    );
    let w = study
        .factor
        .iter()
        .map(|f| f.name.len())
        .max()
        .unwrap_or(6)
        .max(8);
    let _ = write!(
        out,
        "{}",
        study
            .factor
            .iter()
            .map(|f| format!("{:<w$} ", f.name))
            .collect::<String>()
    );
    let _ = writeln!(
        out,
        "{}",
        names.iter().map(|n| format!("{n:>24}")).collect::<String>()
    );
    for c in &conditions {
        let _ = write!(
            out,
            "{}",
            c.iter().map(|l| format!("{l:<w$} ")).collect::<String>()
        );
        for n in &names {
            let xs = measures[*n].get(c).cloned().unwrap_or_default();
            let (m, lo, hi) = mean_ci95(&xs);
            let cell = if m.is_nan() {
                "-".to_owned()
            } else if lo.is_nan() {
                format!("{m:.1} (n={})", xs.len())
            } else {
                format!("{m:.1} [{lo:.1}, {hi:.1}]")
            };
            let _ = write!(out, "{cell:>24}");
        }
        out.push('\n');
    }
    // The panels: one per measure, against the first numeric factor, a line per level of the
    // others.
    let numeric = (0..study.factor.len()).find(|&f| {
        study.factor[f]
            .levels
            .iter()
            .all(|v| matches!(v, toml::Value::Integer(_) | toml::Value::Float(_)))
    });
    let mut panels = Vec::new();
    if let Some(x) = numeric {
        for n in &names {
            let mut lines: Vec<(String, Vec<crate::plots::WithInterval>)> = Vec::new();
            for c in &conditions {
                let Some(xs) = measures[*n].get(c) else {
                    continue;
                };
                let label: Vec<String> = (0..c.len())
                    .filter(|&f| f != x)
                    .map(|f| c[f].clone())
                    .collect();
                let label = if label.is_empty() {
                    n.to_string()
                } else {
                    label.join(", ")
                };
                let (m, lo, hi) = mean_ci95(xs);
                let xv: f64 = c[x].parse().unwrap_or(f64::NAN);
                match lines.iter_mut().find(|l| l.0 == label) {
                    Some(l) => l.1.push((xv, m, lo, hi)),
                    None => lines.push((label, vec![(xv, m, lo, hi)])),
                }
            }
            panels.push(LinePanel {
                title: format!("{n} (mean, 95 % interval)"),
                y_label: if n.as_str() == "tlx_raw" {
                    "0-100"
                } else {
                    "rating"
                },
                lines,
            });
        }
    }
    Ok(Some((out, panels, numeric.unwrap_or(0))))
}
