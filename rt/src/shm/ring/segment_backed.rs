//! Rings in named shared-memory segments: creating them, and opening either half from any process.

use std::marker::PhantomData;
use std::sync::Arc;
use std::time::Duration;

use super::{payload_len, Consumer, Producer, RingOpenError, Shared, RELEASED};
use crate::pod::{ShmPod, TypeIdentity};
use crate::process::ProcessToken;
use crate::shm::header::SegmentKind;
use crate::shm::segment::{CreateError, RawSegment, SegmentName, DEFAULT_READY_TIMEOUT};
use crate::sync::Ordering;

/// How to open a half of an existing ring.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RingOpenOptions {
    /// The capacity the caller expects; `None` accepts whatever the (validated) header says.
    pub capacity: Option<usize>,
    /// How long to wait for the creator to publish `ready`.
    pub ready_timeout: Duration,
}

impl Default for RingOpenOptions {
    fn default() -> Self {
        Self {
            capacity: None,
            ready_timeout: DEFAULT_READY_TIMEOUT,
        }
    }
}

/// The creator's handle on a ring segment. The segment's name is unlinked when this handle and every
/// half claimed through it are dropped; halves opened by other processes keep their mapping until they
/// drop.
pub struct RingSegment<T> {
    shared: Arc<Shared<T>>,
}

impl<T> std::fmt::Debug for RingSegment<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RingSegment")
            .field("name", &self.shared.name())
            .field("capacity", &self.shared.capacity)
            .finish()
    }
}

impl<T: ShmPod> RingSegment<T> {
    /// Creates ring `name` with `capacity` slots (a power of two up to [`super::MAX_CAPACITY`]).
    ///
    /// # Errors
    /// [`CreateError::Exists`] if a segment of that name exists (live or stale: never reused),
    /// [`CreateError::Capacity`] for a bad capacity, [`CreateError::Os`] if the OS refuses.
    pub fn create(name: &SegmentName, capacity: usize) -> Result<Self, CreateError> {
        let cap = capacity as u64;
        let Some(len) = payload_len::<T>(cap) else {
            return Err(CreateError::Capacity {
                name: name.to_string(),
                capacity: cap,
            });
        };
        // The payload is zeroed by ftruncate: head = tail = 0, no claims, slots all-zero (valid ShmPod).
        let seg = RawSegment::create(
            name,
            SegmentKind::Ring,
            TypeIdentity::of::<T>(),
            cap,
            len,
            |_| {},
        )?;
        Ok(Self {
            shared: Arc::new(Shared {
                seg,
                capacity: cap,
                _t: PhantomData,
            }),
        })
    }

    /// Claims the producer half in this process.
    ///
    /// # Errors
    /// [`RingOpenError::Taken`] if a live process holds it.
    pub fn producer(&self) -> Result<Producer<T>, RingOpenError> {
        Producer::attach(self.shared.clone())
    }

    /// Claims the consumer half in this process.
    ///
    /// # Errors
    /// [`RingOpenError::Taken`] if a live process holds it.
    pub fn consumer(&self) -> Result<Consumer<T>, RingOpenError> {
        Consumer::attach(self.shared.clone())
    }

    /// The segment's name.
    pub fn name(&self) -> &str {
        self.shared.name()
    }

    /// Slots in the ring.
    pub fn capacity(&self) -> usize {
        self.shared.capacity as usize
    }

    /// `(head, tail)`: messages taken and pushed so far, as the segment says now. For status and tests;
    /// the values may be corrupt if a peer is.
    pub fn indices(&self) -> (u64, u64) {
        let c = self.shared.control();
        (
            c.head.load(Ordering::Acquire),
            c.tail.load(Ordering::Acquire),
        )
    }

    /// Pids holding the producer and consumer halves now (live or not).
    pub fn holders(&self) -> (Option<u32>, Option<u32>) {
        let c = self.shared.control();
        let pid = |raw: u64| {
            ProcessToken::from_raw(raw)
                .filter(|_| raw != RELEASED)
                .map(ProcessToken::pid)
        };
        (
            pid(c.producer.load(Ordering::Acquire)),
            pid(c.consumer.load(Ordering::Acquire)),
        )
    }
}

