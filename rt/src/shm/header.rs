//! The header every coop segment starts with, and the checks an opener makes (H4).
//!
//! The creator writes every field, initialises the payload, and only then stores [`READY`] into
//! `ready` with `Release`. An opener waits (bounded) for `ready` with `Acquire` and then checks every
//! field; any mismatch is a typed [`OpenError`] that names what was expected and what was found. This is
//! iceoryx2's "version stored last" rule: a half-written segment is never mistaken for a usable one.

use crate::process::{self, Liveness};
use crate::sync::AtomicU64;

use crate::pod::TypeIdentity;

/// `b"COOPSHM\x01"` read as a little-endian u64: identifies a coop-haptics segment.
pub const MAGIC: u64 = u64::from_le_bytes(*b"COOPSHM\x01");
/// Bumped whenever the header or a segment kind's payload layout changes.
pub const LAYOUT_VERSION: u32 = 1;
/// The value `ready` holds once the creator finished: `b"READY!!\0"`.
pub const READY: u64 = u64::from_le_bytes(*b"READY!!\0");
/// Bytes reserved for the header; the payload starts here, cache-line aligned.
pub const HEADER_LEN: usize = 128;

/// What a segment's payload is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum SegmentKind {
    /// An SPSC ring of `capacity` slots of the payload type.
    Ring = 1,
    /// One shared block of the payload type (control, statistics).
    Block = 2,
}

/// The segment header as laid out in shared memory. Fields other than `ready` are written once by the
/// creator before `ready` and never change; openers read them only after seeing `ready == READY`.
#[derive(Debug)]
#[repr(C, align(128))]
pub struct SegmentHeader {
    /// [`MAGIC`].
    pub magic: u64,
    /// [`LAYOUT_VERSION`] of the creator.
    pub layout_version: u32,
    /// [`SegmentKind`] as u32.
    pub kind: u32,
    /// FNV-1a hash of the payload type's `TYPE_NAME`.
    pub type_hash: u64,
    /// `size_of` the payload type.
    pub type_size: u64,
    /// `align_of` the payload type.
    pub type_align: u64,
    /// Ring slots (a power of two), or 1 for a block.
    pub capacity: u64,
    /// Pid of the creating process.
    pub creator_pid: u64,
    /// Start time of the creating process, clock ticks since boot (`/proc/<pid>/stat` field 22).
    pub creator_start_ticks: u64,
    /// [`READY`] once the creator has finished; anything else means "not usable yet".
    pub ready: AtomicU64,
}
#[cfg(not(loom))]
const _: () = assert!(core::mem::size_of::<SegmentHeader>() == HEADER_LEN);

/// A plain copy of the header's fields, read from memory or from the segment file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HeaderFields {
    /// See [`SegmentHeader::magic`].
    pub magic: u64,
    /// See [`SegmentHeader::layout_version`].
    pub layout_version: u32,
    /// See [`SegmentHeader::kind`].
    pub kind: u32,
    /// See [`SegmentHeader::type_hash`].
    pub type_hash: u64,
    /// See [`SegmentHeader::type_size`].
    pub type_size: u64,
    /// See [`SegmentHeader::type_align`].
    pub type_align: u64,
    /// See [`SegmentHeader::capacity`].
    pub capacity: u64,
    /// See [`SegmentHeader::creator_pid`].
    pub creator_pid: u64,
    /// See [`SegmentHeader::creator_start_ticks`].
    pub creator_start_ticks: u64,
    /// See [`SegmentHeader::ready`].
    pub ready: u64,
}

#[cfg_attr(loom, allow(dead_code))]
impl HeaderFields {
    /// Decodes the first [`HEADER_LEN`] bytes of a segment (native byte order, as mapped).
    pub fn from_bytes(b: &[u8; HEADER_LEN]) -> Self {
        let u64_at = |off: usize| {
            let mut w = [0u8; 8];
            w.copy_from_slice(&b[off..off + 8]);
            u64::from_ne_bytes(w)
        };
        let u32_at = |off: usize| {
            let mut w = [0u8; 4];
            w.copy_from_slice(&b[off..off + 4]);
            u32::from_ne_bytes(w)
        };
        use core::mem::offset_of;
        Self {
            magic: u64_at(offset_of!(SegmentHeader, magic)),
            layout_version: u32_at(offset_of!(SegmentHeader, layout_version)),
            kind: u32_at(offset_of!(SegmentHeader, kind)),
            type_hash: u64_at(offset_of!(SegmentHeader, type_hash)),
            type_size: u64_at(offset_of!(SegmentHeader, type_size)),
            type_align: u64_at(offset_of!(SegmentHeader, type_align)),
            capacity: u64_at(offset_of!(SegmentHeader, capacity)),
            creator_pid: u64_at(offset_of!(SegmentHeader, creator_pid)),
            creator_start_ticks: u64_at(offset_of!(SegmentHeader, creator_start_ticks)),
            ready: u64_at(offset_of!(SegmentHeader, ready)),
        }
    }

