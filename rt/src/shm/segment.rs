//! Creating, opening and removing named shared-memory segments (over the `shared_memory` crate).
//!
//! Names are `coop_<session>_<station>_<what>` so that everything a station made can be found,
//! listed and, once its creator is dead, removed (iceoryx2's `iox2_` prefix). Segments are created
//! exclusively (`O_CREAT|O_EXCL`, mode 0600): an existing segment of the same name, live or stale, is an
//! error, never silently reused.

use std::fs::File;
use std::io::Read;
use std::os::unix::fs::MetadataExt;
use std::sync::Arc;
use std::time::{Duration, Instant};

use shared_memory::{Shmem, ShmemConf, ShmemError};

use super::header::{
    HeaderFields, OpenError, SegmentHeader, SegmentKind, HEADER_LEN, LAYOUT_VERSION, MAGIC, READY,
};
use crate::pod::TypeIdentity;
use crate::process::ProcessToken;
use crate::sync::Ordering;

pub use super::name::{NameError, SegmentName, PREFIX, SHM_DIR};

/// How long an opener waits for a segment's creator to finish (bounded: a dead creator must not hang
/// its peers). Two seconds covers a creator that is descheduled on a loaded 2-core machine.
pub const DEFAULT_READY_TIMEOUT: Duration = Duration::from_secs(2);

/// Why a segment could not be created.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CreateError {
    /// The name breaks the naming rule.
    #[error(transparent)]
    Name(#[from] NameError),
    /// A segment of that name exists. If it is stale, `station clean` removes it.
    #[error("segment {name} already exists ({status}); segments are never reused")]
    Exists {
        /// Segment name.
        name: String,
        /// What the existing one is.
        status: SegmentStatus,
    },
    /// The capacity breaks the kind's rule.
    #[error("segment {name}: invalid capacity {capacity}: a ring holds a power of two from 1 to 2^24 slots")]
    Capacity {
        /// Segment name.
        name: String,
        /// Capacity asked for.
        capacity: u64,
    },
    /// The OS refused.
    #[error("segment {name}: cannot create it: {errno}")]
    Os {
        /// Segment name.
        name: String,
        /// What the OS said.
        errno: nix::errno::Errno,
    },
}

/// One mapping of a segment. The creator's mapping unlinks the name when dropped.
pub(crate) struct Mapping {
    shmem: Shmem,
    name: String,
}

// SAFETY: a MAP_SHARED mapping belongs to the process, not to a thread; `Shmem` is !Send only because it
// holds a raw pointer. All access to the mapped bytes goes through atomics or the ring protocol.
unsafe impl Send for Mapping {}
// SAFETY: as above; `&Mapping` only hands out the base pointer and length, never `&mut` to the bytes.
unsafe impl Sync for Mapping {}

impl std::fmt::Debug for Mapping {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mapping")
            .field("name", &self.name)
            .field("len", &self.shmem.len())
            .field("owner", &self.shmem.is_owner())
            .finish()
    }
}

impl Mapping {
    pub(crate) fn base(&self) -> *mut u8 {
        self.shmem.as_ptr()
    }
    pub(crate) fn len(&self) -> usize {
        self.shmem.len()
    }
    pub(crate) fn name(&self) -> &str {
        &self.name
    }
    pub(crate) fn header(&self) -> &SegmentHeader {
        // Every Mapping is at least HEADER_LEN bytes (checked at create/open) and page-aligned.
        // SAFETY: a SegmentHeader (align 128) fits at the base; its plain fields are read only after
        // `ready` (Acquire), when the creator no longer writes them.
        unsafe { &*(self.base() as *const SegmentHeader) }
    }
    pub(crate) fn payload(&self) -> *mut u8 {
        // SAFETY: HEADER_LEN <= len, checked at create/open.
        unsafe { self.base().add(HEADER_LEN) }
    }
    pub(crate) fn header_fields(&self) -> HeaderFields {
        let mut bytes = [0u8; HEADER_LEN];
        // SAFETY: HEADER_LEN bytes are mapped at base. A volatile copy: the creator may still be
        // writing while an opener polls (it then sees `ready != READY` and waits).
        unsafe {
            for (i, b) in bytes.iter_mut().enumerate() {
                *b = core::ptr::read_volatile(self.base().add(i));
            }
        }
        HeaderFields::from_bytes(&bytes)
    }
}

/// A created or opened segment: its mapping and validated capacity.
#[derive(Debug, Clone)]
pub(crate) struct RawSegment {
    pub(crate) map: Arc<Mapping>,
    pub(crate) capacity: u64,
}

