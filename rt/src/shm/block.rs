//! One shared struct in a segment, read and written through atomics: the control block and live loop
//! statistics, which another process reads without disturbing the loop.

use std::marker::PhantomData;
use std::time::Duration;

use super::header::{OpenError, SegmentKind};
use super::segment::{CreateError, RawSegment, SegmentName};
use crate::pod::TypeIdentity;
use crate::process::ProcessToken;

/// Marks a struct that processes share by reference in a segment.
///
/// # Safety
/// Implement only for a `#[repr(C)]` type that
/// - is made of atomics from [`crate::sync`] (and arrays of them) and nothing else;
/// - is a valid value when all-zero (a fresh segment is zeroed) and for every bit pattern (a hostile
///   or stale writer can store anything);
/// - has a [`TYPE_NAME`](ShmShared::TYPE_NAME) that changes whenever its layout changes.
pub unsafe trait ShmShared: Sync + Send + 'static {
    /// The layout's stable name, hashed into the segment header.
    const TYPE_NAME: &'static str;
}

fn identity<B: ShmShared>() -> TypeIdentity {
    TypeIdentity {
        name: B::TYPE_NAME,
        name_hash: crate::pod::fnv1a64(B::TYPE_NAME.as_bytes()),
        size: core::mem::size_of::<B>() as u64,
        align: core::mem::align_of::<B>() as u64,
    }
}

/// A segment holding one `B`. The creator's handle unlinks the name on drop.
pub struct BlockSegment<B> {
    seg: RawSegment,
    _b: PhantomData<B>,
}

impl<B> std::fmt::Debug for BlockSegment<B> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BlockSegment")
            .field("name", &self.seg.map.name())
            .finish()
    }
}

fn block_len<B>(capacity: u64) -> Option<usize> {
    (capacity == 1).then_some(core::mem::size_of::<B>())
}

impl<B: ShmShared> BlockSegment<B> {
    /// Creates segment `name` holding a zeroed `B`.
    ///
    /// # Errors
    /// [`CreateError::Exists`] if the name is taken (never reused), [`CreateError::Os`] otherwise.
    pub fn create(name: &SegmentName) -> Result<Self, CreateError> {
        const { assert!(core::mem::align_of::<B>() <= super::header::HEADER_LEN) };
        let seg = RawSegment::create(
            name,
            SegmentKind::Block,
            identity::<B>(),
            1,
            core::mem::size_of::<B>(),
            |_| {},
        )?;
        Ok(Self {
            seg,
            _b: PhantomData,
        })
    }

    /// Opens segment `name`, waiting up to `ready_timeout` for its creator, and validates its header.
    ///
    /// # Errors
    /// An [`OpenError`] naming the first header field that does not match, or the stale creator.
    pub fn open(name: &SegmentName, ready_timeout: Duration) -> Result<Self, OpenError> {
        let seg = RawSegment::open(
            name,
            SegmentKind::Block,
            identity::<B>(),
            Some(1),
            ready_timeout,
            block_len::<B>,
        )?;
        Ok(Self {
            seg,
            _b: PhantomData,
        })
    }

    /// The segment's name.
    pub fn name(&self) -> &str {
        self.seg.map.name()
    }

    /// Who created the segment, as its header records it (none if it names nobody). Of a
    /// station's control block: that run's supervisor, which tells one run of a station from the
    /// next even when the same pid comes back.
    pub fn creator(&self) -> Option<ProcessToken> {
        let f = self.seg.map.header_fields();
        ProcessToken::new(u32::try_from(f.creator_pid).ok()?, f.creator_start_ticks)
    }
}

impl<B: ShmShared> core::ops::Deref for BlockSegment<B> {
    type Target = B;
    fn deref(&self) -> &B {
        // SAFETY: the payload is exactly size_of::<B>() bytes, 128-byte aligned (checked at open/create); B
        // is valid for any bytes, shared only through atomics (ShmShared); the mapping outlives `self`.
        unsafe { &*(self.seg.map.payload() as *const B) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shm::stats::LoopStats;

    #[test]
    fn the_creator_is_who_created_it_as_every_opener_sees_it() {
        let name = SegmentName::new(&format!("ut{}", std::process::id()), "block", "creator")
            .expect("valid name");
        let made = BlockSegment::<LoopStats>::create(&name).expect("create");
        let opened = BlockSegment::<LoopStats>::open(&name, Duration::from_secs(1)).expect("open");
        let me = ProcessToken::current();
        assert_eq!(made.creator(), Some(me));
        assert_eq!(opened.creator(), Some(me));
        assert_ne!(me.start_ticks(), 0, "a start time, not only a pid");
    }
}
