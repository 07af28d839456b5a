//! One test per header field: corrupt it in a real segment (through its file in /dev/shm, as a foreign
//! or broken process would) and assert the exact typed error an opener gets (H4).

use std::mem::offset_of;
use std::os::unix::fs::FileExt;
use std::time::Duration;

use coop_rt::pod::fnv1a64;
use coop_rt::shm::header::{HEADER_LEN, LAYOUT_VERSION, MAGIC};
use coop_rt::shm::{
    Consumer, OpenError, RingOpenError, RingOpenOptions, RingSegment, SegmentHeader, SegmentName,
    SeqMsg,
};

fn name(what: &str) -> SegmentName {
    SegmentName::new(&format!("hdr{}", std::process::id()), "t", what).expect("valid name")
}

/// Creates a ring, overwrites `bytes` at `offset` of its header, and opens it again.
fn corrupt_and_open(what: &str, offset: usize, bytes: &[u8]) -> (String, OpenError) {
    let n = name(what);
    let ring = RingSegment::<SeqMsg>::create(&n, 8).expect("create");
    let file = std::fs::OpenOptions::new()
        .write(true)
        .open(format!("/dev/shm/{n}"))
        .expect("segment file");
    file.write_all_at(bytes, offset as u64).expect("corrupt");
    let opts = RingOpenOptions {
        capacity: None,
        ready_timeout: Duration::from_millis(100),
    };
    let err = match Consumer::<SeqMsg>::open(&n, &opts) {
        Err(RingOpenError::Open(e)) => e,
        other => panic!("expected a header error, got {other:?}"),
    };
    drop(ring);
    (n.to_string(), err)
}

#[test]
fn magic() {
    let (name, err) = corrupt_and_open(
        "magic",
        offset_of!(SegmentHeader, magic),
        &0xdead_beef_u64.to_ne_bytes(),
    );
    assert_eq!(
        err,
        OpenError::BadMagic {
            name,
            expected: MAGIC,
            found: 0xdead_beef
        }
    );
}

#[test]
fn layout_version() {
    let (name, err) = corrupt_and_open(
        "version",
        offset_of!(SegmentHeader, layout_version),
        &7u32.to_ne_bytes(),
    );
    assert_eq!(
        err,
        OpenError::LayoutVersion {
            name,
            ours: LAYOUT_VERSION,
            theirs: 7
        }
    );
}

#[test]
fn kind() {
    let (name, err) =
        corrupt_and_open("kind", offset_of!(SegmentHeader, kind), &2u32.to_ne_bytes());
    assert_eq!(
        err,
        OpenError::Kind {
            name,
            expected: 1,
            found: 2
        }
    );
}

#[test]
fn type_name_hash() {
    let (name, err) = corrupt_and_open(
        "typehash",
        offset_of!(SegmentHeader, type_hash),
        &42u64.to_ne_bytes(),
    );
    assert_eq!(
        err,
        OpenError::TypeName {
            name,
            expected: "coop.SeqMsg.v1",
            expected_hash: fnv1a64(b"coop.SeqMsg.v1"),
            found_hash: 42
        }
    );
}

#[test]
fn type_size() {
    let (name, err) = corrupt_and_open(
        "typesize",
        offset_of!(SegmentHeader, type_size),
        &32u64.to_ne_bytes(),
    );
    assert_eq!(
        err,
        OpenError::TypeSize {
            name,
            expected: 64,
            found: 32
        }
    );
}

#[test]
fn type_align() {
    let (name, err) = corrupt_and_open(
        "typealign",
        offset_of!(SegmentHeader, type_align),
        &16u64.to_ne_bytes(),
    );
    assert_eq!(
        err,
        OpenError::TypeAlign {
            name,
            expected: 8,
            found: 16
        }
    );
}

#[test]
fn capacity_not_a_power_of_two() {
    let (name, err) = corrupt_and_open(
        "capacity",
        offset_of!(SegmentHeader, capacity),
        &12u64.to_ne_bytes(),
    );
    assert_eq!(err, OpenError::Capacity { name, found: 12 });
}

