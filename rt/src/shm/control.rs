//! A station's control block: its run state, one slot per child process (pid, heartbeat, restarts,
//! scheduling in force, health and last failure), and one group of live figures per process that
//! writes them: the servo's, physics' and the network's (and the device's, the servo's too: it
//! alone opens the device). The supervisor creates it before spawning; each child writes its own
//! slot and its own group; `station status` and `latency attach` read it. Nothing here ever blocks
//! a loop: every field is an atomic with exactly one writer, named on its group (relaxed, but
//! for the run state, the epoch, the seqlocks and a study's trial handshake, whose orderings are
//! said where they are used).

use core::marker::PhantomData;

use crate::msg::ObjectSample;
use crate::shm::ShmShared;
use crate::stats::{LoopStats, SharedHistogram};
use crate::sync::{AtomicU64, Ordering};
use coop_model::body::BodyState;
use coop_model::world::MAX_OBJECTS;

pub use coop_model::MAX_SITES;

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

impl Child {
    /// Every child, in slot order.
    pub const ALL: [Child; CHILDREN] = [Child::Servo, Child::Physics, Child::Network];
    /// Its name, as status and the command line spell it.
    pub fn name(self) -> &'static str {
        match self {
            Child::Servo => "servo",
            Child::Physics => "physics",
            Child::Network => "network",
        }
    }
}

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

/// A key of a [`Counters`] array: a small enum whose every value has a slot.
pub trait CounterKey: Copy + 'static {
    /// Every key, in slot order.
    const ALL: &'static [Self];
    /// Its slot (below [`COUNTER_SLOTS`]).
    fn slot(self) -> usize;
    /// Its name, as status prints it and `--json` keys it.
    fn name(self) -> &'static str;
}

/// Slots of every [`Counters`] array (room for keys added later without a layout change).
pub const COUNTER_SLOTS: usize = 16;

/// Counters indexed by an enum instead of a number: `drops.add(Ring::Tool, 1)`.
#[repr(C)]
pub struct Counters<K> {
    words: [AtomicU64; COUNTER_SLOTS],
    _key: PhantomData<fn() -> K>,
}

impl<K: CounterKey> Counters<K> {
    /// The count for `k`.
    pub fn get(&self, k: K) -> u64 {
        self.words[k.slot()].load(Ordering::Relaxed)
    }
    /// Sets the count for `k` (the one writer publishing its own tally).
    pub fn set(&self, k: K, v: u64) {
        self.words[k.slot()].store(v, Ordering::Relaxed);
    }
    /// Adds to the count for `k` (the one writer: a relaxed load and store, no locked instruction).
    pub fn add(&self, k: K, by: u64) {
        let w = &self.words[k.slot()];
        w.store(
            w.load(Ordering::Relaxed).wrapping_add(by),
            Ordering::Relaxed,
        );
    }
    /// Adds to the count for `k` from any thread (an atomic add: for counts several threads of
    /// one process keep).
    pub fn count(&self, k: K, by: u64) {
        self.words[k.slot()].fetch_add(by, Ordering::Relaxed);
    }
    /// Every key with its count, in slot order.
    pub fn all(&self) -> impl Iterator<Item = (K, u64)> + '_ {
        K::ALL.iter().map(|&k| (k, self.get(k)))
    }
    /// The sum over every key.
    pub fn total(&self) -> u64 {
        self.all().map(|(_, n)| n).sum()
    }
}

impl<K: CounterKey + std::fmt::Debug> std::fmt::Debug for Counters<K> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_map().entries(self.all()).finish()
    }
}

/// The rings of a station, each with one producer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ring {
    /// Servo → physics: tool samples.
    Tool,
    /// Physics → servo: object states.
    Object,
    /// Physics → network: this site's reports.
    Report,
    /// Network → physics: the other sites' reports.
    Remote,
    /// Physics → network: trace records for the recording.
    Trace,
}

impl Ring {
    /// The child that pushes into it (and counts what it could not push).
    pub fn producer(self) -> Child {
        match self {
            Ring::Tool => Child::Servo,
            Ring::Object | Ring::Report | Ring::Trace => Child::Physics,
            Ring::Remote => Child::Network,
        }
    }
}

impl CounterKey for Ring {
    const ALL: &'static [Self] = &[
        Ring::Tool,
        Ring::Object,
        Ring::Report,
        Ring::Remote,
        Ring::Trace,
    ];
    fn slot(self) -> usize {
        self as usize
    }
    fn name(self) -> &'static str {
        match self {
            Ring::Tool => "tool",
            Ring::Object => "object",
            Ring::Report => "report",
            Ring::Remote => "remote",
            Ring::Trace => "trace",
        }
    }
}

