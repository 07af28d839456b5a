//! The stations a launcher starts on this machine: their configurations, their processes, and the
//! stop that leaves none of them behind.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use coop_actors::station::config::{StartMode, StationConfig};
use coop_model::scenario::{MethodName, Scenario};
use coop_transport::network;

use super::{RunArgs, StationBin};

/// One station of a running session.
#[derive(Debug)]
pub(crate) struct Station {
    pub site: String,
    pub child: Option<Child>,
    pub log: PathBuf,
    pub record: PathBuf,
    config: PathBuf,
}

/// `station run --config <config>` as a launcher starts it: its output to `log`, dying with the
/// launcher (`--parent`).
///
/// # Errors
/// The log's handle cannot be duplicated.
pub fn station_run(
    bin: &StationBin,
    config: &std::path::Path,
    log: std::fs::File,
) -> std::io::Result<Command> {
    let mut c = Command::new(&bin.program);
    c.args(&bin.prefix)
        .args(["run", "--config"])
        .arg(config)
        .arg("--parent")
        .arg(std::process::id().to_string())
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log);
    Ok(c)
}

impl Station {
    /// The last lines of its log, for an error that names it.
    pub fn log_tail(&self) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(8)..].join("\n")
    }

    /// Starts its `station run` (its output to its log; it dies with the launcher).
    pub fn spawn(&mut self, bin: &StationBin) -> anyhow::Result<()> {
        let log = std::fs::File::create(&self.log)
            .with_context(|| format!("creating {}", self.log.display()))?;
        let child = station_run(bin, &self.config, log)?
            .spawn()
            .with_context(|| {
                format!("starting {} for site {}", bin.program.display(), self.site)
            })?;
        self.child = Some(child);
        Ok(())
    }

    /// Asks the station to stop (SIGTERM: its stop ladder ramps the force to zero, then unlinks).
    pub fn terminate(&self) {
        if let Some(c) = &self.child {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(c.id() as i32),
                nix::sys::signal::Signal::SIGTERM,
            );
        }
    }

    /// Waits up to `limit` for the station to exit, then SIGKILLs it; its exit status, or `None`
    /// when it had to be killed (or was not running).
    pub fn reap(&mut self, limit: Duration) -> Option<std::process::ExitStatus> {
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

/// Where the stations of one session listen: one loopback port per site, then the launcher's,
/// all different (each is free when picked, and none is bound until its station starts).
pub(crate) fn loopback_ports(sites: usize) -> Vec<String> {
    let mut ports: Vec<String> = Vec::with_capacity(sites + 1);
    while ports.len() <= sites {
        let port = network::concrete_listen(&["tcp/127.0.0.1:0".into()]).remove(0);
        if !ports.contains(&port) {
            ports.push(port);
        }
    }
    ports
}

/// Writes every site's station configuration into `dir` (absolute) and returns its stations, none
/// started yet. Site `i` listens on `ports[i]` and connects to every other port (the launcher's
/// last).
pub(crate) fn prepare(
    a: &RunArgs,
    sc: &Scenario,
    session: &str,
    dir: &Path,
    ports: &[String],
) -> anyhow::Result<Vec<Station>> {
    let sc_path = std::fs::canonicalize(&a.scenario)
        .with_context(|| format!("finding {}", a.scenario.display()))?;
    // Every station on this one machine: their physics processes (and with them their network
    // processes and supervisors) take the CPUs in turn, rather than all the first one while the
    // last holds only the servos (which preempt them there: a higher priority, and short).
    let cpus = coop_rt::sched::allowed_cpus();
    let mut stations = Vec::new();
    for (i, s) in sc.site.iter().enumerate() {
        let others: Vec<String> = (0..ports.len())
            .filter(|&j| j != i)
            .map(|j| ports[j].clone())
            .collect();
        let record = dir.join(format!("{}.mcap", s.name));
        let _ = std::fs::remove_file(&record);
        let config = dir.join(format!("{}.toml", s.name));
        let site = SiteConfig {
            scenario: &sc_path,
            session,
            site: &s.name,
            method: sc.method,
            listen: &ports[i],
            connect: &others,
            record: &record,
            physics_cpu: (!cpus.is_empty()).then(|| cpus[i % cpus.len()]),
        };
        std::fs::write(&config, site.to_toml(a)?)
            .with_context(|| format!("writing {}", config.display()))?;
        stations.push(Station {
            site: s.name.clone(),
            child: None,
            log: dir.join(format!("{}.log", s.name)),
            record,
            config,
        });
    }
    Ok(stations)
}

/// What differs between the stations of one session.
struct SiteConfig<'a> {
    scenario: &'a Path,
    session: &'a str,
    site: &'a str,
    method: MethodName,
    listen: &'a str,
    connect: &'a [String],
    record: &'a Path,
    physics_cpu: Option<usize>,
}

impl SiteConfig<'_> {
    /// The station configuration `session run` writes for one site: the defaults, with this
    /// session's names, scenario, method, recording (and its time bound when asked) and loopback
    /// endpoints, started by the launcher's epoch.
    fn to_toml(&self, a: &RunArgs) -> anyhow::Result<String> {
        let defaults = StationConfig::default();
        let physics = coop_actors::station::config::LoopSpec {
            cpu: self.physics_cpu,
            ..defaults.physics.clone()
        };
        let c = StationConfig {
            session: self.session.to_owned(),
            station: Some(self.site.to_owned()),
            scenario: Some(self.scenario.to_owned()),
            method: Some(self.method),
            start: StartMode::Session,
            trials: a.trials,
            record: Some(self.record.to_owned()),
            network: network::NetworkConfig {
                listen: vec![self.listen.to_owned()],
                connect: self
                    .connect
                    .iter()
                    .cloned()
                    .chain(a.ros2.as_ref().and_then(|r| r.router.clone()))
                    .collect(),
                emulate: a.emulate,
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
            "# Written by `session run` for site {}.\n{}",
            self.site,
            c.to_toml()?
        ))
    }
}

/// The launcher's zenoh session among the stations on loopback `ports` (one per site, then the
/// launcher's own, as [`loopback_ports`] gives them): a peer too, which watches presence and
/// announces time 0.
///
/// # Errors
/// The session does not open.
pub(crate) fn launcher_session(ports: &[String]) -> anyhow::Result<zenoh::Session> {
    let n = ports.len() - 1;
    let endpoints = network::NetworkConfig {
        listen: vec![ports[n].clone()],
        connect: ports[..n].to_vec(),
        mode: network::Mode::Peer,
        tls: None,
        emulate: false,
        ..network::NetworkConfig::default()
    };
    zenoh::Wait::wait(zenoh::open(
        network::config(&endpoints).map_err(anyhow::Error::msg)?,
    ))
    .map_err(|e| anyhow::anyhow!("opening the launcher's zenoh session: {e}"))
}

/// Fails, naming the station and showing its log, if one exited before its time.
pub(crate) fn check_alive(stations: &mut [Station]) -> anyhow::Result<()> {
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
}

/// Stops every station: SIGTERM to all at once (each runs its stop ladder), then waits for each.
///
/// # Errors
/// A station that did not exit successfully in time (its log's tail).
pub(crate) fn stop_all(stations: &mut [Station]) -> anyhow::Result<()> {
    for st in stations.iter() {
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
    Ok(())
}
