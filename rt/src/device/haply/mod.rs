//! Haply Inverse3 through the Haply Inverse Service's simulation channel (WebSocket, JSON format
//! 3.1, `ws://localhost:10001` by default).
//!
//! The servo never touches the socket. [`HaplyDevice::open`] connects, reads the service's snapshot,
//! picks the Inverse3 (by `device_id`, or the only one), and starts a bridge thread that owns the
//! socket (`bridge.rs`); [`HaplyDevice::sample`](CartesianDevice::sample) and
//! [`command`](CartesianDevice::command) only pop a lock-free ring and write a seqlock slot.
//!
//! Why not the `haply` crate: its `HaplyDevice` shares state behind `Arc<tokio::sync::Mutex<_>>`
//! and is driven from async tasks (tokio, tokio-tungstenite, futures, an HTTP client), so a servo
//! reading it would lock and allocate. The protocol is small, and the workspace already has
//! `tungstenite` and `serde_json`: this backend speaks it directly.
//!
//! Faults: when the service goes, the bridge reports [`DeviceFault::Disconnected`] at once (socket
//! closed or reset) or the samples stop advancing and `sample` says `Disconnected` once the newest is
//! older than `stale_limit_ms` (a hung service); a frame that is not what the protocol says gives
//! [`DeviceFault::BadValue`], and the bridge sends zero force until good frames return and the servo
//! commands again.

mod bridge;
pub mod wire;

use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use coop_model::body::Vec3;

pub use bridge::BridgeStats;
use bridge::{Bridge, BridgeMsg, Shared, Target};

use crate::device::{
    BridgedState, CartesianDevice, Command, ConfigError, DeviceFault, DeviceInfo, ProbeReport,
    Sample,
};
use crate::timer::monotonic_ns;

/// The Inverse Service's default simulation channel.
pub const DEFAULT_URL: &str = "ws://localhost:10001";

/// The station config's `[device.haply]` table.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct HaplyConfig {
    /// The service's simulation channel (`ws://` only: the service listens on loopback).
    pub url: String,
    /// Which Inverse3, by the `device_id` the service reports (its serial, e.g. `"049D"`); none: the
    /// only one listed.
    pub device_id: Option<String>,
    /// Messages per second the bridge exchanges with the service (it answers one frame per message).
    pub rate_hz: f64,
    /// A sample older than this is stale: `sample` reports `Disconnected`.
    pub stale_limit_ms: f64,
    /// How long to wait for the TCP connection and the service's first frame.
    pub connect_timeout_ms: u64,
    /// How long a send or a reply may take before the connection counts as lost.
    pub io_timeout_ms: u64,
    /// How long to wait between reconnection attempts after a loss.
    pub reconnect_ms: u64,
    /// The largest force to report as the device's maximum, N. The default is conservative: set it
    /// to your device's rating; the safety layer clamps to the smaller of this and the station's.
    pub max_force_n: f64,
    /// The stiffest contact to report as stable, N/m.
    pub max_stiffness_n_per_m: f64,
    /// The largest damping to report as stable, N·s/m (`max_damping_ns_per_m`, its old name,
    /// is read too).
    #[cfg_attr(feature = "serde", serde(alias = "max_damping_ns_per_m"))]
    pub max_damping_n_s_per_m: f64,
    /// The radius of the workspace sphere to report, m.
    pub workspace_radius_m: f64,
}

impl Default for HaplyConfig {
    fn default() -> Self {
        Self {
            url: DEFAULT_URL.to_owned(),
            device_id: None,
            rate_hz: 1000.0,
            stale_limit_ms: 20.0,
            connect_timeout_ms: 2000,
            io_timeout_ms: 100,
            reconnect_ms: 500,
            max_force_n: 3.0,
            max_stiffness_n_per_m: 1000.0,
            max_damping_n_s_per_m: 5.0,
            workspace_radius_m: 0.1,
        }
    }
}

fn bad(field: &str, value: impl std::fmt::Display, rule: &str) -> ConfigError {
    ConfigError {
        field: field.to_owned(),
        value: value.to_string(),
        rule: rule.to_owned(),
    }
}

