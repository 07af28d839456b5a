//! `station status`: what a running station is doing, read from its control block and rings without
//! touching the loops (no claim, no lock; two snapshots 200 ms apart give the achieved rates).
//!
//! [`StationStatus`] is the one model of it: serialised as is for `--json` (and by `session run`
//! into its report), printed for people by its `Display`.

use std::fmt;
use std::time::{Duration, Instant};

use coop_rt::msg::{ObjectSample, SiteReport, ToolSample, TraceRecord};
use coop_rt::shm::control::{Child, ControlBlock, CounterKey, Health, Ring, RunState};
use coop_rt::shm::station::Names;
use coop_rt::shm::{BlockSegment, RingFill, RingOpenOptions, RingSegment};
use coop_rt::stats::LoopSnapshot;
use coop_rt::sync::Ordering;
use serde::Serialize;

mod device;
mod pipeline;
mod show;

pub use device::{DeviceStatus, FaultsStatus, LastFault};
pub use pipeline::{Hop, HOPS};

/// Everything `station status` shows.
#[derive(Debug, Clone, Serialize)]
pub struct StationStatus {
    /// Session name.
    pub session: String,
    /// Station (site) name.
    pub station: String,
    /// `starting`, `running`, `stopping` or `stopped`.
    pub run_state: String,
    /// The network process is down: the station runs on locally (servo and physics), without the
    /// other sites, while the network is restarted with backoff.
    pub degraded: bool,
    /// One row per child process.
    pub children: Vec<ChildStatus>,
    /// The two real-time loops.
    pub loops: Loops,
    /// Ring fill and drops.
    pub rings: Rings,
    /// The network process.
    pub network: NetworkStatus,
    /// What physics did with the remote reports.
    pub physics: PhysicsStatus,
    /// What the servo displays.
    pub servo: ServoStatus,
    /// The servo's device (none before the servo opened it).
    pub device: Option<DeviceStatus>,
    /// The pipeline's own latency, hop by hop (`pipeline.rs`).
    pub pipeline: Vec<Hop>,
    /// The task as this site shows it, judged live by the servo (none: no task, or the session
    /// has not started).
    pub task: Option<TaskStatus>,
    /// The run state is `running`.
    pub running: bool,
}

/// The task's outcome as the site shows it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskStatus {
    /// `running`, `done` or `failed`.
    pub outcome: &'static str,
    /// When it was done or failed, s from the session's time 0 (none while running).
    pub at_s: Option<f64>,
    /// What failed it: `timeout` or `fail[k]` (none: not failed).
    pub failed_by: Option<String>,
}

impl TaskStatus {
    /// What the control block holds (none: no task, or not started).
    pub fn of(t: &coop_rt::shm::control::TaskShared) -> Option<Self> {
        use coop_rt::shm::control::TaskState;
        let (state, at_s, by) = t.read()?;
        match state {
            TaskState::None => None,
            TaskState::Running => Some(Self {
                outcome: state.name(),
                at_s: None,
                failed_by: None,
            }),
            TaskState::Done | TaskState::Failed => Some(Self {
                outcome: state.name(),
                at_s: Some(at_s),
                failed_by: (state == TaskState::Failed).then(|| match by {
                    0 => "timeout".to_owned(),
                    k => format!("fail[{}]", k - 1),
                }),
            }),
        }
    }
}

/// One child process.
#[derive(Debug, Clone, Serialize)]
pub struct ChildStatus {
    /// servo, physics or network.
    pub name: &'static str,
    /// Its pid (0: not running).
    pub pid: u64,
    /// Its heartbeat counter.
    pub heartbeat: u64,
    /// Restarts so far.
    pub restarts: u64,
    /// `starting`, `up` or `down` (failed since it was last up; being restarted).
    pub health: &'static str,
    /// For how long it has been down, s (none: it is not down).
    pub down_s: Option<f64>,
    /// Why it last failed, as the supervisor saw it (none: it never failed).
    pub last_failure: Option<String>,
    /// Scheduling policy in force.
    pub policy: &'static str,
    /// Priority in force.
    pub priority: u64,
    /// CPUs in force, e.g. `1` or `0,1` (`-`: not known).
    pub cpus: String,
}