impl RawSegment {
    /// Creates `name` exclusively, writes the header, lets `init` initialise the payload (zeroed on
    /// entry), then publishes `ready` last.
    pub(crate) fn create(
        name: &SegmentName,
        kind: SegmentKind,
        ty: TypeIdentity,
        capacity: u64,
        payload_len: usize,
        init: impl FnOnce(*mut u8),
    ) -> Result<Self, CreateError> {
        let me = ProcessToken::current();
        let shmem = match ShmemConf::new()
            .size(HEADER_LEN + payload_len)
            .os_id(name.as_str())
            .create()
        {
            Ok(s) => s,
            Err(ShmemError::MappingIdExists) => {
                return Err(CreateError::Exists {
                    name: name.to_string(),
                    status: inspect(name.as_str()).map_or_else(
                        |e| SegmentStatus::Unrecognized {
                            reason: e.to_string(),
                        },
                        |i| i.status,
                    ),
                })
            }
            Err(e) => {
                return Err(CreateError::Os {
                    name: name.to_string(),
                    errno: errno_of(&e),
                })
            }
        };
        let map = Mapping {
            shmem,
            name: name.to_string(),
        };
        let h = map.base() as *mut SegmentHeader;
        // Raw field writes, no reference to the whole header: openers may already be polling `ready`.
        // SAFETY: we created the segment exclusively, nobody uses it before `ready`, and the header
        // fits (size >= HEADER_LEN, page-aligned base).
        unsafe {
            (&raw mut (*h).magic).write_volatile(MAGIC);
            (&raw mut (*h).layout_version).write_volatile(LAYOUT_VERSION);
            (&raw mut (*h).kind).write_volatile(kind as u32);
            (&raw mut (*h).type_hash).write_volatile(ty.name_hash);
            (&raw mut (*h).type_size).write_volatile(ty.size);
            (&raw mut (*h).type_align).write_volatile(ty.align);
            (&raw mut (*h).capacity).write_volatile(capacity);
            (&raw mut (*h).creator_pid).write_volatile(u64::from(me.pid()));
            (&raw mut (*h).creator_start_ticks).write_volatile(me.start_ticks());
        }
        init(map.payload());
        // SYNC: Release publishes the header fields and the payload initialisation above; pairs with
        // the Acquire load of `ready` in `open`.
        map.header().ready.store(READY, Ordering::Release);
        Ok(Self {
            map: Arc::new(map),
            capacity,
        })
    }

    /// Opens `name`, waits up to `timeout` for `ready`, and validates every header field.
    pub(crate) fn open(
        name: &SegmentName,
        kind: SegmentKind,
        ty: TypeIdentity,
        expected_capacity: Option<u64>,
        timeout: Duration,
        payload_len: impl Fn(u64) -> Option<usize>,
    ) -> Result<Self, OpenError> {
        let start = Instant::now();
        let map = loop {
            match try_map(name.as_str()) {
                Ok(m) => break m,
                // Created but not yet sized by its creator: wait like for `ready`.
                Err(OpenError::TooSmall { .. }) if start.elapsed() < timeout => {
                    std::thread::sleep(Duration::from_millis(1))
                }
                Err(e) => return Err(e),
            }
        };
        // SYNC: Acquire pairs with the creator's Release store of READY: once seen, every header field
        // and the payload initialisation are visible.
        while map.header().ready.load(Ordering::Acquire) != READY {
            if start.elapsed() >= timeout {
                let f = map.header_fields();
                if f.magic != MAGIC && f.magic != 0 {
                    return Err(OpenError::BadMagic {
                        name: name.to_string(),
                        expected: MAGIC,
                        found: f.magic,
                    });
                }
                return Err(OpenError::NotReady {
                    name: name.to_string(),
                    waited_ms: start.elapsed().as_millis() as u64,
                    found: f.ready,
                    creator_pid: f.creator_pid,
                });
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        let f = map.header_fields();
        f.validate(
            name.as_str(),
            kind,
            ty,
            expected_capacity,
            map.len(),
            payload_len,
        )?;
        Ok(Self {
            map: Arc::new(map),
            capacity: f.capacity,
        })
    }
}

fn try_map(name: &str) -> Result<Mapping, OpenError> {
    let shmem = ShmemConf::new().os_id(name).open().map_err(|e| {
        let errno = errno_of(&e);
        match errno {
            nix::errno::Errno::ENOENT => OpenError::NotFound {
                name: name.to_owned(),
            },
            // mmap of a zero-length object: the creator has not sized it yet.
            nix::errno::Errno::EINVAL => OpenError::TooSmall {
                name: name.to_owned(),
                needed: HEADER_LEN,
                found: 0,
            },
            errno => OpenError::Os {
                name: name.to_owned(),
                errno,
            },
        }
    })?;
    if shmem.len() < HEADER_LEN {
        return Err(OpenError::TooSmall {
            name: name.to_owned(),
            needed: HEADER_LEN,
            found: shmem.len(),
        });
    }
    Ok(Mapping {
        shmem,
        name: name.to_owned(),
    })
}

fn errno_of(e: &ShmemError) -> nix::errno::Errno {
    match e {
        ShmemError::MapCreateFailed(n)
        | ShmemError::MapOpenFailed(n)
        | ShmemError::UnknownOsError(n) => nix::errno::Errno::from_raw(*n as i32),
        ShmemError::MappingIdExists => nix::errno::Errno::EEXIST,
        _ => nix::errno::Errno::EINVAL,
    }
}

/// What a segment found in [`SHM_DIR`] is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SegmentStatus {
    /// Its creator runs.
    Live {
        /// Creator pid.
        creator_pid: u64,
    },
    /// Its creator is gone (or its pid was reused): safe to remove, never to use.
    Stale {
        /// Creator pid recorded.
        creator_pid: u64,
    },
    /// Not a complete coop segment and no recorded creator to judge by: left alone.
    Unrecognized {
        /// Why it was not recognised.
        reason: String,
    },
}

impl std::fmt::Display for SegmentStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Live { creator_pid } => write!(f, "live, creator pid {creator_pid}"),
            Self::Stale { creator_pid } => write!(f, "stale, creator pid {creator_pid} is gone"),
            Self::Unrecognized { reason } => write!(f, "unrecognized: {reason}"),
        }
    }
}

