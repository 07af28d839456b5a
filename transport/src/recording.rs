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
//! | `/task`     | each change of the task's outcome | running, done or failed, when, and what failed it |
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

use std::path::Path;
use std::time::Duration;

/// Foxglove's log level ([`LogLine::level`], [`Recorder::event`]).
pub use foxglove::messages::log::Level;

mod messages;
mod part;
mod parts;
mod reader;
pub mod scene;
pub mod session;
#[cfg(test)]
mod test_support;
mod topic;
mod writer;

pub use messages::{
    AdoptionMsg, ClockMsg, DeviceMsg, DivergenceMsg, LiveSample, ObjectPose, ObjectSamples,
    PeerMsg, PresenceMsg, PublishedMsg, RemoteMsg, SampleMsg, SessionMsg, StatusMsg, TaskMsg,
    TrafficMsg, WIRE_KINDS,
};
pub use parts::{part_path, Rotation};
pub use reader::{read, read_part, LogLine, Recording};
pub use scene::Scene;
pub use writer::Recorder;

/// How often the writer pushes what it has to the file.
pub const FLUSH_EVERY: Duration = Duration::from_millis(200);
/// The metadata key naming the station run a recording belongs to (the run's supervisor, as
/// `coop_rt::shm::BlockSegment::creator` of its control block gives it): a recorder created with
/// the same one at the same path continues the recording ([`Recorder::continue_or_create`]).
pub const STATION_RUN: &str = "station_run";
/// How often, in sample time, the whole `/scene` is written (the frames move it in between).
pub const SCENE_EVERY: Duration = Duration::from_millis(50);
/// The metadata key naming a world's objects in order, comma-separated (a world of several only).
pub const OBJECTS_KEY: &str = "objects";

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