impl HaplyConfig {
    /// Checks every field (positive containment, so NaN fails).
    ///
    /// # Errors
    /// The first field that breaks its rule, with its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let url: Result<tungstenite::http::Uri, _> = self.url.parse();
        let ok_url = url
            .as_ref()
            .is_ok_and(|u| u.scheme_str() == Some("ws") && u.host().is_some_and(|h| !h.is_empty()));
        if !ok_url {
            return Err(bad(
                "url",
                format!("{:?}", self.url),
                "must be a ws://host:port URL (the service's simulation channel, e.g. ws://localhost:10001)",
            ));
        }
        if let Some(id) = &self.device_id {
            if id.is_empty() || id.len() > 32 || !id.bytes().all(|b| b.is_ascii_alphanumeric()) {
                return Err(bad(
                    "device_id",
                    format!("{id:?}"),
                    "must be the device_id the service lists (1 to 32 letters or digits, e.g. \"049D\")",
                ));
            }
        }
        crate::device::check_bridged(
            self.rate_hz,
            self.stale_limit_ms,
            [
                self.max_force_n,
                self.max_stiffness_n_per_m,
                self.max_damping_n_s_per_m,
                self.workspace_radius_m,
            ],
        )?;
        for (field, v) in [
            ("connect_timeout_ms", self.connect_timeout_ms),
            ("io_timeout_ms", self.io_timeout_ms),
            ("reconnect_ms", self.reconnect_ms),
        ] {
            if !(1..=60_000).contains(&v) {
                return Err(bad(field, v, "must be in 1..=60000 ms"));
            }
        }
        Ok(())
    }

    fn target(&self) -> Target {
        Target {
            url: self.url.clone(),
            connect_timeout: Duration::from_millis(self.connect_timeout_ms),
            io_timeout: Duration::from_millis(self.io_timeout_ms),
        }
    }

    fn info(&self, device_id: &str) -> DeviceInfo {
        DeviceInfo {
            backend: "haply",
            model: "Inverse3".to_owned(),
            serial: Some(device_id.to_owned()),
            dof: 3,
            max_force_n: self.max_force_n,
            max_stiffness_n_per_m: self.max_stiffness_n_per_m,
            max_damping_n_s_per_m: self.max_damping_n_s_per_m,
            workspace_radius_m: self.workspace_radius_m,
            native_rate_hz: self.rate_hz,
            senses_force: false,
        }
    }
}

/// Why [`HaplyDevice::open`] failed. Nothing was started.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HaplyOpenError {
    /// The config breaks a rule.
    #[error("device.haply.{0}")]
    Config(ConfigError),
    /// No TCP connection.
    #[error("Haply Inverse Service not reachable at {url} (device.haply.url): {reason}")]
    Unreachable {
        /// Where we looked.
        url: String,
        /// The OS's words.
        reason: String,
    },
    /// TCP, but no WebSocket.
    #[error("{url} (device.haply.url) did not complete a WebSocket handshake: {reason}")]
    Handshake {
        /// Where.
        url: String,
        /// tungstenite's words.
        reason: String,
    },
    /// Connected, but the service sent no snapshot in time.
    #[error("the Haply Inverse Service at {url} sent no snapshot: {reason}")]
    NoSnapshot {
        /// Where.
        url: String,
        /// What happened instead.
        reason: String,
    },
    /// The snapshot is not the protocol's (refused; nothing was commanded).
    #[error("the Haply Inverse Service at {url} sent a frame we refuse: {reason}")]
    BadSnapshot {
        /// Where.
        url: String,
        /// What was wrong.
        reason: String,
    },
    /// The service lists no Inverse3.
    #[error(
        "the Haply Inverse Service at {url} lists no Inverse3 (is it plugged in and powered?)"
    )]
    NoDevice {
        /// Where.
        url: String,
    },
    /// `device_id` is not among those listed.
    #[error("device.haply.device_id = {wanted:?}: the service at {url} lists only {found:?}")]
    NotListed {
        /// Where.
        url: String,
        /// What the config asked for.
        wanted: String,
        /// What the service lists.
        found: Vec<String>,
    },
    /// Several listed and the config does not say which.
    #[error(
        "the service at {url} lists several Inverse3 {found:?}: set device.haply.device_id to one"
    )]
    Ambiguous {
        /// Where.
        url: String,
        /// What the service lists.
        found: Vec<String>,
    },
    /// The bridge thread did not start.
    #[error("starting the Haply bridge thread: {0}")]
    Thread(String),
}

/// Sample messages the ring holds: at 1 kHz, a quarter second of a servo that does not read.
const RING_SLOTS: usize = 256;