/// Why the network process refused a received message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// Another wire version.
    Version,
    /// Not exactly one message long.
    Length,
    /// Well-formed but invalid: non-finite, not a unit quaternion, unknown kind.
    Contents,
    /// Its site is not one of the session's, or not the one its key names.
    Foreign,
    /// A sequence number already seen from that site, or older than the newest seen.
    Stale,
    /// A state from a site whose clock offset is not known yet: its time cannot be read.
    NoOffset,
    /// Its time, corrected by the sender's clock offset, is older than the age limit: a backlog
    /// after a partition, or a replay.
    TooOld,
    /// Its corrected time lies in the future beyond the window: a wrong clock or a forgery.
    Future,
    /// Finite but impossible for this world: outside its extent, faster or spinning faster than
    /// anything in it can make the object, or inclusion times that no site has reached.
    Implausible,
}

/// What the network process puts on the wire and gets from it, by kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WireKind {
    /// Site reports (object states, forces): this site's puts, the others' it receives, and the
    /// current states a late joiner asks for.
    State,
    /// Tool tracks (`timewarp`, `coupled`).
    Track,
    /// Clock exchanges: the queries and their answers (the session's time 0 too).
    Clock,
    /// Liveliness: this site's token, and the others' comings and goings (no payload).
    Presence,
    /// The live view's samples (put only).
    Live,
    /// ROS 2 topics the network process puts: poses, forces, frames and events (a `ros2`
    /// device's own traffic is its bridge's, in the servo process, and not counted here).
    Ros2,
}

impl CounterKey for WireKind {
    const ALL: &'static [Self] = &[
        WireKind::State,
        WireKind::Track,
        WireKind::Clock,
        WireKind::Presence,
        WireKind::Live,
        WireKind::Ros2,
    ];
    fn slot(self) -> usize {
        self as usize
    }
    fn name(self) -> &'static str {
        match self {
            WireKind::State => "states",
            WireKind::Track => "tracks",
            WireKind::Clock => "clock",
            WireKind::Presence => "presence",
            WireKind::Live => "live",
            WireKind::Ros2 => "ros2",
        }
    }
}

/// The network process's traffic by [`WireKind`]: payload bytes and messages it put (each put
/// once, however many peers zenoh sends it to) and got. Any of its threads counts
/// ([`Counters::count`]).
#[derive(Debug)]
#[repr(C)]
pub struct Traffic {
    /// Payload bytes put.
    pub sent_bytes: Counters<WireKind>,
    /// Messages put (and queries made, tokens declared).
    pub sent_msgs: Counters<WireKind>,
    /// Payload bytes received.
    pub received_bytes: Counters<WireKind>,
    /// Messages received.
    pub received_msgs: Counters<WireKind>,
}

impl Traffic {
    /// One message of `kind`, `bytes` long, put.
    pub fn sent(&self, kind: WireKind, bytes: usize) {
        self.sent_msgs.count(kind, 1);
        self.sent_bytes.count(kind, bytes as u64);
    }
    /// One message of `kind`, `bytes` long, received.
    pub fn received(&self, kind: WireKind, bytes: usize) {
        self.received_msgs.count(kind, 1);
        self.received_bytes.count(kind, bytes as u64);
    }
}

impl CounterKey for Refused {
    const ALL: &'static [Self] = &[
        Refused::Version,
        Refused::Length,
        Refused::Contents,
        Refused::Foreign,
        Refused::Stale,
        Refused::NoOffset,
        Refused::TooOld,
        Refused::Future,
        Refused::Implausible,
    ];
    fn slot(self) -> usize {
        self as usize
    }
    fn name(self) -> &'static str {
        match self {
            Refused::Version => "version",
            Refused::Length => "length",
            Refused::Contents => "contents",
            Refused::Foreign => "foreign",
            Refused::Stale => "duplicate_or_reordered",
            Refused::NoOffset => "no_clock_offset_yet",
            Refused::TooOld => "too_old",
            Refused::Future => "in_the_future",
            Refused::Implausible => "implausible",
        }
    }
}

/// Reasons a message can be refused for ([`Refused`]'s values).
pub const REFUSED_REASONS: usize = 9;
const _: () = assert!(<Refused as CounterKey>::ALL.len() == REFUSED_REASONS);

