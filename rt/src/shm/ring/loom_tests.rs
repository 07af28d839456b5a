//! loom models of the ring's memory ordering (H14): every interleaving of the producer and consumer
//! threads is explored, and loom's cell checks that each slot write happens-before its read.
//!
//! Run: `RUSTFLAGS="--cfg loom" cargo test -p coop-rt --lib --release loom`.

use super::{heap_ring, PopError, PushError};
use loom::thread;

fn push_all(p: &mut super::Producer<u64>, values: std::ops::Range<u64>) {
    for v in values {
        let mut v = v;
        loop {
            match p.push(v) {
                Ok(()) => break,
                Err(PushError::Full(back)) => {
                    v = back;
                    thread::yield_now();
                }
                Err(PushError::Corrupt(..)) => panic!("indices corrupt in a model run"),
            }
        }
    }
}

/// Every pushed value arrives once, in order, through a ring smaller than the message count (so the
/// producer must see the consumer's head to reuse a slot).
#[test]
fn loom_push_pop_in_order() {
    loom::model(|| {
        let (mut p, mut c) = heap_ring::<u64>(2);
        let producer = thread::spawn(move || push_all(&mut p, 0..3));
        let mut next = 0;
        while next < 3 {
            match c.pop() {
                Ok(v) => {
                    assert_eq!(v, next);
                    next += 1;
                }
                Err(PopError::Empty) => thread::yield_now(),
                Err(PopError::Corrupt(c)) => panic!("{c}"),
            }
        }
        producer.join().expect("producer");
        assert_eq!(c.pop(), Err(PopError::Empty));
    });
}

/// Once the consumer sees the producer abandoned the ring, everything it pushed before is readable:
/// nothing is lost, nothing appears after.
#[test]
fn loom_abandon_loses_nothing() {
    loom::model(|| {
        let (mut p, mut c) = heap_ring::<u64>(2);
        let producer = thread::spawn(move || {
            push_all(&mut p, 0..2);
            drop(p);
        });
        let mut got = Vec::new();
        loop {
            match c.pop() {
                Ok(v) => got.push(v),
                Err(PopError::Empty) => {
                    if c.is_abandoned() {
                        while let Ok(v) = c.pop() {
                            got.push(v);
                        }
                        break;
                    }
                    thread::yield_now();
                }
                Err(PopError::Corrupt(c)) => panic!("{c}"),
            }
        }
        producer.join().expect("producer");
        assert_eq!(got, vec![0, 1]);
    });
}

/// `pop_newest` returns the latest published value and accounts for every older one as skipped.
#[test]
fn loom_pop_newest_accounts_for_everything() {
    loom::model(|| {
        let (mut p, mut c) = heap_ring::<u64>(4);
        let producer = thread::spawn(move || push_all(&mut p, 0..3));
        let mut seen = 0u64; // values consumed so far (read or skipped)
        while seen < 3 {
            match c.pop_newest() {
                Ok(n) => {
                    assert_eq!(n.value, seen + n.skipped);
                    seen = n.value + 1;
                }
                Err(PopError::Empty) => thread::yield_now(),
                Err(PopError::Corrupt(c)) => panic!("{c}"),
            }
        }
        producer.join().expect("producer");
    });
}
