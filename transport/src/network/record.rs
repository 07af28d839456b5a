//! The station's recording, from the network process: physics' trace ring drained into it, and
//! what this process saw (states received and published, presence, clocks, the session, the final
//! counters). The recorder rotates its parts as the station's [`Rotation`] says. A write that fails
//! (a full disk) stops the recording, not the station.

use std::collections::BTreeMap;
use std::path::Path;

use coop_rt::msg::TraceRecord;
use coop_rt::shm::Consumer;

use super::NetworkError;
use crate::recording::{Recorder, RecordingError, Rotation, StatusMsg};

/// The recording being written, if any.
pub(super) struct Recording {
    recorder: Option<Recorder>,
    /// The first write error since the last [`Recording::stop_on_error`].
    err: Option<String>,
}

impl Recording {
    /// Creates the recording at `path` (none: nothing is recorded) with its `metadata`, in parts
    /// bounded by `rotation`.
    pub(super) fn create(
        path: Option<&Path>,
        metadata: BTreeMap<String, String>,
        rotation: Rotation,
    ) -> Result<Self, NetworkError> {
        let recorder = match path {
            Some(p) => Some(Recorder::create(p, metadata, rotation)?),
            None => None,
        };
        Ok(Self {
            recorder,
            err: None,
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

    /// Moves physics' trace records into the recording.
    pub(super) fn drain_trace(&mut self, trace: &mut Consumer<TraceRecord>) {
        while let Ok(t) = trace.pop() {
            self.write(|w| w.trace(&t));
        }
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