    /// Checks every field against what the opener expects, in header order, then the creator's
    /// liveness. `payload_len(capacity)` is the payload size a valid capacity implies.
    pub(crate) fn validate(
        &self,
        name: &str,
        kind: SegmentKind,
        ty: TypeIdentity,
        expected_capacity: Option<u64>,
        mapping_len: usize,
        payload_len: impl Fn(u64) -> Option<usize>,
    ) -> Result<(), OpenError> {
        let name = name.to_owned();
        if self.magic != MAGIC {
            return Err(OpenError::BadMagic {
                name,
                expected: MAGIC,
                found: self.magic,
            });
        }
        if self.layout_version != LAYOUT_VERSION {
            return Err(OpenError::LayoutVersion {
                name,
                ours: LAYOUT_VERSION,
                theirs: self.layout_version,
            });
        }
        if self.kind != kind as u32 {
            return Err(OpenError::Kind {
                name,
                expected: kind as u32,
                found: self.kind,
            });
        }
        if self.type_hash != ty.name_hash {
            return Err(OpenError::TypeName {
                name,
                expected: ty.name,
                expected_hash: ty.name_hash,
                found_hash: self.type_hash,
            });
        }
        if self.type_size != ty.size {
            return Err(OpenError::TypeSize {
                name,
                expected: ty.size,
                found: self.type_size,
            });
        }
        if self.type_align != ty.align {
            return Err(OpenError::TypeAlign {
                name,
                expected: ty.align,
                found: self.type_align,
            });
        }
        let Some(needed) = payload_len(self.capacity) else {
            return Err(OpenError::Capacity {
                name,
                found: self.capacity,
            });
        };
        if let Some(expected) = expected_capacity {
            if expected != self.capacity {
                return Err(OpenError::CapacityMismatch {
                    name,
                    expected,
                    found: self.capacity,
                });
            }
        }
        if HEADER_LEN + needed != mapping_len {
            return Err(OpenError::LengthMismatch {
                name,
                capacity: self.capacity,
                expected: HEADER_LEN + needed,
                found: mapping_len,
            });
        }
        self.check_creator(&name)
    }

    /// A segment is stale when its creator no longer runs: it must not be used, only removed.
    pub(crate) fn check_creator(&self, name: &str) -> Result<(), OpenError> {
        let pid = u32::try_from(self.creator_pid).unwrap_or(0);
        match (pid, process::liveness(pid, self.creator_start_ticks)) {
            (0, _) | (_, Liveness::Gone) => Err(OpenError::CreatorDead {
                name: name.to_owned(),
                pid: self.creator_pid,
            }),
            (_, Liveness::Reused { found_start_ticks }) => Err(OpenError::CreatorPidReused {
                name: name.to_owned(),
                pid: self.creator_pid,
                recorded_start_ticks: self.creator_start_ticks,
                found_start_ticks,
            }),
            (_, Liveness::Alive) => Ok(()),
        }
    }
}

