//! Clocks: every site answers queries for its monotonic clock, and samples every present peer's,
//! NTP-style, keeping the offset of the exchange with the shortest round trip of the last few. The
//! receive side corrects the peers' state times by these offsets.

use std::sync::Mutex;
use std::time::Duration;

use coop_rt::shm::control::{ControlBlock, Traffic, WireKind};
use coop_rt::sync::{AtomicU64, Ordering};
use coop_rt::timer::monotonic_ns;
use zenoh::query::Queryable;
use zenoh::{Session, Wait};

use super::{lock, NetworkError};
use crate::recording::ClockMsg;
use crate::{keys, wire};

/// How often each peer's clock is sampled (the first few samples come faster).
pub const CLOCK_EVERY: Duration = Duration::from_millis(500);
/// Clock samples kept per peer; the offset comes from the one with the shortest round trip.
pub const CLOCK_WINDOW: usize = 8;

/// Per-peer clock samples.
#[derive(Debug, Default, Clone)]
pub(super) struct ClockPeer {
    samples: Vec<(u64, i64)>,
}

impl ClockPeer {
    /// Adds a sample (round trip, offset) and returns the best estimate.
    pub(super) fn add(&mut self, rtt: u64, offset: i64) -> (u64, i64) {
        if self.samples.len() == CLOCK_WINDOW {
            self.samples.remove(0);
        }
        self.samples.push((rtt, offset));
        self.samples
            .iter()
            .copied()
            .min_by_key(|s| s.0)
            .unwrap_or((rtt, offset))
    }
}

/// One NTP-style exchange: our time before, theirs, ours after → (round trip, their − our clock).
pub fn clock_estimate(t0: u64, remote: u64, t2: u64) -> (u64, i64) {
    let rtt = t2.saturating_sub(t0);
    let mid = t0 as i128 + (rtt / 2) as i128;
    (rtt, (remote as i128 - mid) as i64)
}

/// The answers a clock queryable gave since they were last counted: (messages, bytes).
#[derive(Debug, Default, Clone)]
pub(super) struct Answers(std::sync::Arc<Mutex<(u64, u64)>>);

impl Answers {
    /// Counts the answers given since the last call into `traffic`.
    pub(super) fn count(&self, traffic: &Traffic) {
        let (msgs, bytes) = std::mem::take(&mut *lock(&self.0));
        traffic.sent_msgs.count(WireKind::Clock, msgs);
        traffic.sent_bytes.count(WireKind::Clock, bytes);
    }
}

/// Answers queries for this site's clock (or, with `site` = [`crate::acl::LAUNCHER`], the
/// launcher's); the answers are counted in the [`Answers`] returned.
pub(super) fn serve(
    session: &Session,
    session_name: &str,
    site: &str,
) -> Result<(Queryable<()>, Answers), NetworkError> {
    let clock_key = keys::clock(session_name, site);
    let reply_key = clock_key.clone();
    let answers = Answers::default();
    let counted = answers.clone();
    let q = session
        .declare_queryable(clock_key)
        .callback(move |q| {
            let bytes = wire::encode_u64(monotonic_ns());
            if q.reply(reply_key.as_str(), bytes.to_vec()).wait().is_ok() {
                let mut c = lock(&counted.0);
                *c = (c.0 + 1, c.1 + bytes.len() as u64);
            }
        })
        .wait()
        .map_err(NetworkError::declare("clock queryable"))?;
    Ok((q, answers))
}

/// How often the clock thread looks for a present peer whose offset is unknown or due.
const LOOK_EVERY: Duration = Duration::from_millis(5);
/// Exchanges at the faster pace once a peer is present (a new peer's offset settles quickly).
const FAST_SAMPLES: u32 = 5;

/// One peer's sampling: its window of exchanges, how many, and when the next is due (our clock).
#[derive(Debug, Default, Clone)]
struct Peer {
    window: ClockPeer,
    count: u32,
    due_ns: u64,
}