/// An Inverse3 through the service, servo side.
#[derive(Debug)]
pub struct HaplyDevice {
    info: DeviceInfo,
    rx: rtrb::Consumer<BridgeMsg>,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    state: BridgedState,
    displayed_force_n: Option<Vec3>,
}

impl HaplyDevice {
    /// Connects to the service, checks its snapshot, and starts the bridge at `config.rate_hz`.
    /// Until the servo commands, the bridge sends zero force.
    ///
    /// # Errors
    /// A bad config, an unreachable or misbehaving service, or no matching Inverse3.
    pub fn open(config: &HaplyConfig) -> Result<Self, HaplyOpenError> {
        config.validate().map_err(HaplyOpenError::Config)?;
        let target = config.target();
        let (ws, snapshot) = bridge::connect(&target)?;
        let url = config.url.clone();
        let listed = wire::list_devices(&snapshot).map_err(|e| HaplyOpenError::BadSnapshot {
            url: url.clone(),
            reason: e.to_string(),
        })?;
        let ids: Vec<String> = listed.iter().map(|d| d.device_id.clone()).collect();
        let device_id = match (&config.device_id, ids.as_slice()) {
            (_, []) => return Err(HaplyOpenError::NoDevice { url }),
            (Some(w), _) if !ids.contains(w) => {
                return Err(HaplyOpenError::NotListed {
                    url,
                    wanted: w.clone(),
                    found: ids,
                })
            }
            (Some(w), _) => w.clone(),
            (None, [one]) => one.clone(),
            (None, _) => return Err(HaplyOpenError::Ambiguous { url, found: ids }),
        };
        let first =
            wire::device_state(&snapshot, &device_id).map_err(|e| HaplyOpenError::BadSnapshot {
                url: config.url.clone(),
                reason: e.to_string(),
            })?;
        let newest = Sample {
            t_ns: monotonic_ns(),
            position_m: first.position_m,
            velocity_m_s: first.velocity_m_s,
            orientation: first.orientation,
            buttons: first.buttons,
            force_sensed_n: None,
        };
        let (tx, rx) = rtrb::RingBuffer::new(RING_SLOTS);
        let shared = Arc::new(Shared::default());
        shared.stats.set_connected(true);
        let b = Bridge {
            target,
            device_id: device_id.clone(),
            period_ns: (1e9 / config.rate_hz) as u64,
            reconnect: Duration::from_millis(config.reconnect_ms),
            gate: shared.cmd.load().0,
            shared: Arc::clone(&shared),
            tx,
        };
        let thread = std::thread::Builder::new()
            .name("haply-bridge".into())
            .spawn(move || b.run(ws))
            .map_err(|e| HaplyOpenError::Thread(e.to_string()))?;
        Ok(Self {
            info: config.info(&device_id),
            rx,
            shared,
            thread: Some(thread),
            state: BridgedState::new(newest, (config.stale_limit_ms * 1e6) as u64),
            displayed_force_n: first.displayed_force_n,
        })
    }

    /// The bridge's counters and last error (for status and tests).
    pub fn stats(&self) -> &BridgeStats {
        &self.shared.stats
    }

    /// The newest sample the bridge delivered, fresh or not (for status and tests).
    pub fn last_sample(&self) -> Sample {
        self.state.newest()
    }

    /// The stale limit, ns.
    pub fn stale_limit_ns(&self) -> u64 {
        self.state.stale_limit_ns()
    }

    /// What the service last said it displays (`current_cursor_force`), as of the newest sample
    /// `sample` returned: the benchmark's round trip reads it.
    pub fn displayed_force_n(&self) -> Option<Vec3> {
        self.displayed_force_n
    }

    fn drain(&mut self) {
        while let Ok(m) = self.rx.pop() {
            match m {
                BridgeMsg::Frame {
                    sample,
                    displayed_force_n,
                } => {
                    self.state.take(sample);
                    self.displayed_force_n = displayed_force_n;
                }
                BridgeMsg::Fault(f) => self.state.fail(f),
            }
        }
    }
}

impl CartesianDevice for HaplyDevice {
    fn info(&self) -> &DeviceInfo {
        &self.info
    }

