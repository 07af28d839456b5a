//! Live loop statistics that another process reads without disturbing the loop (H5).
//!
//! `hdrhistogram::Histogram` owns a `Vec`, so it cannot live in shared memory. A loop instead records
//! into [`LoopStats`]: fixed arrays of atomic 1 µs buckets (cyclictest's histogram) plus counters. The
//! loop is the only writer, so each update is a relaxed load and store (no locked instruction); a
//! reader takes a [`LoopSnapshot`] and turns the buckets into hdrhistogram on its own side.

use crate::shm::ShmShared;
use crate::sync::{AtomicU64, Ordering};

/// Linear 1 µs buckets: 0 µs up to `BUCKETS - 1` µs; slower samples go to the 1 ms tail buckets.
pub const BUCKETS: usize = 2000;
/// Linear 1 ms tail buckets after the µs ones: `BUCKETS` µs up to `TAIL_END_US`; slower samples go to
/// the overflow count. A stall of a few to tens of ms (a VM's vCPU taken away, a page fault) is
/// measured here rather than guessed: a reader of a window (the difference of two snapshots) sees
/// each tail sample at its own ms, not at the loop's lifetime maximum.
pub const TAIL_BUCKETS: usize = 98;
/// Where the tail buckets end, µs: `BUCKETS` µs plus `TAIL_BUCKETS` ms (100 ms).
pub const TAIL_END_US: u64 = BUCKETS as u64 + 1_000 * TAIL_BUCKETS as u64;

/// One histogram of durations in shared memory.
#[derive(Debug)]
#[repr(C)]
pub struct SharedHistogram {
    /// Samples with `µs = i` in `buckets[i]`.
    pub buckets: [AtomicU64; BUCKETS],
    /// Samples with `µs = BUCKETS + 1000 i ..< BUCKETS + 1000 (i + 1)` in `tail[i]`.
    pub tail: [AtomicU64; TAIL_BUCKETS],
    /// Samples of [`TAIL_END_US`] or more.
    pub overflow: AtomicU64,
    /// Smallest sample in ns (0 until the first sample; see `LoopStats::cycles`).
    pub min_ns: AtomicU64,
    /// Largest sample in ns.
    pub max_ns: AtomicU64,
    /// Sum of samples in ns.
    pub sum_ns: AtomicU64,
}

impl SharedHistogram {
    /// Records one sample (`first`: the first one ever, which sets the minimum). Single writer:
    /// plain relaxed load + store, no read-modify-write.
    #[inline]
    pub fn record(&self, ns: u64, first: bool) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let us = (ns / 1_000) as usize;
        let cell = match self.buckets.get(us) {
            Some(c) => c,
            None => self
                .tail
                .get((us - BUCKETS) / 1_000)
                .unwrap_or(&self.overflow),
        };
        bump(cell, 1);
        bump(&self.sum_ns, ns);
        if first || ns < self.min_ns.load(Ordering::Relaxed) {
            self.min_ns.store(ns, Ordering::Relaxed);
        }
        if ns > self.max_ns.load(Ordering::Relaxed) {
            self.max_ns.store(ns, Ordering::Relaxed);
        }
    }

    /// An hdrhistogram (in µs) of the buckets; tail samples are recorded at their bucket's lower
    /// end (a 1 ms resolution), overflow samples at the observed maximum (at least [`TAIL_END_US`]).
    pub fn to_hdr(&self) -> hdrhistogram::Histogram<u64> {
        let max_us = (self.max_ns.load(Ordering::Relaxed) / 1_000).max(TAIL_END_US);
        let mut h = hdrhistogram::Histogram::new_with_bounds(1, max_us.max(2), 3)
            .expect("bounds 1..max with 3 digits are valid");
        for (us, b) in self.buckets.iter().enumerate() {
            let n = b.load(Ordering::Relaxed);
            if n > 0 {
                h.saturating_record_n(us as u64, n);
            }
        }
        for (i, b) in self.tail.iter().enumerate() {
            let n = b.load(Ordering::Relaxed);
            if n > 0 {
                h.saturating_record_n(BUCKETS as u64 + 1_000 * i as u64, n);
            }
        }
        let over = self.overflow.load(Ordering::Relaxed);
        if over > 0 {
            h.saturating_record_n(max_us, over);
        }
        h
    }
}

