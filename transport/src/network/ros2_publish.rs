//! The station's ROS 2 publisher, in the network process: what physics' trace ring already
//! brings it (this site's copy of every object, its tool, the force displayed to its user), at
//! most [`Ros2Config::rate_hz`], and the station's events, as a ROS 2 node under `rmw_zenoh`'s
//! conventions on the station's own zenoh session.
//!
//! | topic | type | QoS |
//! |---|---|---|
//! | `<ns>/tool` | `geometry_msgs/msg/PoseStamped` (frame `world`) | best effort |
//! | `<ns>/force` | `geometry_msgs/msg/WrenchStamped`: the force on the user's hand (frame `world`) | best effort |
//! | `<ns>/object` (a world of one), `<ns>/object/<name>` (several) | `geometry_msgs/msg/PoseStamped` | best effort |
//! | `/tf` | `tf2_msgs/msg/TFMessage`: `world → tool/<site>`, `world → object/<site>` (`object/<name>/<site>`) | best effort |
//! | `/rosout` | `rcl_interfaces/msg/Log`: the station's events | reliable, transient local |
//!
//! `<ns>` is [`crate::ros2::namespace`], the node is `station` in it. Nothing here waits: puts are
//! dropped, not queued, under congestion, at background priority, and the streams' are skipped
//! altogether while no one subscribes (a `/rosout` line is always put, and kept for late
//! subscribers: the last 1000 of the last 10 s, `_max` of them if a query asks). Stamps are the
//! samples' monotonic times translated to wall time. Each publisher's GID is `rmw_zenoh`'s, the
//! hash of its liveliness token ([`graph::gid`]).

use std::sync::{Arc, Mutex};

use coop_rt::msg::TraceRecord;
use coop_rt::shm::control::{Traffic, WireKind};
use zenoh::bytes::Encoding;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Publisher;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::query::Queryable;
use zenoh::time::{Timestamp, TimestampId, NTP64};
use zenoh::{Session, Wait};

use super::NetworkError;
use crate::recording::Scene;
use crate::ros2::cdr::{self, Header, Log, PoseStamped, TransformStamped, WrenchStamped};
use crate::ros2::graph::{self, Attachment, Kind, MsgType, Node, Qos};
use crate::ros2::Ros2Config;

/// The encoding `rmw_zenoh` labels its samples with.
pub const CDR_ENCODING: &str = "application/cdr";

/// How many `/rosout` lines a late subscriber can still get (as `rcl` keeps: its depth).
const ROSOUT_KEPT: usize = 1000;

/// A `/rosout` line kept for late subscribers: when it was put, its CDR bytes, its attachment and
/// the zenoh timestamp it was put with (by which an `AdvancedSubscriber` orders the lines and
/// drops the ones it already has).
type KeptLine = (std::time::Instant, Vec<u8>, Vec<u8>, Timestamp);

/// The `/rosout` lines kept for late subscribers.
type Kept = Arc<Mutex<std::collections::VecDeque<KeptLine>>>;

/// How long a `/rosout` line stays worth serving to a late subscriber (rcl's lifespan).
const ROSOUT_LIFESPAN: std::time::Duration = std::time::Duration::from_secs(10);

/// One ROS 2 publisher: its zenoh publisher, its token, its numbering.
struct Endpoint {
    publisher: Publisher<'static>,
    _token: LivelinessToken,
    gid: [u8; 16],
    seq: i64,
}

