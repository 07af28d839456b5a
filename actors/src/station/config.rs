//! A station's configuration: which session and site it is, where the world comes from (a scenario
//! file, by default the paper's experiment embedded in the binary), and how its loops are scheduled.
//! Every field has a default, so a station starts with no file at all; a file is TOML with unknown
//! fields refused, and validation names the field, the value and the rule.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use coop_model::scenario::{MethodName, Scenario};
use coop_rt::sched::{Policy, Request};
use coop_rt::shm::station::RingSlots;
use coop_rt::shm::SegmentName;
use coop_transport::network::{Mode, NetworkConfig};
use coop_transport::recording::Rotation;
use serde::{Deserialize, Serialize};

use crate::scenario_file;

/// The paper's experiment, the default world.
pub const DEFAULT_SCENARIO: &str = include_str!("../../../scenarios/paper.toml");

/// Scheduling of one loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopSpec {
    /// CPU to pin to. Default: the servo gets the last allowed CPU to itself; physics, the network
    /// process and the supervisor share the first (on one CPU, everything shares it).
    pub cpu: Option<usize>,
    /// fifo, rr or other.
    pub policy: String,
    /// 1..=99 for fifo/rr, 0 for other. Default: 80 for the servo, 70 for physics under fifo/rr,
    /// 0 under other.
    pub priority: Option<i32>,
}

/// When the users' scripts start (the session's time 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum StartMode {
    /// When this station starts.
    #[default]
    Now,
    /// When the session's launcher announces it (on `coop/<session>/epoch`).
    Session,
}

/// The supervisor's policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupervisorSpec {
    /// never, on-failure or always.
    pub restart: String,
    /// Most restarts of one child within the window before the station stops.
    pub max_restarts: u32,
    /// The window, s.
    pub restart_window_s: f64,
    /// First restart delay, ms (doubling per restart in the window).
    pub backoff_initial_ms: u64,
    /// Longest restart delay, ms.
    pub backoff_max_ms: u64,
    /// A loop whose heartbeat stands still this long is hung and killed, ms.
    pub heartbeat_timeout_ms: u64,
    /// Time a child has to show its first heartbeat, ms.
    pub startup_timeout_ms: u64,
}

impl Default for SupervisorSpec {
    fn default() -> Self {
        Self {
            restart: "on-failure".into(),
            max_restarts: 3,
            restart_window_s: 10.0,
            backoff_initial_ms: 100,
            backoff_max_ms: 2000,
            heartbeat_timeout_ms: 500,
            startup_timeout_ms: 3000,
        }
    }
}

/// The configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StationConfig {
    /// Session name: stations of one session see each other.
    pub session: String,
    /// This station's site: a site name of the scenario (default: its first site).
    pub station: Option<String>,
    /// Scenario file with the world, the rates, the device and the user's script (default: the
    /// paper's experiment).
    pub scenario: Option<PathBuf>,
    /// Consistency method, overriding the scenario's.
    pub method: Option<MethodName>,
    /// Lock all memory of the loop processes.
    pub mlockall: bool,
    /// Hold `/dev/cpu_dma_latency` at 0 µs while the loops run (as cyclictest does): CPUs stay out
    /// of deep idle states, at the cost of power (and, on a VM, host CPU spent polling).
    pub cpu_dma_latency_zero: bool,
    /// The servo loop.
    pub servo: LoopSpec,
    /// The physics loop.
    pub physics: LoopSpec,
    /// Ring sizes.
    pub rings: RingSlots,
    /// Restart policy and watchdog.
    pub supervisor: SupervisorSpec,
    /// The network process: zenoh endpoints, mode, TLS, link emulation.
    pub network: NetworkConfig,
    /// When the users' scripts start: `now` or `session`.
    pub start: StartMode,
    /// Record what this station believed and displayed to this MCAP file (relative to the config
    /// file's directory). Default: no recording.
    pub record: Option<PathBuf>,
    /// The recording goes on in its next part (`user1.1.mcap`, `user1.2.mcap`, …) once a part holds
    /// this many MiB…
    pub record_max_file_mib: u64,
    /// …or has been written for this long, s.
    pub record_max_file_s: u64,
    /// Parts kept, the oldest removed beyond them (0: keep all).
    pub record_keep_files: u32,
}

