//! A study's trials, both sides. The study runner (a launcher) puts each trial on
//! `coop/<session>/trial` ([`TrialMsg`]: its number, name and scenario), again and again until
//! every station says it is ready (its figures' [`TrialFigures`]), then the same trial with its
//! time 0 in the runner's clock, again until every station has taken it. A station started for a
//! study (`trials = true`) hears it here: it checks the scenario, closes its receiver's gate
//! (nothing of the last trial reaches physics any more), asks its servo and physics for the trial
//! (the control block's [`coop_rt::shm::control::TrialShared`]), and once all three processes
//! have stopped the last trial it drains what physics sent, finishes the last trial's recording,
//! starts the new one's and sets its receiver up for the new trial's links. It takes the time 0
//! once its servo and physics are ready, translated by the launcher's clock offset, and opens the
//! gate to what was sent from then on. When every site's task has ended (or the trial's timeout
//! passed), the runner puts the trial once more, ended: each station finishes its recording of
//! it, records nothing until the next trial, and its servo ramps the force out (a pause or a
//! questionnaire between trials displays nothing).
//!
//! Puts are repeated, and a station acts on a trial once (a number it has not seen yet), so a lost
//! put or one that overtakes another changes nothing.

use std::path::{Path, PathBuf};

use coop_rt::shm::control::{Child, ControlBlock, TaskState};
use coop_rt::sync::Ordering;
use serde::{Deserialize, Serialize};
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::sample::Sample;
use zenoh::{Session, Wait};

use std::sync::Mutex;

use super::epoch::translate;
use super::receive::{Gate, Receiver};
use super::{lock, Emulation, NetworkError};
use crate::admit::Bounds;
use crate::keys;
use crate::recording::Scene;

/// What the runner puts on the trial key (JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialMsg {
    /// The trial's number in the study's run (from 1, rising).
    pub trial: u64,
    /// Its name: the stations' recordings of it are named by it (`[A-Za-z0-9_.-]`, 1-64 bytes).
    pub name: String,
    /// Its scenario, as TOML.
    pub scenario: String,
    /// Its time 0 in the runner's CLOCK_MONOTONIC, ns, once every station is ready for it.
    pub epoch_ns: Option<u64>,
    /// The trial is over (every site's task ended, or its timeout): each station finishes its
    /// recording of it, so that the runner can read it.
    #[serde(default)]
    pub end: bool,
}

/// How far a station is with the trial asked for last, in its figures.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TrialFigures {
    /// The trial (0: none yet).
    pub trial: u64,
    /// Its name.
    pub name: String,
    /// Every process of the station has rebuilt itself for it.
    pub ready: bool,
    /// Why the station cannot run it (then it never becomes ready).
    pub refused: Option<String>,
    /// Its time 0 is taken (the trial runs, or ran).
    pub started: bool,
    /// Its end was heard and its recording is finished.
    pub recorded: bool,
    /// The task as this site shows it: `none`, `running`, `done`, `failed`.
    pub task: String,
    /// When it was done or failed, s from the trial's time 0.
    pub task_at_s: f64,
    /// What failed it: 0 the timeout (or not failed), k + 1 the task's `fail[k]`.
    pub failed_by: u64,
    /// Bytes this station has sent since it started (every kind of message).
    pub sent_bytes: u64,
    /// The process ids of its servo, physics and network processes: the same through a study
    /// (its processes are not restarted between trials).
    pub pids: Vec<u64>,
    /// The runner's clock minus this station's, as measured when the trial's time 0 was taken,
    /// ns (0: not measured).
    pub clock_offset_ns: i64,
}

/// What a station's network process needs for a trial, made from its scenario by the station
/// (which has the scenario parser and its own configuration).
#[derive(Debug)]
pub struct TrialSetup {
    /// The scenario's name, and its method.
    pub names: (String, String),
    /// Its fingerprint.
    pub scenario_hash: u64,
    /// Receive-side emulation of its network, if the station emulates.
    pub emulation: Option<Emulation>,
    /// What a received state may be.
    pub bounds: Bounds,
    /// Per site: how long it may be silent before it is lost, ns.
    pub silence_ns: Vec<u64>,
    /// What this site shows.
    pub scene: Scene,
    /// The emulated link, as the recording says it ([`Emulation::describe`], or `none`).
    pub emulation_text: String,
}

/// Makes a trial's [`TrialSetup`] from its scenario text, or says why the station cannot run it.
pub struct TrialSetupFn(pub Box<MakeSetup>);

/// See [`TrialSetupFn`].
pub type MakeSetup = dyn Fn(&str) -> Result<TrialSetup, String> + Send;

impl std::fmt::Debug for TrialSetupFn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("TrialSetupFn")
    }
}

/// A trial's name is safe in a file name.
pub fn valid_name(name: &str) -> bool {
    (1..=64).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"_.-".contains(&b))
        && !name.starts_with('.')
}

/// Where a trial's recording goes, beside the station's `record` file: `<stem>-<trial>.mcap`.
pub fn record_path(record: &Path, name: &str) -> PathBuf {
    let stem = record
        .file_stem()
        .map_or_else(|| "station".into(), |s| s.to_string_lossy().into_owned());
    record.with_file_name(format!("{stem}-{name}.mcap"))
}