impl Endpoint {
    fn declare(
        session: &Session,
        node: &Node,
        entity: u32,
        topic: &str,
        ty: &MsgType,
        qos: Qos,
    ) -> Result<Self, NetworkError> {
        let key = graph::topic_key(node.domain, topic, ty);
        let publisher = session
            .declare_publisher(key)
            .encoding(Encoding::from(CDR_ENCODING))
            // Dropped, never waited for, even on the reliable /rosout: a slow subscriber must not
            // hold up the network process (nor, by zenoh closing a blocked link, cut the link
            // the session's states share); a line it misses is still in the cache.
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::Background)
            .wait()
            .map_err(NetworkError::declare("ROS 2 publisher"))?;
        let token_key = node.endpoint_token(entity, Kind::Publisher, topic, ty, qos);
        // rmw_zenoh's GID: the hash of the token's key, which every reader of the token can redo.
        let gid = graph::gid(&token_key);
        let token = session
            .liveliness()
            .declare_token(token_key)
            .wait()
            .map_err(NetworkError::declare("ROS 2 publisher token"))?;
        Ok(Self {
            publisher,
            _token: token,
            gid,
            seq: 0,
        })
    }

    /// Whether anyone subscribes (zenoh's matching status; unknown counts as yes).
    fn watched(&self) -> bool {
        self.publisher
            .matching_status()
            .wait()
            .map_or(true, |m| m.matching())
    }

    /// The next sample's attachment: this publisher's next sequence number, `wall_ns`, its GID.
    fn attachment(&mut self, wall_ns: i64) -> Vec<u8> {
        self.seq += 1;
        Attachment {
            seq: self.seq,
            source_ns: wall_ns,
            gid: self.gid,
        }
        .encode()
        .to_vec()
    }

    /// Puts `bytes` with the next attachment; counts it.
    fn put(&mut self, bytes: Vec<u8>, wall_ns: i64, traffic: &Traffic) {
        let attachment = self.attachment(wall_ns);
        self.put_with(bytes, attachment, None, traffic);
    }

    /// Puts `bytes` with `attachment` (and `timestamp`, if any); counts it.
    fn put_with(
        &mut self,
        bytes: Vec<u8>,
        attachment: Vec<u8>,
        timestamp: Option<Timestamp>,
        traffic: &Traffic,
    ) {
        let len = bytes.len();
        // A failed put loses one sample of a ROS view, nothing else.
        if self
            .publisher
            .put(bytes)
            .attachment(attachment)
            .timestamp(timestamp)
            .wait()
            .is_ok()
        {
            traffic.sent(WireKind::Ros2, len);
        }
    }
}

/// The station's ROS 2 node.
pub struct Ros2Publisher {
    _node: LivelinessToken,
    tool: Endpoint,
    force: Endpoint,
    objects: Vec<Endpoint>,
    tf: Endpoint,
    rosout: Endpoint,
    /// The lines kept for late `/rosout` subscribers, with their attachments.
    kept: Kept,
    _cache: Queryable<()>,
    /// The `/rosout` cache's `@adv` token, by which an `AdvancedSubscriber` finds it.
    _cache_token: LivelinessToken,
    /// The id in the `/rosout` lines' timestamps (this session's), and the last time given one.
    stamp_id: TimestampId,
    last_stamp: NTP64,
    frames: Frames,
    logger: String,
    period_ns: u64,
    last_ns: Option<u64>,
    pending: Option<(TraceRecord, Vec<TraceRecord>)>,
}

/// The frames of this site's tool and objects (the recording's Foxglove frames).
struct Frames {
    tool: String,
    objects: Vec<String>,
}

impl std::fmt::Debug for Ros2Publisher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2Publisher")
            .field("logger", &self.logger)
            .field("period_ns", &self.period_ns)
            .finish_non_exhaustive()
    }
}

/// The topic names of a site, relative to nothing: `(tool, force, objects)`.
pub fn topics(session: &str, scene: &Scene) -> (String, String, Vec<String>) {
    let ns = crate::ros2::namespace(session, &scene.site);
    let objects = if scene.others.is_empty() {
        vec![format!("{ns}/object")]
    } else {
        std::iter::once(scene.first_name.as_str())
            .chain(scene.others.iter().map(|(n, _)| n.as_str()))
            .map(|n| format!("{ns}/object/{}", graph::ros_name(n)))
            .collect()
    };
    (format!("{ns}/tool"), format!("{ns}/force"), objects)
}

