//! Publishing this site's reports: only the newest one each time (states replace each other, a
//! backlog is stale), none older than [`STALE_REPORT_NS`], express at real-time priority and dropped
//! rather than queued under congestion; the last one published answers late joiners' queries for
//! the current state. The loop wakes just after physics' next report is expected ([`next_wake`]).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use coop_rt::msg::{SiteReport, ToolTrack};
use coop_rt::shm::Consumer;
use coop_rt::timer::monotonic_ns;
use zenoh::pubsub::Publisher;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::query::Queryable;
use zenoh::{Session, Wait};

use super::{lock, NetworkError};
use crate::recording::PublishedMsg;
use crate::{keys, wire};

/// The loop's longest sleep: it drains the trace ring, releases emulated messages and beats its
/// heartbeat at least this often.
pub const POLL: Duration = Duration::from_millis(1);
/// How long after physics' expected next report the loop looks for it (physics' wake latency and
/// step), and how often it looks again while the report is late. Every state waits at least this
/// on its way out: 40 µs and 25 µs put stations at 2× a bare zenoh ping-pong's one way at p50
/// (`session bench-router`), 20 µs and 10 µs 1.3–1.5×; a report later than this costs a few
/// more turns of the loop, at most until [`GIVE_UP_NS`].
pub const PUBLISH_LAG_NS: u64 = 20_000;
/// See [`PUBLISH_LAG_NS`].
pub const RETRY_NS: u64 = 10_000;
/// Past this lateness physics is taken to be stopped (restarting), and the loop polls at [`POLL`].
pub const GIVE_UP_NS: u64 = 500_000;
/// A report older than this when the network process gets to it is not published (ns).
pub const STALE_REPORT_NS: u64 = 100_000_000;

/// When the loop wakes next: just after physics' next report is expected (it tells its last report
/// time and its period in the control block), soon again if that report is late, never later
/// than [`POLL`].
pub fn next_wake(period: u64, last: u64, now: u64) -> u64 {
    let poll = now + POLL.as_nanos() as u64;
    if period == 0 || last == 0 {
        return poll;
    }
    let expected = last + period;
    if now < expected + PUBLISH_LAG_NS {
        (expected + PUBLISH_LAG_NS).min(poll)
    } else if now < expected + GIVE_UP_NS {
        now + RETRY_NS
    } else {
        poll
    }
}

/// A publisher at the states' QoS: dropped rather than queued under congestion (a newer report
/// replaces it), real-time priority, sent at once (`express`, no batching).
fn realtime_publisher(
    session: &Session,
    key: String,
    what: &'static str,
) -> Result<Publisher<'static>, NetworkError> {
    session
        .declare_publisher(key)
        .congestion_control(CongestionControl::Drop)
        .priority(Priority::RealTime)
        .express(true)
        .wait()
        .map_err(NetworkError::declare(what))
}

/// This site's state key: the publisher, and the queryable answering with the last state put.
pub(super) struct Publish {
    publisher: Publisher<'static>,
    last: Arc<Mutex<Option<Vec<u8>>>>,
    current: Option<Queryable<()>>,
    /// Reports published.
    pub(super) published: u64,
    /// Reports not published: replaced by a newer one, or stale.
    pub(super) stale_skipped: u64,
}

impl Publish {
    /// Declares `site`'s publisher.
    pub(super) fn declare(
        session: &Session,
        session_name: &str,
        site: &str,
    ) -> Result<Self, NetworkError> {
        let publisher =
            realtime_publisher(session, keys::state(session_name, 0, site), "publisher")?;
        Ok(Self {
            publisher,
            last: Arc::default(),
            current: None,
            published: 0,
            stale_skipped: 0,
        })
    }

