//! `session`: the product's main job — a multi-site session of real stations on this machine.
//!
//! `session run SCENARIO` starts one `station run` per site of the scenario (each a supervisor with
//! its servo, physics and network processes), connected as zenoh peers on loopback with the
//! scenario's network emulated on receive. It waits until every station is present (liveliness),
//! announces the session's time 0, runs the users' scripts, stops the stations cleanly, reads their
//! MCAP recordings, and prints the metrics table of `sim compare` for the real run next to the
//! simulator's figures for the same scenario, with the Fig. 9–12 plots per method.
//!
//! Next to the stations' recordings it writes `session.mcap`: every site's copy, tool and forces
//! on the scenario's grid, the divergence, and the simulator's reference copy, in one file as
//! `sim run` writes it for a simulated run ([`coop_transport::recording::session`]).
//!
//! With `--live`, the launcher also serves every site's copy, tool and force to Foxglove while the
//! session runs ([`coop_transport::live_view`]).
//!
//! With `--attach` ([`attach`]), it drives stations it did not start, on other machines: it waits
//! for their presence through a router or at given locators, announces time 0 in its own clock
//! (each station translates it with its measured offset to the launcher's clock), and reads their
//! recordings from paths.
//!
//! Stations die with the launcher (parent-death signal, then their own stop ladder), so an
//! interrupted session leaves nothing behind.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{bail, Context};
use coop_actors::scenario_file;
use coop_model::scenario::{MethodName, Scenario};
use coop_transport::keys;
use zenoh::Wait;

pub mod attach;
mod launch;
mod outcome;
mod recorded;
mod report;
mod stations;
pub mod trials;

pub use launch::run_method;
pub use outcome::{
    LiveStatus, MethodOutcome, ObjectFigures, ObjectRow, SessionOverruns, SessionRun,
    StationReport, WireRow,
};
pub use recorded::run_from_recordings;
pub use report::print as print_report;
pub use stations::station_run;

/// What `session run` was asked.
#[derive(Debug, Clone)]
pub struct RunArgs {
    /// Scenario file.
    pub scenario: PathBuf,
    /// Output directory (per method: station configs, logs, recordings, metrics, plots).
    pub out: PathBuf,
    /// Methods to run, one session each.
    pub methods: Vec<MethodName>,
    /// Session name prefix (default: unique per launcher).
    pub session: Option<String>,
    /// Sites that join late: (site, seconds after the session's start).
    pub late: Vec<(String, f64)>,
    /// Emulate the scenario's network on receive (default on).
    pub emulate: bool,
    /// How long stations get to be present.
    pub start_timeout: Duration,
    /// The station program.
    pub station_bin: StationBin,
    /// Show progress on a terminal.
    pub progress: bool,
    /// Raised by SIGINT/SIGTERM: stop the stations cleanly and return.
    pub stop: crate::cli::StopFlag,
    /// The stations' `record_max_file_s` (default: the station's own).
    pub record_max_file_s: Option<u64>,
    /// Serve each session live to Foxglove while it runs (`--live`).
    pub live: Option<Arc<coop_transport::live_view::LiveView>>,
    /// Drive stations already running instead of starting them (`--attach`).
    pub attach: Option<attach::Attach>,
    /// Publish every site as ROS 2 topics (`--ros2`).
    pub ros2: Option<Ros2Run>,
    /// Start the stations for a study's trials (`trials = true`): they run the trials a study
    /// runner announces and stay up between them.
    pub trials: bool,
}

/// `session run --ros2`: the domain, and the zenoh router the ROS 2 graph meets at.
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2Run {
    /// The ROS domain.
    pub domain_id: u32,
    /// A router every station connects to as well, where `rmw_zenoh`'s nodes find one
    /// (`rmw_zenohd`: `tcp/localhost:7447`); `None`: the stations' own endpoints only.
    pub router: Option<String>,
}

