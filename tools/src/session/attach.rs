//! `session run --attach`: drive stations this launcher did not start (on other machines, started
//! by hand with `start = "session"`), found through a router or at given locators.
//!
//! The launcher opens its own zenoh session (a client of the routers, or a peer of the stations,
//! with the launcher's certificate from `session certs` for mutual TLS), answers its clock on
//! `clock/launcher` (only the launcher's certificate may, under the generated access control),
//! waits for every site's presence token (naming who is missing after the timeout), and announces
//! time 0 in its own clock, [`LEAD`] ahead. Each station samples the launcher's clock as it
//! samples its peers' and translates time 0 into its own clock with that offset before it takes
//! it, so the scripts start together whatever the machines' clocks say. A station stops by itself
//! once the scenario is over; the launcher then reads the recordings and prints the same table as
//! a session it started.
//!
//! The recordings are read from paths (`--recording SITE=PATH`, or `--recordings DIR` for
//! `DIR/<site>.mcap`: a directory the stations write to and this machine sees, or where they were
//! copied), not sent over zenoh: a recording is a set of finished MCAP parts of some MB that its
//! station writes as it goes and completes at its stop ladder; moving it over zenoh would be a
//! transfer protocol of its own (chunks, retries, completion, more keys in the access control)
//! whose failure loses the run, while a path is the file the station wrote, read by the same
//! reader as on one machine, and still there to read again if anything fails. The launcher waits,
//! bounded, for each recording to hold its final counters (what a station writes last).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::bail;
use coop_model::scenario::{MethodName, Scenario};
use coop_transport::network;
use coop_transport::recording::{self, Recording};
use zenoh::Wait;

use super::{lock, MethodOutcome, RunArgs};

/// How far ahead of its announcement time 0 is: each station needs the announcement and its
/// offset to the launcher's clock before it (they sample the launcher's clock from their start,
/// three exchanges back to back give it), across a router and machines of their own.
pub const LEAD: Duration = Duration::from_secs(1);

/// How long after the scenario's end the stations get to stop and finish their recordings (each
/// stops by itself 2 s after the end, then runs its stop ladder).
pub const COLLECT_TIMEOUT: Duration = Duration::from_secs(20);

/// Where the stations are and how to reach them.
#[derive(Debug, Clone)]
pub struct Attach {
    /// Zenoh locators: the routers' (client mode) or the stations' (peer mode).
    pub connect: Vec<String>,
    /// Client of routers (default) or peer of the stations.
    pub mode: network::Mode,
    /// The launcher's TLS files (its certificate `launcher.pem`/`.key` from `session certs`).
    pub tls: Option<network::Tls>,
    /// Per site: its recording's first part, as this machine sees it.
    pub recordings: BTreeMap<String, PathBuf>,
}

impl Attach {
    /// The TLS files `session certs` wrote to `dir` for the launcher: `ca.pem`, `launcher.pem`,
    /// `launcher.key`, mutual.
    pub fn tls_from_certs(dir: &Path) -> network::Tls {
        network::Tls {
            root_ca_certificate: Some(dir.join("ca.pem")),
            connect_certificate: Some(dir.join(format!("{}.pem", coop_transport::acl::LAUNCHER))),
            connect_private_key: Some(dir.join(format!("{}.key", coop_transport::acl::LAUNCHER))),
            enable_mtls: true,
            ..network::Tls::default()
        }
    }

