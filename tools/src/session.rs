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

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use coop_model::body::Vec3;
use coop_model::method::EnergyAccount;
use coop_model::metrics::{self, Metrics};
use coop_model::scenario::{MethodName, Scenario};
use coop_model::sim::{AdoptionEvent, ForceSteps, Mode, ObjectTrace, RunResult, SiteTrace};
use coop_transport::recording::{self, Recording, SampleMsg};
use coop_transport::{keys, network};
use zenoh::Wait;

pub mod attach;

use coop_actors::scenario_file;
use coop_actors::station::config::{StartMode, StationConfig};

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

/// Locks `m`; a panic in a zenoh callback that held it does not poison the launcher.
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

/// One station of a running session.
#[derive(Debug)]
struct Station {
    site: String,
    child: Option<Child>,
    log: PathBuf,
    record: PathBuf,
    config: PathBuf,
}

impl Station {
    fn log_tail(&self) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(8)..].join("\n")
    }
}

impl Station {
    /// Asks the station to stop (SIGTERM: its stop ladder ramps the force to zero, then unlinks).
    fn terminate(&self) {
        if let Some(c) = &self.child {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(c.id() as i32),
                nix::sys::signal::Signal::SIGTERM,
            );
        }
    }

    /// Waits up to `limit` for the station to exit, then SIGKILLs it; its exit status, or `None`
    /// when it had to be killed (or was not running).
    fn reap(&mut self, limit: Duration) -> Option<std::process::ExitStatus> {
        let mut c = self.child.take()?;
        let deadline = Instant::now() + limit;
        while Instant::now() < deadline {
            if let Ok(Some(s)) = c.try_wait() {
                return Some(s);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = c.kill();
        let _ = c.wait();
        None
    }
}

impl Drop for Station {
    fn drop(&mut self) {
        // Whatever happened, no station outlives its session.
        self.terminate();
        self.reap(Duration::from_secs(6));
    }
}

/// The outcome of one method's session.
#[derive(Debug)]
pub struct MethodOutcome {
    /// The simulator's reference run's figures.
    pub reference: Metrics,
    /// The simulator's figures for this method.
    pub simulated: Metrics,
    /// The stations' figures.
    pub real: Metrics,
    /// Per station: its final network counters and loop statistics.
    pub stations: serde_json::Value,
    /// The session's time 0 in the launcher's clock (CLOCK_MONOTONIC ns).
    pub launcher_epoch_ns: u64,
    /// In a world of several objects, each object's figures (empty in a world of one).
    pub objects: Vec<ObjectRow>,
    /// Each station's traffic (payload kbit/s put and got, by kind).
    pub wire: Vec<WireRow>,
}

/// One object's figures in a session: the simulator's and the stations'.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObjectRow {
    /// The object's name.
    pub name: String,
    /// The simulator's run.
    pub simulated: ObjectFigures,
    /// The stations' run.
    pub real: ObjectFigures,
}

/// How one object's copies agreed with each other and with the reference, mm.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObjectFigures {
    /// Largest distance between two sites' copies of it, mm.
    pub div_max_mm: f64,
    /// RMS over the samples of that distance, mm.
    pub div_rms_mm: f64,
    /// That distance at the end, mm.
    pub div_final_mm: f64,
    /// Largest distance of any site's copy from the reference's, mm.
    pub err_ref_max_mm: f64,
}

impl ObjectFigures {
    /// Object `o`'s figures in `run` against `reference`.
    pub fn of(run: &RunResult, reference: &RunResult, o: usize) -> Self {
        let n = run.t.len();
        let div: Vec<f64> = (0..n)
            .map(|k| metrics::object_divergence(run, o, k))
            .collect();
        let rms = (div.iter().map(|d| d * d).sum::<f64>() / n.max(1) as f64).sqrt();
        let err = run
            .sites
            .iter()
            .flat_map(|s| {
                let r = reference.sites[0].object_pos(o);
                s.object_pos(o).iter().zip(r).map(|(a, b)| (a - b).norm())
            })
            .fold(0.0, f64::max);
        Self {
            div_max_mm: div.iter().copied().fold(0.0, f64::max) * 1e3,
            div_rms_mm: rms * 1e3,
            div_final_mm: div.last().copied().unwrap_or(0.0) * 1e3,
            err_ref_max_mm: err * 1e3,
        }
    }
}

