//! Method `timewarp`: exchange the users' *tools* (the causes), not the object's state (the
//! effects), and roll back.
//!
//! Every site runs the same deterministic physics on a common tick grid. At each tick every user's
//! tool acts on the copy through the same contact law (Eq. 7, with friction memory), computed from
//! the tool's position at that tick, quantized to [`QUANTUM_M`] so every site uses the same bits: the
//! own tool as measured, a remote one from its received trajectory, and beyond the last received
//! tick a bounded prediction and then a hold. A site reports the own
//! tool's positions since its last report and those of the few reports before (so a lost report
//! or two lose nothing; more while its receivers ask for gaps: [`MAX_REDUNDANCY`]). When more is
//! lost in a row, the receiver holds later positions but not the gap's: it asks for the gap
//! ([`ToolReport::need`]) and the sender sends [`WINDOW_TICKS`] from there besides the newest in
//! every report.
//!
//! The copy's full state (body, momenta, environment friction memory, every tool's friction
//! memory) is kept for every tick of the horizon. When a received position differs from what was
//! predicted at a tick already simulated, the copy is restored to that tick and re-simulated to now
//! with what is known ([`RollbackStats::rollbacks`]). A position older than the horizon cannot be undone: it
//! is counted ([`RollbackStats::fallbacks`]) and the rollback starts at the oldest tick kept.
//!
//! Ticks whose inputs are known from every site are *confirmed*: their state is the same bits at
//! every site. Each report carries the sender's confirmed frontier and a hash of its state there;
//! a receiver that has confirmed the same tick compares ([`RollbackStats::hash_checks`],
//! [`RollbackStats::hash_mismatches`]), so a divergence of confirmed state is never silent (never
//! at a tick older than one it compared of that sender, as a repair's frontier is, nor before a
//! state it adopted: that history differs for good, and the world since agrees).
//!
//! A divergence heals: confirmed states differ only where a site never knew an input (a link down
//! for longer than the horizon: a fallback; a physics process that started after the session did,
//! restarted or late, which joins the grid where the session is ([`Consistency::start_at_tick`])
//! with no history before it), and then no
//! rollback can repair them. A site whose confirmed state differs from that of a site *before* it
//! asks that site for its state ([`ToolReport::need_state`]); that site sends its full confirmed
//! state ([`Snapshot`]: bodies, momenta, every friction memory, the objects' sleep) with its
//! report (a world of several one object per report, all at one tick), and again a round trip
//! later while still asked ([`STATE_RESEND_SLACK_S`]), and the asking site adopts it at that
//! tick, once it has all of it and has confirmed that tick too, and re-simulates to now
//! ([`RollbackStats::adopted_states`]):
//! the paper's adoption of a received state, at the confirmed frontier. Sites are ordered by the
//! tick their physics process started at ([`ToolReport::started_tick`]: the newest yields), then
//! by number; the first site's history is the one kept, so sites that all disagree still converge
//! on one. A state that puts the object deeper into the environment than all the users' forces
//! together could ([`TimeWarp::set_max_spring_energy`]) is not adopted: the mismatches go on,
//! counted. (Stations carry a world of one object's state so far: their wire's snapshot.)
//!
//! What rolling back costs the user's feel is counted too: confirmed ticks in which the own tool
//! touched the object though the copy had shown no contact when it first simulated them
//! ([`RollbackStats::unfelt_contact_ticks`]), and the other way round ([`RollbackStats::phantom_contact_ticks`]).
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
//! until it reaches the copy ([`RollbackStats::replays`]). The user feels the knock the confirmed history
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
//! as the partners' hands move it ([`RollbackStats::local_lag_ticks`], [`RollbackStats::lagged_ticks`]). The input
//! of a tick is whatever position the site stepped it with: every site still steps the same inputs.
//!
//! Determinism: the forces are summed in site order whatever site computes them, every input is an
//! integer, and the step uses only `+ − × ÷ sqrt` and `nalgebra`'s rotations (the same code on the
//! same platform gives the same bits; see the crate docs on transcendental functions).

mod before;
mod deadband;
mod hash;
mod islands;
mod lag;
mod predict;
mod replay;

