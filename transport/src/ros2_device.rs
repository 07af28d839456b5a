//! `device = "ros2"`: any haptic device whose ROS 2 driver publishes its end effector's pose as a
//! `geometry_msgs/msg/PoseStamped` and takes a force command as a `geometry_msgs/msg/WrenchStamped`
//! (Haply's `haply_ros2_interface`, the Geomagic Touch and Falcon drivers, `ros_force_dimension`,
//! with a remap where their names differ), through `rmw_zenoh`'s conventions on a zenoh session of
//! its own (a peer of the ROS 2 graph's router), with no ROS installed.
//!
//! The servo never touches zenoh. [`Ros2Device::open`] joins the graph (a node with one
//! subscription and one publisher, declared by liveliness tokens), waits for the driver's first
//! pose, and starts a bridge thread that owns the zenoh subscriber and publisher:
//!
//! - driver → servo: each pose, decoded and checked, as a [`Sample`] stamped on arrival, through
//!   an rtrb SPSC ring (a pose that is not a finite `PoseStamped` is a
//!   [`DeviceFault::BadValue`]);
//! - servo → driver: the newest command through a [`CommandSlot`] (seqlock), put as a
//!   `WrenchStamped` in the driver's frame each time the servo writes it (a release is a zero
//!   wrench), at most at the driver's rate; a servo that stops writing for `stale_limit_ms`
//!   leaves the driver a zero wrench.
//!
//! The driver is the publisher of the first pose (its GID, from `rmw_zenoh`'s attachment): poses
//! from any other (a second driver, a bag played on the same topic) are refused and counted
//! (`station status` shows them in its device section).
//!
//! A driver that goes silent leaves the newest sample ageing: past `stale_limit_ms`, `sample` and
//! `command` say [`DeviceFault::Disconnected`] and the safety layer releases the device. Closing
//! puts a zero wrench.

use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use coop_model::body::Vec3;
use coop_rt::device::{
    BridgedState, CartesianDevice, Command, CommandSlot, ConfigError, DeviceFault, DeviceInfo,
    ProbeReport, Sample,
};
use coop_rt::sync::{AtomicU64, Ordering};
use coop_rt::timer::monotonic_ns;
use nalgebra::{Quaternion, UnitQuaternion};
use serde::{Deserialize, Serialize};
use zenoh::handlers::{RingChannel, RingChannelHandler};
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::{CongestionControl, Priority};
use zenoh::sample::Sample as ZSample;
use zenoh::{Session, Wait};

use crate::network::{Mode, NetworkConfig};
use crate::ros2::cdr::{Header, PoseStamped, WrenchStamped};
use crate::ros2::graph::{self, Attachment, Kind, Node, Qos};
use crate::ros2::MAX_DOMAIN_ID;

/// The station config's `[device.ros2]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2DeviceConfig {
    /// The driver's end-effector pose (`geometry_msgs/msg/PoseStamped`), a fully qualified topic.
    pub pose_topic: String,
    /// Where the force command goes (`geometry_msgs/msg/WrenchStamped`, the pose's frame).
    pub wrench_topic: String,
    /// The ROS domain.
    pub domain_id: u32,
    /// Zenoh locators of the ROS 2 graph's router (where `rmw_zenohd` listens), or the driver's.
    pub connect: Vec<String>,
    /// How often the driver publishes its pose, Hz (the device's native rate).
    pub rate_hz: f64,
    /// A pose older than this is stale: the device is released.
    pub stale_limit_ms: f64,
    /// How long to wait at start for the driver's first pose, ms.
    pub first_pose_timeout_ms: u64,
    /// The largest force to report as the device's maximum, N (conservative: set it to the device's
    /// rating; the safety layer clamps to the smaller of this and the station's).
    pub max_force_n: f64,
    /// The stiffest contact to report as stable, N/m.
    pub max_stiffness_n_per_m: f64,
    /// The largest damping to report as stable, N·s/m (`max_damping_ns_per_m`, its old name,
    /// is read too).
    #[serde(alias = "max_damping_ns_per_m")]
    pub max_damping_n_s_per_m: f64,
    /// The radius of the workspace sphere to report, m.
    pub workspace_radius_m: f64,
}