/// One station's traffic over its network process's life (payload as put and got, `station
/// status`'s counts): per kind, and in all.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WireRow {
    /// The site.
    pub site: String,
    /// How long its network process ran, s.
    pub duration_s: f64,
    /// Payload put, kbit/s, all kinds.
    pub sent_kbit_s: f64,
    /// Payload received, kbit/s, all kinds.
    pub received_kbit_s: f64,
    /// Per kind (`states`, `tracks`, `clock`, `presence`, `live`): messages put per second,
    /// payload put and received, kbit/s.
    pub kinds: Vec<(String, f64, f64, f64)>,
}

impl WireRow {
    /// From a station's recording: its final counts over its network process's life (the
    /// recording's session message to its status), or `None` if it has not both.
    pub fn of(site: &str, rec: &Recording) -> Option<Self> {
        use coop_rt::shm::control::{CounterKey, WireKind};
        let status = rec.status?;
        let start = rec.session.as_ref()?.t_ns;
        let dt = status.t_ns.saturating_sub(start) as f64 * 1e-9;
        if dt <= 0.0 {
            return None;
        }
        let t = status.traffic;
        let kbit = |b: u64| b as f64 * 8e-3 / dt;
        Some(Self {
            site: site.to_owned(),
            duration_s: dt,
            sent_kbit_s: kbit(t.sent_bytes.iter().sum()),
            received_kbit_s: kbit(t.received_bytes.iter().sum()),
            kinds: WireKind::ALL
                .iter()
                .enumerate()
                .map(|(k, kind)| {
                    (
                        kind.name().to_owned(),
                        t.sent_msgs[k] as f64 / dt,
                        kbit(t.sent_bytes[k]),
                        kbit(t.received_bytes[k]),
                    )
                })
                .collect(),
        })
    }
}

/// Prints each station's traffic (`methods`: the run's JSON `methods`, each with its `wire`).
///
/// # Errors
/// A method's `wire` is not a list of [`WireRow`].
pub fn print_wire(methods: &serde_json::Value) -> anyhow::Result<()> {
    for (m, r) in methods.as_object().into_iter().flatten() {
        let rows: Vec<WireRow> = serde_json::from_value(r["wire"].clone())
            .with_context(|| format!("the {m} run's traffic"))?;
        for w in rows {
            let kinds: Vec<String> = w
                .kinds
                .iter()
                .filter(|k| k.1 > 0.0 || k.3 > 0.0)
                .map(|(kind, msgs, sent, got)| format!("{kind} {msgs:.0} msg/s {sent:.1}/{got:.1}"))
                .collect();
            println!(
                "# wire: {m:<9} {:<6} sent {:.1} kbit/s, received {:.1} kbit/s over {:.1} s ({})",
                w.site,
                w.sent_kbit_s,
                w.received_kbit_s,
                w.duration_s,
                kinds.join("; ")
            );
        }
    }
    Ok(())
}

/// Prints the per-object lines under the table: per method and object, the simulator's figures
/// and the stations' (`methods`: the run's JSON `methods`, each with its `objects`).
///
/// # Errors
/// A method's `objects` is not a list of [`ObjectRow`].
pub fn print_objects(methods: &serde_json::Value) -> anyhow::Result<()> {
    for (m, r) in methods.as_object().into_iter().flatten() {
        let rows: Vec<ObjectRow> = serde_json::from_value(r["objects"].clone())
            .with_context(|| format!("the {m} run's per-object figures"))?;
        for o in rows {
            let f = |x: &ObjectFigures| {
                format!(
                    "div max {:.2} rms {:.2} final {:.2}, err ref max {:.2}",
                    x.div_max_mm, x.div_rms_mm, x.div_final_mm, x.err_ref_max_mm
                )
            };
            println!(
                "# object {:<10} {m}-sim: {} | {m}-real: {} (mm)",
                o.name,
                f(&o.simulated),
                f(&o.real)
            );
        }
    }
    Ok(())
}

