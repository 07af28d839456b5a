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
use coop_transport::network::{Locator, Mode, NetworkConfig};
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

/// The supervisor's policy: `max_restarts` … `backoff_max_ms` are the servo's and physics'
/// (a failure beyond them stops the station); the network process is retried without limit, its
/// delay capped by `network_backoff_max_ms` (see [`crate::policy`]).
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
    /// Longest restart delay of the network process, ms: it is restarted without limit (the
    /// station goes on without it, degraded), the delay doubling from `backoff_initial_ms`.
    pub network_backoff_max_ms: u64,
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
            network_backoff_max_ms: 5000,
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
    /// The device: backend, placement in the world, loop owner, safety limits.
    pub device: crate::station::device::DeviceSpec,
    /// The recording also holds Foxglove's `/tf`, `/scene` and `/log` channels (default: yes).
    pub record_foxglove: bool,
    /// Serve this station's own live view to Foxglove or Lichtblick (`foxglove.websocket.v1`) on
    /// this address, `host:port` (port 0: one chosen at start, printed); from the network
    /// process, off the real-time loops. Default: none (`station run --live` sets it).
    pub live: Option<String>,
    /// ROS 2: publish this site's poses, force, frames and events as ROS 2 topics under
    /// `rmw_zenoh`'s conventions (`[ros2] publish = true`, `domain_id`, `rate_hz`), from the
    /// network process. Default: off.
    pub ros2: coop_transport::ros2::Ros2Config,
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
            // A station records about 190 KB/s (130 KB/s without the Foxglove channels): a part
            // holds about 6 minutes, the 24 parts (at most 1.5 GiB) about 2 hours and a half.
            record_max_file_mib: 64,
            record_max_file_s: 600,
            record_keep_files: 24,
            device: crate::station::device::DeviceSpec::default(),
            record_foxglove: true,
            live: None,
            ros2: coop_transport::ros2::Ros2Config::default(),
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
    /// The supervisor's restart policy (of the servo and physics).
    pub policy: crate::policy::RestartPolicy,
    /// The network process's retry schedule.
    pub network_backoff: crate::policy::Backoff,
    /// The device, checked (and a replayed hand loaded).
    pub device: crate::station::device::DeviceSetup,
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

/// Rebases `t`'s files on `base` (relative paths are relative to the configuration file) and
/// checks each one opens as a regular file (opened, not only looked at: zenoh reads them at every
/// start of the network); `prefix` names the table in messages.
///
/// # Errors
/// A file that cannot be read or is not a regular file, naming `<prefix>.<field>` and the path.
pub(crate) fn tls_files_readable(
    t: &mut coop_transport::network::Tls,
    base: Option<&Path>,
    prefix: &str,
) -> anyhow::Result<()> {
    for (field, f) in t.files_mut() {
        let Some(p) = f else { continue };
        if let Some(b) = base.filter(|_| p.is_relative()) {
            *p = b.join(&*p);
        }
        readable(&format!("{prefix}.{field}"), p)?;
    }
    Ok(())
}

/// `field = path` opens and is a regular file.
///
/// # Errors
/// It cannot be read, or it is a directory or a special file.
pub(crate) fn readable(field: &str, p: &Path) -> anyhow::Result<()> {
    let shown = p.display().to_string();
    if let Err(e) = std::fs::File::open(p) {
        bail!("{field} = {shown:?}: cannot be read: {e}");
    }
    if !p.is_file() {
        bail!("{field} = {shown:?}: must be a regular file");
    }
    Ok(())
}

impl StationConfig {
    /// The rings' slots for a world of `objects` objects: the rings that carry a message per
    /// object a step (object states, reports, remote reports, trace records) have the configured
    /// slots per object (rounded up to a power of two), so that a world of several holds as many
    /// steps as a world of one; the others as configured. Fixed at start: nothing grows later.
    pub fn rings_for(&self, objects: usize) -> RingSlots {
        let n = objects
            .clamp(1, coop_model::world::MAX_OBJECTS)
            .next_power_of_two();
        let r = &self.rings;
        RingSlots {
            object_slots: r.object_slots * n,
            report_slots: r.report_slots * n,
            remote_slots: r.remote_slots * n,
            trace_slots: r.trace_slots * n,
            ..r.clone()
        }
    }

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
        let scenario = match &self.scenario {
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
        self.resolve_with(base, scenario)
    }

