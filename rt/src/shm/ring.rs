//! A lock-free single-producer single-consumer ring in a shared-memory segment (H3).
//!
//! The algorithm is rtrb's: the producer owns `tail`, the consumer owns `head`, each keeps a cached copy
//! of the other's index and reloads it only when the ring looks full (producer) or empty (consumer).
//! What shared memory adds:
//! - **The layout lives in the segment** (`#[repr(C)]`, each index on its own 128-byte line) after the
//!   validated [`SegmentHeader`](super::header::SegmentHeader); the slots follow.
//! - **One producer and one consumer across processes.** Each side claims its half with a
//!   compare-and-swap of its [`ProcessToken`] (pid + start time). A second claimant gets
//!   [`RingOpenError::Taken`]; the claim of a process that died can be taken over. Dropping a half
//!   releases its claim, so the peer sees [`Consumer::is_abandoned`].
//! - **Indices from shared memory are never trusted.** Both counters are u64 that only grow; whenever one
//!   side loads the other's index it checks `0 <= tail - head <= capacity` and reports a
//!   [`RingCorruption`] otherwise. Slot positions come from the *local* mask, validated once at open, so
//!   even a hostile segment cannot steer an access out of bounds. Payloads are [`ShmPod`]: any bytes
//!   are a valid value.
//!
//! Real-time contract: after `open`/`create`, [`Producer::push`], [`Consumer::pop`] and
//! [`Consumer::pop_newest`] do not allocate, lock, log or make system calls; `is_abandoned` reads
//! `/proc` and is not for the hot path.

use core::marker::PhantomData;

use crate::pod::ShmPod;
use crate::process::ProcessToken;
use crate::sync::{AtomicU64, CachePadded, Ordering, SlotCell};

/// Largest ring: 2^24 slots.
pub const MAX_CAPACITY: u64 = 1 << 24;
/// Claim word of a half that was dropped cleanly.
const RELEASED: u64 = u64::MAX;

/// The ring's shared control block, at the start of the segment's payload.
#[derive(Debug)]
#[repr(C)]
pub(crate) struct RingControl {
    /// Count of messages taken so far. Stored only by the consumer, with Release, after it read the slot;
    /// loaded by the producer with Acquire to learn which slots are free. Invariant:
    /// `tail - head ∈ [0, capacity]` (wrapping u64 arithmetic).
    head: CachePadded<AtomicU64>,
    /// Count of messages pushed so far. Stored only by the producer, with Release, after it wrote the
    /// slot; loaded by the consumer with Acquire.
    tail: CachePadded<AtomicU64>,
    /// The producer's claim: 0 = never claimed, [`RELEASED`] = dropped, else its [`ProcessToken`].
    producer: CachePadded<AtomicU64>,
    /// The consumer's claim, likewise.
    consumer: CachePadded<AtomicU64>,
}
/// Bytes of the control block; the slots start right after it, 128-byte aligned.
const CONTROL_LEN: usize = core::mem::size_of::<RingControl>();
#[cfg(not(loom))]
const _: () = assert!(CONTROL_LEN == 512);

/// Payload bytes a ring of `capacity` slots of `T` needs, or `None` if the capacity breaks the rule.
pub(crate) fn payload_len<T>(capacity: u64) -> Option<usize> {
    if !capacity.is_power_of_two() || capacity > MAX_CAPACITY {
        return None;
    }
    let slots = usize::try_from(capacity)
        .ok()?
        .checked_mul(core::mem::size_of::<T>())?;
    CONTROL_LEN.checked_add(slots)
}

/// Which half of a ring.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The writing half.
    Producer,
    /// The reading half.
    Consumer,
}

impl core::fmt::Display for Side {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Producer => "producer",
            Self::Consumer => "consumer",
        })
    }
}