/// The station configuration `session run` writes for one site: the defaults, with this session's
/// names, scenario, method, recording (and its time bound when asked) and loopback endpoints,
/// started by the launcher's epoch.
#[allow(clippy::too_many_arguments)]
fn station_config(
    scenario: &Path,
    session: &str,
    site: &str,
    method: MethodName,
    listen: &str,
    connect: &[String],
    record: &Path,
    a: &RunArgs,
    physics_cpu: Option<usize>,
) -> anyhow::Result<String> {
    let defaults = StationConfig::default();
    let emulate = a.emulate;
    let physics = coop_actors::station::config::LoopSpec {
        cpu: physics_cpu,
        ..defaults.physics.clone()
    };
    let c = StationConfig {
        session: session.to_owned(),
        station: Some(site.to_owned()),
        scenario: Some(scenario.to_owned()),
        method: Some(method),
        start: StartMode::Session,
        record: Some(record.to_owned()),
        network: network::NetworkConfig {
            listen: vec![listen.to_owned()],
            connect: connect
                .iter()
                .cloned()
                .chain(a.ros2.as_ref().and_then(|r| r.router.clone()))
                .collect(),
            emulate,
            ..network::NetworkConfig::default()
        },
        record_max_file_s: a.record_max_file_s.unwrap_or(defaults.record_max_file_s),
        physics,
        ros2: match &a.ros2 {
            Some(r) => coop_transport::ros2::Ros2Config {
                publish: true,
                domain_id: r.domain_id,
                ..defaults.ros2.clone()
            },
            None => defaults.ros2.clone(),
        },
        ..defaults
    };
    Ok(format!(
        "# Written by `session run` for site {site}.\n{}",
        c.to_toml()?
    ))
}