/// How a child is, as the supervisor publishes it in [`ChildSlot::health`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u64)]
pub enum Health {
    /// Started for the first time, no heartbeat yet (also: a supervisor that never wrote it).
    Starting = 0,
    /// Its heartbeat moves.
    Up = 1,
    /// It failed since it was last up: waiting for its restart, or restarted and not beating yet.
    Down = 2,
}

impl Health {
    /// `starting`, `up` or `down`.
    pub fn name(self) -> &'static str {
        match self {
            Health::Starting => "starting",
            Health::Up => "up",
            Health::Down => "down",
        }
    }
}

/// Words of a child's last-failure text (256 bytes).
pub const FAILURE_WORDS: usize = 32;

/// One child's slot: written by the child (pid, heartbeat, scheduling) and by the supervisor
/// (restarts, health, down since, last failure).
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
    /// [`Health`] as u64.
    pub health: AtomicU64,
    /// When it went down, CLOCK_MONOTONIC ns (0: it is not down).
    pub down_since_ns: AtomicU64,
    /// Bytes of `last_failure` in use (written last, Release).
    pub last_failure_len: AtomicU64,
    /// Why it last failed (the supervisor's words), as text.
    pub last_failure: [AtomicU64; FAILURE_WORDS],
}

impl ChildSlot {
    /// The child's health (an unknown value reads as `Down`).
    pub fn health(&self) -> Health {
        match self.health.load(Ordering::Relaxed) {
            0 => Health::Starting,
            1 => Health::Up,
            _ => Health::Down,
        }
    }
    /// Sets the health (the supervisor).
    pub fn set_health(&self, h: Health) {
        self.health.store(h as u64, Ordering::Relaxed);
    }
    /// Writes the last-failure text (the supervisor), cut to 256 bytes.
    pub fn set_last_failure(&self, text: &str) {
        store_text(&self.last_failure_len, &self.last_failure, text);
    }
    /// The last-failure text (empty: none yet).
    pub fn last_failure(&self) -> String {
        load_text(&self.last_failure_len, &self.last_failure)
    }
}

/// Writes `text` (cut to what `words` hold, on a character boundary) into `words`, publishing its
/// length in `len` last.
fn store_text(len: &AtomicU64, words: &[AtomicU64], text: &str) {
    len.store(0, Ordering::Release);
    let mut n = text.len().min(words.len() * 8);
    while !text.is_char_boundary(n) {
        n -= 1;
    }
    for (w, chunk) in words.iter().zip(text.as_bytes()[..n].chunks(8)) {
        let mut b = [0u8; 8];
        b[..chunk.len()].copy_from_slice(chunk);
        w.store(u64::from_le_bytes(b), Ordering::Relaxed);
    }
    // SYNC: Release publishes the bytes; pairs with the Acquire in `load_text`.
    len.store(n as u64, Ordering::Release);
}

/// Reads what [`store_text`] wrote (lossy UTF-8: a read during a write may mix two texts).
fn load_text(len: &AtomicU64, words: &[AtomicU64]) -> String {
    let n = (len.load(Ordering::Acquire) as usize).min(words.len() * 8);
    let mut bytes: Vec<u8> = words
        .iter()
        .flat_map(|w| w.load(Ordering::Relaxed).to_le_bytes())
        .collect();
    bytes.truncate(n);
    String::from_utf8_lossy(&bytes).into_owned()
}

/// What the servo process writes.
#[derive(Debug)]
#[repr(C)]
pub struct ServoShared {
    /// Its loop's statistics.
    pub stats: LoopStats,
    /// Pushes refused because a ring was full (its own: [`Ring::Tool`]).
    pub drops: Counters<Ring>,
    /// The last commanded force magnitude, N (f64 bits).
    pub command_n: AtomicU64,
    /// The display scale: 1 fresh, 0 stale (f64 bits).
    pub scale: AtomicU64,
    /// The last stale episode: the time of the newest object state it had, ns.
    pub stale_state_ns: AtomicU64,
    /// ... and when its command first reached zero in that episode, ns (0: not yet).
    pub stale_limp_ns: AtomicU64,
    /// The device safety limit that acted last (`device::safety::Limit::code`, 0: none yet).
    pub safety_limit: AtomicU64,
    /// ... when it acted last, ns.
    pub safety_at_ns: AtomicU64,
    /// Episodes of any limit acting so far.
    pub safety_episodes: AtomicU64,
    /// Round trips measured: from a tool sample to the object state computed with it arriving back
    /// (servo → physics → servo).
    pub roundtrip_count: AtomicU64,
    /// Their histogram.
    pub roundtrip: SharedHistogram,
    /// Object states read: how long each waited in the ring after physics computed it, ns (the
    /// pipeline's last hop, physics → servo; once per physics step).
    pub state_wait: SharedHistogram,
    /// Count of `state_wait` samples.
    pub state_wait_count: AtomicU64,
    /// Partners' reports reaching the displayed force: from the partner's physics tick (its
    /// report's time, on this machine's clock) to the servo tick that first reads a state
    /// computed with it, ns (once per report or track that changed the newest).
    pub remote_display: SharedHistogram,
    /// Count of `remote_display` samples.
    pub remote_display_count: AtomicU64,
    /// What the display stages did (`coop_model::display`).
    pub display: DisplayShared,
}

