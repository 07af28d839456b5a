//! Clocks: every site answers queries for its monotonic clock, and samples every present peer's,
//! NTP-style, keeping the offset of the exchange with the shortest round trip of the last few. The
//! receive side corrects the peers' state times by these offsets.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use coop_rt::shm::control::ControlBlock;
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

/// Answers queries for this site's clock.
pub(super) fn serve(
    session: &Session,
    session_name: &str,
    site: &str,
) -> Result<Queryable<()>, NetworkError> {
    let clock_key = keys::clock(session_name, site);
    let reply_key = clock_key.clone();
    session
        .declare_queryable(clock_key)
        .callback(move |q| {
            let _ = q
                .reply(
                    reply_key.as_str(),
                    wire::encode_u64(monotonic_ns()).to_vec(),
                )
                .wait();
        })
        .wait()
        .map_err(NetworkError::declare("clock queryable"))
}

/// Samples the present peers' clocks into the control block (and `log`, for the recording).
pub(super) struct Sampler<'a> {
    pub(super) session: &'a Session,
    pub(super) session_name: &'a str,
    pub(super) sites: &'a [String],
    pub(super) me: usize,
    pub(super) ctl: &'a ControlBlock,
}

impl Sampler<'_> {
    /// The clock thread: a round over the present peers, a pause, again, until `stop`.
    pub(super) fn run(&self, log: &Mutex<Vec<ClockMsg>>, stop: &AtomicU64) {
        let mut peers = vec![ClockPeer::default(); self.sites.len()];
        let mut round = 0u32;
        while stop.load(Ordering::Relaxed) == 0 {
            let present = self.ctl.network.peers_present.load(Ordering::Relaxed);
            for (j, peer) in peers.iter_mut().enumerate() {
                if j == self.me || present & (1 << j) == 0 {
                    continue;
                }
                if let Some(m) = self.sample(j, peer) {
                    lock(log).push(m);
                }
            }
            round += 1;
            let pause = if round < 5 {
                CLOCK_EVERY / 5
            } else {
                CLOCK_EVERY
            };
            let until = Instant::now() + pause;
            while Instant::now() < until && stop.load(Ordering::Relaxed) == 0 {
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }

    /// One exchange with site `j`; its estimate goes to the control block.
    fn sample(&self, j: usize, peer: &mut ClockPeer) -> Option<ClockMsg> {
        let t0 = monotonic_ns();
        let replies = self
            .session
            .get(keys::clock(self.session_name, &self.sites[j]))
            .timeout(Duration::from_millis(200))
            .wait()
            .ok()?;
        let reply = replies.recv().ok()?;
        let t2 = monotonic_ns();
        let remote = reply
            .result()
            .ok()
            .and_then(|s| wire::decode_u64(&s.payload().to_bytes()).ok())?;
        let (rtt, offset) = clock_estimate(t0, remote, t2);
        let (rtt, offset) = peer.add(rtt, offset);
        let net = &self.ctl.network;
        net.clock_offset_ns[j].store(offset as u64, Ordering::Relaxed);
        net.clock_rtt_ns[j].store(rtt, Ordering::Relaxed);
        Some(ClockMsg {
            t_ns: t2,
            site: j,
            offset_ns: offset,
            rtt_ns: rtt,
        })
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
