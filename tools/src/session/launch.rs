//! One method's session of stations this launcher starts on this machine: configure and start
//! them, wait for every one's presence, announce time 0, start the late ones at their time, read
//! each one's live status just before the end, stop them, and measure their recordings.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use coop_model::scenario::{MethodName, Scenario};
use coop_transport::network;
use coop_transport::recording::{self, Recording};
use zenoh::Wait;

use super::outcome::{outcome, LiveStatus, MethodOutcome, Recorded, SessionOverruns};
use super::stations::{self, Station};
use super::{lock, unix_ns_of, watch_presence, RunArgs};

/// What a launcher holds while a method's session runs (started here or attached): who is present,
/// the epoch it answers and announces, and the live view it feeds.
// NB: fields drop in declaration order: the live view first, the presence subscriber last.
pub(super) struct Held {
    _live: Option<coop_transport::live_view::Following>,
    /// Time 0's queryable, answered from here on (the stations measure their offset to it).
    pub epoch: network::EpochAnnouncer,
    _presence: zenoh::pubsub::Subscriber<()>,
    /// The sites whose presence is seen.
    pub present: Arc<Mutex<std::collections::BTreeSet<String>>>,
}

impl Held {
    /// Declares them on the launcher's zenoh session `z`.
    ///
    /// # Errors
    /// A declaration zenoh refuses; the live view cannot follow the session.
    pub(super) fn declare(
        a: &RunArgs,
        z: &zenoh::Session,
        session: &str,
        sc: &Scenario,
    ) -> anyhow::Result<Self> {
        let (present, _presence) = watch_presence(z, session)?;
        let epoch = network::EpochAnnouncer::declare(z, session)?;
        let _live = a
            .live
            .as_ref()
            .map(|l| l.follow(z, session, sc))
            .transpose()?;
        Ok(Self {
            present,
            epoch,
            _presence,
            _live,
        })
    }
}

/// The scenario under `method`, and the directory its run writes to (made).
///
/// # Errors
/// The directory cannot be made.
pub(super) fn method_run(
    a: &RunArgs,
    sc: &Scenario,
    method: MethodName,
) -> anyhow::Result<(Scenario, std::path::PathBuf)> {
    let mut sc = sc.clone();
    sc.method = method;
    let dir = a.out.join(method.as_str());
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok((sc, dir))
}

/// Runs one session of `method` and gathers its figures.
///
/// # Errors
/// A station that does not start, is not present in time, or fails; recordings that cannot be read.
pub fn run_method(
    a: &RunArgs,
    sc: &Scenario,
    method: MethodName,
    session: &str,
) -> anyhow::Result<MethodOutcome> {
    let (sc, dir) = method_run(a, sc, method)?;
    // Absolute: the station configs name their recordings, and a relative path in a config is
    // relative to the config's own directory.
    let dir = std::fs::canonicalize(&dir).with_context(|| format!("finding {}", dir.display()))?;
    let n = sc.site.len();
    let ports = stations::loopback_ports(n);
    let mut stations = stations::prepare(a, &sc, session, &dir, &ports)?;
    let late: BTreeMap<&str, f64> = a.late.iter().map(|(s, t)| (s.as_str(), *t)).collect();

    // The launcher is a zenoh peer too: it watches presence and announces the session's time 0.
    let z = stations::launcher_session(&ports)?;
    let held = Held::declare(a, &z, session, &sc)?;

    for st in stations
        .iter_mut()
        .filter(|s| !late.contains_key(s.site.as_str()))
    {
        st.spawn(&a.station_bin)?;
    }
    wait_present(a, &mut stations, &held.present, &dir)?;
    // Time 0 a little ahead, so every station has it before it matters.
    let t0 = coop_rt::timer::monotonic_ns() + 300_000_000;
    // Time 0 on the wall clock, for the session file's log times (next to the recordings').
    let t0_unix_ns = unix_ns_of(t0);
    held.epoch.announce(t0)?;
    let live = run_until_end(a, &sc, session, &mut stations, &late, t0, &dir)?;
    stations::stop_all(&mut stations)?;
    let _ = z.close().wait();

    let recordings: Vec<Recording> = stations
        .iter()
        .map(|s| recording::read(&s.record).with_context(|| format!("station {}", s.site)))
        .collect::<anyhow::Result<_>>()?;
    let sites: Vec<(String, PathBuf)> = stations
        .iter()
        .map(|s| (s.site.clone(), s.record.clone()))
        .collect();
    let recorded = Recorded {
        sites: &sites,
        recordings: &recordings,
        epochs: &vec![t0; n],
    };
    let mut o = outcome(&sc, session, t0_unix_ns, &dir, &recorded, live)?;
    o.launcher_epoch_ns = t0;
    Ok(o)
}

/// The error of a session stopped by SIGINT/SIGTERM (dropping the stations stops each one with
/// its own stop ladder).
fn interrupted(dir: &Path) -> anyhow::Error {
    anyhow::anyhow!(
        "interrupted: the stations were stopped (their logs are in {})",
        dir.display()
    )
}