/// The servo's display stages (`coop_model::display::DisplayStats`), as the servo last published
/// them. f64 fields hold f64 bits.
#[derive(Debug)]
#[repr(C)]
pub struct DisplayShared {
    /// Corrections of the copy absorbed into the displayed object.
    pub corrections: AtomicU64,
    /// Servo ticks at which the step limiter held the displayed force back.
    pub ticks_limited: AtomicU64,
    /// The largest displayed-force step per tick, N (f64 bits).
    pub max_step_n: AtomicU64,
    /// The largest step beyond the displayed object's own contact change, N (f64 bits).
    pub max_correction_step_n: AtomicU64,
    /// Servo ticks at which the passivity controller added damping.
    pub ticks_damped: AtomicU64,
    /// The largest damping it added, N·s/m (f64 bits).
    pub max_damping_n_s_per_m: AtomicU64,
    /// The energy the display's deviation has injected into the user, J (f64 bits; ≤ 0 passive).
    pub energy_j: AtomicU64,
    /// The largest it ever was, J (f64 bits).
    pub max_energy_j: AtomicU64,
}

/// What the physics process writes.
#[derive(Debug)]
#[repr(C)]
pub struct PhysicsShared {
    /// Its loop's statistics.
    pub stats: LoopStats,
    /// Pushes refused because a ring was full (its own: object, report, trace).
    pub drops: Counters<Ring>,
    /// Remote reports taken from the ring.
    pub received: AtomicU64,
    /// Remote reports that did not convert to the model's (cannot happen from our own network
    /// process, which validated them; counted so that a foreign writer of the ring shows).
    pub rejected: AtomicU64,
    /// States adopted.
    pub adoptions: AtomicU64,
    /// The own tool sample's age when physics took it (the pipeline's first hop, servo →
    /// physics), ns.
    pub tool_wait: SharedHistogram,
    /// Count of `tool_wait` samples.
    pub tool_wait_count: AtomicU64,
    /// A partner's report or track's age when physics took it: from the partner's physics tick
    /// (on this machine's clock) through its network, zenoh and ours to this physics, ns.
    pub remote_wait: SharedHistogram,
    /// Count of `remote_wait` samples.
    pub remote_wait_count: AtomicU64,
    /// The world's objects (physics writes it at start).
    pub objects: AtomicU64,
    /// States adopted, by object (a world's adopted at once counts for each of its objects).
    pub adoptions_by_object: [AtomicU64; MAX_OBJECTS],
    /// Adoptions or steps that would have made the copy non-finite: the copy kept its state.
    pub nonfinite_kept: AtomicU64,
    /// The newest state, for a restarted physics to resume from (a seqlock: see
    /// [`ControlBlock::store_resume`]).
    pub resume_seq: AtomicU64,
    /// The words of that state: the count of objects, then an [`ObjectSample`] per object.
    pub resume: [AtomicU64; RESUME_WORDS],
    /// The last report sequence number, so a restarted physics continues the sequence (a receiver
    /// ignores sequence numbers it has seen).
    pub report_seq: AtomicU64,
    /// When the last report was made (the step's wake time, ns), and the report period: the network
    /// process wakes just after the next one instead of polling.
    pub last_report_ns: AtomicU64,
    /// See `last_report_ns`.
    pub report_period_ns: AtomicU64,
    /// Rollback and tool-track figures (methods that exchange tools; zero otherwise).
    pub rollback: RollbackShared,
}

// ---- physics/network: rollback and tool-track figures (timewarp on stations) ----

pub use super::rollback::{RollbackFigures, RollbackShared};

