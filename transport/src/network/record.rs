//! The station's recording, from the network process: physics' trace ring drained into it, and
//! what this process saw (states received and published, presence, clocks, the session, the final
//! counters), with Foxglove's channels showing the site's [`Scene`] and its events (including the
//! servo's display going stale and fresh again, watched in the control block). The recorder rotates
//! its parts as the station's [`Rotation`] says. A write that fails (a full disk) stops the
//! recording, not the station.

use std::collections::BTreeMap;
use std::path::Path;

use coop_rt::msg::TraceRecord;
use coop_rt::shm::control::ControlBlock;
use coop_rt::shm::Consumer;
use coop_rt::sync::Ordering;
use foxglove::messages::log::Level;

use super::NetworkError;
use crate::recording::{Recorder, RecordingError, Rotation, Scene, StatusMsg};

/// The recording being written, if any.
pub(super) struct Recording {
    recorder: Option<Recorder>,
    /// The first write error since the last [`Recording::stop_on_error`].
    err: Option<String>,
    /// The servo's display was stale at the last look (none: not looked yet).
    stale: Option<bool>,
}

impl Recording {
    /// Creates the recording at `path` (none: nothing is recorded) with its `metadata`, in parts
    /// bounded by `rotation`, showing `scene` on the Foxglove channels (none: JSON channels only).
    pub(super) fn create(
        path: Option<&Path>,
        metadata: BTreeMap<String, String>,
        rotation: Rotation,
        scene: Option<Scene>,
    ) -> Result<Self, NetworkError> {
        let recorder = match (path, scene) {
            (Some(p), Some(scene)) => {
                Some(Recorder::create_with_scene(p, metadata, rotation, scene)?)
            }
            (Some(p), None) => Some(Recorder::create(p, metadata, rotation)?),
            (None, _) => None,
        };
        Ok(Self {
            recorder,
            err: None,
            stale: None,
        })
    }

    /// Writes with `f`, remembering the first error.
    pub(super) fn write(&mut self, f: impl FnOnce(&mut Recorder) -> Result<(), RecordingError>) {
        if let Some(r) = &mut self.recorder {
            if let Err(e) = f(r) {
                self.err
                    .get_or_insert(format!("writing the recording: {e}"));
            }
        }
    }

    /// Moves physics' trace records into the recording; returns the newest sample among them.
    pub(super) fn drain_trace(&mut self, trace: &mut Consumer<TraceRecord>) -> Option<TraceRecord> {
        let mut newest = None;
        while let Ok(t) = trace.pop() {
            self.write(|w| w.trace(&t));
            if t.kind == TraceRecord::SAMPLE {
                newest = Some(t);
            }
        }
        newest
    }

    /// Logs the servo's display going stale (its scale below 1: the newest object state is older
    /// than the stale limit) and fresh again, as the control block shows it at `now`.
    pub(super) fn watch_servo(&mut self, ctl: &ControlBlock, now: u64) {
        let scale = f64::from_bits(ctl.servo.scale.load(Ordering::Relaxed));
        let stale = scale < 1.0;
        if self.stale == Some(stale) || (self.stale.is_none() && !stale) {
            self.stale = Some(stale);
            return;
        }
        self.stale = Some(stale);
        let (level, text) = if stale {
            (
                Level::Warning,
                format!("stale: the object state is past the stale limit; the force display ramps to zero (scale {scale:.2})"),
            )
        } else {
            (Level::Info, "fresh: the force display is back".to_owned())
        };
        self.write(|w| w.event(now, level, text));
    }

    /// After a failed write: says so once and stops recording.
    pub(super) fn stop_on_error(&mut self, site: &str) {
        if let Some(e) = self.err.take() {
            // A full disk must not take the station down.
            eprintln!("network {site}: {e}; recording stopped");
            self.recorder = None;
        }
    }

    /// Writes the final counters and closes the file.
    pub(super) fn finish(mut self, site: &str, status: &StatusMsg) {
        if let Some(mut r) = self.recorder.take() {
            let _ = r.status(status);
            if let Err(e) = r.finish() {
                eprintln!("network {site}: finishing the recording: {e}");
            }
        }
    }
}