/// Where `rmw_zenohd` listens by default.
pub const DEFAULT_ROUTER: &str = "tcp/127.0.0.1:7447";

impl Default for Ros2DeviceConfig {
    fn default() -> Self {
        Self {
            pose_topic: "/haptic/pose".into(),
            wrench_topic: "/haptic/wrench_command".into(),
            domain_id: 0,
            connect: vec![DEFAULT_ROUTER.into()],
            rate_hz: 1000.0,
            stale_limit_ms: 20.0,
            first_pose_timeout_ms: 5000,
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

/// Whether `t` is a fully qualified ROS 2 topic name: `/` then segments of letters, digits and
/// underscores, none empty or starting with a digit.
fn is_topic(t: &str) -> bool {
    t.strip_prefix('/').is_some_and(|rest| {
        rest.split('/').all(|seg| {
            !seg.is_empty()
                && !seg.starts_with(|c: char| c.is_ascii_digit())
                && seg.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        })
    })
}

impl Ros2DeviceConfig {
    /// Checks every field (positive containment, so NaN fails).
    ///
    /// # Errors
    /// The first field that breaks its rule, with its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (field, t) in [
            ("pose_topic", &self.pose_topic),
            ("wrench_topic", &self.wrench_topic),
        ] {
            if !is_topic(t) {
                return Err(bad(
                    field,
                    format!("{t:?}"),
                    "must be a fully qualified ROS 2 topic: /a/b, segments of letters, digits and _, none starting with a digit",
                ));
            }
        }
        if self.pose_topic == self.wrench_topic {
            return Err(bad(
                "wrench_topic",
                format!("{:?}", self.wrench_topic),
                "must differ from pose_topic",
            ));
        }
        if self.domain_id > MAX_DOMAIN_ID {
            return Err(bad(
                "domain_id",
                self.domain_id,
                &format!("must be 0..={MAX_DOMAIN_ID} (ROS 2's range)"),
            ));
        }
        if self.connect.is_empty() {
            return Err(bad(
                "connect",
                "[]",
                &format!("must name the ROS 2 graph's router, e.g. [\"{DEFAULT_ROUTER}\"]"),
            ));
        }
        for l in &self.connect {
            if !(l.starts_with("tcp/") || l.starts_with("tls/")) || l.len() < 6 {
                return Err(bad(
                    "connect",
                    format!("{l:?}"),
                    "each must be a zenoh locator tcp/<host>:<port> or tls/<host>:<port>",
                ));
            }
        }
        coop_rt::device::check_bridged(self.rate_hz, self.stale_limit_ms, self.maxima())?;
        if !(1..=60_000).contains(&self.first_pose_timeout_ms) {
            return Err(bad(
                "first_pose_timeout_ms",
                self.first_pose_timeout_ms,
                "must be in 1..=60000 ms",
            ));
        }
        Ok(())
    }

    /// The maxima the device reports, as [`coop_rt::device::check_bridged`] takes them.
    fn maxima(&self) -> [f64; 4] {
        [
            self.max_force_n,
            self.max_stiffness_n_per_m,
            self.max_damping_n_s_per_m,
            self.workspace_radius_m,
        ]
    }

    fn info(&self) -> DeviceInfo {
        DeviceInfo {
            backend: "ros2",
            model: format!("ROS 2 driver on {}", self.pose_topic),
            serial: None,
            dof: 3,
            max_force_n: self.max_force_n,
            max_stiffness_n_per_m: self.max_stiffness_n_per_m,
            max_damping_n_s_per_m: self.max_damping_n_s_per_m,
            workspace_radius_m: self.workspace_radius_m,
            native_rate_hz: self.rate_hz,
            senses_force: false,
        }
    }

    fn where_(&self) -> String {
        format!(
            "{} in ROS domain {} via [{}]",
            self.pose_topic,
            self.domain_id,
            self.connect.join(", ")
        )
    }
}

/// Why [`Ros2Device::open`] failed. Nothing was started.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Ros2OpenError {
    /// The config breaks a rule.
    #[error("device.ros2.{0}")]
    Config(ConfigError),
    /// Zenoh would not open or declare.
    #[error("device.ros2: joining the ROS 2 graph: {0}")]
    Zenoh(String),
    /// No pose came in time.
    #[error("device.ros2: no geometry_msgs/msg/PoseStamped on {what} within {ms} ms (device.ros2.first_pose_timeout_ms): is the driver running, and the router reachable (device.ros2.connect)?")]
    NoPose {
        /// Topic, domain, locators.
        what: String,
        /// How long we waited.
        ms: u64,
    },
    /// The first pose was not one.
    #[error("device.ros2: the first message on {what} is not a finite geometry_msgs/msg/PoseStamped: {reason}")]
    BadPose {
        /// Topic, domain, locators.
        what: String,
        /// Why.
        reason: String,
    },
    /// The bridge thread did not start.
    #[error("starting the ROS 2 bridge thread: {0}")]
    Thread(String),
}

