//! `study run --stations`: a study's trials on live stations of this machine, started once for
//! the whole run ([`crate::session::trials`]): between trials no process restarts, the stations
//! rebuild themselves from each trial's scenario and take its time 0 from the runner. Each trial
//! leaves one recording per station (`stations/<site>-<group>-t<trial>.mcap`) and a row per site
//! in `trials.csv`, written as `study run --sim` writes them; what the stations do not measure
//! live yet (grip force, divergence, phantom contact) is left empty. A run cut short resumes as
//! a simulated one does: finished trials are kept, the cut one runs again, marked.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use coop_transport::network::trial::TrialFigures;

use super::run::{attempt_seed, Ran, Tables};
use super::{Study, Trial};
use coop_model::scenario::Scenario;

use crate::session::trials::{StudyStations, TrialRun};
use crate::session::RunArgs;

/// The name a trial's recordings carry: its group and number (and its attempt, after the first).
pub fn trial_name(t: &Trial, attempt: u32) -> String {
    let safe: String = t
        .group_id
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "_.-".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if attempt > 1 {
        format!("{safe}-t{:03}-a{attempt}", t.trial)
    } else {
        format!("{safe}-t{:03}", t.trial)
    }
}

/// A study's stations, as a run drives them: started at its first trial (so a run that has
/// nothing left to do, or whose table cannot be opened, starts none), each trial run on them and
/// its rows appended, stopped at the end with what they did said.
#[derive(Debug)]
pub struct OnStations {
    a: RunArgs,
    out: PathBuf,
    /// The first trial's scenario: the stations' world.
    sc: Scenario,
    timeout: Duration,
    stations: Option<StudyStations>,
    /// A trial's number on the stations: rising through the run (stations started afresh, by a
    /// resumed run too, count from 1).
    k: u64,
    /// Per trial, seconds from asking for it to its time 0.
    gaps: Vec<f64>,
    /// Per site, the processes (servo, physics, network) that ran its trials.
    processes: BTreeMap<String, Vec<Vec<u64>>>,
}

impl OnStations {
    /// Checks that every condition of `study` can run on the stations of its first (same sites,
    /// objects and kind of method, which each station checks again): said here, before anything
    /// starts. The stations start with `a` (its scenario the study's) at the first trial.
    ///
    /// # Errors
    /// A condition that cannot share the stations, naming it and the rule.
    pub fn new(study: &Study, out: &Path, a: RunArgs) -> anyhow::Result<Self> {
        let plan = study.plan();
        let Some(first) = plan.first() else {
            bail!("study file {}: no trials", study.path.display());
        };
        let (_, sc) = study.scenario_text_for(&first.levels, first.seed, 0)?;
        for levels in study.all_level_combinations() {
            let (_, other) = study.scenario_text_for(&levels, first.seed, 0)?;
            coop_actors::station::trials::fits(&sc, &other).map_err(|why| {
                anyhow::anyhow!(
                    "study file {}: the condition {} cannot run on the stations of {}: {why}",
                    study.path.display(),
                    study.condition_name(&levels),
                    study.condition_name(&first.levels)
                )
            })?;
        }
        let timeout = Duration::from_secs_f64(study.file.timeout_s.unwrap_or(sc.duration_s) + 1.0);
        Ok(Self {
            a,
            out: out.to_owned(),
            sc,
            timeout,
            stations: None,
            k: 0,
            gaps: Vec::new(),
            processes: BTreeMap::new(),
        })
    }

    /// Starts the stations if they are not up yet.
    fn start(&mut self, study: &Study) -> anyhow::Result<()> {
        if self.stations.is_none() {
            let session: String = format!("study-{}-{}", std::process::id(), study.file.name)
                .chars()
                .map(|c| {
                    if c.is_ascii_alphanumeric() || c == '-' {
                        c
                    } else {
                        '-'
                    }
                })
                .collect();
            let st = StudyStations::start(&self.a, &self.sc, &session, &self.out.join("stations"))?;
            self.stations = Some(st);
        }
        Ok(())
    }