impl Ros2Publisher {
    /// Declares the node, its publishers and their tokens on `session`.
    ///
    /// # Errors
    /// A declaration zenoh refuses (an access control that does not allow the ROS 2 keys).
    pub fn declare(
        session: &Session,
        session_name: &str,
        scene: &Scene,
        config: &Ros2Config,
    ) -> Result<Self, NetworkError> {
        let node = Node {
            domain: config.domain_id,
            zid: session.zid().to_string(),
            id: 0,
            namespace: crate::ros2::namespace(session_name, &scene.site),
            name: "station".into(),
        };
        let token = session
            .liveliness()
            .declare_token(node.token())
            .wait()
            .map_err(NetworkError::declare("ROS 2 node token"))?;
        let (tool_topic, force_topic, object_topics) = topics(session_name, scene);
        let mut entity = 0;
        let mut next = || {
            entity += 1;
            entity
        };
        let tool = Endpoint::declare(
            session,
            &node,
            next(),
            &tool_topic,
            &graph::POSE_STAMPED,
            Qos::STREAM,
        )?;
        let force = Endpoint::declare(
            session,
            &node,
            next(),
            &force_topic,
            &graph::WRENCH_STAMPED,
            Qos::STREAM,
        )?;
        let objects = object_topics
            .iter()
            .map(|t| {
                Endpoint::declare(session, &node, next(), t, &graph::POSE_STAMPED, Qos::STREAM)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let tf = Endpoint::declare(
            session,
            &node,
            next(),
            "/tf",
            &graph::TF_MESSAGE,
            Qos::STREAM,
        )?;
        let rosout =
            Endpoint::declare(session, &node, next(), "/rosout", &graph::LOG, Qos::ROSOUT)?;
        let kept = Arc::new(Mutex::new(std::collections::VecDeque::new()));
        let (cache, cache_token) = declare_cache(session, &node, kept.clone())?;
        let mut frames = Frames {
            tool: scene.tool_frame(),
            objects: vec![scene.object_frame()],
        };
        frames
            .objects
            .extend(scene.others.iter().map(|(n, _)| scene.other_frame(n)));
        Ok(Self {
            _node: token,
            tool,
            force,
            objects,
            tf,
            rosout,
            kept,
            _cache: cache,
            _cache_token: cache_token,
            stamp_id: session.zid().into(),
            last_stamp: NTP64::default(),
            frames,
            logger: format!(
                "coop.{}.{}",
                graph::ros_name(session_name),
                graph::ros_name(&scene.site)
            ),
            period_ns: config.period_ns(),
            last_ns: None,
            pending: None,
        })
    }

    /// When the next sample is due, if one waits (the network loop wakes for it).
    pub fn due_ns(&self) -> Option<u64> {
        self.pending.as_ref()?;
        Some(self.last_ns.map_or(0, |t| t + self.period_ns))
    }

    /// Keeps `newest` (the newest sample drained this turn, if any) and publishes the newest kept
    /// one when the period has passed since the last.
    pub fn offer(
        &mut self,
        newest: Option<&(TraceRecord, Vec<TraceRecord>)>,
        now: u64,
        traffic: &Traffic,
    ) {
        if let Some(n) = newest {
            self.pending = Some(n.clone());
        }
        if self
            .last_ns
            .is_some_and(|t| now.saturating_sub(t) < self.period_ns)
        {
            return;
        }
        let Some((first, others)) = self.pending.take() else {
            return;
        };
        self.last_ns = Some(now);
        let offset = crate::ros2::wall_minus_monotonic_ns();
        let stamp = crate::ros2::stamp(first.t_ns, offset);
        let wall_ns = crate::ros2::wall_ns(now, offset);
        let header = Header {
            stamp,
            frame_id: crate::recording::scene::WORLD.into(),
        };
        let records: Vec<&TraceRecord> = std::iter::once(&first).chain(&others).collect();
        if self.tool.watched() {
            let m = PoseStamped {
                header: header.clone(),
                position: first.tool_pos,
                orientation: [0.0, 0.0, 0.0, 1.0],
            };
            self.tool.put(m.encode(), wall_ns, traffic);
        }
        if self.force.watched() {
            let m = WrenchStamped {
                header: header.clone(),
                force: first.f_desired,
                torque: [0.0; 3],
            };
            self.force.put(m.encode(), wall_ns, traffic);
        }
        for (e, r) in self.objects.iter_mut().zip(&records) {
            if e.watched() {
                let m = PoseStamped {
                    header: header.clone(),
                    position: r.pos,
                    orientation: xyzw(r.rot),
                };
                e.put(m.encode(), wall_ns, traffic);
            }
        }
        if self.tf.watched() {
            let mut transforms = vec![TransformStamped {
                header: header.clone(),
                child_frame_id: self.frames.tool.clone(),
                translation: first.tool_pos,
                rotation: [0.0, 0.0, 0.0, 1.0],
            }];
            transforms.extend(self.frames.objects.iter().zip(&records).map(|(f, r)| {
                TransformStamped {
                    header: header.clone(),
                    child_frame_id: f.clone(),
                    translation: r.pos,
                    rotation: xyzw(r.rot),
                }
            }));
            self.tf.put(cdr::encode_tf(&transforms), wall_ns, traffic);
        }
    }

    /// One line on `/rosout` (kept for late subscribers, whether anyone listens now or not).
    pub fn log(&mut self, level: u8, text: &str, traffic: &Traffic) {
        let offset = crate::ros2::wall_minus_monotonic_ns();
        let now = coop_rt::timer::monotonic_ns();
        let m = Log {
            stamp: crate::ros2::stamp(now, offset),
            level,
            name: self.logger.clone(),
            msg: text.to_owned(),
            ..Log::default()
        };
        let bytes = m.encode();
        // The line is kept with the attachment and the timestamp it is put with.
        let attachment = self.rosout.attachment(crate::ros2::wall_ns(now, offset));
        let timestamp = self.next_timestamp();
        {
            let mut kept = self.kept.lock().unwrap_or_else(|e| e.into_inner());
            if kept.len() == ROSOUT_KEPT {
                kept.pop_front();
            }
            kept.push_back((
                std::time::Instant::now(),
                bytes.clone(),
                attachment.clone(),
                timestamp,
            ));
        }
        self.rosout
            .put_with(bytes, attachment, Some(timestamp), traffic);
    }

    /// A zenoh timestamp for the next `/rosout` line: wall time, this session's id, strictly later
    /// than the last (an `AdvancedSubscriber` takes two lines with one timestamp for one).
    fn next_timestamp(&mut self) -> Timestamp {
        let now = NTP64::from(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap_or_default(),
        );
        self.last_stamp = if now > self.last_stamp {
            now
        } else {
            self.last_stamp + 1
        };
        Timestamp::new(self.last_stamp, self.stamp_id)
    }
}

/// ROS orders a quaternion x, y, z, w; ours is w, x, y, z.
fn xyzw(r: [f64; 4]) -> [f64; 4] {
    [r[1], r[2], r[3], r[0]]
}

/// The transient-local cache of `/rosout` as `rmw_zenoh` serves it (zenoh-ext's
/// `AdvancedPublisher` with a cache and publisher detection): a liveliness token and a queryable,
/// both on [`graph::adv_key`]. An `AdvancedSubscriber` with history (`rmw_zenoh`'s transient-local
/// subscriptions) asks `<key>/@adv/**?_max=<depth>` when it starts, and, for each `@adv/pub` token
/// it sees, that token's key with the same `_max`, accepting replies on any key: both reach the
/// queryable, which replies the newest `_max` kept lines, on the topic's key, each with its
/// attachment and the timestamp it was put with (by which the subscriber drops the lines the
/// other query, or the live topic, already gave it).
fn declare_cache(
    session: &Session,
    node: &Node,
    kept: Kept,
) -> Result<(Queryable<()>, LivelinessToken), NetworkError> {
    let key = graph::topic_key(node.domain, "/rosout", &graph::LOG);
    let cache_key = graph::adv_key(&key, &node.zid);
    let queryable = session
        .declare_queryable(cache_key.clone())
        .callback(move |q| {
            // The newest `_max` lines (the subscriber's depth) younger than the lifespan.
            let max = q
                .parameters()
                .get("_max")
                .and_then(|m| m.parse::<usize>().ok())
                .unwrap_or(ROSOUT_KEPT);
            let lines: Vec<(Vec<u8>, Vec<u8>, Timestamp)> = {
                let kept = kept.lock().unwrap_or_else(|e| e.into_inner());
                let young: Vec<_> = kept
                    .iter()
                    .filter(|(t, _, _, _)| t.elapsed() < ROSOUT_LIFESPAN)
                    .collect();
                young[young.len().saturating_sub(max)..]
                    .iter()
                    .map(|(_, b, a, ts)| (b.clone(), a.clone(), *ts))
                    .collect()
            };
            for (bytes, attachment, timestamp) in lines {
                // A reply that cannot go is a line the late subscriber misses.
                let _ = q
                    .reply(key.clone(), bytes)
                    .encoding(Encoding::from(CDR_ENCODING))
                    .attachment(attachment)
                    .timestamp(timestamp)
                    .wait();
            }
        })
        .wait()
        .map_err(NetworkError::declare("ROS 2 /rosout cache"))?;
    let token = session
        .liveliness()
        .declare_token(cache_key)
        .wait()
        .map_err(NetworkError::declare("ROS 2 /rosout cache token"))?;
    Ok((queryable, token))
}
