//! The recordings' messages: each JSON channel's struct, with its `jsonschema` derived from the
//! same field list, and the messages built from physics' trace records.

use coop_rt::msg::TraceRecord;
use coop_rt::shm::control::REFUSED_REASONS;
use foxglove::messages::log::Level;
use serde::{Deserialize, Serialize};

/// A message type's JSON schema (each channel's `jsonschema`), derived from its fields' types by
/// [`json_message!`], so it cannot disagree with what serde writes.
pub(super) trait JsonSchema {
    fn schema() -> serde_json::Value;
}

macro_rules! json_schema_is {
    ($type:literal: $($t:ty),*) => {$(
        impl JsonSchema for $t {
            fn schema() -> serde_json::Value {
                serde_json::json!({ "type": $type })
            }
        }
    )*};
}
json_schema_is!("integer": u64, i64, usize);
json_schema_is!("number": f64);
json_schema_is!("boolean": bool);
json_schema_is!("string": String);

impl<T: JsonSchema, const N: usize> JsonSchema for [T; N] {
    fn schema() -> serde_json::Value {
        serde_json::json!({ "type": "array", "items": T::schema(), "minItems": N, "maxItems": N })
    }
}

impl<T: JsonSchema> JsonSchema for Vec<T> {
    fn schema() -> serde_json::Value {
        serde_json::json!({ "type": "array", "items": T::schema() })
    }
}

impl<T: JsonSchema> JsonSchema for Option<T> {
    fn schema() -> serde_json::Value {
        serde_json::json!({ "anyOf": [T::schema(), { "type": "null" }] })
    }
}

