//! A station's recording: what it believed and displayed, as [MCAP](https://mcap.dev) files (one
//! or more parts, see below) that Foxglove, the `mcap` CLI and the `mcap` Python package read.
//!
//! Every message is JSON (`message_encoding = "json"`, each channel with a `jsonschema` schema). Times
//! inside messages (`t_ns`) are CLOCK_MONOTONIC ns of the recording station; the MCAP `log_time` is
//! the wall clock, for viewers. Channels:
//!
//! | topic       | rate                         | contents                                              |
//! |-------------|------------------------------|-------------------------------------------------------|
//! | `/session`  | once the session time is known, again atop each later part | session, site, scenario, method, epoch, emulation |
//! | `/object`   | scenario sample rate         | object pose and velocity as this site believes it     |
//! | `/tool`     | scenario sample rate         | tool position, desired/measured force, force on object |
//! | `/adoption` | each adoption                | sender, position jump, how far it was dead-reckoned  |
//! | `/remote`   | each state handed to physics | sender, sequence, sent time, position, age, emulated delay |
//! | `/published`| each report published        | sequence and time of the state                        |
//! | `/presence` | each join or leave           | site, present                                         |
//! | `/peer`     | each loss or rejoin          | site, lost or rejoined, how long it was silent        |
//! | `/clock`    | each new estimate            | per peer clock offset and round trip                 |
//! | `/status`   | at the end                   | the network counters                                  |
//!
//! Physics' trace records go in whole ([`Recorder::trace`]); each channel's `jsonschema` is derived
//! from its message struct's fields.
//!
//! A recording made with a [`Scene`] ([`Recorder::create_with_scene`], as the network process makes
//! it unless the station's `record_foxglove` is off) also has Foxglove's well-known channels (`message_encoding = "protobuf"`, each schema the
//! `foxglove` crate's FileDescriptorSet, named `foxglove.<Type>`), so Foxglove and Lichtblick show
//! it in their 3-D panel and log view without any setup (see [`scene`] for the frames and entities):
//!
//! | topic    | schema                    | rate                  | contents                        |
//! |----------|---------------------------|-----------------------|---------------------------------|
//! | `/tf`    | `foxglove.FrameTransform` | two per sample        | `world → object/<site>`, `world → tool/<site>` |
//! | `/scene` | `foxglove.SceneUpdate`    | every [`SCENE_EVERY`] of samples, and the first sample of each part | the object, tool, force arrow, environment |
//! | `/log`   | `foxglove.Log`            | each station event    | started, joined/left, lost/rejoined, stale/fresh, a child restarted, a device safety limit acting, stopping |
//!
//! The protobuf messages go through the same writer as the JSON ones (not the SDK's own MCAP
//! sink), so they rotate, flush and survive a crash with them, and each part holds its own
//! schemas.
//!
//! A run's whole session in one file, as `sim run` and `session run` write it next to their plots,
//! is [`session`]'s.
//!
//! Each file is written without chunks and flushed every [`FLUSH_EVERY`], so a crash keeps
//! everything up to the last flush; [`read`] accepts such a file (no summary, no end magic).
//!
//! # Parts
//!
//! A recording does not grow without bound: once its file holds [`Rotation::max_file_bytes`] or
//! has been written for [`Rotation::max_file_duration`], the recorder finishes it and goes on in
//! the next part, named after the first ([`part_path`]): `user1.mcap`, then `user1.1.mcap`,
//! `user1.2.mcap`, … Beyond [`Rotation::keep_files`] parts the oldest is removed. Every part is a
//! whole MCAP file that opens alone: its own header, schemas, channels and metadata (the station's,
//! plus `part`, its number, and `started_unix_ns`, when the recording's first part was created,
//! which tells one recording from another), and the `/session` message again at its top once the
//! session is known. A sample's `/object` and `/tool` are never split between parts. Creating a
//! recording removes the parts an earlier one left at the same path, unless it continues it
//! ([`Recorder::continue_or_create`]: a restarted network process of the same station run goes on
//! in the next part of what its predecessor wrote, as the same recording). [`read`] reads every
//! part in order as one recording and refuses parts of different recordings; [`read_part`] reads
//! one.

use std::cell::Cell;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::{Duration, Instant};

use coop_rt::msg::TraceRecord;
use coop_rt::shm::control::REFUSED_REASONS;
/// Foxglove's log level ([`LogLine::level`], [`Recorder::event`]).
pub use foxglove::messages::log::Level;
use foxglove::messages::{FrameTransform, Log, SceneUpdate};
use foxglove::Encode;
use serde::{Deserialize, Serialize};

pub mod scene;
pub mod session;
pub use scene::Scene;

/// How often the writer pushes what it has to the file.
pub const FLUSH_EVERY: Duration = Duration::from_millis(200);
/// The metadata key naming the station run a recording belongs to (the run's supervisor, as
/// `coop_rt::shm::BlockSegment::creator` of its control block gives it): a recorder created with
/// the same one at the same path continues the recording ([`Recorder::continue_or_create`]).
pub const STATION_RUN: &str = "station_run";
/// How much of a part's beginning is read for its metadata (written right after its header).
const HEAD_BYTES: u64 = 64 << 10;
/// How often, in sample time, the whole `/scene` is written (the frames move it in between).
pub const SCENE_EVERY: Duration = Duration::from_millis(50);

/// A message type's JSON schema (each channel's `jsonschema`), derived from its fields' types by
/// [`json_message!`], so it cannot disagree with what serde writes.
trait JsonSchema {
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

