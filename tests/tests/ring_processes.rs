//! The shared-memory ring between real processes: ten million sequenced messages arrive once
//! and in order; a producer SIGKILLed midway loses nothing it pushed and nothing appears after it; a
//! second claimant is refused while the first lives and may take over once it died; a segment whose
//! creator died is detected as stale and removed.

use std::process::Command;
use std::time::Duration;

use coop_rt::shm::{
    self, Consumer, OpenError, Producer, RingOpenError, RingOpenOptions, RingSegment, SegmentName,
    SegmentStatus, SeqMsg, Side,
};
use coop_tests::{first_line, shm_entries, unique_session, wait_until, Reaped};

const PRODUCER: &str = env!("CARGO_BIN_EXE_ring_producer");
const CONSUMER: &str = env!("CARGO_BIN_EXE_ring_consumer");
const OWNER: &str = env!("CARGO_BIN_EXE_segment_owner");

/// Generous: the two processes share two cores with every other test running in parallel.
const LIMIT: Duration = Duration::from_secs(120);

fn ring_name(what: &str) -> SegmentName {
    SegmentName::new(&unique_session(), "rp", what).expect("valid name")
}

#[test]
fn ten_million_messages_arrive_once_and_in_order() {
    const COUNT: u64 = 10_000_000;
    let name = ring_name("ten");
    let ring = RingSegment::<SeqMsg>::create(&name, 4096).expect("create");
    let mut consumer = Reaped::spawn(
        Command::new(CONSUMER)
            .arg(name.as_str())
            .arg(COUNT.to_string()),
    );
    assert_eq!(first_line(&mut consumer), "ready");
    let producer = Reaped::spawn(
        Command::new(PRODUCER)
            .arg(name.as_str())
            .arg(COUNT.to_string()),
    );
    let (p_status, p_out) = producer.finish();
    assert!(p_status.success(), "producer failed: {p_status}");
    assert!(p_out.contains(&format!("pushed {COUNT}")), "{p_out}");
    let (c_status, c_out) = consumer.finish();
    assert!(
        c_status.success(),
        "consumer found a bad message: {c_status} {c_out}"
    );
    assert!(
        c_out.contains(&format!("received {COUNT} last {}", COUNT - 1)),
        "{c_out}"
    );
    assert_eq!(ring.indices(), (COUNT, COUNT));
}

#[test]
fn producer_killed_midway_loses_nothing_and_adds_nothing() {
    let name = ring_name("kill");
    let ring = RingSegment::<SeqMsg>::create(&name, 1024).expect("create");
    let mut consumer = Reaped::spawn(
        Command::new(CONSUMER)
            .arg(name.as_str())
            .arg("--until-abandoned"),
    );
    assert_eq!(first_line(&mut consumer), "ready");
    let mut producer = Reaped::spawn(
        Command::new(PRODUCER)
            .arg(name.as_str())
            .arg("1000000000000"),
    );
    // Kill it well into the run, while it is pushing.
    wait_until("1M messages pushed", LIMIT, || {
        (ring.indices().1 >= 1_000_000).then_some(())
    });
    producer.kill();
    let (status, _) = producer.finish();
    assert!(!status.success(), "producer should have died by SIGKILL");
    let (c_status, c_out) = consumer.finish();
    assert!(c_status.success(), "consumer found a bad message: {c_out}");
    let (head, tail) = ring.indices();
    assert!(
        c_out.contains("abandoned"),
        "consumer never saw is_abandoned: {c_out}"
    );
    // Everything committed before the kill arrived, in order, and nothing after it.
    assert_eq!(head, tail);
    assert!(
        c_out.contains(&format!("received {tail} last {}", tail - 1)),
        "tail {tail}, consumer said: {c_out}"
    );
}

#[test]
fn a_second_claimant_is_refused_until_the_first_dies() {
    let name = ring_name("claim");
    let ring = RingSegment::<SeqMsg>::create(&name, 8).expect("create");
    let mut holder = Reaped::spawn(
        Command::new(PRODUCER)
            .arg(name.as_str())
            .arg("0")
            .arg("--hold"),
    );
    assert_eq!(first_line(&mut holder), "ready");
    let pid = holder.pid();
    assert_eq!(
        Producer::<SeqMsg>::open(&name, &RingOpenOptions::default()).map(drop),
        Err(RingOpenError::Taken {
            name: name.to_string(),
            side: Side::Producer,
            pid
        })
    );
    assert_eq!(ring.holders().0, Some(pid));
    // The consumer half is independent.
    let consumer = Consumer::<SeqMsg>::open(&name, &RingOpenOptions::default()).expect("consumer");
    assert!(!consumer.is_abandoned());
    holder.kill();
    let _ = holder.finish();
    assert!(
        consumer.is_abandoned(),
        "a dead producer is an abandoned ring"
    );
    let _p = Producer::<SeqMsg>::open(&name, &RingOpenOptions::default())
        .expect("the claim of a dead process can be taken over");
    assert!(!consumer.is_abandoned());
    assert_eq!(ring.holders().0, Some(std::process::id()));
}

#[test]
fn a_stale_segment_is_detected_refused_and_removed() {
    let session = unique_session();
    let name = SegmentName::new(&session, "rp", "stale").expect("valid name");
    let prefix = SegmentName::station_prefix(&session, "rp").expect("valid prefix");
    let mut owner = Reaped::spawn(Command::new(OWNER).arg(name.as_str()));
    assert_eq!(first_line(&mut owner), "ready");
    let pid = u64::from(owner.pid());
    assert_eq!(
        shm::list(&prefix).expect("list")[0].status,
        SegmentStatus::Live { creator_pid: pid }
    );
    assert!(
        shm::remove_stale(&prefix).expect("clean").is_empty(),
        "live segments stay"
    );

    owner.kill();
    let _ = owner.finish();
    assert_eq!(
        shm_entries(name.as_str()),
        vec![name.to_string()],
        "a crash leaves it behind"
    );
    assert_eq!(
        shm::list(&prefix).expect("list")[0].status,
        SegmentStatus::Stale { creator_pid: pid }
    );
    // Never silently reused: opening says stale, creating says it exists and is stale.
    assert_eq!(
        Consumer::<SeqMsg>::open(&name, &RingOpenOptions::default()).map(drop),
        Err(RingOpenError::Open(OpenError::CreatorDead {
            name: name.to_string(),
            pid
        }))
    );
    assert!(matches!(
        RingSegment::<SeqMsg>::create(&name, 8),
        Err(shm::CreateError::Exists {
            status: SegmentStatus::Stale { .. },
            ..
        })
    ));
    let removed = shm::remove_stale(&prefix).expect("clean");
    assert_eq!(removed.len(), 1);
    assert_eq!(removed[0].name, name.to_string());
    assert!(shm_entries(name.as_str()).is_empty());
    // And the name is free again.
    let _fresh = RingSegment::<SeqMsg>::create(&name, 8).expect("re-create after clean");
}