/// The servo's and physics' loops.
#[derive(Debug, Clone, Serialize)]
pub struct Loops {
    /// The servo loop.
    pub servo: LoopStatus,
    /// The physics loop.
    pub physics: LoopStatus,
}

/// One loop's figures.
#[derive(Debug, Clone, Serialize)]
pub struct LoopStatus {
    /// Its period, µs.
    pub period_us: f64,
    /// Its achieved rate over the 200 ms between two snapshots, Hz.
    pub rate_hz: f64,
    /// Cycles so far.
    pub cycles: u64,
    /// Deadlines missed so far.
    pub overruns: u64,
    /// Wake-up latency, µs.
    pub wake_us: Quantiles,
    /// Compute time, µs.
    pub compute_us: Quantiles,
}

/// A distribution's landmarks, µs.
#[derive(Debug, Clone, Serialize)]
pub struct Quantiles {
    /// Smallest (wake-up latency only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// Median.
    pub p50: u64,
    /// 99th percentile.
    pub p99: u64,
    /// 99.9th percentile (wake-up latency only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub p999: Option<u64>,
    /// Largest.
    pub max: f64,
}

/// One ring's fill, or why it could not be read.
#[derive(Debug, Clone, Serialize)]
#[serde(untagged)]
pub enum RingStatus {
    /// Read.
    Fill {
        /// Slots in use.
        used: u64,
        /// Slots.
        capacity: u64,
        /// Pushed so far.
        pushed: u64,
    },
    /// Not readable.
    Error {
        /// Why.
        error: String,
    },
}

/// Ring fill and drops.
#[derive(Debug, Clone, Serialize)]
pub struct Rings {
    /// Servo → physics.
    pub tool: RingStatus,
    /// Physics → servo.
    pub object: RingStatus,
    /// Physics → network.
    pub report: RingStatus,
    /// Network → physics.
    pub remote: RingStatus,
    /// Physics → recorder.
    pub trace: RingStatus,
    /// Pushes refused because the ring was full, by ring name.
    pub drops: std::collections::BTreeMap<&'static str, u64>,
}

/// The network process's figures.
#[derive(Debug, Clone, Serialize)]
pub struct NetworkStatus {
    /// Its zenoh id, mode, listen and connect locators.
    pub locators: String,
    /// Reports published.
    pub published: u64,
    /// Other sites' reports handed to physics.
    pub received: u64,
    /// Messages refused, all reasons.
    pub rejected: u64,
    /// Messages refused, by reason.
    pub refused: std::collections::BTreeMap<&'static str, u64>,
    /// `none`, or what is emulated on receive.
    pub emulation: &'static str,
    /// Messages the emulation dropped.
    pub emulated_lost: u64,
    /// States a late joiner got from the session at start.
    pub join_states: u64,
    /// Sites that joined since the network process started.
    pub joins: u64,
    /// Sites that left.
    pub leaves: u64,
    /// Times a site was lost (silent past its limit).
    pub losses: u64,
    /// Times a lost site was heard again.
    pub rejoins: u64,
    /// Times a site's sequence was resynchronised.
    pub resyncs: u64,
    /// States held until their sender's clock offset was known.
    pub held_for_offset: u64,
    /// Every site of the session.
    pub peers: Vec<PeerStatus>,
    /// Station-to-station latency, µs (none before the first sample).
    pub latency_us: Option<Latency>,
    /// The session's time 0, ns (none until known).
    pub epoch_ns: Option<u64>,
    /// What it put on the wire and got from it, by kind: totals, and rates over the status'
    /// window.
    pub traffic: Vec<TrafficStatus>,
    /// That window, s.
    pub traffic_window_s: f64,
}

