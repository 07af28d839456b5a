//! `study run --sim`: a study's trials with simulated participants, in the simulator.
//!
//! Trials run on every core, a batch at a time; each finished batch is appended to
//! `trials.csv` (one row per site and trial) and flushed before the next starts, so a run cut
//! short (a crash, Ctrl-C) loses at most the batch in flight: `--resume` reads the table, keeps
//! every trial it holds whole, and runs the rest. The simulator is deterministic, so a trial run
//! again gives the same row to the bit. `meta.json` says what ran: the study file's hash, the
//! commit, the machine, when.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context};
use coop_model::metrics;
use coop_model::sim::{self, Mode};

use super::{level_text, Study, Trial, COLUMNS};

/// What a run of the trials did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ran {
    /// Trials run now.
    pub ran: usize,
    /// Trials found done in the table (resumed).
    pub kept: usize,
    /// Wall-clock seconds.
    pub seconds: f64,
}

/// The table's header: its own columns with the factors' after `order_position`.
pub fn header(study: &Study) -> Vec<String> {
    let mut h: Vec<String> = COLUMNS[..8].iter().map(|s| (*s).to_owned()).collect();
    h.extend(study.file.factor.iter().map(|f| f.name.clone()));
    h.extend(COLUMNS[8..].iter().map(|s| (*s).to_owned()));
    h
}

/// Where a run writes, and what it has written.
pub(super) struct Tables {
    file: File,
    begun_log: File,
    /// Trials begun by an earlier run (`group trial`).
    begun: Vec<String>,
    /// Trials whole in the table, with their attempts.
    done: Whole,
}