/// The indices found in shared memory break `0 <= tail - head <= capacity`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("ring indices corrupt: head {head}, tail {tail}, capacity {capacity}")]
pub struct RingCorruption {
    /// Head (messages taken) as read.
    pub head: u64,
    /// Tail (messages pushed) as read.
    pub tail: u64,
    /// The ring's capacity.
    pub capacity: u64,
}

/// Why [`Producer::push`] did not push. The value is handed back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PushError<T> {
    /// No free slot.
    Full(T),
    /// The consumer's index is invalid; nothing was written.
    Corrupt(T, RingCorruption),
}

/// Why [`Consumer::pop`] returned nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PopError {
    /// Nothing to read.
    #[error("ring empty")]
    Empty,
    /// The producer's index is invalid; nothing was read.
    #[error(transparent)]
    Corrupt(#[from] RingCorruption),
}

/// The newest message and how many older ones [`Consumer::pop_newest`] skipped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Newest<T> {
    /// The most recently pushed message.
    pub value: T,
    /// Messages that were waiting before it and are now consumed unread.
    pub skipped: u64,
}

/// Why a ring half could not be opened.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RingOpenError {
    /// The segment failed validation.
    #[error(transparent)]
    Open(#[from] super::header::OpenError),
    /// A live process already holds this half.
    #[error("ring {name}: the {side} half is already claimed by live pid {pid}")]
    Taken {
        /// Segment name.
        name: String,
        /// Which half.
        side: Side,
        /// Its holder's pid.
        pid: u32,
    },
    /// The indices in the segment are invalid.
    #[error("ring {name}: {corruption}")]
    Corrupt {
        /// Segment name.
        name: String,
        /// What was found.
        corruption: RingCorruption,
    },
}

/// The memory a ring lives in: a shared-memory segment, or (under loom) the heap.
struct Shared<T> {
    #[cfg(not(loom))]
    seg: super::segment::RawSegment,
    #[cfg(loom)]
    control: Box<RingControl>,
    #[cfg(loom)]
    slots: Box<[SlotCell<T>]>,
    capacity: u64,
    _t: PhantomData<T>,
}

// The ring protocol hands each slot to exactly one side at a time (the producer writes [tail,
// head + capacity), the consumer reads [head, tail)); indices are atomics; the mapping lives with the Arc.
// SAFETY: per the protocol above, slots are never shared between sides; T: Send lets values move.
unsafe impl<T: Send> Send for Shared<T> {}
// SAFETY: as above; shared access is through atomics or the protocol-guarded slots.
unsafe impl<T: Send> Sync for Shared<T> {}

impl<T> Shared<T> {
    #[inline(always)]
    fn control(&self) -> &RingControl {
        #[cfg(not(loom))]
        // SAFETY: the payload starts 128-byte aligned with CONTROL_LEN bytes of RingControl, zeroed at
        // creation (a valid RingControl: all atomics 0), and the mapping outlives `self`.
        unsafe {
            &*(self.seg.map.payload() as *const RingControl)
        }
        #[cfg(loom)]
        &self.control
    }

    /// The slot for index `i`, masked locally so no value from shared memory can reach out of bounds.
    #[inline(always)]
    fn slot(&self, i: u64) -> &SlotCell<T> {
        let i = (i & (self.capacity - 1)) as usize;
        #[cfg(not(loom))]
        // SAFETY: i < capacity, and the segment was validated to hold exactly `capacity` slots of T after
        // the control block (length check at open), aligned (CONTROL_LEN is a multiple of 128 >= align).
        unsafe {
            &*(self.seg.map.payload().add(CONTROL_LEN) as *const SlotCell<T>).add(i)
        }
        #[cfg(loom)]
        &self.slots[i]
    }