/// Declares a channel's message struct and derives its [`JsonSchema`] from the same field list.
macro_rules! json_message {
    (
        $(#[$meta:meta])*
        $vis:vis struct $name:ident {
            $( $(#[$fmeta:meta])* $fvis:vis $field:ident : $t:ty ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        $vis struct $name {
            $( $(#[$fmeta])* $fvis $field: $t, )*
        }

        impl JsonSchema for $name {
            fn schema() -> serde_json::Value {
                let mut properties = serde_json::Map::new();
                $( properties.insert(stringify!($field).into(), <$t as JsonSchema>::schema()); )*
                serde_json::json!({ "type": "object", "properties": properties })
            }
        }
    };
}

json_message! {
    /// `/session`.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
    pub struct SessionMsg {
        /// When this was written, ns (monotonic).
        pub t_ns: u64,
        /// Session name.
        pub session: String,
        /// Site name.
        pub site: String,
        /// Site index in the scenario.
        pub site_index: usize,
        /// Scenario name.
        pub scenario: String,
        /// Consistency method.
        pub method: String,
        /// The session's time 0, ns (monotonic).
        pub epoch_ns: u64,
        /// "none", or "EMULATED: …" with the link's parameters.
        pub emulation: String,
    }
}

json_message! {
    /// `/object` and `/tool` in one (they are sampled together; split on writing).
    #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
    pub struct SampleMsg {
        /// ns (monotonic).
        pub t_ns: u64,
        /// Object position, m.
        pub pos: [f64; 3],
        /// Object orientation (w, x, y, z).
        pub rot: [f64; 4],
        /// Object velocity, m/s.
        pub vel: [f64; 3],
        /// Adoptions so far.
        pub adoptions: u64,
        /// Tool position, m.
        pub tool_pos: [f64; 3],
        /// Desired force at the hand, N.
        pub f_desired: [f64; 3],
        /// Measured force, N.
        pub f_measured: [f64; 3],
        /// Users' force on this copy, N.
        pub f_object: [f64; 3],
        /// The own user touches the object.
        pub touching: bool,
    }
}

impl From<&TraceRecord> for SampleMsg {
    /// The sample part of a trace record (its adoption fields are left out).
    fn from(t: &TraceRecord) -> Self {
        Self {
            t_ns: t.t_ns,
            pos: t.pos,
            rot: t.rot,
            vel: t.vel,
            adoptions: t.adoptions,
            tool_pos: t.tool_pos,
            f_desired: t.f_desired,
            f_measured: t.f_measured,
            f_object: t.f_object,
            touching: t.touching != 0,
        }
    }
}

/// One object's pose, m and (w, x, y, z).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct ObjectPose {
    /// Centre of mass, m.
    pub pos: [f64; 3],
    /// Orientation (w, x, y, z).
    pub rot: [f64; 4],
}

/// What a station puts for live viewers (`coop/<session>/live/<site>`, `docs/wire.md`): a
/// sample, and in a world of several objects the others' poses in the world's order (absent in a
/// world of one: the message is then a [`SampleMsg`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct LiveSample {
    /// The sample (its object the world's first).
    #[serde(flatten)]
    pub sample: SampleMsg,
    /// The world's other objects.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub others: Vec<ObjectPose>,
}

impl LiveSample {
    /// The first object's record and the others' of the same time (the world's order).
    pub fn from_trace(first: &TraceRecord, others: &[TraceRecord]) -> Self {
        Self {
            sample: SampleMsg::from(first),
            others: others
                .iter()
                .map(|t| ObjectPose {
                    pos: t.pos,
                    rot: t.rot,
                })
                .collect(),
        }
    }

    /// The others' poses as [`Scene::other_transforms`](super::Scene::other_transforms) takes them.
    pub fn other_poses(&self) -> Vec<([f64; 3], [f64; 4])> {
        self.others.iter().map(|p| (p.pos, p.rot)).collect()
    }
}

json_message! {
    /// `/object`: the sample's object part, named after its site (a viewer that opens several
    /// sites' recordings, or a session file, tells them apart by it: `/object{site=="user1"}`),
    /// and in a world of several objects after its object (`/object{object=="cup"}`; absent in a
    /// world of one).
    #[derive(Serialize, Deserialize)]
    pub(super) struct ObjectPart {
        pub(super) t_ns: u64,
        #[serde(default)]
        pub(super) site: String,
        #[serde(default, skip_serializing_if = "String::is_empty")]
        pub(super) object: String,
        pub(super) pos: [f64; 3],
        pub(super) rot: [f64; 4],
        pub(super) vel: [f64; 3],
        pub(super) adoptions: u64,
        /// In a station's recording of a world of several: whether its user's tool touches this
        /// object (absent in a world of one: `/tool` says it).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        pub(super) touching: Option<bool>,
    }
}

/// One object of a world of several (the second on), as a recording holds it: its name and its
/// samples (pose, velocity, whether the site's tool touches it).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ObjectSamples {
    /// The object's name.
    pub name: String,
    /// Its samples: `t_ns`, `pos`, `rot`, `vel`, `adoptions`, `touching` filled, the tool's
    /// fields left at 0.
    pub samples: Vec<SampleMsg>,
}

json_message! {
    /// `/tool`: the sample's tool part, named after its site as `/object` is.
    #[derive(Serialize, Deserialize)]
    pub(super) struct ToolPart {
        pub(super) t_ns: u64,
        #[serde(default)]
        pub(super) site: String,
        pub(super) tool_pos: [f64; 3],
        pub(super) f_desired: [f64; 3],
        pub(super) f_measured: [f64; 3],
        pub(super) f_object: [f64; 3],
        pub(super) touching: bool,
    }
}

json_message! {
    /// `/adoption`.
    #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
    pub struct AdoptionMsg {
        /// ns (monotonic).
        pub t_ns: u64,
        /// Sender's site index.
        pub from: usize,
        /// Position jump, m.
        pub jump_m: f64,
        /// How far the state was dead-reckoned, s.
        pub age_s: f64,
    }
}

impl From<&TraceRecord> for AdoptionMsg {
    /// The adoption part of a trace record.
    fn from(t: &TraceRecord) -> Self {
        Self {
            t_ns: t.t_ns,
            from: t.from as usize,
            jump_m: t.jump_m,
            age_s: t.age_s,
        }
    }
}

json_message! {
    /// `/remote`.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
    pub struct RemoteMsg {
        /// When it was handed to physics, ns (monotonic).
        pub t_ns: u64,
        /// Sender's site index.
        pub from: usize,
        /// Sender's sequence number.
        pub seq: u64,
        /// Sender's time of the state, corrected to our clock, ns.
        pub sent_ns: u64,
        /// The state's centre of mass as the sender gave it, m (0 in a force report).
        #[serde(default)]
        pub pos: [f64; 3],
        /// The correction applied: the sender's clock minus ours, ns.
        #[serde(default)]
        pub offset_ns: i64,
        /// `t_ns − sent_ns`, s.
        pub age_s: f64,
        /// Delay the emulation added on top of the real one, s (0 without emulation).
        pub emulated_delay_s: f64,
        /// The zenoh timestamp (HLC) of the sample, if it had one.
        pub zenoh_ts: Option<String>,
        /// `live`, or `join` for a state from the session's queryable at start.
        pub via: String,
    }
}

json_message! {
    /// `/published`.
    #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
    pub struct PublishedMsg {
        /// When it was published, ns (monotonic).
        pub t_ns: u64,
        /// Its sequence number.
        pub seq: u64,
        /// Its state's time (the report's `t_ns`), ns.
        pub state_ns: u64,
    }
}

json_message! {
    /// `/peer`: a site lost (silent past the loss limit) or heard again.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
    pub struct PeerMsg {
        /// ns (monotonic).
        pub t_ns: u64,
        /// Site name.
        pub site: String,
        /// `lost` or `rejoined`.
        pub event: String,
        /// How long it had been silent, s.
        pub silent_s: f64,
    }
}

json_message! {
    /// `/presence`.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
    pub struct PresenceMsg {
        /// ns (monotonic).
        pub t_ns: u64,
        /// Site name.
        pub site: String,
        /// Joined (true) or left.
        pub present: bool,
    }
}

json_message! {
    /// `/clock`.
    #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
    pub struct ClockMsg {
        /// ns (monotonic).
        pub t_ns: u64,
        /// Peer site index.
        pub site: usize,
        /// Its clock minus ours, ns.
        pub offset_ns: i64,
        /// Round trip of the exchange, ns.
        pub rtt_ns: u64,
    }
}

json_message! {
    /// `/task`: the task's outcome as this site showed it, each time it changes (the servo judges
    /// it live).
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
    pub struct TaskMsg {
        /// ns (monotonic).
        pub t_ns: u64,
        /// `running`, `done` or `failed`.
        pub outcome: String,
        /// When it was done or failed, s from the session's time 0 (0 while running).
        pub at_s: f64,
        /// What failed it: `timeout` or `fail[k]` (empty: not failed).
        pub failed_by: String,
    }
}

impl TaskMsg {
    /// What it says, for `/log` and a station's event watchers: a failure is a warning.
    pub fn said(&self) -> (Level, String) {
        match self.outcome.as_str() {
            "failed" => (
                Level::Warning,
                format!("task failed at {:.2} s by {}", self.at_s, self.failed_by),
            ),
            "done" => (Level::Info, format!("task done at {:.2} s", self.at_s)),
            o => (Level::Info, format!("task {o}")),
        }
    }
}

json_message! {
    /// `/status`.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
    pub struct StatusMsg {
        /// ns (monotonic).
        pub t_ns: u64,
        /// Reports published.
        pub published: u64,
        /// Reports handed to physics.
        pub received: u64,
        /// Refused, by reason in `coop_rt::shm::control::Refused` order: version, length,
        /// contents, foreign, duplicate/out of order, no clock offset yet, too old, in the future,
        /// implausible.
        pub refused: [u64; REFUSED_REASONS],
        /// Dropped by the emulation.
        pub emulated_lost: u64,
        /// States from the session's queryable at start.
        pub join_states: u64,
        /// Reports not published because a newer one was already waiting.
        #[serde(default)]
        pub stale_skipped: u64,
        /// What the network process put on the wire and got from it, by kind, over its life.
        #[serde(default)]
        pub traffic: TrafficMsg,
        /// The device as the servo last published it (empty: it never opened one).
        #[serde(default)]
        pub device: DeviceMsg,
    }
}

json_message! {
    /// A station's device at the end: what it is and what it saw since the servo opened it (a
    /// restarted servo counts afresh), as `station status` shows it.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
    pub struct DeviceMsg {
        /// The backend (`sim`, `replay`, `haply`, `dhd`, `ros2`; empty: none opened).
        pub backend: String,
        /// The model, as the device says it.
        pub model: String,
        /// Servo ticks at which the device gave a sample.
        pub samples: u64,
        /// ... of them newer than the one before (what the device itself delivered).
        pub new_samples: u64,
        /// Servo ticks at which it reported a fault, of any kind.
        pub faults: u64,
        /// ... of them its samples stale.
        pub stale: u64,
        /// Messages its bridge refused, for any reason (not a sample, or from another publisher),
        /// as `station status` counts them.
        pub refused: u64,
        /// ... of them from another publisher than its driver's.
        pub foreign: u64,
        /// Force commands it took.
        pub commands: u64,
        /// The last fault, in words (empty: none).
        pub last_fault: String,
    }
}

impl DeviceMsg {
    /// The device group `d` now.
    pub fn of(d: &coop_rt::shm::device::DeviceShared) -> Self {
        if !d.is_open() {
            return Self::default();
        }
        let c = d.counts.load();
        Self {
            backend: d.backend.load(),
            model: d.model.load(),
            samples: c.samples,
            new_samples: c.new_samples,
            faults: c.faults,
            stale: c.stale,
            refused: c.refused + c.foreign,
            foreign: c.foreign,
            commands: c.commands,
            last_fault: d.last_fault().map(|(_, text, _)| text).unwrap_or_default(),
        }
    }
}

json_message! {
    /// The network process's traffic over its life, per `coop_rt::shm::control::WireKind` in
    /// its order (states, tracks, clock, presence, live): payload bytes and messages put and got.
    #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
    pub struct TrafficMsg {
        /// Payload bytes put, by kind.
        pub sent_bytes: [u64; WIRE_KINDS],
        /// Messages put, by kind.
        pub sent_msgs: [u64; WIRE_KINDS],
        /// Payload bytes received, by kind.
        pub received_bytes: [u64; WIRE_KINDS],
        /// Messages received, by kind.
        pub received_msgs: [u64; WIRE_KINDS],
    }
}

/// How many kinds of traffic a [`TrafficMsg`] counts.
pub const WIRE_KINDS: usize = 6;

impl TrafficMsg {
    /// The counts in `t` now.
    pub fn of(t: &coop_rt::shm::control::Traffic) -> Self {
        use coop_rt::shm::control::{CounterKey, WireKind};
        let each = |c: &coop_rt::shm::control::Counters<WireKind>| {
            let mut out = [0; WIRE_KINDS];
            for (o, &k) in out.iter_mut().zip(WireKind::ALL) {
                *o = c.get(k);
            }
            out
        };
        Self {
            sent_bytes: each(&t.sent_bytes),
            sent_msgs: each(&t.sent_msgs),
            received_bytes: each(&t.received_bytes),
            received_msgs: each(&t.received_msgs),
        }
    }
}

json_message! {
    /// `/divergence`, in a session file ([`session`](super::session)): how far the sites' copies are apart.
    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
    pub struct DivergenceMsg {
        /// ns since the session's time 0.
        pub t_ns: u64,
        /// The largest distance between any two sites' copies of the object, m
        /// (`coop_model::metrics::divergence`).
        pub max_m: f64,
        /// Each site's copy's distance from the reference copy, m, in the scenario's site order.
        pub vs_reference_m: Vec<f64>,
    }
}
