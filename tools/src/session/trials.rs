//! A study's stations on this machine, started once for all its trials: the runner's side of
//! [`coop_transport::network::trial`]. Each trial is put (its scenario) until every station is
//! ready for it, then put again with its time 0 until every station has taken it, and runs until
//! every site's task is done or failed, or its timeout passes; then put once more, ended, until
//! every station has finished its recording of it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use coop_model::scenario::Scenario;
use coop_transport::network::figures::{self, StationFigures};
use coop_transport::network::trial::{TrialFigures, TrialMsg};
use coop_transport::network::{self as net, EpochAnnouncer};
use zenoh::Wait;

use super::stations::{self, Station};
use super::{watch_presence, RunArgs};

/// How far ahead of now a trial's time 0 is put: every station has it before it matters.
pub const LEAD: Duration = Duration::from_millis(500);
/// How often a put is repeated and the stations asked, while waiting.
const ASK_EVERY: Duration = Duration::from_millis(100);
/// How long the stations have to get ready for a trial (the servo's ramp to zero, a rebuild).
const READY_TIMEOUT: Duration = Duration::from_secs(20);

/// The stations of a study, up.
pub struct StudyStations {
    z: zenoh::Session,
    session: String,
    /// The launcher's clock (the stations translate each time 0 with it).
    _clock: EpochAnnouncer,
    _presence: zenoh::pubsub::Subscriber<()>,
    stations: Vec<Station>,
    sites: Vec<String>,
    dir: PathBuf,
}

impl std::fmt::Debug for StudyStations {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StudyStations")
            .field("session", &self.session)
            .field("sites", &self.sites)
            .field("dir", &self.dir)
            .finish_non_exhaustive()
    }
}

/// What one trial gave, per site.
#[derive(Debug, Clone)]
pub struct TrialRun {
    /// Per site, its figures when the trial ended.
    pub sites: BTreeMap<String, TrialFigures>,
    /// Seconds from asking for the trial to every station being ready for it.
    pub setup_s: f64,
    /// Seconds from its time 0 to its end.
    pub run_s: f64,
    /// Per site, the bytes it sent from being ready for the trial to its end.
    pub sent_bytes: BTreeMap<String, u64>,
    /// Per site, its method's rollback figures over the trial (the grid's methods: `timewarp`,
    /// and `coupled`, which rolls nothing back; none for the others).
    pub rollback: BTreeMap<String, Option<coop_rt::shm::rollback::RollbackFigures>>,
}

impl StudyStations {
    /// Starts one station per site of `sc` (`a.trials` set: each waits for the trials), writing
    /// their configurations, logs and recordings into `dir`, and waits until all are present.
    ///
    /// # Errors
    /// A station that does not start or is not present in time.
    pub fn start(a: &RunArgs, sc: &Scenario, session: &str, dir: &Path) -> anyhow::Result<Self> {
        if !a.trials {
            bail!("a study's stations are started for trials (RunArgs::trials)");
        }
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let dir = std::fs::canonicalize(dir)?;
        let n = sc.site.len();
        let ports = stations::loopback_ports(n);
        let mut stations = stations::prepare(a, sc, session, &dir, &ports)?;
        let z = stations::launcher_session(&ports)?;
        let (present, presence) = watch_presence(&z, session)?;
        let clock = EpochAnnouncer::declare(&z, session)?;
        for st in &mut stations {
            st.spawn(&a.station_bin)?;
        }
        // (An error drops the stations, each stopping with its own stop ladder.)
        super::launch::wait_present(a, &mut stations, &present, &dir)?;
        Ok(Self {
            z,
            session: session.to_owned(),
            _clock: clock,
            _presence: presence,
            sites: stations.iter().map(|s| s.site.clone()).collect(),
            stations,
            dir,
        })
    }

    /// Each station's recording of trial `name`.
    pub fn recordings(&self, name: &str) -> Vec<(String, PathBuf)> {
        self.stations
            .iter()
            .map(|s| (s.site.clone(), net::trial::record_path(&s.record, name)))
            .collect()
    }

