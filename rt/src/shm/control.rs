//! A station's control block: its run state, one slot per child process (pid, heartbeat, restarts,
//! scheduling in force), the servo and physics loops' live statistics, and ring drop counters. The
//! supervisor creates it before spawning; children write their own slot and stats; `station status`
//! and `latency attach` read it. Nothing here ever blocks a loop: every field is a relaxed atomic
//! written by one party.

use crate::msg::ObjectSample;
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
    /// The session's time 0 on CLOCK_MONOTONIC, ns: the users' scripts run from it. 0 until known
    /// (a station started alone sets it at start; one in a session learns it from the session).
    pub epoch_ns: AtomicU64,
    /// Physics' newest state, for a restarted physics to resume from (a seqlock: see
    /// [`ControlBlock::store_resume`]).
    pub resume_seq: AtomicU64,
    /// The words of that state: an [`ObjectSample`] (t_ns, seq, pos, rot, vel, ang_mom, ...).
    pub resume: [AtomicU64; RESUME_WORDS],
    /// Physics' last report sequence number, so a restarted physics continues the sequence (a
    /// receiver ignores sequence numbers it has seen).
    pub report_seq: AtomicU64,
    /// Messages refused by the network process, by reason: version, length, contents, foreign
    /// (unknown site, or a site other than its key says), duplicate or out of order.
    pub net_refused: [AtomicU64; 5],
    /// 1 when the network process emulates delay, jitter and loss on receive.
    pub net_emulated: AtomicU64,
    /// Messages the emulation dropped.
    pub net_emulated_lost: AtomicU64,
    /// Sites present in the session (liveliness), as a bit mask by site index.
    pub peers_present: AtomicU64,
    /// Sites that joined / left since the network process started.
    pub peer_joins: AtomicU64,
    /// See `peer_joins`.
    pub peer_leaves: AtomicU64,
    /// States a late joiner got from the session's queryable at start.
    pub net_join_states: AtomicU64,
    /// Per site: its clock minus ours, ns (i64 bits), from the NTP-style exchange.
    pub clock_offset_ns: [AtomicU64; MAX_SITES],
    /// Per site: the round trip of the exchange the offset came from, ns (0: not measured).
    pub clock_rtt_ns: [AtomicU64; MAX_SITES],
    /// Station-to-station latency, physics at the sender to the ring into our physics, ns.
    pub net_latency: crate::stats::SharedHistogram,
    /// Count of `net_latency` samples.
    pub net_latency_count: AtomicU64,
    /// When physics last made a report (the step's wake time, ns), and its report period: the
    /// network process wakes just after the next one instead of polling.
    pub physics_last_report_ns: AtomicU64,
    /// See `physics_last_report_ns`.
    pub physics_report_period_ns: AtomicU64,
    /// Bytes of `locators` in use (written last, Release).
    pub locators_len: AtomicU64,
    /// The zenoh locators the network process listens on and its peers' ids, as text.
    pub locators: [AtomicU64; LOCATOR_WORDS],
}

/// Words of the resume state.
pub const RESUME_WORDS: usize = ObjectSample::WORDS;
/// Words of the locator text (512 bytes).
pub const LOCATOR_WORDS: usize = 64;
/// Sites the control block has per-peer slots for.
pub const MAX_SITES: usize = coop_model::method::MAX_SITES;

// SAFETY: repr(C), made only of AtomicU64 (directly, in arrays and in LoopStats/ChildSlot, which are
// the same); all-zero and every bit pattern are valid.
unsafe impl ShmShared for ControlBlock {
    const TYPE_NAME: &'static str = "coop.ControlBlock.v4";
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

    /// The session's time 0, if known.
    pub fn epoch(&self) -> Option<u64> {
        Some(self.epoch_ns.load(Ordering::Acquire)).filter(|&e| e != 0)
    }

    /// Physics (the one writer) stores its newest state for a successor to resume from. A seqlock
    /// of relaxed atomic words: odd sequence while writing, even when done.
    pub fn store_resume(&self, s: &ObjectSample) {
        let seq = self.resume_seq.load(Ordering::Relaxed);
        self.resume_seq.store(seq | 1, Ordering::Relaxed);
        // SYNC: the odd sequence is visible before any word changes.
        core::sync::atomic::fence(Ordering::Release);
        for (w, v) in self.resume.iter().zip(s.words()) {
            w.store(v, Ordering::Relaxed);
        }
        // SYNC: Release publishes the words with the even sequence; pairs with `resume`'s Acquire.
        self.resume_seq
            .store((seq | 1).wrapping_add(1), Ordering::Release);
    }

    /// The newest state physics stored, if any and if it reads back whole and valid.
    pub fn resume(&self) -> Option<ObjectSample> {
        for _ in 0..100 {
            let before = self.resume_seq.load(Ordering::Acquire);
            if before == 0 {
                return None;
            }
            let mut words = [0u64; RESUME_WORDS];
            for (v, w) in words.iter_mut().zip(&self.resume) {
                *v = w.load(Ordering::Relaxed);
            }
            // SYNC: the word loads complete before the sequence is read again.
            core::sync::atomic::fence(Ordering::Acquire);
            if before & 1 == 0 && self.resume_seq.load(Ordering::Relaxed) == before {
                let s = ObjectSample::from_words(words);
                return s.state().map(|_| s);
            }
            std::thread::yield_now();
        }
        None
    }

    /// Writes the locator text (the network process, once it knows it).
    pub fn set_locators(&self, text: &str) {
        self.locators_len.store(0, Ordering::Release);
        let bytes = &text.as_bytes()[..text.len().min(LOCATOR_WORDS * 8)];
        for (i, chunk) in bytes.chunks(8).enumerate() {
            let mut w = [0u8; 8];
            w[..chunk.len()].copy_from_slice(chunk);
            self.locators[i].store(u64::from_le_bytes(w), Ordering::Relaxed);
        }
        // SYNC: Release publishes the bytes; pairs with the Acquire in `locators`.
        self.locators_len
            .store(bytes.len() as u64, Ordering::Release);
    }

    /// The locator text (lossy UTF-8; empty until the network process wrote it).
    pub fn locators(&self) -> String {
        let len = (self.locators_len.load(Ordering::Acquire) as usize).min(LOCATOR_WORDS * 8);
        let mut bytes = Vec::with_capacity(len);
        for w in &self.locators {
            bytes.extend_from_slice(&w.load(Ordering::Relaxed).to_le_bytes());
        }
        bytes.truncate(len);
        String::from_utf8_lossy(&bytes).into_owned()
    }
}