/// Samples the present peers' clocks into the control block (and `log`, for the recording). A
/// peer whose offset is not known (it just appeared, or came back) is sampled within
/// [`LOOK_EVERY`]: until then its states cannot be read and are refused.
pub(super) struct Sampler<'a> {
    session: &'a Session,
    session_name: &'a str,
    sites: &'a [String],
    me: usize,
    ctl: &'a ControlBlock,
    peers: Mutex<Vec<Peer>>,
    log: Mutex<Vec<ClockMsg>>,
    /// The launcher's clock, sampled until the session's time 0 is taken (it is announced in the
    /// launcher's clock: [`super::epoch`] translates it with this offset).
    launcher: Mutex<Launcher>,
}

/// Exchanges with the launcher's clock made back to back (one per look, [`LOOK_EVERY`]) when it
/// appears, before its offset is trusted; then at the fast pace until time 0 is taken. The offset
/// is the shortest round trip's of the window: the first exchanges over a new link through a
/// router took 50 ms and more, and one of them alone was 10 ms off, a report period at 90 Hz;
/// three back to back take a few milliseconds more (a late joiner still takes time 0 at once).
const LAUNCHER_BURST: u32 = 3;

/// The launcher's clock as sampled: the window, how many exchanges answered, when the next is due.
#[derive(Debug, Default)]
struct Launcher {
    peer: Peer,
    best: Option<(u64, i64)>,
}

impl<'a> Sampler<'a> {
    /// A sampler of `sites`' clocks (this site is `me`).
    pub(super) fn new(
        session: &'a Session,
        session_name: &'a str,
        sites: &'a [String],
        me: usize,
        ctl: &'a ControlBlock,
    ) -> Self {
        Self {
            session,
            session_name,
            sites,
            me,
            ctl,
            peers: Mutex::new(vec![Peer::default(); sites.len()]),
            log: Mutex::default(),
            launcher: Mutex::default(),
        }
    }

    /// The launcher's clock offset (its clock − ours, ns) and the round trip it came with, once
    /// [`LAUNCHER_BURST`] exchanges answered.
    pub(super) fn launcher_offset(&self) -> Option<(u64, i64)> {
        lock(&self.launcher).best
    }

    /// The launcher's clock thread: samples it until the session's time 0 is taken (afterwards
    /// nothing needs it), or with `through_run` (a study's station: each trial's time 0 is in the
    /// runner's clock, and a restarted network process needs it again) until `stop`. A thread of
    /// its own: an exchange may wait up to its timeout for a launcher not there yet, and the
    /// peers' sampling must not wait with it.
    pub(super) fn run_launcher(&self, stop: &AtomicU64, through_run: bool) {
        while stop.load(Ordering::Relaxed) == 0 && (through_run || self.ctl.epoch().is_none()) {
            self.sample_launcher();
            std::thread::sleep(LOOK_EVERY);
        }
    }

    /// One exchange with the launcher's clock if one is due.
    fn sample_launcher(&self) {
        if monotonic_ns() < lock(&self.launcher).peer.due_ns {
            return;
        }
        let key = keys::clock(self.session_name, crate::acl::LAUNCHER);
        let t0 = monotonic_ns();
        let remote = self.ask(&key);
        let t2 = monotonic_ns();
        let mut l = lock(&self.launcher);
        let Some(remote) = remote else {
            // No launcher (yet, or any more: the next may be another machine's, with another
            // clock): start over, and look again at the fast pace.
            *l = Launcher::default();
            l.peer.due_ns = t2 + CLOCK_EVERY.as_nanos() as u64 / 5;
            return;
        };
        let (rtt, offset) = clock_estimate(t0, remote, t2);
        let best = l.peer.window.add(rtt.max(1), offset);
        l.peer.count += 1;
        if l.peer.count >= LAUNCHER_BURST {
            l.best = Some(best);
        }
        l.peer.due_ns = if l.peer.count < LAUNCHER_BURST {
            t2
        } else {
            t2 + CLOCK_EVERY.as_nanos() as u64 / 5
        };
    }

    /// Queries a clock key; the first answer's time.
    fn ask(&self, key: &str) -> Option<u64> {
        let traffic = &self.ctl.network.traffic;
        traffic.sent(WireKind::Clock, 0);
        let b = self
            .session
            .get(key)
            .timeout(Duration::from_millis(200))
            .wait()
            .ok()
            .and_then(|replies| replies.recv().ok())
            .and_then(|r| r.result().ok().map(|s| s.payload().to_bytes().to_vec()))?;
        traffic.received(WireKind::Clock, b.len());
        wire::decode_u64(&b).ok()
    }