    /// Checks every value against `scenario`, the world this configuration names (already
    /// loaded; relative paths in the configuration are relative to `base`).
    ///
    /// # Errors
    /// As [`StationConfig::load`].
    pub fn resolve_with(
        self,
        base: Option<&Path>,
        mut scenario: Scenario,
    ) -> anyhow::Result<Resolved> {
        SegmentName::station_prefix(&self.session, "x")
            .map_err(|e| anyhow::anyhow!("session = {:?}: {e}", self.session))?;
        if let Some(m) = self.method {
            scenario.method = m;
        }
        if matches!(scenario.method, MethodName::Timewarp | MethodName::Coupled) {
            // One tick grid for the session: every site steps at the same rate.
            let r0 = scenario.site[0].physics_rate_hz;
            if let Some((k, s)) = scenario
                .site
                .iter()
                .enumerate()
                .find(|(_, s)| s.physics_rate_hz != r0)
            {
                bail!(
                    "site[{k}].physics_rate_hz = {} (scenario {:?}): method {} steps every site on one tick grid, so every site's physics rate must equal site[0]'s ({r0} Hz)",
                    s.physics_rate_hz,
                    scenario.name,
                    scenario.method.as_str()
                );
            }
        }
        if self.ros2.publish {
            coop_transport::ros2::check_names(
                scenario.site.iter().map(|s| s.name.as_str()),
                scenario.objects.iter().map(|o| o.name.as_str()),
            )
            .map_err(|e| {
                anyhow::anyhow!("ros2.publish = true: scenario {:?}: {e}", scenario.name)
            })?;
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
            ("rings.track_slots", self.rings.track_slots),
        ] {
            if !(slots.is_power_of_two() && (2..=65536).contains(&slots)) {
                bail!("{field} = {slots}: must be a power of two from 2 to 65536");
            }
        }
        network_rules(&self.network)?;
        if let Some(age) = self.network.max_state_age_ms {
            if !(10.0..=60_000.0).contains(&age) {
                bail!("network.max_state_age_ms = {age}: must be from 10 to 60000 ms");
            }
        }
        let lost = self.network.lost_after_reports;
        if !(2..=10_000).contains(&lost) {
            bail!("network.lost_after_reports = {lost}: must be from 2 to 10000 report periods");
        }
        self.check_record_bounds()?;
        if let Some(l) = &self.live {
            if coop_transport::live_view::parse_addr(l).is_err() {
                bail!(
                    "live = {l:?}: not an address such as {} (host:port; port 0 picks a free one)",
                    coop_transport::live_view::DEFAULT_ADDR
                );
            }
        }
        self.ros2.validate().map_err(anyhow::Error::msg)?;
        let mut config = self;
        let rebase = |p: &mut PathBuf| {
            if let Some(b) = base.filter(|_| p.is_relative()) {
                *p = b.join(&*p);
            }
        };
        if let Some(r) = &mut config.record {
            rebase(r);
            record_rules(r)?;
        }
        if let Some(a) = &mut config.network.access_control {
            rebase(a);
            let shown = a.display().to_string();
            if let Err(e) = std::fs::File::open(&*a) {
                bail!("network.access_control = {shown:?}: cannot be read: {e}");
            }
        }
        if let Some(t) = &mut config.network.tls {
            tls_files_readable(t, base, "network.tls")?;
        }
        let device = config.device.resolve(base)?;
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
            (
                "supervisor.network_backoff_max_ms",
                sup.network_backoff_max_ms,
                sup.backoff_initial_ms,
            ),
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
        let network_backoff = crate::policy::Backoff {
            initial: std::time::Duration::from_millis(sup.backoff_initial_ms),
            max: std::time::Duration::from_millis(sup.network_backoff_max_ms),
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
            network_backoff,
            device,
        })
    }
}