    /// The others' poses as [`Scene::other_transforms`] takes them.
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
    struct ObjectPart {
        t_ns: u64,
        #[serde(default)]
        site: String,
        #[serde(default, skip_serializing_if = "String::is_empty")]
        object: String,
        pos: [f64; 3],
        rot: [f64; 4],
        vel: [f64; 3],
        adoptions: u64,
        /// In a station's recording of a world of several: whether its user's tool touches this
        /// object (absent in a world of one: `/tool` says it).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        touching: Option<bool>,
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
    struct ToolPart {
        t_ns: u64,
        #[serde(default)]
        site: String,
        tool_pos: [f64; 3],
        f_desired: [f64; 3],
        f_measured: [f64; 3],
        f_object: [f64; 3],
        touching: bool,
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
    /// `/status`.
    #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
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
    /// `/divergence`, in a session file ([`session`]): how far the sites' copies are apart.
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

const TOPICS: [&str; 10] = [
    "/session",
    "/object",
    "/tool",
    "/adoption",
    "/remote",
    "/presence",
    "/clock",
    "/status",
    "/published",
    "/peer",
];

/// Foxglove's well-known channels, after [`TOPICS`] (with a [`Scene`] only).
const FOXGLOVE_TOPICS: [&str; 3] = ["/tf", "/scene", "/log"];

/// The schema (from the `foxglove` crate) of a Foxglove channel.
fn foxglove_schema(topic: &str) -> Option<foxglove::Schema> {
    match topic {
        "/tf" => FrameTransform::get_schema(),
        "/scene" => SceneUpdate::get_schema(),
        "/log" => Log::get_schema(),
        _ => None,
    }
}

/// When a part of a recording is finished and the next begun, and how many parts are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rotation {
    /// A part that holds this many bytes is finished (`None`: no size bound).
    pub max_file_bytes: Option<u64>,
    /// A part written for this long is finished (`None`: no time bound).
    pub max_file_duration: Option<Duration>,
    /// Parts kept on disk, the oldest removed beyond them (0: all are kept).
    pub keep_files: usize,
}

impl Rotation {
    /// One file, however large it grows.
    pub const NONE: Rotation = Rotation {
        max_file_bytes: None,
        max_file_duration: None,
        keep_files: 0,
    };
}

/// The file of part `n` of the recording whose first part is `first`: `first` itself for 0, else
/// the number before the extension (`user1.mcap`, `user1.1.mcap`, `user1.2.mcap`, …; `rec`,
/// `rec.1`, … without one).
pub fn part_path(first: &Path, n: u32) -> PathBuf {
    if n == 0 {
        return first.to_owned();
    }
    let (stem, ext) = stem_and_ext(first);
    first.with_file_name(match ext {
        Some(e) => format!("{stem}.{n}.{e}"),
        None => format!("{stem}.{n}"),
    })
}

fn stem_and_ext(first: &Path) -> (String, Option<String>) {
    let lossy = |s: &std::ffi::OsStr| s.to_string_lossy().into_owned();
    match (first.file_stem(), first.extension()) {
        (Some(s), Some(e)) => (lossy(s), Some(lossy(e))),
        _ => (first.file_name().map(lossy).unwrap_or_default(), None),
    }
}

/// The parts of the recording whose first part is `first` that are on disk, by number.
fn parts_on_disk(first: &Path) -> std::io::Result<Vec<(u32, PathBuf)>> {
    let (stem, ext) = stem_and_ext(first);
    let dir = match first.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut parts = Vec::new();
    if first.is_file() {
        parts.push((0, first.to_owned()));
    }
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(parts),
        Err(e) => return Err(e),
    };
    for entry in entries {
        let name = entry?.file_name();
        let Some(name) = name.to_str() else { continue };
        let number = name
            .strip_prefix(stem.as_str())
            .and_then(|r| r.strip_prefix('.'));
        let number = match &ext {
            Some(e) => number.and_then(|r| r.strip_suffix(e.as_str())?.strip_suffix('.')),
            None => number,
        };
        // Only the names `part_path` writes (no `user1.01.mcap`).
        if let Some(n) = number
            .and_then(|d| d.parse::<u32>().ok())
            .filter(|&n| n > 0 && part_path(first, n).file_name() == Some(name.as_ref()))
        {
            parts.push((n, part_path(first, n)));
        }
    }
    parts.sort();
    Ok(parts)
}

/// The first [`HEAD_BYTES`] of a file.
fn head_of(path: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut head = Vec::new();
    File::open(path)?.take(HEAD_BYTES).read_to_end(&mut head)?;
    Ok(head)
}

/// The newest part on disk of the recording at `first` that holds metadata, with its
/// `started_unix_ns`, if it is of the station run, session and site `metadata` names (none when
/// `metadata` names no [`STATION_RUN`]).
fn same_run_part(
    first: &Path,
    metadata: &BTreeMap<String, String>,
) -> Result<Option<(u32, String)>, RecordingError> {
    if metadata.get(STATION_RUN).is_none_or(String::is_empty) {
        return Ok(None);
    }
    for (n, path) in parts_on_disk(first)
        .map_err(io_err(first))?
        .into_iter()
        .rev()
    {
        let meta = metadata_of(&head_of(&path).map_err(io_err(&path))?);
        if meta.is_empty() {
            // Cut before its metadata reached the disk: look at the part before.
            continue;
        }
        let same = [STATION_RUN, "session", "site"]
            .into_iter()
            .all(|k| meta.get(k) == metadata.get(k));
        return Ok(match meta.get("started_unix_ns") {
            Some(started) if same => Some((n, started.clone())),
            _ => None,
        });
    }
    Ok(None)
}

/// The file being written, counting the bytes that go into it.
struct Counted {
    file: BufWriter<File>,
    written: Rc<Cell<u64>>,
}

impl Write for Counted {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.file.write(buf)?;
        self.written.set(self.written.get() + n as u64);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl Seek for Counted {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.file.seek(pos)
    }
}

/// One part being written.
struct Part {
    w: mcap::Writer<Counted>,
    path: PathBuf,
    number: u32,
    /// The JSON channels' ids, in the order they were declared.
    channels: Vec<u16>,
    /// `/tf`, `/scene`, `/log`, when the recording has a scene.
    foxglove: Option<[u16; FOXGLOVE_TOPICS.len()]>,
    /// The sample time the whole scene was last written in this part at.
    scene_ns: Option<u64>,
    written: Rc<Cell<u64>>,
    started: Instant,
    /// Messages written besides the repeated `/session`.
    messages: u64,
}

/// The metadata key naming a world's objects in order, comma-separated (a world of several only).
pub const OBJECTS_KEY: &str = "objects";

/// Writes a recording, in parts as its [`Rotation`] says.
pub struct Recorder {
    part: Part,
    first: PathBuf,
    /// The station's metadata and `started_unix_ns` (each part adds its `part`).
    metadata: BTreeMap<String, String>,
    rotation: Rotation,
    /// The `/session` message, once written: repeated at the top of every later part.
    session: Option<SessionMsg>,
    /// What the site shows, for the Foxglove channels (none: JSON channels only).
    scene: Option<Scene>,
    /// The site, in `/object` and `/tool` (the scene's, else the metadata's `site`).
    site: String,
    seq: u32,
    wall_minus_mono: i128,
    last_flush: Instant,
    /// The part an earlier process wrote last, when this recorder continues its recording.
    continued: Option<u32>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("path", &self.part.path)
            .field("seq", &self.seq)
            .finish()
    }
}

/// A recording could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// File system.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        error: std::io::Error,
    },
    /// MCAP.
    #[error("{path}: MCAP: {error}")]
    Mcap {
        /// The file.
        path: String,
        /// Why.
        error: mcap::McapError,
    },
    /// A file that is not the next part of the recording being read.
    #[error("{path}: {why}")]
    NotThisRecording {
        /// The file.
        path: String,
        /// How it differs.
        why: String,
    },
}

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> RecordingError + '_ {
    move |error| RecordingError::Io {
        path: path.display().to_string(),
        error,
    }
}

fn mcap_err(path: &Path) -> impl Fn(mcap::McapError) -> RecordingError + '_ {
    move |error| RecordingError::Mcap {
        path: path.display().to_string(),
        error,
    }
}

/// The `jsonschema` of a topic's messages.
fn schema_of(topic: &str) -> serde_json::Value {
    match topic {
        "/session" => SessionMsg::schema(),
        "/object" => ObjectPart::schema(),
        "/tool" => ToolPart::schema(),
        "/adoption" => AdoptionMsg::schema(),
        "/remote" => RemoteMsg::schema(),
        "/presence" => PresenceMsg::schema(),
        "/peer" => PeerMsg::schema(),
        "/clock" => ClockMsg::schema(),
        "/status" => StatusMsg::schema(),
        "/published" => PublishedMsg::schema(),
        "/divergence" => DivergenceMsg::schema(),
        _ => serde_json::json!({ "type": "object" }),
    }
}

impl Part {
    /// Creates (truncates) part `number` at `path` and writes its header, metadata, schemas and
    /// channels: the JSON channels `json` (each with [`schema_of`] its topic; ids in that order),
    /// then, `with_foxglove`, the [`FOXGLOVE_TOPICS`]. A station's parts are written `!chunked`
    /// (every message reaches the file at the next flush: crash-safe); a file written at once
    /// (a session file) in chunks, with their indexes, which some readers (Rerun) need.
    fn create(
        path: PathBuf,
        number: u32,
        metadata: &BTreeMap<String, String>,
        json: &[&str],
        with_foxglove: bool,
        chunked: bool,
    ) -> Result<Self, RecordingError> {
        let file = File::create(&path).map_err(io_err(&path))?;
        let written = Rc::new(Cell::new(0));
        let mut w = mcap::WriteOptions::new()
            .use_chunks(chunked)
            .profile("")
            .library(concat!("coop-haptics ", env!("CARGO_PKG_VERSION")))
            .create(Counted {
                file: BufWriter::new(file),
                written: written.clone(),
            })
            .map_err(mcap_err(&path))?;
        let mut metadata = metadata.clone();
        metadata.insert("part".into(), number.to_string());
        w.write_metadata(&mcap::records::Metadata {
            name: "coop-haptics".into(),
            metadata,
        })
        .map_err(mcap_err(&path))?;
        let mut channels = Vec::with_capacity(json.len());
        for &topic in json {
            let schema = w
                .add_schema(topic, "jsonschema", schema_of(topic).to_string().as_bytes())
                .map_err(mcap_err(&path))?;
            channels.push(
                w.add_channel(schema, topic, "json", &BTreeMap::new())
                    .map_err(mcap_err(&path))?,
            );
        }
        let foxglove = if with_foxglove {
            let mut ids = [0u16; FOXGLOVE_TOPICS.len()];
            for (c, topic) in ids.iter_mut().zip(FOXGLOVE_TOPICS) {
                let s = foxglove_schema(topic).ok_or_else(|| RecordingError::Io {
                    path: path.display().to_string(),
                    error: std::io::Error::other(format!("{topic}: the SDK gives no schema")),
                })?;
                let schema = w
                    .add_schema(&s.name, &s.encoding, &s.data)
                    .map_err(mcap_err(&path))?;
                *c = w
                    .add_channel(schema, topic, "protobuf", &BTreeMap::new())
                    .map_err(mcap_err(&path))?;
            }
            Some(ids)
        } else {
            None
        };
        if !chunked {
            // The part's metadata reaches the disk now, not at the first flush: a process killed
            // before that must leave a part a successor recognises as its run's, not an empty file.
            w.flush().map_err(mcap_err(&path))?;
        }
        Ok(Self {
            w,
            path,
            number,
            channels,
            foxglove,
            scene_ns: None,
            written,
            started: Instant::now(),
            messages: 0,
        })
    }