fn spawn(bin: &StationBin, st: &Station) -> anyhow::Result<Child> {
    let log =
        std::fs::File::create(&st.log).with_context(|| format!("creating {}", st.log.display()))?;
    Command::new(&bin.program)
        .args(&bin.prefix)
        .args(["run", "--config"])
        .arg(&st.config)
        .arg("--parent")
        .arg(std::process::id().to_string())
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .with_context(|| format!("starting {} for site {}", bin.program.display(), st.site))
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
    let mut sc = sc.clone();
    sc.method = method;
    let dir = a.out.join(method.as_str());
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    // Absolute: the station configs name their recordings, and a relative path in a config is
    // relative to the config's own directory.
    let dir = std::fs::canonicalize(&dir).with_context(|| format!("finding {}", dir.display()))?;
    let sc_path = std::fs::canonicalize(&a.scenario)
        .with_context(|| format!("finding {}", a.scenario.display()))?;
    let n = sc.site.len();
    let ports: Vec<String> = (0..=n)
        .map(|_| network::concrete_listen(&["tcp/127.0.0.1:0".into()]).remove(0))
        .collect();
    // Every station on this one machine: their physics processes (and with them their network
    // processes and supervisors) take the CPUs in turn, rather than all the first one while the
    // last holds only the servos (which preempt them there: a higher priority, and short).
    let cpus = coop_rt::sched::allowed_cpus();
    let mut stations: Vec<Station> = Vec::new();
    for (i, s) in sc.site.iter().enumerate() {
        let physics_cpu = (!cpus.is_empty()).then(|| cpus[i % cpus.len()]);
        let others: Vec<String> = (0..=n)
            .filter(|&j| j != i)
            .map(|j| ports[j].clone())
            .collect();
        let record = dir.join(format!("{}.mcap", s.name));
        let _ = std::fs::remove_file(&record);
        let config = dir.join(format!("{}.toml", s.name));
        std::fs::write(
            &config,
            station_config(
                &sc_path,
                session,
                &s.name,
                method,
                &ports[i],
                &others,
                &record,
                a,
                physics_cpu,
            )?,
        )
        .with_context(|| format!("writing {}", config.display()))?;
        stations.push(Station {
            site: s.name.clone(),
            child: None,
            log: dir.join(format!("{}.log", s.name)),
            record,
            config,
        });
    }
    let late: BTreeMap<&str, f64> = a.late.iter().map(|(s, t)| (s.as_str(), *t)).collect();

    // The launcher is a zenoh peer too: it watches presence and announces the session's time 0.
    let endpoints = network::NetworkConfig {
        listen: vec![ports[n].clone()],
        connect: ports[..n].to_vec(),
        mode: network::Mode::Peer,
        tls: None,
        emulate: false,
        ..network::NetworkConfig::default()
    };
    let z = zenoh::open(network::config(&endpoints).map_err(anyhow::Error::msg)?)
        .wait()
        .map_err(|e| anyhow::anyhow!("opening the launcher's zenoh session: {e}"))?;
    let (present, _presence) = watch_presence(&z, session)?;
    let epoch = network::EpochAnnouncer::declare(&z, session)?;
    let _live = a
        .live
        .as_ref()
        .map(|l| l.follow(&z, session, &sc))
        .transpose()?;

    for st in stations
        .iter_mut()
        .filter(|s| !late.contains_key(s.site.as_str()))
    {
        st.child = Some(spawn(&a.station_bin, st)?);
    }
    let check_alive = |stations: &mut [Station]| -> anyhow::Result<()> {
        for st in stations.iter_mut() {
            if let Some(c) = &mut st.child {
                if let Ok(Some(status)) = c.try_wait() {
                    st.child = None;
                    bail!(
                        "station {} exited early ({status}); its log ({}):\n{}",
                        st.site,
                        st.log.display(),
                        st.log_tail()
                    );
                }
            }
        }
        Ok(())
    };
    let interrupted = || {
        anyhow::anyhow!(
            "interrupted: the stations were stopped (their logs are in {})",
            dir.display()
        )
    };
    let waited = Instant::now();
    loop {
        if a.stop.is_raised() {
            return Err(interrupted());
        }
        check_alive(&mut stations)?;
        let have = lock(&present).clone();
        let missing: Vec<&str> = stations
            .iter()
            .filter(|s| s.child.is_some() && !have.contains(&s.site))
            .map(|s| s.site.as_str())
            .collect();
        if missing.is_empty() {
            break;
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
    // Time 0 a little ahead, so every station has it before it matters.
    let t0 = coop_rt::timer::monotonic_ns() + 300_000_000;
    // Time 0 on the wall clock, for the session file's log times (next to the recordings').
    let t0_unix_ns = unix_ns_of(t0);
    epoch.announce(t0)?;

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
    let bar = (a.progress && std::io::IsTerminal::is_terminal(&std::io::stderr())).then(|| {
        let b = indicatif::ProgressBar::new((sc.duration_s * 10.0) as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template("{msg:>14} [{bar:40}] {pos}/{len} ds")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b.set_message(format!("session {}", method.as_str()));
        b
    });
    if bar.is_none() && a.progress {
        eprintln!(
            "session {session}: {} stations running {} for {} s",
            n,
            method.as_str(),
            sc.duration_s
        );
    }
    let end = t0 + (sc.duration_s * 1e9) as u64 + 200_000_000;
    let mut statuses = serde_json::Map::new();
    loop {
        let now = coop_rt::timer::monotonic_ns();
        let t = now.saturating_sub(t0) as f64 * 1e-9;
        for st in stations.iter_mut().filter(|s| s.child.is_none()) {
            if late.get(st.site.as_str()).is_some_and(|&l| t >= l) && !st.record.exists() {
                st.child = Some(spawn(&a.station_bin, st)?);
            }
        }
        check_alive(&mut stations)?;
        if a.stop.is_raised() {
            if let Some(b) = &bar {
                b.finish_and_clear();
            }
            // Dropping the stations stops each one with its own stop ladder.
            return Err(interrupted());
        }
        if let Some(b) = &bar {
            b.set_position((t * 10.0) as u64);
        }
        if now >= end {
            break;
        }
        // Just before the end: each station's live statistics (loops, network) for the report.
        if now + 300_000_000 >= end && statuses.is_empty() {
            let sites: Vec<String> = sc.site.iter().map(|s| s.name.clone()).collect();
            for st in &stations {
                let at_end = coop_actors::station::status::overruns(session, &st.site).ok();
                if let Ok(mut s) = coop_actors::station::status::read(session, &st.site, &sites) {
                    s.name_objects(&sc);
                    let mut v = s.to_json();
                    // A late joiner's whole run is in the session.
                    let start = overruns_at_start.get(&st.site).copied().unwrap_or([0, 0]);
                    if let Some(e) = at_end {
                        v["overruns_during_session"] = serde_json::json!({
                            "servo": e[0].saturating_sub(start[0]),
                            "physics": e[1].saturating_sub(start[1]),
                        });
                    }
                    statuses.insert(st.site.clone(), v);
                }
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    // Stop: SIGTERM every station at once (each runs its stop ladder), then wait for each.
    for st in &stations {
        st.terminate();
    }
    for st in stations.iter_mut().filter(|s| s.child.is_some()) {
        match st.reap(Duration::from_secs(10)) {
            Some(s) if s.success() => {}
            other => bail!(
                "station {} did not stop cleanly ({other:?}); its log:\n{}",
                st.site,
                st.log_tail()
            ),
        }
    }
    let _ = z.close().wait();

    let recordings: Vec<Recording> = stations
        .iter()
        .map(|s| recording::read(&s.record).with_context(|| format!("station {}", s.site)))
        .collect::<anyhow::Result<_>>()?;
    let sites: Vec<(String, PathBuf)> = stations
        .iter()
        .map(|s| (s.site.clone(), s.record.clone()))
        .collect();
    let mut o = outcome(
        &sc,
        method,
        session,
        t0_unix_ns,
        &dir,
        &sites,
        &recordings,
        &vec![t0; n],
        &statuses,
    )?;
    o.launcher_epoch_ns = t0;
    Ok(o)
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

/// The figures of a session that ran: the stations' recordings (in the scenario's site order,
/// with their paths in `sites`) on the scenario's grid from each one's time 0 (`epochs`, in its
/// own clock), the simulator's runs of the same scenario, the metrics, `metrics.json` and the
/// plots in `dir`, and per station what its recording says (with its live statistics when read).
///
/// # Errors
/// A recording without samples; the plots or `metrics.json` cannot be written.
#[allow(clippy::too_many_arguments)]
fn outcome(
    sc: &Scenario,
    method: MethodName,
    session: &str,
    t0_unix_ns: u64,
    dir: &Path,
    sites: &[(String, PathBuf)],
    recordings: &[Recording],
    epochs: &[u64],
    statuses: &serde_json::Map<String, serde_json::Value>,
) -> anyhow::Result<MethodOutcome> {
    let real_run = run_from_recordings(sc, recordings, epochs)?;
    let reference_run = crate::sim::run_mode(sc, Mode::Reference);
    let sim_run = crate::sim::run_mode(sc, Mode::Distributed(method));
    let reference = metrics::compute(sc, &reference_run, &reference_run);
    let mut simulated = metrics::compute(sc, &sim_run, &reference_run);
    simulated.method = format!("{}-sim", method.as_str());
    let mut real = metrics::compute(sc, &real_run, &reference_run);
    real.method = format!("{}-real", method.as_str());
    for s in &mut real.sites {
        // Not measured on real stations (the servo's adoption step and the energy account live in
        // the simulator only).
        s.max_adoption_force_step_n = f64::NAN;
        s.energy_from_others_j = f64::NAN;
        s.others_work_j = f64::NAN;
    }
    crate::plots::figures(dir, sc, &real_run, &reference_run)?;
    let session_file = dir.join("session.mcap");
    recording::session::write(
        &session_file,
        BTreeMap::from([
            ("session".into(), session.to_owned()),
            ("scenario".into(), sc.name.clone()),
            ("method".into(), method.as_str().to_owned()),
        ]),
        sc,
        &real_run,
        Some(&reference_run),
        recording::session::Source::Stations,
        t0_unix_ns,
    )
    .with_context(|| format!("writing {}", session_file.display()))?;
    std::fs::write(
        dir.join("metrics.json"),
        serde_json::to_string_pretty(&serde_json::json!({ "real": real, "simulated": simulated }))?
            + "\n",
    )?;
    let mut per_station = serde_json::Map::new();
    for (((site, record), rec), &t0) in sites.iter().zip(recordings).zip(epochs) {
        let since = |t_ns: u64| (t_ns as f64 - t0 as f64) * 1e-9;
        per_station.insert(
            site.clone(),
            serde_json::json!({
                "recording": record.display().to_string(),
                "recording_parts": rec.files.len(),
                "final": rec.status,
                "live": statuses.get(site),
                // The session's time 0 in this station's clock.
                "epoch_ns": t0,
                // When its network joined the session (its own presence seen).
                "joined_s": rec.presence.iter().find(|p| &p.site == site && p.present).map(|p| since(p.t_ns)),
                "first_sample_s": rec.samples.first().map(|s| since(s.t_ns)),
                "last_sample_s": rec.samples.last().map(|s| since(s.t_ns)),
                // When its tool first touched the object (its script's first contact).
                "first_contact_s": rec.samples.iter().find(|s| s.touching).map(|s| since(s.t_ns)),
                "final_object_m": rec.samples.last().map(|s| s.pos),
                "first_adoption_jump_m": rec.adoptions.first().map(|a| a.jump_m),
                "truncated": rec.truncated,
                "first_adoption_s": rec.adoptions.first().map(|a| since(a.t_ns)),
                "join_states": rec.status.map(|s| s.join_states),
            }),
        );
    }
    // A world of several: each object's own figures (the table's are the worst object's).
    let objects = if sc.objects.len() > 1 {
        (0..sc.objects.len())
            .map(|o| ObjectRow {
                name: sc.object_name(o).to_owned(),
                simulated: ObjectFigures::of(&sim_run, &reference_run, o),
                real: ObjectFigures::of(&real_run, &reference_run, o),
            })
            .collect()
    } else {
        Vec::new()
    };
    let wire = sites
        .iter()
        .zip(recordings)
        .filter_map(|((site, _), rec)| WireRow::of(site, rec))
        .collect();
    Ok(MethodOutcome {
        reference,
        simulated,
        real,
        stations: serde_json::Value::Object(per_station),
        launcher_epoch_ns: 0,
        objects,
        wire,
    })
}

/// Turns the stations' recordings into the simulator's run layout: every site's trace on the
/// scenario's sample grid from the session's time 0 (each value the newest recorded at or before
/// the grid time), adoptions, and message counts. `epochs` is time 0 per recording, in its
/// station's clock (on one machine, one value; across machines each station's translation).
///
/// # Errors
/// A recording without samples, or not one time 0 per recording.
pub fn run_from_recordings(
    sc: &Scenario,
    recs: &[Recording],
    epochs: &[u64],
) -> anyhow::Result<RunResult> {
    if epochs.len() != recs.len() {
        bail!(
            "{} recordings but {} times 0 (one per recording)",
            recs.len(),
            epochs.len()
        );
    }
    let rate = sc.sample_rate_hz;
    let samples = (sc.duration_s * rate).round() as usize + 1;
    let t: Vec<f64> = (0..samples).map(|k| k as f64 / rate).collect();
    let mut sites = Vec::new();
    let mut adoptions = Vec::new();
    let mut messages = (0u64, 0u64, 0u64);
    for (i, (r, &epoch_ns)) in recs.iter().zip(epochs).enumerate() {
        if r.samples.is_empty() {
            bail!("the recording of site {} has no samples", sc.site[i].name);
        }
        let mut tr = SiteTrace::default();
        if let Some(st) = r.status {
            // What the station put: site reports and tool tracks (`WireKind` order).
            tr.puts = [st.traffic.sent_msgs[0], st.traffic.sent_msgs[1]];
            tr.sent_bytes = st.traffic.sent_bytes[0] + st.traffic.sent_bytes[1];
        }
        let at = |tk: f64| epoch_ns as f64 + tk * 1e9;
        for s in resample(&r.samples, &t, at) {
            tr.obj_pos.push(Vec3::from(s.pos));
            tr.obj_vel.push(Vec3::from(s.vel));
            tr.obj_rot.push(s.rot);
            tr.tool_pos.push(Vec3::from(s.tool_pos));
            tr.f_desired.push(Vec3::from(s.f_desired));
            tr.f_measured.push(Vec3::from(s.f_measured));
            tr.f_on_object.push(Vec3::from(s.f_object));
            tr.touching.push(s.touching);
        }
        // A world of several: every other object (the recording names them in the world's
        // order), and which of them the tool touches.
        if sc.objects.len() > 1 {
            if r.others.len() + 1 != sc.objects.len() {
                bail!(
                    "the recording of site {} has {} objects, scenario {:?} {}",
                    sc.site[i].name,
                    r.others.len() + 1,
                    sc.name,
                    sc.objects.len()
                );
            }
            tr.touched = tr.touching.iter().map(|&t| u16::from(t)).collect();
            for (k, o) in r.others.iter().enumerate() {
                if o.samples.is_empty() {
                    bail!(
                        "the recording of site {} has no samples of object {}",
                        sc.site[i].name,
                        o.name
                    );
                }
                let mut ob = ObjectTrace::default();
                for (j, s) in resample(&o.samples, &t, at).enumerate() {
                    ob.pos.push(Vec3::from(s.pos));
                    ob.vel.push(Vec3::from(s.vel));
                    ob.rot.push(s.rot);
                    if s.touching {
                        tr.touched[j] |= 1 << (k + 1);
                    }
                }
                tr.others.push(ob);
            }
            // Whether the user touches an object: any of them, as the simulator has it.
            for (t, &bits) in tr.touching.iter_mut().zip(&tr.touched) {
                *t = bits != 0;
            }
        }
        sites.push(tr);
        for a in &r.adoptions {
            adoptions.push(AdoptionEvent {
                t_s: (a.t_ns as f64 - epoch_ns as f64) * 1e-9,
                site: i,
                from: a.from,
                jump_m: a.jump_m,
                age_s: a.age_s,
                force_step_n: 0.0,
                energy_j: f64::NAN,
                work_j: f64::NAN,
                clipped_j: f64::NAN,
            });
        }
        if let Some(s) = r.status {
            messages.0 += s.published * (recs.len() as u64).saturating_sub(1);
            messages.1 += s.received;
            messages.2 += s.emulated_lost;
        }
    }
    adoptions.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    Ok(RunResult {
        mode: Mode::Distributed(sc.method),
        t,
        sites,
        adoptions,
        energy: vec![EnergyAccount::default(); recs.len()],
        mech_energy: vec![(0.0, 0.0); recs.len()],
        messages,
        rollback: vec![None; recs.len()],
        force_steps: vec![ForceSteps::default(); recs.len()],
    })
}

/// The sample of `samples` (in time order, not empty) in force at each time of `t` (`at` gives
/// a time of `t` in the recording's clock, ns): the last one at or before it, else the first.
fn resample<'a>(
    samples: &'a [SampleMsg],
    t: &'a [f64],
    at: impl Fn(f64) -> f64 + 'a,
) -> impl Iterator<Item = &'a SampleMsg> + 'a {
    let mut k = 0usize;
    t.iter().map(move |&tk| {
        let at = at(tk);
        while k + 1 < samples.len() && (samples[k + 1].t_ns as f64) <= at {
            k += 1;
        }
        &samples[k]
    })
}

/// Runs every requested method: the scenario, the table's rows (reference, then per method the
/// simulator's and the stations' figures), and everything as JSON.
///
/// # Errors
/// As [`run_method`]; a bad scenario file.
pub fn run(a: &RunArgs) -> anyhow::Result<(Scenario, Vec<Metrics>, serde_json::Value)> {
    let sc = scenario_file::load(&a.scenario)?;
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
    if let Some(at) = &a.attach {
        if a.methods.len() != 1 {
            bail!("--attach drives the stations' one session: give --method naive or --method paper, the method of their configurations");
        }
        if !a.late.is_empty() {
            bail!(
                "--late: with --attach the stations are started by hand (start one later yourself)"
            );
        }
        if at.connect.is_empty() {
            bail!(
                "--attach: give --connect LOCATOR (a router's, or the stations' own with --peer)"
            );
        }
        let Some(session) = &a.session else {
            bail!("--attach: give --session NAME, the `session` of the stations' configurations");
        };
        let m = a.methods[0];
        let o = attach::run_attached(a, at, &sc, m, session)
            .with_context(|| format!("session {session} ({}, attached)", m.as_str()))?;
        let rows = vec![o.reference.clone(), o.simulated.clone(), o.real.clone()];
        let v = serde_json::json!({
            "scenario": sc.name,
            "out": a.out.display().to_string(),
            "reference": o.reference,
            "methods": { m.as_str(): {
                "simulated": o.simulated, "real": o.real, "stations": o.stations,
                "launcher_epoch_ns": o.launcher_epoch_ns, "objects": o.objects, "wire": o.wire,
            } },
        });
        return Ok((sc, rows, v));
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
    let mut rows = Vec::new();
    let mut json = serde_json::Map::new();
    for &m in &a.methods {
        let session = format!("{base}-{}", m.as_str());
        let o = run_method(a, &sc, m, &session)
            .with_context(|| format!("session {session} ({})", m.as_str()))?;
        if rows.is_empty() {
            rows.push(o.reference.clone());
        }
        rows.push(o.simulated.clone());
        rows.push(o.real.clone());
        json.insert(
            m.as_str().to_owned(),
            serde_json::json!({
                "simulated": o.simulated, "real": o.real, "stations": o.stations,
                "launcher_epoch_ns": o.launcher_epoch_ns, "objects": o.objects, "wire": o.wire,
            }),
        );
    }
    let v = serde_json::json!({
        "scenario": sc.name,
        "out": a.out.display().to_string(),
        "reference": rows.first(),
        "methods": json,
    });
    Ok((sc, rows, v))
}