/// The `[network]` rules that need no look at the machine: every locator is a zenoh endpoint of a
/// transport this build has; no port (but 0) is listened on twice; client mode has routers to go
/// through; a `tls/` locator has the TLS files it needs named.
fn network_rules(net: &NetworkConfig) -> anyhow::Result<()> {
    let mut listening: Vec<(&String, Locator)> = Vec::new();
    for (field, list) in [
        ("network.listen", &net.listen),
        ("network.connect", &net.connect),
    ] {
        for l in list {
            if l.len() > 256 {
                bail!("{field} contains {l:?}: a locator is at most 256 bytes");
            }
            let loc =
                Locator::parse(l).map_err(|e| anyhow::anyhow!("{field} contains {l:?}: {e}"))?;
            // Client mode does not listen (zenoh ignores `listen` there).
            let listens = field == "network.listen" && net.mode == Mode::Peer;
            if listens && loc.port != 0 {
                if let Some((other, _)) = listening.iter().find(|(_, o)| o.overlaps(&loc)) {
                    bail!(
                        "{field} contains {other:?} and {l:?}: the same port twice (each port is listened on once)"
                    );
                }
            }
            if loc.protocol == "tls" && (listens || field == "network.connect") {
                let t = net.tls.clone().unwrap_or_default();
                let needs: Vec<(&str, bool)> = if listens {
                    vec![
                        ("listen_certificate", t.listen_certificate.is_some()),
                        ("listen_private_key", t.listen_private_key.is_some()),
                        (
                            "root_ca_certificate (enable_mtls)",
                            !t.enable_mtls || t.root_ca_certificate.is_some(),
                        ),
                    ]
                } else {
                    vec![
                        ("root_ca_certificate", t.root_ca_certificate.is_some()),
                        (
                            "connect_certificate (enable_mtls)",
                            !t.enable_mtls || t.connect_certificate.is_some(),
                        ),
                        (
                            "connect_private_key (enable_mtls)",
                            !t.enable_mtls || t.connect_private_key.is_some(),
                        ),
                    ]
                };
                let missing: Vec<&str> = needs
                    .iter()
                    .filter(|(_, ok)| !ok)
                    .map(|(n, _)| *n)
                    .collect();
                if !missing.is_empty() {
                    let table = if net.tls.is_none() {
                        "a [network.tls] table with"
                    } else {
                        "[network.tls]"
                    };
                    bail!(
                        "{field} contains {l:?}: a tls/ locator needs {table} {}",
                        missing.join(" and ")
                    );
                }
            }
            if listens {
                listening.push((l, loc));
            }
        }
    }
    own_certificate_rules(net)?;
    if net.mode == Mode::Client && net.connect.is_empty() {
        bail!("network.mode = \"client\" needs network.connect: the zenohd routers to go through");
    }
    Ok(())
}

/// A station given TLS presents its own certificate (common name = its site name: what the
/// access control knows it by) in every direction it uses TLS, and access control needs mutual
/// TLS (its rules name certificates).
fn own_certificate_rules(net: &NetworkConfig) -> anyhow::Result<()> {
    let Some(t) = &net.tls else {
        if let Some(a) = &net.access_control {
            bail!(
                "network.access_control = {:?}: needs [network.tls] with enable_mtls = true (its rules name the certificates stations present)",
                a.display().to_string()
            );
        }
        return Ok(());
    };
    let tls = |l: &String| l.starts_with("tls/");
    let connects = net.connect.iter().any(tls);
    let listens = net.mode == Mode::Peer && net.listen.iter().any(tls);
    for (uses, field, ok) in [
        (
            connects,
            "connect_certificate",
            t.connect_certificate.is_some(),
        ),
        (
            connects,
            "connect_private_key",
            t.connect_private_key.is_some(),
        ),
        (
            listens,
            "listen_certificate",
            t.listen_certificate.is_some(),
        ),
        (
            listens,
            "listen_private_key",
            t.listen_private_key.is_some(),
        ),
    ] {
        if uses && !ok {
            let how = if field.starts_with("connect") {
                "connects"
            } else {
                "listens"
            };
            bail!(
                "network.tls.{field} is missing: a station that {how} over TLS presents its own certificate (common name = its site name; `session certs` makes one)"
            );
        }
    }
    if let Some(a) = &net.access_control {
        if !t.enable_mtls {
            bail!(
                "network.access_control = {:?}: needs network.tls.enable_mtls = true (its rules name the certificates stations present)",
                a.display().to_string()
            );
        }
    }
    Ok(())
}