impl Default for StationConfig {
    fn default() -> Self {
        Self {
            session: "local".into(),
            station: None,
            scenario: None,
            method: None,
            mlockall: true,
            cpu_dma_latency_zero: true,
            servo: LoopSpec::default(),
            physics: LoopSpec::default(),
            rings: RingSlots::default(),
            supervisor: SupervisorSpec::default(),
            network: NetworkConfig::default(),
            start: StartMode::Now,
            record: None,
            // A station records about 130 KB/s: a part holds about 8 minutes, the 24 parts (at
            // most 1.5 GiB) about 3 hours.
            record_max_file_mib: 64,
            record_max_file_s: 600,
            record_keep_files: 24,
        }
    }
}

impl Default for LoopSpec {
    fn default() -> Self {
        Self {
            cpu: None,
            policy: "fifo".into(),
            priority: None,
        }
    }
}

/// A configuration with its scenario loaded and every value checked.
#[derive(Debug, Clone)]
pub struct Resolved {
    /// The file's values.
    pub config: StationConfig,
    /// The world.
    pub scenario: Scenario,
    /// This station's site index in the scenario.
    pub site: usize,
    /// This station's site name.
    pub name: String,
    /// Servo scheduling.
    pub servo_sched: Request,
    /// Physics scheduling.
    pub physics_sched: Request,
    /// CPUs for everything that is not the servo (physics, network, supervisor).
    pub housekeeping_cpus: Vec<usize>,
    /// The supervisor's restart policy.
    pub policy: crate::policy::RestartPolicy,
}

fn sched(
    field: &str,
    l: &LoopSpec,
    default_cpu: usize,
    default_rt_priority: i32,
) -> anyhow::Result<Request> {
    let policy: Policy = l
        .policy
        .parse()
        .map_err(|e: String| anyhow::anyhow!("{field}.policy = {:?}: {e}", l.policy))?;
    let req = Request {
        policy,
        priority: l.priority.unwrap_or(if policy.is_realtime() {
            default_rt_priority
        } else {
            0
        }),
        cpus: Some(vec![l.cpu.unwrap_or(default_cpu)]),
        prefault_stack_bytes: 256 * 1024,
    };
    req.validate()
        .map_err(|e| anyhow::anyhow!("{field}: {e}"))?;
    Ok(req)
}

impl StationConfig {
    /// The recording's bounds, as the recorder takes them.
    pub fn record_rotation(&self) -> Rotation {
        Rotation {
            max_file_bytes: Some(self.record_max_file_mib << 20),
            max_file_duration: Some(std::time::Duration::from_secs(self.record_max_file_s)),
            keep_files: self.record_keep_files as usize,
        }
    }

    /// Checks the recording's bounds.
    fn check_record_bounds(&self) -> anyhow::Result<()> {
        for (field, v, hi) in [
            ("record_max_file_mib", self.record_max_file_mib, 65_536),
            ("record_max_file_s", self.record_max_file_s, 86_400),
        ] {
            if !(1..=hi).contains(&v) {
                bail!("{field} = {v}: must be from 1 to {hi}");
            }
        }
        if self.record_keep_files == 1 {
            bail!(
                "record_keep_files = 1: must be 0 (keep all) or at least 2 (1 would remove each \
                 part as soon as it is finished)"
            );
        }
        Ok(())
    }