pub use super::device::DeviceShared;
pub use super::device::ShmText;

/// What the network process writes.
#[derive(Debug)]
#[repr(C)]
pub struct NetworkShared {
    /// Pushes refused because a ring was full (its own: [`Ring::Remote`]).
    pub drops: Counters<Ring>,
    /// Reports published.
    pub published: AtomicU64,
    /// Other sites' reports handed to physics.
    pub received: AtomicU64,
    /// Messages refused, by reason.
    pub refused: Counters<Refused>,
    /// States refused as implausible or as another object than their key's, by the object their
    /// key names (a world of several: which object's states are refused).
    pub refused_by_object: [AtomicU64; MAX_OBJECTS],
    /// What it put on the wire and got from it, by kind.
    pub traffic: Traffic,
    /// 1 when it emulates delay, jitter and loss on receive.
    pub emulated: AtomicU64,
    /// Messages the emulation dropped.
    pub emulated_lost: AtomicU64,
    /// Sites present in the session (liveliness), as a bit mask by site index.
    pub peers_present: AtomicU64,
    /// Sites that joined since the network process started.
    pub peer_joins: AtomicU64,
    /// Sites that left since the network process started.
    pub peer_leaves: AtomicU64,
    /// Sites lost (silent for longer than the loss limit), as a bit mask by site index.
    pub peers_lost: AtomicU64,
    /// Times a site was lost since the network process started.
    pub peer_losses: AtomicU64,
    /// Times a lost site was heard again.
    pub peer_rejoins: AtomicU64,
    /// States held because their sender's clock offset was not known yet (the newest of each
    /// site is checked again once it is; the others are superseded).
    pub held_for_offset: AtomicU64,
    /// Times a site's sequence was resynchronised after its genuine, newer states kept being
    /// refused as out of order (a forged or reset sequence number cannot silence a site).
    pub resyncs: AtomicU64,
    /// States a late joiner got from the session's queryable at start.
    pub join_states: AtomicU64,
    /// Per site: its clock minus ours, ns (i64 bits), from the NTP-style exchange.
    pub clock_offset_ns: [AtomicU64; MAX_SITES],
    /// Per site: the round trip of the exchange the offset came from, ns (0: not measured).
    pub clock_rtt_ns: [AtomicU64; MAX_SITES],
    /// Station-to-station latency, physics at the sender to the ring into our physics, ns.
    pub latency: SharedHistogram,
    /// Count of `latency` samples.
    pub latency_count: AtomicU64,
    /// The own reports and tracks: from physics' tick (their time) to their put on zenoh, ns
    /// (the pipeline's hop physics → network).
    pub publish_wait: SharedHistogram,
    /// Count of `publish_wait` samples.
    pub publish_wait_count: AtomicU64,
    /// Bytes of `locators` in use (written last, Release).
    pub locators_len: AtomicU64,
    /// The zenoh locators it listens on and its zenoh id, as text.
    pub locators: [AtomicU64; LOCATOR_WORDS],
}

/// The control block (in a [`crate::shm::BlockSegment`]).
#[derive(Debug)]
#[repr(C)]
pub struct ControlBlock {
    /// [`RunState`] as u64 (the supervisor).
    pub run_state: AtomicU64,
    /// Per child, indexed by [`Child`].
    pub children: [ChildSlot; CHILDREN],
    /// The session's time 0 on CLOCK_MONOTONIC, ns: the users' scripts run from it. 0 until known;
    /// set once (compare-exchange from 0) by whoever learns it first: the supervisor of a station
    /// started alone, or the network process from the session's launcher.
    pub epoch_ns: AtomicU64,
    /// The servo's figures.
    pub servo: ServoShared,
    /// Physics' figures.
    pub physics: PhysicsShared,
    /// The network's figures.
    pub network: NetworkShared,
    /// The task's outcome as this site shows it (the servo judges it live).
    pub task: TaskShared,
    /// The device's figures (the servo's: it alone opens the device).
    pub device: DeviceShared,
    /// The trial a study asks for, and how far each child is with it (stations started for a
    /// study: `trials = true`).
    pub trial: TrialShared,
}

/// Words of a trial's scenario text (32 KiB: a task scenario with participants is 3-6 KiB).
pub const TRIAL_SCENARIO_WORDS: usize = 4096;
/// Words of a trial's name (64 bytes).
pub const TRIAL_NAME_WORDS: usize = 8;

