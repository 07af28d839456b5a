//! A station's control block: its run state, one slot per child process (pid, heartbeat, restarts,
//! scheduling in force), the servo and physics loops' live statistics, and ring drop counters. The
//! supervisor creates it before spawning; children write their own slot and stats; `station status`
//! and `latency attach` read it. Nothing here ever blocks a loop: every field is a relaxed atomic
//! written by one party.

use crate::shm::ShmShared;
use crate::stats::LoopStats;
use crate::sync::{AtomicU64, Ordering};

/// The station's child processes, in slot order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(usize)]
pub enum Child {
    /// The servo loop.
    Servo = 0,
    /// The physics loop.
    Physics = 1,
    /// The network process.
    Network = 2,
}

/// Children per station.
pub const CHILDREN: usize = 3;

/// Run state of the station, as the supervisor sets it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u64)]
pub enum RunState {
    /// Children are being started.
    Starting = 0,
    /// Running.
    Running = 1,
    /// Cooperative stop requested: the servo ramps its force to zero, then every loop exits.
    Stopping = 2,
    /// Stopped.
    Stopped = 3,
}

/// One child's slot: written by the child (heartbeat, scheduling) and by the supervisor (pid,
/// restarts).
#[derive(Debug)]
#[repr(C)]
pub struct ChildSlot {
    /// Pid of the running child, 0 when none.
    pub pid: AtomicU64,
    /// Bumped by the child every cycle (loops) or tick (network); a stalled counter is a hung child.
    pub heartbeat: AtomicU64,
    /// Restarts so far.
    pub restarts: AtomicU64,
    /// Scheduling policy in force (the kernel's number).
    pub policy: AtomicU64,
    /// Priority in force.
    pub priority: AtomicU64,
    /// CPUs in force, as a bit mask.
    pub cpus: AtomicU64,
}

/// The control block (in a [`crate::shm::BlockSegment`]).
#[derive(Debug)]
#[repr(C)]
pub struct ControlBlock {
    /// [`RunState`] as u64.
    pub run_state: AtomicU64,
    /// Per child, indexed by [`Child`].
    pub children: [ChildSlot; CHILDREN],
    /// The servo loop's statistics.
    pub servo: LoopStats,
    /// The physics loop's statistics.
    pub physics: LoopStats,
    /// Pushes refused because the ring was full: tool, object, report, remote.
    pub drops: [AtomicU64; 4],
    /// The servo's last commanded force magnitude, N (f64 bits).
    pub servo_command_n: AtomicU64,
    /// The servo's display scale: 1 fresh, 0 stale (f64 bits).
    pub servo_scale: AtomicU64,
    /// Reports the network process published.
    pub net_published: AtomicU64,
    /// Other sites' reports it handed to physics.
    pub net_received: AtomicU64,
    /// Messages it refused.
    pub net_rejected: AtomicU64,
    /// Remote reports physics took from the ring.
    pub physics_received: AtomicU64,
    /// States physics adopted.
    pub physics_adoptions: AtomicU64,
    /// The servo's last stale episode: the time of the newest object state it had, ns.
    pub servo_stale_state_ns: AtomicU64,
    /// ... and when its command first reached zero in that episode, ns (0: not yet).
    pub servo_stale_limp_ns: AtomicU64,
    /// Round trips measured by the servo: from a tool sample to the object state computed with it
    /// arriving back (servo → physics → servo).
    pub roundtrip_count: AtomicU64,
    /// Their histogram.
    pub roundtrip: crate::stats::SharedHistogram,
}

// SAFETY: repr(C), made only of AtomicU64 (directly, in arrays and in LoopStats/ChildSlot, which are
// the same); all-zero and every bit pattern are valid.
unsafe impl ShmShared for ControlBlock {
    const TYPE_NAME: &'static str = "coop.ControlBlock.v3";
}

impl ControlBlock {
    /// The run state (an unknown value reads as `Stopping`, the safe interpretation).
    pub fn run_state(&self) -> RunState {
        match self.run_state.load(Ordering::Acquire) {
            0 => RunState::Starting,
            1 => RunState::Running,
            3 => RunState::Stopped,
            _ => RunState::Stopping,
        }
    }
    /// Sets the run state.
    pub fn set_run_state(&self, s: RunState) {
        // SYNC: Release pairs with the Acquire in `run_state`.
        self.run_state.store(s as u64, Ordering::Release);
    }
    /// A child's slot.
    pub fn child(&self, c: Child) -> &ChildSlot {
        &self.children[c as usize]
    }
    /// Stores an f64 field.
    pub fn store_f64(field: &AtomicU64, v: f64) {
        field.store(v.to_bits(), Ordering::Relaxed);
    }
    /// Loads an f64 field.
    pub fn load_f64(field: &AtomicU64) -> f64 {
        f64::from_bits(field.load(Ordering::Relaxed))
    }
}