    /// Runs `t`'s `attempt` on the stations (`cut`: an earlier run began it), appends its rows to
    /// `tables`, and gives its line for the log.
    ///
    /// # Errors
    /// A station that does not start, refuses the trial or exits; interrupted; a file.
    pub(super) fn run(
        &mut self,
        tables: &mut Tables,
        study: &Study,
        t: &Trial,
        attempt: u32,
        cut: bool,
    ) -> anyhow::Result<String> {
        if self.a.stop.is_raised() {
            bail!("interrupted");
        }
        let (text, trial_sc) = study.scenario_text_for(
            &t.levels,
            attempt_seed(t, attempt),
            study.people_seed(t.group),
        )?;
        self.k += 1;
        let name = trial_name(t, attempt);
        self.start(study)?;
        let stations = self.stations.as_mut().context("the study's stations")?;
        let r = stations.trial(&self.a, self.k, &name, &text, self.timeout)?;
        // A recording that cannot be read leaves the cell empty, not the trial unrecorded.
        let divergence = recorded_divergence(stations, &name, &trial_sc).unwrap_or_else(|e| {
            eprintln!("study: trial {name}: no divergence from its recordings: {e:#}");
            f64::NAN
        });
        self.gaps
            .push(r.setup_s + crate::session::trials::LEAD.as_secs_f64());
        self.log(t, &name, &r)?;
        let (rows, line) = rows(study, t, &trial_sc, &r, divergence, cut, attempt);
        tables.append(t, &rows, attempt)?;
        Ok(line)
    }

    /// Notes in `stations/trials.csv` how long the stations took to be ready for trial `name`
    /// and which processes ran it: a lab's evidence that nothing restarted between trials.
    fn log(&mut self, t: &Trial, name: &str, r: &TrialRun) -> anyhow::Result<()> {
        let path = self.out.join("stations").join("trials.csv");
        let fresh = !path.exists();
        let mut log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .with_context(|| format!("opening {}", path.display()))?;
        if fresh {
            writeln!(
                log,
                "group,trial,name,site,setup_s,run_s,servo_pid,physics_pid,network_pid,clock_offset_ms"
            )?;
        }
        for (site, f) in &r.sites {
            let seen = self.processes.entry(site.clone()).or_default();
            if !seen.contains(&f.pids) {
                seen.push(f.pids.clone());
            }
            let pid = |i: usize| f.pids.get(i).copied().unwrap_or(0);
            writeln!(
                log,
                "{},{},{name},{site},{:.3},{:.3},{},{},{},{:.3}",
                t.group_id,
                t.trial,
                r.setup_s,
                r.run_s,
                pid(0),
                pid(1),
                pid(2),
                f.clock_offset_ns as f64 * 1e-6
            )?;
        }
        log.flush()?;
        Ok(())
    }

    /// Stops the stations (if they started), and gives what they did: the time between trials,
    /// and whether any process was restarted.
    ///
    /// # Errors
    /// A station that did not stop cleanly.
    pub fn finish(self) -> anyhow::Result<Vec<String>> {
        if let Some(st) = self.stations {
            st.stop()?;
        }
        let mut lines = Vec::new();
        let gaps = &self.gaps;
        if !gaps.is_empty() {
            let mean = gaps.iter().sum::<f64>() / gaps.len() as f64;
            let max = gaps.iter().copied().fold(0.0, f64::max);
            lines.push(format!(
                "between trials (asking for a trial to its time 0): mean {mean:.2} s, max {max:.2} s over {} trials",
                gaps.len()
            ));
            for (site, seen) in &self.processes {
                lines.push(format!(
                    "station {site}: {} set{} of servo, physics and network processes ran its {} trials{}",
                    seen.len(),
                    if seen.len() == 1 { "" } else { "s" },
                    gaps.len(),
                    if seen.len() == 1 { " (none restarted)" } else { " (a process was restarted)" }
                ));
            }
        }
        Ok(lines)
    }
}

