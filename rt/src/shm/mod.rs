//! Shared memory: named segments with validated headers, SPSC rings and shared blocks in them.
//!
//! This module and [`crate::sched`] are the only places `unsafe` is allowed in coop-rt (H2). Under
//! `--cfg loom` only the ring protocol (over heap memory) and what it needs are compiled.
#![allow(unsafe_code)]

#[cfg(not(loom))]
pub mod block;
#[cfg(not(loom))]
pub mod control;
#[cfg(not(loom))]
pub mod device;
pub mod header;
pub mod name;
pub mod ring;
#[cfg(not(loom))]
pub mod rollback;
#[cfg(not(loom))]
pub mod segment;
#[cfg(not(loom))]
pub mod station;
#[cfg(not(loom))]
pub mod stats;

pub use crate::pod::{SeqMsg, ShmPod, TypeIdentity};
#[cfg(not(loom))]
pub use block::{BlockSegment, ShmShared};
pub use header::{OpenError, SegmentHeader, SegmentKind};
pub use name::{NameError, SegmentName, PREFIX, SHM_DIR};
pub use ring::{
    Consumer, Newest, PopError, Producer, PushError, RingCorruption, RingOpenError, Side,
};
#[cfg(not(loom))]
pub use ring::{RingFill, RingOpenOptions, RingSegment};
#[cfg(not(loom))]
pub use segment::{inspect, list, remove_stale, CreateError, SegmentInfo, SegmentStatus};