    fn claim(&self, side: Side) -> Result<(), u32> {
        let word = match side {
            Side::Producer => &self.control().producer,
            Side::Consumer => &self.control().consumer,
        };
        let me = ProcessToken::current().raw();
        let mut cur = word.load(Ordering::Acquire);
        loop {
            let holder = ProcessToken::from_raw(cur).filter(|_| cur != RELEASED);
            if let Some(h) = holder.filter(|h| h.is_alive()) {
                return Err(h.pid());
            }
            // SYNC: AcqRel: Acquire pairs with the previous holder's Release in `release`, so its last
            // index store is visible before we read the index; Release publishes our claim.
            match word.compare_exchange(cur, me, Ordering::AcqRel, Ordering::Acquire) {
                Ok(_) => return Ok(()),
                Err(now) => cur = now,
            }
        }
    }

    fn release(&self, side: Side) {
        let word = match side {
            Side::Producer => &self.control().producer,
            Side::Consumer => &self.control().consumer,
        };
        // SYNC: Release orders our last index store before the release; pairs with the Acquire load in
        // `peer_gone` (and in `claim` of a successor).
        let _ = word.compare_exchange(
            ProcessToken::current().raw(),
            RELEASED,
            Ordering::Release,
            Ordering::Relaxed,
        );
    }

    /// Whether the `side` half was claimed once and is now released or held by a dead process.
    fn peer_gone(&self, side: Side) -> bool {
        let word = match side {
            Side::Producer => &self.control().producer,
            Side::Consumer => &self.control().consumer,
        };
        // SYNC: Acquire pairs with the Release in `release`: if we see RELEASED, the peer's last index
        // store is visible to our next index load.
        match word.load(Ordering::Acquire) {
            0 => false,
            RELEASED => true,
            raw => ProcessToken::from_raw(raw).is_none_or(|t| !t.is_alive()),
        }
    }

    fn check(&self, head: u64, tail: u64) -> Result<u64, RingCorruption> {
        let used = tail.wrapping_sub(head);
        if used > self.capacity {
            return Err(RingCorruption {
                head,
                tail,
                capacity: self.capacity,
            });
        }
        Ok(used)
    }

    fn name(&self) -> &str {
        #[cfg(not(loom))]
        return self.seg.map.name();
        #[cfg(loom)]
        "heap"
    }

    /// Claims `side`, reads and validates both indices: the start state of a new half.
    fn attach(self: &std::sync::Arc<Self>, side: Side) -> Result<(u64, u64), RingOpenError> {
        self.claim(side).map_err(|pid| RingOpenError::Taken {
            name: self.name().to_owned(),
            side,
            pid,
        })?;
        let head = self.control().head.load(Ordering::Acquire);
        let tail = self.control().tail.load(Ordering::Acquire);
        if let Err(corruption) = self.check(head, tail) {
            self.release(side);
            return Err(RingOpenError::Corrupt {
                name: self.name().to_owned(),
                corruption,
            });
        }
        Ok((head, tail))
    }
}

/// Makes a half `!Sync` without costing anything: one side, one thread at a time (H3).
type NotSync = PhantomData<core::cell::Cell<()>>;

/// The writing half. `Send`, not `Sync`, not `Clone`.
pub struct Producer<T> {
    shared: std::sync::Arc<Shared<T>>,
    /// Our tail: the authoritative copy (only we store it).
    tail: u64,
    /// Last head we loaded; the real head is >= this.
    cached_head: u64,
    _not_sync: NotSync,
}

/// The reading half. `Send`, not `Sync`, not `Clone`.
pub struct Consumer<T> {
    shared: std::sync::Arc<Shared<T>>,
    /// Our head: the authoritative copy (only we store it).
    head: u64,
    /// Last tail we loaded; the real tail is >= this.
    cached_tail: u64,
    _not_sync: NotSync,
}

impl<T> core::fmt::Debug for Producer<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Producer")
            .field("ring", &self.shared.name())
            .field("tail", &self.tail)
            .finish()
    }
}
impl<T> core::fmt::Debug for Consumer<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Consumer")
            .field("ring", &self.shared.name())
            .field("head", &self.head)
            .finish()
    }
}

