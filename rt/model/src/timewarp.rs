//! Method `timewarp`: exchange the users' *tools* (the causes), not the object's state (the
//! effects), and roll back.
//!
//! Every site runs the same deterministic physics on a common tick grid. At each tick every user's
//! tool acts on the copy through the same contact law (Eq. 7, with friction memory), computed from
//! the tool's position at that tick, quantized to [`QUANTUM_M`] so every site uses the same bits: the
//! own tool as measured, a remote one from its received trajectory, and beyond the last received
//! tick a bounded prediction and then a hold. A site reports the own
//! tool's positions of the last [`WINDOW_TICKS`] ticks (so a few lost reports lose nothing). When
//! more is lost in a row, the receiver holds later positions but not the gap's: it asks for the
//! gap ([`ToolReport::need`]) and the sender sends the window from there in every other report.
//!
//! The copy's full state (body, momenta, environment friction memory, every tool's friction
//! memory) is kept for every tick of the horizon. When a received position differs from what was
//! predicted at a tick already simulated, the copy is restored to that tick and re-simulated to now
//! with what is known ([`Stats::rollbacks`]). A position older than the horizon cannot be undone: it
//! is counted ([`Stats::fallbacks`]) and the rollback starts at the oldest tick kept.
//!
//! Ticks whose inputs are known from every site are *confirmed*: their state is the same bits at
//! every site. Each report carries the sender's confirmed frontier and a hash of its state there;
//! a receiver that has confirmed the same tick compares ([`Stats::hash_checks`],
//! [`Stats::hash_mismatches`]), so a divergence of confirmed state is never silent.
//!
//! A divergence heals: confirmed states differ only where a site never knew an input (a link down
//! for longer than the horizon: a fallback; a physics process that started after the session did,
//! restarted or late, which joins the grid where the session is ([`Consistency::start_at_tick`])
//! with no history before it), and then no
//! rollback can repair them. A site whose confirmed state differs from that of a site *before* it
//! asks that site for its state ([`ToolReport::need_state`]); that site sends its full confirmed
//! state ([`Snapshot`]: body, momenta, every friction memory) with its reports while asked, and
//! the asking site adopts it at that tick and re-simulates to now ([`Stats::adopted_states`]):
//! the paper's adoption of a received state, at the confirmed frontier. Sites are ordered by the
//! tick their physics process started at ([`ToolReport::started_tick`]: the newest yields), then
//! by number; the first site's history is the one kept, so sites that all disagree still converge
//! on one. A state that puts the object deeper into the environment than all the users' forces
//! together could ([`TimeWarp::set_max_spring_energy`]) is not adopted: the mismatches go on,
//! counted.
//!
//! What rolling back costs the user's feel is counted too: confirmed ticks in which the own tool
//! touched the object though the copy had shown no contact when it first simulated them
//! ([`Stats::unfelt_contact_ticks`]), and the other way round ([`Stats::phantom_contact_ticks`]).
//! "Shown" is the physics' contact at the tick's first simulation, not the force the servo
//! displayed (a station that catches up several ticks in one period simulates some it never
//! displays), and a tick that leaves the history before it is confirmed (a partner silent for
//! longer than the horizon, a fallback) is not compared.
//!
//! A contact the user missed is replayed to them, late, when their hand is still where it was:
//! a rollback whose re-simulation has the own tool touching the object in ticks that showed no
//! contact live ([`REPLAY_MIN_TICKS`] or more), while no tool touches the object now (a free
//! object's knock, not a grasp: replayed against several hands that all moved on, the history
//! cost the three-user grasp 2 of 12 seeds' carry at 200 ms) and the own tool is within
//! [`REPLAY_REACH_M`] of where it was then, makes [`Consistency::shown`] (what the servo
//! renders against) the re-simulated history from [`REPLAY_LEAD_TICKS`] before the contact on,
//! [`REPLAY_SPEED`] times as fast and at the history's own pace into and through the contact,
//! until it reaches the copy ([`Stats::replays`]). The user feels the knock the confirmed history
//! says they got, as hard as it was, instead of the object appearing where the knock left it:
//! at a constant 500 ms the paper task's disk knocks user 2's waiting tool 0.2 s before any news of
//! the push can reach user 2. The copy, its confirmed state and every site's physics are
//! untouched; a contact of the live copy, or the hand moving away, ends a replay at once.
//!
//! Local lag (Mauve et al. 2004's companion of timewarp, GGPO's input delay): while the own tool
//! and a partner's are both within [`LOCAL_LAG_NEAR_M`] of the object, the own tool's measured
//! positions enter the physics late by [`LOCAL_LAG_SHARE`] of the partner's measured one-way delay
//! (at most [`LOCAL_LAG_MAX_TICKS`]), grown into at half speed and caught up at twice it, the
//! latter never while the own tool touches the object. Each copy then holds its own tool and the partners'
//! newest known positions nearer the same moment, so each user's hand reacts to an object that moves
//! as the partners' hands move it ([`Stats::local_lag_ticks`], [`Stats::lagged_ticks`]). The input
//! of a tick is whatever position the site stepped it with: every site still steps the same inputs.
//!
//! Determinism: the forces are summed in site order whatever site computes them, every input is an
//! integer, and the step uses only `+ − × ÷ sqrt` and `nalgebra`'s rotations (the same code on the
//! same platform gives the same bits; see the crate docs on transcendental functions).

use crate::body::{BodyState, Vec3};
use crate::contact::{
    tool_contact, ContactForce, ContactParams, EnvContactState, ToolContactState,
};
use crate::method::{integrate, Adoption, Consistency, ObjectCopy, Report, World, MAX_SITES};

/// The quantum of a tool position on the wire and in the physics, m (0.01 mm).
pub const QUANTUM_M: f64 = 1e-5;
/// Own tool positions in each report: the last this many ticks.
pub const WINDOW_TICKS: usize = 256;
/// A remote tool that touched the object at its last known tick is extrapolated with its last
/// velocity for at most this many ticks, then held: the contact, not the hand's motion, decides
/// where it goes next (the hand's force balance against the object cannot be predicted, and a tool
/// predicted on into the object pushes it through the grasp: at 150 ms the copies then disagree by
/// centimetres while both users hold the disk).
pub const EXTRAPOLATE_TICKS: i64 = 20;
/// A remote tool that was free at its last known tick is predicted as a reaching hand: on with its
/// mean velocity over this many ticks (the last 10 ms: through the quantization and the sensor's
/// noise)...
pub const REACH_VELOCITY_TICKS: i64 = 10;
/// ...slowing as a reach does, so that `h` ticks on it has gone `v·h·τ/(h+τ)`, never farther than
/// `v·τ` (τ this many ticks, 0.3 s at 1 kHz; rational, not exponential: only `+ − × ÷`). Over a
/// delay a free tool crosses, this shows a push in the copy before the pushing tool's positions
/// arrive, so a far user feels the pushed object arrive when it does: the paper task at a constant
/// 300 ms passes all 12 phases with it, 10 without (seeds 1–3).
pub const REACH_TIME_TICKS: i64 = 300;
/// How long a reach is predicted before the tool is held, ticks.
pub const REACH_TICKS: i64 = 1000;

/// A contact the own user missed (see the module docs) is replayed at this many times
/// its speed (the contact itself at its own) until the display catches up with the copy: a
/// replay of `d` ticks of history ends about `d / (REPLAY_SPEED - 1)` ticks later (250 ms after
/// a 500 ms delay's news).
pub const REPLAY_SPEED: i64 = 3;
/// A replay slows to the history's own pace this many ticks before a contact in it, so the
/// object meets the hand as fast as it did (no harder).
pub const REPLAY_SLOW_TICKS: i64 = 10;
/// A replay starts this many ticks before the missed contact, so the user sees the object come.
pub const REPLAY_LEAD_TICKS: i64 = 40;
/// A replay starts only while the own tool is within this of where the missed contact had it,
/// and ends when it moves farther: the history replayed is one in which the hand was there, m.
pub const REPLAY_REACH_M: f64 = 0.002;
/// ... and only for a missed contact of at least this many ticks.
pub const REPLAY_MIN_TICKS: u64 = 3;

/// Local lag (Mauve et al. 2004's companion of timewarp): while the own tool and another site's
/// are both within this of the object's surface, the own tool's positions enter the physics late
/// by [`LOCAL_LAG_SHARE`] of that site's measured delay, m.
pub const LOCAL_LAG_NEAR_M: f64 = 0.01;
/// The share of the nearby partners' (largest) measured one-way delay the own tool is delayed by.
/// The copy then holds the own tool and the partners' newest known positions nearer the same
/// moment (the partners' are predicted as far ahead as before: the own positions are sent as they
/// are stepped): a three-user carry at 200 ms, whose users' hands each react to the disk a delay
/// late, does every phase in 23 of 24 seeds instead of 11 (the 3-D three-user lift in 18 instead
/// of 0).
pub const LOCAL_LAG_SHARE: f64 = 0.5;
/// The most the own tool is delayed by, ticks (100 ms at 1 kHz): beyond it a lag costs the
/// single-user parts of a task more than it saves (the 3-D lift at 300 ms fails with 150).
pub const LOCAL_LAG_MAX_TICKS: i64 = 100;
/// How the lag changes, in half ticks of the own tool's measured positions per tick: it grows by
/// playing them at half speed (a position between two measured ones at the odd half ticks) and
/// shrinks by playing them at twice the speed, the latter only while the own tool touches nothing
/// (a hand in contact is never fast-forwarded into the object; it may be slowed).
const LAG_GROW_HALF_TICKS: i64 = 1;
const LAG_SHRINK_HALF_TICKS: i64 = 4;
/// ... and within these of its target (half ticks) it stays (a measured delay jitters; none
/// above it when no lag is wanted): it settles up to a tick below its target.
const LAG_SLACK_BELOW_HALF_TICKS: i64 = 2;
const LAG_SLACK_ABOVE_HALF_TICKS: i64 = 20;
/// The largest local lag, ticks ([`TimeWarp::set_local_lag`]): 200 ms at the fastest physics
/// rate a scenario may have (20 kHz).
pub const MAX_LOCAL_LAG_TICKS: i64 = 4000;
/// The own tool's measured positions kept for the lag (a power of two above the largest lag and
/// its slack, in ticks).
const MEASURED_RING: usize = 4096;
const _: () =
    assert!(MEASURED_RING as i64 > MAX_LOCAL_LAG_TICKS + LAG_SLACK_ABOVE_HALF_TICKS / 2 + 1);
