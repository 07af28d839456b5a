//! A study's trials on a station that stays up for all of them (`trials = true`): how the servo
//! and physics processes leave one trial and rebuild themselves for the next without a restart
//! (the device stays open, the rings are reused), following the handshake of
//! [`coop_rt::shm::control::TrialShared`]. The network process hears the trials from the study
//! runner and drives its side of it (`coop_transport::network`).

use std::time::Duration;

use coop_model::scenario::Scenario;
use coop_rt::shm::control::{Child, ControlBlock, RunState};
use coop_rt::sync::Ordering;

use super::config::Resolved;

/// How often a process waiting for the others to stop looks again (not a loop's tick: between
/// trials nothing is displayed or stepped).
const POLL: Duration = Duration::from_millis(1);

fn running(ctl: &ControlBlock) -> bool {
    matches!(ctl.run_state(), RunState::Starting | RunState::Running)
}

/// After `child`'s loop for `trial` has ended: whether a later trial is asked for (not a stop).
/// If so, says that `child` produces nothing more of the last one, waits until the other
/// processes have said so too (its heartbeat going on meanwhile, so the supervisor does not take
/// the wait for a hang), and sets `trial` to the one asked for; `false` when the station stops.
pub fn next(ctl: &ControlBlock, child: Child, trial: &mut u64) -> bool {
    if !running(ctl) {
        return false;
    }
    let mut k = ctl.trial.requested();
    if k <= *trial {
        return false;
    }
    ctl.trial.set_stopped(child, k);
    let slot = ctl.child(child);
    while !ctl.trial.all_stopped(k) {
        if !running(ctl) {
            return false;
        }
        slot.heartbeat.fetch_add(1, Ordering::Relaxed);
        std::thread::sleep(POLL);
        // A later trial asked for meanwhile (the runner skipped one): stop for it instead.
        let newer = ctl.trial.requested();
        if newer > k {
            k = newer;
            ctl.trial.set_stopped(child, k);
        }
    }
    *trial = k;
    true
}

/// After `child` has rebuilt itself for `trial` (and said so): waits until the network process
/// has too, which first drains what physics sent of the last trial (so nothing of the new one is
/// written into the last one's recording or dropped with its leftovers); `false` when the
/// station stops meanwhile.
pub fn wait_network(ctl: &ControlBlock, child: Child, trial: u64) -> bool {
    let slot = ctl.child(child);
    while ctl.trial.ready(Child::Network, trial).is_none() {
        if !running(ctl) || ctl.trial.requested() > trial {
            // Stopping, or a later trial already: the loop ends at once and sees which.
            return running(ctl);
        }
        slot.heartbeat.fetch_add(1, Ordering::Relaxed);
        std::thread::sleep(POLL);
    }
    true
}

/// A process started (or restarted) while trial `trial` is asked for builds it at once (having
/// emptied the rings it reads, if the trial has not started: its predecessor may have died before
/// it did), and says it is stopped and ready, or why it cannot run the trial (`refused`).
pub fn joined(ctl: &ControlBlock, child: Child, trial: u64, refused: &str) {
    if trial > 0 {
        ctl.trial.set_stopped(child, trial);
        if ctl.trial.ready(child, trial).is_none() {
            ctl.trial.set_ready(child, trial, refused);
        }
    }
}

/// `child` has rebuilt itself for `trial` (`refused`: why it could not; empty: it could): says so,
/// then waits for the network process as [`wait_network`] does.
pub fn rebuilt(ctl: &ControlBlock, child: Child, trial: u64, refused: &str) {
    ctl.trial.set_ready(child, trial, refused);
    // (A stop or a later trial meanwhile: the loop's first tick sees it.)
    wait_network(ctl, child, trial);
}

/// The trial asked for now (0: none; a process restarted in the middle of one runs it), the
/// scenario to build from, and why the trial's does not fit (see [`scenario_or_own`]).
pub fn current(cfg: &Resolved, ctl: &ControlBlock) -> (u64, Scenario, String) {
    match ctl.trial.requested() {
        0 => (0, cfg.scenario.clone(), String::new()),
        k => {
            let (sc, refused) = scenario_or_own(cfg, ctl);
            (k, sc, refused)
        }
    }
}

