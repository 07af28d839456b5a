//! A station's recording: what it believed and displayed, as an [MCAP](https://mcap.dev) file that
//! Foxglove, the `mcap` CLI and the `mcap` Python package read.
//!
//! Every message is JSON (`message_encoding = "json"`, each channel with a `jsonschema` schema). Times
//! inside messages (`t_ns`) are CLOCK_MONOTONIC ns of the recording station; the MCAP `log_time` is
//! the wall clock, for viewers. Channels:
//!
//! | topic       | rate                         | contents                                              |
//! |-------------|------------------------------|-------------------------------------------------------|
//! | `/session`  | once the session time is known | session, site, scenario, method, epoch, emulation   |
//! | `/object`   | scenario sample rate         | object pose and velocity as this site believes it     |
//! | `/tool`     | scenario sample rate         | tool position, desired/measured force, force on object |
//! | `/adoption` | each adoption                | sender, position jump, how far it was dead-reckoned  |
//! | `/remote`   | each state handed to physics | sender, sequence, sent time, age, emulated delay      |
//! | `/published`| each report published        | sequence and time of the state                        |
//! | `/presence` | each join or leave           | site, present                                         |
//! | `/clock`    | each new estimate            | per peer clock offset and round trip                 |
//! | `/status`   | at the end                   | the network counters                                  |
//!
//! Physics' trace records go in whole ([`Recorder::trace`]); each channel's `jsonschema` is derived
//! from its message struct's fields.
//!
//! The file is written without chunks and flushed every [`FLUSH_EVERY`], so a crash keeps everything
//! up to the last flush; [`read`] accepts such a file (no summary, no end magic).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;
use std::time::{Duration, Instant};

use coop_rt::msg::TraceRecord;
use serde::{Deserialize, Serialize};

/// How often the writer pushes what it has to the file.
pub const FLUSH_EVERY: Duration = Duration::from_millis(200);

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

json_message! {
    #[derive(Serialize, Deserialize)]
    struct ObjectPart {
        t_ns: u64,
        pos: [f64; 3],
        rot: [f64; 4],
        vel: [f64; 3],
        adoptions: u64,
    }
}

json_message! {
    #[derive(Serialize, Deserialize)]
    struct ToolPart {
        t_ns: u64,
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
        /// Refused: version, length, contents, foreign, duplicate/out of order.
        pub refused: [u64; 5],
        /// Dropped by the emulation.
        pub emulated_lost: u64,
        /// States from the session's queryable at start.
        pub join_states: u64,
        /// Reports not published because a newer one was already waiting.
        #[serde(default)]
        pub stale_skipped: u64,
    }
}

const TOPICS: [&str; 9] = [
    "/session",
    "/object",
    "/tool",
    "/adoption",
    "/remote",
    "/presence",
    "/clock",
    "/status",
    "/published",
];

/// Writes a recording.
pub struct Recorder {
    w: mcap::Writer<BufWriter<File>>,
    channels: [u16; TOPICS.len()],
    seq: u32,
    wall_minus_mono: i128,
    last_flush: Instant,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder").field("seq", &self.seq).finish()
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
        "/clock" => ClockMsg::schema(),
        "/status" => StatusMsg::schema(),
        "/published" => PublishedMsg::schema(),
        _ => serde_json::json!({ "type": "object" }),
    }
}

impl Recorder {
    /// Creates (truncates) `path` and writes the header, schemas and channels. Its directory must
    /// exist: none is created (a mistyped path must not make directories, least of all as root).
    ///
    /// # Errors
    /// The file cannot be created or written.
    pub fn create(path: &Path, metadata: BTreeMap<String, String>) -> Result<Self, RecordingError> {
        let p = path.display().to_string();
        let mcap_err = |error| RecordingError::Mcap {
            path: p.clone(),
            error,
        };
        let file = File::create(path).map_err(|error| RecordingError::Io {
            path: p.clone(),
            error,
        })?;
        let mut w = mcap::WriteOptions::new()
            .use_chunks(false)
            .profile("")
            .library(concat!("coop-haptics ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(mcap_err)?;
        w.write_metadata(&mcap::records::Metadata {
            name: "coop-haptics".into(),
            metadata,
        })
        .map_err(mcap_err)?;
        let mut channels = [0u16; TOPICS.len()];
        for (c, topic) in channels.iter_mut().zip(TOPICS) {
            let schema = w
                .add_schema(topic, "jsonschema", schema_of(topic).to_string().as_bytes())
                .map_err(mcap_err)?;
            *c = w
                .add_channel(schema, topic, "json", &BTreeMap::new())
                .map_err(mcap_err)?;
        }
        let wall = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        let mono = i128::from(coop_rt::timer::monotonic_ns());
        Ok(Self {
            w,
            channels,
            seq: 0,
            wall_minus_mono: wall - mono,
            last_flush: Instant::now(),
        })
    }

    fn put<T: Serialize>(
        &mut self,
        topic: usize,
        t_ns: u64,
        msg: &T,
    ) -> Result<(), mcap::McapError> {
        let data = serde_json::to_vec(msg).unwrap_or_default();
        self.seq = self.seq.wrapping_add(1);
        let log_time = u64::try_from(i128::from(t_ns) + self.wall_minus_mono).unwrap_or(0);
        self.w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: self.channels[topic],
                sequence: self.seq,
                log_time,
                publish_time: log_time,
            },
            &data,
        )?;
        if self.last_flush.elapsed() >= FLUSH_EVERY {
            self.last_flush = Instant::now();
            self.w.flush()?;
        }
        Ok(())
    }

