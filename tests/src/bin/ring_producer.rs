//! Fixture: the producer half of a ring in its own process.
//!
//! `ring_producer RING COUNT [--hold]`: opens RING's producer half and pushes `SeqMsg` 0..COUNT,
//! spinning politely (yield) while the ring is full, then exits 0. With `--hold` it only claims the
//! half, prints `ready`, and waits to be killed (fakes a live claimant).

use coop_rt::shm::{Producer, PushError, RingOpenOptions, SegmentName, SeqMsg};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(ring), Some(count)) = (args.get(1), args.get(2)) else {
        eprintln!("usage: ring_producer RING COUNT [--hold]");
        std::process::exit(2);
    };
    let name: SegmentName = ring.parse().expect("ring name");
    let count: u64 = count.parse().expect("count");
    let mut p = Producer::<SeqMsg>::open(&name, &RingOpenOptions::default())
        .unwrap_or_else(|e| panic!("open producer: {e}"));
    println!("ready");
    if args.iter().any(|a| a == "--hold") {
        loop {
            std::thread::park();
        }
    }
    for seq in 0..count {
        let mut msg = SeqMsg::new(seq);
        loop {
            match p.push(msg) {
                Ok(()) => break,
                Err(PushError::Full(m)) => {
                    msg = m;
                    std::thread::yield_now();
                }
                Err(PushError::Corrupt(_, c)) => panic!("{c}"),
            }
        }
    }
    println!("pushed {count}");
}