/// A ring's fill as seen from outside: read without claiming either half.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RingFill {
    /// Messages waiting.
    pub used: u64,
    /// Slots.
    pub capacity: u64,
    /// Messages pushed since creation.
    pub pushed: u64,
}

impl<T: ShmPod> RingSegment<T> {
    /// Reads ring `name`'s indices without claiming a half (for status tools).
    ///
    /// # Errors
    /// As [`Producer::open`], without the claim.
    pub fn inspect(name: &SegmentName, opts: &RingOpenOptions) -> Result<RingFill, RingOpenError> {
        let shared = open_shared::<T>(name, opts)?;
        let c = shared.control();
        let (head, tail) = (
            c.head.load(Ordering::Acquire),
            c.tail.load(Ordering::Acquire),
        );
        Ok(RingFill {
            used: tail.wrapping_sub(head).min(shared.capacity),
            capacity: shared.capacity,
            pushed: tail,
        })
    }
}

fn open_shared<T: ShmPod>(
    name: &SegmentName,
    opts: &RingOpenOptions,
) -> Result<Arc<Shared<T>>, RingOpenError> {
    let seg = RawSegment::open(
        name,
        SegmentKind::Ring,
        TypeIdentity::of::<T>(),
        opts.capacity.map(|c| c as u64),
        opts.ready_timeout,
        payload_len::<T>,
    )?;
    Ok(Arc::new(Shared {
        capacity: seg.capacity,
        seg,
        _t: PhantomData,
    }))
}

impl<T: ShmPod> Producer<T> {
    /// Opens ring `name` (created by another process, usually the station supervisor) and claims its
    /// producer half.
    ///
    /// # Errors
    /// [`RingOpenError::Open`] if the segment fails validation (each header field has its own variant),
    /// [`RingOpenError::Taken`] if a live process holds the half, [`RingOpenError::Corrupt`] if the
    /// indices are invalid.
    pub fn open(name: &SegmentName, opts: &RingOpenOptions) -> Result<Self, RingOpenError> {
        Self::attach(open_shared(name, opts)?)
    }
}