/// One kind of the network process's traffic (payload, as put and got: a put goes to every
/// subscribed peer, or once to a router).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct TrafficStatus {
    /// `states`, `tracks`, `clock`, `presence` or `live`.
    pub kind: &'static str,
    /// Messages put, in all.
    pub sent_msgs: u64,
    /// Payload bytes put, in all.
    pub sent_bytes: u64,
    /// Messages received, in all.
    pub received_msgs: u64,
    /// Payload bytes received, in all.
    pub received_bytes: u64,
    /// Messages put per second, over the window.
    pub sent_msgs_per_s: f64,
    /// Payload put, kbit/s, over the window.
    pub sent_kbit_s: f64,
    /// Payload received, kbit/s, over the window.
    pub received_kbit_s: f64,
}

impl TrafficStatus {
    /// Each kind's totals now, and its rates since `before` (the totals `dt_s` seconds ago).
    fn of(
        now: &coop_transport::recording::TrafficMsg,
        before: &coop_transport::recording::TrafficMsg,
        dt_s: f64,
    ) -> Vec<Self> {
        use coop_rt::shm::control::{CounterKey, WireKind};
        let rate = |a: u64, b: u64| a.saturating_sub(b) as f64 / dt_s.max(1e-9);
        WireKind::ALL
            .iter()
            .enumerate()
            .map(|(k, kind)| Self {
                kind: kind.name(),
                sent_msgs: now.sent_msgs[k],
                sent_bytes: now.sent_bytes[k],
                received_msgs: now.received_msgs[k],
                received_bytes: now.received_bytes[k],
                sent_msgs_per_s: rate(now.sent_msgs[k], before.sent_msgs[k]),
                sent_kbit_s: rate(now.sent_bytes[k], before.sent_bytes[k]) * 8e-3,
                received_kbit_s: rate(now.received_bytes[k], before.received_bytes[k]) * 8e-3,
            })
            .collect()
    }
}

/// One site as the network process sees it.
#[derive(Debug, Clone, Serialize)]
pub struct PeerStatus {
    /// Site name.
    pub site: String,
    /// Its liveliness token is seen.
    pub present: bool,
    /// Silent past its loss limit (what physics applied of it fades out).
    pub lost: bool,
    /// Its clock minus ours, µs (none before the first exchange).
    pub clock_offset_us: Option<f64>,
    /// The round trip of the exchange the offset came from, µs.
    pub clock_rtt_us: Option<f64>,
}

/// Station-to-station latency.
#[derive(Debug, Clone, Serialize)]
pub struct Latency {
    /// Samples.
    pub count: u64,
    /// Median, µs.
    pub p50: u64,
    /// 99th percentile, µs.
    pub p99: u64,
    /// Largest, µs.
    pub max: u64,
}

impl Latency {
    /// The figures of `h` with its `count` samples (none before the first).
    pub fn of(
        h: &coop_rt::stats::SharedHistogram,
        count: &coop_rt::sync::AtomicU64,
    ) -> Option<Self> {
        let count = count.load(Ordering::Relaxed);
        (count > 0).then(|| {
            let h = h.to_hdr();
            Self {
                count,
                p50: h.value_at_quantile(0.5),
                p99: h.value_at_quantile(0.99),
                max: h.max(),
            }
        })
    }
}

/// Physics' figures.
#[derive(Debug, Clone, Serialize)]
pub struct PhysicsStatus {
    /// Remote reports taken from the ring.
    pub remote_received: u64,
    /// Remote reports that did not convert (a foreign writer of the ring).
    pub remote_rejected: u64,
    /// States adopted.
    pub adoptions: u64,
    /// Adoptions or steps that would have made the copy non-finite (it kept its state).
    pub nonfinite_kept: u64,
    /// In a world of several objects, per object (empty in a world of one).
    pub objects: Vec<ObjectStatus>,
    /// Rollback and tool-track figures, if the method exchanges tools (it stepped on the grid).
    pub rollback: Option<coop_rt::shm::rollback::RollbackFigures>,
}