/// A study's trials on a station that stays up for all of them. The network process (its one
/// writer of `requested`, the scenario and the name) hears the next trial from the study runner;
/// each child then stops producing into its rings (`stopped`), and once all three have, drains
/// what it consumes, rebuilds from the trial's scenario and says so (`ready`); the network then
/// tells the runner, which announces the trial's time 0. No process restarts: the device stays
/// open, the rings and the zenoh session are reused.
#[derive(Debug, Default)]
#[repr(C)]
pub struct TrialShared {
    /// The trial asked for (numbered from 1; 0: none yet). Written after the scenario and name
    /// (Release); a child reads them after it (Acquire).
    pub requested: AtomicU64,
    /// Per child ([`Child`]): the newest trial for which it produces nothing more of the last one.
    pub stopped: [AtomicU64; CHILDREN],
    /// Per child: the newest trial it has rebuilt itself for (and waits for its time 0).
    pub ready: [AtomicU64; CHILDREN],
    /// The newest trial whose end the runner announced (the network process): the servo ramps
    /// its force out and holds it there until the next trial.
    pub ended: AtomicU64,
    /// Per child: why it could not rebuild for the requested trial (empty: it could).
    pub refused: [ShmText<FAILURE_WORDS>; CHILDREN],
    /// The trial's scenario, as TOML.
    pub scenario: ShmText<TRIAL_SCENARIO_WORDS>,
    /// The trial's name (its recordings are named by it).
    pub name: ShmText<TRIAL_NAME_WORDS>,
}

impl TrialShared {
    /// The trial asked for (0: none).
    pub fn requested(&self) -> u64 {
        // SYNC: Acquire pairs with the Release in `request`: the scenario and name are visible.
        self.requested.load(Ordering::Acquire)
    }

    /// Asks for trial `trial` of `scenario` named `name` (the network process); `false` (and
    /// nothing asked) when the scenario is longer than the block holds.
    pub fn request(&self, trial: u64, name: &str, scenario: &str) -> bool {
        if scenario.len() > TRIAL_SCENARIO_WORDS * 8 {
            return false;
        }
        self.scenario.store(scenario);
        self.name.store(name);
        // SYNC: Release publishes the texts with the number; pairs with `requested`'s Acquire.
        self.requested.store(trial, Ordering::Release);
        true
    }

    /// The runner announced the end of `trial`.
    pub fn set_ended(&self, trial: u64) {
        self.ended.store(trial, Ordering::Release);
    }

    /// Whether the end of `trial` (not 0) was announced.
    pub fn is_ended(&self, trial: u64) -> bool {
        trial > 0 && self.ended.load(Ordering::Acquire) >= trial
    }

    /// `child` produces nothing more of the trial before `trial`.
    pub fn set_stopped(&self, child: Child, trial: u64) {
        self.stopped[child as usize].store(trial, Ordering::Release);
    }

    /// Whether every child has stopped for `trial`.
    pub fn all_stopped(&self, trial: u64) -> bool {
        self.stopped
            .iter()
            .all(|s| s.load(Ordering::Acquire) >= trial)
    }

    /// `child` has rebuilt itself for `trial` (`refused`: why it could not; empty: it could).
    pub fn set_ready(&self, child: Child, trial: u64, refused: &str) {
        self.refused[child as usize].store(refused);
        self.ready[child as usize].store(trial, Ordering::Release);
    }

    /// Whether `child` is ready for `trial`, and if it refused it, why.
    pub fn ready(&self, child: Child, trial: u64) -> Option<Result<(), String>> {
        (self.ready[child as usize].load(Ordering::Acquire) >= trial).then(|| {
            let why = self.refused[child as usize].load();
            if why.is_empty() {
                Ok(())
            } else {
                Err(why)
            }
        })
    }
}

/// A task's state as the control block holds it ([`TaskShared::state`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u64)]
pub enum TaskState {
    /// The scenario has no task, or the session has not started.
    None = 0,
    /// Neither done nor failed yet.
    Running = 1,
    /// Done (its condition held for its hold time).
    Done = 2,
    /// Failed (a fail condition, or the timeout).
    Failed = 3,
}

impl TaskState {
    /// The state a word holds (an unknown value reads as `None`).
    pub fn from_word(w: u64) -> Self {
        match w {
            1 => Self::Running,
            2 => Self::Done,
            3 => Self::Failed,
            _ => Self::None,
        }
    }

    /// Its name, as status and recordings say it.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Running => "running",
            Self::Done => "done",
            Self::Failed => "failed",
        }
    }
}