/// Why a segment could not be opened. Each variant names the segment and, for a mismatch, the value
/// expected and the value found.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OpenError {
    /// The name breaks the naming rule.
    #[error(transparent)]
    Name(#[from] super::name::NameError),
    /// No segment of that name exists.
    #[error("segment {name}: no such shared-memory segment (is its station running?)")]
    NotFound {
        /// Segment name.
        name: String,
    },
    /// The OS refused to open or map it.
    #[error("segment {name}: cannot open or map it: {errno}")]
    Os {
        /// Segment name.
        name: String,
        /// What the OS said.
        errno: nix::errno::Errno,
    },
    /// Smaller than a header: not ours, or truncated.
    #[error("segment {name}: {found} bytes, smaller than the {needed}-byte header")]
    TooSmall {
        /// Segment name.
        name: String,
        /// Bytes needed at least.
        needed: usize,
        /// Bytes found.
        found: usize,
    },
    /// `ready` never became [`READY`] within the wait.
    #[error(
        "segment {name}: not ready after {waited_ms} ms (ready word {found:#018x}, creator pid \
         {creator_pid}): its creator died or hung while creating it"
    )]
    NotReady {
        /// Segment name.
        name: String,
        /// How long the opener waited.
        waited_ms: u64,
        /// The ready word found.
        found: u64,
        /// The creator pid recorded so far (0 if not yet written).
        creator_pid: u64,
    },
    /// Not a coop segment.
    #[error("segment {name}: bad magic: expected {expected:#018x}, found {found:#018x} (not a coop-haptics segment)")]
    BadMagic {
        /// Segment name.
        name: String,
        /// [`MAGIC`].
        expected: u64,
        /// What the header holds.
        found: u64,
    },
    /// Created by a build with another layout.
    #[error(
        "segment {name}: layout version mismatch: ours {ours}, theirs {theirs} (mixed builds?)"
    )]
    LayoutVersion {
        /// Segment name.
        name: String,
        /// Our [`LAYOUT_VERSION`].
        ours: u32,
        /// The segment's.
        theirs: u32,
    },
    /// A ring opened as a block or the other way round.
    #[error(
        "segment {name}: kind mismatch: expected {expected}, found {found} (1 = ring, 2 = block)"
    )]
    Kind {
        /// Segment name.
        name: String,
        /// Kind expected.
        expected: u32,
        /// Kind found.
        found: u32,
    },
    /// Another payload type.
    #[error("segment {name}: payload type mismatch: expected {expected} (hash {expected_hash:#018x}), found hash {found_hash:#018x}")]
    TypeName {
        /// Segment name.
        name: String,
        /// Our type's `TYPE_NAME`.
        expected: &'static str,
        /// Its hash.
        expected_hash: u64,
        /// The hash in the header.
        found_hash: u64,
    },
    /// Same name, other size: a layout changed without a new `TYPE_NAME`.
    #[error("segment {name}: payload size mismatch: expected {expected} bytes, found {found}")]
    TypeSize {
        /// Segment name.
        name: String,
        /// `size_of` our type.
        expected: u64,
        /// Size in the header.
        found: u64,
    },
    /// Same name, other alignment.
    #[error("segment {name}: payload alignment mismatch: expected {expected}, found {found}")]
    TypeAlign {
        /// Segment name.
        name: String,
        /// `align_of` our type.
        expected: u64,
        /// Alignment in the header.
        found: u64,
    },
    /// The capacity breaks the kind's rule.
    #[error("segment {name}: invalid capacity {found}: a ring holds a power of two from 1 to 2^24 slots, a block exactly 1")]
    Capacity {
        /// Segment name.
        name: String,
        /// Capacity in the header.
        found: u64,
    },
    /// The caller asked for another capacity.
    #[error("segment {name}: capacity mismatch: expected {expected}, found {found}")]
    CapacityMismatch {
        /// Segment name.
        name: String,
        /// Capacity asked for.
        expected: u64,
        /// Capacity in the header.
        found: u64,
    },
    /// The mapping's size does not match the header's capacity.
    #[error("segment {name}: length mismatch: capacity {capacity} needs {expected} bytes, the segment has {found}")]
    LengthMismatch {
        /// Segment name.
        name: String,
        /// Capacity in the header.
        capacity: u64,
        /// Bytes the capacity implies.
        expected: usize,
        /// Bytes the segment has.
        found: usize,
    },
    /// Stale: the creator is gone. Remove it with `station clean`; it is never reused.
    #[error(
        "segment {name}: stale: its creator (pid {pid}) is gone; remove it with `station clean`"
    )]
    CreatorDead {
        /// Segment name.
        name: String,
        /// Creator pid recorded.
        pid: u64,
    },
    /// Stale: the creator's pid now belongs to another process.
    #[error(
        "segment {name}: stale: creator pid {pid} was reused (recorded start {recorded_start_ticks}, \
         found {found_start_ticks}); remove it with `station clean`"
    )]
    CreatorPidReused {
        /// Segment name.
        name: String,
        /// Creator pid recorded.
        pid: u64,
        /// Start ticks recorded.
        recorded_start_ticks: u64,
        /// Start ticks of the process that has the pid now.
        found_start_ticks: u64,
    },
}

impl OpenError {
    /// Whether this error means "the segment is stale" (its creator is gone).
    pub fn is_stale(&self) -> bool {
        matches!(
            self,
            Self::CreatorDead { .. } | Self::CreatorPidReused { .. }
        )
    }
}