impl<T: ShmPod> Consumer<T> {
    /// Opens ring `name` and claims its consumer half.
    ///
    /// # Errors
    /// As [`Producer::open`].
    pub fn open(name: &SegmentName, opts: &RingOpenOptions) -> Result<Self, RingOpenError> {
        Self::attach(open_shared(name, opts)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pod::SeqMsg;
    use crate::shm::header::OpenError;
    use crate::shm::ring::{PopError, PushError, RingCorruption, Side};
    use std::os::unix::fs::FileExt;

    fn name(what: &str) -> SegmentName {
        SegmentName::new(&format!("ut{}", std::process::id()), "ring", what).expect("valid name")
    }

    #[test]
    fn fifo_order_full_and_empty() {
        let ring = RingSegment::<SeqMsg>::create(&name("fifo"), 4).expect("create");
        let mut p = ring.producer().expect("producer");
        let mut c = ring.consumer().expect("consumer");
        assert_eq!(c.pop(), Err(PopError::Empty));
        for i in 0..4 {
            p.push(SeqMsg::new(i)).expect("room");
        }
        assert_eq!(p.push(SeqMsg::new(4)), Err(PushError::Full(SeqMsg::new(4))));
        assert_eq!(p.slots(), 0);
        assert_eq!(c.slots(), 4);
        for i in 0..4 {
            assert_eq!(c.pop().expect("item").seq, i);
        }
        assert_eq!(c.pop(), Err(PopError::Empty));
        // Wraps around the slots many times.
        for i in 4..1000 {
            p.push(SeqMsg::new(i)).expect("room");
            let m = c.pop().expect("item");
            assert_eq!(m.seq, i);
            assert!(m.is_intact());
        }
    }

    #[test]
    fn pop_newest_skips_the_backlog() {
        let ring = RingSegment::<SeqMsg>::create(&name("newest"), 8).expect("create");
        let mut p = ring.producer().expect("producer");
        let mut c = ring.consumer().expect("consumer");
        assert_eq!(c.pop_newest(), Err(PopError::Empty));
        for i in 0..5 {
            p.push(SeqMsg::new(i)).expect("room");
        }
        let n = c.pop_newest().expect("newest");
        assert_eq!((n.value.seq, n.skipped), (4, 4));
        assert_eq!(c.pop(), Err(PopError::Empty));
        assert_eq!(p.slots(), 8);
    }

    #[test]
    fn second_claimant_is_refused_and_release_allows_a_successor() {
        let n = name("claim");
        let ring = RingSegment::<SeqMsg>::create(&n, 4).expect("create");
        let p = ring.producer().expect("producer");
        let me = std::process::id();
        assert_eq!(
            Producer::<SeqMsg>::open(&n, &RingOpenOptions::default()).map(drop),
            Err(RingOpenError::Taken {
                name: n.to_string(),
                side: Side::Producer,
                pid: me
            })
        );
        let c = ring.consumer().expect("consumer");
        assert!(matches!(
            ring.consumer(),
            Err(RingOpenError::Taken {
                side: Side::Consumer,
                ..
            })
        ));
        assert!(!c.is_abandoned());
        drop(p);
        assert!(c.is_abandoned());
        let _p2 = Producer::<SeqMsg>::open(&n, &RingOpenOptions::default()).expect("successor");
        assert!(!c.is_abandoned());
    }

    #[test]
    fn corrupt_indices_are_errors_not_accesses() {
        let n = name("corrupt");
        let ring = RingSegment::<SeqMsg>::create(&n, 4).expect("create");
        let mut p = ring.producer().expect("producer");
        let mut c = ring.consumer().expect("consumer");
        p.push(SeqMsg::new(0)).expect("room");
        assert_eq!(c.pop().map(|m| m.seq), Ok(0));
        let file = std::fs::OpenOptions::new()
            .write(true)
            .open(format!("/dev/shm/{n}"))
            .expect("segment file");
        // tail is the second cache-padded word of the control block after the 128-byte header.
        let tail_off = 128 + 128;
        file.write_all_at(&1_000_000u64.to_ne_bytes(), tail_off)
            .expect("write");
        assert_eq!(
            c.pop(),
            Err(PopError::Corrupt(RingCorruption {
                head: 1,
                tail: 1_000_000,
                capacity: 4
            }))
        );
        let head_off = 128;
        file.write_all_at(&u64::MAX.to_ne_bytes(), head_off)
            .expect("write");
        for i in 1..4 {
            p.push(SeqMsg::new(i)).expect("cached head says room");
        }
        assert!(matches!(
            p.push(SeqMsg::new(9)),
            Err(PushError::Corrupt(_, RingCorruption { head: u64::MAX, .. }))
        ));
        drop((p, c));
        assert!(matches!(
            Consumer::<SeqMsg>::open(&n, &RingOpenOptions::default()),
            Err(RingOpenError::Corrupt { .. })
        ));
    }

    #[test]
    fn capacity_rules() {
        assert!(matches!(
            RingSegment::<SeqMsg>::create(&name("cap3"), 3),
            Err(CreateError::Capacity { capacity: 3, .. })
        ));
        assert!(matches!(
            RingSegment::<SeqMsg>::create(&name("cap0"), 0),
            Err(CreateError::Capacity { capacity: 0, .. })
        ));
        let n = name("cap8");
        let _ring = RingSegment::<SeqMsg>::create(&n, 8).expect("create");
        let opts = RingOpenOptions {
            capacity: Some(16),
            ..Default::default()
        };
        assert!(matches!(
            Consumer::<SeqMsg>::open(&n, &opts),
            Err(RingOpenError::Open(OpenError::CapacityMismatch {
                expected: 16,
                found: 8,
                ..
            }))
        ));
    }

    #[test]
    fn existing_name_is_never_reused_and_drop_unlinks() {
        let n = name("exists");
        let ring = RingSegment::<SeqMsg>::create(&n, 4).expect("create");
        assert!(matches!(
            RingSegment::<SeqMsg>::create(&n, 4),
            Err(CreateError::Exists { .. })
        ));
        let path = format!("/dev/shm/{n}");
        assert!(std::path::Path::new(&path).exists());
        drop(ring);
        assert!(!std::path::Path::new(&path).exists());
    }
}