    /// Each site's recording: the ones named, the others `dir/<site>.mcap`.
    ///
    /// # Errors
    /// A site named that is not the scenario's; a site with no recording named and no `dir`.
    pub fn recordings_for(
        sc: &Scenario,
        named: &[(String, PathBuf)],
        dir: Option<&Path>,
    ) -> anyhow::Result<BTreeMap<String, PathBuf>> {
        let mut out = BTreeMap::new();
        for (site, path) in named {
            if !sc.site.iter().any(|s| &s.name == site) {
                bail!(
                    "--recording {site}={}: no site {site:?} in scenario {:?}",
                    path.display(),
                    sc.name
                );
            }
            out.insert(site.clone(), path.clone());
        }
        for s in &sc.site {
            if out.contains_key(&s.name) {
                continue;
            }
            let Some(d) = dir else {
                bail!(
                    "--attach: where is site {}'s recording? Give --recording {}=PATH (its station's `record`, as this machine sees it) or --recordings DIR (DIR/{}.mcap)",
                    s.name,
                    s.name,
                    s.name
                );
            };
            out.insert(s.name.clone(), d.join(format!("{}.mcap", s.name)));
        }
        Ok(out)
    }

    /// The launcher's zenoh session, reaching the stations as configured.
    ///
    /// # Errors
    /// A TLS file that is not there; zenoh refuses the configuration or cannot open.
    fn open(&self) -> anyhow::Result<zenoh::Session> {
        let endpoints = network::NetworkConfig {
            listen: vec![],
            connect: self.connect.clone(),
            mode: self.mode,
            tls: self.tls.clone(),
            emulate: false,
            ..network::NetworkConfig::default()
        };
        if let Some(t) = &self.tls {
            for (field, path) in t.files() {
                if let Some(p) = path {
                    if !p.is_file() {
                        bail!(
                            "--certs: the launcher's TLS {field} {} is not a readable file (make it with `session certs`)",
                            p.display()
                        );
                    }
                }
            }
        }
        let z = zenoh::open(network::config(&endpoints).map_err(anyhow::Error::msg)?)
            .wait()
            .map_err(
                |e| match network::explain_open(e, &endpoints, self.side()) {
                    network::NetworkError::Link(l) => anyhow::anyhow!("{l}"),
                    e => anyhow::anyhow!(
                        "opening the launcher's zenoh session ({} to {}): {e}",
                        self.mode,
                        self.connect.join(", ")
                    ),
                },
            )?;
        Ok(z)
    }

    /// How the launcher's link failures are worded: its `--certs`, towards routers (client) or
    /// stations (peer).
    fn side(&self) -> network::link::Side {
        network::link::Side {
            me: "launcher",
            far: match self.mode {
                network::Mode::Client => network::link::Far::Router,
                network::Mode::Peer => network::link::Far::Station,
            },
            files: network::link::Files::CertsDir,
        }
    }

    /// Why the links to `connect` fail, if they do (a peer's links do not stop its session from
    /// opening: the stations' presence just never comes).
    fn link_failures(&self) -> Option<network::link::LinkFailures> {
        let found = network::probe::diagnose(&self.connect, self.tls.as_ref(), self.side());
        (!found.is_empty()).then_some(network::link::LinkFailures(found))
    }
}