    /// The estimates made since the last call, for the recording.
    pub(super) fn take_log(&self) -> Vec<ClockMsg> {
        std::mem::take(&mut *lock(&self.log))
    }

    fn known(&self, j: usize) -> bool {
        self.ctl.network.clock_rtt_ns[j].load(Ordering::Relaxed) > 0
    }

    /// Samples site `j` now unless its offset is already known (a late joiner reading the
    /// session's state).
    pub(super) fn sample_if_unknown(&self, j: usize) {
        if j != self.me && j < self.sites.len() && !self.known(j) {
            self.sample(j);
        }
    }

    /// The clock thread: every present peer whose offset is unknown or due is sampled, until
    /// `stop`; and a peer not present whose offset is unknown, every [`CLOCK_EVERY`]. Its
    /// liveliness token's return may never reach us (a token deleted while a link was down and
    /// declared again before the routes were back), and every track it sends is held until its
    /// offset is known: presence alone must not decide that it never will be.
    pub(super) fn run(&self, stop: &AtomicU64) {
        while stop.load(Ordering::Relaxed) == 0 {
            let present = self.ctl.network.peers_present.load(Ordering::Relaxed);
            for j in 0..self.sites.len() {
                let here = present & (1 << j) != 0;
                if j == self.me || (!here && self.known(j)) {
                    continue;
                }
                let due = {
                    let mut peers = lock(&self.peers);
                    let p = &mut peers[j];
                    if !self.known(j) && p.count > 0 {
                        // It left and came back (its run may have another clock): start over.
                        *p = Peer::default();
                    }
                    let now = monotonic_ns();
                    if here {
                        p.count == 0 || now >= p.due_ns
                    } else {
                        now >= p.due_ns
                    }
                };
                if due {
                    self.sample(j);
                    if !here && !self.known(j) {
                        // Asked again at the slow pace: a site that never joined costs one
                        // query a period, answered at once by nobody.
                        lock(&self.peers)[j].due_ns =
                            monotonic_ns() + CLOCK_EVERY.as_nanos() as u64;
                    }
                }
            }
            std::thread::sleep(LOOK_EVERY);
        }
    }

    /// One exchange with site `j`; its estimate goes to the control block.
    fn sample(&self, j: usize) {
        let t0 = monotonic_ns();
        let remote = self.ask(&keys::clock(self.session_name, &self.sites[j]));
        let t2 = monotonic_ns();
        let mut peers = lock(&self.peers);
        let p = &mut peers[j];
        let Some(remote) = remote else {
            // No answer: try again a little later.
            p.due_ns = t2 + CLOCK_EVERY.as_nanos() as u64 / 10;
            return;
        };
        let (rtt, offset) = clock_estimate(t0, remote, t2);
        let (rtt, offset) = p.window.add(rtt.max(1), offset);
        p.count += 1;
        let pace = if p.count < FAST_SAMPLES {
            CLOCK_EVERY / 5
        } else {
            CLOCK_EVERY
        };
        p.due_ns = t2 + pace.as_nanos() as u64;
        let net = &self.ctl.network;
        net.clock_offset_ns[j].store(offset as u64, Ordering::Relaxed);
        // Stored last: a round trip above 0 says the offset beside it is known.
        net.clock_rtt_ns[j].store(rtt, Ordering::Release);
        lock(&self.log).push(ClockMsg {
            t_ns: t2,
            site: j,
            offset_ns: offset,
            rtt_ns: rtt,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_estimates_take_the_shortest_round_trip() {
        // Their clock is 1000 ns ahead; the exchange took 200 ns.
        assert_eq!(clock_estimate(10_000, 11_100, 10_200), (200, 1000));
        let mut p = ClockPeer::default();
        assert_eq!(p.add(500, 40), (500, 40));
        assert_eq!(p.add(100, 5), (100, 5));
        assert_eq!(
            p.add(900, 300),
            (100, 5),
            "a slow exchange does not move the estimate"
        );
        for _ in 0..CLOCK_WINDOW {
            p.add(400, 20);
        }
        assert_eq!(p.add(400, 20), (400, 20), "old samples leave the window");
    }
}