/// The scenario to build the trial asked for from: its own, or, when it does not fit, the
/// station's (held: no time 0 comes for a refused trial), with why (empty: it fits).
pub fn scenario_or_own(cfg: &Resolved, ctl: &ControlBlock) -> (Scenario, String) {
    match scenario(cfg, ctl) {
        Ok(sc) => (sc, String::new()),
        Err(why) => (cfg.scenario.clone(), why),
    }
}

/// The scenario of the trial asked for, parsed and checked against the station's own
/// ([`parse`]).
///
/// # Errors
/// As [`parse`], the trial named.
pub fn scenario(cfg: &Resolved, ctl: &ControlBlock) -> Result<Scenario, String> {
    // A trial asked for while the texts were read is read again (and a text torn by a rewrite
    // that came between is superseded by the trial that rewrote it, asked for right after).
    let (k, name, text) = loop {
        let k = ctl.trial.requested();
        let (name, text) = (ctl.trial.name.load(), ctl.trial.scenario.load());
        if ctl.trial.requested() == k {
            break (k, name, text);
        }
    };
    parse(&cfg.scenario, &text).map_err(|e| format!("trial {k} ({name}): {e}"))
}

/// A trial's scenario `text`, parsed and checked against the station's own, `station`: the rings
/// were made for its sites, its objects and its kind of method, so a trial may change anything
/// else (the method among those of the same kind, the network, the people, the rates).
///
/// # Errors
/// The scenario does not parse, breaks a rule, or does not fit the station (in words that name
/// the field).
pub fn parse(station: &Scenario, text: &str) -> Result<Scenario, String> {
    let sc = crate::scenario_file::parse(text).map_err(|e| format!("its scenario: {e}"))?;
    fits(station, &sc)?;
    Ok(sc)
}

/// Whether a trial's scenario `trial` can run on a station started with `station`'s.
///
/// # Errors
/// The field that differs, both values, and the rule.
pub fn fits(station: &Scenario, trial: &Scenario) -> Result<(), String> {
    let names = |sc: &Scenario| sc.site.iter().map(|s| s.name.clone()).collect::<Vec<_>>();
    if names(station) != names(trial) {
        return Err(format!(
            "site = {:?}, the station's scenario has {:?}: a trial keeps the study's sites",
            names(trial),
            names(station)
        ));
    }
    if station.objects.len() != trial.objects.len() {
        return Err(format!(
            "{} objects, the station's scenario has {}: its rings are sized for its world",
            trial.objects.len(),
            station.objects.len()
        ));
    }
    let grid = |sc: &Scenario| sc.steps_on_grid(sc.method);
    if grid(station) != grid(trial) {
        return Err(format!(
            "method = {:?} {} tool tracks and the station's {:?} {}: a study's methods all exchange tool tracks (timewarp, coupled) or none do (naive, paper)",
            trial.method.as_str(),
            if grid(trial) { "exchanges" } else { "does not exchange" },
            station.method.as_str(),
            if grid(station) { "does" } else { "does not" },
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use coop_model::scenario::MethodName;

    fn tray() -> Scenario {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenarios/participants/tray.toml");
        crate::scenario_file::load(&path).expect("the tray scenario")
    }

    #[test]
    fn a_trial_may_change_the_method_of_its_kind_and_the_network_but_not_the_world() {
        let station = tray();
        let mut t = station.clone();
        t.method = MethodName::Coupled;
        t.network.delay_min_ms = 300.0;
        t.network.delay_max_ms = 300.0;
        assert_eq!(fits(&station, &t), Ok(()));
        t.method = MethodName::Paper;
        let e = fits(&station, &t).expect_err("paper exchanges no tracks");
        assert!(e.contains("method = \"paper\""), "{e}");
        let mut t = station.clone();
        t.site[1].name = "other".into();
        assert!(fits(&station, &t).expect_err("renamed").contains("site = "));
        let mut t = station.clone();
        t.objects.pop();
        assert!(fits(&station, &t).expect_err("fewer").contains("objects"));
    }
}
