//! Publishing this site's reports: only the newest one of each object each time (states replace
//! each other, a backlog is stale), none older than [`STALE_REPORT_NS`], express at real-time priority and dropped
//! rather than queued under congestion; the last one published answers late joiners' queries for
//! the current state. The loop wakes just after physics' next report is expected ([`next_wake`]).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use coop_rt::msg::{SiteReport, ToolTrack};
use coop_rt::shm::control::{record_counted, NetworkShared, Traffic, WireKind};
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

/// This site's state keys, one per object of the world: the publishers, and the queryables
/// answering with the last state put of each.
pub(super) struct Publish {
    publishers: Vec<Publisher<'static>>,
    last: Arc<Mutex<Vec<Option<Vec<u8>>>>>,
    current: Vec<Queryable<()>>,
    /// Current states sent to late joiners since the loop last took them: (messages, bytes).
    replies: Arc<Mutex<(u64, u64)>>,
    /// Reports published.
    pub(super) published: u64,
    /// Reports not published: replaced by a newer one, or stale.
    pub(super) stale_skipped: u64,
}

impl Publish {
    /// Declares `site`'s publishers of a world of `objects` objects: one per object, on its own
    /// key (a viewer may follow one object; a receiver checks that a state is the object its
    /// key names).
    pub(super) fn declare(
        session: &Session,
        session_name: &str,
        site: &str,
        objects: usize,
    ) -> Result<Self, NetworkError> {
        let publishers = (0..objects.max(1))
            .map(|k| {
                realtime_publisher(
                    session,
                    keys::state(session_name, k as u32, site),
                    "publisher",
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            last: Arc::new(Mutex::new(vec![None; publishers.len()])),
            publishers,
            current: Vec::new(),
            replies: Arc::default(),
            published: 0,
            stale_skipped: 0,
        })
    }

    /// Answers queries for `site`'s current state of each object from now on.
    pub(super) fn serve_current(
        &mut self,
        session: &Session,
        session_name: &str,
        site: &str,
    ) -> Result<(), NetworkError> {
        for k in 0..self.publishers.len() {
            let lr = self.last.clone();
            let replies = self.replies.clone();
            let current_key = keys::current(session_name, k as u32, site);
            let reply_key = current_key.clone();
            let q = session
                .declare_queryable(current_key)
                .callback(move |q| {
                    // Replies carry this site's own key (the query's may be a wildcard).
                    if let Some(bytes) = lock(&lr)[k].clone() {
                        let len = bytes.len() as u64;
                        if q.reply(reply_key.as_str(), bytes).wait().is_ok() {
                            let mut r = lock(&replies);
                            *r = (r.0 + 1, r.1 + len);
                        }
                    }
                })
                .wait()
                .map_err(NetworkError::declare("current-state queryable"))?;
            self.current.push(q);
        }
        Ok(())
    }

    /// Counts the current states sent to late joiners since the last call into `traffic`.
    pub(super) fn count_replies(&self, traffic: &Traffic) {
        let (msgs, bytes) = std::mem::take(&mut *lock(&self.replies));
        traffic.sent_msgs.count(WireKind::State, msgs);
        traffic.sent_bytes.count(WireKind::State, bytes);
    }

    /// Publishes the newest fresh report of each object in `reports` (counted in `net`'s
    /// traffic, its wait from physics' tick to the put in `net.publish_wait`); what was put, for
    /// the recording.
    pub(super) fn newest(
        &mut self,
        reports: &mut Consumer<SiteReport>,
        net: &NetworkShared,
    ) -> Vec<PublishedMsg> {
        let traffic = &net.traffic;
        // Only the newest report of each object: states replace each other, and a backlog
        // (physics ran before this process was up, or while it restarted) is stale by
        // definition.
        let mut newest: Vec<Option<SiteReport>> = vec![None; self.publishers.len()];
        while let Ok(r) = reports.pop() {
            match newest.get_mut(r.object as usize) {
                Some(slot) => {
                    if slot.replace(r).is_some() {
                        self.stale_skipped += 1;
                    }
                }
                // Not an object of this world (physics never writes one): not published.
                None => self.stale_skipped += 1,
            }
        }
        let mut put = Vec::new();
        for (k, r) in newest.into_iter().enumerate() {
            let Some(r) = r else { continue };
            // A ring that filled up before this process was up holds old states only.
            if monotonic_ns().saturating_sub(r.t_ns) > STALE_REPORT_NS {
                self.stale_skipped += 1;
                continue;
            }
            let bytes = wire::encode(&r);
            if self.publishers[k].put(bytes.clone()).wait().is_ok() {
                let now = monotonic_ns();
                traffic.sent(WireKind::State, bytes.len());
                record_counted(
                    &net.publish_wait,
                    &net.publish_wait_count,
                    now.saturating_sub(r.t_ns),
                );
                self.published += 1;
                put.push(PublishedMsg {
                    t_ns: now,
                    seq: r.seq,
                    state_ns: r.t_ns,
                });
            }
            lock(&self.last)[k] = Some(bytes);
        }
        put
    }
}

/// This site's tool-track key (methods that exchange tools): each track is put as it comes, at
/// the state's QoS, every one: a track carries the ticks since the last report (and a few
/// reports' again), a repair or a world's other objects' states, so an older waiting one says
/// what a newer one may not. Only a stale one (older than a state may be) is skipped.
pub(super) struct TrackPublish {
    publisher: Publisher<'static>,
    /// Tracks published.
    pub(super) published: u64,
    /// Tracks not published: stale.
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

    /// Publishes every fresh track waiting in `tracks`, in order; counted in `net`'s traffic,
    /// its wait from physics' tick to the put in `net.publish_wait`.
    pub(super) fn all(&mut self, tracks: &mut Consumer<ToolTrack>, net: &NetworkShared) {
        let traffic = &net.traffic;
        while let Ok(t) = tracks.pop() {
            if monotonic_ns().saturating_sub(t.t_ns) > STALE_REPORT_NS {
                self.stale_skipped += 1;
                continue;
            }
            let bytes = wire::encode_track(&t);
            let len = bytes.len();
            if self.publisher.put(bytes).wait().is_ok() {
                traffic.sent(WireKind::Track, len);
                let wait = monotonic_ns().saturating_sub(t.t_ns);
                record_counted(&net.publish_wait, &net.publish_wait_count, wait);
                self.published += 1;
            }
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