impl Tables {
    /// Opens `out`'s table (made, or resumed), its record of trials begun, and `meta.json`.
    pub(super) fn open(
        study: &Study,
        out: &Path,
        resume: bool,
        trials: usize,
    ) -> anyhow::Result<Self> {
        let table = out.join("trials.csv");
        let head = header(study).join(",");
        let done = if resume {
            // The same study, to the byte: a changed seed, design or level under the same
            // factor names would mix two studies in one table.
            let was = std::fs::read(out.join("study.toml")).unwrap_or_default();
            if was != std::fs::read(&study.path).unwrap_or_default() {
                bail!(
                    "--resume: {} was run from another study file than {} (its study.toml differs): resume with the file it was run from, or give another --out",
                    out.display(),
                    study.path.display()
                );
            }
            let done = done_trials(study, &table, &head)?;
            truncate_to_whole_trials(study, &table, &head)?;
            done
        } else {
            let left = ["trials.csv", "begun.txt", "questionnaires.csv"]
                .into_iter()
                .find(|f| out.join(f).exists());
            if let Some(f) = left {
                bail!(
                    "{} already holds a study's run ({f}): give another --out, or --resume to go on with it",
                    out.display()
                );
            }
            std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
            let mut f =
                File::create(&table).with_context(|| format!("creating {}", table.display()))?;
            writeln!(f, "{head}")?;
            std::fs::copy(&study.path, out.join("study.toml")).with_context(|| {
                format!("copying {} into {}", study.path.display(), out.display())
            })?;
            Whole::new()
        };
        write_meta(study, out, trials)?;
        let file = OpenOptions::new()
            .append(true)
            .open(&table)
            .with_context(|| format!("opening {}", table.display()))?;
        // The trials begun: one begun but not in the table was cut short, and is marked when
        // run again.
        let begun_path = out.join("begun.txt");
        let begun: Vec<String> = std::fs::read_to_string(&begun_path)
            .unwrap_or_default()
            .lines()
            .map(str::to_owned)
            .collect();
        let begun_log = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&begun_path)
            .with_context(|| format!("opening {}", begun_path.display()))?;
        Ok(Self {
            file,
            begun_log,
            begun,
            done,
        })
    }

    /// Whether the table holds `t` whole.
    pub(super) fn holds(&self, t: &Trial) -> bool {
        self.done.contains_key(&(t.group_id.clone(), t.trial))
    }

    /// Notes that `t` begins (a trial begun and not in the table was cut short), and whether an
    /// earlier run began it.
    pub(super) fn begin(&mut self, t: &Trial) -> anyhow::Result<bool> {
        writeln!(self.begun_log, "{} {}", t.group_id, t.trial)?;
        self.begun_log.sync_data()?;
        Ok(self.begun.contains(&format!("{} {}", t.group_id, t.trial)))
    }

    /// Appends `t`'s `rows` of its `attempt` and flushes them.
    pub(super) fn append(&mut self, t: &Trial, rows: &str, attempt: u32) -> anyhow::Result<()> {
        self.file.write_all(rows.as_bytes())?;
        self.file.flush()?;
        self.file.sync_data()?;
        self.done
            .entry((t.group_id.clone(), t.trial))
            .or_default()
            .push(attempt);
        Ok(())
    }

    /// Notes that `t` is run again, and gives that attempt's number (the next after the table's).
    pub(super) fn begin_repeat(&mut self, t: &Trial) -> anyhow::Result<u32> {
        let attempt = self
            .done
            .get(&(t.group_id.clone(), t.trial))
            .and_then(|a| a.iter().max())
            .map_or(1, |a| a + 1);
        writeln!(self.begun_log, "{} {} {attempt}", t.group_id, t.trial)?;
        self.begun_log.sync_data()?;
        Ok(attempt)
    }

    /// Runs `t` again (its next attempt, a new run of the same people) and appends its rows.
    pub(super) fn repeat(
        &mut self,
        study: &Study,
        t: &Trial,
        outcome: &mut dyn FnMut(String),
    ) -> anyhow::Result<()> {
        let attempt = self.begin_repeat(t)?;
        let (rows, line) = trial_rows(study, t, false, attempt)?;
        self.append(t, &rows, attempt)?;
        outcome(line);
        Ok(())
    }

    /// Runs `trials` on every core, then appends their rows and flushes them; each trial's
    /// outcome line to `outcome`.
    pub(super) fn run(
        &mut self,
        study: &Study,
        trials: &[&Trial],
        outcome: &mut dyn FnMut(String),
    ) -> anyhow::Result<()> {
        for t in trials {
            writeln!(self.begun_log, "{} {}", t.group_id, t.trial)?;
        }
        self.begun_log.sync_data()?;
        let rows = crate::sweep::par_map(trials, |t| {
            let cut = self.begun.contains(&format!("{} {}", t.group_id, t.trial));
            trial_rows(study, t, cut, 1)
        });
        for r in rows {
            let (rows, line) = r?;
            self.file.write_all(rows.as_bytes())?;
            outcome(line);
        }
        self.file.flush()?;
        self.file.sync_data()?;
        for t in trials {
            self.done
                .entry((t.group_id.clone(), t.trial))
                .or_default()
                .push(1);
        }
        Ok(())
    }
}