/// What the bridge tells the servo.
#[derive(Debug, Clone, Copy, PartialEq)]
enum BridgeMsg {
    /// A pose, as a sample stamped on arrival.
    Pose(Sample),
    /// A message that is not a pose.
    Fault(DeviceFault),
}

/// Counters both halves, the station and the benchmark read.
#[derive(Debug, Default)]
pub struct Ros2DeviceStats {
    /// Poses taken.
    pub poses: AtomicU64,
    /// Messages refused (not a finite `PoseStamped`).
    pub bad_poses: AtomicU64,
    /// Poses refused for coming from another publisher than the first pose's (a second driver, a
    /// bag played on the same topic).
    pub foreign_poses: AtomicU64,
    /// Wrenches put.
    pub wrenches: AtomicU64,
    /// Wrenches put that were not zero.
    pub forces: AtomicU64,
}

/// What both halves share.
#[derive(Debug, Default)]
struct Shared {
    cmd: CommandSlot,
    stop: AtomicU64,
    stats: Ros2DeviceStats,
}

/// Sample messages the ring holds: at 1 kHz, a quarter second of a servo that does not read.
const RING_SLOTS: usize = 256;

/// A device through its ROS 2 driver, servo side.
#[derive(Debug)]
pub struct Ros2Device {
    info: DeviceInfo,
    rx: rtrb::Consumer<BridgeMsg>,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    state: BridgedState,
}

/// The bridge's half: the zenoh session and its declarations.
struct Bridge {
    session: Session,
    _tokens: Vec<LivelinessToken>,
    poses: Subscriber<RingChannelHandler<ZSample>>,
    wrench: Publisher<'static>,
    gid: [u8; 16],
    /// The driver's GID (from its first pose's attachment): poses of any other are refused.
    driver: Option<[u8; 16]>,
    frame_id: String,
    period: Duration,
    stale_limit: Duration,
    shared: Arc<Shared>,
    tx: rtrb::Producer<BridgeMsg>,
    last: Option<(Sample, i128)>,
}

/// The longest gap between two poses a velocity is taken over, ns: beyond it the hand may have done
/// anything in between, and the velocity is not known (zero).
const VELOCITY_GAP_NS: i128 = 100_000_000;

/// A pose as a device sample (device frame), stamped `now_ns` (its arrival), its velocity from the
/// previous pose: over the stamps' interval where the driver's stamps advance by a plausible
/// amount (at least a tenth of a millisecond, at most [`VELOCITY_GAP_NS`]), else over the arrivals'
/// (a driver that leaves its stamps at 0, or repeats them).
fn to_sample(p: &PoseStamped, now_ns: u64, previous: Option<&(Sample, i128)>) -> (Sample, i128) {
    let stamp = i128::from(p.header.stamp.sec) * 1_000_000_000 + i128::from(p.header.stamp.nanosec);
    let position = Vec3::from(p.position);
    let [x, y, z, w] = p.orientation;
    let q = Quaternion::new(w, x, y, z);
    // A driver that does not sense orientation publishes zeros: no orientation, not a NaN.
    let orientation = ((q.norm() - 1.0).abs() < 1e-3).then(|| UnitQuaternion::from_quaternion(q));
    let plausible = |dt: i128| (100_000..=VELOCITY_GAP_NS).contains(&dt);
    let velocity = match previous {
        Some((s, t)) if plausible(stamp - t) => {
            (position - s.position_m) / ((stamp - t) as f64 * 1e-9)
        }
        Some((s, _)) if plausible(i128::from(now_ns) - i128::from(s.t_ns)) => {
            (position - s.position_m) / ((now_ns - s.t_ns) as f64 * 1e-9)
        }
        // The same instant (a burst), or too long ago to say.
        Some((s, _)) if now_ns.saturating_sub(s.t_ns) < 100_000 => s.velocity_m_s,
        _ => Vec3::zeros(),
    };
    (
        Sample {
            t_ns: now_ns,
            position_m: position,
            velocity_m_s: velocity,
            orientation,
            buttons: 0,
            force_sensed_n: None,
        },
        stamp,
    )
}