    /// Writes one message on channel `channel_id` at `log_time` (also its publish time), with
    /// `sequence`.
    fn write(
        &mut self,
        channel_id: u16,
        sequence: u32,
        log_time: u64,
        data: &[u8],
    ) -> Result<(), RecordingError> {
        self.w
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id,
                    sequence,
                    log_time,
                    publish_time: log_time,
                },
                data,
            )
            .map_err(mcap_err(&self.path))?;
        self.messages += 1;
        Ok(())
    }

    /// Whether the part has reached a bound (a part takes at least one message).
    fn full(&self, r: &Rotation) -> bool {
        self.messages > 0
            && (r.max_file_bytes.is_some_and(|b| self.written.get() >= b)
                || r.max_file_duration
                    .is_some_and(|d| self.started.elapsed() >= d))
    }
}

impl Recorder {
    /// Creates (truncates) `path`, the first part, and writes the header, metadata, schemas and
    /// channels; removes the parts an earlier recording left at the same path. Its directory must
    /// exist: none is created (a mistyped path must not make directories, least of all as root).
    ///
    /// # Errors
    /// The file cannot be created or written, or an earlier part cannot be removed.
    pub fn create(
        path: &Path,
        metadata: BTreeMap<String, String>,
        rotation: Rotation,
    ) -> Result<Self, RecordingError> {
        Self::create_with(path, metadata, rotation, None, false)
    }

    /// As [`Recorder::create`], and with Foxglove's `/tf`, `/scene` and `/log` channels showing
    /// `scene`: each sample's frames and scene, and a log line for each station event (the
    /// session's start, joins and leaves, losses and rejoins, [`Recorder::event`]s, the end).
    ///
    /// # Errors
    /// As [`Recorder::create`].
    pub fn create_with_scene(
        path: &Path,
        metadata: BTreeMap<String, String>,
        rotation: Rotation,
        scene: Scene,
    ) -> Result<Self, RecordingError> {
        Self::create_with(path, metadata, rotation, Some(scene), false)
    }

    /// As [`Recorder::create_with_scene`] (or [`Recorder::create`] without a scene), unless the
    /// recording at `path` is one an earlier process of the same station run wrote: `metadata`
    /// names a [`STATION_RUN`], and the newest part on disk that holds metadata names the same one
    /// (and the same session and site). Then nothing is removed: the recording goes on in the part
    /// after that one, as the same recording (its `started_unix_ns` kept), and
    /// [`Recorder::continued`] says so. A new run of the station, or a recording made without a
    /// station run, starts afresh.
    ///
    /// # Errors
    /// As [`Recorder::create`]; a part on disk that cannot be read.
    pub fn continue_or_create(
        path: &Path,
        metadata: BTreeMap<String, String>,
        rotation: Rotation,
        scene: Option<Scene>,
    ) -> Result<Self, RecordingError> {
        Self::create_with(path, metadata, rotation, scene, true)
    }

    fn create_with(
        path: &Path,
        mut metadata: BTreeMap<String, String>,
        rotation: Rotation,
        scene: Option<Scene>,
        may_continue: bool,
    ) -> Result<Self, RecordingError> {
        let earlier = if may_continue {
            same_run_part(path, &metadata)?
        } else {
            None
        };
        let wall = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        let mono = i128::from(coop_rt::timer::monotonic_ns());
        // Continuing: the parts after the earlier one hold no metadata (cut before any reached
        // the disk), so nothing of the recording is in them and `read` could not read past them.
        // Afresh: every part of an earlier recording goes (the first is written over).
        let continued = earlier.as_ref().map(|(n, _)| *n);
        let (number, started) = match earlier {
            Some((n, started)) => (n + 1, started),
            None => (0, wall.to_string()),
        };
        for (m, old) in parts_on_disk(path).map_err(io_err(path))? {
            if m > continued.unwrap_or(0) {
                std::fs::remove_file(&old).map_err(io_err(&old))?;
            }
        }
        metadata.insert("started_unix_ns".into(), started);
        if let Some(sc) = scene.as_ref().filter(|s| !s.others.is_empty()) {
            // The world's objects in order: `/object` names them, and a reader orders them by it.
            let names: Vec<String> = (0..=sc.others.len()).map(|k| sc.object_name(k)).collect();
            metadata.insert(OBJECTS_KEY.into(), names.join(","));
        }
        let site = scene
            .as_ref()
            .map(|s| s.site.clone())
            .or_else(|| metadata.get("site").cloned())
            .unwrap_or_default();
        let r = Self {
            part: Part::create(
                part_path(path, number),
                number,
                &metadata,
                &TOPICS,
                scene.is_some(),
                false,
            )?,
            first: path.to_owned(),
            metadata,
            rotation,
            session: None,
            site,
            scene,
            seq: 0,
            wall_minus_mono: wall - mono,
            last_flush: Instant::now(),
            continued,
        };
        r.remove_beyond_kept()?;
        Ok(r)
    }

    /// When this recorder continues a recording an earlier process of its station run wrote
    /// ([`Recorder::continue_or_create`]): the number of the part that process wrote last.
    pub fn continued(&self) -> Option<u32> {
        self.continued
    }

