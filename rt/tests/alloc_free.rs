//! The real-time paths allocate nothing (H6): a counting global allocator watches push, pop,
//! pop_newest, the timer's wait and the live statistics over thousands of calls.
//!
//! Counting is per thread, so tests running in parallel in this binary do not see each other's
//! allocations.

use std::time::Duration;

use coop_rt::shm::{BlockSegment, RingSegment, SegmentName, SeqMsg};
use coop_rt::stats::LoopStats;
use coop_rt::timer::PeriodicTimer;

mod common;
use common::counting_alloc::allocations_during;

fn name(what: &str) -> SegmentName {
    SegmentName::new(&format!("alloc{}", std::process::id()), "t", what).expect("valid name")
}

#[test]
fn counting_allocator_sees_allocations() {
    // The check itself can fail: a Vec is counted.
    assert!(allocations_during(|| drop(std::hint::black_box(vec![1u8; 64]))) >= 1);
}

#[test]
fn ring_push_pop_and_pop_newest_allocate_nothing() {
    let ring = RingSegment::<SeqMsg>::create(&name("ring"), 64).expect("create");
    let mut p = ring.producer().expect("producer");
    let mut c = ring.consumer().expect("consumer");
    let n = allocations_during(|| {
        for i in 0..100_000u64 {
            p.push(SeqMsg::new(i)).expect("room");
            let m = c.pop().expect("item");
            assert_eq!(m.seq, i);
            if i % 7 == 0 {
                // Full and empty paths, too.
                for j in 0..64 {
                    let _ = p.push(SeqMsg::new(j));
                }
                assert!(p.push(SeqMsg::new(0)).is_err());
                let newest = c.pop_newest().expect("newest");
                assert_eq!(newest.skipped, 63);
                assert!(c.pop().is_err());
            }
        }
    });
    assert_eq!(n, 0, "ring hot path allocated {n} times");
}

#[test]
fn timer_wait_and_stats_record_allocate_nothing() {
    let stats = BlockSegment::<LoopStats>::create(&name("stats")).expect("create");
    let mut timer = PeriodicTimer::new(Duration::from_micros(100));
    let n = allocations_during(|| {
        for _ in 0..2_000 {
            let w = timer.wait();
            stats.record(w.latency_ns, 1_000, w.missed);
        }
    });
    assert_eq!(n, 0, "timer/stats hot path allocated {n} times");
    assert_eq!(stats.snapshot().cycles, 2_000);
}
