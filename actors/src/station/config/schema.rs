//! The configuration file as TOML holds it: every table and field, each with its default, unknown
//! fields refused. Nothing here checks a value (see `rules`) or loads a file (see `resolve`).
//!
//! A scheduling policy and a restart mode stay text here, parsed when the configuration is
//! resolved: serde would refuse a misspelt one without the field's name, and the messages name it.

use std::path::PathBuf;

use coop_model::scenario::MethodName;
use coop_rt::shm::station::RingSlots;
use coop_transport::network::NetworkConfig;
use coop_transport::recording::Rotation;
use serde::{Deserialize, Serialize};

/// Scheduling of one loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
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
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, schemars::JsonSchema,
)]
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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
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
    /// Time a child has to show its first heartbeat, ms. The servo has this plus its device's own
    /// start wait (`device.ros2.first_pose_timeout_ms`; `device.haply.connect_timeout_ms` plus
    /// `io_timeout_ms`), so a device that does not open ends the station with its own error, not
    /// as a hung servo.
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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
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
    /// A study's station: it runs the trials a study runner announces (`study run --stations`),
    /// each from its scenario and its time 0, and stays up between them: no process restarts,
    /// the device stays open (a simulated hand is made again per trial), one recording per trial
    /// (named by it, beside `record`). Needs `start = "session"`. Default: no.
    pub trials: bool,
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
            trials: false,
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

    /// The configuration as a TOML file, the form [`StationConfig::load`] reads back (a launcher
    /// writes its stations' files with it; nothing spells the format out by hand).
    ///
    /// # Errors
    /// A value TOML cannot hold (none of this type's).
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        toml::to_string(self)
    }
}
