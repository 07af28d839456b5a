//! The benchmark's stand-in ROS 2 driver: a zenoh session of its own that publishes an end
//! effector's `PoseStamped` at 1 kHz under `rmw_zenoh`'s conventions and listens for the
//! `WrenchStamped` coming back, as a device's ROS 2 driver would.
//!
//! Its pose steps by [`STEP_M`] along x every [`STEP_EVERY_NS`]; the servo's spring turns each
//! step into a force step of `-stiffness · STEP_M`. The round trip of one step is from the put of
//! its first pose to the first wrench reflecting it (closer to the new force than to the old),
//! both read on this side's clock: pose in, zenoh, bridge, servo tick, bridge, zenoh, force out.

use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use coop_rt::sync::{AtomicU64, Ordering};
use coop_rt::timer::{monotonic_ns, sleep_until};
use coop_transport::ros2::cdr::{Header, PoseStamped, WrenchStamped};
use coop_transport::ros2::graph::{self, Attachment};
use hdrhistogram::Histogram;
use zenoh::Wait;

/// The pose's topic.
pub const POSE_TOPIC: &str = "/bench/pose";
/// The wrench's topic.
pub const WRENCH_TOPIC: &str = "/bench/wrench_command";
/// How far each step moves the end effector, m.
pub const STEP_M: f64 = 0.0005;
/// How often it steps, ns.
pub const STEP_EVERY_NS: u64 = 50_000_000;
/// The driver's rate, Hz.
pub const RATE_HZ: f64 = 1000.0;

/// A running driver.
pub struct Driver {
    /// Where the device connects.
    pub locator: String,
    stop: Arc<AtomicU64>,
    /// Recording on: steps and wrenches are logged only while a ROS 2 phase runs.
    pub recording: Arc<AtomicU64>,
    thread: Option<JoinHandle<()>>,
    log: Arc<Mutex<Log>>,
    _session: zenoh::Session,
    _sub: zenoh::pubsub::Subscriber<()>,
}

/// What the driver saw: its steps (time, x before, x after) and the wrenches (time, F_x).
#[derive(Debug, Default)]
struct Log {
    steps: Vec<(u64, f64, f64)>,
    wrenches: Vec<(u64, f64)>,
}

impl Driver {
    /// Opens the driver's session on a free loopback port and starts publishing.
    ///
    /// # Errors
    /// Zenoh refuses.
    pub fn start() -> anyhow::Result<Self> {
        let locator =
            coop_transport::network::concrete_listen(&["tcp/127.0.0.1:0".into()]).remove(0);
        let net = coop_transport::network::NetworkConfig {
            listen: vec![locator.clone()],
            ..coop_transport::network::NetworkConfig::default()
        };
        let session = zenoh::open(coop_transport::network::config(&net)?)
            .wait()
            .map_err(|e| anyhow::anyhow!("the stand-in ROS 2 driver's zenoh session: {e}"))?;
        let log = Arc::new(Mutex::new(Log::default()));
        let recording = Arc::new(AtomicU64::new(0));
        let (l, r) = (log.clone(), recording.clone());
        let sub = session
            .declare_subscriber(graph::topic_key(0, WRENCH_TOPIC, &graph::WRENCH_STAMPED))
            .callback(move |s| {
                let t = monotonic_ns();
                if r.load(Ordering::Relaxed) == 0 {
                    return;
                }
                if let Ok(w) = WrenchStamped::decode(&s.payload().to_bytes()) {
                    l.lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .wrenches
                        .push((t, w.force[0]));
                }
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("the stand-in driver's subscriber: {e}"))?;
        let publisher = session
            .declare_publisher(graph::topic_key(0, POSE_TOPIC, &graph::POSE_STAMPED))
            .express(true)
            .wait()
            .map_err(|e| anyhow::anyhow!("the stand-in driver's publisher: {e}"))?;
        let stop = Arc::new(AtomicU64::new(0));
        let (st, l, r) = (stop.clone(), log.clone(), recording.clone());
        let thread = std::thread::Builder::new()
            .name("ros2-driver".into())
            .spawn(move || {
                let period = (1e9 / RATE_HZ) as u64;
                let mut next = monotonic_ns();
                let mut next_step = next + STEP_EVERY_NS;
                let (mut x, mut seq) = (0.0f64, 0i64);
                while st.load(Ordering::Relaxed) == 0 {
                    let now = monotonic_ns();
                    if now >= next_step {
                        let before = x;
                        x = if x == 0.0 { STEP_M } else { 0.0 };
                        next_step += STEP_EVERY_NS;
                        if r.load(Ordering::Relaxed) == 1 {
                            l.lock().unwrap_or_else(|e| e.into_inner()).steps.push((
                                monotonic_ns(),
                                before,
                                x,
                            ));
                        }
                    }
                    let offset = coop_transport::ros2::wall_minus_monotonic_ns();
                    let pose = PoseStamped {
                        header: Header {
                            stamp: coop_transport::ros2::stamp(now, offset),
                            frame_id: "device".into(),
                        },
                        position: [x, -0.12, 0.15],
                        orientation: [0.0, 0.0, 0.0, 1.0],
                    };
                    seq += 1;
                    let a = Attachment {
                        seq,
                        source_ns: 0,
                        gid: [9; 16],
                    };
                    let _ = publisher
                        .put(pose.encode())
                        .attachment(a.encode().to_vec())
                        .wait();
                    next += period;
                    sleep_until(next);
                }
            })?;
        Ok(Self {
            locator,
            stop,
            recording,
            thread: Some(thread),
            log,
            _session: session,
            _sub: sub,
        })
    }

    /// The round trips of every step logged, ns, for a spring of `stiffness` N/m: for each step,
    /// the first wrench after it closer to the force the new pose gives than to the old one's.
    pub fn round_trips(&self, stiffness: f64, into: &mut Histogram<u64>) {
        let log = self.log.lock().unwrap_or_else(|e| e.into_inner());
        for &(t, before, after) in &log.steps {
            // The force just before the step, and the force the step should give.
            let Some(&(_, f_old)) = log.wrenches.iter().rev().find(|w| w.0 < t) else {
                continue;
            };
            let f_new = f_old - stiffness * (after - before);
            if let Some(&(tw, _)) = log
                .wrenches
                .iter()
                .find(|w| w.0 >= t && (w.1 - f_new).abs() < (w.1 - f_old).abs())
            {
                // A step older than the next one's answer was not answered on its own.
                if tw - t < STEP_EVERY_NS {
                    into.saturating_record(tw - t);
                }
            }
        }
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        self.stop.store(1, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