/// How far what was sent before a trial's time 0 may be taken as the trial's own, ns: a track
/// of the trial's first tick is sent at its time 0 by the sender's clock, which the measured
/// offset maps into ours within far less; the last trial's were sent before every station was
/// ready, at least the runner's lead before time 0.
pub const GATE_SLACK_NS: u64 = 100_000_000;

/// A station's side.
pub(super) struct TrialListener {
    sub: Subscriber<FifoChannelHandler<Sample>>,
    setup: TrialSetupFn,
    /// The newest trial heard (0: none).
    asked: u64,
    name: String,
    phase: Phase,
    refused: Option<String>,
    /// The trial's time 0 as announced, in the runner's clock.
    epoch_heard: Option<u64>,
    /// The trial's end was heard.
    end_heard: bool,
    /// The runner's clock offset when the time 0 was taken, ns.
    offset_ns: i64,
    said_bad: bool,
}

/// Where a station is with the newest trial.
enum Phase {
    /// No trial yet, or one refused.
    Idle,
    /// Asked of the servo and physics; waiting until every process has stopped the last one.
    Stopping(Box<TrialSetup>),
    /// The network is set up for it; waiting for the servo and physics to be.
    Rebuilding,
    /// Every process is ready; waiting for its time 0.
    Ready,
    /// Its time 0 is taken.
    Started,
    /// Its end was heard: its recording is finished.
    Ended,
}

/// What the network loop must do for a trial.
pub(super) enum Change {
    /// Every process has stopped the last trial: drain physics' rings, finish the last trial's
    /// recording and start this one's, set the receiver up with this setup, then say it is ready
    /// ([`TrialListener::network_ready`]).
    Rebuild(Box<TrialSetup>),
    /// The trial's time 0 is taken, ns on our clock: open the receiver's gate from it.
    Started(u64),
    /// The trial is over: finish its recording (nothing is recorded until the next trial).
    End,
}

impl TrialListener {
    /// Subscribes to `session_name`'s trials; `setup` makes each one's network pieces.
    pub(super) fn declare(
        session: &Session,
        session_name: &str,
        setup: TrialSetupFn,
    ) -> Result<Self, NetworkError> {
        let sub = session
            .declare_subscriber(keys::trial(session_name))
            .wait()
            .map_err(NetworkError::declare("trial subscriber"))?;
        Ok(Self {
            sub,
            setup,
            asked: 0,
            name: String::new(),
            phase: Phase::Idle,
            refused: None,
            epoch_heard: None,
            end_heard: false,
            offset_ns: 0,
            said_bad: false,
        })
    }

    /// The trial asked for last (0: none).
    pub(super) fn asked(&self) -> u64 {
        self.asked
    }

    /// The trial being run's name (none before the first).
    pub(super) fn name(&self) -> Option<&str> {
        (self.asked > 0).then_some(self.name.as_str())
    }

    /// Takes what the runner put since the last call and moves the trial on; what the loop must
    /// do, if anything. `launcher` is the launcher's clock offset and round trip once measured.
    pub(super) fn poll(
        &mut self,
        ctl: &ControlBlock,
        launcher: Option<(u64, i64)>,
        site: &str,
        rx: &Mutex<Receiver<'_>>,
    ) -> Option<Change> {
        while let Ok(Some(s)) = self.sub.try_recv() {
            let bytes = s.payload().to_bytes();
            match serde_json::from_slice::<TrialMsg>(&bytes) {
                Ok(m) => self.hear(ctl, m, site, rx),
                Err(e) => {
                    if !self.said_bad {
                        self.said_bad = true;
                        eprintln!("network {site}: refused a trial message: {e} (further ones are only dropped)");
                    }
                }
            }
        }
        match std::mem::replace(&mut self.phase, Phase::Idle) {
            Phase::Stopping(setup) if ctl.trial.all_stopped(self.asked) => {
                self.phase = Phase::Rebuilding;
                return Some(Change::Rebuild(setup));
            }
            Phase::Rebuilding => {
                let k = self.asked;
                match (
                    ctl.trial.ready(Child::Servo, k),
                    ctl.trial.ready(Child::Physics, k),
                ) {
                    (Some(s), Some(p)) => match s.and(p) {
                        Ok(()) => self.phase = Phase::Ready,
                        Err(why) => self.refuse(why, site),
                    },
                    _ => self.phase = Phase::Rebuilding,
                }
            }
            Phase::Started if self.end_heard => {
                self.phase = Phase::Ended;
                return Some(Change::End);
            }
            // Taken already: a restarted network process took the trial up as it runs.
            Phase::Ready if ctl.epoch().is_some() => {
                self.phase = Phase::Started;
                return ctl.epoch().map(Change::Started);
            }
            Phase::Ready => match (self.epoch_heard, launcher) {
                (Some(e), Some((_, offset))) => {
                    let local = translate(e, offset);
                    // SYNC: Release pairs with `ControlBlock::epoch`'s Acquire (cleared to 0 when
                    // the trial was asked for).
                    let _ = ctl.epoch_ns.compare_exchange(
                        0,
                        local,
                        Ordering::AcqRel,
                        Ordering::Relaxed,
                    );
                    self.phase = Phase::Started;
                    self.offset_ns = offset;
                    eprintln!(
                        "network {site}: trial {} ({}) starts",
                        self.asked, self.name
                    );
                    return Some(Change::Started(local));
                }
                _ => self.phase = Phase::Ready,
            },
            other => self.phase = other,
        }
        None
    }