/// Runs `study`'s trials (those `trials.csv` does not hold yet, with `resume`) on its stations
/// `on` (started at the first trial, stopped at the end), into `out`; `outcome` gets a line per
/// trial and what the stations did.
///
/// # Errors
/// As `run_sim`; a station that does not start, refuses a trial or exits.
pub fn run_stations(
    study: &Study,
    out: &Path,
    resume: bool,
    mut on: OnStations,
    outcome: &mut dyn FnMut(String),
) -> anyhow::Result<Ran> {
    let started = Instant::now();
    let plan = study.plan();
    let mut tables = Tables::open(study, out, resume, plan.len())?;
    let todo: Vec<&Trial> = plan.iter().filter(|t| !tables.holds(t)).collect();
    let kept = plan.len() - todo.len();
    let run = todo.iter().try_for_each(|t| {
        let cut = tables.begin(t)?;
        outcome(on.run(&mut tables, study, t, 1, cut)?);
        anyhow::Ok(())
    });
    let said = on.finish();
    run?;
    for line in said? {
        outcome(line);
    }
    Ok(Ran {
        ran: todo.len(),
        kept,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// The largest distance between the sites' copies while their users touched the object together
/// over trial `name` of scenario `sc`, m, from the stations' recordings of it (read as `session
/// run` reads its stations': the simulator's metric on the recorded traces).
///
/// # Errors
/// A recording that cannot be read or has no time 0.
fn recorded_divergence(
    stations: &StudyStations,
    name: &str,
    sc: &coop_model::scenario::Scenario,
) -> anyhow::Result<f64> {
    let recs: Vec<coop_transport::recording::Recording> = stations
        .recordings(name)
        .iter()
        .map(|(site, p)| {
            coop_transport::recording::read(p)
                .with_context(|| format!("station {site}'s recording of trial {name}"))
        })
        .collect::<anyhow::Result<_>>()?;
    let epochs: Vec<u64> = recs
        .iter()
        .map(|r| r.session.as_ref().map(|s| s.epoch_ns))
        .collect::<Option<_>>()
        .with_context(|| format!("a recording of trial {name} without its time 0"))?;
    let run = crate::session::run_from_recordings(sc, &recs, &epochs)?;
    Ok(coop_model::metrics::compute(sc, &run, &run).co_contact_divergence_max_m)
}

/// `t`'s rows from what the stations said at its end and the divergence their recordings show
/// (`cut`: an earlier run began it), and its line for the log.
fn rows(
    study: &Study,
    t: &Trial,
    sc: &coop_model::scenario::Scenario,
    r: &TrialRun,
    divergence_m: f64,
    cut: bool,
    attempt: u32,
) -> (String, String) {
    let none = TrialFigures::default();
    let sites: Vec<(&String, &TrialFigures)> = r.sites.iter().collect();
    let done = |f: &TrialFigures| f.task == "done";
    let trial_done = !sites.is_empty() && sites.iter().all(|(_, f)| done(f));
    let completion = sites.iter().map(|(_, f)| f.task_at_s).fold(0.0, f64::max);
    let mut out = String::new();
    let names: BTreeMap<&str, usize> = study
        .sites
        .iter()
        .enumerate()
        .map(|(i, s)| (s.as_str(), i))
        .collect();
    let num = |v: f64, prec: usize| {
        if v.is_finite() {
            format!("{v:.prec$}")
        } else {
            String::new()
        }
    };
    for (site, i) in &names {
        let f = r.sites.get(*site).unwrap_or(&none);
        let rollback = r.rollback.get(*site).copied().flatten();
        let tick_ms = 1e3 / sc.site[*i].physics_rate_hz;
        let ms = |ticks: u64| ticks as f64 * tick_ms;
        let outcome = match f.task.as_str() {
            "done" | "failed" => f.task.clone(),
            _ => "undecided".to_owned(),
        };
        let failed_by = match (f.task.as_str(), f.failed_by) {
            ("failed", 0) => "timeout".to_owned(),
            ("failed", k) => format!("fail[{}]", k - 1),
            _ => String::new(),
        };
        let mut cells = super::run::row_head(study, t, *i, site);
        cells.extend([
            attempt_seed(t, attempt).to_string(),
            outcome,
            failed_by,
            u8::from(done(f)).to_string(),
            u8::from(trial_done).to_string(),
            if done(f) {
                format!("{:.3}", f.task_at_s)
            } else {
                String::new()
            },
            if trial_done {
                format!("{completion:.3}")
            } else {
                String::new()
            },
            // Grip force and slips: the participant's, not sent by its station yet.
            String::new(),
            String::new(),
            String::new(),
            String::new(),
            num(divergence_m * 1e3, 2),
            // Phantom and unfelt contact: what the method's rollbacks took back (`timewarp`).
            rollback.map_or(String::new(), |f| num(ms(f.phantom_contact_ticks), 1)),
            rollback.map_or(String::new(), |f| num(ms(f.unfelt_contact_ticks), 1)),
            r.sent_bytes.get(*site).copied().unwrap_or(0).to_string(),
            u8::from(cut).to_string(),
            attempt.to_string(),
        ]);
        out.push_str(&super::csv::line(&cells));
        out.push('\n');
    }
    let line = super::run::trial_line(
        study,
        t,
        attempt,
        trial_done.then_some(completion),
        " on stations",
    );
    (out, line)
}