/// A partner's measured one-way delay follows each report's by this share (a low-pass filter).
const DELAY_FILTER_SHARE: f64 = 0.125;

/// A tool position on the tick grid, in quanta.
pub type Quantized = [i32; 3];

/// Where a tool is before anything is known of it: 10 km away, touching nothing.
pub const UNKNOWN: Quantized = [1_000_000_000; 3];

/// A received position and its tick.
type Received = Option<(i64, Quantized)>;

/// The fastest a tool moves in the physics, m/s: a prediction that jumps (a held position meeting
/// the received one) must not kick the object through the contact's damping.
pub const MAX_TOOL_SPEED_M_PER_S: f64 = 10.0;

/// Quantizes a position (clamped to ±20 km, far outside any world).
pub fn quantize(p: Vec3) -> Quantized {
    let q = |x: f64| (x / QUANTUM_M).round().clamp(-2e9, 2e9) as i32;
    [q(p.x), q(p.y), q(p.z)]
}

/// A quantized position in metres.
pub fn position(q: Quantized) -> Vec3 {
    Vec3::new(
        f64::from(q[0]) * QUANTUM_M,
        f64::from(q[1]) * QUANTUM_M,
        f64::from(q[2]) * QUANTUM_M,
    )
}

/// A site's full state at the start of one of its confirmed ticks: what a site whose confirmed
/// history diverged from it adopts (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Snapshot {
    /// The tick.
    pub tick: i64,
    /// The object.
    pub state: BodyState,
    /// The environment's friction memory.
    pub env: EnvContactState,
    /// Every tool's friction memory.
    pub contacts: [ToolContactState; MAX_SITES],
}

// `ToolReport::need_state` has a bit per site.
const _: () = assert!(MAX_SITES <= 8);

/// What a timewarp site reports: its tool's recent positions, and its confirmed frontier's hash.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolReport {
    /// The tick of `positions[0]`.
    pub first_tick: i64,
    /// How many of `positions` are filled.
    pub count: usize,
    /// Own tool positions, tick `first_tick + k` at `k`.
    pub positions: [Quantized; WINDOW_TICKS],
    /// The sender's confirmed frontier: the first tick whose inputs it does not all know.
    pub confirmed_tick: i64,
    /// The hash of its state at the start of that tick (0: none kept).
    pub confirmed_hash: u64,
    /// Per site `j`: the first tick of `j`'s positions the sender lacks though it holds later
    /// ones (reports lost in a row for longer than the window), for `j` to send again; -1: none.
    pub need: [i64; MAX_SITES],
    /// Bit `j`: the sender's confirmed state differs from site `j`'s (`j` before the sender), and
    /// it asks `j` for [`ToolReport::state`].
    pub need_state: u8,
    /// The session tick at which the sender's physics process started (0: at the session's start;
    /// later: a restart, a late station). Sites are ordered by it, then by number: a site adopts
    /// the confirmed state of one before it (see the module docs).
    pub started_tick: u64,
    /// The sender's state at `confirmed_tick`, sent while a site after it asks for it.
    pub state: Option<Snapshot>,
}

impl ToolReport {
    /// No positions and no confirmed frontier (a `coupled` state sent apart from its track).
    pub const NONE: ToolReport = ToolReport {
        first_tick: 0,
        count: 0,
        positions: [[0; 3]; WINDOW_TICKS],
        confirmed_tick: 0,
        confirmed_hash: 0,
        need: [-1; MAX_SITES],
        need_state: 0,
        started_tick: 0,
        state: None,
    };
}

/// What the method did, for status, recordings and benchmarks.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Stats {
    /// Rollbacks (restores and re-simulations).
    pub rollbacks: u64,
    /// Ticks re-simulated in all.
    pub resimulated_ticks: u64,
    /// The deepest rollback, ticks.
    pub max_depth: u64,
    /// Received positions older than the horizon (could not be undone), and gaps of lost
    /// reports that left the horizon before their sender repaired them (never known).
    pub fallbacks: u64,
    /// Confirmed-frontier hashes compared with the sender's.
    pub hash_checks: u64,
    /// ... that differed.
    pub hash_mismatches: u64,
    /// Every rollback's depth, ticks (for percentiles).
    pub depths: crate::histogram::DepthHistogram,
    /// Confirmed ticks in which the own tool touched the object but had not when the tick was
    /// first simulated (live): contact the user was never shown, because the news of it (a remote
    /// push that brought the object) came after the user had lived through it.
    pub unfelt_contact_ticks: u64,
    /// Confirmed ticks in which the own tool did not touch the object but had when the tick was
    /// first simulated: contact the user was shown that the confirmed history took back (a
    /// prediction's).
    pub phantom_contact_ticks: u64,
    /// Confirmed states adopted from a site before this one whose confirmed history differed
    /// (after a fallback or a restart): see the module docs.
    pub adopted_states: u64,
    /// Missed contacts replayed to the own user ([`Consistency::shown`]).
    pub replays: u64,
    /// The own tool's local lag now, ticks ([`LOCAL_LAG_SHARE`]).
    pub local_lag_ticks: u64,
    /// ... the largest it has been ...
    pub max_local_lag_ticks: u64,
    /// ... and the ticks simulated with a lag.
    pub lagged_ticks: u64,
}

/// One tick's record: the state at its start, and the inputs used in it.
#[derive(Debug, Clone, Copy)]
struct Slot {
    tick: i64,
    copy: ObjectCopy,
    contacts: [ToolContactState; MAX_SITES],
    inputs: [Quantized; MAX_SITES],
    /// Per site: whether `inputs` held a received (true) or predicted (false) position.
    known: [bool; MAX_SITES],
    /// Whether the own tool touched the object in this tick's first (live) simulation...
    felt: bool,
    /// ...and in its latest.
    touched: bool,
}

/// The `timewarp` method of one site.
#[derive(Debug, Clone)]
pub struct TimeWarp {
    me: usize,
    sites: usize,
    dt: f64,
    contact: ContactParams,
    radii: [f64; MAX_SITES],
    /// Ring of slots, tick `t` at `t % len`.
    slots: Box<[Slot]>,
    /// The tick the copy is at the start of (the next to simulate).
    now_tick: i64,
    /// Per site: received positions with their ticks (ring like `slots`).
    received: Box<[[Received; MAX_SITES]]>,
    /// Per site: the tick up to which every position is known (-1: none); a gap (reports lost
    /// for longer than the window) holds it back until the sender repairs it.
    known_until: [i64; MAX_SITES],
    /// Per site: the newest tick whose position is known (-1: none).
    newest: [i64; MAX_SITES],
    /// Per site: the first own tick it last asked for again ([`ToolReport::need`]; -1: none).
    asked: [i64; MAX_SITES],
    /// Per site: the gap its frontier waits at was given up (counted once).
    given_up: [bool; MAX_SITES],
    /// Whether the last report repaired a gap (repairs alternate with the newest window).
    repaired_last: std::cell::Cell<bool>,
    /// Per site before this one: its confirmed state differed from ours at the last comparison,
    /// and we ask it for that state.
    want_state: [bool; MAX_SITES],
    /// Per site: it asks for our confirmed state.
    state_asked: [bool; MAX_SITES],
    /// The tick this site's physics process started at ([`ToolReport::started_tick`]).
    started_tick: u64,
    /// The most environment-spring energy an adopted state may hold, J.
    max_spring_j: f64,
    contacts: [ToolContactState; MAX_SITES],
    /// The oldest tick a received position changed since the last rollback.
    dirty_from: Option<i64>,
    /// The own tool's position at the tick being simulated: the measured one, `lag` ticks late.
    own: Quantized,
    /// The own tool's measured positions, the `k`-th at `k % MEASURED_RING`, and how many.
    measured: Box<[Quantized]>,
    measured_count: i64,
    /// Which measured position is the own input, in half ticks (the lag grows at half speed).
    play_head: i64,
    /// The lag wanted now, ticks (0: none).
    lag_target: i64,
    /// Per site: its positions' measured one-way delay, ticks (filtered; 0: none yet).
    delay_ticks: [f64; MAX_SITES],
    /// The share of a near partner's delay the own tool is lagged by, and the most, ticks.
    lag_share: f64,
    lag_max: i64,
    stats: Stats,
    /// The first confirmed tick not yet compared, live against confirmed contact.
    tallied_until: i64,
    /// A missed contact being replayed: the tick shown, and the own tool's position then.
    replay: Option<(i64, Quantized)>,
    /// Missed contacts before this tick were replayed (or passed over): not again.
    replayed_until: i64,
    /// The tick this site's history starts at (0, or where a restarted physics joined the grid:
    /// [`Consistency::start_at_tick`]).
    origin_tick: i64,
}