    /// `/session`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn session(&mut self, m: &SessionMsg) -> Result<(), mcap::McapError> {
        self.put(0, m.t_ns, m)
    }
    /// A record from physics' trace ring: `/adoption` for a [`TraceRecord::ADOPTION`], else
    /// `/object` and `/tool` (a [`TraceRecord::SAMPLE`]); the same messages as [`Recorder::adoption`]
    /// and [`Recorder::sample`] write.
    ///
    /// # Errors
    /// Writing failed.
    pub fn trace(&mut self, t: &TraceRecord) -> Result<(), mcap::McapError> {
        if t.kind == TraceRecord::ADOPTION {
            self.adoption(&AdoptionMsg::from(t))
        } else {
            self.sample(&SampleMsg::from(t))
        }
    }
    /// `/object` and `/tool`.
    ///
    /// # Errors
    /// Writing failed.
    fn sample(&mut self, m: &SampleMsg) -> Result<(), mcap::McapError> {
        self.put(
            1,
            m.t_ns,
            &ObjectPart {
                t_ns: m.t_ns,
                pos: m.pos,
                rot: m.rot,
                vel: m.vel,
                adoptions: m.adoptions,
            },
        )?;
        self.put(
            2,
            m.t_ns,
            &ToolPart {
                t_ns: m.t_ns,
                tool_pos: m.tool_pos,
                f_desired: m.f_desired,
                f_measured: m.f_measured,
                f_object: m.f_object,
                touching: m.touching,
            },
        )
    }
    /// `/adoption`.
    ///
    /// # Errors
    /// Writing failed.
    fn adoption(&mut self, m: &AdoptionMsg) -> Result<(), mcap::McapError> {
        self.put(3, m.t_ns, m)
    }
    /// `/remote`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn remote(&mut self, m: &RemoteMsg) -> Result<(), mcap::McapError> {
        self.put(4, m.t_ns, m)
    }
    /// `/presence`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn presence(&mut self, m: &PresenceMsg) -> Result<(), mcap::McapError> {
        self.put(5, m.t_ns, m)
    }
    /// `/clock`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn clock(&mut self, m: &ClockMsg) -> Result<(), mcap::McapError> {
        self.put(6, m.t_ns, m)
    }
    /// `/status`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn status(&mut self, m: &StatusMsg) -> Result<(), mcap::McapError> {
        self.put(7, m.t_ns, m)
    }
    /// `/published`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn published(&mut self, m: &PublishedMsg) -> Result<(), mcap::McapError> {
        self.put(8, m.t_ns, m)
    }

    /// Writes the summary and footer and closes the file.
    ///
    /// # Errors
    /// Writing failed.
    pub fn finish(mut self) -> Result<(), mcap::McapError> {
        self.w.finish()?;
        Ok(())
    }
}

/// A recording, read back.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recording {
    /// The session message, if the session started.
    pub session: Option<SessionMsg>,
    /// Samples (object and tool joined by time).
    pub samples: Vec<SampleMsg>,
    /// Adoptions.
    pub adoptions: Vec<AdoptionMsg>,
    /// Remote states handed to physics.
    pub remote: Vec<RemoteMsg>,
    /// Reports published.
    pub published: Vec<PublishedMsg>,
    /// Joins and leaves.
    pub presence: Vec<PresenceMsg>,
    /// Clock estimates.
    pub clock: Vec<ClockMsg>,
    /// Final counters, if the station stopped cleanly.
    pub status: Option<StatusMsg>,
    /// The file ended early (no footer): the station did not finish it.
    pub truncated: bool,
}

/// Reads a recording written by [`Recorder`], also one cut short by a crash.
///
/// # Errors
/// The file cannot be read, is not MCAP, or a message is not what its channel says.
pub fn read(path: &Path) -> Result<Recording, RecordingError> {
    let p = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|error| RecordingError::Io {
        path: p.clone(),
        error,
    })?;
    let mcap_err = |error| RecordingError::Mcap {
        path: p.clone(),
        error,
    };
    let bad = |what: String| RecordingError::Io {
        path: p.clone(),
        error: std::io::Error::new(std::io::ErrorKind::InvalidData, what),
    };
    let stream =
        mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
            .map_err(mcap_err)?;
    let mut r = Recording::default();
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
            "/clock" => r.clock.push(serde_json::from_slice(data).map_err(e)?),
            "/status" => r.status = Some(serde_json::from_slice(data).map_err(e)?),
            "/published" => r.published.push(serde_json::from_slice(data).map_err(e)?),
            _ => {}
        }
    }
    r.truncated |= mcap::read::footer(&bytes).is_err();
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
        let mut w = Recorder::create(&by_trace, BTreeMap::new()).expect("create");
        w.trace(&t).expect("w");
        t.kind = TraceRecord::ADOPTION;
        t.t_ns = 43;
        w.trace(&t).expect("w");
        w.finish().expect("finish");
        // The same, copied field by field the way the network loop did before `trace`.
        let by_fields = dir.join("fields.mcap");
        let mut w = Recorder::create(&by_fields, BTreeMap::new()).expect("create");
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
                    pos: [0.0; 3],
                    rot: [0.0; 4],
                    vel: [0.0; 3],
                    adoptions: 0,
                }),
            ),
            (
                "/tool",
                serde_json::to_value(ToolPart {
                    t_ns: 0,
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
            ("/clock", serde_json::to_value(ClockMsg::default())),
            ("/status", serde_json::to_value(StatusMsg::default())),
            ("/published", serde_json::to_value(PublishedMsg::default())),
        ];
        assert_eq!(written.len(), TOPICS.len());
        for (topic, value) in written {
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
        let mut w =
            Recorder::create(&path, BTreeMap::from([("site".into(), "a".into())])).expect("create");
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
}