impl Ros2Device {
    /// Joins the ROS 2 graph, waits for the driver's first pose (its publisher is the driver from
    /// then on), and starts the bridge. Until the servo commands, the driver is sent nothing.
    ///
    /// # Errors
    /// A bad config, zenoh refusing, or no pose from the driver in time.
    pub fn open(config: &Ros2DeviceConfig) -> Result<Self, Ros2OpenError> {
        config.validate().map_err(Ros2OpenError::Config)?;
        // Zenoh's threads are made by whichever thread opens the first session and inherit its
        // policy and affinity: opened from a servo thread already under SCHED_FIFO, they would
        // compete with it. Join the graph from an ordinary thread.
        let (session, tokens, poses, wrench, (pose, driver)) = std::thread::scope(|s| {
            s.spawn(|| {
                coop_rt::sched::make_ordinary();
                join(config)
            })
            .join()
            .unwrap_or_else(|_| Err(Ros2OpenError::Thread("joining the graph panicked".into())))
        })?;
        let (newest, stamp) = to_sample(&pose, monotonic_ns(), None);
        let (tx, rx) = rtrb::RingBuffer::new(RING_SLOTS);
        let shared = Arc::new(Shared::default());
        shared.stats.poses.fetch_add(1, Ordering::Relaxed);
        let b = Bridge {
            gid: graph::gid(&wrench_token(&device_node(config, &session), config)),
            session,
            _tokens: tokens,
            poses,
            wrench,
            driver,
            frame_id: pose.header.frame_id.clone(),
            period: Duration::from_secs_f64(1.0 / config.rate_hz),
            stale_limit: Duration::from_secs_f64(config.stale_limit_ms * 1e-3),
            shared: Arc::clone(&shared),
            tx,
            last: Some((newest, stamp)),
        };
        let thread = std::thread::Builder::new()
            .name("ros2-bridge".into())
            .spawn(move || b.run())
            .map_err(|e| Ros2OpenError::Thread(e.to_string()))?;
        Ok(Self {
            info: config.info(),
            rx,
            shared,
            thread: Some(thread),
            state: BridgedState::new(newest, (config.stale_limit_ms * 1e6) as u64),
        })
    }

    /// The bridge's counters.
    pub fn stats(&self) -> &Ros2DeviceStats {
        &self.shared.stats
    }

    /// The newest sample the bridge delivered, fresh or not.
    pub fn last_sample(&self) -> Sample {
        self.state.newest()
    }

    fn drain(&mut self) {
        while let Ok(m) = self.rx.pop() {
            match m {
                BridgeMsg::Pose(s) => self.state.take(s),
                BridgeMsg::Fault(f) => self.state.fail(f),
            }
        }
    }
}