    /// The network process is set up for the trial asked for.
    pub(super) fn network_ready(&self, ctl: &ControlBlock) {
        ctl.trial.set_ready(Child::Network, self.asked, "");
    }

    /// The network process could not set itself up for the trial (its recording): refused.
    pub(super) fn fail(&mut self, why: String, site: &str) {
        let why = format!("trial {} ({}): {why}", self.asked, self.name);
        self.refuse(why, site);
    }

    fn refuse(&mut self, why: String, site: &str) {
        eprintln!("network {site}: refused {why}");
        self.refused = Some(why);
        self.phase = Phase::Idle;
    }

    fn hear(&mut self, ctl: &ControlBlock, m: TrialMsg, site: &str, rx: &Mutex<Receiver<'_>>) {
        if m.trial < self.asked || m.trial == 0 {
            return;
        }
        if m.trial == self.asked {
            if let Some(e) = m.epoch_ns.filter(|&e| e != 0) {
                self.epoch_heard.get_or_insert(e);
            }
            self.end_heard |= m.end;
            return;
        }
        // A new trial: whatever happens next, it is the one this station answers for.
        self.asked = m.trial;
        self.name.clone_from(&m.name);
        self.refused = None;
        self.epoch_heard = m.epoch_ns.filter(|&e| e != 0);
        self.end_heard = m.end;
        self.offset_ns = 0;
        if !valid_name(&m.name) {
            return self.refuse(
                format!(
                    "trial {} named {:?}: a trial's name is 1 to 64 of A-Z a-z 0-9 _ . - (its recordings are named by it)",
                    m.trial, m.name
                ),
                site,
            );
        }
        let setup = match (self.setup.0)(&m.scenario) {
            Ok(s) => s,
            Err(why) => return self.refuse(format!("trial {} ({}): {why}", m.trial, m.name), site),
        };
        if m.scenario.len() > coop_rt::shm::control::TRIAL_SCENARIO_WORDS * 8 {
            return self.refuse(
                format!(
                    "trial {} ({}): its scenario is {} bytes, more than a station holds ({})",
                    m.trial,
                    m.name,
                    m.scenario.len(),
                    coop_rt::shm::control::TRIAL_SCENARIO_WORDS * 8
                ),
                site,
            );
        }
        lock(rx).gate = Gate::Closed;
        if m.trial == ctl.trial.requested() {
            // Asked for already, by this station's network process before a restart: the
            // servo and physics have it (and may be running it); this process sets itself up
            // for it and takes its time 0 as it stands.
            eprintln!(
                "network {site}: trial {} ({}) taken up as the station runs it",
                m.trial, m.name
            );
        } else {
            // Nothing more of the last trial reaches physics, and nothing of its time 0 stays:
            // the servo and physics wait for the next one's.
            ctl.epoch_ns.store(0, Ordering::Release);
            ctl.trial.request(m.trial, &m.name, &m.scenario);
            eprintln!("network {site}: trial {} ({}) asked for", m.trial, m.name);
        }
        ctl.trial.set_stopped(Child::Network, m.trial);
        self.phase = Phase::Stopping(Box::new(setup));
    }

    /// What the figures say of the trial now.
    pub(super) fn figures(&self, ctl: &ControlBlock) -> TrialFigures {
        let (task, at_s, failed_by) = ctl.task.read().unwrap_or((TaskState::None, 0.0, 0));
        TrialFigures {
            trial: self.asked,
            name: self.name.clone(),
            ready: matches!(self.phase, Phase::Ready | Phase::Started | Phase::Ended),
            refused: self.refused.clone(),
            started: matches!(self.phase, Phase::Started | Phase::Ended),
            recorded: matches!(self.phase, Phase::Ended),
            task: task.name().into(),
            task_at_s: at_s,
            failed_by,
            sent_bytes: ctl.network.traffic.sent_bytes.total(),
            pids: Child::ALL
                .iter()
                .map(|&c| ctl.child(c).pid.load(Ordering::Relaxed))
                .collect(),
            clock_offset_ns: self.offset_ns,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trial_names_are_file_name_safe_and_name_the_recording() {
        assert!(valid_name("g01-t003_timewarp.100ms"));
        for bad in ["", ".hidden", "a/b", "a b", "ü", &"x".repeat(65)] {
            assert!(!valid_name(bad), "{bad:?}");
        }
        assert_eq!(
            record_path(Path::new("/tmp/run/user1.mcap"), "g01-t003"),
            PathBuf::from("/tmp/run/user1-g01-t003.mcap")
        );
    }
}