/// The recording's rules: its directory exists and is writable (none is created), and the path
/// is a regular file or not there yet (not a directory, a device or a pipe: `/dev/full` would take
/// the recording and fail every write).
fn record_rules(path: &Path) -> anyhow::Result<()> {
    let shown = path.display().to_string();
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match std::fs::metadata(dir) {
        Err(e) => bail!(
            "record = {shown:?}: its directory {:?} cannot be used ({e}); it is not created, make it first",
            dir.display().to_string()
        ),
        Ok(m) if !m.is_dir() => bail!(
            "record = {shown:?}: {:?} is not a directory",
            dir.display().to_string()
        ),
        Ok(_) => {}
    }
    if let Err(e) = nix::unistd::access(dir, nix::unistd::AccessFlags::W_OK) {
        bail!(
            "record = {shown:?}: its directory {:?} is not writable ({e})",
            dir.display().to_string()
        );
    }
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => {
            use std::os::unix::fs::FileTypeExt;
            let t = m.file_type();
            let what = if t.is_dir() {
                "a directory"
            } else if t.is_char_device() || t.is_block_device() {
                "a device"
            } else if t.is_fifo() {
                "a pipe"
            } else if t.is_socket() {
                "a socket"
            } else {
                "not a file"
            };
            bail!("record = {shown:?}: must be a regular file (it is {what})");
        }
        Ok(_) => {
            if let Err(e) = nix::unistd::access(path, nix::unistd::AccessFlags::W_OK) {
                bail!("record = {shown:?}: is not writable ({e})");
            }
        }
        Err(_) => {}
    }
    Ok(())
}