/// Runs `study`'s trials in the simulator into `out` (created), or, with `resume`, those its
/// `trials.csv` does not hold yet, on every core, a batch at a time. `progress(done, total)`
/// after each batch.
///
/// # Errors
/// `out` holds another study's (or no) table when resuming, or holds one when not; a file cannot
/// be written.
pub fn run_sim(
    study: &Study,
    out: &Path,
    resume: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> anyhow::Result<Ran> {
    let started = Instant::now();
    let plan = study.plan();
    let mut tables = Tables::open(study, out, resume, plan.len())?;
    let todo: Vec<&Trial> = plan.iter().filter(|t| !tables.holds(t)).collect();
    let batch = std::thread::available_parallelism().map_or(2, |n| n.get()) * 2;
    let kept = plan.len() - todo.len();
    let mut finished = kept;
    for chunk in todo.chunks(batch) {
        tables.run(study, chunk, &mut |_| {})?;
        finished += chunk.len();
        progress(finished, plan.len());
    }
    Ok(Ran {
        ran: todo.len(),
        kept,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Appends a participant's answers to `path` (made with its header): one row per item.
///
/// # Errors
/// The file cannot be written.
pub fn store_answers(
    study: &Study,
    path: &Path,
    p: &super::board::Pending,
    answers: &[(String, u32)],
) -> anyhow::Result<()> {
    use std::fmt::Write as _;
    let new = !path.exists();
    let mut f = OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))?;
    let mut text = String::new();
    if new {
        let factors: Vec<&str> = study.file.factor.iter().map(|f| f.name.as_str()).collect();
        let _ = writeln!(
            text,
            "study,group,participant,site,block,{},item,value,answered_unix_s",
            factors.join(",")
        );
    }
    let when = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    for (item, value) in answers {
        let cells: Vec<String> = [
            study.file.name.clone(),
            p.group.clone(),
            p.participant.clone(),
            p.site.clone(),
            p.block.to_string(),
        ]
        .into_iter()
        .chain(p.levels.iter().cloned())
        .chain([item.clone(), value.to_string(), when.to_string()])
        .collect();
        let _ = writeln!(text, "{}", super::csv::line(&cells));
    }
    f.write_all(text.as_bytes())?;
    f.sync_data()?;
    Ok(())
}

/// The seed of `t`'s `attempt` (its own for the first; a repeat is a new run of the same people).
pub(super) fn attempt_seed(t: &Trial, attempt: u32) -> u64 {
    if attempt <= 1 {
        t.seed
    } else {
        super::seed63(super::mix(t.seed, &[u64::from(attempt)]))
    }
}

/// One trial in the simulator: its rows (one per site), as CSV lines, and its outcome in a
/// line; `cut`: a run of it was cut short before (this one replaces it); `attempt`: 1, or which
/// repeat this is.
fn trial_rows(
    study: &Study,
    t: &Trial,
    cut: bool,
    attempt: u32,
) -> anyhow::Result<(String, String)> {
    use std::fmt::Write as _;
    let seed = attempt_seed(t, attempt);
    let sc = study.scenario_for(&t.levels, seed, study.people_seed(t.group))?;
    let r = sim::run_wired(
        &sc,
        Mode::Distributed(sc.method),
        &mut |_| {},
        &coop_transport::wire::StationWire,
    );
    // The task's figures need no reference run (nothing here is compared with one): the run
    // stands in for it, and the reference's columns are not written.
    let m = metrics::compute(&sc, &r, &r);
    let (trial_done, completion) = crate::figures::task_completion(&m);
    let num = |v: f64, prec: usize| {
        if v.is_finite() {
            format!("{v:.prec$}")
        } else {
            String::new()
        }
    };
    let mut out = String::new();
    for (i, s) in m.sites.iter().enumerate() {
        let task = s.task.clone().unwrap_or(coop_model::task::TaskFigures {
            outcome: "undecided".into(),
            time_s: f64::NAN,
            failed_by: String::new(),
            grip_mean_n: f64::NAN,
            grip_peak_n: f64::NAN,
            grip_margin: f64::NAN,
            slips: 0,
            steps: (0, 0),
        });
        let mut cells = row_head(study, t, i, &s.name);
        cells.extend([
            seed.to_string(),
            task.outcome.clone(),
            task.failed_by.clone(),
            u8::from(task.outcome == "done").to_string(),
            u8::from(trial_done).to_string(),
            if task.outcome == "done" {
                num(task.time_s, 3)
            } else {
                String::new()
            },
            num(completion, 3),
            num(task.grip_mean_n, 3),
            num(task.grip_peak_n, 3),
            num(task.grip_margin, 3),
            task.slips.to_string(),
            num(m.co_contact_divergence_max_m * 1e3, 2),
            num(s.phantom_contact_ms, 1),
            num(s.unfelt_contact_ms, 1),
            s.sent_bytes.to_string(),
            u8::from(cut).to_string(),
            attempt.to_string(),
        ]);
        let _ = writeln!(out, "{}", super::csv::line(&cells));
    }
    let line = trial_line(study, t, attempt, trial_done.then_some(completion), "");
    Ok((out, line))
}

/// The first cells of a trial's row for site `i` named `site`: the study, the group, the
/// participant, the site, the block, the trial, practice or not, its order position, and the
/// condition's levels.
pub(super) fn row_head(study: &Study, t: &Trial, i: usize, site: &str) -> Vec<String> {
    let mut cells = vec![
        study.file.name.clone(),
        t.group_id.clone(),
        study.groups[t.group].participants[i].clone(),
        site.to_owned(),
        t.block.to_string(),
        t.trial.to_string(),
        u8::from(t.practice).to_string(),
        t.block.to_string(),
    ];
    cells.extend(
        study
            .file
            .factor
            .iter()
            .zip(&t.levels)
            .map(|(f, &l)| level_text(&f.levels[l])),
    );
    cells
}

/// A trial's line for the log and the experimenter's page: its group, number, condition, attempt,
/// where it ran (`place`, e.g. " on stations") and its completion time if it was done.
pub(super) fn trial_line(
    study: &Study,
    t: &Trial,
    attempt: u32,
    done_in_s: Option<f64>,
    place: &str,
) -> String {
    format!(
        "{} trial {} ({}{}{}){place}: {}",
        t.group_id,
        t.trial,
        study.condition_name(&t.levels),
        if t.practice { ", practice" } else { "" },
        if attempt > 1 {
            format!(", attempt {attempt}")
        } else {
            String::new()
        },
        match done_in_s {
            Some(s) => format!("done in {s:.2} s"),
            None => "not done".to_owned(),
        }
    )
}

/// Per trial (group id, trial), its attempts whose every site's row `text` holds complete (a
/// line ended by its newline, with every cell).
type Whole = std::collections::BTreeMap<(String, usize), Vec<u32>>;

/// A complete line of the table and its trial's attempt: (group id, trial, attempt).
type Line<'a> = (&'a str, (String, usize, u32));

/// The whole attempts of `text`'s trials, and each complete line with its key.
fn whole_attempts<'a>(
    text: &'a str,
    width: usize,
    name: &str,
    sites: usize,
) -> (Whole, Vec<Line<'a>>) {
    let mut lines = Vec::new();
    let mut counts: std::collections::BTreeMap<(String, usize, u32), usize> = Default::default();
    for line in text.split_inclusive('\n').skip(1) {
        // A line cut by a crash has no newline, or fewer cells: it does not count.
        if !line.ends_with('\n') {
            continue;
        }
        let cells = super::csv::split(line.trim_end_matches(['\n', '\r']));
        if cells.len() != width || cells[0] != name {
            continue;
        }
        let (Ok(trial), Ok(attempt)) = (cells[5].parse::<usize>(), cells[width - 1].parse::<u32>())
        else {
            continue;
        };
        let key = (cells[1].clone(), trial, attempt);
        *counts.entry(key.clone()).or_default() += 1;
        lines.push((line, key));
    }
    let mut whole: Whole = Default::default();
    for ((g, t, a), n) in counts {
        if n == sites {
            whole.entry((g, t)).or_default().push(a);
        }
    }
    (whole, lines)
}