    /// Removes the oldest part beyond the ones kept, counting the one being written as the newest.
    fn remove_beyond_kept(&self) -> Result<(), RecordingError> {
        let number = self.part.number;
        let keep = u32::try_from(self.rotation.keep_files).unwrap_or(u32::MAX);
        if keep > 0 && number >= keep {
            let oldest = part_path(&self.first, number - keep);
            match std::fs::remove_file(&oldest) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(io_err(&oldest)(e));
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.part.path
    }

    /// Before a message: when the part is full, finishes it, begins the next (the `/session`
    /// message at its top) and removes the oldest part beyond the ones kept.
    fn rotate_if_full(&mut self) -> Result<(), RecordingError> {
        if !self.part.full(&self.rotation) {
            return Ok(());
        }
        let number = self.part.number + 1;
        let next = Part::create(
            part_path(&self.first, number),
            number,
            &self.metadata,
            &TOPICS,
            self.scene.is_some(),
            false,
        )?;
        let mut done = std::mem::replace(&mut self.part, next);
        done.w.finish().map_err(mcap_err(&done.path))?;
        self.remove_beyond_kept()?;
        if let Some(s) = self.session.clone() {
            self.put(0, s.t_ns, &s)?;
        }
        self.part.messages = 0;
        Ok(())
    }

    fn put<T: Serialize>(
        &mut self,
        topic: usize,
        t_ns: u64,
        msg: &T,
    ) -> Result<(), RecordingError> {
        let data = serde_json::to_vec(msg).unwrap_or_default();
        self.put_bytes(self.part.channels[topic], t_ns, &data)
    }

    /// The wall clock (ns since the Unix epoch) of monotonic time `t_ns`.
    fn wall_ns(&self, t_ns: u64) -> u64 {
        u64::try_from(i128::from(t_ns) + self.wall_minus_mono).unwrap_or(0)
    }

    /// A protobuf message on Foxglove channel `topic` (an index into [`FOXGLOVE_TOPICS`]); nothing
    /// without a scene.
    fn put_foxglove<T: Encode>(
        &mut self,
        topic: usize,
        t_ns: u64,
        msg: &T,
    ) -> Result<(), RecordingError> {
        match self.part.foxglove {
            Some(ids) => self.put_bytes(ids[topic], t_ns, &scene::encode(msg)),
            None => Ok(()),
        }
    }

    /// A `/log` line at `t_ns`, when the recording has a scene.
    fn put_log(&mut self, t_ns: u64, level: Level, text: String) -> Result<(), RecordingError> {
        let Some(scene) = &self.scene else {
            return Ok(());
        };
        let m = scene.log(self.wall_ns(t_ns), level, text);
        self.put_foxglove(2, t_ns, &m)
    }

    fn put_bytes(&mut self, channel_id: u16, t_ns: u64, data: &[u8]) -> Result<(), RecordingError> {
        self.seq = self.seq.wrapping_add(1);
        let log_time = self.wall_ns(t_ns);
        self.part.write(channel_id, self.seq, log_time, data)?;
        if self.last_flush.elapsed() >= FLUSH_EVERY {
            self.last_flush = Instant::now();
            self.part.w.flush().map_err(mcap_err(&self.part.path))?;
        }
        Ok(())
    }

    /// `/session` (and again at the top of every later part).
    ///
    /// # Errors
    /// Writing failed.
    pub fn session(&mut self, m: &SessionMsg) -> Result<(), RecordingError> {
        self.rotate_if_full()?;
        let first = self.session.is_none();
        self.session = Some(m.clone());
        self.put(0, m.t_ns, m)?;
        let text = match self.continued {
            Some(n) if first => format!(
                "station {} recording again in session {} after its network process restarted: \
                 part {} goes on from part {n}",
                m.site, m.session, self.part.number
            ),
            _ => format!(
                "station {} started in session {}: scenario {}, method {}, emulation {}",
                m.site, m.session, m.scenario, m.method, m.emulation
            ),
        };
        self.put_log(m.t_ns, Level::Info, text)
    }
    /// A record from physics' trace ring: `/adoption` for a [`TraceRecord::ADOPTION`], else
    /// `/object` and `/tool` (a [`TraceRecord::SAMPLE`]); the same messages as `Recorder::adoption`
    /// and `Recorder::sample` write.
    ///
    /// # Errors
    /// Writing failed.
    pub fn trace(&mut self, t: &TraceRecord) -> Result<(), RecordingError> {
        if t.kind == TraceRecord::ADOPTION {
            self.adoption(&AdoptionMsg::from(t))
        } else if t.object == 0 {
            self.sample(&SampleMsg::from(t))
        } else {
            self.other_object(t)
        }
    }
    /// The name `/object` gives object `k` (the scene's; without one, its index past the first).
    fn object_name(&self, k: usize) -> String {
        match &self.scene {
            Some(s) => s.object_name(k),
            None if k == 0 => String::new(),
            None => k.to_string(),
        }
    }
    /// Whether the world has several objects (`/object` names them and says which the tool
    /// touches).
    fn several(&self) -> bool {
        self.scene.as_ref().is_some_and(|s| !s.others.is_empty())
    }
    /// `/object` of the world's object `t.object` (1 or later), in the same part as the first's;
    /// with a scene, its `/tf` frame (its entity goes with the first's `/scene`).
    ///
    /// # Errors
    /// Writing failed.
    fn other_object(&mut self, t: &TraceRecord) -> Result<(), RecordingError> {
        let k = usize::try_from(t.object).unwrap_or(usize::MAX);
        self.rotate_if_full()?;
        self.put(
            1,
            t.t_ns,
            &ObjectPart {
                t_ns: t.t_ns,
                site: self.site.clone(),
                object: self.object_name(k),
                pos: t.pos,
                rot: t.rot,
                vel: t.vel,
                adoptions: t.adoptions,
                touching: Some(t.touching != 0),
            },
        )?;
        let wall = self.wall_ns(t.t_ns);
        if let Some(f) = self
            .scene
            .as_ref()
            .and_then(|s| s.other_transform(k, t.pos, t.rot, wall))
        {
            self.put_foxglove(0, t.t_ns, &f)?;
        }
        Ok(())
    }
    /// `/object` and `/tool`, in the same part; with a scene, the sample's `/tf` frames and, every
    /// [`SCENE_EVERY`] (and first in each part), its `/scene`.
    ///
    /// # Errors
    /// Writing failed.
    fn sample(&mut self, m: &SampleMsg) -> Result<(), RecordingError> {
        self.rotate_if_full()?;
        self.put(
            1,
            m.t_ns,
            &ObjectPart {
                t_ns: m.t_ns,
                site: self.site.clone(),
                object: self.object_name(0),
                pos: m.pos,
                rot: m.rot,
                vel: m.vel,
                adoptions: m.adoptions,
                touching: self.several().then_some(m.touching),
            },
        )?;
        self.put(
            2,
            m.t_ns,
            &ToolPart {
                t_ns: m.t_ns,
                site: self.site.clone(),
                tool_pos: m.tool_pos,
                f_desired: m.f_desired,
                f_measured: m.f_measured,
                f_object: m.f_object,
                touching: m.touching,
            },
        )?;
        let Some(scene) = &self.scene else {
            return Ok(());
        };
        let wall = self.wall_ns(m.t_ns);
        let frames = scene.transforms(m, wall);
        let due = self
            .part
            .scene_ns
            .is_none_or(|t| m.t_ns.saturating_sub(t) >= SCENE_EVERY.as_nanos() as u64);
        let update = due.then(|| scene.update(m, wall));
        for f in &frames {
            self.put_foxglove(0, m.t_ns, f)?;
        }
        if let Some(u) = update {
            self.put_foxglove(1, m.t_ns, &u)?;
            self.part.scene_ns = Some(m.t_ns);
        }
        Ok(())
    }
    /// One message on `topic` (an index into [`TOPICS`]), in the current part or the next.
    fn one<T: Serialize>(&mut self, topic: usize, t_ns: u64, m: &T) -> Result<(), RecordingError> {
        self.rotate_if_full()?;
        self.put(topic, t_ns, m)
    }
    /// `/adoption`.
    ///
    /// # Errors
    /// Writing failed.
    fn adoption(&mut self, m: &AdoptionMsg) -> Result<(), RecordingError> {
        self.one(3, m.t_ns, m)
    }
    /// `/remote`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn remote(&mut self, m: &RemoteMsg) -> Result<(), RecordingError> {
        self.one(4, m.t_ns, m)
    }
    /// `/presence`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn presence(&mut self, m: &PresenceMsg) -> Result<(), RecordingError> {
        self.one(5, m.t_ns, m)?;
        let what = if m.present { "joined" } else { "left" };
        self.put_log(m.t_ns, Level::Info, format!("{} {what}", m.site))
    }
    /// `/peer`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn peer(&mut self, m: &PeerMsg) -> Result<(), RecordingError> {
        self.put(9, m.t_ns, m)?;
        let (level, text) = match m.event.as_str() {
            "lost" => (
                Level::Warning,
                format!("{} lost: silent for {:.3} s", m.site, m.silent_s),
            ),
            e => (
                Level::Info,
                format!("{} {e} after {:.3} s of silence", m.site, m.silent_s),
            ),
        };
        self.put_log(m.t_ns, level, text)
    }
    /// A station event for `/log` only (nothing without a scene): `level` is Foxglove's.
    ///
    /// # Errors
    /// Writing failed.
    pub fn event(&mut self, t_ns: u64, level: Level, text: String) -> Result<(), RecordingError> {
        self.rotate_if_full()?;
        self.put_log(t_ns, level, text)
    }
    /// `/clock`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn clock(&mut self, m: &ClockMsg) -> Result<(), RecordingError> {
        self.one(6, m.t_ns, m)
    }
    /// `/status`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn status(&mut self, m: &StatusMsg) -> Result<(), RecordingError> {
        self.one(7, m.t_ns, m)?;
        let refused: u64 = m.refused.iter().sum();
        self.put_log(
            m.t_ns,
            Level::Info,
            format!(
                "station stopping: {} published, {} received, {refused} refused",
                m.published, m.received
            ),
        )
    }
    /// `/published`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn published(&mut self, m: &PublishedMsg) -> Result<(), RecordingError> {
        self.one(8, m.t_ns, m)
    }

    /// Writes the current part's summary and footer and closes it.
    ///
    /// # Errors
    /// Writing failed.
    pub fn finish(mut self) -> Result<(), RecordingError> {
        self.part.w.finish().map_err(mcap_err(&self.part.path))?;
        Ok(())
    }
}

/// A recording, read back.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recording {
    /// The session message, if the session started.
    pub session: Option<SessionMsg>,
    /// Samples (object and tool joined by time): in a world of several objects, the first
    /// object's.
    pub samples: Vec<SampleMsg>,
    /// In a world of several objects, the others', in the world's order.
    pub others: Vec<ObjectSamples>,
    /// Adoptions.
    pub adoptions: Vec<AdoptionMsg>,
    /// Remote states handed to physics.
    pub remote: Vec<RemoteMsg>,
    /// Reports published.
    pub published: Vec<PublishedMsg>,
    /// Joins and leaves.
    pub presence: Vec<PresenceMsg>,
    /// Sites lost and heard again.
    pub peers: Vec<PeerMsg>,
    /// Clock estimates.
    pub clock: Vec<ClockMsg>,
    /// Final counters, if the station stopped cleanly.
    pub status: Option<StatusMsg>,
    /// The station's events, as `/log` holds them (with a scene only).
    pub logs: Vec<LogLine>,
    /// A file ended early (no footer): the station did not finish it.
    pub truncated: bool,
    /// The files read, in order (the parts on disk).
    pub files: Vec<PathBuf>,
}

/// A `/log` line, read back.
#[derive(Debug, Clone, PartialEq)]
pub struct LogLine {
    /// When, wall clock ns since the Unix epoch (the message's log time).
    pub unix_ns: u64,
    /// Foxglove's level.
    pub level: Level,
    /// What it says.
    pub text: String,
}