#[inline(always)]
fn bump(a: &AtomicU64, by: u64) {
    a.store(
        a.load(Ordering::Relaxed).wrapping_add(by),
        Ordering::Relaxed,
    );
}

/// A periodic loop's live statistics, in a [`crate::shm::BlockSegment`] or a control segment.
#[derive(Debug)]
#[repr(C)]
pub struct LoopStats {
    /// The loop's period in ns (set by the loop before its first cycle).
    pub period_ns: AtomicU64,
    /// Cycles completed. Stored last in each update with Release, so a reader that loads it with
    /// Acquire sees at least that many samples' worth of the other fields.
    pub cycles: AtomicU64,
    /// Deadlines missed: the loop woke after its *next* deadline had already passed.
    pub overruns: AtomicU64,
    /// Wake-up latency of the last cycle, ns (cyclictest's "Act").
    pub last_wake_ns: AtomicU64,
    /// Wake-up latency: actual wake minus scheduled deadline.
    pub wake: SharedHistogram,
    /// Compute time: from wake to the end of the cycle's work.
    pub compute: SharedHistogram,
}

// SAFETY: repr(C), made only of AtomicU64 and arrays of them; all-zero and every bit pattern are valid.
unsafe impl ShmShared for LoopStats {
    const TYPE_NAME: &'static str = "coop.LoopStats.v2";
}

impl LoopStats {
    /// Sets the period (once, before the loop starts).
    pub fn set_period_ns(&self, ns: u64) {
        self.period_ns.store(ns, Ordering::Relaxed);
    }

    /// Records one tick of a loop that has no deadlines of its own to wake to (a vendor's loop,
    /// which calls us): its lateness is its start against the previous tick's start plus the
    /// period (none for the first, `previous_ns` 0), and each whole period of it a missed tick.
    /// Only the loop that owns these statistics may call this.
    #[inline]
    pub fn record_tick(&self, started_ns: u64, previous_ns: u64, compute_ns: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let period = self.period_ns.load(Ordering::Relaxed).max(1);
        let late = if previous_ns == 0 {
            0
        } else {
            started_ns.saturating_sub(previous_ns + period)
        };
        self.record(late, compute_ns, late / period);
    }

    /// Records one cycle. Only the loop that owns these statistics may call this.
    #[inline]
    pub fn record(&self, wake_ns: u64, compute_ns: u64, missed: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let cycles = self.cycles.load(Ordering::Relaxed);
        self.wake.record(wake_ns, cycles == 0);
        self.compute.record(compute_ns, cycles == 0);
        self.last_wake_ns.store(wake_ns, Ordering::Relaxed);
        if missed > 0 {
            bump(&self.overruns, missed);
        }
        // SYNC: Release publishes this cycle's samples; pairs with the Acquire in `snapshot`.
        self.cycles.store(cycles.wrapping_add(1), Ordering::Release);
    }

    /// Copies the statistics into histograms on the reader's side. Never blocks or disturbs the writer;
    /// figures of a cycle in progress may be partly included.
    pub fn snapshot(&self) -> LoopSnapshot {
        // SYNC: Acquire pairs with the Release store of `cycles` in `record`.
        let cycles = self.cycles.load(Ordering::Acquire);
        LoopSnapshot {
            period_ns: self.period_ns.load(Ordering::Relaxed),
            cycles,
            overruns: self.overruns.load(Ordering::Relaxed),
            last_wake_ns: self.last_wake_ns.load(Ordering::Relaxed),
            wake_min_ns: self.wake.min_ns.load(Ordering::Relaxed),
            wake_max_ns: self.wake.max_ns.load(Ordering::Relaxed),
            wake_sum_ns: self.wake.sum_ns.load(Ordering::Relaxed),
            compute_max_ns: self.compute.max_ns.load(Ordering::Relaxed),
            wake_us: self.wake.to_hdr(),
            compute_us: self.compute.to_hdr(),
        }
    }
}

