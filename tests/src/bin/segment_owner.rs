//! Fixture: a process that creates a ring segment and then waits to be killed, so a test can make a
//! *stale* segment (creator gone) the way a crash does.
//!
//! `segment_owner RING`: creates RING (SeqMsg, 8 slots), prints `ready`, parks forever.

use coop_rt::shm::{RingSegment, SegmentName, SeqMsg};

fn main() {
    let Some(ring) = std::env::args().nth(1) else {
        eprintln!("usage: segment_owner RING");
        std::process::exit(2);
    };
    let name: SegmentName = ring.parse().expect("ring name");
    let _ring = RingSegment::<SeqMsg>::create(&name, 8).unwrap_or_else(|e| panic!("{e}"));
    println!("ready");
    loop {
        std::thread::park();
    }
}