/// The sites whose presence tokens `z` sees in `session`, kept up to date by zenoh's callback
/// while the returned subscriber lives.
///
/// # Errors
/// Zenoh refuses the liveliness subscriber.
#[allow(clippy::type_complexity)]
pub(crate) fn watch_presence(
    z: &zenoh::Session,
    session: &str,
) -> anyhow::Result<(Arc<Mutex<BTreeSet<String>>>, zenoh::pubsub::Subscriber<()>)> {
    let present: Arc<Mutex<BTreeSet<String>>> = Arc::default();
    let p = present.clone();
    let sub = z
        .liveliness()
        .declare_subscriber(keys::all_presence(session))
        .history(true)
        .callback(move |s| {
            let site = keys::site_of(s.key_expr().as_str()).to_owned();
            let mut set = lock(&p);
            if s.kind() == zenoh::sample::SampleKind::Put {
                set.insert(site);
            } else {
                set.remove(&site);
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("watching presence: {e}"))?;
    Ok((present, sub))
}

/// Locks `m`; a panic in a zenoh callback that held it does not poison the launcher.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// How to run a station: a program and the arguments before its subcommand (`session station run`
/// when the launcher runs its own executable, `station run` for a separate binary).
#[derive(Debug, Clone)]
pub struct StationBin {
    /// The executable.
    pub program: PathBuf,
    /// Arguments before `run`.
    pub prefix: Vec<String>,
}

/// `mono_ns` (this machine's CLOCK_MONOTONIC, near now) on the wall clock: a session file's log
/// times sit next to the recordings'.
pub(crate) fn unix_ns_of(mono_ns: u64) -> u64 {
    let now = coop_rt::timer::monotonic_ns();
    let unix = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    (i128::from(unix) + i128::from(mono_ns) - i128::from(now)).max(0) as u64
}

/// Runs every requested method, one session each (or with `--attach`, the stations' one): the
/// scenario and what the sessions produced.
///
/// # Errors
/// As [`run_method`]; a bad scenario file; arguments that do not fit it.
pub fn run(a: &RunArgs) -> anyhow::Result<(Scenario, SessionRun)> {
    let sc = scenario_file::load(&a.scenario)?;
    check_late(a, &sc)?;
    let mut out = SessionRun::new(&sc, &a.out);
    if let Some(at) = &a.attach {
        let (m, session) = attached_method(a, at)?;
        let o = attach::run_attached(a, at, &sc, m, session)
            .with_context(|| format!("session {session} ({}, attached)", m.as_str()))?;
        out.push(m, o);
        return Ok((sc, out));
    }
    if !a.station_bin.program.exists() {
        bail!(
            "station binary {} not found (build it: cargo build --release -p coop-tools)",
            a.station_bin.program.display()
        );
    }
    let base = a
        .session
        .clone()
        .unwrap_or_else(|| format!("s{}", std::process::id()));
    for &m in &a.methods {
        let session = format!("{base}-{}", m.as_str());
        let o = run_method(a, &sc, m, &session)
            .with_context(|| format!("session {session} ({})", m.as_str()))?;
        out.push(m, o);
    }
    Ok((sc, out))
}

/// `--late`'s sites are the scenario's, each joining within its duration.
fn check_late(a: &RunArgs, sc: &Scenario) -> anyhow::Result<()> {
    for (site, t) in &a.late {
        if !sc.site.iter().any(|s| &s.name == site) {
            bail!(
                "--late {site}={t}: no site {site:?} in scenario {:?}",
                sc.name
            );
        }
        if !(t.is_finite() && *t >= 0.0 && *t < sc.duration_s) {
            bail!(
                "--late {site}={t}: must be from 0 to the scenario's duration ({} s)",
                sc.duration_s
            );
        }
    }
    Ok(())
}

/// With `--attach`: the one method and the session name of the stations' configurations.
///
/// # Errors
/// Not one method; `--late`; no locator; no session name.
fn attached_method<'a>(
    a: &'a RunArgs,
    at: &attach::Attach,
) -> anyhow::Result<(MethodName, &'a str)> {
    if a.methods.len() != 1 {
        bail!("--attach drives the stations' one session: give --method naive or --method paper, the method of their configurations");
    }
    if !a.late.is_empty() {
        bail!("--late: with --attach the stations are started by hand (start one later yourself)");
    }
    if at.connect.is_empty() {
        bail!("--attach: give --connect LOCATOR (a router's, or the stations' own with --peer)");
    }
    let Some(session) = &a.session else {
        bail!("--attach: give --session NAME, the `session` of the stations' configurations");
    };
    Ok((a.methods[0], session))
}