impl CartesianDevice for Ros2Device {
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
        self.shared.stop.store(1, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl coop_rt::device::VendorDevice for Ros2Device {
    fn bridge_counts(&self) -> Option<coop_rt::device::BridgeCounts> {
        let s = &self.shared.stats;
        let n = |a: &AtomicU64| a.load(Ordering::Relaxed);
        Some(coop_rt::device::BridgeCounts {
            received: n(&s.poses) + n(&s.bad_poses) + n(&s.foreign_poses),
            refused: n(&s.bad_poses),
            foreign: n(&s.foreign_poses),
            sent_forces: n(&s.forces),
            losses: 0,
            reconnects: 0,
        })
    }
}

impl Drop for Ros2Device {
    fn drop(&mut self) {
        self.close();
    }
}

impl Bridge {
    /// Until stopped: each pose to the servo, each new command to the driver, and a release
    /// when the servo stops commanding.
    fn run(mut self) {
        use std::time::Instant;
        // Started from the servo's thread, it would inherit its SCHED_FIFO and CPU.
        coop_rt::sched::make_ordinary();
        // Nothing is sent until the servo commands: the write count at start is not ours.
        let mut seen = self.shared.cmd.load().0;
        let mut last_write = Instant::now();
        let mut last_put: Option<Instant> = None;
        // What the driver displays now, as far as we told it: nothing until we put.
        let mut displaying: Option<Command> = None;
        while self.shared.stop.load(Ordering::Acquire) == 0 {
            match self.poses.recv_timeout(self.period) {
                Ok(Some(z)) => {
                    self.take(&z);
                    // Everything that queued meanwhile, in order: the newest pose is the last.
                    while let Ok(Some(z)) = self.poses.try_recv() {
                        self.take(&z);
                    }
                }
                Ok(None) => {}
                // The session is closing.
                Err(_) => break,
            }
            let (n, cmd) = self.shared.cmd.load();
            if n != seen {
                seen = n;
                last_write = Instant::now();
                if last_put.is_none_or(|t| t.elapsed() >= self.period) {
                    last_put = Some(Instant::now());
                    self.put(cmd, false);
                    displaying = Some(cmd);
                }
            } else if last_write.elapsed() > self.stale_limit
                && matches!(displaying, Some(Command::Force(_)))
            {
                // The servo stopped commanding (stalled, or gone): no force it no longer vouches
                // for stays on the hand.
                self.put(Command::Release, true);
                displaying = Some(Command::Release);
            }
        }
        // Whatever the driver was displaying, it displays nothing now; sent reliably (the
        // session closes next). A driver never commanded is not touched (a probe, say).
        if displaying.is_some() {
            self.put(Command::Release, true);
        }
        let _ = self.session.close().wait();
    }

    /// A driver's message: a pose for the servo, or a fault; another publisher's is refused.
    fn take(&mut self, z: &ZSample) {
        if let Some(driver) = self.driver {
            let from = z
                .attachment()
                .and_then(|a| Attachment::decode(&a.to_bytes()))
                .map(|a| a.gid);
            if from != Some(driver) {
                self.shared
                    .stats
                    .foreign_poses
                    .fetch_add(1, Ordering::Relaxed);
                return;
            }
        }
        let msg = match PoseStamped::decode(&z.payload().to_bytes()) {
            Ok(p) => {
                let (s, stamp) = to_sample(&p, monotonic_ns(), self.last.as_ref());
                self.last = Some((s, stamp));
                self.shared.stats.poses.fetch_add(1, Ordering::Relaxed);
                BridgeMsg::Pose(s)
            }
            Err(_) => {
                self.shared.stats.bad_poses.fetch_add(1, Ordering::Relaxed);
                BridgeMsg::Fault(DeviceFault::BadValue { what: "pose" })
            }
        };
        // A full ring is a servo that does not read: the pose is lost, the next one replaces it.
        let _ = self.tx.push(msg);
    }

    /// Puts `cmd` as a wrench in the driver's frame; `reliably`: waiting for room rather than
    /// dropping it under congestion (a release that must not be lost).
    fn put(&mut self, cmd: Command, reliably: bool) {
        let force = match cmd {
            Command::Force(f) => [f.x, f.y, f.z],
            Command::Release => [0.0; 3],
        };
        let offset = crate::ros2::wall_minus_monotonic_ns();
        let now = monotonic_ns();
        let m = WrenchStamped {
            header: Header {
                stamp: crate::ros2::stamp(now, offset),
                frame_id: self.frame_id.clone(),
            },
            force,
            torque: [0.0; 3],
        };
        let seq = self.shared.stats.wrenches.fetch_add(1, Ordering::Relaxed) + 1;
        if force.iter().any(|&f| f != 0.0) {
            self.shared.stats.forces.fetch_add(1, Ordering::Relaxed);
        }
        let attachment = Attachment {
            seq: i64::try_from(seq).unwrap_or(i64::MAX),
            source_ns: crate::ros2::wall_ns(now, offset),
            gid: self.gid,
        };
        let (bytes, attachment) = (m.encode(), attachment.encode().to_vec());
        // A put that fails is one command the driver misses; the next replaces it.
        let _ = if reliably {
            // The publisher drops under congestion; this one waits for room, on the same key.
            self.session
                .put(self.wrench.key_expr(), bytes)
                .congestion_control(CongestionControl::Block)
                .priority(Priority::InteractiveHigh)
                .express(true)
                .attachment(attachment)
                .wait()
        } else {
            self.wrench.put(bytes).attachment(attachment).wait()
        };
    }
}

/// The bridge's zenoh declarations, and the driver's first pose.
type Joined = (
    Session,
    Vec<LivelinessToken>,
    Subscriber<RingChannelHandler<ZSample>>,
    Publisher<'static>,
    (PoseStamped, Option<[u8; 16]>),
);

/// The bridge's node in the graph of `session`.
fn device_node(config: &Ros2DeviceConfig, session: &Session) -> Node {
    Node {
        domain: config.domain_id,
        zid: session.zid().to_string(),
        id: 0,
        namespace: "/".into(),
        name: "coop_haptics_device".into(),
    }
}

/// The liveliness token of the bridge's wrench publisher (its GID is this token's hash).
fn wrench_token(node: &Node, config: &Ros2DeviceConfig) -> String {
    node.endpoint_token(
        2,
        Kind::Publisher,
        &config.wrench_topic,
        &graph::WRENCH_STAMPED,
        Qos::STREAM,
    )
}

/// Joins the ROS 2 graph as a node with one subscription (the pose) and one publisher (the
/// wrench), and waits for the driver's first pose.
fn join(config: &Ros2DeviceConfig) -> Result<Joined, Ros2OpenError> {
    let net = NetworkConfig {
        listen: Vec::new(),
        connect: config.connect.clone(),
        mode: Mode::Peer,
        ..NetworkConfig::default()
    };
    let zerr = |e: &dyn std::fmt::Display| Ros2OpenError::Zenoh(e.to_string());
    let session = zenoh::open(crate::network::config(&net).map_err(|e| zerr(&e))?)
        .wait()
        .map_err(|e| zerr(&e))?;
    let node = device_node(config, &session);
    let mut tokens = Vec::new();
    for key in [
        node.token(),
        node.endpoint_token(
            1,
            Kind::Subscription,
            &config.pose_topic,
            &graph::POSE_STAMPED,
            Qos::STREAM,
        ),
        wrench_token(&node, config),
    ] {
        tokens.push(
            session
                .liveliness()
                .declare_token(key)
                .wait()
                .map_err(|e| zerr(&e))?,
        );
    }
    let poses = session
        .declare_subscriber(graph::topic_key(
            config.domain_id,
            &config.pose_topic,
            &graph::POSE_STAMPED,
        ))
        .with(RingChannel::new(64))
        .wait()
        .map_err(|e| zerr(&e))?;
    let wrench = session
        .declare_publisher(graph::topic_key(
            config.domain_id,
            &config.wrench_topic,
            &graph::WRENCH_STAMPED,
        ))
        .congestion_control(CongestionControl::Drop)
        .priority(Priority::InteractiveHigh)
        .express(true)
        .wait()
        .map_err(|e| zerr(&e))?;
    let first = poses
        .recv_timeout(Duration::from_millis(config.first_pose_timeout_ms))
        .ok()
        .flatten()
        .ok_or_else(|| Ros2OpenError::NoPose {
            what: config.where_(),
            ms: config.first_pose_timeout_ms,
        })?;
    let pose =
        PoseStamped::decode(&first.payload().to_bytes()).map_err(|e| Ros2OpenError::BadPose {
            what: config.where_(),
            reason: e.to_string(),
        })?;
    let driver = first
        .attachment()
        .and_then(|a| Attachment::decode(&a.to_bytes()))
        .map(|a| a.gid);
    Ok((session, tokens, poses, wrench, (pose, driver)))
}

/// What `station devices` says of the ROS 2 backend: whether a pose comes on the configured topic
/// (joins the graph for at most a second, or `first_pose_timeout_ms` if shorter; commands
/// nothing).
pub fn probe(config: &Ros2DeviceConfig) -> ProbeReport {
    let config = &Ros2DeviceConfig {
        first_pose_timeout_ms: config.first_pose_timeout_ms.min(1000),
        ..config.clone()
    };
    let mut report = ProbeReport {
        backend: "ros2",
        built_in: true,
        status: String::new(),
        devices: Vec::new(),
    };
    if let Err(e) = config.validate() {
        report.status = format!("device.ros2.{e}");
        return report;
    }
    match Ros2Device::open(config) {
        Ok(mut d) => {
            let s = d.last_sample();
            report.status = format!(
                "{}: a pose at ({:.4}, {:.4}, {:.4}) m",
                config.where_(),
                s.position_m.x,
                s.position_m.y,
                s.position_m.z
            );
            report.devices.push(d.info().clone());
            d.close();
        }
        Err(e) => report.status = e.to_string(),
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_config_is_valid_and_each_rule_names_its_field() {
        assert_eq!(Ros2DeviceConfig::default().validate(), Ok(()));
        let cases: Vec<(Ros2DeviceConfig, &str)> = vec![
            (
                Ros2DeviceConfig {
                    pose_topic: "haptic/pose".into(),
                    ..Default::default()
                },
                "pose_topic",
            ),
            (
                Ros2DeviceConfig {
                    wrench_topic: "/haptic/2nd".into(),
                    ..Default::default()
                },
                "wrench_topic",
            ),
            (
                Ros2DeviceConfig {
                    wrench_topic: "/haptic/pose".into(),
                    ..Default::default()
                },
                "wrench_topic",
            ),
            (
                Ros2DeviceConfig {
                    domain_id: 233,
                    ..Default::default()
                },
                "domain_id",
            ),
            (
                Ros2DeviceConfig {
                    connect: vec!["localhost:7447".into()],
                    ..Default::default()
                },
                "connect",
            ),
            (
                Ros2DeviceConfig {
                    rate_hz: f64::NAN,
                    ..Default::default()
                },
                "rate_hz",
            ),
            (
                Ros2DeviceConfig {
                    stale_limit_ms: 1.0,
                    ..Default::default()
                },
                "stale_limit_ms",
            ),
            (
                Ros2DeviceConfig {
                    max_force_n: 0.0,
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
    fn a_pose_becomes_a_sample_with_its_velocity_from_the_stamps() {
        let mut p = PoseStamped {
            position: [0.01, 0.02, 0.03],
            orientation: [0.0, 0.0, 0.0, 1.0],
            ..PoseStamped::default()
        };
        p.header.stamp.sec = 10;
        let first = to_sample(&p, 5, None);
        assert_eq!(first.0.position_m, Vec3::new(0.01, 0.02, 0.03));
        assert_eq!(first.0.velocity_m_s, Vec3::zeros());
        assert!(first.0.orientation.is_some());
        p.position[0] = 0.02;
        p.header.stamp.nanosec = 1_000_000;
        p.orientation = [0.0; 4];
        let second = to_sample(&p, 6, Some(&first));
        assert!((second.0.velocity_m_s.x - 10.0).abs() < 1e-9, "{second:?}");
        assert_eq!(second.0.t_ns, 6);
        assert!(second.0.orientation.is_none());
    }

    #[test]
    fn no_driver_is_one_clear_error_naming_the_topic() {
        let c = Ros2DeviceConfig {
            // Nothing listens on port 1.
            connect: vec!["tcp/127.0.0.1:1".into()],
            first_pose_timeout_ms: 200,
            ..Default::default()
        };
        let e = Ros2Device::open(&c).expect_err("no driver");
        assert!(matches!(e, Ros2OpenError::NoPose { .. }), "{e}");
        assert!(e.to_string().contains("/haptic/pose"), "{e}");
        let p = probe(&c);
        assert!(p.built_in && p.devices.is_empty());
        assert!(
            p.status.contains("no geometry_msgs/msg/PoseStamped"),
            "{}",
            p.status
        );
    }
}
