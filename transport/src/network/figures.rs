//! A station's figures for a launcher that cannot read its control block (`session run
//! --attach`, the stations on other machines): answered on the station's figures key, as JSON,
//! from the control block when asked. Deadlines missed count from the session's time 0, as the
//! launcher counts them for stations it started.

use coop_rt::shm::control::ControlBlock;
use coop_rt::shm::rollback::RollbackFigures;
use coop_rt::sync::Ordering;
use serde::{Deserialize, Serialize};
use zenoh::handlers::FifoChannelHandler;
use zenoh::query::{Query, Queryable};
use zenoh::{Session, Wait};

use super::NetworkError;
use crate::keys;

/// A scenario's fingerprint: FNV-1a 64 of its parsed form, so two files that parse to the same
/// scenario (comments, order, the embedded default against its file) agree and any field that
/// differs does not.
pub fn scenario_hash(sc: &coop_model::scenario::Scenario) -> u64 {
    coop_rt::pod::fnv1a64(format!("{sc:?}").as_bytes())
}

/// What a station runs: what a launcher attaching to it checks before time 0.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StationRuns {
    /// Its scenario's name...
    pub scenario: String,
    /// ... and fingerprint ([`scenario_hash`], its method included).
    pub scenario_hash: u64,
    /// Its method.
    pub method: String,
    /// Whether it emulates the scenario's network on receive.
    pub emulated: bool,
}

/// What a station says about its run: the figures `session run`'s stations table shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StationFigures {
    /// The site.
    pub site: String,
    /// What it runs.
    pub runs: StationRuns,
    /// Servo deadlines missed since the session's time 0 (all of them before it is known).
    pub servo_overruns: u64,
    /// Physics deadlines missed since then.
    pub physics_overruns: u64,
    /// Physics cycles run since then.
    pub physics_cycles: u64,
    /// Physics' compute time per cycle, 99th percentile over its life, µs.
    pub physics_compute_p99_us: u64,
    /// Rollback and tool-track figures, if the method rolls back.
    pub rollback: Option<RollbackFigures>,
    /// A study's station: how far it is with the trial asked for last.
    #[serde(default)]
    pub trial: Option<super::trial::TrialFigures>,
}

/// The station's figures queryable, and the counters at the session's time 0.
pub(super) struct Figures {
    queryable: Queryable<FifoChannelHandler<Query>>,
    key: String,
    site: String,
    runs: StationRuns,
    /// (servo overruns, physics overruns, physics cycles) when time 0 came.
    at_epoch: Option<[u64; 3]>,
    /// A study's station: its trial, as the loop last saw it.
    pub(super) trial: Option<super::trial::TrialFigures>,
}

impl Figures {
    /// Declares `site`'s figures queryable in `session_name`, saying it `runs` what it runs.
    pub(super) fn declare(
        session: &Session,
        session_name: &str,
        site: &str,
        runs: StationRuns,
    ) -> Result<Self, NetworkError> {
        let key = keys::figures(session_name, site);
        let queryable = session
            .declare_queryable(&key)
            .wait()
            .map_err(NetworkError::declare("figures queryable"))?;
        Ok(Self {
            queryable,
            key,
            site: site.to_owned(),
            runs,
            at_epoch: None,
            trial: None,
        })
    }

    /// A study's next trial runs `runs`: its counters count from its time 0.
    pub(super) fn begin_trial(&mut self, runs: StationRuns) {
        self.runs = runs;
        self.at_epoch = None;
    }

    fn counters(ctl: &ControlBlock) -> [u64; 3] {
        [
            ctl.servo.stats.overruns.load(Ordering::Relaxed),
            ctl.physics.stats.overruns.load(Ordering::Relaxed),
            ctl.physics.stats.cycles.load(Ordering::Relaxed),
        ]
    }

    /// The figures now.
    pub(super) fn now(&self, ctl: &ControlBlock) -> StationFigures {
        let [s, p, c] = Self::counters(ctl);
        let [s0, p0, c0] = self.at_epoch.unwrap_or_default();
        StationFigures {
            site: self.site.clone(),
            runs: self.runs.clone(),
            servo_overruns: s.saturating_sub(s0),
            physics_overruns: p.saturating_sub(p0),
            physics_cycles: c.saturating_sub(c0),
            physics_compute_p99_us: ctl
                .physics
                .stats
                .snapshot()
                .compute_us
                .value_at_quantile(0.99),
            rollback: ctl.physics.rollback.figures(),
            trial: self.trial.clone(),
        }
    }

    /// Takes the counters when the session's time 0 has come, and answers the queries waiting.
    pub(super) fn turn(&mut self, ctl: &ControlBlock, now: u64) {
        if self.at_epoch.is_none() && ctl.epoch().is_some_and(|e| now >= e) {
            self.at_epoch = Some(Self::counters(ctl));
        }
        while let Ok(Some(q)) = self.queryable.try_recv() {
            let Ok(json) = serde_json::to_vec(&self.now(ctl)) else {
                continue;
            };
            // A launcher gone before the reply is not this station's problem.
            let _ = q.reply(&self.key, json).wait();
        }
    }
}

/// Asks every station of `session_name` for its figures, waiting at most `timeout` for the
/// replies; those that parse, by site.
pub fn ask(
    session: &Session,
    session_name: &str,
    timeout: std::time::Duration,
) -> std::collections::BTreeMap<String, StationFigures> {
    let mut out = std::collections::BTreeMap::new();
    let Ok(replies) = session
        .get(keys::all_figures(session_name))
        .timeout(timeout)
        .wait()
    else {
        return out;
    };
    while let Ok(r) = replies.recv() {
        if let Some(f) = r
            .result()
            .ok()
            .and_then(|s| serde_json::from_slice::<StationFigures>(&s.payload().to_bytes()).ok())
        {
            out.insert(f.site.clone(), f);
        }
    }
    out
}