    /// Where the stations' configurations, logs and recordings are.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn put(&self, m: &TrialMsg) -> anyhow::Result<()> {
        let json = serde_json::to_vec(m)?;
        self.z
            .put(coop_transport::keys::trial(&self.session), json)
            .wait()
            .map_err(|e| anyhow::anyhow!("putting trial {}: {e}", m.trial))
    }

    /// Every station's figures of trial `k` (its trial's and the whole station's), once each
    /// has answered for it.
    fn ask(&self, k: u64) -> Option<BTreeMap<String, (TrialFigures, StationFigures)>> {
        let mut got: BTreeMap<String, StationFigures> =
            figures::ask(&self.z, &self.session, ASK_EVERY);
        let out: BTreeMap<String, (TrialFigures, StationFigures)> = self
            .sites
            .iter()
            .filter_map(|s| {
                let f = got.remove(s)?;
                let t = f.trial.clone().filter(|t| t.trial == k)?;
                Some((s.clone(), (t, f)))
            })
            .collect();
        (out.len() == self.sites.len()).then_some(out)
    }

    /// Runs trial `k` (rising from 1) named `name` of scenario `text` (which parses to `sc`):
    /// until every site's task has ended, or `timeout` from its time 0.
    ///
    /// # Errors
    /// A station refuses the trial or is not ready in time; a station exited; interrupted.
    pub fn trial(
        &mut self,
        a: &RunArgs,
        k: u64,
        name: &str,
        text: &str,
        timeout: Duration,
    ) -> anyhow::Result<TrialRun> {
        let mut m = TrialMsg {
            trial: k,
            name: name.to_owned(),
            scenario: text.to_owned(),
            epoch_ns: None,
            end: false,
        };
        let asked = Instant::now();
        let at_ready: BTreeMap<String, TrialFigures>;
        // Until every station is ready (a put lost or not yet routed is put again).
        loop {
            self.check(a)?;
            self.put(&m)?;
            if let Some(f) = self.ask(k) {
                if let Some((site, why)) = f
                    .iter()
                    .find_map(|(s, (t, _))| t.refused.as_ref().map(|w| (s, w)))
                {
                    bail!("station {site} refused trial {k} ({name}): {why}");
                }
                if f.values().all(|(t, _)| t.ready) {
                    at_ready = f.into_iter().map(|(s, (t, _))| (s, t)).collect();
                    break;
                }
            }
            if asked.elapsed() > READY_TIMEOUT {
                bail!(
                    "the stations were not ready for trial {k} ({name}) after {READY_TIMEOUT:?} (logs in {})",
                    self.dir.display()
                );
            }
        }
        let setup_s = asked.elapsed().as_secs_f64();
        let t0 = coop_rt::timer::monotonic_ns() + LEAD.as_nanos() as u64;
        m.epoch_ns = Some(t0);
        let end = t0 + timeout.as_nanos() as u64;
        // The stations' figures when every task had ended, or at the timeout: the trial's.
        let mut at_end = None;
        loop {
            self.check(a)?;
            let f = self.ask(k);
            if f.as_ref()
                .is_none_or(|f| f.values().any(|(t, _)| !t.started))
            {
                self.put(&m)?;
            }
            let ended = f.as_ref().is_some_and(|f| {
                f.values()
                    .all(|(t, _)| t.started && matches!(t.task.as_str(), "done" | "failed"))
            });
            if f.is_some() {
                at_end = f;
            }
            if ended || coop_rt::timer::monotonic_ns() >= end {
                break;
            }
        }
        let run_s = coop_rt::timer::monotonic_ns().saturating_sub(t0) as f64 * 1e-9;
        let Some(at_end) = at_end else {
            bail!(
                "the stations did not answer during trial {k} ({name}) (logs in {})",
                self.dir.display()
            );
        };
        let late: Vec<&str> = at_end
            .iter()
            .filter(|(_, (t, _))| !t.started)
            .map(|(s, _)| s.as_str())
            .collect();
        if !late.is_empty() {
            bail!(
                "station {} never took the time 0 of trial {k} ({name}) (logs in {})",
                late.join(", "),
                self.dir.display()
            );
        }
        // Over: every station finishes its recording of it (what the runner then reads), says so
        // with its figures, and ramps its force out until the next trial.
        m.end = true;
        let ending = Instant::now();
        loop {
            self.check(a)?;
            self.put(&m)?;
            let f = self.ask(k);
            if f.as_ref()
                .is_some_and(|f| f.values().all(|(t, _)| t.recorded))
            {
                break;
            }
            if ending.elapsed() > READY_TIMEOUT {
                let open: Vec<&str> = match &f {
                    Some(f) => f
                        .iter()
                        .filter(|(_, (t, _))| !t.recorded)
                        .map(|(s, _)| s.as_str())
                        .collect(),
                    None => vec!["(one did not answer)"],
                };
                bail!(
                    "station {} did not finish its recording of trial {k} ({name}) in {READY_TIMEOUT:?} (logs in {})",
                    open.join(", "),
                    self.dir.display()
                );
            }
        }
        let last = at_end;
        let sent_bytes = last
            .iter()
            .map(|(s, (t, _))| {
                let before = at_ready.get(s).map_or(0, |r| r.sent_bytes);
                (s.clone(), t.sent_bytes.saturating_sub(before))
            })
            .collect();
        let rollback = last
            .iter()
            .map(|(s, (_, f))| (s.clone(), f.rollback))
            .collect();
        Ok(TrialRun {
            sites: last.into_iter().map(|(s, (t, _))| (s, t)).collect(),
            setup_s,
            run_s,
            sent_bytes,
            rollback,
        })
    }

    fn check(&mut self, a: &RunArgs) -> anyhow::Result<()> {
        stations::check_alive(&mut self.stations)?;
        if a.stop.is_raised() {
            bail!(
                "interrupted: the stations are stopped (their logs are in {})",
                self.dir.display()
            );
        }
        Ok(())
    }

    /// The stations' process ids (supervisors), by site: the same for every trial.
    pub fn pids(&self) -> BTreeMap<String, Option<u32>> {
        self.stations
            .iter()
            .map(|s| {
                (
                    s.site.clone(),
                    s.child.as_ref().map(std::process::Child::id),
                )
            })
            .collect()
    }

    /// Stops every station (each with its stop ladder).
    ///
    /// # Errors
    /// A station that did not stop cleanly.
    pub fn stop(mut self) -> anyhow::Result<()> {
        let r = stations::stop_all(&mut self.stations);
        let _ = self.z.close().wait();
        r
    }
}
