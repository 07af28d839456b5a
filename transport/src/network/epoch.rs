//! The session's time 0, both sides: the launcher decides it in its own clock and announces it on
//! `coop/<session>/epoch` (a put when decided, and a queryable for stations that start later), and
//! answers queries for its clock on `coop/<session>/clock/launcher`. A station that waits for it
//! asks once at start and listens for the put; it samples the launcher's clock NTP-style (as it
//! samples its peers') and takes time 0 only once it knows the offset, translated into its own
//! clock, so that scripts start together on machines whose clocks differ by anything. The first
//! value a station learns is kept.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use coop_rt::shm::control::ControlBlock;
use coop_rt::sync::{AtomicU64, Ordering};
use coop_rt::timer::monotonic_ns;
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::query::Queryable;
use zenoh::sample::Sample;
use zenoh::{Session, Wait};

use super::{lock, NetworkError};
use crate::{keys, wire};

/// The launcher's side: answers for its clock, and for the epoch once decided, and puts it when it
/// is.
pub struct EpochAnnouncer {
    session: Session,
    key: String,
    epoch: Arc<Mutex<Option<u64>>>,
    _queryable: Queryable<()>,
    _clock: Queryable<()>,
}

impl std::fmt::Debug for EpochAnnouncer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EpochAnnouncer")
            .field("key", &self.key)
            .field("epoch", &*lock(&self.epoch))
            .finish()
    }
}

impl EpochAnnouncer {
    /// Declares the epoch queryable of `session_name` (it answers nothing until [`Self::announce`])
    /// and the launcher's clock queryable.
    ///
    /// # Errors
    /// Zenoh refuses the queryable.
    pub fn declare(session: &Session, session_name: &str) -> Result<Self, NetworkError> {
        let epoch: Arc<Mutex<Option<u64>>> = Arc::default();
        let e = epoch.clone();
        let queryable = session
            .declare_queryable(keys::epoch(session_name))
            .callback(move |q| {
                let v = *lock(&e);
                if let Some(v) = v {
                    let _ = q
                        .reply(q.key_expr().clone(), wire::encode_u64(v).to_vec())
                        .wait();
                }
            })
            .wait()
            .map_err(NetworkError::declare("epoch queryable"))?;
        let (clock, _launcher_answers) =
            super::clock::serve(session, session_name, crate::acl::LAUNCHER)?;
        Ok(Self {
            session: session.clone(),
            key: keys::epoch(session_name),
            epoch,
            _queryable: queryable,
            _clock: clock,
        })
    }

    /// Time 0 is `epoch_ns` (this launcher's CLOCK_MONOTONIC; each station translates it into its
    /// own): answered from now on, and put to the stations present.
    ///
    /// # Errors
    /// Zenoh refuses the put.
    pub fn announce(&self, epoch_ns: u64) -> Result<(), NetworkError> {
        *lock(&self.epoch) = Some(epoch_ns);
        self.session
            .put(self.key.as_str(), wire::encode_u64(epoch_ns).to_vec())
            .wait()
            .map_err(|error| NetworkError::Put {
                what: "announcing the session start",
                error,
            })
    }
}

/// How long a station holds an announced time 0 whose launcher clock it has not measured before it
/// says so as an error (it goes on holding: an untranslated time 0 would start its script early or
/// late by the clocks' difference, which across machines is anything).
pub const EPOCH_HOLD_LIMIT: Duration = Duration::from_secs(5);

/// The station's side: the launcher's put (or its answer to the one-off query), in the launcher's
/// clock, held until the launcher's clock offset is measured, then translated into this station's
/// clock and taken ([`EpochListener::poll`]).
pub(super) struct EpochListener {
    sub: Subscriber<FifoChannelHandler<Sample>>,
    /// The first time 0 heard, in the launcher's clock (0: none yet).
    heard: AtomicU64,
    /// When it was heard (our clock), and whether the hold was said and its limit passed.
    hold: Mutex<Hold>,
    site: String,
}

#[derive(Debug, Default)]
struct Hold {
    since_ns: u64,
    said: bool,
    over_limit: bool,
}

impl EpochListener {
    /// Subscribes to `session_name`'s epoch (for `site`'s log lines).
    pub(super) fn declare(
        session: &Session,
        session_name: &str,
        site: &str,
    ) -> Result<Self, NetworkError> {
        let sub = session
            .declare_subscriber(keys::epoch(session_name))
            .wait()
            .map_err(NetworkError::declare("epoch subscriber"))?;
        Ok(Self {
            sub,
            heard: AtomicU64::new(0),
            hold: Mutex::default(),
            site: site.to_owned(),
        })
    }

