//! coop-rt: the real-time building blocks every station process stands on.
//!
//! - [`shm`]: named shared-memory segments with a validated, versioned header; lock-free SPSC rings
//!   in them (rtrb's algorithm, one producer and one consumer enforced across processes); shared blocks.
//! - [`sched`]: affinity, SCHED_FIFO/RR/OTHER, `mlockall`, stack pre-faulting, and a report of what is in
//!   force, falling back loudly when a privilege is missing.
//! - [`timer`]: a periodic timer on absolute CLOCK_MONOTONIC deadlines with overrun counting.
//! - [`stats`]: live loop statistics another process reads without disturbing the loop.
//! - [`device`]: the Cartesian device interface, its backends built in (the simulated SCARA arm, a
//!   replayed hand, the Haply Inverse3 through its service, Force Dimension/Falcon through the DHD
//!   SDK loaded at run time), the device-to-world placement and the safety contract every backend
//!   runs under.
//! - [`msg`], [`servo`], [`physics`]: the station's ring messages and the bodies of its servo and
//!   physics loops over the model (the processes around them come with the station).
//!
//! Real-time contract: after construction, `Producer::push`, `Consumer::pop`/`pop_newest`,
//! `PeriodicTimer::wait`, `LoopStats::record` and the device layer's `sample`/`display` (with the
//! backends built in) do not allocate, lock or log, and make no system call but the timer's
//! `clock_nanosleep` (`rt/tests/alloc_free.rs` and `rt/tests/loops.rs` check the allocation part).
//! Everything else (create, open, claim, `is_abandoned`, scheduling) is setup and may.
//!
//! `unsafe` lives only in [`shm`], [`pod`] (the plain-data contract a ring's messages sign, a leaf
//! both [`msg`] and [`shm`] import), [`sched`] (H2), [`msg`] (each ring message's `unsafe impl
//! ShmPod`) and `device::dhd` (calls into the DHD SDK, a C library loaded at run time: nothing else
//! can reach it); every block says why it is sound.
#![deny(unsafe_code)]
#![warn(missing_docs)]

#[cfg(not(loom))]
pub mod device;
#[cfg(not(loom))]
pub mod msg;
#[cfg(not(loom))]
pub mod physics;
pub mod pod;
pub mod process;
#[cfg(not(loom))]
pub mod run;
#[cfg(not(loom))]
pub mod sched;
#[cfg(not(loom))]
pub mod servo;
pub mod shm;
#[cfg(not(loom))]
pub use shm::stats;
pub mod sync;
#[cfg(not(loom))]
pub mod timer;