impl TimeWarp {
    /// Site `me` of `sites`, stepping `dt` s, with the tool contact law and each site's tool
    /// radius, keeping `horizon_ticks` of history; starting from `copy` at tick 0.
    pub fn new(
        me: usize,
        sites: usize,
        dt: f64,
        contact: ContactParams,
        radii: [f64; MAX_SITES],
        horizon_ticks: usize,
        copy: &ObjectCopy,
    ) -> Self {
        let len = horizon_ticks.max(WINDOW_TICKS) + 1;
        let slot = Slot {
            tick: i64::MIN,
            copy: *copy,
            contacts: [ToolContactState::default(); MAX_SITES],
            inputs: [UNKNOWN; MAX_SITES],
            known: [false; MAX_SITES],
            felt: false,
            touched: false,
        };
        Self {
            me,
            sites: sites.min(MAX_SITES),
            dt,
            contact,
            radii,
            slots: vec![slot; len].into_boxed_slice(),
            now_tick: 0,
            received: vec![[None; MAX_SITES]; len].into_boxed_slice(),
            known_until: [-1; MAX_SITES],
            newest: [-1; MAX_SITES],
            asked: [-1; MAX_SITES],
            given_up: [false; MAX_SITES],
            repaired_last: std::cell::Cell::new(false),
            want_state: [false; MAX_SITES],
            state_asked: [false; MAX_SITES],
            started_tick: 0,
            max_spring_j: f64::INFINITY,
            contacts: [ToolContactState::default(); MAX_SITES],
            dirty_from: None,
            own: [0; 3],
            measured: vec![[0; 3]; MEASURED_RING].into_boxed_slice(),
            measured_count: 0,
            play_head: 0,
            lag_target: 0,
            delay_ticks: [0.0; MAX_SITES],
            lag_share: LOCAL_LAG_SHARE,
            lag_max: LOCAL_LAG_MAX_TICKS,
            stats: Stats::default(),
            tallied_until: 0,
            replay: None,
            replayed_until: 0,
            origin_tick: 0,
        }
    }

    /// This site's physics process started at session tick `tick` (a restart, a late station):
    /// it yields to the sites that started before it (see the module docs).
    pub fn set_started_tick(&mut self, tick: u64) {
        self.started_tick = tick;
    }

    /// An adopted state may put the object into the environment's penalty springs with at most
    /// `joules` (what every user pressing it with all the device's force could; a deeper one is
    /// not adopted).
    pub fn set_max_spring_energy(&mut self, joules: f64) {
        self.max_spring_j = joules;
    }

    /// What it did so far.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// Ticks of history kept (the horizon, at least [`WINDOW_TICKS`], and the current tick).
    pub fn history_ticks(&self) -> usize {
        self.slots.len()
    }

    /// The horizon, ticks.
    fn len(&self) -> i64 {
        self.slots.len() as i64
    }

    /// The oldest tick whose record is still kept.
    fn oldest_kept(&self) -> i64 {
        (self.now_tick - self.len() + 1).max(self.origin_tick)
    }

    fn idx(&self, tick: i64) -> usize {
        tick.rem_euclid(self.len()) as usize
    }

    /// The first tick whose inputs are not all known.
    pub fn confirmed_tick(&self) -> i64 {
        (0..self.sites)
            .map(|j| {
                if j == self.me {
                    self.now_tick
                } else {
                    self.known_until[j] + 1
                }
            })
            .min()
            .unwrap_or(self.now_tick)
    }

    /// The received position of site `j` at tick `t`, if it is kept.
    fn received_at(&self, j: usize, t: i64) -> Option<Quantized> {
        self.received[self.idx(t)][j]
            .filter(|(tick, _)| *tick == t)
            .map(|(_, q)| q)
    }

    /// The input of site `j` at tick `t`: received, or predicted from its last known positions.
    fn input(&self, j: usize, t: i64) -> (Quantized, bool) {
        if let Some(q) = self.received_at(j, t) {
            return (q, true);
        }
        // In a gap, predicted on from before it (as it was live); past the newest, from that.
        let last = if t < self.newest[j] {
            self.known_until[j]
        } else {
            self.newest[j]
        };
        let Some(p) = self.received_at(j, last) else {
            // Nothing known yet (or only what left the horizon): where it was last used.
            let prev = &self.slots[self.idx(t - 1)];
            let q = if prev.tick == t - 1 {
                prev.inputs[j]
            } else {
                UNKNOWN
            };
            return (q, false);
        };
        let at = |t: i64| self.received_at(j, t);
        let at_last = &self.slots[self.idx(last)];
        let free = at_last.tick == last && !at_last.contacts[j].touching();
        if free {
            return (
                self.reach(p, at(last - REACH_VELOCITY_TICKS), t - last),
                false,
            );
        }
        let v = at(last - 1).map_or([0; 3], |p0| [p[0] - p0[0], p[1] - p0[1], p[2] - p0[2]]);
        let k = (t - last).clamp(0, EXTRAPOLATE_TICKS) as i32;
        (
            [
                p[0].saturating_add(v[0].saturating_mul(k)),
                p[1].saturating_add(v[1].saturating_mul(k)),
                p[2].saturating_add(v[2].saturating_mul(k)),
            ],
            false,
        )
    }

    /// A free remote tool `h` ticks after it was last known at `p` (and at `earlier`,
    /// [`REACH_VELOCITY_TICKS`] before): see [`REACH_TIME_TICKS`]. Held where nothing earlier is
    /// known.
    fn reach(&self, p: Quantized, earlier: Option<Quantized>, h: i64) -> Quantized {
        let Some(p0) = earlier else {
            return p;
        };
        let h = h.clamp(0, REACH_TICKS) as f64;
        let tau = REACH_TIME_TICKS as f64;
        // Quanta per tick.
        let v: [f64; 3] = std::array::from_fn(|k| {
            f64::from(p[k].saturating_sub(p0[k])) / REACH_VELOCITY_TICKS as f64
        });
        let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let max = MAX_TOOL_SPEED_M_PER_S * self.dt / QUANTUM_M;
        let scale = if speed > max { max / speed } else { 1.0 };
        let gone = h * tau / (h + tau) * scale;
        let q = |k: usize| {
            let d = (v[k] * gone).round().clamp(-2e9, 2e9) as i32;
            p[k].saturating_add(d)
        };
        [q(0), q(1), q(2)]
    }

    /// Simulates tick `self.now_tick` on `copy` and keeps its record.
    fn tick(&mut self, world: &World, copy: &mut ObjectCopy) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let t = self.now_tick;
        let prev = self.slots[self.idx(t - 1)];
        let mut slot = Slot {
            tick: t,
            copy: *copy,
            contacts: self.contacts,
            inputs: [[0; 3]; MAX_SITES],
            known: [false; MAX_SITES],
            felt: false,
            touched: false,
        };
        let mut users = [ContactForce::default(); MAX_SITES];
        for (j, user) in users.iter_mut().enumerate().take(self.sites) {
            let (q, known) = if j == self.me {
                (self.own_at(t), true)
            } else {
                self.input(j, t)
            };
            slot.inputs[j] = q;
            slot.known[j] = known;
            let p = position(q);
            let v = if prev.tick == t - 1 && prev.inputs[j] != UNKNOWN && q != UNKNOWN {
                let v = (p - position(prev.inputs[j])) / self.dt;
                let speed = v.norm();
                if speed > MAX_TOOL_SPEED_M_PER_S {
                    v * (MAX_TOOL_SPEED_M_PER_S / speed)
                } else {
                    v
                }
            } else {
                Vec3::zeros()
            };
            *user = tool_contact(
                &self.contact,
                &mut self.contacts[j],
                &world.shape,
                &copy.state,
                &world.mass,
                p,
                v,
                self.radii[j],
            );
        }
        let i = self.idx(t);
        slot.touched = users[self.me].touching;
        // A re-simulation keeps what the first simulation of the tick showed.
        slot.felt = if self.slots[i].tick == t {
            self.slots[i].felt
        } else {
            slot.touched
        };
        self.slots[i] = slot;
        // Summed in site order, the same at every site: all users count as "own" here.
        integrate(world, copy, &users[..self.sites], self.sites, self.dt);
        self.now_tick = t + 1;
    }

    /// The own tool's position at tick `t` (the current tick: as just measured).
    fn own_at(&self, t: i64) -> Quantized {
        if t == self.now_tick {
            self.own
        } else {
            self.slots[self.idx(t)].inputs[self.me]
        }
    }

    /// Restores the copy to tick `from` and simulates again to where it was.
    fn rollback(&mut self, world: &World, copy: &mut ObjectCopy, from: i64) -> u64 {
        let to = self.now_tick;
        let oldest = self.oldest_kept();
        let from = from.max(oldest);
        if from >= to {
            return 0;
        }
        let s = self.slots[self.idx(from)];
        let own_now = self.own;
        *copy = s.copy;
        self.contacts = s.contacts;
        self.now_tick = from;
        while self.now_tick < to {
            // The own positions of past ticks are the ones used then.
            self.own = self.slots[self.idx(self.now_tick)].inputs[self.me];
            self.tick(world, copy);
        }
        self.own = own_now;
        let depth = (to - from) as u64;
        self.stats.rollbacks += 1;
        self.stats.resimulated_ticks += depth;
        self.stats.max_depth = self.stats.max_depth.max(depth);
        self.stats.depths.record(depth);
        depth
    }

    /// Compares, for every tick confirmed since the last call, the own contact of its confirmed
    /// simulation with that of its first ([`Stats::unfelt_contact_ticks`],
    /// [`Stats::phantom_contact_ticks`]). A confirmed tick is never simulated again. Called where
    /// the frontier moves, on receiving; not per tick.
    fn tally(&mut self) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let upto = self.confirmed_tick().min(self.now_tick);
        let oldest = self.oldest_kept();
        for t in self.tallied_until.max(oldest)..upto {
            let s = &self.slots[self.idx(t)];
            if s.tick == t {
                self.stats.unfelt_contact_ticks += u64::from(s.touched && !s.felt);
                self.stats.phantom_contact_ticks += u64::from(s.felt && !s.touched);
            }
        }
        self.tallied_until = self.tallied_until.max(upto);
    }

    /// Adopts the state `r` carries (its sender's at its confirmed frontier, which this site has
    /// confirmed too) at that tick and re-simulates to now; `None` if it carries none, or one
    /// that is not the state its hash names.
    fn resync(&mut self, world: &World, copy: &mut ObjectCopy, r: &ToolReport) -> Option<Adoption> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let snap = r
            .state
            .filter(|s| s.tick == r.confirmed_tick && hash_state(&s.state) == r.confirmed_hash)?;
        let i = self.idx(snap.tick);
        // A kept slot is a simulated tick (the current one is not kept yet: hash_at checked).
        if self.slots[i].tick != snap.tick
            || crate::tank::spring_energy(world, &snap.state) > self.max_spring_j
        {
            return None;
        }
        let before = *copy;
        let e = |s: &BodyState| s.mechanical_energy(&world.mass, world.gravity);
        let slot = &mut self.slots[i];
        // The jump is energy no force of the history accounts for.
        slot.copy.energy.adoption_j += e(&snap.state) - e(&slot.copy.state);
        slot.copy.state = snap.state;
        slot.copy.env = snap.env;
        slot.contacts = snap.contacts;
        self.rollback(world, copy, snap.tick);
        self.stats.adopted_states += 1;
        // Every force's work so far, as the re-simulated account has it (as in `receive`).
        let w = |c: &ObjectCopy| c.energy.own_j + c.energy.remote_j + c.energy.env_j;
        Some(Adoption {
            jump: before.state.pos - copy.state.pos,
            energy_j: e(&copy.state) - e(&before.state),
            work_j: w(copy) - w(&before),
            age_s: (self.now_tick - snap.tick) as f64 * self.dt,
            clipped_j: 0.0,
        })
    }

    /// After a rollback from `from`: when the re-simulated history has the own tool touching the
    /// object where the live simulation had not (a contact the user missed: the news of a remote
    /// push came after the object had reached the hand), no tool touches the object now, and the
    /// own tool is still where it was then, the user is shown that history from a little before the contact
    /// on, sped up ([`REPLAY_SPEED`]), until it catches up with the copy.
    fn replay_missed_contact(&mut self, from: i64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        // Only a free object's knock: in a grasp (another tool on the object) the history
        // replayed would be felt against hands that are all moving on.
        let touched_now = self.contacts[..self.sites].iter().any(|c| c.touching());
        if self.replay.is_some() || touched_now {
            return;
        }
        let start = from.max(self.replayed_until).max(self.oldest_kept());
        let mut first = None;
        let mut missed = 0;
        for t in start..self.now_tick {
            let s = &self.slots[self.idx(t)];
            if s.tick == t && s.touched && !s.felt {
                first = first.or(Some(t));
                missed += 1;
            }
        }
        let Some(first) = first.filter(|_| missed >= REPLAY_MIN_TICKS) else {
            return;
        };
        let then = self.slots[self.idx(first)].inputs[self.me];
        self.replayed_until = self.now_tick;
        if (position(self.own) - position(then)).norm() > REPLAY_REACH_M {
            return;
        }
        self.replay = Some(((first - REPLAY_LEAD_TICKS).max(start), then));
        self.stats.replays += 1;
    }

    /// One live tick on: a replay advances [`REPLAY_SPEED`] ticks, and ends once it reaches the
    /// copy, when the own tool touches the copy (the user feels what is now), or when the tool
    /// has moved away from where the replayed history had it.
    fn advance_replay(&mut self) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let Some((mut t, then)) = self.replay else {
            return;
        };
        // Fast up to the contact, at its own pace into and through it (the user feels the
        // contact as the history had it, not harder).
        t += self.replay_speed(t);
        let kept = self.slots[self.idx(t)].tick == t;
        let away = (position(self.own) - position(then)).norm() > REPLAY_REACH_M;
        self.replay = (t < self.now_tick && kept && !away && !self.contacts[self.me].touching())
            .then_some((t, then));
    }

    /// How many ticks of history a live tick replays from tick `t` on: one while the own tool
    /// touches the object in it or is about to ([`REPLAY_SLOW_TICKS`]), [`REPLAY_SPEED`]
    /// otherwise.
    fn replay_speed(&self, t: i64) -> i64 {
        let near = (t..=t + REPLAY_SLOW_TICKS).any(|u| {
            let s = &self.slots[self.idx(u)];
            s.tick == u && s.touched
        });
        if near {
            1
        } else {
            REPLAY_SPEED
        }
    }

    /// FNV-1a of the state at the start of tick `t`, if it is still kept.
    fn hash_at(&self, t: i64) -> Option<u64> {
        let s = &self.slots[self.idx(t)];
        (s.tick == t).then(|| hash_state(&s.copy.state))
    }
}

