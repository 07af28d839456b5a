//! One emulated network link, for both places that emulate one: the simulator's virtual network and
//! the station's receive-side emulation. The delay swings between a minimum and a maximum with a
//! period, plus uniform jitter; a message is lost with a probability. Both draw from a seeded
//! [`Rng`] in the same order (loss, then jitter, also for a lost message), so a link behaves the
//! same wherever it is emulated.
//!
//! [`DueQueue`] holds messages until their delivery time, earliest first, ties in the order they
//! were queued.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::rng::Rng;
use crate::scenario::LinkSpec;

impl LinkSpec {
    /// The one-way delay of a message sent `since_start_s` after the session's time 0, ms, given
    /// a jitter draw in ±`jitter_ms`: `delay_min + (max − min)·(½ − ½·cos(2π t / period)) + jitter`.
    /// May be negative with a large jitter; [`LinkSpec::transmit`] clamps it at 0.
    pub fn delay_ms(&self, since_start_s: f64, jitter_draw: f64) -> f64 {
        let swing = 0.5 - 0.5 * (std::f64::consts::TAU * since_start_s / self.delay_period_s).cos();
        self.delay_min_ms + (self.delay_max_ms - self.delay_min_ms) * swing + jitter_draw
    }

    /// One message over the link: `None` if it is lost, else its delay in ns (rounded, never
    /// negative). Draws loss, then jitter, from `rng`, always both.
    pub fn transmit(&self, rng: &mut Rng, since_start_s: f64) -> Option<u64> {
        let lost = rng.uniform() < self.loss;
        let jitter = rng.range(-self.jitter_ms, self.jitter_ms);
        let delay_ms = self.delay_ms(since_start_s, jitter);
        if lost {
            return None;
        }
        Some((delay_ms.max(0.0) * 1e6).round() as u64)
    }
}

/// One queued item: ordered by due time, then by queueing order.
#[derive(Debug, Clone, Copy)]
struct Due<T> {
    at_ns: u64,
    order: u64,
    item: T,
}
impl<T> PartialEq for Due<T> {
    fn eq(&self, o: &Self) -> bool {
        (self.at_ns, self.order) == (o.at_ns, o.order)
    }
}
impl<T> Eq for Due<T> {}
impl<T> PartialOrd for Due<T> {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl<T> Ord for Due<T> {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        (self.at_ns, self.order).cmp(&(o.at_ns, o.order))
    }
}

/// Items held until a time (ns): the earliest first, items due at the same time in the order they
/// were pushed.
#[derive(Debug, Clone)]
pub struct DueQueue<T> {
    heap: BinaryHeap<Reverse<Due<T>>>,
    pushed: u64,
}

impl<T> Default for DueQueue<T> {
    fn default() -> Self {
        Self {
            heap: BinaryHeap::new(),
            pushed: 0,
        }
    }
}

impl<T> DueQueue<T> {
    /// An empty queue.
    pub fn new() -> Self {
        Self::default()
    }
    /// Holds `item` until `at_ns`.
    pub fn push(&mut self, at_ns: u64, item: T) {
        self.pushed += 1;
        self.heap.push(Reverse(Due {
            at_ns,
            order: self.pushed,
            item,
        }));
    }
    /// When the earliest item is due.
    pub fn next_at(&self) -> Option<u64> {
        self.heap.peek().map(|d| d.0.at_ns)
    }
    /// The earliest item, if it is due at or before `now_ns`.
    pub fn pop_due(&mut self, now_ns: u64) -> Option<T> {
        if self.next_at()? > now_ns {
            return None;
        }
        self.heap.pop().map(|d| d.0.item)
    }
    /// Items held.
    pub fn len(&self) -> usize {
        self.heap.len()
    }
    /// Nothing held.
    pub fn is_empty(&self) -> bool {
        self.heap.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn link() -> LinkSpec {
        LinkSpec {
            delay_min_ms: 10.0,
            delay_max_ms: 30.0,
            delay_period_s: 4.0,
            jitter_ms: 0.0,
            loss: 0.0,
        }
    }

    #[test]
    fn the_delay_swings_between_min_and_max() {
        let l = link();
        assert_eq!(l.delay_ms(0.0, 0.0), 10.0);
        assert!((l.delay_ms(2.0, 0.0) - 30.0).abs() < 1e-12);
        assert!((l.delay_ms(1.0, 0.5) - 20.5).abs() < 1e-12);
        let mut rng = Rng::new(1);
        assert_eq!(l.transmit(&mut rng, 0.0), Some(10_000_000));
    }

    #[test]
    fn a_lost_message_still_draws_its_jitter() {
        let mut l = link();
        l.loss = 1.0;
        l.jitter_ms = 5.0;
        let (mut a, mut b) = (Rng::new(9), Rng::new(9));
        assert_eq!(l.transmit(&mut a, 0.0), None);
        b.uniform();
        b.uniform();
        assert_eq!(a, b, "two draws per message, lost or not");
    }

    #[test]
    fn the_queue_releases_earliest_first_ties_in_push_order() {
        let mut q = DueQueue::new();
        q.push(20, "b");
        q.push(10, "a");
        q.push(20, "c");
        assert_eq!(q.next_at(), Some(10));
        assert_eq!(q.pop_due(5), None);
        assert_eq!(q.pop_due(20), Some("a"));
        assert_eq!(q.pop_due(20), Some("b"));
        assert_eq!(q.pop_due(20), Some("c"));
        assert!(q.is_empty());
    }
}