/// One object of a world of several, as the station sees it.
#[derive(Debug, Clone, Serialize, PartialEq, Eq)]
pub struct ObjectStatus {
    /// Its name (its index until [`StationStatus::name_objects`] names it).
    pub name: String,
    /// States of it adopted (a confirmed world adopted whole counts for each object).
    pub adoptions: u64,
    /// Received states of it refused as implausible, or as another object than their key names.
    pub refused: u64,
}

/// The servo's figures.
#[derive(Debug, Clone, Serialize)]
pub struct ServoStatus {
    /// The commanded force, N.
    pub command_n: f64,
    /// The display scale: 1 fresh, 0 stale.
    pub display_scale: f64,
    /// The device safety limit that acted last, if any.
    pub safety: Option<SafetyStatus>,
    /// What the display stages did.
    pub display: DisplayStatus,
}

/// The servo's display continuity and passivity figures (`coop_model::display`).
#[derive(Debug, Clone, Serialize)]
pub struct DisplayStatus {
    /// Corrections of the copy absorbed into the displayed object.
    pub corrections: u64,
    /// Servo ticks at which the step limiter held the displayed force back.
    pub ticks_limited: u64,
    /// The largest displayed-force step per tick, N.
    pub max_step_n: f64,
    /// The largest step beyond the displayed object's own contact change, N.
    pub max_correction_step_n: f64,
    /// Servo ticks at which the passivity controller added damping.
    pub ticks_damped: u64,
    /// The largest damping it added, N·s/m.
    pub max_damping_n_s_per_m: f64,
    /// The energy the display's deviation has injected into the user, J (≤ 0: passive).
    pub energy_j: f64,
    /// The largest it ever was, J.
    pub max_energy_j: f64,
}

impl DisplayStatus {
    fn of(d: &coop_rt::shm::control::DisplayShared) -> Self {
        let f = ControlBlock::load_f64;
        Self {
            corrections: d.corrections.load(Ordering::Relaxed),
            ticks_limited: d.ticks_limited.load(Ordering::Relaxed),
            max_step_n: f(&d.max_step_n),
            max_correction_step_n: f(&d.max_correction_step_n),
            ticks_damped: d.ticks_damped.load(Ordering::Relaxed),
            max_damping_n_s_per_m: f(&d.max_damping_n_s_per_m),
            energy_j: f(&d.energy_j),
            max_energy_j: f(&d.max_energy_j),
        }
    }
}

impl std::fmt::Display for DisplayStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "display: {} corrections blended; step limiter held {} ticks (largest step {:.3} N, {:.3} N beyond the contact's own); passivity damped {} ticks (up to {:.2} N·s/m), display energy {:.3} mJ (peak {:.3} mJ)",
            self.corrections,
            self.ticks_limited,
            self.max_step_n,
            self.max_correction_step_n,
            self.ticks_damped,
            self.max_damping_n_s_per_m,
            self.energy_j * 1e3,
            self.max_energy_j * 1e3
        )
    }
}

/// The device safety limit that acted last (see `coop_rt::device::safety`).
#[derive(Debug, Clone, Serialize)]
pub struct SafetyStatus {
    /// Its name, as in `[device.safety]` (`max_force_n`, `watchdog_ms`, …).
    pub limit: &'static str,
    /// Whether it releases the device (velocity, watchdog, fault) rather than clamping a value.
    pub releases: bool,
    /// When it acted last, CLOCK_MONOTONIC ns.
    pub at_ns: u64,
    /// How long ago, s.
    pub ago_s: f64,
    /// Episodes of any limit acting so far.
    pub episodes: u64,
}