/// The task's outcome, written by the servo (its one writer) when it changes: a seqlock of
/// relaxed words, so a reader gets the state, its time and its cause from one write, never a mix
/// of two ([`TaskShared::publish`], [`TaskShared::read`]).
#[derive(Debug)]
#[repr(C)]
pub struct TaskShared {
    /// Odd while the servo writes, even when done (0: never written).
    pub seq: AtomicU64,
    /// [`TaskState`] as u64.
    pub state: AtomicU64,
    /// When it was done or failed, s of session time, as f64 bits.
    pub at_s: AtomicU64,
    /// What failed it: 0 the timeout (or not failed), k + 1 the task's `fail[k]`.
    pub failed_by: AtomicU64,
}

impl TaskShared {
    /// Publishes an outcome: `state`, when it ended (s of session time) and what failed it (as
    /// [`TaskShared::failed_by`]).
    pub fn publish(&self, state: TaskState, at_s: f64, failed_by: u64) {
        // REAL-TIME: relaxed and release stores only.
        let seq = self.seq.load(Ordering::Relaxed);
        self.seq.store(seq | 1, Ordering::Relaxed);
        // SYNC: the odd sequence is visible before any word changes.
        core::sync::atomic::fence(Ordering::Release);
        self.state.store(state as u64, Ordering::Relaxed);
        self.at_s.store(at_s.to_bits(), Ordering::Relaxed);
        self.failed_by.store(failed_by, Ordering::Relaxed);
        // SYNC: Release publishes the words with the even sequence; pairs with `read`'s Acquire.
        self.seq.store((seq | 1).wrapping_add(1), Ordering::Release);
    }

    /// The outcome last published, whole: its state, when it ended and what failed it (`None`
    /// while the servo is writing after repeated tries; the caller looks again later).
    pub fn read(&self) -> Option<(TaskState, f64, u64)> {
        for _ in 0..100 {
            let before = self.seq.load(Ordering::Acquire);
            let state = self.state.load(Ordering::Relaxed);
            let at = self.at_s.load(Ordering::Relaxed);
            let by = self.failed_by.load(Ordering::Relaxed);
            // SYNC: the word loads complete before the sequence is read again.
            core::sync::atomic::fence(Ordering::Acquire);
            if before & 1 == 0 && self.seq.load(Ordering::Relaxed) == before {
                return Some((TaskState::from_word(state), f64::from_bits(at), by));
            }
            std::thread::yield_now();
        }
        None
    }
}

/// Words of the resume state: a count, then every object's sample.
pub const RESUME_WORDS: usize = 1 + MAX_OBJECTS * ObjectSample::WORDS;
/// Words of the locator text (512 bytes).
pub const LOCATOR_WORDS: usize = 64;