/// Runs one session of stations already running (their configuration names `method` and
/// `session`), and gathers its figures.
///
/// # Errors
/// The launcher's zenoh session cannot open; a site not present within the start timeout (named);
/// a recording not finished in time, or of another session, site or method.
pub fn run_attached(
    a: &RunArgs,
    at: &Attach,
    sc: &Scenario,
    method: MethodName,
    session: &str,
) -> anyhow::Result<MethodOutcome> {
    let (sc, dir) = super::launch::method_run(a, sc, method)?;
    let z = at.open()?;
    // From here on the launcher answers its clock: the stations measure their offset to it while
    // the others come.
    let held = super::launch::Held::declare(a, &z, session, &sc)?;
    if a.progress {
        eprintln!(
            "session {session}: waiting for {} ({} {})",
            sc.site
                .iter()
                .map(|s| s.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            at.mode,
            at.connect.join(", ")
        );
    }
    wait_present(a, at, &sc, session, &held.present)?;
    check_stations(&z, &sc, session)?;
    let t0 = coop_rt::timer::monotonic_ns() + LEAD.as_nanos() as u64;
    held.epoch.announce(t0)?;
    if a.progress {
        eprintln!(
            "session {session}: every site present; time 0 announced ({} s ahead, in the launcher's clock); running {} for {} s",
            LEAD.as_secs_f64(),
            method.as_str(),
            sc.duration_s
        );
    }
    // At the end, before they stop, the stations' figures (their control blocks are on their
    // own machines): asked through zenoh.
    let finish = t0 + (sc.duration_s * 1e9) as u64;
    wait_until(finish, a)?;
    let figures = coop_transport::network::figures::ask(&z, session, Duration::from_secs(1));
    // The stations stop by themselves after the end; wait for that, then for their recordings.
    wait_until(
        finish + coop_actors::station::run::SESSION_END_GRACE.as_nanos() as u64,
        a,
    )?;
    let recordings = collect(&sc, at, session, method, &a.stop)?;
    let _ = z.close().wait();
    let sites: Vec<(String, PathBuf)> = sc
        .site
        .iter()
        .map(|s| (s.name.clone(), at.recordings[&s.name].clone()))
        .collect();
    // Each recording on its own station's time 0 (its translation of the launcher's).
    let epochs: Vec<u64> = recordings
        .iter()
        .map(|r| r.session.as_ref().map_or(0, |s| s.epoch_ns))
        .collect();
    let recorded = super::outcome::Recorded {
        sites: &sites,
        recordings: &recordings,
        epochs: &epochs,
    };
    // Their statuses are on their own machines: their figures came through zenoh.
    let live = BTreeMap::new();
    let mut o =
        super::outcome::outcome(&sc, session, super::unix_ns_of(t0), &dir, &recorded, live)?;
    o.launcher_epoch_ns = t0;
    for s in &sc.site {
        if let (Some(st), Some(f)) = (o.stations.get_mut(&s.name), figures.get(&s.name)) {
            let ticks = (sc.duration_s * s.physics_rate_hz).round() as u64;
            st.figures = Some(super::outcome::StationRow::of_figures(f, ticks));
        }
    }
    Ok(o)
}

/// Waits until `t_ns` (this machine's monotonic clock).
///
/// # Errors
/// Interrupted first (the stations stop by themselves at the scenario's end).
fn wait_until(t_ns: u64, a: &RunArgs) -> anyhow::Result<()> {
    while coop_rt::timer::monotonic_ns() < t_ns {
        if a.stop.is_raised() {
            bail!("interrupted: the stations stop by themselves at the scenario's end");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

/// How long the launcher asks the present stations what they run before it gives up on one.
const ASK_RUNS: Duration = Duration::from_secs(3);

/// Before time 0: every station runs the launcher's scenario (by its fingerprint) and method, and
/// one that does not emulate the scenario's network is said (its delays are the real network's,
/// not the scenario's the simulator rows assume). Nothing is announced if one refuses.
///
/// # Errors
/// A station that does not say what it runs within [`ASK_RUNS`], or runs another scenario or
/// method (named, with both values).
fn check_stations(z: &zenoh::Session, sc: &Scenario, session: &str) -> anyhow::Result<()> {
    let want = coop_transport::network::figures::scenario_hash(sc);
    let deadline = std::time::Instant::now() + ASK_RUNS;
    let mut figures = BTreeMap::new();
    while figures.len() < sc.site.len() && std::time::Instant::now() < deadline {
        figures.extend(coop_transport::network::figures::ask(
            z,
            session,
            Duration::from_millis(500),
        ));
    }
    for s in &sc.site {
        let Some(f) = figures.get(&s.name) else {
            bail!(
                "station {} is present but did not say what it runs within {} s (a station of an older version?); nothing was started",
                s.name,
                ASK_RUNS.as_secs()
            );
        };
        let r = &f.runs;
        if r.method != sc.method.as_str() {
            bail!(
                "station {} runs method {}, the launcher was given {}: start the stations with --method {} (or their config's method), or give the launcher --method {}; nothing was started",
                s.name,
                r.method,
                sc.method.as_str(),
                sc.method.as_str(),
                r.method
            );
        }
        if r.scenario_hash != want {
            bail!(
                "station {} runs another scenario ({:?}, fingerprint {:016x}) than the launcher's ({:?}, {:016x}): give both the same scenario file; nothing was started",
                s.name,
                r.scenario,
                r.scenario_hash,
                sc.name,
                want
            );
        }
        let delayed =
            sc.network.delay_max_ms > 0.0 || sc.network.jitter_ms > 0.0 || sc.network.loss > 0.0;
        if !r.emulated && delayed {
            eprintln!(
                "warning: station {} does not emulate the scenario's network (network.emulate = false): its delays are the real network's, while the simulator rows assume the scenario's ({}-{} ms, jitter {} ms, loss {}); compare the -real rows with the -sim rows with that in mind",
                s.name,
                sc.network.delay_min_ms,
                sc.network.delay_max_ms,
                sc.network.jitter_ms,
                sc.network.loss
            );
        }
    }
    Ok(())
}

/// Waits until every site's presence is seen (`present`), within the start timeout.
///
/// # Errors
/// Interrupted; a site not present in time (named, with those that are).
fn wait_present(
    a: &RunArgs,
    at: &Attach,
    sc: &Scenario,
    session: &str,
    present: &Arc<Mutex<BTreeSet<String>>>,
) -> anyhow::Result<()> {
    let waited = Instant::now();
    loop {
        if a.stop.is_raised() {
            bail!("interrupted before the session started (the stations were not told anything)");
        }
        let have = lock(present).clone();
        let missing: Vec<&str> = sc
            .site
            .iter()
            .map(|s| s.name.as_str())
            .filter(|s| !have.contains(*s))
            .collect();
        if missing.is_empty() {
            return Ok(());
        }
        if waited.elapsed() > a.start_timeout {
            if let Some(links) = at.link_failures() {
                bail!(
                    "stations not present after {:?}: {}, and the launcher's links fail: {links}",
                    a.start_timeout,
                    missing.join(", ")
                );
            }
            bail!(
                "stations not present after {:?}: {} (none of their presence tokens reached the launcher through {}; present: {}). Are they running with session = {session:?}, and reaching the same routers?",
                a.start_timeout,
                missing.join(", "),
                at.connect.join(", "),
                if have.is_empty() { "none".to_owned() } else { have.into_iter().collect::<Vec<_>>().join(", ") }
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits (up to [`COLLECT_TIMEOUT`]) for every site's recording to be finished, and checks it is
/// this session's, that site's and this method's.
fn collect(
    sc: &Scenario,
    at: &Attach,
    session: &str,
    method: MethodName,
    stop: &crate::cli::StopFlag,
) -> anyhow::Result<Vec<Recording>> {
    let deadline = Instant::now() + COLLECT_TIMEOUT;
    let mut out = Vec::new();
    for s in &sc.site {
        let path = &at.recordings[&s.name];
        let rec = loop {
            let last = recording::read(path);
            match last {
                Ok(r) if r.status.is_some() => break r,
                _ if Instant::now() > deadline || stop.is_raised() => {
                    let why = match last {
                        Ok(_) => {
                            "it has no final counters yet (its station has not stopped)".to_owned()
                        }
                        Err(e) => e.to_string(),
                    };
                    bail!(
                        "site {}'s recording {} is not finished {:?} after the scenario's end: {why} (is it the station's `record`, on a directory this machine sees?)",
                        s.name,
                        path.display(),
                        COLLECT_TIMEOUT
                    );
                }
                _ => std::thread::sleep(Duration::from_millis(200)),
            }
        };
        let Some(m) = &rec.session else {
            bail!(
                "site {}'s recording {} has no session start: its station never took the session's time 0 (its log says why)",
                s.name,
                path.display()
            );
        };
        if m.session != session || m.site != s.name || m.method != method.as_str() {
            bail!(
                "{} is not site {}'s recording of session {session} ({}): it is site {}'s of session {} ({})",
                path.display(),
                s.name,
                method.as_str(),
                m.site,
                m.session,
                m.method
            );
        }
        out.push(rec);
    }
    Ok(out)
}