fn policy_name(n: u64) -> &'static str {
    match n {
        0 => "SCHED_OTHER",
        1 => "SCHED_FIFO",
        2 => "SCHED_RR",
        _ => "other",
    }
}

fn cpus(mask: u64) -> String {
    let v: Vec<String> = (0..64)
        .filter(|c| mask & (1 << c) != 0)
        .map(|c| c.to_string())
        .collect();
    if v.is_empty() {
        "-".into()
    } else {
        v.join(",")
    }
}

impl LoopStatus {
    fn of(s: &LoopSnapshot, rate_hz: f64) -> Self {
        let q = |p: f64| s.wake_us.value_at_quantile(p);
        Self {
            period_us: s.period_ns as f64 / 1e3,
            rate_hz,
            cycles: s.cycles,
            overruns: s.overruns,
            wake_us: Quantiles {
                min: Some(s.wake_min_ns as f64 / 1e3),
                p50: q(0.5),
                p99: q(0.99),
                p999: Some(q(0.999)),
                max: s.wake_max_ns as f64 / 1e3,
            },
            compute_us: Quantiles {
                min: None,
                p50: s.compute_us.value_at_quantile(0.5),
                p99: s.compute_us.value_at_quantile(0.99),
                p999: None,
                max: s.compute_max_ns as f64 / 1e3,
            },
        }
    }
}

impl RingStatus {
    fn of<E: fmt::Display>(r: Result<RingFill, E>) -> Self {
        match r {
            Ok(f) => RingStatus::Fill {
                used: f.used,
                capacity: f.capacity,
                pushed: f.pushed,
            },
            Err(e) => RingStatus::Error {
                error: e.to_string(),
            },
        }
    }
}

impl fmt::Display for RingStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RingStatus::Fill { used, capacity, .. } => write!(f, "{used}/{capacity}"),
            RingStatus::Error { .. } => f.write_str("?"),
        }
    }
}

/// Why a station's status cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum StatusError {
    /// The session or station name cannot make segment names.
    #[error(transparent)]
    Name(#[from] coop_rt::shm::NameError),
    /// The station's control block does not open: no such station, or a stale one.
    #[error("station {station} of session {session}")]
    Open {
        /// The station.
        station: String,
        /// Its session.
        session: String,
        /// Why.
        #[source]
        error: coop_rt::shm::OpenError,
    },
}

fn open(session: &str, station: &str) -> Result<(Names, BlockSegment<ControlBlock>), StatusError> {
    let names = Names::of(session, station)?;
    let ctl = BlockSegment::<ControlBlock>::open(&names.control, Duration::from_millis(500))
        .map_err(|error| StatusError::Open {
            station: station.to_owned(),
            session: session.to_owned(),
            error,
        })?;
    Ok((names, ctl))
}

/// A running station's rollback figures as its physics last published them (cheap: no window
/// of loop rates, no ring opened; `None` for a method that does not roll back). For a caller
/// that must act at a point of the session, which a full [`read`] (a 200 ms window and more)
/// would reach late on a loaded machine.
///
/// # Errors
/// No such station.
pub fn rollback_figures(
    session: &str,
    station: &str,
) -> Result<Option<coop_rt::shm::rollback::RollbackFigures>, StatusError> {
    let (_, ctl) = open(session, station)?;
    Ok(ctl.physics.rollback.figures())
}

/// The overrun counters of a running station's servo and physics loops (cheap: no snapshot).
///
/// # Errors
/// No such station.
pub fn overruns(session: &str, station: &str) -> Result<[u64; 2], StatusError> {
    let (_, ctl) = open(session, station)?;
    Ok([
        ctl.servo.stats.overruns.load(Ordering::Relaxed),
        ctl.physics.stats.overruns.load(Ordering::Relaxed),
    ])
}