    /// The configuration as a TOML file, the form [`StationConfig::load`] reads back (a launcher
    /// writes its stations' files with it; nothing spells the format out by hand).
    ///
    /// # Errors
    /// A value TOML cannot hold (none of this type's).
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        toml::to_string(self)
    }

    /// Reads `path` (or the defaults when `None`) and resolves it.
    ///
    /// # Errors
    /// Unreadable file, bad TOML, unknown field, or a value that breaks a rule (the message names
    /// the field, the value and the rule).
    pub fn load(path: Option<&Path>) -> anyhow::Result<Resolved> {
        let config = match path {
            None => StationConfig::default(),
            Some(p) => {
                let text = std::fs::read_to_string(p)
                    .with_context(|| format!("reading station config {}", p.display()))?;
                toml::from_str(&text)
                    .map_err(|e| anyhow::anyhow!("{}", e.to_string().trim_end()))
                    .with_context(|| format!("station config {}", p.display()))?
            }
        };
        config
            .resolve(path.and_then(Path::parent))
            .with_context(|| {
                format!(
                    "station config {}",
                    path.map_or("(defaults)".into(), |p| p.display().to_string())
                )
            })
    }

    /// Checks every value and loads the scenario (a relative scenario path is relative to `base`).
    ///
    /// # Errors
    /// As [`StationConfig::load`].
    pub fn resolve(self, base: Option<&Path>) -> anyhow::Result<Resolved> {
        SegmentName::station_prefix(&self.session, "x")
            .map_err(|e| anyhow::anyhow!("session = {:?}: {e}", self.session))?;
        let mut scenario = match &self.scenario {
            None => {
                scenario_file::parse(DEFAULT_SCENARIO).context("the embedded paper scenario")?
            }
            Some(p) => {
                let full = if p.is_relative() {
                    base.unwrap_or(Path::new(".")).join(p)
                } else {
                    p.clone()
                };
                scenario_file::load(&full)?
            }
        };
        if let Some(m) = self.method {
            scenario.method = m;
        }
        let name = self
            .station
            .clone()
            .unwrap_or_else(|| scenario.site[0].name.clone());
        let Some(site) = scenario.site.iter().position(|s| s.name == name) else {
            bail!(
                "station = {name:?}: names no site of scenario {:?} (its sites: {})",
                scenario.name,
                scenario
                    .site
                    .iter()
                    .map(|s| s.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        };
        for (field, slots) in [
            ("rings.tool_slots", self.rings.tool_slots),
            ("rings.object_slots", self.rings.object_slots),
            ("rings.report_slots", self.rings.report_slots),
            ("rings.remote_slots", self.rings.remote_slots),
            ("rings.trace_slots", self.rings.trace_slots),
        ] {
            if !(slots.is_power_of_two() && (2..=65536).contains(&slots)) {
                bail!("{field} = {slots}: must be a power of two from 2 to 65536");
            }
        }
        for (field, list) in [
            ("network.listen", &self.network.listen),
            ("network.connect", &self.network.connect),
        ] {
            if let Some(bad) = list.iter().find(|e| !e.contains('/') || e.len() > 256) {
                bail!("{field} contains {bad:?}: a zenoh locator looks like tcp/127.0.0.1:7447");
            }
        }
        if let Some(age) = self.network.max_state_age_ms {
            if !(10.0..=60_000.0).contains(&age) {
                bail!("network.max_state_age_ms = {age}: must be from 10 to 60000 ms");
            }
        }
        let lost = self.network.lost_after_reports;
        if !(2..=10_000).contains(&lost) {
            bail!("network.lost_after_reports = {lost}: must be from 2 to 10000 report periods");
        }
        if self.network.mode == Mode::Client && self.network.connect.is_empty() {
            bail!(
                "network.mode = \"client\" needs network.connect: the zenohd routers to go through"
            );
        }
        self.check_record_bounds()?;
        let mut config = self;
        let rebase = |p: &mut PathBuf| {
            if let Some(b) = base.filter(|_| p.is_relative()) {
                *p = b.join(&*p);
            }
        };
        if let Some(r) = &mut config.record {
            rebase(r);
        }
        if let Some(t) = &mut config.network.tls {
            for (field, f) in [
                ("root_ca_certificate", &mut t.root_ca_certificate),
                ("listen_certificate", &mut t.listen_certificate),
                ("listen_private_key", &mut t.listen_private_key),
                ("connect_certificate", &mut t.connect_certificate),
                ("connect_private_key", &mut t.connect_private_key),
            ] {
                if let Some(p) = f {
                    rebase(p);
                    if !p.is_file() {
                        bail!(
                            "network.tls.{field} = {:?}: no such file",
                            p.display().to_string()
                        );
                    }
                }
            }
        }
        let allowed = coop_rt::sched::allowed_cpus();
        let (first, last) = (
            allowed.first().copied().unwrap_or(0),
            allowed.last().copied().unwrap_or(0),
        );
        let servo_sched = sched("servo", &config.servo, last, 80)?;
        let physics_sched = sched("physics", &config.physics, first, 70)?;
        let sup = &config.supervisor;
        let mode = sup
            .restart
            .parse()
            .map_err(|e: String| anyhow::anyhow!("supervisor.restart = {:?}: {e}", sup.restart))?;
        if !(sup.restart_window_s > 0.0 && sup.restart_window_s <= 3600.0) {
            bail!(
                "supervisor.restart_window_s = {}: must be above 0 and at most 3600",
                sup.restart_window_s
            );
        }
        for (field, v, lo) in [
            ("supervisor.backoff_initial_ms", sup.backoff_initial_ms, 1),
            (
                "supervisor.backoff_max_ms",
                sup.backoff_max_ms,
                sup.backoff_initial_ms,
            ),
            (
                "supervisor.heartbeat_timeout_ms",
                sup.heartbeat_timeout_ms,
                10,
            ),
            ("supervisor.startup_timeout_ms", sup.startup_timeout_ms, 10),
        ] {
            if !(lo..=600_000).contains(&v) {
                bail!("{field} = {v}: must be from {lo} to 600000");
            }
        }
        let policy = crate::policy::RestartPolicy {
            mode,
            max_restarts: sup.max_restarts,
            window: std::time::Duration::from_secs_f64(sup.restart_window_s),
            backoff_initial: std::time::Duration::from_millis(sup.backoff_initial_ms),
            backoff_max: std::time::Duration::from_millis(sup.backoff_max_ms),
        };
        Ok(Resolved {
            config,
            scenario,
            site,
            name,
            housekeeping_cpus: physics_sched.cpus.clone().unwrap_or_default(),
            servo_sched,
            physics_sched,
            policy,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_resolve_to_the_paper_scenario_first_site() {
        let r = StationConfig::default()
            .resolve(None)
            .expect("defaults are valid");
        assert_eq!((r.name.as_str(), r.site), ("user1", 0));
        assert_eq!(r.servo_sched.policy, Policy::Fifo);
        assert_eq!(r.scenario.name, "paper");
    }

    #[test]
    fn each_rule_names_field_value_and_rule() {
        let cases: [(&str, &str); 8] = [
            (
                "[supervisor]\nrestart = \"sometimes\"",
                "supervisor.restart = \"sometimes\"",
            ),
            (
                "[supervisor]\nheartbeat_timeout_ms = 0",
                "supervisor.heartbeat_timeout_ms = 0: must be from 10",
            ),
            ("session = \"a_b\"", "session = \"a_b\""),
            (
                "station = \"nobody\"",
                "station = \"nobody\": names no site",
            ),
            (
                "[servo]\npriority = 120",
                "servo: priority 120 is out of range",
            ),
            (
                "[physics]\npolicy = \"deadline\"",
                "physics.policy = \"deadline\"",
            ),
            (
                "[rings]\ntool_slots = 100",
                "rings.tool_slots = 100: must be a power of two",
            ),
            ("sesion = \"x\"", "unknown field `sesion`"),
        ];
        for (text, needle) in cases {
            let err = toml::from_str::<StationConfig>(text)
                .map_err(anyhow::Error::from)
                .and_then(|c| c.resolve(None).map(drop))
                .expect_err(text);
            assert!(format!("{err:#}").contains(needle), "{text}: {err:#}");
        }
    }
}