/// FNV-1a 64 of a state's bits.
pub fn hash_state(s: &BodyState) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let words = s
        .pos
        .iter()
        .chain(s.vel.iter())
        .chain(s.ang_mom.iter())
        .chain(s.rot.coords.iter());
    for w in words {
        for b in w.to_bits().to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

impl Consistency for TimeWarp {
    fn name(&self) -> &'static str {
        "timewarp"
    }
    fn own_tool(&mut self, tool_pos: Vec3) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let n = self.measured_count;
        self.measured[n as usize % MEASURED_RING] = quantize(tool_pos);
        self.measured_count = n + 1;
        // The lag in half ticks if the play head moves on at the measured pace, and the step of
        // the play head towards the one wanted.
        let (now, want) = (2 * n, 2 * self.lag_target);
        let lag = (now - self.play_head - 2).max(0);
        let above = if want == 0 {
            0
        } else {
            LAG_SLACK_ABOVE_HALF_TICKS
        };
        let step = if lag < want - LAG_SLACK_BELOW_HALF_TICKS {
            LAG_GROW_HALF_TICKS
        } else if lag > want + above && !self.contacts[self.me].touching() {
            LAG_SHRINK_HALF_TICKS
        } else {
            2
        };
        self.play_head = (self.play_head + step).min(now);
        let at = |k: i64| self.measured[k as usize % MEASURED_RING];
        let k = self.play_head / 2;
        self.own = if self.play_head % 2 == 0 {
            at(k)
        } else {
            // Half-way between two measured positions (k + 1 <= n: the head is below `now`).
            let (a, b) = (at(k), at(k + 1));
            std::array::from_fn(|i| ((i64::from(a[i]) + i64::from(b[i])) / 2) as i32)
        };
        // How late the input is: whole ticks, a half rounded up.
        let lag = ((now - self.play_head + 1) / 2).unsigned_abs();
        self.stats.local_lag_ticks = lag;
        self.stats.max_local_lag_ticks = self.stats.max_local_lag_ticks.max(lag);
        self.stats.lagged_ticks += u64::from(lag > 0);
    }
    fn physics_step(
        &mut self,
        world: &World,
        copy: &mut ObjectCopy,
        _own: &ContactForce,
        _dt: f64,
    ) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        self.tick(world, copy);
        self.advance_replay();
        self.want_lag(world, copy);
    }
    fn report(&self, _copy: &ObjectCopy, _own: &ContactForce, _now_s: f64) -> Report {
        let end = self.now_tick; // ticks up to end - 1 are simulated, with the own positions
                                 // (Nothing before the tick this site's history starts at: it was not here.)
        let window = (end - WINDOW_TICKS as i64).max(self.origin_tick);
        // A peer that lost more than a window of reports asked for the first tick it lacks: every
        // other report sends the window from there instead (while it is still kept), so the
        // newest positions keep flowing and the peer's frontier can pass the gap.
        let oldest = self.oldest_kept();
        let repair = (0..self.sites)
            .filter(|&j| j != self.me)
            .map(|j| self.asked[j])
            .filter(|&t| t >= oldest && t < window)
            .min()
            .filter(|_| !self.repaired_last.get());
        self.repaired_last.set(repair.is_some());
        let first = repair.unwrap_or(window);
        let count = (end - first).min(WINDOW_TICKS as i64);
        let mut r = ToolReport {
            first_tick: first,
            count: count as usize,
            positions: [[0; 3]; WINDOW_TICKS],
            // A repair's window ends before the frontier: the frontier (and its hash and state)
            // is given at the window's end, a tick the sender has confirmed too, so that no
            // report names a frontier past the last position it carries (the wire's rule,
            // `coop_rt::msg::ToolTrack::report`: a station refused every repair before).
            // (Nor past the last tick simulated: a site whose grid runs behind the others' knows
            // their positions beyond its own tick, and its frontier is then a state it has not
            // stepped to yet, with no hash to send: it sent none, and was never compared.)
            confirmed_tick: self
                .confirmed_tick()
                .min(first + count)
                .min(self.now_tick - 1),
            confirmed_hash: 0,
            need: [-1; MAX_SITES],
            need_state: 0,
            started_tick: self.started_tick,
            state: None,
        };
        for (j, &want) in self.want_state.iter().enumerate() {
            r.need_state |= u8::from(want) << j;
        }
        if self.state_asked.iter().any(|&a| a) {
            let t = r.confirmed_tick;
            let s = &self.slots[self.idx(t)];
            r.state = (s.tick == t).then_some(Snapshot {
                tick: t,
                state: s.copy.state,
                env: s.copy.env,
                contacts: s.contacts,
            });
        }
        for j in (0..self.sites).filter(|&j| j != self.me) {
            if self.newest[j] > self.known_until[j] {
                r.need[j] = self.known_until[j] + 1;
            }
        }
        for (k, t) in (first..first + r.count as i64).enumerate() {
            r.positions[k] = self.slots[self.idx(t)].inputs[self.me];
        }
        r.confirmed_hash = self.hash_at(r.confirmed_tick).unwrap_or(0);
        Report::Tools(r)
    }
    fn receive(
        &mut self,
        world: &World,
        copy: &mut ObjectCopy,
        from: usize,
        msg: &Report,
        _now_s: f64,
    ) -> Option<Adoption> {
        let Report::Tools(r) = msg else {
            return None;
        };
        if from >= self.sites || from == self.me {
            return None;
        }
        self.asked[from] = r.need[self.me];
        self.state_asked[from] = r.need_state & (1 << self.me) != 0;
        let oldest = self.oldest_kept();
        for (k, &q) in r.positions[..r.count.min(WINDOW_TICKS)].iter().enumerate() {
            let t = r.first_tick + k as i64;
            if t <= self.known_until[from] {
                continue;
            }
            if t < oldest {
                self.stats.fallbacks += 1;
                self.dirty_from = Some(self.dirty_from.map_or(oldest, |d| d.min(oldest)));
                continue;
            }
            let i = self.idx(t);
            self.received[i][from] = Some((t, q));
            // Simulated with another (predicted) position: from there on it is re-simulated.
            let s = &self.slots[i];
            if t < self.now_tick && s.tick == t && s.inputs[from] != q {
                self.dirty_from = Some(self.dirty_from.map_or(t, |d| d.min(t)));
            }
        }
        if r.count > 0 {
            let end = r.first_tick + r.count as i64 - 1;
            // How late the newest position arrived (a repair of older ones says nothing of it).
            // (Ahead of this site's tick, by the two grids' offset, it says nothing either.)
            let late = self.now_tick - end;
            if end > self.newest[from] && late >= 0 {
                let late = late as f64;
                let d = &mut self.delay_ticks[from];
                *d = if *d == 0.0 {
                    late
                } else {
                    *d + (late - *d) * DELAY_FILTER_SHARE
                };
            }
            self.newest[from] = self.newest[from].max(end);
        }
        // Every position up to the frontier is known: a gap holds it back (the sender is asked
        // for it), and one that left the history can never be filled: given up, counted once
        // (while the rest of it leaves the history, report by report, it is the same gap).
        // A gap is given up where the sender can no longer fill it either: before its history,
        // which ends later than this site's when its grid runs ahead (stations started apart).
        // (Given up only at this site's horizon, a gap the sender had already dropped followed
        // that horizon forever: the frontier stayed a history behind, and no hash was compared.)
        let senders_oldest = oldest.max(self.newest[from] - self.len() + 2);
        let mut k = self.known_until[from];
        if k + 1 < senders_oldest && self.newest[from] >= senders_oldest {
            self.stats.fallbacks += u64::from(!self.given_up[from]);
            self.given_up[from] = true;
            k = senders_oldest - 1;
        }
        let pinned = k;
        while k < self.newest[from] && self.received_at(from, k + 1).is_some() {
            k += 1;
        }
        self.given_up[from] &= k == pinned;
        self.known_until[from] = k;
        // Ticks not all known (a gap's, and past the newest) are predicted again: one simulated
        // with another prediction is re-simulated too, so the copy is always what the inputs known now give
        // (and a re-simulation arrives at the same bits).
        for t in (self.known_until[from] + 1).max(oldest)..self.now_tick {
            let s = &self.slots[self.idx(t)];
            if s.tick == t && s.inputs[from] != self.input(from, t).0 {
                self.dirty_from = Some(self.dirty_from.map_or(t, |d| d.min(t)));
                break;
            }
        }
        let mut adoption = None;
        if let Some(from_tick) = self.dirty_from.take() {
            let before = *copy;
            if self.rollback(world, copy, from_tick) > 0 {
                self.replay_missed_contact(from_tick);
                let e = |s: &BodyState| s.mechanical_energy(&world.mass, world.gravity);
                // Every force's work so far, as the copy's account has it (restored with the
                // snapshot and re-accumulated by the re-simulation).
                let w = |c: &ObjectCopy| c.energy.own_j + c.energy.remote_j + c.energy.env_j;
                adoption = Some(Adoption {
                    jump: before.state.pos - copy.state.pos,
                    energy_j: e(&copy.state) - e(&before.state),
                    work_j: w(copy) - w(&before),
                    age_s: (self.now_tick - from_tick) as f64 * self.dt,
                    clipped_j: 0.0,
                });
            }
        }
        // Confirmed state compared where both know it.
        if r.confirmed_hash != 0 && r.confirmed_tick <= self.confirmed_tick() {
            if let Some(h) = self.hash_at(r.confirmed_tick) {
                self.stats.hash_checks += 1;
                let differs = h != r.confirmed_hash;
                self.stats.hash_mismatches += u64::from(differs);
                // Asked for while it differs from a site before this one (and no longer when the
                // order changes: a restart moves a site back).
                let earlier = (r.started_tick, from) < (self.started_tick, self.me);
                self.want_state[from] = earlier && differs;
                if earlier && differs {
                    if let Some(a) = self.resync(world, copy, r) {
                        adoption = Some(adoption.map_or(a, |b| Adoption {
                            jump: a.jump + b.jump,
                            energy_j: a.energy_j + b.energy_j,
                            work_j: a.work_j + b.work_j,
                            age_s: a.age_s.max(b.age_s),
                            clipped_j: 0.0,
                        }));
                        self.want_state[from] = false;
                    }
                }
            }
        }
        self.tally();
        adoption
    }
    fn peer_lost(&mut self, from: usize, _now_s: f64) {
        // A silent site neither asks for our state nor sends its own: ask again once it is back.
        if let (Some(asked), Some(want)) = (
            self.state_asked.get_mut(from),
            self.want_state.get_mut(from),
        ) {
            *asked = false;
            *want = false;
        }
        // Nor is its delay known any more: no lag for it until it reports again.
        if let Some(d) = self.delay_ticks.get_mut(from) {
            *d = 0.0;
        }
    }
    fn timewarp_stats(&self) -> Option<Stats> {
        Some(self.stats)
    }
    /// The copy's state, or during a replay of a missed contact the history's at the replayed
    /// tick, its velocities at the replay's speed (so the display sees the motion it shows).
    fn shown(&self, copy: &ObjectCopy) -> BodyState {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        match self.replay {
            Some((t, _)) if self.slots[self.idx(t)].tick == t => {
                let mut s = self.slots[self.idx(t)].copy.state;
                let k = self.replay_speed(t) as f64;
                s.vel *= k;
                s.ang_mom *= k;
                s
            }
            _ => copy.state,
        }
    }
    fn start_at_tick(&mut self, tick: i64) {
        let tick = tick.max(0);
        // It was not there from the start: it yields (see the module docs).
        self.started_tick = tick.unsigned_abs();
        self.now_tick = tick;
        self.origin_tick = tick;
        // No position before the history's start is needed (none is simulated here): the
        // others' are taken from `tick` on, and those before it are neither gaps nor fallbacks.
        for j in (0..self.sites).filter(|&j| j != self.me) {
            self.known_until[j] = tick - 1;
            self.newest[j] = tick - 1;
        }
    }
}

