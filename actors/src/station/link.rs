//! What `station run` says when its network process cannot link.
//!
//! A network process in client mode whose links fail exits quietly and is restarted with
//! backoff; this side of the station says why, once: after a failure it probes the `connect`
//! locators itself, as the network process did ([`coop_transport::network::probe`]), off the
//! supervisor's thread. A cause is said when it is new; the same cause again is only counted, and
//! the count is said with the next cause (or when the network comes up again), so a router that
//! stays down for an hour is one line, not one per retry. The cause also goes to the network's
//! last failure in the control block, where `station status` shows it.

use coop_transport::network::link::{self, LinkFailures};
use coop_transport::network::{probe, Mode};
use tokio::task::JoinHandle;

use super::config::Resolved;

/// The causes said so far, and a probe under way.
#[derive(Debug, Default)]
pub(super) struct LinkTeller {
    /// The cause said last, while the network is down.
    said: Option<LinkFailures>,
    /// How many more failures found that same cause.
    repeats: u32,
    /// Whether the last probe found the cause said (not a failure of another kind since).
    current: bool,
    /// The network's last failure a probe was started for.
    probed_for: Option<String>,
    /// The probe under way.
    probing: Option<JoinHandle<Vec<link::LinkFailure>>>,
}

impl LinkTeller {
    /// The network process failed with `failure` (the supervisor's words): probes its links,
    /// unless this failure was probed already or a probe is under way.
    pub(super) fn failed(&mut self, cfg: &Resolved, failure: &str) {
        if self.probing.is_some() || self.probed_for.as_deref() == Some(failure) {
            return;
        }
        self.probed_for = Some(failure.to_owned());
        let net = cfg.config.network.clone();
        // A client's session opens only when one of its links does; a peer's opens without them,
        // so its failures are not its links'.
        if net.mode != Mode::Client || net.connect.is_empty() {
            return;
        }
        let side = coop_transport::network::station_side(net.mode);
        self.probing = Some(tokio::task::spawn_blocking(move || {
            probe::diagnose(&net.connect, net.tls.as_ref(), side)
        }));
    }

    /// Whether a probe is under way.
    pub(super) fn probing(&self) -> bool {
        self.probing.is_some()
    }

    /// The probe's result, once it is done (pending while none is under way).
    pub(super) async fn probed(&mut self) -> Vec<link::LinkFailure> {
        let Some(p) = &mut self.probing else {
            return std::future::pending().await;
        };
        let found = p.await.unwrap_or_default();
        self.probing = None;
        found
    }

    /// What to say of what the probe `found`: its cause if it is new (nothing: the same cause
    /// again, counted; or no link fails, the network process having said its own error).
    pub(super) fn tell(&mut self, found: Vec<link::LinkFailure>) -> Option<String> {
        self.current = !found.is_empty();
        if found.is_empty() {
            return None;
        }
        let found = LinkFailures(found);
        if self.said.as_ref() == Some(&found) {
            self.repeats += 1;
            return None;
        }
        let before = match (&self.said, self.repeats) {
            (Some(_), n) if n > 0 => {
                format!(" (the cause before was found {n} more time(s) after it was said)")
            }
            _ => String::new(),
        };
        let line = format!("the network cannot link: {found}{before}");
        self.said = Some(found);
        self.repeats = 0;
        Some(line)
    }

    /// The network is up again: what to say (how often the last cause came back after it was
    /// said, if it did); the cause is forgotten, so the next failure is said anew.
    pub(super) fn up(&mut self) -> Option<String> {
        let line = (self.said.take().is_some() && self.repeats > 0).then(|| {
            format!(
                "the network links now (the last cause was found {} more time(s) after it was said)",
                self.repeats
            )
        });
        self.repeats = 0;
        self.current = false;
        self.probed_for = None;
        line
    }

    /// The cause of the network's last failure, for its last failure in the control block.
    pub(super) fn cause(&self) -> Option<String> {
        self.said
            .as_ref()
            .filter(|_| self.current)
            .map(ToString::to_string)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use coop_transport::network::link::{Cause, Far, Files, LinkFailure, Side};

    fn failure(cause: Cause) -> Vec<LinkFailure> {
        vec![LinkFailure {
            locator: "tls/127.0.0.1:7447".into(),
            side: Side {
                me: "station",
                far: Far::Router,
                files: Files::Table("network.tls"),
            },
            cause: Box::new(cause),
        }]
    }

    /// A cause is said once; the same again is counted, and the count said with the next cause
    /// or when the network links; a probe that finds nothing says nothing.
    #[test]
    fn a_cause_is_said_once_and_its_repeats_with_the_next() {
        let mut t = LinkTeller::default();
        let down = t.tell(failure(Cause::NothingListens)).expect("said");
        assert_eq!(
            down,
            "the network cannot link: nothing listens on tls/127.0.0.1:7447: is the router running?"
        );
        assert_eq!(
            t.cause().as_deref(),
            Some(&down["the network cannot link: ".len()..])
        );
        for _ in 0..3 {
            assert_eq!(t.tell(failure(Cause::NothingListens)), None);
        }
        assert_eq!(t.tell(Vec::new()), None, "not the links: nothing to say");
        assert_eq!(t.cause(), None, "and no cause to show");
        let changed = t
            .tell(failure(Cause::UnknownIssuer { root_ca: None }))
            .expect("a new cause");
        assert!(
            changed.ends_with("(the cause before was found 3 more time(s) after it was said)"),
            "{changed}"
        );
        assert_eq!(
            t.tell(failure(Cause::UnknownIssuer { root_ca: None })),
            None
        );
        assert_eq!(
            t.up().as_deref(),
            Some(
                "the network links now (the last cause was found 1 more time(s) after it was said)"
            )
        );
        assert!(
            t.tell(failure(Cause::NothingListens)).is_some(),
            "after it linked, a failure is said anew"
        );
        assert_eq!(t.up(), None, "said once and never again: nothing to add");
    }
}
