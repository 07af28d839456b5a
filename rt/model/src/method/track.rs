//! The tool tracks `timewarp` and `coupled` exchange: positions on the session's tick grid,
//! quantized so every site steps the same bits, and what goes with them.

use crate::body::{BodyState, Vec3};
use crate::contact::{EnvContactState, PairContactState, ToolContactState};
use crate::world::{MAX_OBJECTS, MAX_SITES};

/// The quantum of a tool position on the wire and in the physics, m (0.01 mm).
pub const QUANTUM_M: f64 = 1e-5;

/// Own tool positions in each report: the last this many ticks.
pub const WINDOW_TICKS: usize = 256;

/// A tool position on the tick grid, in quanta.
pub type Quantized = [i32; 3];

/// Where a tool is before anything is known of it: 10 km away, touching nothing.
pub const UNKNOWN: Quantized = [1_000_000_000; 3];

/// A received position and its tick.
pub(crate) type Received = Option<(i64, Quantized)>;

/// The fastest a tool moves in the physics, m/s: a prediction that jumps (a held position meeting
/// the received one) must not kick the object through the contact's damping.
pub const MAX_TOOL_SPEED_M_PER_S: f64 = 10.0;

/// `v`, m/s, at most [`MAX_TOOL_SPEED_M_PER_S`] fast (its direction kept).
pub fn limit_speed(v: Vec3) -> Vec3 {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    let speed = v.norm();
    if speed > MAX_TOOL_SPEED_M_PER_S {
        v * (MAX_TOOL_SPEED_M_PER_S / speed)
    } else {
        v
    }
}

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

/// One object of a site's full state at the start of one of its confirmed ticks: what a site
/// whose confirmed history diverged from it adopts (see the module docs). A world of several
/// objects travels one object per report, all at the same tick, and is adopted once every object
/// of it has arrived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Snapshot {
    /// The tick.
    pub tick: i64,
    /// Which object this is, of how many.
    pub object: usize,
    /// See `object`.
    pub objects: usize,
    /// The hash of the whole world's state at `tick` (what every object of it together gives).
    pub world_hash: u64,
    /// The object.
    pub state: BodyState,
    /// The environment's friction memory.
    pub env: EnvContactState,
    /// Every tool's friction memory.
    pub contacts: [ToolContactState; MAX_SITES],
    /// Its contact memory with each later object (`object + 1 + k` at `k`).
    pub pairs: [PairContactState; MAX_OBJECTS - 1],
    /// The steps in a row it has been still (it sleeps after a number of them).
    pub still: u32,
}

impl Snapshot {
    /// The state of a world of one object (`world_hash` its state's hash: `hash_state`).
    pub fn one(
        tick: i64,
        world_hash: u64,
        state: BodyState,
        env: EnvContactState,
        contacts: [ToolContactState; MAX_SITES],
    ) -> Self {
        Self {
            tick,
            object: 0,
            objects: 1,
            world_hash,
            state,
            env,
            contacts,
            pairs: [PairContactState::default(); MAX_OBJECTS - 1],
            still: 0,
        }
    }
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
    /// Per site `j`: the share of `j`'s reports the sender found lost lately, in 255ths (so `j`
    /// sends its ticks again in as many reports as that loss needs).
    pub loss: [u8; MAX_SITES],
    /// The report's sequence number among its sender's, as the carrier numbers them (the wire's
    /// track sequence, the simulator's count); 0: unknown. Not sent by the method: received.
    pub seq: u64,
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
        loss: [0; MAX_SITES],
        seq: 0,
    };
}

/// What a `coupled` site reports: its tool trajectory, its copy, and when its user's contact began.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoupledReport {
    /// The tool positions, as `timewarp` sends them (no confirmed hash: `confirmed_hash` 0).
    pub tools: ToolReport,
    /// Which object `state` is (its tools come with object 0's report only).
    pub object: usize,
    /// Time of `state`, s (sender's clock).
    pub t_s: f64,
    /// The sender's copy.
    pub state: BodyState,
    /// Gravity less the environment's support at `state`, m/s² (for dead reckoning).
    pub accel: Vec3,
    /// When the sender's user's current contact began, s; infinite: not touching.
    pub touch_since_s: f64,
    /// When the sender's user last touched, s; negative infinity: never.
    pub last_touch_s: f64,
}
