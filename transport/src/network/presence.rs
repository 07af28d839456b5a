//! Who is present: this site declares a liveliness token, and watches everyone's (with history, so
//! the sites already there count). Joins and leaves go to the control block and the recording; a
//! site that leaves starts its sequence afresh when it comes back.

use std::sync::{Arc, Mutex};

use coop_rt::shm::control::ControlBlock;
use coop_rt::sync::Ordering;
use coop_rt::timer::monotonic_ns;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Subscriber;
use zenoh::sample::{Sample, SampleKind};
use zenoh::{Session, Wait};

use super::receive::Receiver;
use super::{lock, NetworkError};
use crate::keys;
use crate::recording::PresenceMsg;

/// (site, present, when zenoh told us)
type Events = Arc<Mutex<Vec<(String, bool, u64)>>>;

/// This site's presence and its view of the others'.
pub(super) struct Presence {
    _token: LivelinessToken,
    _watch: Subscriber<()>,
    events: Events,
    mask: u64,
    joins: u64,
    leaves: u64,
}

impl Presence {
    /// Declares `site`'s token in the session and watches everyone's.
    pub(super) fn declare(
        session: &Session,
        session_name: &str,
        site: &str,
    ) -> Result<Self, NetworkError> {
        let token = session
            .liveliness()
            .declare_token(keys::presence(session_name, site))
            .wait()
            .map_err(NetworkError::declare("liveliness token"))?;
        let events = Events::default();
        let pe = events.clone();
        let watch = session
            .liveliness()
            .declare_subscriber(keys::all_presence(session_name))
            .history(true)
            .callback(move |s: Sample| {
                let name = keys::site_of(s.key_expr().as_str()).to_owned();
                lock(&pe).push((name, s.kind() == SampleKind::Put, monotonic_ns()));
            })
            .wait()
            .map_err(NetworkError::declare("presence subscriber"))?;
        Ok(Self {
            _token: token,
            _watch: watch,
            events,
            mask: 0,
            joins: 0,
            leaves: 0,
        })
    }

    /// Applies the joins and leaves of scenario `sites` seen since the last call (to the control
    /// block, and a leaver's sequence to `rx`), and returns them for the recording.
    pub(super) fn update(
        &mut self,
        sites: &[String],
        ctl: &ControlBlock,
        rx: &Mutex<Receiver<'_>>,
    ) -> Vec<PresenceMsg> {
        let mut out = Vec::new();
        for (name, present, at) in std::mem::take(&mut *lock(&self.events)) {
            ctl.network
                .traffic
                .received(coop_rt::shm::control::WireKind::Presence, 0);
            let Some(j) = sites.iter().position(|s| *s == name) else {
                continue;
            };
            if present {
                self.mask |= 1 << j;
                self.joins += 1;
            } else {
                self.mask &= !(1 << j);
                self.leaves += 1;
                // A site that left and comes back starts its sequence, clock and silence afresh.
                lock(rx).left(j);
            }
            ctl.network
                .peers_present
                .store(self.mask, Ordering::Relaxed);
            ctl.network.peer_joins.store(self.joins, Ordering::Relaxed);
            ctl.network
                .peer_leaves
                .store(self.leaves, Ordering::Relaxed);
            out.push(PresenceMsg {
                t_ns: at,
                site: name,
                present,
            });
        }
        out
    }
}