pub use super::stats::CodecError;
use super::window::Tracks;
pub use super::window::{
    GAP_CHANCE, LOSS_FILTER_SHARE, MAX_REDUNDANCY, MIN_REDUNDANCY, REDUNDANCY_DECAY_REPORTS,
};
use before::Before;
use deadband::Moved;
pub use deadband::{DeadbandSpec, FLOOR_SHARE, JND_SHARE};
pub use hash::{hash_state, hash_world, STATE_RESEND_SLACK_S};
use lag::{DELAY_FILTER_SHARE, MEASURED_RING};
pub use lag::{LOCAL_LAG_MAX_TICKS, LOCAL_LAG_NEAR_M, LOCAL_LAG_SHARE, MAX_LOCAL_LAG_TICKS};
pub use predict::{
    EXTRAPOLATE_TICKS, REACH_TICKS, REACH_TIME_TICKS, REACH_VELOCITY_TICKS, SAMPLE_VELOCITY_TICKS,
};
pub use replay::{
    REPLAY_LEAD_TICKS, REPLAY_MIN_TICKS, REPLAY_REACH_M, REPLAY_SLOW_TICKS, REPLAY_SPEED,
};

use crate::body::{BodyState, Vec3};
use crate::contact::{tool_contact, ContactForce, ContactParams, ToolContactState};
use crate::world::{World, MAX_OBJECTS, MAX_SITES};

use super::consistency::{Consistency, Sink};
use super::copy::{integrate, integrate_some, WorldCopy};
use super::report::{Adoption, Report};
use super::stats::{RollbackStats, Stats};
use super::track::{
    limit_speed, position, quantize, Quantized, Received, Snapshot, ToolReport,
    MAX_TOOL_SPEED_M_PER_S, QUANTUM_M, UNKNOWN, WINDOW_TICKS,
};