impl TimeWarp {
    /// Lags the own tool by `share` (0 to 1; 0: never) of a near partner's delay, at most
    /// `max_ticks` (up to [`MAX_LOCAL_LAG_TICKS`]); [`LOCAL_LAG_SHARE`] and
    /// [`LOCAL_LAG_MAX_TICKS`] unless set.
    pub fn set_local_lag(&mut self, share: f64, max_ticks: i64) {
        self.lag_share = if share.is_finite() {
            share.clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.lag_max = max_ticks.clamp(0, MAX_LOCAL_LAG_TICKS);
    }

    /// The local lag wanted from the next tick on: the configured share of the largest measured
    /// delay of the sites whose tools (as last simulated) are within [`LOCAL_LAG_NEAR_M`] of the
    /// object while the own tool (as measured) is too; none otherwise.
    fn want_lag(&mut self, world: &World, copy: &ObjectCopy) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let body = &copy.state;
        let inv = body.rot.inverse();
        let near = |q: Quantized, radius: f64| {
            q != UNKNOWN
                && world
                    .shape
                    .signed_distance(inv * (position(q) - body.pos))
                    .0
                    - radius
                    <= LOCAL_LAG_NEAR_M
        };
        let measured = self.measured[(self.measured_count - 1).max(0) as usize % MEASURED_RING];
        let last = &self.slots[self.idx(self.now_tick - 1)];
        let mut delay: f64 = 0.0;
        if self.measured_count > 0
            && last.tick == self.now_tick - 1
            && near(measured, self.radii[self.me])
        {
            for j in (0..self.sites).filter(|&j| j != self.me) {
                if near(last.inputs[j], self.radii[j]) {
                    delay = delay.max(self.delay_ticks[j]);
                }
            }
        }
        self.lag_target = ((delay * self.lag_share) as i64).clamp(0, self.lag_max);
    }

    /// GGPO's synctest: rolls the copy back `depth` ticks and re-simulates them with the same
    /// inputs; whether it arrived at the same bits (state, friction memory) it had. Determinism is
    /// what makes every site's confirmed state the same: this checks it on every tick it is run.
    pub fn synctest(&mut self, world: &World, copy: &mut ObjectCopy, depth: i64) -> bool {
        let (before, contacts) = (*copy, self.contacts);
        let stats = self.stats;
        self.rollback(world, copy, self.now_tick - depth);
        self.stats = stats; // a test's rollbacks are not the method's
        copy.state == before.state && copy.env == before.env && self.contacts == contacts
    }
}