/// The trials `table` holds whole (every site's row of some attempt), with their attempts.
fn done_trials(study: &Study, table: &Path, head: &str) -> anyhow::Result<Whole> {
    let text = std::fs::read_to_string(table).with_context(|| {
        format!(
            "--resume: {} has no trials.csv: nothing to resume (run without --resume)",
            table.parent().unwrap_or(Path::new(".")).display()
        )
    })?;
    if text.lines().next().unwrap_or_default() != head {
        bail!(
            "--resume: {} was written for another study (its header differs from {}'s)",
            table.display(),
            study.path.display()
        );
    }
    let width = super::csv::split(head).len();
    Ok(whole_attempts(&text, width, &study.file.name, study.sites.len()).0)
}

/// Rewrites `table` with only the whole attempts' rows (a batch cut mid-write leaves some of a
/// trial's sites, or half a line).
fn truncate_to_whole_trials(study: &Study, table: &Path, head: &str) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(table)?;
    let width = super::csv::split(head).len();
    let (whole, lines) = whole_attempts(&text, width, &study.file.name, study.sites.len());
    let mut keep = String::from(head);
    keep.push('\n');
    for (line, (g, t, a)) in lines {
        if whole.get(&(g, t)).is_some_and(|w| w.contains(&a)) {
            keep.push_str(line);
        }
    }
    let tmp = table.with_extension("csv.tmp");
    std::fs::write(&tmp, keep)?;
    std::fs::rename(&tmp, table)?;
    Ok(())
}