/// One tick's record: the inputs used in it (the state at its start is kept beside it, in
/// [`TimeWarp::worlds`] and [`TimeWarp::tools`]).
#[derive(Debug, Clone, Copy)]
struct Slot {
    tick: i64,
    inputs: [Quantized; MAX_SITES],
    /// Per site: whether `inputs` held a received (true) or predicted (false) position.
    known: [bool; MAX_SITES],
    /// Whether the own tool touched the object in this tick's first (live) simulation...
    felt: bool,
    /// ...and in its latest.
    touched: bool,
    /// Per site: its tool's last motion (for its velocity through a deadband).
    moved: [Moved; MAX_SITES],
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
    /// Per slot, the copy at the start of its tick.
    worlds: Box<[WorldCopy]>,
    /// Per slot, every tool's friction memory with every object at the start of its tick
    /// ([`Self::tools_len`] each, as [`Self::contacts`]).
    tools: Box<[ToolContactState]>,
    /// Every tool's friction memory with every object: object `k`'s with site `j`'s tool at
    /// `k * MAX_SITES + j`.
    contacts: Box<[ToolContactState]>,
    /// Every tool's contact with every object in the tick being simulated (as `contacts`).
    users: Box<[ContactForce]>,
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
    /// What the own tracks sent and how much of it they send again, and the loss both ways
    /// ([`Tracks`]).
    tracks: Tracks,
    /// Per site before this one: its confirmed state differed from ours at the last comparison,
    /// and we ask it for that state.
    want_state: [bool; MAX_SITES],
    /// Per site: it asks for our confirmed state.
    state_asked: [bool; MAX_SITES],
    /// The tick the confirmed state was last sent at (`i64::MIN`: never).
    state_sent: std::cell::Cell<i64>,
    /// Per site: the newest of its confirmed ticks compared here (-1: none since it was last
    /// lost). A report naming an older one (a repair's, whose frontier is its window's end) is
    /// not compared: it says nothing the newer tick did not, and after an adoption it names the
    /// history the adopted state replaced.
    compared: [i64; MAX_SITES],
    /// The tick the newest adopted state was adopted at (`i64::MIN`: none): the history before
    /// it no longer leads to the copy, and is not compared.
    adopted_tick: i64,
    /// A world's state being received, object by object (all from one site, at one tick).
    incoming: Box<[Option<Snapshot>]>,
    /// The site `incoming` comes from: its start tick and number (the sites' order).
    incoming_from: (u64, usize),
    /// The tick this site's physics process started at ([`ToolReport::started_tick`]).
    started_tick: u64,
    /// The most environment-spring energy an adopted state may hold, J.
    max_spring_j: f64,
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
    stats: RollbackStats,
    /// The first confirmed tick not yet compared, live against confirmed contact.
    tallied_until: i64,
    /// A missed contact being replayed: the tick shown, and the own tool's position then.
    replay: Option<(i64, Quantized)>,
    /// Missed contacts before this tick were replayed (or passed over): not again.
    replayed_until: i64,
    /// The tick this site's history starts at (0, or where a restarted physics joined the grid:
    /// [`Consistency::start_at_tick`]).
    origin_tick: i64,
    /// A rollback's re-simulation in progress ([`islands`]).
    resim: Option<islands::Resim>,
    /// The copy and the tools' memory as a rollback found them: the old history's newest tick.
    scratch: WorldCopy,
    scratch_tools: Box<[ToolContactState]>,
    /// Per slot, its world's sketch for the reach tests; and the scratch's.
    sketches: Box<[islands::Sketch]>,
    scratch_sketch: islands::Sketch,
    /// Whether a re-simulation steps only what a changed input reaches ([`islands`]).
    islands: bool,
    /// The own positions' perceptual deadband, when on ([`deadband`]).
    deadband: Option<deadband::Deadband>,
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
        copy: &WorldCopy,
    ) -> Self {
        let len = horizon_ticks.max(WINDOW_TICKS) + 1;
        let tools_len = MAX_SITES * copy.len();
        let slot = Slot {
            tick: i64::MIN,
            inputs: [UNKNOWN; MAX_SITES],
            known: [false; MAX_SITES],
            felt: false,
            touched: false,
            moved: [Moved::rest(UNKNOWN, i64::MIN); MAX_SITES],
        };
        Self {
            me,
            sites: sites.min(MAX_SITES),
            dt,
            contact,
            radii,
            slots: vec![slot; len].into_boxed_slice(),
            worlds: vec![copy.clone(); len].into_boxed_slice(),
            tools: vec![ToolContactState::default(); len * tools_len].into_boxed_slice(),
            contacts: vec![ToolContactState::default(); tools_len].into_boxed_slice(),
            users: vec![ContactForce::default(); tools_len].into_boxed_slice(),
            now_tick: 0,
            received: vec![[None; MAX_SITES]; len].into_boxed_slice(),
            known_until: [-1; MAX_SITES],
            newest: [-1; MAX_SITES],
            asked: [-1; MAX_SITES],
            given_up: [false; MAX_SITES],
            tracks: Tracks::new(),
            want_state: [false; MAX_SITES],
            state_asked: [false; MAX_SITES],
            state_sent: std::cell::Cell::new(i64::MIN),
            compared: [-1; MAX_SITES],
            adopted_tick: i64::MIN,
            incoming: vec![None; MAX_OBJECTS].into_boxed_slice(),
            incoming_from: (0, 0),
            started_tick: 0,
            max_spring_j: f64::INFINITY,
            dirty_from: None,
            own: [0; 3],
            measured: vec![[0; 3]; MEASURED_RING].into_boxed_slice(),
            measured_count: 0,
            play_head: 0,
            lag_target: 0,
            delay_ticks: [0.0; MAX_SITES],
            lag_share: LOCAL_LAG_SHARE,
            lag_max: LOCAL_LAG_MAX_TICKS,
            stats: RollbackStats::default(),
            tallied_until: 0,
            replay: None,
            replayed_until: 0,
            origin_tick: 0,
            resim: None,
            scratch: copy.clone(),
            scratch_tools: vec![ToolContactState::default(); tools_len].into_boxed_slice(),
            sketches: vec![islands::Sketch::EMPTY; len].into_boxed_slice(),
            scratch_sketch: islands::Sketch::EMPTY,
            islands: true,
            deadband: None,
        }
    }

    /// Sends (and steps with) the own tool's positions through a perceptual deadband
    /// (`[timewarp.deadband]`, the `deadband` module).
    pub fn set_deadband(&mut self, spec: DeadbandSpec) {
        self.deadband = Some(deadband::Deadband::new(spec));
    }

    /// With a deadband: the own ticks stepped, and the positions sent (that left the band).
    pub fn deadband_samples(&self) -> Option<(u64, u64)> {
        self.deadband.map(|d| (d.ticks, d.samples))
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
    pub fn rollback_stats(&self) -> RollbackStats {
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

    /// Every tool's friction memory with every object, per slot.
    fn tools_len(&self) -> usize {
        self.contacts.len()
    }

    /// Whether site `j`'s tool touches any object, as the tools' friction memory `tools` has it.
    fn touches(tools: &[ToolContactState], j: usize) -> bool {
        tools
            .iter()
            .skip(j)
            .step_by(MAX_SITES)
            .any(|c| c.touching())
    }

    /// The tools' friction memory at the start of the tick in slot `i`.
    fn tools_at(&self, i: usize) -> &[ToolContactState] {
        let n = self.tools_len();
        &self.tools[i * n..(i + 1) * n]
    }

    /// Simulates tick `self.now_tick` on `copy` and keeps its record (in a rollback, stepping
    /// only the objects its changed inputs reach: [`islands`]).
    fn tick(&mut self, world: &World, copy: &mut WorldCopy) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let t = self.now_tick;
        let prev = self.slots[self.idx(t - 1)];
        let i = self.idx(t);
        let old = self.slots[i];
        // (In a re-simulation stepping the reached objects only, their record is written
        // below, once they are known; the others' is the old history's.)
        let islands = self.in_islands();
        if !islands {
            self.worlds[i].copy_from(copy);
            let n = self.tools_len();
            self.tools[i * n..(i + 1) * n].copy_from_slice(&self.contacts);
            self.sketches[i].update(copy, &self.contacts, &[true; MAX_OBJECTS]);
        }
        let mut slot = Slot {
            tick: t,
            inputs: [[0; 3]; MAX_SITES],
            known: [false; MAX_SITES],
            felt: false,
            touched: false,
            moved: [Moved::rest(UNKNOWN, t); MAX_SITES],
        };
        let objects = copy.len().min(world.bodies().len());
        let sites = self.sites;
        let mut tips = [Vec3::zeros(); MAX_SITES];
        let mut speeds = [Vec3::zeros(); MAX_SITES];
        for j in 0..sites {
            let (q, known) = if j == self.me {
                (self.own_at(t), true)
            } else {
                self.input(j, t)
            };
            slot.inputs[j] = q;
            slot.known[j] = known;
            let p = position(q);
            let was = (prev.tick == t - 1 && prev.inputs[j] != UNKNOWN && q != UNKNOWN)
                .then_some((prev.inputs[j], prev.moved[j]));
            slot.moved[j] = Moved::next(was, q, t);
            let v = if self.deadband.is_some() {
                slot.moved[j].velocity(q, t, self.dt)
            } else if was.is_some() {
                limit_speed((p - position(prev.inputs[j])) / self.dt)
            } else {
                Vec3::zeros()
            };
            tips[j] = p;
            speeds[j] = v;
        }
        let reached = islands.then(|| self.reach_objects(world, copy, t, (&old, &slot), &tips));
        let stepped = |k: usize| reached.is_none_or(|r| r[k]);
        // (An object not stepped keeps whatever its entries held: nothing reads them.)
        for j in 0..sites {
            for (k, body) in world.bodies()[..objects].iter().enumerate() {
                if stepped(k) {
                    self.users[k * sites + j] = tool_contact(
                        &self.contact,
                        &mut self.contacts[k * MAX_SITES + j],
                        &body.shape,
                        &copy.objects()[k].state,
                        &body.mass,
                        tips[j],
                        speeds[j],
                        self.radii[j],
                    );
                }
            }
        }
        slot.touched = (0..objects).any(|k| {
            if stepped(k) {
                self.users[k * sites + self.me].touching
            } else {
                self.touched_before(k, t)
            }
        });
        // A re-simulation keeps what the first simulation of the tick showed.
        slot.felt = if old.tick == t {
            old.felt
        } else {
            slot.touched
        };
        self.slots[i] = slot;
        // Summed in site order, the same at every site: all users count as "own" here.
        let users = &self.users[..objects * sites];
        match reached {
            None => integrate(world, copy, users, sites, sites, self.dt, &mut []),
            Some(r) => {
                let skip: [bool; MAX_OBJECTS] = std::array::from_fn(|k| k < objects && !r[k]);
                integrate_some(world, copy, (users, sites, sites), self.dt, &mut [], &skip);
            }
        }
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
    /// `whole`: every object is re-simulated (the state at `from` changed, or a test forces it);
    /// otherwise only what the changed inputs reach ([`islands`]).
    fn rollback(&mut self, world: &World, copy: &mut WorldCopy, from: i64, whole: bool) -> u64 {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let to = self.now_tick;
        let oldest = self.oldest_kept();
        let from = from.max(oldest);
        if from >= to {
            return 0;
        }
        let i = self.idx(from);
        let own_now = self.own;
        self.begin_resim(copy, (from, to), whole);
        copy.copy_from(&self.worlds[i]);
        let n = self.tools_len();
        self.contacts
            .copy_from_slice(&self.tools[i * n..(i + 1) * n]);
        self.now_tick = from;
        while self.now_tick < to {
            // The own positions of past ticks are the ones used then.
            self.own = self.slots[self.idx(self.now_tick)].inputs[self.me];
            self.tick(world, copy);
        }
        self.end_resim(copy);
        self.own = own_now;
        let depth = (to - from) as u64;
        self.stats.rollbacks += 1;
        self.stats.resimulated_ticks += depth;
        self.stats.max_depth = self.stats.max_depth.max(depth);
        self.stats.depths.record(depth);
        depth
    }

    /// Compares, for every tick confirmed since the last call, the own contact of its confirmed
    /// simulation with that of its first ([`RollbackStats::unfelt_contact_ticks`],
    /// [`RollbackStats::phantom_contact_ticks`]). A confirmed tick is never simulated again. Called where
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
}

impl TimeWarp {
    /// The own tool's newest ticks (and the last reports' again: [`window`]) and the confirmed
    /// frontier (see [`Consistency::report`]).
    #[cfg(test)]
    fn track_report(&self) -> Report {
        self.newest_track().1
    }

    /// [`Self::track_report`], and the tick its window starts at.
    fn newest_track(&self) -> (i64, Report) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        // Ticks up to end - 1 are simulated, with the own positions. (Nothing before the tick
        // this site's history starts at: it was not here.)
        let end = self.now_tick;
        let first = self.tracks.next_window(end, self.origin_tick);
        let due = end
            >= self
                .state_sent
                .get()
                .saturating_add(self.state_resend_ticks());
        let r = self.track_from(first, due);
        if matches!(r, Report::Tools(ToolReport { state: Some(_), .. })) {
            self.state_sent.set(end);
        }
        (first, r)
    }

    /// A peer that lost more reports in a row than the newest window covers asked for the first
    /// tick it lacks: a track from there ([`WINDOW_TICKS`] of them), sent besides the newest
    /// window in every report while it asks and the ticks are still kept, so the newest
    /// positions keep flowing and the peer's frontier can pass the gap. `window`: where the
    /// newest window starts.
    fn repair_report(&self, window: i64) -> Option<Report> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let oldest = self.oldest_kept();
        let first = (0..self.sites)
            .filter(|&j| j != self.me)
            .map(|j| self.asked[j])
            .filter(|&t| t >= oldest && t < window)
            .min()?;
        Some(self.track_from(first, false))
    }

    /// A track of the own positions from tick `first` to now (at most [`WINDOW_TICKS`]), with
    /// the confirmed frontier and what this site asks for; `with_state`: and the confirmed state
    /// if a site asks for it.
    fn track_from(&self, first: i64, with_state: bool) -> Report {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let count = (self.now_tick - first).min(WINDOW_TICKS as i64);
        let mut r = ToolReport {
            first_tick: first,
            count: count as usize,
            positions: [[0; 3]; WINDOW_TICKS],
            // A repair's window ends before the frontier: the frontier (and its hash) is given
            // at the window's end, a tick the sender has confirmed too, so that no report names
            // a frontier past the last position it carries (the wire's rule,
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
            loss: self.tracks.shares(),
            seq: 0,
        };
        for (j, &want) in self.want_state.iter().enumerate() {
            r.need_state |= u8::from(want) << j;
        }
        r.confirmed_hash = self.hash_at(r.confirmed_tick).unwrap_or(0);
        // (Its first object: the others follow in reports of their own, `Consistency::report`.)
        let t = r.confirmed_tick;
        r.state = (with_state
            && self.state_asked.iter().any(|&a| a)
            && self.slots[self.idx(t)].tick == t)
            .then(|| self.snapshot_at(t, 0, r.confirmed_hash));
        for j in (0..self.sites).filter(|&j| j != self.me) {
            if self.newest[j] > self.known_until[j] {
                r.need[j] = self.known_until[j] + 1;
            }
        }
        for (k, t) in (first..first + r.count as i64).enumerate() {
            r.positions[k] = self.slots[self.idx(t)].inputs[self.me];
        }
        Report::Tools(r)
    }
}

