//! Receive-side emulation of the scenario's link (delay, jitter, loss, seeded), so long delays can
//! be run on one machine: each received state is held until the link would have delivered it, or
//! dropped as lost. The link itself is the simulator's ([`coop_model::link`]).

use coop_model::link::DueQueue;
use coop_model::rng::Rng;
use coop_model::scenario::LinkSpec;

/// The receive-side emulation of a link.
#[derive(Debug, Clone, PartialEq)]
pub struct Emulation {
    /// Delay, jitter and loss, as in the scenario's `[network]`.
    pub link: LinkSpec,
    /// The scenario's seed (each link draws from its own stream of it, as in the simulator).
    pub seed: u64,
}

impl Emulation {
    /// A one-line description, as status and recordings show it.
    pub fn describe(&self) -> String {
        let l = &self.link;
        format!(
            "EMULATED: delay {}–{} ms (period {} s), jitter ±{} ms, loss {:.1} %, seed {}",
            l.delay_min_ms,
            l.delay_max_ms,
            l.delay_period_s,
            l.jitter_ms,
            l.loss * 100.0,
            self.seed
        )
    }
}

/// The emulated links into this site, and the states (or, as `T`, tool tracks: their own links
/// with the same law and seed) they still hold.
#[derive(Debug)]
pub(super) struct Emulator<T> {
    link: LinkSpec,
    /// One generator per sending site.
    rngs: Vec<Rng>,
    held: DueQueue<T>,
}

impl<T> Emulator<T> {
    /// The links from each of `n` sites to site `me`.
    pub(super) fn new(e: &Emulation, n: usize, me: usize) -> Self {
        Self {
            link: e.link.clone(),
            // Link from→me draws from stream from·n + me, as the simulator's links do.
            rngs: (0..n)
                .map(|from| Rng::derive(e.seed, (from * n + me) as u64))
                .collect(),
            held: DueQueue::new(),
        }
    }

    /// When a state `from` sent at `sent_ns` (sender's time corrected to ours) arrives, or `None` if
    /// the link loses it; the delay swings with the time since the session's `epoch`.
    pub(super) fn arrival(&mut self, from: usize, sent_ns: u64, epoch: Option<u64>) -> Option<u64> {
        let since_epoch = epoch.map_or(0.0, |e| sent_ns.saturating_sub(e) as f64 * 1e-9);
        let delay_ns = self.link.transmit(&mut self.rngs[from], since_epoch)?;
        Some(sent_ns + delay_ns)
    }

    /// Holds `d` until `at_ns`.
    pub(super) fn hold(&mut self, at_ns: u64, d: T) {
        self.held.push(at_ns, d);
    }

    /// The next held state due at or before `now`.
    pub(super) fn pop_due(&mut self, now: u64) -> Option<T> {
        self.held.pop_due(now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emulation_is_described_as_emulated() {
        let e = Emulation {
            link: LinkSpec::default(),
            seed: 3,
        };
        assert!(e.describe().starts_with("EMULATED"));
    }

    #[test]
    fn a_lossless_link_delays_by_its_minimum_at_time_zero() {
        let e = Emulation {
            link: LinkSpec {
                delay_min_ms: 50.0,
                delay_max_ms: 50.0,
                delay_period_s: 1.0,
                jitter_ms: 0.0,
                loss: 0.0,
            },
            seed: 1,
        };
        let mut em: Emulator<u8> = Emulator::new(&e, 2, 1);
        assert_eq!(em.arrival(0, 1_000, Some(1_000)), Some(50_001_000));
    }
}