/// A reader's copy of [`LoopStats`].
#[derive(Debug, Clone)]
pub struct LoopSnapshot {
    /// Period, ns.
    pub period_ns: u64,
    /// Cycles completed.
    pub cycles: u64,
    /// Deadlines missed.
    pub overruns: u64,
    /// Latest wake-up latency, ns.
    pub last_wake_ns: u64,
    /// Smallest wake-up latency, ns.
    pub wake_min_ns: u64,
    /// Largest wake-up latency, ns.
    pub wake_max_ns: u64,
    /// Sum of wake-up latencies, ns.
    pub wake_sum_ns: u64,
    /// Largest compute time, ns.
    pub compute_max_ns: u64,
    /// Wake-up latency histogram, µs (1 µs buckets).
    pub wake_us: hdrhistogram::Histogram<u64>,
    /// Compute-time histogram, µs.
    pub compute_us: hdrhistogram::Histogram<u64>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shm::{BlockSegment, SegmentName};
    use std::time::Duration;

    #[test]
    fn a_second_mapping_reads_what_the_loop_recorded() {
        let name = SegmentName::new(&format!("ut{}", std::process::id()), "stats", "loop")
            .expect("valid name");
        let writer = BlockSegment::<LoopStats>::create(&name).expect("create");
        let reader = BlockSegment::<LoopStats>::open(&name, Duration::from_secs(1)).expect("open");
        writer.set_period_ns(1_000_000);
        for i in 0..1000u64 {
            // 1000 samples: 990 at 3.x µs, 9 at 40 µs, one at 5 ms (a tail bucket).
            let wake = match i {
                0 => 5_000_000,
                1..=9 => 40_000,
                _ => 3_000 + i,
            };
            writer.record(wake, 20_000, u64::from(i == 0));
        }
        let s = reader.snapshot();
        assert_eq!(s.cycles, 1000);
        assert_eq!(s.overruns, 1);
        assert_eq!(s.period_ns, 1_000_000);
        assert_eq!(s.wake_max_ns, 5_000_000);
        assert_eq!(s.wake_min_ns, 3_010);
        assert_eq!(s.wake_us.len(), 1000);
        assert_eq!(s.wake_us.value_at_quantile(0.5), 3);
        assert_eq!(s.wake_us.value_at_quantile(0.995), 40);
        assert!(s.wake_us.equivalent(s.wake_us.max(), 5_000));
        assert_eq!(s.compute_us.value_at_quantile(0.5), 20);
    }

    #[test]
    fn tail_samples_keep_their_ms_and_only_the_overflow_takes_the_maximum() {
        let h = SharedHistogram {
            buckets: std::array::from_fn(|_| AtomicU64::new(0)),
            tail: std::array::from_fn(|_| AtomicU64::new(0)),
            overflow: AtomicU64::new(0),
            min_ns: AtomicU64::new(0),
            max_ns: AtomicU64::new(0),
            sum_ns: AtomicU64::new(0),
        };
        for (i, ns) in [
            1_999_999,
            2_000_000,
            2_999_999,
            22_500_000,
            99_999_999,
            250_000_000,
        ]
        .into_iter()
        .enumerate()
        {
            h.record(ns, i == 0);
        }
        assert_eq!(h.buckets[1_999].load(Ordering::Relaxed), 1);
        assert_eq!(h.tail[0].load(Ordering::Relaxed), 2);
        assert_eq!(h.tail[20].load(Ordering::Relaxed), 1);
        assert_eq!(h.tail[TAIL_BUCKETS - 1].load(Ordering::Relaxed), 1);
        assert_eq!(h.overflow.load(Ordering::Relaxed), 1);
        let hdr = h.to_hdr();
        assert_eq!(hdr.len(), 6);
        assert_eq!(hdr.count_between(22_000, 22_999), 1);
        assert!(hdr.equivalent(hdr.max(), 250_000));
    }
}