/// Waits until every started station's presence is seen (`present`), within the start timeout.
///
/// # Errors
/// Interrupted; a station exited; a station not present in time (named).
pub(super) fn wait_present(
    a: &RunArgs,
    stations: &mut [Station],
    present: &Arc<Mutex<std::collections::BTreeSet<String>>>,
    dir: &Path,
) -> anyhow::Result<()> {
    let waited = Instant::now();
    loop {
        if a.stop.is_raised() {
            return Err(interrupted(dir));
        }
        stations::check_alive(stations)?;
        let have = lock(present).clone();
        let missing: Vec<&str> = stations
            .iter()
            .filter(|s| s.child.is_some() && !have.contains(&s.site))
            .map(|s| s.site.as_str())
            .collect();
        if missing.is_empty() {
            return Ok(());
        }
        if waited.elapsed() > a.start_timeout {
            bail!(
                "stations not present after {:?}: {} (logs in {})",
                a.start_timeout,
                missing.join(", "),
                dir.display()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Runs the session from time 0 `t0` to its end: starts the late stations at their time, shows
/// progress, and just before the end reads each station's live status (by site).
///
/// # Errors
/// Interrupted; a station that cannot start or exited.
fn run_until_end(
    a: &RunArgs,
    sc: &Scenario,
    session: &str,
    stations: &mut [Station],
    late: &BTreeMap<&str, f64>,
    t0: u64,
    dir: &Path,
) -> anyhow::Result<BTreeMap<String, LiveStatus>> {
    // Overruns from here on are the session's (startup, with every station's processes and zenoh
    // coming up on two cores, is reported apart).
    let overruns_at_start: BTreeMap<String, [u64; 2]> = stations
        .iter()
        .filter_map(|s| {
            Some((
                s.site.clone(),
                coop_actors::station::status::overruns(session, &s.site).ok()?,
            ))
        })
        .collect();
    let bar = progress(a, sc, session, stations.len());
    let end = t0 + (sc.duration_s * 1e9) as u64 + 200_000_000;
    let mut live = BTreeMap::new();
    loop {
        let now = coop_rt::timer::monotonic_ns();
        let t = now.saturating_sub(t0) as f64 * 1e-9;
        for st in stations.iter_mut().filter(|s| s.child.is_none()) {
            if late.get(st.site.as_str()).is_some_and(|&l| t >= l) && !st.record.exists() {
                st.spawn(&a.station_bin)?;
            }
        }
        stations::check_alive(stations)?;
        if a.stop.is_raised() {
            if let Some(b) = &bar {
                b.finish_and_clear();
            }
            return Err(interrupted(dir));
        }
        if let Some(b) = &bar {
            b.set_position((t * 10.0) as u64);
        }
        if now >= end {
            break;
        }
        // Just before the end: each station's live statistics (loops, network) for the report.
        if now + 300_000_000 >= end && live.is_empty() {
            live = live_statuses(sc, session, stations, &overruns_at_start);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    Ok(live)
}

/// A progress bar on a terminal, else (when progress is asked) one line saying what runs.
fn progress(
    a: &RunArgs,
    sc: &Scenario,
    session: &str,
    stations: usize,
) -> Option<indicatif::ProgressBar> {
    let bar = (a.progress && std::io::IsTerminal::is_terminal(&std::io::stderr())).then(|| {
        let b = indicatif::ProgressBar::new((sc.duration_s * 10.0) as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template("{msg:>14} [{bar:40}] {pos}/{len} ds")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b.set_message(format!("session {}", sc.method.as_str()));
        b
    });
    if bar.is_none() && a.progress {
        eprintln!(
            "session {session}: {} stations running {} for {} s",
            stations,
            sc.method.as_str(),
            sc.duration_s
        );
    }
    bar
}

/// Each station's status as it reads now, with its overruns since `at_start` (a station missing
/// there, a late joiner, has its whole run in the session). A station whose status cannot be
/// read is left out.
fn live_statuses(
    sc: &Scenario,
    session: &str,
    stations: &[Station],
    at_start: &BTreeMap<String, [u64; 2]>,
) -> BTreeMap<String, LiveStatus> {
    let sites: Vec<String> = sc.site.iter().map(|s| s.name.clone()).collect();
    let mut out = BTreeMap::new();
    for st in stations {
        let at_end = coop_actors::station::status::overruns(session, &st.site).ok();
        if let Ok(mut status) = coop_actors::station::status::read(session, &st.site, &sites) {
            status.name_objects(sc);
            let start = at_start.get(&st.site).copied().unwrap_or([0, 0]);
            let ticks = sc
                .site
                .iter()
                .find(|s| s.name == st.site)
                .map_or(0, |s| (sc.duration_s * s.physics_rate_hz).round() as u64);
            let overruns_during_session = at_end.map(|e| {
                SessionOverruns::new(
                    e[0].saturating_sub(start[0]),
                    e[1].saturating_sub(start[1]),
                    ticks,
                )
            });
            out.insert(
                st.site.clone(),
                LiveStatus {
                    status,
                    overruns_during_session,
                },
            );
        }
    }
    out
}