// Made only of AtomicU64 (directly, in arrays, in LoopStats, ChildSlot, Counters (its PhantomData is
// zero-sized), ShmText and the per-process groups).
// SAFETY: repr(C), AtomicU64s only (above): all-zero and every bit pattern are valid values.
unsafe impl ShmShared for ControlBlock {
    const TYPE_NAME: &'static str = "coop.ControlBlock.v25";
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
    /// Pushes into `ring` refused because it was full, as its producer counted them.
    pub fn ring_drops(&self, ring: Ring) -> u64 {
        match ring.producer() {
            Child::Servo => self.servo.drops.get(ring),
            Child::Physics => self.physics.drops.get(ring),
            Child::Network => self.network.drops.get(ring),
        }
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

    /// Physics (the one writer) stores its newest state of the world's `objects` objects
    /// (`sample(k)` of each) for a successor to resume from. A seqlock of relaxed atomic words
    /// (the count, then the samples' `to_words`): odd sequence while writing, even when done.
    pub fn store_resume(&self, objects: usize, sample: impl Fn(usize) -> ObjectSample) {
        // REAL-TIME: relaxed and release stores only.
        let objects = objects.min(MAX_OBJECTS);
        let seq = self.physics.resume_seq.load(Ordering::Relaxed);
        self.physics.resume_seq.store(seq | 1, Ordering::Relaxed);
        // SYNC: the odd sequence is visible before any word changes.
        core::sync::atomic::fence(Ordering::Release);
        self.physics.resume[0].store(objects as u64, Ordering::Relaxed);
        for k in 0..objects {
            let at = 1 + k * ObjectSample::WORDS;
            let words = &self.physics.resume[at..at + ObjectSample::WORDS];
            for (w, v) in words.iter().zip(sample(k).to_words()) {
                w.store(v, Ordering::Relaxed);
            }
        }
        // SYNC: Release publishes the words with the even sequence; pairs with `resume`'s Acquire.
        self.physics
            .resume_seq
            .store((seq | 1).wrapping_add(1), Ordering::Release);
    }

    /// The newest state physics stored, if any and if it reads back whole and valid (every
    /// object's, each naming itself).
    pub fn resume(&self) -> Option<Resume> {
        for _ in 0..100 {
            let before = self.physics.resume_seq.load(Ordering::Acquire);
            if before == 0 {
                return None;
            }
            let mut words = [0u64; RESUME_WORDS];
            for (v, w) in words.iter_mut().zip(&self.physics.resume) {
                *v = w.load(Ordering::Relaxed);
            }
            // SYNC: the word loads complete before the sequence is read again.
            core::sync::atomic::fence(Ordering::Acquire);
            if before & 1 == 0 && self.physics.resume_seq.load(Ordering::Relaxed) == before {
                return Resume::from_words(&words);
            }
            std::thread::yield_now();
        }
        None
    }

    /// Writes the locator text (the network process, once it knows it).
    pub fn set_locators(&self, text: &str) {
        self.network.locators_len.store(0, Ordering::Release);
        let bytes = &text.as_bytes()[..text.len().min(LOCATOR_WORDS * 8)];
        for (i, chunk) in bytes.chunks(8).enumerate() {
            let mut w = [0u8; 8];
            w[..chunk.len()].copy_from_slice(chunk);
            self.network.locators[i].store(u64::from_le_bytes(w), Ordering::Relaxed);
        }
        // SYNC: Release publishes the bytes; pairs with the Acquire in `locators`.
        self.network
            .locators_len
            .store(bytes.len() as u64, Ordering::Release);
    }

    /// The locator text (lossy UTF-8; empty until the network process wrote it).
    pub fn locators(&self) -> String {
        let len =
            (self.network.locators_len.load(Ordering::Acquire) as usize).min(LOCATOR_WORDS * 8);
        let mut bytes = Vec::with_capacity(len);
        for w in &self.network.locators {
            bytes.extend_from_slice(&w.load(Ordering::Relaxed).to_le_bytes());
        }
        bytes.truncate(len);
        String::from_utf8_lossy(&bytes).into_owned()
    }
}

/// The world a physics process stored for its successor (see [`ControlBlock::resume`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resume {
    /// How many objects (1 ..= [`MAX_OBJECTS`]).
    pub objects: usize,
    /// Each object's sample, in the world's order (past `objects`, defaults).
    pub samples: [ObjectSample; MAX_OBJECTS],
}

impl Resume {
    /// From the seqlock's words: `None` unless the count is 1 ..= [`MAX_OBJECTS`], each sample
    /// names its own index and holds a valid state.
    fn from_words(words: &[u64; RESUME_WORDS]) -> Option<Self> {
        let objects = usize::try_from(words[0])
            .ok()
            .filter(|n| (1..=MAX_OBJECTS).contains(n))?;
        let mut samples = [ObjectSample::default(); MAX_OBJECTS];
        for (k, s) in samples[..objects].iter_mut().enumerate() {
            let at = 1 + k * ObjectSample::WORDS;
            let w: &[u64; ObjectSample::WORDS] =
                words[at..at + ObjectSample::WORDS].try_into().ok()?;
            *s = ObjectSample::from_words(w);
            (s.object() == Some(k) && s.state().is_some()).then_some(())?;
        }
        Some(Self { objects, samples })
    }

    /// The first object's sample.
    pub fn first(&self) -> &ObjectSample {
        &self.samples[0]
    }

    /// Every object's state, in the world's order (past `objects`, at rest at the origin).
    pub fn states(&self) -> [BodyState; MAX_OBJECTS] {
        std::array::from_fn(|k| {
            self.samples[k]
                .state()
                .filter(|_| k < self.objects)
                .unwrap_or_else(|| BodyState::at_rest(coop_model::body::Vec3::zeros()))
        })
    }
}

/// Records `ns` in `h`, counting it in `count` (the first sample sets the minimum). Single writer.
pub fn record_counted(h: &SharedHistogram, count: &AtomicU64, ns: u64) {
    // REAL-TIME: relaxed loads and stores only.
    let n = count.load(Ordering::Relaxed);
    h.record(ns, n == 0);
    count.store(n + 1, Ordering::Relaxed);
}