/// `meta.json`: the study, its hash, the commit, the machine, the time.
fn write_meta(study: &Study, out: &Path, trials: usize) -> anyhow::Result<()> {
    let commit = std::process::Command::new("git")
        .args(["rev-parse", "--short=10", "HEAD"])
        .current_dir(
            study
                .path
                .parent()
                .filter(|p| !p.as_os_str().is_empty())
                .unwrap_or(Path::new(".")),
        )
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned());
    let host = std::fs::read_to_string("/etc/hostname")
        .map(|s| s.trim().to_owned())
        .unwrap_or_default();
    let meta = serde_json::json!({
        "study": study.file.name,
        "study_file": study.path.display().to_string(),
        "study_hash_xxh3_64": study.hash,
        "scenario": study.scenario_path.display().to_string(),
        "mode": "simulation",
        "sites": study.sites,
        "groups": study.groups,
        // Each group's people are drawn with this seed (the scenario's people_seed); each
        // trial's run seed is in the table.
        "people_seeds": study
            .groups
            .iter()
            .enumerate()
            .map(|(g, group)| (group.id.clone(), study.people_seed(g)))
            .collect::<std::collections::BTreeMap<_, _>>(),
        "trials": trials,
        "commit": commit,
        "machine": {
            "host": host,
            "cpus": std::thread::available_parallelism().map_or(1, |n| n.get()),
        },
        "clock_offsets_ms": serde_json::Value::Null,
        "written_unix_s": std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
    });
    std::fs::write(
        out.join("meta.json"),
        serde_json::to_string_pretty(&meta)? + "\n",
    )
    .with_context(|| format!("writing {}", out.join("meta.json").display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::whole_attempts;

    #[test]
    fn only_complete_lines_of_every_site_make_a_trial_whole() {
        // Columns: study, group, participant, site, block, trial, ..., attempt (8 cells here).
        let row = |g: &str, site: &str, trial: u32, attempt: u32| {
            format!("s,{g},{g}-{site},{site},1,{trial},x,{attempt}\n")
        };
        let mut text = String::from("head\n");
        // Trial 1 whole; trial 2 missing a site; trial 3 whole in attempt 1, its attempt 2's
        // last line cut before its newline; trial 4's second site's line torn short.
        text += &row("g01", "a", 1, 1);
        text += &row("g01", "b", 1, 1);
        text += &row("g01", "a", 2, 1);
        text += &row("g01", "a", 3, 1);
        text += &row("g01", "b", 3, 1);
        text += &row("g01", "a", 3, 2);
        text += &row("g01", "a", 4, 1);
        text += "s,g01,g01-b,b,1,4,x\n";
        text += row("g01", "b", 3, 2).trim_end();
        let (whole, lines) = whole_attempts(&text, 8, "s", 2);
        let keys: Vec<_> = whole.iter().map(|(k, a)| (k.1, a.clone())).collect();
        assert_eq!(keys, vec![(1, vec![1]), (3, vec![1])]);
        // The cut line is not among the complete ones; another study's rows are not counted.
        assert_eq!(lines.len(), 7);
        let (other, _) = whole_attempts(&text, 8, "t", 2);
        assert!(other.is_empty());
    }
}