/// A segment found in [`SHM_DIR`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SegmentInfo {
    /// Its name.
    pub name: String,
    /// Its size in bytes.
    pub len: u64,
    /// Live, stale or unrecognised.
    pub status: SegmentStatus,
}

/// Reads a segment's header from its file, without mapping it.
///
/// # Errors
/// The I/O error opening or reading the file.
pub fn inspect(name: &str) -> std::io::Result<SegmentInfo> {
    let mut file = File::open(format!("{SHM_DIR}/{name}"))?;
    let len = file.metadata()?.size();
    let mut bytes = [0u8; HEADER_LEN];
    let status = if (len as usize) < HEADER_LEN {
        SegmentStatus::Unrecognized {
            reason: format!("{len} bytes, smaller than a header"),
        }
    } else {
        file.read_exact(&mut bytes)?;
        let f = HeaderFields::from_bytes(&bytes);
        if f.magic != MAGIC && f.magic != 0 {
            SegmentStatus::Unrecognized {
                reason: format!("bad magic {:#018x}", f.magic),
            }
        } else if f.creator_pid == 0 {
            SegmentStatus::Unrecognized {
                reason: "no creator recorded (being created?)".into(),
            }
        } else if f.check_creator(name).is_ok() {
            SegmentStatus::Live {
                creator_pid: f.creator_pid,
            }
        } else {
            SegmentStatus::Stale {
                creator_pid: f.creator_pid,
            }
        }
    };
    Ok(SegmentInfo {
        name: name.to_owned(),
        len,
        status,
    })
}

/// Lists every segment in [`SHM_DIR`] whose name starts with `prefix` (use [`PREFIX`] for all coop
/// segments, or [`SegmentName::station_prefix`] for one station), sorted by name.
///
/// # Errors
/// The I/O error reading [`SHM_DIR`].
pub fn list(prefix: &str) -> std::io::Result<Vec<SegmentInfo>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(SHM_DIR)? {
        let entry = entry?;
        let Some(name) = entry.file_name().to_str().map(str::to_owned) else {
            continue;
        };
        if !name.starts_with(PREFIX) || !name.starts_with(prefix) {
            continue;
        }
        match inspect(&name) {
            Ok(info) => out.push(info),
            // Removed between read_dir and open: nothing to report.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => out.push(SegmentInfo {
                name,
                len: 0,
                status: SegmentStatus::Unrecognized {
                    reason: e.to_string(),
                },
            }),
        }
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

/// Removes every *stale* segment under `prefix` and returns what it removed. Live and unrecognised
/// segments are left alone.
///
/// # Errors
/// The I/O error reading [`SHM_DIR`]; a segment that vanished meanwhile is not an error.
pub fn remove_stale(prefix: &str) -> std::io::Result<Vec<SegmentInfo>> {
    let mut removed = Vec::new();
    for info in list(prefix)? {
        if matches!(info.status, SegmentStatus::Stale { .. }) {
            match nix::sys::mman::shm_unlink(info.name.as_str()) {
                Ok(()) | Err(nix::errno::Errno::ENOENT) => removed.push(info),
                Err(e) => return Err(std::io::Error::from(e)),
            }
        }
    }
    Ok(removed)
}