    fn sample(&mut self, now_ns: u64) -> Result<Sample, DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls (ring pops only).
        self.drain();
        self.state.fresh(now_ns)
    }

    fn command(&mut self, now_ns: u64, cmd: Command) -> Result<(), DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls (one seqlock write).
        self.shared.cmd.command(&self.state, now_ns, cmd)
    }

    fn close(&mut self) {
        self.shared.cmd.store(Command::Release);
        self.shared.stop.store(1, crate::sync::Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl crate::device::VendorDevice for HaplyDevice {
    fn bridge_counts(&self) -> Option<crate::device::BridgeCounts> {
        let s = &self.shared.stats;
        let n = |a: &crate::sync::AtomicU64| a.load(crate::sync::Ordering::Relaxed);
        Some(crate::device::BridgeCounts {
            received: n(&s.frames) + n(&s.bad_frames),
            refused: n(&s.bad_frames),
            foreign: 0,
            sent_forces: n(&s.forces_sent),
            losses: n(&s.losses),
            reconnects: n(&s.reconnects),
        })
    }
}

impl Drop for HaplyDevice {
    fn drop(&mut self) {
        self.close();
    }
}

/// What `station devices` says of the Haply backend: whether the service answers at
/// `config.url`, and the Inverse3 devices it lists. Connects once and leaves again; commands
/// nothing.
pub fn probe(config: &HaplyConfig) -> ProbeReport {
    let mut report = ProbeReport {
        backend: "haply",
        built_in: true,
        status: String::new(),
        devices: Vec::new(),
    };
    if let Err(e) = config.validate() {
        report.status = format!("device.haply.{e}");
        return report;
    }
    match bridge::connect(&config.target()) {
        Err(e) => report.status = e.to_string(),
        Ok((mut ws, snapshot)) => {
            match wire::list_devices(&snapshot) {
                Err(e) => {
                    report.status = format!(
                        "Haply Inverse Service at {} sent a frame we refuse: {e}",
                        config.url
                    );
                }
                Ok(list) => {
                    report.status = format!(
                        "Haply Inverse Service at {}: {} Inverse3{}",
                        config.url,
                        list.len(),
                        list.iter()
                            .map(|d| {
                                let mut s = format!(" {}", d.device_id);
                                if let Some(h) = &d.handedness {
                                    s.push_str(&format!(" ({h}-handed)"));
                                }
                                s
                            })
                            .collect::<String>()
                    );
                    report.devices = list.iter().map(|d| config.info(&d.device_id)).collect();
                }
            }
            let _ = ws.close(None);
            let _ = ws.flush();
        }
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_config_is_valid_and_each_rule_names_its_field() {
        assert_eq!(HaplyConfig::default().validate(), Ok(()));
        let cases: Vec<(HaplyConfig, &str)> = vec![
            (
                HaplyConfig {
                    url: "http://localhost:10001".into(),
                    ..Default::default()
                },
                "url",
            ),
            (
                HaplyConfig {
                    url: "wss://x:1".into(),
                    ..Default::default()
                },
                "url",
            ),
            (
                HaplyConfig {
                    device_id: Some("04 9D".into()),
                    ..Default::default()
                },
                "device_id",
            ),
            (
                HaplyConfig {
                    rate_hz: f64::NAN,
                    ..Default::default()
                },
                "rate_hz",
            ),
            (
                HaplyConfig {
                    stale_limit_ms: 1.0,
                    ..Default::default()
                },
                "stale_limit_ms",
            ),
            (
                HaplyConfig {
                    io_timeout_ms: 0,
                    ..Default::default()
                },
                "io_timeout_ms",
            ),
            (
                HaplyConfig {
                    max_force_n: -1.0,
                    ..Default::default()
                },
                "max_force_n",
            ),
        ];
        for (c, field) in cases {
            let e = c.validate().expect_err(field);
            assert_eq!(e.field, field, "{e}");
            assert!(!e.rule.is_empty() && !e.value.is_empty(), "{e}");
        }
    }

    #[test]
    fn an_unreachable_service_is_one_clear_error() {
        // Port 1 on loopback: nothing listens there.
        let c = HaplyConfig {
            url: "ws://127.0.0.1:1".into(),
            connect_timeout_ms: 500,
            ..Default::default()
        };
        let e = HaplyDevice::open(&c).expect_err("nothing listens");
        assert!(matches!(e, HaplyOpenError::Unreachable { .. }), "{e}");
        assert!(e.to_string().contains("device.haply.url"), "{e}");
        let p = probe(&c);
        assert!(p.built_in && p.devices.is_empty());
        assert!(p.status.contains("not reachable"), "{}", p.status);
    }
}