#[test]
fn capacity_larger_than_the_segment() {
    let (name, err) = corrupt_and_open(
        "caplen",
        offset_of!(SegmentHeader, capacity),
        &1024u64.to_ne_bytes(),
    );
    assert_eq!(
        err,
        OpenError::LengthMismatch {
            name,
            capacity: 1024,
            expected: HEADER_LEN + 512 + 1024 * 64,
            found: HEADER_LEN + 512 + 8 * 64,
        }
    );
}

/// A pid that no process has: the segment is stale.
#[test]
fn creator_pid() {
    let dead = (300_000..4_000_000u64)
        .step_by(7919)
        .find(|p| !std::path::Path::new(&format!("/proc/{p}")).exists())
        .expect("some free pid");
    let (name, err) = corrupt_and_open(
        "creatorpid",
        offset_of!(SegmentHeader, creator_pid),
        &dead.to_ne_bytes(),
    );
    assert_eq!(err, OpenError::CreatorDead { name, pid: dead });
    assert!(err.is_stale());
}

/// Our own pid with another start time: the pid was reused, so the segment is stale.
#[test]
fn creator_start_time() {
    let me = coop_rt::process::ProcessToken::current();
    let (name, err) = corrupt_and_open(
        "creatorstart",
        offset_of!(SegmentHeader, creator_start_ticks),
        &(me.start_ticks() + 1).to_ne_bytes(),
    );
    assert_eq!(
        err,
        OpenError::CreatorPidReused {
            name,
            pid: u64::from(me.pid()),
            recorded_start_ticks: me.start_ticks() + 1,
            found_start_ticks: me.start_ticks(),
        }
    );
    assert!(err.is_stale());
}

/// A ready word that never became READY: the bounded wait ends with `NotReady`.
#[test]
fn ready_word() {
    let (name, err) = corrupt_and_open(
        "ready",
        offset_of!(SegmentHeader, ready),
        &0u64.to_ne_bytes(),
    );
    match err {
        OpenError::NotReady {
            name: n,
            found: 0,
            creator_pid,
            waited_ms,
        } => {
            assert_eq!(n, name);
            assert_eq!(creator_pid, u64::from(std::process::id()));
            assert!(waited_ms >= 100);
        }
        other => panic!("expected NotReady, got {other:?}"),
    }
}

/// Shorter than a header: not ours, or truncated.
#[test]
fn truncated_segment() {
    let n = name("short");
    let ring = RingSegment::<SeqMsg>::create(&n, 8).expect("create");
    let file = std::fs::OpenOptions::new()
        .write(true)
        .open(format!("/dev/shm/{n}"))
        .expect("segment file");
    file.set_len(64).expect("truncate");
    let opts = RingOpenOptions {
        capacity: None,
        ready_timeout: Duration::from_millis(50),
    };
    assert_eq!(
        Consumer::<SeqMsg>::open(&n, &opts).map(drop),
        Err(RingOpenError::Open(OpenError::TooSmall {
            name: n.to_string(),
            needed: HEADER_LEN,
            found: 64
        }))
    );
    drop(ring);
}

#[test]
fn missing_segment() {
    let n = name("missing");
    assert_eq!(
        Consumer::<SeqMsg>::open(&n, &RingOpenOptions::default()).map(drop),
        Err(RingOpenError::Open(OpenError::NotFound {
            name: n.to_string()
        }))
    );
}

/// A ring of another payload type is refused by name before its size is even considered.
#[test]
fn other_payload_type() {
    let n = name("othertype");
    let _ring = RingSegment::<u64>::create(&n, 8).expect("create");
    assert!(matches!(
        Consumer::<SeqMsg>::open(&n, &RingOpenOptions::default()),
        Err(RingOpenError::Open(OpenError::TypeName {
            expected: "coop.SeqMsg.v1",
            ..
        }))
    ));
}