impl Resolved {
    /// The rules that look at the machine as it is now, checked by `station run` before it creates
    /// anything (not by every resolve: a child re-reads the configuration while its station's
    /// network process holds the ports): every listen port that is not 0 is free, the live
    /// view's too.
    ///
    /// # Errors
    /// A taken port (or an address of another machine), naming the field and the value.
    pub fn check_listen_ports_free(&self) -> anyhow::Result<()> {
        if let Some(l) = &self.config.live {
            let addr = coop_transport::live_view::parse_addr(l)
                .map_err(|_| anyhow::anyhow!("live = {l:?}: not an address (host:port)"))?;
            if addr.port() != 0 {
                if let Err(e) = std::net::TcpListener::bind(addr) {
                    bail!(
                        "live = {l:?}: cannot listen there now ({e}); choose a free port, or 0 for one chosen at start"
                    );
                }
            }
        }
        let net = &self.config.network;
        if net.mode == Mode::Client {
            return Ok(());
        }
        for l in &net.listen {
            let loc = Locator::parse(l)
                .map_err(|e| anyhow::anyhow!("network.listen contains {l:?}: {e}"))?;
            if loc.port != 0 {
                if let Err(e) = loc.bind_check() {
                    bail!(
                        "network.listen contains {l:?}: cannot listen there now ({e}); choose a free port, or 0 for one chosen at start"
                    );
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timewarp_and_coupled_need_one_physics_rate() {
        for m in [MethodName::Timewarp, MethodName::Coupled] {
            let c = StationConfig {
                method: Some(m),
                ..StationConfig::default()
            };
            let mut sc = scenario_file::parse(DEFAULT_SCENARIO).expect("paper");
            c.clone()
                .resolve_with(None, sc.clone())
                .expect("the paper's sites share a physics rate");
            sc.site[1].physics_rate_hz = 500.0;
            let err = c.resolve_with(None, sc).expect_err("two rates");
            let err = format!("{err:#}");
            assert!(
                err.contains("site[1].physics_rate_hz = 500")
                    && err.contains(&format!("method {} steps", m.as_str()))
                    && err.contains("must equal site[0]'s"),
                "{err}"
            );
        }
    }

    /// Stations run a world of several objects, with rotational friction on the table, between
    /// the objects and at the fingertips, under every method: their rings and wire carry every
    /// object's state, every contact's torque, and every friction memory a snapshot holds.
    #[test]
    fn stations_take_a_world_of_several_objects_with_every_friction() {
        for (file, text) in [
            ("stack.toml", include_str!("../../../scenarios/stack.toml")),
            ("tray.toml", include_str!("../../../scenarios/tray.toml")),
            (
                "billiards.toml",
                include_str!("../../../scenarios/billiards.toml"),
            ),
        ] {
            let sc = scenario_file::parse(text).expect(file);
            assert!(sc.objects.len() > 1, "{file}");
            for m in MethodName::ALL {
                let c = StationConfig {
                    method: Some(m),
                    ..StationConfig::default()
                };
                let r = c
                    .resolve_with(None, sc.clone())
                    .unwrap_or_else(|e| panic!("{file} under {}: {e:#}", m.as_str()));
                // The rings that carry a message per object grow with the world.
                let n = sc.objects.len().next_power_of_two();
                let d = coop_rt::shm::station::RingSlots::default();
                let slots = r.config.rings_for(sc.objects.len());
                assert_eq!(slots.object_slots, d.object_slots * n, "{file}");
                assert_eq!(slots.trace_slots, d.trace_slots * n, "{file}");
                assert_eq!(slots.tool_slots, d.tool_slots, "{file}");
            }
        }
    }

    #[test]
    fn defaults_resolve_to_the_paper_scenario_first_site() {
        let r = StationConfig::default()
            .resolve(None)
            .expect("defaults are valid");
        assert_eq!((r.name.as_str(), r.site), ("user1", 0));
        assert_eq!(r.servo_sched.policy, Policy::Fifo);
        assert_eq!(r.scenario.name, "paper");
        assert_eq!(r.network_backoff.max, std::time::Duration::from_secs(5));
    }

    #[test]
    fn a_taken_listen_port_is_refused_before_start_and_a_free_one_passes() {
        let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = taken.local_addr().expect("addr").port();
        let mut c = StationConfig::default();
        c.network.listen = vec![format!("tcp/127.0.0.1:{port}")];
        let r = c
            .clone()
            .resolve(None)
            .expect("no look at the machine in resolve");
        let err = r.check_listen_ports_free().expect_err("taken");
        assert!(
            format!("{err:#}").contains(&format!(
                "network.listen contains \"tcp/127.0.0.1:{port}\": cannot listen there now"
            )),
            "{err:#}"
        );
        drop(taken);
        r.check_listen_ports_free().expect("free now");
        c.network.mode = Mode::Client;
        c.network.connect = vec!["tcp/127.0.0.1:7447".into()];
        let taken = std::net::TcpListener::bind(("127.0.0.1", port)).expect("bind again");
        c.resolve(None)
            .expect("valid")
            .check_listen_ports_free()
            .expect("a client does not listen");
        drop(taken);
    }

    #[test]
    fn a_taken_live_view_port_is_refused_before_start_and_port_0_passes() {
        let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = taken.local_addr().expect("addr").port();
        let live = |addr: String| StationConfig {
            live: Some(addr),
            ..StationConfig::default()
        };
        let r = live(format!("127.0.0.1:{port}"))
            .resolve(None)
            .expect("no look at the machine in resolve");
        let err = r.check_listen_ports_free().expect_err("taken");
        assert!(
            format!("{err:#}").contains(&format!(
                "live = \"127.0.0.1:{port}\": cannot listen there now"
            )),
            "{err:#}"
        );
        live("127.0.0.1:0".into())
            .resolve(None)
            .expect("valid")
            .check_listen_ports_free()
            .expect("port 0 is chosen at start");
        drop(taken);
    }

    #[test]
    fn a_recording_path_is_a_file_in_a_writable_directory_never_made() {
        let dir = std::env::temp_dir().join(format!("coop-rec-rules-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let with = |p: &Path| StationConfig {
            record: Some(p.to_owned()),
            ..StationConfig::default()
        };
        with(&dir.join("a.mcap")).resolve(None).expect("a new file");
        let err = with(&dir).resolve(None).expect_err("a directory");
        assert!(
            format!("{err:#}").contains("must be a regular file (it is a directory)"),
            "{err:#}"
        );
        let missing = dir.join("not-made/a.mcap");
        assert!(with(&missing).resolve(None).is_err());
        assert!(
            !dir.join("not-made").exists(),
            "validation made a directory"
        );
        // Relative to the config file's directory.
        std::fs::create_dir_all(dir.join("rec")).expect("dir");
        let r = with(Path::new("rec/a.mcap"))
            .resolve(Some(&dir))
            .expect("relative");
        assert_eq!(r.config.record, Some(dir.join("rec/a.mcap")));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_station_given_tls_presents_its_own_certificate() {
        for (text, needle) in [
            (
                "[network]\nmode = \"client\"\nconnect = [\"tls/192.0.2.1:7447\"]\n[network.tls]\nroot_ca_certificate = \"/dev/null\"",
                "network.tls.connect_certificate is missing: a station that connects over TLS presents its own certificate",
            ),
            (
                "[network]\nconnect = [\"tcp/127.0.0.1:7447\"]\naccess_control = \"/dev/null\"",
                "network.access_control = \"/dev/null\": needs [network.tls] with enable_mtls = true",
            ),
        ] {
            let err = toml::from_str::<StationConfig>(text)
                .map_err(anyhow::Error::from)
                .and_then(|c| c.resolve(None).map(drop))
                .expect_err(text);
            assert!(format!("{err:#}").contains(needle), "{text}: {err:#}");
        }
    }

    #[test]
    fn each_rule_names_field_value_and_rule() {
        let cases: [(&str, &str); 29] = [
            (
                "[device]\ndevice = \"haply\"\n[device.haply]\nurl = \"http://localhost:10001\"",
                "device.haply.url = \"http://localhost:10001\": must be a ws://host:port URL",
            ),
            (
                "[device]\ndevice = \"haply\"\n[device.haply]\nrate = 5",
                "device.haply: unknown field `rate`",
            ),
            (
                "[device.haply]\nurl = \"ws://localhost:10001\"",
                "device.haply: a table for backend \"haply\", but device = \"sim\"",
            ),
            (
                "[device]\ndevice = \"phantom\"",
                "unknown variant `phantom`, expected one of `sim`, `replay`, `haply`, `dhd`",
            ),
            (
                "[device]\nloop = \"vendor\"",
                "device.loop = \"vendor\": device \"sim\" cannot call the station from its own thread",
            ),
            (
                "[device.safety]\nmax_force_n = 0",
                "device.safety.max_force_n = 0: must be above 0 and at most 100 N",
            ),
            (
                "[device.safety]\nwatchdog_ms = 0.5",
                "device.safety.watchdog_ms = 0.5: must be from 1 and at most 10000 ms",
            ),
            (
                "[device.safety]\nmax_velocity_m_s = nan",
                "device.safety.max_velocity_m_s = NaN: must be above 0",
            ),
            (
                "[device.placement]\nworkspace_scale = 0",
                "device.placement.workspace_scale = 0: must be from 0.001 to 1000",
            ),
            (
                "[device.placement]\ntranslation_m = [0.1, 0, 0]",
                "must be the identity for device = \"sim\"",
            ),
            (
                "[device]\ndevice = \"replay\"",
                "device.replay.file is missing",
            ),
            (
                "[device]\ndevice = \"replay\"\n[device.replay]\nfile = \"/nonexistent-coop/hand.csv\"",
                "device.replay.file = \"/nonexistent-coop/hand.csv\": cannot be read",
            ),
            (
                "[device]\ndevice = \"dhd\"\n[device.dhd]\nwatchdog_ms = 40",
                "device.dhd.watchdog_ms = 40: must be 0 (off) or in 0.125..=31.875 ms",
            ),
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
            (
                "[network]\nlisten = [\"udp/127.0.0.1:0\"]",
                "network.listen contains \"udp/127.0.0.1:0\": transport \"udp\" is not in this build",
            ),
            (
                "[network]\nconnect = [\"tcp/127.0.0.1\"]",
                "network.connect contains \"tcp/127.0.0.1\": a zenoh locator looks like",
            ),
            (
                "[network]\nlisten = [\"tcp/0.0.0.0:7447\", \"tls/127.0.0.1:7447\"]",
                "the same port twice",
            ),
            (
                "[network]\nlisten = [\"tls/127.0.0.1:0\"]",
                "a tls/ locator needs a [network.tls] table with listen_certificate and listen_private_key",
            ),
            (
                "[network]\nconnect = [\"tls/127.0.0.1:7447\"]\n[network.tls]\nenable_mtls = true",
                "needs [network.tls] root_ca_certificate and connect_certificate (enable_mtls) and",
            ),
            (
                "record = \"/dev/full\"",
                "record = \"/dev/full\": must be a regular file (it is a device)",
            ),
            (
                "record = \"/nonexistent-coop-dir/a.mcap\"",
                "its directory \"/nonexistent-coop-dir\" cannot be used",
            ),
            (
                "[supervisor]\nbackoff_initial_ms = 100\nnetwork_backoff_max_ms = 50",
                "supervisor.network_backoff_max_ms = 50: must be from 100",
            ),
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