impl<T: ShmPod> Producer<T> {
    fn attach(shared: std::sync::Arc<Shared<T>>) -> Result<Self, RingOpenError> {
        let (head, tail) = shared.attach(Side::Producer)?;
        Ok(Self {
            shared,
            tail,
            cached_head: head,
            _not_sync: PhantomData,
        })
    }

    /// Pushes `value`, or hands it back if the ring is full or the consumer's index is corrupt.
    ///
    /// # Errors
    /// [`PushError::Full`] when no slot is free; [`PushError::Corrupt`] when the consumer's index breaks
    /// the ring invariant. Either way nothing was written.
    #[inline]
    pub fn push(&mut self, value: T) -> Result<(), PushError<T>> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let tail = self.tail;
        let capacity = self.shared.capacity;
        if tail.wrapping_sub(self.cached_head) >= capacity {
            // SYNC: Acquire pairs with the consumer's Release store of head in `pop`: the slot it freed
            // has been read completely before we overwrite it.
            let head = self.shared.control().head.load(Ordering::Acquire);
            match self.shared.check(head, tail) {
                Err(c) => return Err(PushError::Corrupt(value, c)),
                Ok(used) if used == capacity => return Err(PushError::Full(value)),
                Ok(_) => self.cached_head = head,
            }
        }
        self.shared.slot(tail).with_mut(|p| {
            // SAFETY: slot `tail` is free (tail - head < capacity), so the consumer does not read it until
            // we publish tail + 1 below; `p` is in bounds and aligned (see `slot`).
            unsafe { p.write(value) }
        });
        let next = tail.wrapping_add(1);
        // SYNC: Release publishes the slot write; pairs with the consumer's Acquire load of tail.
        self.shared.control().tail.store(next, Ordering::Release);
        self.tail = next;
        Ok(())
    }

    /// Free slots, reading the consumer's current index (one atomic load).
    pub fn slots(&self) -> usize {
        let head = self.shared.control().head.load(Ordering::Acquire);
        let used = self
            .shared
            .check(head, self.tail)
            .unwrap_or(self.shared.capacity);
        (self.shared.capacity - used) as usize
    }

    /// Free slots as of the last head we loaded: no shared access, a lower bound.
    pub fn cached_slots(&self) -> usize {
        (self.shared.capacity - self.tail.wrapping_sub(self.cached_head)) as usize
    }

    /// Slots in the ring.
    pub fn capacity(&self) -> usize {
        self.shared.capacity as usize
    }

    /// Messages pushed through this ring since it was created.
    pub fn pushed(&self) -> u64 {
        self.tail
    }

    /// Whether the consumer was attached and has since dropped its half or died. Reads `/proc`: not for
    /// the hot path.
    pub fn is_abandoned(&self) -> bool {
        self.shared.peer_gone(Side::Consumer)
    }
}

impl<T: ShmPod> Consumer<T> {
    fn attach(shared: std::sync::Arc<Shared<T>>) -> Result<Self, RingOpenError> {
        let (head, tail) = shared.attach(Side::Consumer)?;
        Ok(Self {
            shared,
            head,
            cached_tail: tail,
            _not_sync: PhantomData,
        })
    }

    /// Loads the producer's tail and validates it against our head.
    #[inline]
    fn load_tail(&mut self) -> Result<u64, RingCorruption> {
        // SYNC: Acquire pairs with the producer's Release store of tail in `push`: every slot below it
        // is completely written.
        let tail = self.shared.control().tail.load(Ordering::Acquire);
        self.shared.check(self.head, tail)?;
        self.cached_tail = tail;
        Ok(tail)
    }

