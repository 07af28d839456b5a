//! Fixture: the consumer half of a ring in its own process, checking every message.
//!
//! `ring_consumer RING (COUNT | --until-abandoned)`: pops `SeqMsg`s and checks each is intact and is
//! exactly the next sequence number. Stops after COUNT messages, or once the producer abandoned the
//! ring and everything it pushed was drained. Prints `received N last L` and exits 0; exits 1 on the
//! first missing, repeated, reordered or torn message.

use coop_rt::shm::{Consumer, PopError, RingOpenOptions, SegmentName, SeqMsg};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(ring), Some(mode)) = (args.get(1), args.get(2)) else {
        eprintln!("usage: ring_consumer RING (COUNT | --until-abandoned)");
        std::process::exit(2);
    };
    let name: SegmentName = ring.parse().expect("ring name");
    let limit: Option<u64> = (mode != "--until-abandoned").then(|| mode.parse().expect("count"));
    let mut c = Consumer::<SeqMsg>::open(&name, &RingOpenOptions::default())
        .unwrap_or_else(|e| panic!("open consumer: {e}"));
    println!("ready");
    let mut next = 0u64;
    let mut idle = 0u32;
    let mut abandoned = false;
    while limit.is_none_or(|l| next < l) {
        match c.pop() {
            Ok(m) => {
                idle = 0;
                if m.seq != next || !m.is_intact() {
                    eprintln!("expected seq {next}, got {m:?}");
                    std::process::exit(1);
                }
                next += 1;
            }
            Err(PopError::Empty) if abandoned => break,
            Err(PopError::Empty) => {
                idle += 1;
                // is_abandoned reads /proc: ask only once the ring has been idle a while.
                if limit.is_none() && idle.is_multiple_of(256) && c.is_abandoned() {
                    // Everything pushed before the producer died is visible now: drain it.
                    abandoned = true;
                    continue;
                }
                std::thread::yield_now();
            }
            Err(PopError::Corrupt(e)) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
    }
    if abandoned {
        println!("abandoned");
    }
    println!("received {next} last {}", next.wrapping_sub(1));
}
