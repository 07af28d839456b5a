//! `study run --serve`: a study's trials as a lab's session goes, with the experimenter's page
//! ([`super::web`]) and the questionnaires between blocks, run in the simulator or on a study's
//! live stations ([`super::live`]).

use std::path::Path;
use std::time::Instant;

use super::run::{Ran, Tables};
use super::{level_text, Study, Trial};

/// Where a served run's trials run.
#[derive(Debug)]
pub enum Runner<'a> {
    /// In the simulator: a block's trials on every core.
    Sim,
    /// On a study's live stations: one trial at a time, the experimenter's pause and abort heard
    /// between trials.
    Stations(&'a mut super::live::OnStations),
}

impl Runner<'_> {
    /// Runs `t` again (its next attempt) and appends its rows; its line to `outcome`.
    fn repeat(
        &mut self,
        tables: &mut Tables,
        study: &Study,
        t: &Trial,
        outcome: &mut dyn FnMut(String),
    ) -> anyhow::Result<()> {
        match self {
            Runner::Sim => tables.repeat(study, t, outcome),
            Runner::Stations(on) => {
                let attempt = tables.begin_repeat(t)?;
                outcome(on.run(tables, study, t, attempt, false)?);
                Ok(())
            }
        }
    }

    /// Runs a block's `trials` (first attempts) and appends their rows, each trial's line to
    /// `outcome`; how many ran (on stations, fewer when `go_on` says stop between two).
    fn block(
        &mut self,
        tables: &mut Tables,
        study: &Study,
        trials: &[&Trial],
        go_on: &dyn Fn() -> bool,
        outcome: &mut dyn FnMut(String),
    ) -> anyhow::Result<usize> {
        match self {
            Runner::Sim => {
                tables.run(study, trials, outcome)?;
                Ok(trials.len())
            }
            Runner::Stations(on) => {
                let mut ran = 0;
                for t in trials {
                    if ran > 0 && !go_on() {
                        break;
                    }
                    let cut = tables.begin(t)?;
                    outcome(on.run(tables, study, t, 1, cut)?);
                    ran += 1;
                }
                Ok(ran)
            }
        }
    }
}

/// [`super::run::run_sim`] as a lab's session goes, with the experimenter's page (`shared`, served by
/// [`super::web`]): group by group and block by block (in the simulator each block's trials on
/// every core; on stations one trial at a time), the experimenter's pause holding the next block
/// back (on stations, the next trial) and an abort ending the run after the block (the trial)
/// running, and after each block its questionnaire asked of each of the group's participants
/// (waited for; one a resumed run finds unanswered is asked again).
///
/// # Errors
/// As [`super::run::run_sim`]; the answers cannot be read; a station that fails.
pub fn run_served(
    study: &Study,
    out: &Path,
    resume: bool,
    shared: &super::board::Shared,
    runner: &mut Runner<'_>,
) -> anyhow::Result<Ran> {
    let started = Instant::now();
    let plan = study.plan();
    let mut tables = Tables::open(study, out, resume, plan.len())?;
    let kept = plan.iter().filter(|t| tables.holds(t)).count();
    shared.update(|b| b.done = kept);
    let items = shared
        .questionnaire
        .as_ref()
        .map_or(0, |q| q.questions().len());
    let answered = answered(&super::web::answers_path(out), items)?;
    let mut ran = 0;
    // The last trial run, for the experimenter's repeat.
    let mut last: Option<&Trial> = None;
    'groups: for (g, group) in study.groups.iter().enumerate() {
        let blocks = plan
            .iter()
            .filter(|t| t.group == g)
            .map(|t| t.block)
            .max()
            .unwrap_or(0);
        for block in 1..=blocks {
            let trials: Vec<&Trial> = plan
                .iter()
                .filter(|t| t.group == g && t.block == block)
                .collect();
            let todo: Vec<&Trial> = trials
                .iter()
                .copied()
                .filter(|t| !tables.holds(t))
                .collect();
            let levels = &trials[0].levels;
            if let (true, Some(t)) = (shared.take_repeat(), last) {
                runner.repeat(&mut tables, study, t, &mut |line| {
                    shared.trial_repeated(line)
                })?;
                ran += 1;
            }
            if !todo.is_empty() {
                if !shared.may_go_on() {
                    break 'groups;
                }
                let what = format!(
                    "{} block {block} of {blocks}: {}",
                    group.id,
                    study.condition_name(levels)
                );
                shared.update(|b| b.now = what);
                let n = runner.block(
                    &mut tables,
                    study,
                    &todo,
                    &|| shared.may_go_on(),
                    &mut |line| shared.trial_done(line),
                )?;
                ran += n;
                last = todo[..n].last().copied().or(last);
                if n < todo.len() {
                    break 'groups;
                }
            }
            if shared.questionnaire.is_some() {
                let owed: Vec<super::board::Pending> = group
                    .participants
                    .iter()
                    .zip(&study.sites)
                    .filter(|(p, _)| !answered.contains(&(group.id.clone(), block, (*p).clone())))
                    .map(|(p, site)| super::board::Pending {
                        group: group.id.clone(),
                        participant: p.clone(),
                        site: site.clone(),
                        block,
                        levels: study
                            .file
                            .factor
                            .iter()
                            .zip(levels)
                            .map(|(f, &l)| level_text(&f.levels[l]))
                            .collect(),
                    })
                    .collect();
                if !owed.is_empty() {
                    let what =
                        format!("{} block {block}: waiting for the questionnaires", group.id);
                    shared.update(|b| {
                        b.now = what;
                        b.pending = owed;
                    });
                    loop {
                        match shared.wait_answers() {
                            super::board::Waited::Answered => break,
                            super::board::Waited::Aborted => break 'groups,
                            super::board::Waited::Repeat => {
                                if let Some(t) = last {
                                    runner.repeat(&mut tables, study, t, &mut |line| {
                                        shared.trial_repeated(line)
                                    })?;
                                    ran += 1;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    let aborted = shared.lock().control == super::board::Control::Aborted;
    shared.update(|b| {
        b.finished = true;
        b.now = if aborted {
            "aborted: `study run --resume` goes on from here".into()
        } else {
            "every trial done".into()
        };
    });
    Ok(Ran {
        ran,
        kept,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// The questionnaires `path` holds whole, every one of its `items` on a complete line:
/// (group, block, participant). One cut by a crash is asked again.
fn answered(path: &Path, items: usize) -> anyhow::Result<Vec<(String, usize, String)>> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Ok(Vec::new());
    };
    let mut counts: std::collections::BTreeMap<(String, usize, String), usize> = Default::default();
    for line in text.split_inclusive('\n').skip(1) {
        if !line.ends_with('\n') {
            continue;
        }
        let c = super::csv::split(line.trim_end_matches(['\n', '\r']));
        if c.len() >= 5 {
            if let Ok(block) = c[4].parse() {
                *counts
                    .entry((c[1].clone(), block, c[2].clone()))
                    .or_default() += 1;
            }
        }
    }
    Ok(counts
        .into_iter()
        .filter(|(_, n)| *n >= items)
        .map(|(k, _)| k)
        .collect())
}