    /// Answers queries for `site`'s current state from now on.
    pub(super) fn serve_current(
        &mut self,
        session: &Session,
        session_name: &str,
        site: &str,
    ) -> Result<(), NetworkError> {
        let lr = self.last.clone();
        let current_key = keys::current(session_name, 0, site);
        let reply_key = current_key.clone();
        let q = session
            .declare_queryable(current_key)
            .callback(move |q| {
                // Replies carry this site's own key (the query's may be a wildcard).
                if let Some(bytes) = lock(&lr).clone() {
                    let _ = q.reply(reply_key.as_str(), bytes).wait();
                }
            })
            .wait()
            .map_err(NetworkError::declare("current-state queryable"))?;
        self.current = Some(q);
        Ok(())
    }

    /// Publishes the newest report in `reports`, if there is a fresh one; what was put, for the
    /// recording.
    pub(super) fn newest(&mut self, reports: &mut Consumer<SiteReport>) -> Option<PublishedMsg> {
        // Only the newest report: states replace each other, and a backlog (physics ran before
        // this process was up, or while it restarted) is stale by definition.
        let newest = reports.pop_newest().ok()?;
        self.stale_skipped += newest.skipped;
        // A ring that filled up before this process was up holds old states only.
        if monotonic_ns().saturating_sub(newest.value.t_ns) > STALE_REPORT_NS {
            self.stale_skipped += 1;
            return None;
        }
        let r = newest.value;
        let bytes = wire::encode(&r);
        let put = self.publisher.put(bytes.clone()).wait().is_ok().then(|| {
            self.published += 1;
            PublishedMsg {
                t_ns: monotonic_ns(),
                seq: r.seq,
                state_ns: r.t_ns,
            }
        });
        *lock(&self.last) = Some(bytes);
        put
    }
}

/// This site's tool-track key (methods that exchange tools): each track is put as it comes, at
/// the state's QoS. Only the newest waiting one: a track repeats the last 256 ticks, so a newer
/// one holds everything an older one said.
pub(super) struct TrackPublish {
    publisher: Publisher<'static>,
    /// Tracks published.
    pub(super) published: u64,
    /// Tracks not published: replaced by a newer one, or stale.
    pub(super) stale_skipped: u64,
}

impl TrackPublish {
    /// Declares `site`'s tool-track publisher.
    pub(super) fn declare(
        session: &Session,
        session_name: &str,
        site: &str,
    ) -> Result<Self, NetworkError> {
        let publisher = realtime_publisher(
            session,
            keys::tool(session_name, 0, site),
            "tool track publisher",
        )?;
        Ok(Self {
            publisher,
            published: 0,
            stale_skipped: 0,
        })
    }

    /// Publishes the newest track in `tracks`, if there is a fresh one.
    pub(super) fn newest(&mut self, tracks: &mut Consumer<ToolTrack>) {
        let Ok(newest) = tracks.pop_newest() else {
            return;
        };
        self.stale_skipped += newest.skipped;
        if monotonic_ns().saturating_sub(newest.value.t_ns) > STALE_REPORT_NS {
            self.stale_skipped += 1;
            return;
        }
        if self
            .publisher
            .put(wire::encode_track(&newest.value))
            .wait()
            .is_ok()
        {
            self.published += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_loop_wakes_just_after_the_next_report() {
        let ms = 1_000_000;
        // Nothing known yet: poll.
        assert_eq!(next_wake(0, 0, 10 * ms), 11 * ms);
        // Last report at 10 ms, every 1 ms, now 10.5 ms: wake PUBLISH_LAG_NS after 11 ms.
        assert_eq!(
            next_wake(ms, 10 * ms, 10 * ms + ms / 2),
            11 * ms + PUBLISH_LAG_NS
        );
        // Late: look again soon.
        assert_eq!(
            next_wake(ms, 10 * ms, 11 * ms + 100_000),
            11 * ms + 100_000 + RETRY_NS
        );
        // Long late (physics restarting): poll.
        assert_eq!(next_wake(ms, 10 * ms, 12 * ms), 13 * ms);
        // A slow report rate: never sleep past the poll period.
        assert_eq!(next_wake(50 * ms, 10 * ms, 10 * ms), 11 * ms);
    }
}