    /// Takes the oldest message.
    ///
    /// # Errors
    /// [`PopError::Empty`] when there is none; [`PopError::Corrupt`] when the producer's index breaks the
    /// ring invariant (nothing is read).
    #[inline]
    pub fn pop(&mut self) -> Result<T, PopError> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let head = self.head;
        if head == self.cached_tail && self.load_tail()? == head {
            return Err(PopError::Empty);
        }
        let value = self.shared.slot(head).with(|p| {
            // SAFETY: head < tail, so the producer has published this slot and will not overwrite it
            // until we store head + 1; any bytes are a valid T (ShmPod).
            unsafe { p.read() }
        });
        let next = head.wrapping_add(1);
        // SYNC: Release orders our read of the slot before the producer may reuse it; pairs with the
        // producer's Acquire load of head.
        self.shared.control().head.store(next, Ordering::Release);
        self.head = next;
        Ok(value)
    }

    /// Takes the newest message and consumes every older one unread: what a state channel wants (the
    /// servo needs the latest object state, not the backlog). One Acquire load, one read, one store.
    ///
    /// # Errors
    /// As [`pop`](Self::pop).
    #[inline]
    pub fn pop_newest(&mut self) -> Result<Newest<T>, PopError> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let head = self.head;
        let tail = self.load_tail()?;
        if tail == head {
            return Err(PopError::Empty);
        }
        let newest = tail.wrapping_sub(1);
        let value = self.shared.slot(newest).with(|p| {
            // SAFETY: newest < tail was published, and stays ours until we store head below.
            unsafe { p.read() }
        });
        // SYNC: Release, as in `pop`.
        self.shared.control().head.store(tail, Ordering::Release);
        self.head = tail;
        Ok(Newest {
            value,
            skipped: newest.wrapping_sub(head),
        })
    }

    /// Messages waiting, reading the producer's current index (one atomic load).
    pub fn slots(&self) -> usize {
        let tail = self.shared.control().tail.load(Ordering::Acquire);
        self.shared.check(self.head, tail).unwrap_or(0) as usize
    }

    /// Slots in the ring.
    pub fn capacity(&self) -> usize {
        self.shared.capacity as usize
    }

    /// Messages taken from this ring since it was created.
    pub fn popped(&self) -> u64 {
        self.head
    }

    /// Whether the producer was attached and has since dropped its half or died. Everything it pushed
    /// before is still readable: call `pop` until `Empty` after this returns true. Reads `/proc`: not
    /// for the hot path.
    pub fn is_abandoned(&self) -> bool {
        self.shared.peer_gone(Side::Producer)
    }
}

impl<T> Drop for Producer<T> {
    fn drop(&mut self) {
        self.shared.release(Side::Producer);
    }
}
impl<T> Drop for Consumer<T> {
    fn drop(&mut self) {
        self.shared.release(Side::Consumer);
    }
}

#[cfg(not(loom))]
mod segment_backed;
#[cfg(not(loom))]
pub use segment_backed::{RingFill, RingOpenOptions, RingSegment};

/// A heap-backed ring for loom models: the same control block and protocol, in loom's atomics.
///
/// # Panics
/// If `capacity` is not a power of two within [`MAX_CAPACITY`].
#[cfg(loom)]
pub fn heap_ring<T: ShmPod + Default>(capacity: u64) -> (Producer<T>, Consumer<T>) {
    assert!(payload_len::<T>(capacity).is_some());
    let shared = std::sync::Arc::new(Shared {
        control: Box::new(RingControl {
            head: CachePadded(AtomicU64::new(0)),
            tail: CachePadded(AtomicU64::new(0)),
            producer: CachePadded(AtomicU64::new(0)),
            consumer: CachePadded(AtomicU64::new(0)),
        }),
        slots: (0..capacity).map(|_| SlotCell::new(T::default())).collect(),
        capacity,
        _t: PhantomData,
    });
    let p = Producer::attach(shared.clone()).expect("fresh ring");
    let c = Consumer::attach(shared).expect("fresh ring");
    (p, c)
}

#[cfg(all(test, loom))]
mod loom_tests;