/// Reads the recording whose first part is `first`: every part on disk in order, as one
/// recording (the oldest parts may have been removed; the first need not exist then). A part cut
/// short by a crash is read up to the cut.
///
/// # Errors
/// No part, a part that cannot be read, is not MCAP or has a message that is not what its channel
/// says; a part of another recording (session, site or start differ, or its `part` is not its
/// number); a part missing between two that are there.
pub fn read(first: &Path) -> Result<Recording, RecordingError> {
    let parts = parts_on_disk(first).map_err(io_err(first))?;
    if parts.is_empty() {
        // The error of the missing first file.
        return read_part(first);
    }
    let mut r = Recording::default();
    let mut seen: Option<(u32, PathBuf, BTreeMap<String, String>)> = None;
    for (n, path) in parts {
        let bytes = std::fs::read(&path).map_err(io_err(&path))?;
        let meta = metadata_of(&bytes);
        let refuse = |why: String| RecordingError::NotThisRecording {
            path: path.display().to_string(),
            why,
        };
        if let Some(p) = meta.get("part").filter(|p| **p != n.to_string()) {
            return Err(refuse(format!(
                "its metadata says part {p}, its name part {n}"
            )));
        }
        if let Some((before, before_path, before_meta)) = &seen {
            if n != before + 1 {
                return Err(refuse(format!(
                    "part {n} follows part {before} ({}): the parts between are missing",
                    before_path.display()
                )));
            }
            for key in ["session", "site", "started_unix_ns"] {
                if meta.get(key) != before_meta.get(key) {
                    return Err(refuse(format!(
                        "a part of another recording than {}: {key} {:?}, not {:?}",
                        before_path.display(),
                        meta.get(key).map_or("(none)", String::as_str),
                        before_meta.get(key).map_or("(none)", String::as_str),
                    )));
                }
            }
        }
        let p = parse(&path, &bytes)?;
        r.session = r.session.or(p.session);
        r.samples.extend(p.samples);
        for o in p.others {
            match r.others.iter_mut().find(|x| x.name == o.name) {
                Some(x) => x.samples.extend(o.samples),
                None => r.others.push(o),
            }
        }
        r.adoptions.extend(p.adoptions);
        r.remote.extend(p.remote);
        r.published.extend(p.published);
        r.presence.extend(p.presence);
        r.peers.extend(p.peers);
        r.clock.extend(p.clock);
        r.logs.extend(p.logs);
        r.status = p.status.or(r.status);
        r.truncated |= p.truncated;
        r.files.push(path.clone());
        seen = Some((n, path, meta));
    }
    Ok(r)
}

/// Reads one file written by [`Recorder`] (one part of a recording), also one cut short by a crash.
///
/// # Errors
/// The file cannot be read, is not MCAP, or a message is not what its channel says.
pub fn read_part(path: &Path) -> Result<Recording, RecordingError> {
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    parse(path, &bytes)
}

/// The metadata record of a part (empty when it has none).
fn metadata_of(bytes: &[u8]) -> BTreeMap<String, String> {
    let Ok(records) = mcap::read::LinearReader::new_with_options(
        bytes,
        mcap::read::Options::IgnoreEndMagic.into(),
    ) else {
        return BTreeMap::new();
    };
    for record in records {
        match record {
            Ok(mcap::records::Record::Metadata(m)) if m.name == "coop-haptics" => {
                return m.metadata
            }
            // Written before any schema, channel or message.
            Ok(mcap::records::Record::Header(_) | mcap::records::Record::Metadata(_)) => {}
            _ => break,
        }
    }
    BTreeMap::new()
}