impl Consistency for TimeWarp {
    fn name(&self) -> &'static str {
        "timewarp"
    }
    fn own_tool(&mut self, tool_pos: Vec3) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        self.play_own(tool_pos);
    }
    fn physics_step(
        &mut self,
        world: &World,
        copy: &mut WorldCopy,
        _own: &[ContactForce],
        _dt: f64,
    ) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let (me, sites, t) = (self.me, self.sites, self.now_tick);
        // (The last tick's slot, for the held tool's velocity: read only through a deadband.)
        let prev = self.deadband.is_some().then(|| self.slots[self.idx(t - 1)]);
        if let (Some(d), Some(prev)) = (self.deadband.as_mut(), prev) {
            let objects = copy.len().min(world.bodies().len());
            let own = (0..objects).map(|k| self.users[k * sites + me]);
            let radius = self.radii[me];
            let width = d.width_m(
                (world, copy),
                &self.contact,
                position(self.own),
                radius,
                own,
            );
            let measured = self.own;
            self.own = d.filter(measured, width);
            // The velocity the step will give the held tool (as `tick` derives it).
            let was = (prev.tick == t - 1 && prev.inputs[me] != UNKNOWN)
                .then_some((prev.inputs[me], prev.moved[me]));
            let held_velocity = Moved::next(was, self.own, t).velocity(self.own, t, self.dt);
            // The own tool's contact from the tick's world state, its friction memory untouched.
            let (contact, memory) = (&self.contact, &self.contacts);
            d.measure((measured, self.own, held_velocity), self.dt, |p, v| {
                world.bodies()[..objects].iter().enumerate().fold(
                    (Vec3::zeros(), false),
                    |(f, touched), (k, body)| {
                        let mut m = memory[k * MAX_SITES + me];
                        let state = &copy.objects()[k].state;
                        let c = tool_contact(
                            contact,
                            &mut m,
                            &body.shape,
                            state,
                            &body.mass,
                            p,
                            v,
                            radius,
                        );
                        (f + c.force, touched || c.touching)
                    },
                )
            });
        }
        self.tick(world, copy);
        self.advance_replay();
        self.want_lag(world, copy);
    }
    /// One report for the whole world: the own tool's track and the confirmed world's hash; when
    /// it carries the confirmed state (a site asks for it, and again a round trip later while it
    /// still asks), of a world of several objects, one more report per object after the first,
    /// at the same tick (no positions, no hash: the state alone), so the whole state travels at
    /// once and arrives while its tick is still kept.
    fn report(&self, _copy: &WorldCopy, _own: &[ContactForce], _now_s: f64, out: Sink<'_>) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let (window, first) = self.newest_track();
        let rest = match &first {
            Report::Tools(r) => r.state.map(|s| (*r, s)),
            _ => None,
        };
        out(first);
        if let Some((r, s)) = rest {
            for k in 1..s.objects {
                out(Report::Tools(ToolReport {
                    // No positions: the window is empty at the frontier (a frontier never lies
                    // past a report's last tick).
                    first_tick: s.tick,
                    count: 0,
                    positions: [[0; 3]; WINDOW_TICKS],
                    confirmed_hash: 0,
                    state: Some(self.snapshot_at(s.tick, k, s.world_hash)),
                    ..r
                }));
            }
        }
        if let Some(repair) = self.repair_report(window) {
            out(repair);
        }
    }
    fn receive(
        &mut self,
        world: &World,
        copy: &mut WorldCopy,
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
        let need = r.need[self.me];
        if need >= 0 && need != self.asked[from] {
            self.tracks.gap_asked();
        }
        self.asked[from] = need;
        self.tracks.heard(from, r.seq, r.loss[self.me]);
        let asks = r.need_state & (1 << self.me) != 0;
        if asks && !self.state_asked[from] {
            // A site that starts asking gets the state with the next report, not a round trip
            // after another site's.
            self.state_sent.set(i64::MIN);
        }
        self.state_asked[from] = asks;
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
            let before = Before::of(world, copy);
            if self.rollback(world, copy, from_tick, false) > 0 {
                self.replay_missed_contact(from_tick);
                adoption = Some(before.adoption(
                    world,
                    copy,
                    (self.now_tick - from_tick) as f64 * self.dt,
                ));
            }
        }
        // Confirmed state compared where both know it, never at a tick older than the newest
        // compared (a repair's frontier, its window's end) nor before an adopted state: after an
        // adoption that history still differs, for good, and was counted a mismatch (and asked
        // for the state again) of a world that agrees.
        let t = r.confirmed_tick;
        if r.confirmed_hash != 0
            && t <= self.confirmed_tick()
            && t >= self.compared[from]
            && t >= self.adopted_tick
        {
            if let Some(h) = self.hash_at(t) {
                self.compared[from] = t;
                self.stats.hash_checks += 1;
                let differs = h != r.confirmed_hash;
                self.stats.hash_mismatches += u64::from(differs);
                // Asked for while it differs from a site before this one (and no longer when the
                // order changes: a restart moves a site back).
                let earlier = (r.started_tick, from) < (self.started_tick, self.me);
                self.want_state[from] = earlier && differs;
            }
        }
        // The state asked for (the first of its objects comes with a hash compared above, a world
        // of several's others in reports of their own), adopted once its tick is confirmed here:
        // this report may have brought it, or the inputs it waited for.
        if self.want_state[from] {
            self.gather(world, from, r);
        }
        if let Some(a) = self.adopt_gathered(world, copy) {
            adoption = Some(adoption.map_or(a, |b| Adoption {
                jump: a.jump + b.jump,
                energy_j: a.energy_j + b.energy_j,
                work_j: a.work_j + b.work_j,
                age_s: a.age_s.max(b.age_s),
                clipped_j: 0.0,
            }));
        }
        self.tally();
        adoption
    }
    fn peer_lost(&mut self, from: usize, _now_s: f64) {
        self.tracks.peer_lost(from);
        // A silent site neither asks for our state nor sends its own: ask again once it is back.
        if let (Some(asked), Some(want)) = (
            self.state_asked.get_mut(from),
            self.want_state.get_mut(from),
        ) {
            *asked = false;
            *want = false;
        }
        // (A site back from silence may have restarted, its frontier earlier than before.)
        if let Some(c) = self.compared.get_mut(from) {
            *c = -1;
        }
        // Nor is its delay known any more: no lag for it until it reports again.
        if let Some(d) = self.delay_ticks.get_mut(from) {
            *d = 0.0;
        }
    }
    fn stats(&self) -> Stats {
        let mut st = self.stats;
        if let Some(d) = self.deadband {
            (st.deadband_ticks, st.deadband_samples) = (d.ticks, d.samples);
            st.deadband_error = d.error;
        }
        st.redundancy_reports = self.tracks.reports() as u64;
        Stats::Rollback(st)
    }
    fn grid_history_ticks(&self) -> Option<u64> {
        Some(self.history_ticks() as u64)
    }
    /// The copy's state, or during a replay of a missed contact the history's at the replayed
    /// tick, its velocities at the replay's speed (so the display sees the motion it shows).
    fn shown(&self, copy: &WorldCopy, k: usize) -> BodyState {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        match self.replay {
            Some((t, _)) if self.slots[self.idx(t)].tick == t => {
                let mut s = self.worlds[self.idx(t)].objects()[k].state;
                let k = self.replay_speed(t) as f64;
                s.vel *= k;
                s.ang_mom *= k;
                s
            }
            _ => copy.objects()[k].state,
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
    /// GGPO's synctest: rolls the copy back `depth` ticks and re-simulates them with the same
    /// inputs; whether it arrived at the same bits (state, friction memory) it had. Determinism is
    /// what makes every site's confirmed state the same: this checks it on every tick it is run.
    /// (A test's tool: it allocates.)
    pub fn synctest(&mut self, world: &World, copy: &mut WorldCopy, depth: i64) -> bool {
        let (before, contacts) = (copy.clone(), self.contacts.clone());
        let stats = self.stats;
        self.rollback(world, copy, self.now_tick - depth, true);
        self.stats = stats; // a test's rollbacks are not the method's
        let same = |a: &WorldCopy, b: &WorldCopy| {
            a.pairs() == b.pairs()
                && a.still() == b.still()
                && a.objects()
                    .iter()
                    .zip(b.objects())
                    .all(|(x, y)| x.state == y.state && x.env == y.env)
        };
        same(copy, &before) && self.contacts == contacts
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
mod tests;