    /// The first time 0 learnt is kept.
    fn hear(&self, bytes: &[u8]) {
        if let Ok(e) = wire::decode_u64(bytes) {
            if e != 0
                && self
                    .heard
                    .compare_exchange(0, e, Ordering::AcqRel, Ordering::Relaxed)
                    .is_ok()
            {
                lock(&self.hold).since_ns = monotonic_ns();
            }
        }
    }

    /// Takes an epoch put since the last call and, once `launcher` (the launcher's clock offset
    /// and round trip, [`super::clock::Sampler::launcher_offset`]) is known, the session's time 0
    /// in this station's clock: the announced time minus the offset. Until then it holds it, with
    /// one line on stderr, and one more if the hold passes [`EPOCH_HOLD_LIMIT`].
    pub(super) fn poll(&self, ctl: &ControlBlock, launcher: Option<(u64, i64)>) {
        while let Ok(Some(s)) = self.sub.try_recv() {
            self.hear(&s.payload().to_bytes());
        }
        let heard = self.heard.load(Ordering::Acquire);
        if heard == 0 || ctl.epoch().is_some() {
            return;
        }
        let mut hold = lock(&self.hold);
        let Some((rtt, offset)) = launcher else {
            let held = monotonic_ns().saturating_sub(hold.since_ns);
            if !hold.said {
                hold.said = true;
                eprintln!(
                    "station {}: the session's time 0 is announced; holding it until the launcher's clock offset is measured (the users' scripts wait)",
                    self.site
                );
            } else if !hold.over_limit && held > EPOCH_HOLD_LIMIT.as_nanos() as u64 {
                hold.over_limit = true;
                eprintln!(
                    "station {}: ERROR: the launcher's clock has not answered for {:?} since the session's time 0 was announced; the users' scripts do not start until it does (is the launcher running, and may it answer its clock under the access control?)",
                    self.site, EPOCH_HOLD_LIMIT
                );
            }
            return;
        };
        let local = translate(heard, offset);
        // SYNC: Release pairs with `ControlBlock::epoch`'s Acquire.
        if ctl
            .epoch_ns
            .compare_exchange(0, local, Ordering::AcqRel, Ordering::Relaxed)
            .is_ok()
        {
            eprintln!(
                "station {}: the session's time 0 taken, translated by the launcher's clock offset {:+.3} ms (round trip {:.3} ms){}",
                self.site,
                offset as f64 * 1e-6,
                rtt as f64 * 1e-6,
                if hold.said {
                    format!(
                        " after holding it {:.0} ms",
                        monotonic_ns().saturating_sub(hold.since_ns) as f64 * 1e-6
                    )
                } else {
                    String::new()
                }
            );
        }
    }
}

/// Time 0 announced as `launcher_ns` in the launcher's clock, in ours: `offset_ns` is the
/// launcher's clock minus ours (never 0, which means "not known" in the control block).
pub fn translate(launcher_ns: u64, offset_ns: i64) -> u64 {
    (i128::from(launcher_ns) - i128::from(offset_ns)).clamp(1, i128::from(u64::MAX)) as u64
}

/// Asks the launcher once for the epoch, unless it is known (run on a thread of its own: the
/// answer may take up to the query's timeout).
pub(super) fn ask(
    session: &Session,
    session_name: &str,
    ctl: &ControlBlock,
    listener: &EpochListener,
) {
    if ctl.epoch().is_some() {
        return;
    }
    let Ok(replies) = session
        .get(keys::epoch(session_name))
        .timeout(Duration::from_secs(2))
        .wait()
    else {
        return;
    };
    while let Ok(reply) = replies.recv() {
        if let Ok(s) = reply.result() {
            listener.hear(&s.payload().to_bytes());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::translate;

    #[test]
    fn time_0_is_translated_into_the_stations_clock() {
        // The launcher's clock is 1000 s behind ours (we live in a time namespace 1000 s ahead).
        assert_eq!(
            translate(5_000_000_000, -1_000_000_000_000),
            1_005_000_000_000
        );
        // Ahead of ours by 2 ms.
        assert_eq!(translate(5_000_000_000, 2_000_000), 4_998_000_000);
        // Never 0 (unknown) or below.
        assert_eq!(translate(1_000, 5_000), 1);
    }
}