/// Reads the status of station `station` in `session`; `sites` names the session's sites in order
/// (for the per-peer rows; empty: none).
///
/// # Errors
/// No such station, or its segments fail validation (stale: run `station clean`).
pub fn read(session: &str, station: &str, sites: &[String]) -> Result<StationStatus, StatusError> {
    let (names, ctl) = open(session, station)?;
    let snap = || (ctl.servo.stats.snapshot(), ctl.physics.stats.snapshot());
    let traffic0 = coop_transport::recording::TrafficMsg::of(&ctl.network.traffic);
    let ((s0, p0), t0) = (snap(), Instant::now());
    std::thread::sleep(Duration::from_millis(200));
    let (s1, p1) = snap();
    let dt = t0.elapsed().as_secs_f64();
    let rate = |a: &LoopSnapshot, b: &LoopSnapshot| (b.cycles.saturating_sub(a.cycles)) as f64 / dt;
    let opts = RingOpenOptions {
        capacity: None,
        ready_timeout: Duration::from_millis(500),
    };
    let children = Child::ALL
        .iter()
        .map(|&c| {
            let slot = ctl.child(c);
            let load = |a: &coop_rt::sync::AtomicU64| a.load(Ordering::Relaxed);
            let health = slot.health();
            let down_since = load(&slot.down_since_ns);
            let last_failure = slot.last_failure();
            ChildStatus {
                name: c.name(),
                pid: load(&slot.pid),
                heartbeat: load(&slot.heartbeat),
                restarts: load(&slot.restarts),
                health: health.name(),
                down_s: (health == Health::Down && down_since > 0).then(|| {
                    coop_rt::timer::monotonic_ns().saturating_sub(down_since) as f64 / 1e9
                }),
                last_failure: (!last_failure.is_empty()).then_some(last_failure),
                policy: policy_name(load(&slot.policy)),
                priority: load(&slot.priority),
                cpus: cpus(load(&slot.cpus)),
            }
        })
        .collect();
    let run_state = ctl.run_state();
    Ok(StationStatus {
        session: session.to_owned(),
        station: station.to_owned(),
        run_state: format!("{run_state:?}").to_lowercase(),
        degraded: ctl.child(Child::Network).health() == Health::Down,
        children,
        loops: Loops {
            servo: LoopStatus::of(&s1, rate(&s0, &s1)),
            physics: LoopStatus::of(&p1, rate(&p0, &p1)),
        },
        rings: Rings {
            tool: RingStatus::of(RingSegment::<ToolSample>::inspect(&names.tool, &opts)),
            object: RingStatus::of(RingSegment::<ObjectSample>::inspect(&names.object, &opts)),
            report: RingStatus::of(RingSegment::<SiteReport>::inspect(&names.report, &opts)),
            remote: RingStatus::of(RingSegment::<SiteReport>::inspect(&names.remote, &opts)),
            trace: RingStatus::of(RingSegment::<TraceRecord>::inspect(&names.trace, &opts)),
            drops: Ring::ALL
                .iter()
                .map(|&r| (r.name(), ctl.ring_drops(r)))
                .collect(),
        },
        network: NetworkStatus::of(&ctl, sites, (&traffic0, dt)),
        physics: PhysicsStatus {
            remote_received: ctl.physics.received.load(Ordering::Relaxed),
            remote_rejected: ctl.physics.rejected.load(Ordering::Relaxed),
            adoptions: ctl.physics.adoptions.load(Ordering::Relaxed),
            nonfinite_kept: ctl.physics.nonfinite_kept.load(Ordering::Relaxed),
            objects: ObjectStatus::of(&ctl),
            rollback: ctl.physics.rollback.figures(),
        },
        servo: ServoStatus {
            command_n: ControlBlock::load_f64(&ctl.servo.command_n),
            display_scale: ControlBlock::load_f64(&ctl.servo.scale),
            safety: coop_rt::device::safety::Limit::from_code(
                ctl.servo.safety_limit.load(Ordering::Relaxed),
            )
            .map(|l| {
                let at_ns = ctl.servo.safety_at_ns.load(Ordering::Relaxed);
                SafetyStatus {
                    limit: l.name(),
                    releases: l.releases(),
                    at_ns,
                    ago_s: coop_rt::timer::monotonic_ns().saturating_sub(at_ns) as f64 / 1e9,
                    episodes: ctl.servo.safety_episodes.load(Ordering::Relaxed),
                }
            }),
            display: DisplayStatus::of(&ctl.servo.display),
        },
        device: DeviceStatus::of(&ctl.device),
        pipeline: pipeline::hops(&ctl),
        task: TaskStatus::of(&ctl.task),
        running: run_state == RunState::Running,
    })
}

