//! The session's time 0, both sides: the launcher decides it and announces it on
//! `coop/<session>/epoch` (a put when decided, and a queryable for stations that start later); a
//! station that waits for it asks once at start and listens for the put. The first value a station
//! learns is kept.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use coop_rt::shm::control::ControlBlock;
use coop_rt::sync::Ordering;
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::query::Queryable;
use zenoh::sample::Sample;
use zenoh::{Session, Wait};

use super::{lock, NetworkError};
use crate::{keys, wire};

/// The launcher's side: answers for the epoch once decided, and puts it when it is.
pub struct EpochAnnouncer {
    session: Session,
    key: String,
    epoch: Arc<Mutex<Option<u64>>>,
    _queryable: Queryable<()>,
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
    /// Declares the epoch queryable of `session_name` (it answers nothing until [`Self::announce`]).
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
        Ok(Self {
            session: session.clone(),
            key: keys::epoch(session_name),
            epoch,
            _queryable: queryable,
        })
    }

    /// Time 0 is `epoch_ns` (monotonic): answered from now on, and put to the stations present.
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

/// The station's side: the launcher's put, queued for [`EpochListener::poll`].
pub(super) struct EpochListener {
    sub: Subscriber<FifoChannelHandler<Sample>>,
}

impl EpochListener {
    /// Subscribes to `session_name`'s epoch.
    pub(super) fn declare(session: &Session, session_name: &str) -> Result<Self, NetworkError> {
        let sub = session
            .declare_subscriber(keys::epoch(session_name))
            .wait()
            .map_err(NetworkError::declare("epoch subscriber"))?;
        Ok(Self { sub })
    }

    /// Takes an epoch put since the last call.
    pub(super) fn poll(&self, ctl: &ControlBlock) {
        while let Ok(Some(s)) = self.sub.try_recv() {
            adopt(ctl, &s.payload().to_bytes());
        }
    }
}

/// Asks the launcher once for the epoch, unless it is known (run on a thread of its own: the
/// answer may take up to the query's timeout).
pub(super) fn ask(session: &Session, session_name: &str, ctl: &ControlBlock) {
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
            adopt(ctl, &s.payload().to_bytes());
        }
    }
}

/// The first epoch learnt is kept.
fn adopt(ctl: &ControlBlock, bytes: &[u8]) {
    if let Ok(e) = wire::decode_u64(bytes) {
        let _ = ctl
            .epoch_ns
            .compare_exchange(0, e, Ordering::AcqRel, Ordering::Relaxed);
    }
}
