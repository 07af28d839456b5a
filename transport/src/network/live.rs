//! The station's live view: the newest sample of this site's copy and tool, put on
//! `coop/<session>/live/<site>` at most every [`LIVE_EVERY`] (JSON [`LiveSample`], `docs/wire.md`),
//! for a viewer anywhere in the session (`session run --live` serves it to Foxglove).
//!
//! Off the real-time path: the samples are the ones this process already drains from physics'
//! trace ring for the recording, the put is at background priority and dropped, never queued,
//! under congestion, and nothing here waits for a viewer (zenoh sends nothing while no one
//! subscribes).

use coop_rt::msg::TraceRecord;
use coop_rt::shm::control::{Traffic, WireKind};
use zenoh::pubsub::Publisher;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::{Session, Wait};

use super::NetworkError;
use crate::keys;
use crate::live_view::LIVE_EVERY_NS;
use crate::recording::LiveSample;

/// The live publisher and the newest sample not yet put.
pub(super) struct Live {
    publisher: Publisher<'static>,
    pending: Option<(TraceRecord, Vec<TraceRecord>)>,
    last_put_ns: Option<u64>,
}

impl Live {
    /// Declares `site`'s live publisher.
    pub(super) fn declare(
        session: &Session,
        session_name: &str,
        site: &str,
    ) -> Result<Self, NetworkError> {
        let publisher = session
            .declare_publisher(keys::live(session_name, site))
            .congestion_control(CongestionControl::Drop)
            .priority(Priority::Background)
            .wait()
            .map_err(NetworkError::declare("live publisher"))?;
        Ok(Self {
            publisher,
            pending: None,
            last_put_ns: None,
        })
    }

    /// Keeps `newest` (the newest sample drained this turn, if any) and puts the newest kept one
    /// when [`LIVE_EVERY_NS`] has passed since the last put.
    pub(super) fn offer(
        &mut self,
        newest: Option<(TraceRecord, Vec<TraceRecord>)>,
        now: u64,
        traffic: &Traffic,
    ) {
        if newest.is_some() {
            self.pending = newest;
        }
        if self
            .last_put_ns
            .is_some_and(|t| now.saturating_sub(t) < LIVE_EVERY_NS)
        {
            return;
        }
        let Some((t, others)) = self.pending.take() else {
            return;
        };
        // Nobody watching: nothing to send (zenoh would send nothing either), nothing counted.
        let watched = self
            .publisher
            .matching_status()
            .wait()
            .map_or(true, |m| m.matching());
        if !watched {
            return;
        }
        self.last_put_ns = Some(now);
        let bytes = serde_json::to_vec(&LiveSample::from_trace(&t, &others)).unwrap_or_default();
        // A failed put loses one frame of a viewer's picture, nothing else.
        let len = bytes.len();
        if self.publisher.put(bytes).wait().is_ok() {
            traffic.sent(WireKind::Live, len);
        }
    }
}