impl ObjectStatus {
    /// Per object of a world of several (physics says how many), by index.
    fn of(ctl: &ControlBlock) -> Vec<Self> {
        let load = |a: &coop_rt::sync::AtomicU64| a.load(Ordering::Relaxed);
        let n = usize::try_from(load(&ctl.physics.objects))
            .unwrap_or(0)
            .min(coop_model::world::MAX_OBJECTS);
        if n < 2 {
            return Vec::new();
        }
        (0..n)
            .map(|k| Self {
                name: k.to_string(),
                adoptions: load(&ctl.physics.adoptions_by_object[k]),
                refused: load(&ctl.network.refused_by_object[k]),
            })
            .collect()
    }
}

impl StationStatus {
    /// Names the world's objects after `scenario`'s (its `[[object]]` names, in order).
    pub fn name_objects(&mut self, scenario: &coop_model::scenario::Scenario) {
        for (k, o) in self.physics.objects.iter_mut().enumerate() {
            if k < scenario.objects.len() {
                scenario.object_name(k).clone_into(&mut o.name);
            }
        }
    }
}

impl NetworkStatus {
    fn of(
        ctl: &ControlBlock,
        sites: &[String],
        traffic_before: (&coop_transport::recording::TrafficMsg, f64),
    ) -> Self {
        let n = &ctl.network;
        let load = |a: &coop_rt::sync::AtomicU64| a.load(Ordering::Relaxed);
        let present = load(&n.peers_present);
        let lost = load(&n.peers_lost);
        let peers = sites
            .iter()
            .enumerate()
            .map(|(j, name)| {
                let rtt = load(&n.clock_rtt_ns[j]);
                PeerStatus {
                    site: name.clone(),
                    present: present & (1 << j) != 0,
                    lost: lost & (1 << j) != 0,
                    clock_offset_us: (rtt > 0)
                        .then(|| load(&n.clock_offset_ns[j]) as i64 as f64 / 1e3),
                    clock_rtt_us: (rtt > 0).then(|| rtt as f64 / 1e3),
                }
            })
            .collect();
        let latency_us = Latency::of(&n.latency, &n.latency_count);
        Self {
            locators: ctl.locators(),
            published: load(&n.published),
            received: load(&n.received),
            rejected: n.refused.total(),
            refused: n.refused.all().map(|(k, v)| (k.name(), v)).collect(),
            emulation: if load(&n.emulated) == 1 {
                "EMULATED (delay, jitter, loss on receive)"
            } else {
                "none"
            },
            emulated_lost: load(&n.emulated_lost),
            join_states: load(&n.join_states),
            joins: load(&n.peer_joins),
            leaves: load(&n.peer_leaves),
            losses: load(&n.peer_losses),
            rejoins: load(&n.peer_rejoins),
            resyncs: load(&n.resyncs),
            held_for_offset: load(&n.held_for_offset),
            peers,
            latency_us,
            epoch_ns: ctl.epoch(),
            traffic: TrafficStatus::of(
                &coop_transport::recording::TrafficMsg::of(&n.traffic),
                traffic_before.0,
                traffic_before.1,
            ),
            traffic_window_s: traffic_before.1,
        }
    }
}

impl StationStatus {
    /// As JSON (what `--json` prints).
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or(serde_json::Value::Null)
    }
}