/// A report of a tool at `at(t)` for ticks `first..=last` (the methods' tests).
#[cfg(test)]
pub(crate) fn track(first: i64, last: i64, at: impl Fn(i64) -> Quantized) -> Report {
    let mut r = ToolReport {
        first_tick: first,
        ..ToolReport::NONE
    };
    for t in first..=last {
        r.positions[r.count] = at(t);
        r.count += 1;
    }
    Report::Tools(r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyState;
    use crate::scenario::Scenario;

    fn paper_world() -> (Scenario, World) {
        let mut sc = Scenario::default();
        sc.object.start_m = [0.0, 0.0, 0.01];
        sc.world.planes[0].normal = [0.0, 0.0, 1.0];
        sc.world.planes[0].offset_m = 0.0;
        sc.world.gravity_m_per_s2 = [0.0, 0.0, -3.27];
        let w = sc.world();
        (sc, w)
    }

    /// Site 0 of two 5 mm tools, 1 kHz, 600 ticks of history, the disk at rest at the origin on
    /// the table: the method, its copy and the world.
    fn two_tools_on_a_disk() -> (TimeWarp, ObjectCopy, World) {
        let (sc, w) = paper_world();
        let copy = ObjectCopy::new(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
        let mut radii = [0.0; MAX_SITES];
        radii[..2].fill(0.005);
        (
            TimeWarp::new(0, 2, 1e-3, sc.contact, radii, 600, &copy),
            copy,
            w,
        )
    }

    /// [`paper_world`]'s scenario with two users resting 0.2 m either side of the disk.
    fn two_users() -> Scenario {
        let (mut sc, _) = paper_world();
        for (name, x, base) in [("user1", -0.2, -0.3), ("user2", 0.2, 0.3)] {
            sc.site.push(crate::scenario::SiteSpec {
                name: name.into(),
                device_base_m: [base, -0.2, 0.0],
                script: vec![crate::scenario::KeyframeSpec {
                    t_s: 0.0,
                    target_m: [x, 0.0, 0.01],
                }],
                ..Default::default()
            });
        }
        sc
    }

    /// The history kept is `[timewarp] horizon_ms`, or by default what the network can delay a
    /// position by plus 100 ms; a horizon that does not cover that is refused.
    #[test]
    fn the_horizon_is_configured_or_covers_the_latest_arrival() {
        let mut sc = two_users();
        sc.network.delay_min_ms = 20.0;
        sc.network.delay_max_ms = 200.0;
        sc.network.jitter_ms = 10.0;
        sc.site[0].report_rate_hz = 50.0; // 20 ms: 230 ms in all, + 100 ms
        sc.validate().expect("default horizon");
        let copy = ObjectCopy::new(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
        assert_eq!(sc.timewarp(0, &copy).history_ticks(), 331);
        // With loss, 11 reports lost in a row (0.3¹² < 10⁻⁶) and a round trip more: + 450 ms.
        sc.network.loss = 0.3;
        assert_eq!(sc.losses_in_a_row(), 11);
        assert_eq!(sc.timewarp(0, &copy).history_ticks(), 781);
        sc.network.loss = 0.0;
        sc.timewarp.horizon_ms = 2000.0;
        sc.validate().expect("a longer horizon");
        assert_eq!(sc.timewarp(0, &copy).history_ticks(), 2001);
        for bad in [229.0, -1.0, f64::NAN, 10_001.0] {
            sc.timewarp.horizon_ms = bad;
            let e = sc.validate().expect_err("refused");
            assert_eq!(e.field, "timewarp.horizon_ms", "{e}");
            assert!(e.rule.contains("230.0 ms"), "{e}");
        }
    }

    /// `[timewarp] local_lag_share` and `local_lag_max_ms` default to the method's constants, set
    /// the site's lag, and out of range are refused with the field and the rule.
    #[test]
    fn the_local_lag_is_configured_and_checked() {
        let mut sc = two_users();
        sc.validate().expect("defaults");
        assert_eq!(sc.timewarp.local_lag_share, LOCAL_LAG_SHARE);
        let copy = ObjectCopy::new(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
        let tw = sc.timewarp(0, &copy);
        assert_eq!(
            (tw.lag_share, tw.lag_max),
            (LOCAL_LAG_SHARE, LOCAL_LAG_MAX_TICKS)
        );
        sc.timewarp.local_lag_share = 0.0;
        sc.timewarp.local_lag_max_ms = 150.0;
        sc.validate().expect("no lag, a larger cap");
        let tw = sc.timewarp(0, &copy);
        assert_eq!((tw.lag_share, tw.lag_max), (0.0, 150));
        for bad in [-0.1, 1.5, f64::NAN] {
            sc.timewarp.local_lag_share = bad;
            let e = sc.validate().expect_err("refused");
            assert_eq!(e.field, "timewarp.local_lag_share", "{e}");
        }
        sc.timewarp.local_lag_share = 0.5;
        for bad in [-1.0, 201.0, f64::INFINITY] {
            sc.timewarp.local_lag_max_ms = bad;
            let e = sc.validate().expect_err("refused");
            assert_eq!(e.field, "timewarp.local_lag_max_ms", "{e}");
            assert!(e.rule.contains("200"), "{e}");
        }
    }

    /// Two tools squeeze the disk from both sides and carry it: the synctest (a rollback of every
    /// depth up to 50 ticks, on every tick) always arrives at the same bits.
    #[test]
    fn a_forced_rollback_on_every_tick_gives_the_same_bits() {
        let (mut tw, mut copy, w) = two_tools_on_a_disk();
        let mut other = [0i32; 3];
        for k in 0..1500i64 {
            let s = k as f64 * 1e-3;
            let squeeze = (s * 0.02).min(0.008);
            let carry = (s - 0.8).max(0.0) * 0.05;
            tw.own_tool(Vec3::new(-0.045 + squeeze, carry, 0.01));
            // The other site's tool, received with a 30-tick delay in 10-tick batches.
            if k % 10 == 0 && k >= 30 {
                let mut r = ToolReport {
                    first_tick: k - 40,
                    count: 10,
                    positions: [[0; 3]; WINDOW_TICKS],
                    confirmed_tick: 0,
                    confirmed_hash: 0,
                    need: [-1; MAX_SITES],
                    ..ToolReport::NONE
                };
                for j in 0..10 {
                    let t = (k - 40 + j) as f64 * 1e-3;
                    other = quantize(Vec3::new(
                        0.045 - (t * 0.02).min(0.008),
                        (t - 0.8).max(0.0) * 0.05,
                        0.01,
                    ));
                    r.positions[j as usize] = other;
                }
                if r.first_tick >= 0 {
                    tw.receive(&w, &mut copy, 1, &Report::Tools(r), s);
                }
            }
            tw.physics_step(&w, &mut copy, &ContactForce::default(), 1e-3);
            let depth = 1 + k % 50;
            assert!(tw.synctest(&w, &mut copy, depth), "tick {k}, depth {depth}");
        }
        assert!(
            tw.stats().rollbacks > 10,
            "the received tool caused rollbacks: {:?}",
            tw.stats()
        );
        assert!(
            copy.state.pos.y > 0.01,
            "the squeezed disk was carried: {:?}",
            copy.state.pos
        );
        let _ = other;
    }

    /// A remote tool knocks the disk into the own, resting tool. Learned a delay late, that
    /// contact is over before the copy can show it: its confirmed ticks count as unfelt. Learned
    /// before each tick is simulated, everything shown live is what was confirmed.
    #[test]
    fn a_contact_learned_too_late_to_show_counts_as_unfelt() {
        let rest = |_| Vec3::new(0.06, 0.0, 0.01);
        let prompt = knock(0, rest);
        assert!(prompt.touched, "the knocked disk reached the own tool");
        assert_eq!(
            (
                prompt.stats.unfelt_contact_ticks,
                prompt.stats.phantom_contact_ticks
            ),
            (0, 0),
            "{:?}",
            prompt.stats
        );
        let late = knock(300, rest);
        assert!(
            late.stats.unfelt_contact_ticks > 0,
            "the contact the copy learned of 0.3 s late: {:?}",
            late.stats
        );
    }

    /// A contact the own user missed is shown late, replayed from the confirmed history, while
    /// the hand is still where the contact had it; not once it has moved on.
    #[test]
    fn a_missed_contact_is_replayed_to_a_hand_still_there() {
        let rest = |_| Vec3::new(0.06, 0.0, 0.01);
        let prompt = knock(0, rest);
        assert_eq!(
            prompt.stats.replays, 0,
            "nothing missed: {:?}",
            prompt.stats
        );
        assert!(prompt.shown_touching_ticks > 0 && prompt.shown_was_copy);
        let late = knock(300, rest);
        assert_eq!(late.stats.replays, 1, "{:?}", late.stats);
        assert!(
            !late.shown_was_copy,
            "the replay showed the history, not the copy"
        );
        assert!(
            late.shown_touching_ticks > 0,
            "the replayed disk met the hand: {:?}",
            late.stats
        );
        assert!(late.ends_on_copy, "the replay caught up with the copy");
        // The hand moved 5 mm away between the contact and its news: nothing is replayed.
        let moved = knock(300, |k| {
            Vec3::new(if k < 250 { 0.06 } else { 0.065 }, 0.0, 0.01)
        });
        assert!(moved.stats.unfelt_contact_ticks > 0, "{:?}", moved.stats);
        assert_eq!(moved.stats.replays, 0, "{:?}", moved.stats);
        assert!(moved.shown_was_copy && moved.ends_on_copy);
    }

    /// What [`knock`] saw.
    struct Knock {
        stats: Stats,
        /// The copy touched the own tool at some tick.
        touched: bool,
        /// Ticks at which the shown object touched the own tool.
        shown_touching_ticks: u64,
        /// The shown object was always the copy.
        shown_was_copy: bool,
        /// ... and was at the end.
        ends_on_copy: bool,
    }

    /// Site 0 of [`two_tools_on_a_disk`], its tool at `own(k)`; site 1's tool knocks the disk
    /// towards it (from x = -0.1 into the disk's rim at -0.04 in 0.1 s, then back), its
    /// positions arriving `delay` ticks late, 10 to a report (each one at once at 0).
    fn knock(delay: i64, own: impl Fn(i64) -> Vec3) -> Knock {
        let (mut tw, mut copy, w) = two_tools_on_a_disk();
        let remote = |k: i64| {
            let s = k as f64 * 1e-3;
            let x = if s < 0.1 {
                -0.1 + 0.7 * s
            } else {
                (-0.03 - 0.7 * (s - 0.1)).max(-0.1)
            };
            quantize(Vec3::new(x, 0.0, 0.01))
        };
        let mut out = Knock {
            stats: Stats::default(),
            touched: false,
            shown_touching_ticks: 0,
            shown_was_copy: true,
            ends_on_copy: false,
        };
        for k in 0..1000i64 {
            tw.own_tool(own(k));
            let first = k - delay;
            if first >= 0 && (delay == 0 || k % 10 == 0) {
                let count = if delay == 0 { 1 } else { 10 };
                let r = track((first - count + 1).max(0), first, remote);
                tw.receive(&w, &mut copy, 1, &r, k as f64 * 1e-3);
            }
            tw.physics_step(&w, &mut copy, &ContactForce::default(), 1e-3);
            out.touched |= tw.contacts[0].touching();
            let shown = tw.shown(&copy);
            out.shown_was_copy &= shown == copy.state;
            // The rim (0.04 m) meets the tool (0.005 m) in the plane.
            let gap = (own(k) - shown.pos).xy().norm() - 0.045;
            out.shown_touching_ticks += u64::from(gap < 0.0);
            out.ends_on_copy = shown == copy.state;
        }
        out.stats = tw.stats();
        out
    }

    /// Site 0 of [`two_tools_on_a_disk`] for `ticks` ticks, its tool measured at `own(k)`; site
    /// 1's tool at `remote(k)`, its positions arriving `delay` ticks late, 10 to a report. What
    /// the own tool's input was at each tick (from the reports), and the lag after each tick.
    fn lagged(
        ticks: i64,
        delay: i64,
        own: impl Fn(i64) -> Vec3,
        remote: impl Fn(i64) -> Vec3,
    ) -> (Vec<Quantized>, Vec<u64>, TimeWarp) {
        let (mut tw, mut copy, w) = two_tools_on_a_disk();
        let (mut inputs, mut lags) = (Vec::new(), Vec::new());
        for k in 0..ticks {
            tw.own_tool(own(k));
            let first = k - delay;
            if first >= 9 && k % 10 == 0 {
                let r = track(first - 9, first, |t| quantize(remote(t)));
                tw.receive(&w, &mut copy, 1, &r, k as f64 * 1e-3);
            }
            tw.physics_step(&w, &mut copy, &ContactForce::default(), 1e-3);
            inputs.push(tw.own_at(k));
            lags.push(tw.stats().local_lag_ticks);
        }
        (inputs, lags, tw)
    }

    /// Local lag: while the own tool and a partner's are within a centimetre of the object, the
    /// own tool's positions enter the physics half the partner's measured delay late (grown
    /// into at half speed), and exactly as measured again once either is away (caught up at
    /// twice the speed); never before the partner's delay is known.
    #[test]
    fn a_tool_near_the_object_with_a_partner_is_lagged_by_half_its_delay() {
        // The rim is 40 mm from the disk's centre; 5 mm tools 50 mm from it are 5 mm off it.
        // The own tool slides along the rim a quantum a tick (every tick's position differs),
        // and leaves at tick 700.
        let own = |k: i64| {
            let x = if k < 700 { -0.05 } else { -0.1 };
            Vec3::new(x, k as f64 * QUANTUM_M, 0.01)
        };
        let (inputs, lags, tw) = lagged(1000, 120, own, |_| Vec3::new(0.05, 0.0, 0.01));
        // Before the first report (tick 129) no delay is known: no lag.
        assert!(lags[..129].iter().all(|&l| l == 0), "{lags:?}");
        assert!(inputs[..129]
            .iter()
            .enumerate()
            .all(|(k, &q)| q == quantize(own(k as i64))));
        // Half of 120 ticks, within the slack, reached at half speed (60 ticks in 120).
        let lag = lags[600];
        assert!((59..=60).contains(&lag), "lag {lag}");
        assert!(lags[129..260].windows(2).all(|w| w[1] <= w[0] + 1));
        for k in 400..700 {
            assert_eq!(lags[k], lag);
            assert_eq!(inputs[k], quantize(own(k as i64 - lag as i64)), "tick {k}");
        }
        // Away from the object: caught up, a tick a tick, and exactly as measured again.
        assert!(lags[700 + lag as usize + 5..].iter().all(|&l| l == 0));
        assert_eq!(inputs[999], quantize(own(999)));
        let st = tw.stats();
        assert_eq!(st.max_local_lag_ticks, lag);
        assert!(st.lagged_ticks > 500, "{st:?}");
    }

    /// A partner reported lost (its link down) has no known delay: the own tool's lag for it ends.
    #[test]
    fn a_lost_partner_ends_the_lag() {
        let (mut tw, mut copy, w) = two_tools_on_a_disk();
        for k in 0..700i64 {
            tw.own_tool(Vec3::new(-0.05, 0.0, 0.01));
            let first = k - 120;
            if (9..400).contains(&first) && k % 10 == 0 {
                let r = track(first - 9, first, |_| quantize(Vec3::new(0.05, 0.0, 0.01)));
                tw.receive(&w, &mut copy, 1, &r, k as f64 * 1e-3);
            }
            if k == 550 {
                assert!(tw.stats().local_lag_ticks >= 59, "{:?}", tw.stats());
                tw.peer_lost(1, k as f64 * 1e-3);
            }
            tw.physics_step(&w, &mut copy, &ContactForce::default(), 1e-3);
        }
        assert_eq!(tw.stats().local_lag_ticks, 0, "{:?}", tw.stats());
    }

    /// A lag is never caught up while the own tool touches the object: its positions would be
    /// played into the object at twice the speed the hand moved.
    #[test]
    fn a_touching_tool_keeps_its_lag_until_it_lets_go() {
        // Pressing on the disk's top (at 20 mm; 1 mm deep: the table holds the disk) until tick
        // 700, then away; the partner leaves at tick 400 (its leaving arrives at 520).
        let own = |k: i64| {
            let x = if k < 700 { 0.0 } else { -0.1 };
            Vec3::new(x, 0.0, 0.024)
        };
        let remote = |k: i64| Vec3::new(if k < 400 { 0.05 } else { 0.2 }, 0.0, 0.01);
        let (_, lags, _) = lagged(1000, 120, own, remote);
        let lag = lags[519];
        assert!(lag >= 59, "lag {lag}");
        // Wanted no more from tick 520, held while touching: until the tool lets go in the
        // physics (its lagged positions), `lag` ticks after it did; then caught up as fast.
        let lets_go = 700 + lag as usize;
        assert!(lags[520..lets_go].iter().all(|&l| l == lag), "{lags:?}");
        assert!(lags[lets_go + lag as usize + 5..].iter().all(|&l| l == 0));
    }

    /// A physics process that joins the grid late (a restart, a late station) starts where the
    /// session is, not at tick 0, from a copy that is not the session's: it never simulates a
    /// tick before the one it joined at, sends no positions from before it, adopts the earlier
    /// site's confirmed state, and the two agree from then on.
    #[test]
    fn a_site_joining_the_grid_late_starts_there_and_adopts() {
        let (sc, w) = paper_world();
        let start = ObjectCopy::new(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
        let mut radii = [0.0; MAX_SITES];
        radii[..2].fill(0.005);
        let new = |i| TimeWarp::new(i, 2, 1e-3, sc.contact, radii, 600, &start);
        // Site 1 pushes the disk (ticks 900-1300), its physics dies at 1500 and a new one joins
        // the grid at 2000 from the scenario's start.
        let (crash, join) = (1500, 2000);
        let mut sites = [(new(0), start), (new(1), start)];
        let mut in_flight: Vec<(i64, usize, Report)> = Vec::new();
        let down = |i: usize, k: i64| i == 1 && (crash..join).contains(&k);
        for k in 0..4000 {
            if k == join {
                let mut b = new(1);
                b.set_started_tick(join as u64);
                b.start_at_tick(join);
                sites[1] = (b, start);
            }
            for (i, (tw, copy)) in sites.iter_mut().enumerate() {
                if down(i, k) {
                    continue;
                }
                for (_, from, r) in in_flight.iter().filter(|m| m.0 == k && m.1 != i) {
                    tw.receive(&w, copy, *from, r, k as f64 * 1e-3);
                }
                tw.own_tool(sweep_into_the_disk(i, k));
                tw.physics_step(&w, copy, &ContactForce::default(), 1e-3);
            }
            in_flight.retain(|m| m.0 > k);
            if k % 20 == 0 {
                for (i, (tw, copy)) in sites.iter().enumerate() {
                    if down(i, k) {
                        continue;
                    }
                    let r = tw.report(copy, &ContactForce::default(), k as f64 * 1e-3);
                    if let Report::Tools(t) = &r {
                        assert!(
                            i == 0 || k < crash || t.first_tick >= join,
                            "{}",
                            t.first_tick
                        );
                    }
                    in_flight.push((k + 30, i, r));
                }
            }
        }
        let [(a, ca), (b, _)] = &sites;
        assert!(ca.state.pos.x < -0.002, "site 1 pushed the disk");
        assert!(
            b.slots.iter().all(|s| s.tick == i64::MIN || s.tick >= join),
            "nothing simulated before the join"
        );
        let st = b.stats();
        assert!(st.hash_mismatches > 0 && st.adopted_states >= 1, "{st:?}");
        // Positions from before it joined are not counted as ones it could not undo.
        assert_eq!(st.fallbacks, 0, "{st:?}");
        let t = a.confirmed_tick().min(b.confirmed_tick()) - 1;
        assert!(t > 3500, "both confirmed to near the end: {t}");
        assert_eq!(
            a.hash_at(t),
            b.hash_at(t),
            "the same confirmed state at {t}"
        );
        assert_eq!(a.stats().adopted_states, 0, "{:?}", a.stats());
    }

    /// Stations started apart: site 1's grid runs `skew` ticks ahead of site 0's (it started
    /// first), and they hear each other only from wall tick `connect`. Reports go every 11 and 50
    /// ticks (the paper's 90 and 20 Hz) and arrive a tick later. Both compare their confirmed
    /// states, many times, and agree. Before, with 209 ticks of skew and a late connection, neither
    /// compared once: site 0 gave up the start-up gap only at its own horizon, which site 1's
    /// history had already left, so its frontier trailed a history behind for the whole session;
    /// and without a late connection the site ahead compared once or not at all, the frontier
    /// of the site behind being a tick it had not stepped to (no hash sent).
    #[test]
    fn stations_started_apart_compare_their_confirmed_states() {
        let (sc, w) = paper_world();
        for (skew, connect) in [(50_i64, 0_i64), (209, 1000), (-209, 1000), (400, 1500)] {
            let start = ObjectCopy::new(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
            let mut radii = [0.0; MAX_SITES];
            radii[..2].fill(0.005);
            let mut sites = [0, 1].map(|i| {
                (
                    TimeWarp::new(i, 2, 1e-3, sc.contact, radii, 660, &start),
                    start,
                )
            });
            let (begin, every) = ([skew.max(0), (-skew).max(0)], [11_i64, 50]);
            let mut in_flight: Vec<(i64, usize, Report)> = Vec::new();
            for k in 0..6000 {
                for i in (0..2).filter(|&i| k >= begin[i]) {
                    let (tw, copy) = &mut sites[i];
                    for (_, from, r) in in_flight.iter().filter(|m| m.0 == k && m.1 != i) {
                        tw.receive(&w, copy, *from, r, 0.0);
                    }
                    tw.own_tool(Vec3::new(if i == 0 { -0.2 } else { 0.2 }, 0.0, 0.01));
                    tw.physics_step(&w, copy, &ContactForce::default(), 1e-3);
                    if (k - begin[i]) % every[i] == 0 && k >= connect {
                        let r = tw.report(copy, &ContactForce::default(), 0.0);
                        in_flight.push((k + 1, i, r));
                    }
                }
                in_flight.retain(|m| m.0 > k);
            }
            for (i, (tw, _)) in sites.iter().enumerate() {
                let st = tw.stats();
                // A report of the other site's every 50 (or 11) ticks, from the connection on.
                assert!(
                    st.hash_checks > 60,
                    "skew {skew}, connected at {connect}: site {i} compared: {st:?}"
                );
                assert_eq!(st.hash_mismatches, 0, "skew {skew}: site {i}: {st:?}");
            }
        }
    }

    /// Two sites of the disk at rest, 1 kHz, `history` ticks kept, site i's physics started at
    /// tick `started_tick[i]`, for `ticks` ticks: site i's tool at `tool(i, k)`, a report every 20
    /// ticks arriving `delay` ticks later unless `lost(from, k)`; `seen(i, report, k)` sees every
    /// report sent.
    #[allow(clippy::too_many_arguments)]
    fn two_sites(
        history: usize,
        started_tick: [u64; 2],
        ticks: i64,
        tool: impl Fn(usize, i64) -> Vec3,
        delay: i64,
        lost: impl Fn(usize, i64) -> bool,
        mut seen: impl FnMut(usize, &ToolReport, i64, &[(TimeWarp, ObjectCopy); 2]),
    ) -> [(TimeWarp, ObjectCopy); 2] {
        let (sc, w) = paper_world();
        let start = ObjectCopy::new(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
        let mut radii = [0.0; MAX_SITES];
        radii[..2].fill(0.005);
        let mut sites = [0, 1].map(|i| {
            let mut tw = TimeWarp::new(i, 2, 1e-3, sc.contact, radii, history, &start);
            tw.set_started_tick(started_tick[i]);
            (tw, start)
        });
        let mut in_flight: Vec<(i64, usize, Report)> = Vec::new();
        for k in 0..ticks {
            for (i, (tw, copy)) in sites.iter_mut().enumerate() {
                for (_, from, r) in in_flight.iter().filter(|m| m.0 == k && m.1 != i) {
                    tw.receive(&w, copy, *from, r, k as f64 * 1e-3);
                }
                tw.own_tool(tool(i, k));
                tw.physics_step(&w, copy, &ContactForce::default(), 1e-3);
            }
            in_flight.retain(|m| m.0 > k);
            if k % 20 == 0 {
                for i in 0..2 {
                    let (tw, copy) = &sites[i];
                    let r = tw.report(copy, &ContactForce::default(), k as f64 * 1e-3);
                    if let Report::Tools(t) = &r {
                        seen(i, t, k, &sites);
                    }
                    if !lost(i, k) {
                        in_flight.push((k + delay, i, r));
                    }
                }
            }
        }
        sites
    }

    /// Site 1's tool sweeps from the right into the disk's rim (x = 0.04) between ticks 900 and
    /// 1300, then back; site 0's rests left of the disk.
    fn sweep_into_the_disk(i: usize, k: i64) -> Vec3 {
        let s = k as f64 * 1e-3;
        let x = match (i, s) {
            (0, _) => -0.06,
            (_, s) if s < 0.9 => 0.08,
            (_, s) if s < 1.3 => 0.08 - 0.1 * (s - 0.9),
            (_, s) => (0.04 + 0.1 * (s - 1.3)).min(0.08),
        };
        Vec3::new(x, 0.0, 0.01)
    }

    /// Two sites, 100 ticks apart, reporting every 20 ticks. Site 1's tool sweeps into the disk
    /// while 400 ticks of its reports are lost (more than a report's window of 256): site 0 holds
    /// later positions and not the gap's, so its frontier waits there and it asks for the gap
    /// (`need`); site 1 sends the gap again and the confirmed states agree to the bit. Without the
    /// request (the window alone) site 0 would confirm ticks simulated with a prediction of the
    /// sweep, and every later hash would differ.
    #[test]
    fn a_gap_of_lost_reports_is_asked_for_and_sent_again() {
        let start_x = 0.0;
        let mut asked = false;
        let sites = two_sites(
            1000,
            [0, 0],
            3000,
            sweep_into_the_disk,
            100,
            |from, k| from == 1 && (1150..1550).contains(&k),
            |i, t, _, _| asked |= i == 0 && t.need[1] >= 0,
        );
        let [(a, _), (b, _)] = &sites;
        assert!(asked, "site 0 asked for the gap");
        let moved = start_x - sites[1].1.state.pos.x;
        assert!(moved > 1e-3, "the sweep pushed the disk {moved} m");
        for (name, st) in [("site 0", a.stats()), ("site 1", b.stats())] {
            assert!(st.hash_checks > 50, "{name} compared: {st:?}");
            assert_eq!(st.hash_mismatches, 0, "{name}: {st:?}");
            assert_eq!(st.fallbacks, 0, "{name}: {st:?}");
        }
        assert_eq!(
            a.confirmed_tick(),
            b.confirmed_tick(),
            "both confirmed to the last report"
        );
    }

    /// A link down for longer than the history: site 0 never learns part of site 1's sweep into
    /// the disk (a fallback), so their confirmed states differ; site 1 asks site 0 (the lower
    /// number) for its state, adopts it, and from then on they agree again. A site whose physics
    /// started later (a restart) comes after one that was there: then site 0 adopts site 1's.
    #[test]
    fn confirmed_states_that_differ_after_a_fallback_are_resynchronized() {
        // Site 1 adopts site 0's state; with site 0's physics started at tick 1, the other way round.
        for (started_tick, adopter) in [([0, 0], 1), ([1, 0], 0)] {
            let mut asked = false;
            let mut mismatches_at = [0u64; 2];
            // Site 1 → site 0 is down for 1.2 s, twice the history.
            let sites = two_sites(
                600,
                started_tick,
                4000,
                sweep_into_the_disk,
                50,
                |from, k| from == 1 && (1000..2200).contains(&k),
                |i, t, k, sites| {
                    asked |= i == adopter && t.need_state == 1 << (1 - adopter);
                    if k == 3000 {
                        mismatches_at[i] = sites[i].0.stats().hash_mismatches;
                    }
                },
            );
            let [(a, ca), (b, cb)] = &sites;
            let st = [a.stats(), b.stats()];
            let why = format!("{started_tick:?}: {:?} {:?}", st[0], st[1]);
            assert!(
                st[0].fallbacks > 0,
                "site 0 lost part of site 1's sweep: {why}"
            );
            assert!(
                st[0].hash_mismatches + st[1].hash_mismatches > 0,
                "the divergence was seen: {why}"
            );
            assert!(asked, "site {adopter} asked the other for its state: {why}");
            assert!(st[adopter].adopted_states > 0, "{why}");
            assert_eq!(st[1 - adopter].adopted_states, 0, "{why}");
            assert_eq!(
                [st[0].hash_mismatches, st[1].hash_mismatches],
                mismatches_at,
                "no mismatch in the last second: {why}"
            );
            assert!(st[1].hash_checks > mismatches_at[1] + 20, "{why}");
            let t = a.confirmed_tick().min(b.confirmed_tick());
            assert!(t > 3900, "both confirmed to the last report: {t}");
            assert_eq!(a.hash_at(t), b.hash_at(t));
            assert_eq!(ca.state, cb.state, "the copies are the same bits");
            // Who adopted decides where the disk is: with site 0's state it was never swept.
            let swept = ca.state.pos.x < -1e-3;
            assert_eq!(swept, adopter == 0, "{:?}", ca.state.pos);
        }
    }

    /// A state that would put the disk deeper into the table than every user's force could is
    /// not adopted (it would be released as kinetic energy); one at rest on it is.
    #[test]
    fn a_state_deep_in_the_table_is_not_adopted() {
        let (_, w) = paper_world();
        let mut sites = two_sites(
            600,
            [0, 0],
            500,
            |_, _| Vec3::new(0.2, 0.0, 0.01),
            10,
            |_, _| false,
            |_, _, _, _| {},
        );
        let [(a, ca), (b, cb)] = &mut sites;
        b.set_max_spring_energy(0.05);
        let Report::Tools(mut r) = a.report(ca, &ContactForce::default(), 0.5) else {
            panic!("a track");
        };
        assert!(r.confirmed_tick > 400, "{}", r.confirmed_tick);
        let offer = |r: &mut ToolReport, z: f64| {
            let state = BodyState::at_rest(Vec3::new(0.001, 0.0, z));
            r.confirmed_hash = hash_state(&state);
            r.state = Some(Snapshot {
                tick: r.confirmed_tick,
                state,
                env: EnvContactState::default(),
                contacts: [ToolContactState::default(); MAX_SITES],
            });
        };
        // 5 cm into the table: ½ · 3000 N/m · (0.05 m)² ≈ 3.75 J of spring.
        offer(&mut r, 0.01 - 0.05);
        b.receive(&w, cb, 0, &Report::Tools(r), 0.5);
        assert_eq!(b.stats().adopted_states, 0, "{:?}", b.stats());
        assert!(b.stats().hash_mismatches > 0);
        offer(&mut r, 0.01);
        b.receive(&w, cb, 0, &Report::Tools(r), 0.5);
        assert_eq!(b.stats().adopted_states, 1, "{:?}", b.stats());
        assert_eq!(b.hash_at(r.confirmed_tick), Some(r.confirmed_hash));
    }

    #[test]
    fn positions_quantize_to_the_hundredth_of_a_millimetre() {
        assert_eq!(
            quantize(Vec3::new(0.012_345_6, -0.5, 0.0)),
            [1235, -50_000, 0]
        );
        let p = position([1235, -50_000, 0]);
        assert!((p - Vec3::new(0.01235, -0.5, 0.0)).norm() < 1e-15, "{p:?}");
        assert_eq!(
            quantize(p),
            [1235, -50_000, 0],
            "a quantized position quantizes to itself"
        );
    }
}