/// The messages of one part.
fn parse(path: &Path, bytes: &[u8]) -> Result<Recording, RecordingError> {
    let bad = |what: String| RecordingError::Io {
        path: path.display().to_string(),
        error: std::io::Error::new(std::io::ErrorKind::InvalidData, what),
    };
    let stream =
        mcap::MessageStream::new_with_options(bytes, mcap::read::Options::IgnoreEndMagic.into())
            .map_err(mcap_err(path))?;
    let mut r = Recording {
        files: vec![path.to_owned()],
        ..Recording::default()
    };
    let mut tools: Vec<ToolPart> = Vec::new();
    let mut objects: Vec<ObjectPart> = Vec::new();
    for m in stream {
        let m = match m {
            Ok(m) => m,
            // A crash leaves a partly written last record: keep what came before it.
            Err(_) => {
                r.truncated = true;
                break;
            }
        };
        let data: &[u8] = &m.data;
        let topic = m.channel.topic.as_str();
        let e = |err: serde_json::Error| bad(format!("{topic}: {err}"));
        match topic {
            "/session" => r.session = Some(serde_json::from_slice(data).map_err(e)?),
            "/object" => objects.push(serde_json::from_slice(data).map_err(e)?),
            "/tool" => tools.push(serde_json::from_slice(data).map_err(e)?),
            "/adoption" => r.adoptions.push(serde_json::from_slice(data).map_err(e)?),
            "/remote" => r.remote.push(serde_json::from_slice(data).map_err(e)?),
            "/presence" => r.presence.push(serde_json::from_slice(data).map_err(e)?),
            "/peer" => r.peers.push(serde_json::from_slice(data).map_err(e)?),
            "/clock" => r.clock.push(serde_json::from_slice(data).map_err(e)?),
            "/status" => r.status = Some(serde_json::from_slice(data).map_err(e)?),
            "/published" => r.published.push(serde_json::from_slice(data).map_err(e)?),
            "/log" => {
                let l = <Log as foxglove::Decode>::decode(data)
                    .map_err(|err| bad(format!("/log: {err}")))?;
                r.logs.push(LogLine {
                    unix_ns: m.log_time,
                    level: Level::try_from(l.level).unwrap_or(Level::Unknown),
                    text: l.message,
                });
            }
            _ => {}
        }
    }
    r.truncated |= mcap::read::footer(bytes).is_err();
    // The first object's part comes first at every sample (a world of one names none): the
    // others are the ones named otherwise, in the order they first appear (the world's).
    // (The recording's metadata names them in order; without it, the first seen is the first.)
    let names: Vec<String> = metadata_of(bytes)
        .get(OBJECTS_KEY)
        .map(|n| n.split(',').map(str::to_owned).collect())
        .unwrap_or_default();
    let first_name = match names.first() {
        Some(n) => n.clone(),
        None => objects
            .first()
            .map(|o| o.object.clone())
            .unwrap_or_default(),
    };
    for n in names.iter().skip(1) {
        r.others.push(ObjectSamples {
            name: n.clone(),
            samples: Vec::new(),
        });
    }
    let (objects, others): (Vec<ObjectPart>, Vec<ObjectPart>) =
        objects.into_iter().partition(|o| o.object == first_name);
    for o in others {
        let at = match r.others.iter().position(|x| x.name == o.object) {
            Some(at) => at,
            None => {
                r.others.push(ObjectSamples {
                    name: o.object.clone(),
                    samples: Vec::new(),
                });
                r.others.len() - 1
            }
        };
        r.others[at].samples.push(SampleMsg {
            t_ns: o.t_ns,
            pos: o.pos,
            rot: o.rot,
            vel: o.vel,
            adoptions: o.adoptions,
            touching: o.touching.unwrap_or(false),
            ..SampleMsg::default()
        });
    }
    // Object and tool parts of one sample are written back to back with the same time.
    let mut tools = tools.into_iter().peekable();
    for o in objects {
        while tools.next_if(|t| t.t_ns < o.t_ns).is_some() {}
        let t = tools.next_if(|t| t.t_ns == o.t_ns);
        let mut s = SampleMsg {
            t_ns: o.t_ns,
            pos: o.pos,
            rot: o.rot,
            vel: o.vel,
            adoptions: o.adoptions,
            ..SampleMsg::default()
        };
        if let Some(t) = t {
            s.tool_pos = t.tool_pos;
            s.f_desired = t.f_desired;
            s.f_measured = t.f_measured;
            s.f_object = t.f_object;
            s.touching = t.touching;
        }
        r.samples.push(s);
    }
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every message of a recording, as (topic, JSON bytes), in order.
    fn messages(path: &Path) -> Vec<(String, Vec<u8>)> {
        let bytes = std::fs::read(path).expect("read");
        mcap::MessageStream::new(&bytes)
            .expect("mcap")
            .map(|m| {
                let m = m.expect("message");
                (m.channel.topic.clone(), m.data.to_vec())
            })
            .collect()
    }

    #[test]
    fn a_trace_record_is_written_as_the_sample_and_adoption_messages_are() {
        let dir = std::env::temp_dir().join(format!("coop-rec-trace-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let mut t = TraceRecord {
            kind: TraceRecord::SAMPLE,
            t_ns: 42,
            object: 0,
            pos: [0.1, 0.2, 0.3],
            rot: [1.0, 0.0, 0.0, 0.0],
            vel: [1.5, 0.0, -2.0],
            tool_pos: [3.0, 4.0, 5.0],
            f_desired: [0.5, 0.25, 0.0],
            f_measured: [-1.0, 0.0, 1.0],
            f_object: [7.0, 8.0, 9.0],
            touching: 1,
            adoptions: 3,
            from: 1,
            jump_m: 0.01,
            age_s: 0.2,
        };
        let by_trace = dir.join("trace.mcap");
        let mut w = Recorder::create(&by_trace, BTreeMap::new(), Rotation::NONE).expect("create");
        w.trace(&t).expect("w");
        t.kind = TraceRecord::ADOPTION;
        t.t_ns = 43;
        w.trace(&t).expect("w");
        w.finish().expect("finish");
        // The same, copied field by field the way the network loop did before `trace`.
        let by_fields = dir.join("fields.mcap");
        let mut w = Recorder::create(&by_fields, BTreeMap::new(), Rotation::NONE).expect("create");
        w.sample(&SampleMsg {
            t_ns: 42,
            pos: [0.1, 0.2, 0.3],
            rot: [1.0, 0.0, 0.0, 0.0],
            vel: [1.5, 0.0, -2.0],
            adoptions: 3,
            tool_pos: [3.0, 4.0, 5.0],
            f_desired: [0.5, 0.25, 0.0],
            f_measured: [-1.0, 0.0, 1.0],
            f_object: [7.0, 8.0, 9.0],
            touching: true,
        })
        .expect("w");
        w.adoption(&AdoptionMsg {
            t_ns: 43,
            from: 1,
            jump_m: 0.01,
            age_s: 0.2,
        })
        .expect("w");
        w.finish().expect("finish");
        let (a, b) = (messages(&by_trace), messages(&by_fields));
        let topics: Vec<&str> = a.iter().map(|m| m.0.as_str()).collect();
        assert_eq!(topics, ["/object", "/tool", "/adoption"]);
        assert_eq!(a, b, "the same channels and the same JSON");
        let r = read(&by_trace).expect("read");
        assert_eq!(r.samples.len(), 1);
        assert_eq!(r.samples[0].f_object, [7.0, 8.0, 9.0]);
        assert!(r.samples[0].touching);
        assert_eq!(r.adoptions[0].from, 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn every_schema_describes_what_is_written_and_types_its_arrays() {
        fn arrays_have_items(v: &serde_json::Value) -> bool {
            match v {
                serde_json::Value::Object(o) => {
                    (o.get("type") != Some(&"array".into()) || o.contains_key("items"))
                        && o.values().all(arrays_have_items)
                }
                serde_json::Value::Array(a) => a.iter().all(arrays_have_items),
                _ => true,
            }
        }
        fn keys(v: &serde_json::Value) -> Vec<String> {
            v.as_object()
                .map_or_else(Vec::new, |o| o.keys().cloned().collect())
        }
        let written = [
            ("/session", serde_json::to_value(SessionMsg::default())),
            (
                "/object",
                serde_json::to_value(ObjectPart {
                    t_ns: 0,
                    site: String::new(),
                    object: "cup".into(),
                    pos: [0.0; 3],
                    rot: [0.0; 4],
                    vel: [0.0; 3],
                    adoptions: 0,
                    touching: Some(true),
                }),
            ),
            (
                "/tool",
                serde_json::to_value(ToolPart {
                    t_ns: 0,
                    site: String::new(),
                    tool_pos: [0.0; 3],
                    f_desired: [0.0; 3],
                    f_measured: [0.0; 3],
                    f_object: [0.0; 3],
                    touching: false,
                }),
            ),
            ("/adoption", serde_json::to_value(AdoptionMsg::default())),
            ("/remote", serde_json::to_value(RemoteMsg::default())),
            ("/presence", serde_json::to_value(PresenceMsg::default())),
            ("/peer", serde_json::to_value(PeerMsg::default())),
            ("/clock", serde_json::to_value(ClockMsg::default())),
            ("/status", serde_json::to_value(StatusMsg::default())),
            ("/published", serde_json::to_value(PublishedMsg::default())),
        ];
        assert_eq!(written.len(), TOPICS.len());
        let session_file = [(
            "/divergence",
            serde_json::to_value(DivergenceMsg::default()),
        )];
        for (topic, value) in written.into_iter().chain(session_file) {
            let schema = schema_of(topic);
            assert!(arrays_have_items(&schema), "{topic}: {schema}");
            assert_eq!(
                keys(&schema["properties"]),
                keys(&value.expect("json")),
                "{topic}: the schema's properties are the fields written"
            );
        }
        assert_eq!(
            schema_of("/object")["properties"]["rot"],
            serde_json::json!({"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4})
        );
    }

    #[test]
    fn written_then_read_back_also_when_cut_short() {
        let dir = std::env::temp_dir().join(format!("coop-rec-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("a.mcap");
        let mut w = Recorder::create(
            &path,
            BTreeMap::from([("site".into(), "a".into())]),
            Rotation::NONE,
        )
        .expect("create");
        let session = SessionMsg {
            t_ns: 1,
            session: "s".into(),
            site: "a".into(),
            epoch_ns: 5,
            ..SessionMsg::default()
        };
        w.session(&session).expect("w");
        for k in 0..100u64 {
            let s = SampleMsg {
                t_ns: 10 + k,
                pos: [k as f64, 0.0, 0.0],
                rot: [1.0, 0.0, 0.0, 0.0],
                touching: k % 2 == 0,
                ..SampleMsg::default()
            };
            w.sample(&s).expect("w");
        }
        w.adoption(&AdoptionMsg {
            t_ns: 50,
            from: 1,
            jump_m: 0.01,
            age_s: 0.2,
        })
        .expect("w");
        w.status(&StatusMsg::default()).expect("w");
        w.finish().expect("finish");
        let r = read(&path).expect("read");
        assert!(!r.truncated);
        assert_eq!(r.session, Some(session));
        assert_eq!(r.samples.len(), 100);
        assert_eq!(r.samples[7].pos[0], 7.0);
        assert!(!r.samples[7].touching && r.samples[8].touching);
        assert_eq!(r.adoptions.len(), 1);
        assert!(r.status.is_some());
        // Cut the file in the middle of the data: what was before the cut is still there.
        let bytes = std::fs::read(&path).expect("bytes");
        let cut = dir.join("cut.mcap");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write");
        let r = read(&cut).expect("a cut recording still reads");
        assert!(r.truncated);
        assert!(
            r.samples.len() > 20 && r.samples.len() < 100,
            "{}",
            r.samples.len()
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A fresh directory for one test.
    fn scratch(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("coop-rec-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("dir");
        dir
    }

    /// Writes the same input (the session, `n` samples with the station's other messages among
    /// them, the final counters) to a recording at `path` bounded by `rotation`.
    fn record(path: &Path, session: &str, n: u64, rotation: Rotation) {
        let meta = BTreeMap::from([
            ("session".into(), session.to_owned()),
            ("site".into(), "a".into()),
        ]);
        // The recorder creates no directory: the test makes it.
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).expect("dir");
        }
        let mut w = Recorder::create(path, meta, rotation).expect("create");
        w.session(&SessionMsg {
            t_ns: 1,
            session: session.into(),
            site: "a".into(),
            epoch_ns: 5,
            ..SessionMsg::default()
        })
        .expect("w");
        for k in 0..n {
            let t_ns = 10 + 10 * k;
            w.sample(&SampleMsg {
                t_ns,
                pos: [k as f64, 0.0, 0.0],
                rot: [1.0, 0.0, 0.0, 0.0],
                touching: k % 2 == 0,
                ..SampleMsg::default()
            })
            .expect("w");
            if k % 7 == 0 {
                w.adoption(&AdoptionMsg {
                    t_ns,
                    from: 1,
                    jump_m: 0.01,
                    age_s: 0.2,
                })
                .expect("w");
                w.remote(&RemoteMsg {
                    t_ns,
                    seq: k,
                    via: "live".into(),
                    ..RemoteMsg::default()
                })
                .expect("w");
            }
            if k % 11 == 0 {
                w.published(&PublishedMsg {
                    t_ns,
                    seq: k,
                    state_ns: t_ns,
                })
                .expect("w");
                w.clock(&ClockMsg {
                    t_ns,
                    site: 1,
                    offset_ns: -3,
                    rtt_ns: 100,
                })
                .expect("w");
            }
            if k == 3 {
                w.presence(&PresenceMsg {
                    t_ns,
                    site: "b".into(),
                    present: true,
                })
                .expect("w");
            }
        }
        w.status(&StatusMsg {
            t_ns: 10 * n + 20,
            published: n,
            ..StatusMsg::default()
        })
        .expect("w");
        w.finish().expect("finish");
    }

    fn bytes_bound(max_file_bytes: u64, keep_files: usize) -> Rotation {
        Rotation {
            max_file_bytes: Some(max_file_bytes),
            max_file_duration: None,
            keep_files,
        }
    }

    fn files_in(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .expect("dir")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn parts_are_named_after_the_first() {
        let p = |s: &str, n| part_path(Path::new(s), n).display().to_string();
        assert_eq!(p("out/user1.mcap", 0), "out/user1.mcap");
        assert_eq!(p("out/user1.mcap", 1), "out/user1.1.mcap");
        assert_eq!(p("out/user1.mcap", 12), "out/user1.12.mcap");
        assert_eq!(p("a.b.mcap", 2), "a.b.2.mcap");
        assert_eq!(p("rec", 3), "rec.3");
    }

    #[test]
    fn a_bounded_recording_goes_on_in_parts_each_readable_alone_and_read_as_one() {
        let dir = scratch("parts");
        let (whole, parted) = (dir.join("whole.mcap"), dir.join("user1.mcap"));
        record(&whole, "s", 300, Rotation::NONE);
        let bound = 8 << 10;
        record(&parted, "s", 300, bytes_bound(bound, 0));
        let on_disk = parts_on_disk(&parted).expect("parts");
        assert!(on_disk.len() >= 4, "{:?}", files_in(&dir));
        assert_eq!(
            on_disk.iter().map(|p| p.0).collect::<Vec<_>>(),
            (0..on_disk.len() as u32).collect::<Vec<_>>()
        );
        let want = read_part(&whole).expect("whole");
        assert!(!want.truncated && want.samples.len() == 300);
        // Each part alone: a whole MCAP file with the session at its top, its number in its
        // metadata, and about the bound's size (plus its summary).
        let mut concatenated = Vec::new();
        for (n, path) in &on_disk {
            let alone = read_part(path).expect("a part reads alone");
            assert!(!alone.truncated, "{}", path.display());
            assert_eq!(alone.session, want.session, "{}", path.display());
            assert!(!alone.samples.is_empty(), "{}", path.display());
            let bytes = std::fs::read(path).expect("bytes");
            let meta = metadata_of(&bytes);
            assert_eq!(meta["part"], n.to_string());
            assert_eq!(meta["session"], "s");
            assert!(meta.contains_key("started_unix_ns"));
            assert!(
                bytes.len() < (bound as usize) + (8 << 10),
                "{}",
                bytes.len()
            );
            let m = messages(path);
            assert_eq!(m[0].0, "/session", "{}", path.display());
            concatenated.extend(m.into_iter().skip(usize::from(*n > 0)));
        }
        // Together: the same messages in the same order as the unbounded recording.
        assert_eq!(concatenated, messages(&whole));
        let got = read(&parted).expect("read the parts");
        assert_eq!(
            got.files,
            on_disk.into_iter().map(|p| p.1).collect::<Vec<_>>()
        );
        assert_eq!(
            Recording {
                files: want.files.clone(),
                ..got
            },
            want
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_part_written_for_its_time_bound_is_finished() {
        let dir = scratch("time");
        let path = dir.join("t.mcap");
        let rotation = Rotation {
            max_file_bytes: None,
            max_file_duration: Some(Duration::from_millis(20)),
            keep_files: 0,
        };
        let mut w = Recorder::create(&path, BTreeMap::new(), rotation).expect("create");
        for k in 0..3 {
            w.published(&PublishedMsg {
                t_ns: k,
                seq: k,
                state_ns: k,
            })
            .expect("w");
            assert_eq!(w.path(), part_path(&path, k as u32));
            std::thread::sleep(Duration::from_millis(25));
        }
        w.finish().expect("finish");
        assert_eq!(files_in(&dir), ["t.1.mcap", "t.2.mcap", "t.mcap"]);
        assert_eq!(read(&path).expect("read").published.len(), 3);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn beyond_the_parts_kept_the_oldest_are_removed_and_the_rest_still_read() {
        let dir = scratch("keep");
        let (whole, parted) = (dir.join("whole.mcap"), dir.join("user1.mcap"));
        record(&whole, "s", 300, Rotation::NONE);
        record(&parted, "s", 300, bytes_bound(8 << 10, 3));
        let on_disk = parts_on_disk(&parted).expect("parts");
        assert_eq!(on_disk.len(), 3, "{:?}", files_in(&dir));
        assert!(on_disk[0].0 > 0 && !parted.exists(), "the first part went");
        let want = read_part(&whole).expect("whole");
        let got = read(&parted).expect("the kept parts read without the first");
        assert_eq!(got.session, want.session, "each part repeats the session");
        assert!(got.samples.len() < 300);
        assert_eq!(got.samples[..], want.samples[300 - got.samples.len()..]);
        assert_eq!(got.status, want.status);
        // A new recording at the same path removes what the last one left.
        record(&parted, "s", 5, Rotation::NONE);
        assert_eq!(files_in(&dir), ["user1.mcap", "whole.mcap"]);
        assert_eq!(read(&parted).expect("read").samples.len(), 5);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn parts_of_different_recordings_or_with_a_gap_are_refused() {
        let dir = scratch("mix");
        let a = dir.join("a").join("user1.mcap");
        let b = dir.join("b").join("user1.mcap");
        // The recorder makes no directory.
        for d in ["a", "b"] {
            std::fs::create_dir_all(dir.join(d)).expect("dir");
        }
        record(&a, "s1", 200, bytes_bound(8 << 10, 0));
        record(&b, "s2", 200, bytes_bound(8 << 10, 0));
        assert!(parts_on_disk(&a).expect("parts").len() >= 3);
        let refused = |why: &str| {
            let e = read(&a).expect_err(why).to_string();
            assert!(e.contains(why), "{e}");
            assert!(e.contains("user1.1.mcap"), "names the part: {e}");
        };
        // Another session's part 1 among ours.
        std::fs::copy(part_path(&b, 1), part_path(&a, 1)).expect("copy");
        refused("a part of another recording");
        refused("session \"s2\", not \"s1\"");
        // The same session, another run of it (written later).
        record(&b, "s1", 200, bytes_bound(8 << 10, 0));
        std::fs::copy(part_path(&b, 1), part_path(&a, 1)).expect("copy");
        refused("started_unix_ns");
        // Part 2 renamed as part 1.
        std::fs::rename(part_path(&a, 2), part_path(&a, 1)).expect("rename");
        refused("its metadata says part 2, its name part 1");
        // A part missing in between.
        std::fs::remove_file(part_path(&a, 1)).expect("remove");
        let e = read(&a).expect_err("gap").to_string();
        assert!(e.contains("part 3 follows part 0"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_part_cut_short_is_read_up_to_the_cut() {
        let dir = scratch("cut-part");
        let path = dir.join("user1.mcap");
        record(&path, "s", 300, bytes_bound(8 << 10, 0));
        let whole = read(&path).expect("read");
        // A full part, as a crash mid-write leaves it.
        let part = part_path(&path, 1);
        let full = read_part(&part).expect("part 1").samples;
        let bytes = std::fs::read(&part).expect("bytes");
        std::fs::write(&part, &bytes[..bytes.len() / 2]).expect("cut");
        let alone = read_part(&part).expect("a cut part still reads alone");
        assert!(alone.truncated && alone.session.is_some());
        assert!(
            !alone.samples.is_empty() && alone.samples.len() < full.len(),
            "{} of {}",
            alone.samples.len(),
            full.len()
        );
        assert_eq!(alone.samples[..], full[..alone.samples.len()]);
        // With the others: everything but what was after the cut.
        let r = read(&path).expect("a recording with a cut part still reads");
        assert!(r.truncated);
        assert_eq!(
            r.samples.len() + full.len() - alone.samples.len(),
            whole.samples.len()
        );
        assert_eq!(r.status, whole.status, "the last part is whole");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn with_a_scene_every_part_holds_the_foxglove_channels_and_opens_alone() {
        use foxglove::Decode;
        let dir = scratch("foxglove");
        let path = dir.join("b.mcap");
        let scene = Scene {
            site: "b".into(),
            colour: scene::site_colour(1),
            object: scene::Body::Box {
                half: [0.02, 0.03, 0.04],
            },
            tool_radius_m: 0.005,
            planes: vec![([0.0, 0.0, 1.0], 0.0)],
            others: Vec::new(),
            first_name: String::new(),
        };
        let meta = BTreeMap::from([("site".into(), "b".into())]);
        let mut w = Recorder::create_with_scene(&path, meta, bytes_bound(64 << 10, 0), scene)
            .expect("create");
        let t0 = 1_000_000_000;
        w.session(&SessionMsg {
            t_ns: t0,
            site: "b".into(),
            ..SessionMsg::default()
        })
        .expect("w");
        let n = 1000u64;
        for i in 0..n {
            let t_ns = t0 + i * 5_000_000; // 200 Hz
            w.sample(&SampleMsg {
                t_ns,
                pos: [0.001 * i as f64, 0.0, 0.04],
                rot: [1.0, 0.0, 0.0, 0.0],
                tool_pos: [0.0, 0.0, 0.1],
                f_object: [1.0, 0.0, 0.0],
                ..SampleMsg::default()
            })
            .expect("w");
            if i == 500 {
                w.peer(&PeerMsg {
                    t_ns,
                    site: "a".into(),
                    event: "lost".into(),
                    silent_s: 0.5,
                })
                .expect("w");
            }
        }
        w.status(&StatusMsg::default()).expect("w");
        w.finish().expect("finish");
        let r = read(&path).expect("read");
        assert!(r.files.len() >= 3, "rotated: {:?}", r.files);
        assert_eq!(r.samples.len() as u64, n, "the JSON channels are as before");
        let (mut frames, mut logs) = (0u64, Vec::new());
        let mut last_tf = 0u64;
        for part in &r.files {
            let bytes = std::fs::read(part).expect("read");
            let summary = mcap::Summary::read(&bytes)
                .expect("summary")
                .expect("whole");
            let schemas: Vec<(String, String)> = summary
                .channels
                .values()
                .filter(|c| c.message_encoding == "protobuf")
                .map(|c| {
                    let s = c.schema.as_ref().expect("schema");
                    (c.topic.clone(), s.name.clone())
                })
                .collect();
            assert_eq!(
                schemas.len(),
                3,
                "{}: the Foxglove channels in every part: {schemas:?}",
                part.display()
            );
            let mut first_scene = None;
            let mut first_tf = None;
            for m in mcap::MessageStream::new(&bytes).expect("mcap") {
                let m = m.expect("message");
                let schema = m.channel.schema.as_ref().expect("schema");
                match m.channel.topic.as_str() {
                    "/tf" => {
                        assert_eq!(schema.name, "foxglove.FrameTransform");
                        assert_eq!(schema.encoding, "protobuf");
                        assert!(!schema.data.is_empty(), "the FileDescriptorSet");
                        let f = FrameTransform::decode(&m.data[..]).expect("decode");
                        assert_eq!(f.parent_frame_id, "world");
                        assert!(["object/b", "tool/b"].contains(&f.child_frame_id.as_str()));
                        assert!(m.log_time >= last_tf, "/tf in time order");
                        assert_eq!(
                            f.timestamp.map(|t| t.total_nanos()),
                            Some(m.log_time),
                            "the frame's time is the message's"
                        );
                        last_tf = m.log_time;
                        first_tf.get_or_insert(m.sequence);
                        frames += 1;
                    }
                    "/scene" => {
                        assert_eq!(schema.name, "foxglove.SceneUpdate");
                        let u = SceneUpdate::decode(&m.data[..]).expect("decode");
                        let ids: Vec<&str> = u.entities.iter().map(|e| e.id.as_str()).collect();
                        assert_eq!(ids, ["environment", "object/b", "tool/b", "force/b"]);
                        assert_eq!(
                            u.entities[1].cubes[0].size.map(|v| (v.x, v.y, v.z)),
                            Some((0.04, 0.06, 0.08))
                        );
                        first_scene.get_or_insert(m.sequence);
                    }
                    "/log" => {
                        assert_eq!(schema.name, "foxglove.Log");
                        logs.push(Log::decode(&m.data[..]).expect("decode"));
                    }
                    _ => {}
                }
            }
            // (The last part may hold only the final status, no sample.)
            assert!(
                first_tf.is_none()
                    || (first_scene.is_some() && first_scene < first_tf.map(|s| s + 3)),
                "{}: the part's scene comes with its first sample ({first_scene:?}, {first_tf:?})",
                part.display()
            );
        }
        assert_eq!(frames, 2 * n, "two frames per sample");
        let texts: Vec<&str> = logs.iter().map(|l| l.message.as_str()).collect();
        assert_eq!(texts.len(), 3, "{texts:?}");
        assert!(texts[0].starts_with("station b started"), "{texts:?}");
        assert!(texts[1].starts_with("a lost"), "{texts:?}");
        assert_eq!(logs[1].level, Level::Warning as i32);
        assert!(texts[2].starts_with("station stopping"), "{texts:?}");
        assert!(logs.iter().all(|l| l.name == "b"));
        // Cut short: the part still reads, our JSON and the Foxglove messages up to the cut.
        let part = part_path(&path, 1);
        let bytes = std::fs::read(&part).expect("bytes");
        std::fs::write(&part, &bytes[..bytes.len() / 2]).expect("cut");
        let alone = read_part(&part).expect("a cut part reads alone");
        assert!(alone.truncated && !alone.samples.is_empty());
        let cut = std::fs::read(&part).expect("bytes");
        let tf =
            mcap::MessageStream::new_with_options(&cut, mcap::read::Options::IgnoreEndMagic.into())
                .expect("mcap")
                .map_while(Result::ok)
                .filter(|m| m.channel.topic == "/tf")
                .count();
        assert!(tf > 0, "frames before the cut");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A network process killed mid-recording and restarted in the same station run: the new
    /// recorder goes on in the next part and the recording reads as one, with what the killed one
    /// got to the disk; a new run of the station starts afresh, and a part cut before its metadata
    /// reached the disk is written over.
    #[test]
    fn the_same_station_run_continues_its_recording_and_a_new_run_starts_afresh() {
        let dir = scratch("continue");
        let path = dir.join("user1.mcap");
        let meta = |run: &str| {
            BTreeMap::from([
                ("session".into(), "s".into()),
                ("site".into(), "user1".into()),
                (STATION_RUN.into(), run.into()),
            ])
        };
        let scene = || Scene {
            site: "user1".into(),
            colour: scene::site_colour(0),
            object: scene::Body::Box {
                half: [0.02, 0.02, 0.02],
            },
            tool_radius_m: 0.005,
            planes: Vec::new(),
            others: Vec::new(),
            first_name: String::new(),
        };
        let session = SessionMsg {
            t_ns: 1,
            session: "s".into(),
            site: "user1".into(),
            ..SessionMsg::default()
        };
        let sample = |k: u64| SampleMsg {
            t_ns: 10 + 10 * k,
            pos: [k as f64, 0.0, 0.0],
            rot: [1.0, 0.0, 0.0, 0.0],
            ..SampleMsg::default()
        };
        // (The Foxglove schemas alone take some 10 KiB of every part.)
        let rotation = bytes_bound(64 << 10, 0);
        let mut first = Recorder::continue_or_create(&path, meta("run-a"), rotation, Some(scene()))
            .expect("create");
        assert_eq!(first.continued(), None, "nothing to continue yet");
        first.session(&session).expect("w");
        for k in 0..1000 {
            first.sample(&sample(k)).expect("w");
        }
        let killed_in = first.part.number;
        assert!(
            (2..10).contains(&killed_in),
            "rotated a few times first: {killed_in}"
        );
        // Killed: nothing more is flushed, no footer written.
        std::mem::forget(first);
        let before = read(&path).expect("the killed process's parts read");
        assert!(before.samples.len() >= 500, "{}", before.samples.len());

        let mut second =
            Recorder::continue_or_create(&path, meta("run-a"), rotation, Some(scene()))
                .expect("continue");
        assert_eq!(second.continued(), Some(killed_in));
        assert_eq!(second.path(), part_path(&path, killed_in + 1));
        second.session(&session).expect("w");
        for k in 2000..2100 {
            second.sample(&sample(k)).expect("w");
        }
        second.status(&StatusMsg::default()).expect("w");
        let last = second.part.number;
        second.finish().expect("finish");
        let r = read(&path).expect("one recording");
        assert_eq!(r.files.len() as u32, last + 1, "{:?}", files_in(&dir));
        assert!(r.truncated, "the killed process's last part has no footer");
        assert_eq!(
            r.samples[..before.samples.len()],
            before.samples[..],
            "what the killed process wrote is all there"
        );
        let after: Vec<f64> = r.samples[before.samples.len()..]
            .iter()
            .map(|s| s.pos[0])
            .collect();
        assert_eq!(after, (2000..2100).map(|k| k as f64).collect::<Vec<_>>());
        let texts: Vec<&str> = r.logs.iter().map(|l| l.text.as_str()).collect();
        let again = format!(
            "station user1 recording again in session s after its network process restarted: part {} goes on from part {killed_in}",
            killed_in + 1
        );
        assert_eq!(
            texts.first().copied(),
            Some("station user1 started in session s: scenario , method , emulation ")
        );
        assert!(texts.contains(&again.as_str()), "{texts:?}");

        // A part begun and killed before its metadata reached the disk is written over.
        let empty = part_path(&path, last + 1);
        File::create(&empty).expect("an empty part");
        let third =
            Recorder::continue_or_create(&path, meta("run-a"), rotation, None).expect("continue");
        assert_eq!(third.continued(), Some(last));
        assert_eq!(third.path(), empty);
        third.finish().expect("finish");
        assert_eq!(read(&path).expect("read").samples, r.samples);

        // A new run of the station: afresh, the earlier run's parts gone.
        let new_run =
            Recorder::continue_or_create(&path, meta("run-b"), rotation, None).expect("create");
        assert_eq!(new_run.continued(), None);
        assert_eq!(new_run.path(), path);
        new_run.finish().expect("finish");
        assert_eq!(files_in(&dir), ["user1.mcap"]);
        assert!(read(&path).expect("read").samples.is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
