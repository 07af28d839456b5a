//! Method `coupled`: exchange the users' *tools* as `timewarp` does, but without rollback — for
//! sites that cannot run the same deterministic physics, or lose packets — and hold the copies
//! together with an energy-bounded pull.
//!
//! - **Tools from a jitter buffer.** Every site's copy feels every user's tool through the same
//!   contact law: its own as measured, and each remote one as it was a *playout delay* ago, so a
//!   remote tool is played late but whole, in step, rather than predicted and corrected. The
//!   playout delay is adaptive, per remote site, as a voice jitter buffer's: it follows the latest
//!   arrival measured (each report's oldest position new to this site against the tick it arrives
//!   at: the one-way delay plus the sender's report period; a lost report is not counted), a peak
//!   that decays at [`PLAYOUT_DECAY_TICKS_PER_TICK`], plus the largest change between two arrivals
//!   (decaying alike: the jitter, and how far the delay moves between two reports), plus
//!   [`PLAYOUT_MARGIN_S`]. It starts at, and never exceeds,
//!   the configured largest arrival ([`Coupled::max_playout_ticks`]: the largest delay, its jitter
//!   and the slowest report period). To follow a change the remote tool is played slower (half
//!   speed while the delay grows) or faster (5/4 speed while it shrinks), on a quarter-tick grid
//!   between its received positions, so while they are there it neither stands still nor jumps.
//!   A position missing at its playout tick (lost, later than the target) holds the last one
//!   played ([`Coupled::held_ticks`]), and the peak grows to that arrival. With the paper's delay
//!   swinging between 20 and 500 ms (`paper.toml`, seed 7) a partner's tool is felt 130–160 ms late
//!   at the swing's lows (forgetting at 0.125 s/s, the playout lags the delay's fall at up to
//!   0.25 s/s) instead of 0.56 s late throughout, and held 0.6 % (user 1's tool at user 2's site,
//!   90 Hz reports) and 3.3 % (user 2's at user 1's, 20 Hz) of the ticks, on the delay's rises;
//!   the co-contact divergence is 13–16 mm on seeds 1–9 instead of 16–30. The reports are
//!   [`crate::method::track::ToolReport`]s, the same tool trajectory `timewarp` sends, with the
//!   same window: the ticks since the last report and as many reports' again as the loss the
//!   receivers measure needs ([`super::window`]); a longer loss is held, as a late position is.
//! - **Pull towards the site that touched first.** Played late, the remote tools make the copies
//!   drift apart. The site whose user's current contact began first (ties: the lower index) leads;
//!   the others pull their copy towards its reported state (dead-reckoned to now): on each of its
//!   reports, the fraction Δ / (Δ + [`PULL_TIME_S`]) of the way, Δ the time since the last pull —
//!   a first-order convergence with time constant [`PULL_TIME_S`].
//! - **Energy-bounded** (PSPM-style set-position clipping): a pull may bring the copy's energy up to
//!   the leader's state's (that energy is accounted for: the leader's users gave it, at the leader's
//!   site, under its own bound) plus what the copy's tank holds ([`super::tank::bound_gain`] scales
//!   it back along the way, counted); the tank is filled by the users' positive work on this copy,
//!   drained by what pulls add beyond the leader's energy and refilled by what they take. So no pull
//!   gives a copy more energy than some copy's users gave theirs. The leader's energy has to count:
//!   a follower's copy, pulled ahead of the leader's tool played late on it, takes little of that
//!   tool's work, so a tank of its own work alone stays empty and holds the copy back from the
//!   leader's push for good (the paper task at 150 ms, seed 3: 525 pulls scaled back, user 2's
//!   copy stopped short of its tool, 5 of 12 phases). Along the normal of a plane the local copy
//!   rests on, the pull keeps the local contact (as
//!   `paper` does): transplanting another copy's micro-bounce would only pump the table's spring.

use crate::body::{BodyState, Vec3};
use crate::contact::{tool_contact, ContactForce, ContactParams, ToolContactState};
use crate::world::{World, MAX_OBJECTS, MAX_SITES};

use super::consistency::{Consistency, Sink};
use super::copy::{integrate, WorldCopy};
use super::reckon::{dead_reckon, passive_reckoned};
use super::report::{Adoption, Report};
use super::stats::Stats;
use super::track::{
    position, quantize, CoupledReport, Quantized, Received, ToolReport, MAX_TOOL_SPEED_M_PER_S,
    UNKNOWN, WINDOW_TICKS,
};
use super::window::Tracks;

/// Time constant of the pull towards the leading site's copy, s: long against the contact's
/// oscillation (a 0.1 kg disk on the 800 N/m tool spring rings at ~14 ms), short against a task
/// phase (~1 s).
pub const PULL_TIME_S: f64 = 0.05;

/// What the playout delay keeps beyond the latest arrival measured and the largest change between
/// two arrivals, s.
pub const PLAYOUT_MARGIN_S: f64 = 0.005;

/// How fast the latest arrival measured is forgotten, ticks per tick: a delay that falls is
/// followed at up to this rate (the paper's swing falls at up to 0.25 s/s; following it more
/// slowly keeps a longer delay than needed, which costs agreement, never a tool).
pub const PLAYOUT_DECAY_TICKS_PER_TICK: f64 = 0.125;

/// The play head's grid: a remote tool is played at quarter ticks between its positions.
const QUARTERS: i64 = 4;

/// The `coupled` method of one site.
#[derive(Debug, Clone)]
pub struct Coupled {
    me: usize,
    sites: usize,
    dt: f64,
    contact: ContactParams,
    radii: [f64; MAX_SITES],
    /// The configured largest arrival, ticks: where the playout starts and what it never exceeds.
    max_playout_ticks: i64,
    /// Per site: how late its tool is played, quarter ticks.
    playout_q: [i64; MAX_SITES],
    /// Per site: the latest arrival measured, decaying, quarter ticks (0: nothing measured).
    arrival_q: [i64; MAX_SITES],
    /// Per site: the tick after the newest position received (`i64::MIN`: none yet).
    known_end: [i64; MAX_SITES],
    /// Per site: how far its last report that advanced `known_end` advanced it, ticks.
    last_advance: [i64; MAX_SITES],
    /// Per site: ticks its tool was held because its position had not arrived at its playout.
    held: [u64; MAX_SITES],
    /// Per site: the last arrival measured, quarter ticks.
    last_late_q: [i64; MAX_SITES],
    /// Per site: the largest change between two arrivals measured, decaying as the peak does,
    /// quarter ticks (the arrivals' jitter, and how fast the delay moves between two reports).
    jitter_q: [i64; MAX_SITES],
    /// [`PLAYOUT_MARGIN_S`] in quarter ticks.
    margin_q: i64,
    /// [`PLAYOUT_DECAY_TICKS_PER_TICK`] as one quarter tick every this many ticks.
    decay_every: i64,
    now_tick: i64,
    /// The tick this site started stepping at (0, or where a restarted physics joined the grid).
    origin_tick: i64,
    /// Received positions with their ticks, tick `t` at `t % len`.
    received: Box<[[Received; MAX_SITES]]>,
    /// Own positions of the last ticks (tick `t` at `t % WINDOW_TICKS`).
    own_hist: Box<[Quantized]>,
    /// Which own ticks a track carries (the new ones and the last reports' again, as many as the
    /// loss the receivers measure needs), and the loss both ways ([`Tracks`]).
    tracks: Tracks,
    own: Quantized,
    /// Per site: the position played at the last tick.
    played: [Quantized; MAX_SITES],
    /// Per object, per site: its tool's contact memory.
    contacts: [[ToolContactState; MAX_SITES]; MAX_OBJECTS],
    /// Per object, per site: when its user's current contact began, s (infinite: not touching).
    touch_since: [[f64; MAX_SITES]; MAX_OBJECTS],
    /// Per object, per site: when its user last touched, s (negative infinity: never).
    last_touch: [[f64; MAX_SITES]; MAX_OBJECTS],
    /// Per object: the site that leads it.
    leader: [usize; MAX_OBJECTS],
    /// Per object, per site: the time of its newest report taken.
    newest_from: [[f64; MAX_SITES]; MAX_OBJECTS],
    /// Per object: when it was last pulled, s.
    last_pull_s: [f64; MAX_OBJECTS],
    /// Per object: its tank, J.
    tank_j: [f64; MAX_OBJECTS],
    /// Forces of the remote tools on the copy at the last tick (for traces), N.
    remote_force: Vec3,
}

impl Coupled {
    /// Site `me` of `sites`, stepping `dt` s, with the tool contact law and each site's tool radius,
    /// playing remote tools at most `playout_ticks` late (and that late until their arrival is
    /// measured).
    pub fn new(
        me: usize,
        sites: usize,
        dt: f64,
        contact: ContactParams,
        radii: [f64; MAX_SITES],
        playout_ticks: usize,
    ) -> Self {
        let len = playout_ticks + 2 * WINDOW_TICKS + 1;
        Self {
            me,
            sites: sites.min(MAX_SITES),
            dt,
            contact,
            radii,
            max_playout_ticks: playout_ticks as i64,
            playout_q: [playout_ticks as i64 * QUARTERS; MAX_SITES],
            arrival_q: [0; MAX_SITES],
            known_end: [i64::MIN; MAX_SITES],
            last_advance: [i64::MAX; MAX_SITES],
            held: [0; MAX_SITES],
            last_late_q: [0; MAX_SITES],
            jitter_q: [0; MAX_SITES],
            margin_q: (PLAYOUT_MARGIN_S / dt * QUARTERS as f64).ceil() as i64,
            decay_every: ((1.0 / (PLAYOUT_DECAY_TICKS_PER_TICK * QUARTERS as f64)).round() as i64)
                .max(1),
            now_tick: 0,
            origin_tick: 0,
            received: vec![[None; MAX_SITES]; len].into_boxed_slice(),
            own_hist: vec![[0; 3]; WINDOW_TICKS].into_boxed_slice(),
            tracks: Tracks::new(),
            own: [0; 3],
            played: [UNKNOWN; MAX_SITES],
            contacts: [[ToolContactState::default(); MAX_SITES]; MAX_OBJECTS],
            touch_since: [[f64::INFINITY; MAX_SITES]; MAX_OBJECTS],
            last_touch: [[f64::NEG_INFINITY; MAX_SITES]; MAX_OBJECTS],
            leader: [0; MAX_OBJECTS],
            newest_from: [[f64::NEG_INFINITY; MAX_SITES]; MAX_OBJECTS],
            last_pull_s: [0.0; MAX_OBJECTS],
            tank_j: [0.0; MAX_OBJECTS],
            remote_force: Vec3::zeros(),
        }
    }

    /// The configured largest arrival, ticks: the playout delay a remote tool starts at and never
    /// exceeds.
    pub fn max_playout_ticks(&self) -> i64 {
        self.max_playout_ticks
    }

    /// How late site `j`'s tool is played now, ticks (in quarter ticks).
    pub fn site_playout_ticks(&self, j: usize) -> f64 {
        self.playout_q
            .get(j)
            .map_or(0.0, |&q| q as f64 / QUARTERS as f64)
    }

    /// Ticks site `j`'s tool was held: its position had not arrived at its playout.
    pub fn held_ticks(&self, j: usize) -> u64 {
        self.held.get(j).copied().unwrap_or(0)
    }

    /// The position of site `j`'s tool at tick `tick`, if received.
    fn received_at(&self, j: usize, tick: i64) -> Option<Quantized> {
        match self.received[self.slot(tick)][j] {
            Some((t, q)) if t == tick => Some(q),
            _ => None,
        }
    }

    /// Site `j`'s tool at play point `at_q` (quarter ticks): its received position, or the one a
    /// quarter of the way to the next for each quarter past it; `None` if not received.
    fn played_at(&self, j: usize, at_q: i64) -> Option<Quantized> {
        let (tick, quarter) = (at_q.div_euclid(QUARTERS), at_q.rem_euclid(QUARTERS));
        let a = self.received_at(j, tick)?;
        if quarter == 0 {
            return Some(a);
        }
        let Some(b) = self.received_at(j, tick + 1) else {
            return Some(a);
        };
        // Integer interpolation on the quantum grid (the same bits on every machine).
        let mix = |x: i32, y: i32| {
            let v = i64::from(x) * (QUARTERS - quarter) + i64::from(y) * quarter;
            (v + QUARTERS / 2).div_euclid(QUARTERS) as i32
        };
        Some([mix(a[0], b[0]), mix(a[1], b[1]), mix(a[2], b[2])])
    }

    /// Moves site `j`'s playout one tick towards its target: the latest arrival measured, the
    /// largest change between two and the margin, within the configured largest; grows at half
    /// speed, shrinks at 5/4 (from a margin above the target).
    fn adapt_playout(&mut self, j: usize) {
        if self.arrival_q[j] == 0 {
            return; // nothing measured yet: keep the configured largest
        }
        if self.now_tick % self.decay_every == 0 {
            if self.arrival_q[j] > 1 {
                self.arrival_q[j] -= 1; // (never back to 0: something was measured)
            }
            self.jitter_q[j] = (self.jitter_q[j] - 1).max(0);
        }
        let max_q = self.max_playout_ticks * QUARTERS;
        let target = (self.arrival_q[j] + self.jitter_q[j] + self.margin_q).min(max_q);
        let p = &mut self.playout_q[j];
        if *p < target {
            *p = (*p + 2).min(max_q);
        } else if *p > target + self.margin_q {
            // Shrinks only a margin above the target: the arrivals' jitter moves the target by a
            // few ticks between reports, and a play speed that follows it would dither.
            *p -= 1;
        }
    }

    fn slot(&self, t: i64) -> usize {
        t.rem_euclid(self.received.len() as i64) as usize
    }

    /// Keeps the tool positions of `tools` from `from` that can still be played, and measures
    /// their arrival: the oldest position new to this site against the tick it arrives at. A
    /// report that advances the newest tick known counts from one *usual span* before its end
    /// (the smaller of its advance and the one before: a report lost in between, or a partition,
    /// is a loss, not a delay); one that fills a gap behind it (reordered) counts as late as it is.
    fn take_tools(&mut self, from: usize, tools: &ToolReport) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let count = tools.count.min(WINDOW_TICKS);
        if count == 0 {
            return;
        }
        self.tracks.heard(from, tools.seq, tools.loss[self.me]);
        let end = tools.first_tick + count as i64;
        // What can still be played: from the largest playout back to a window ahead (older or
        // newer positions would only alias the slots of ones waiting to be played).
        let oldest = tools.first_tick.max(self.now_tick - self.max_playout_ticks);
        let newest = end.min(self.now_tick + 2 * WINDOW_TICKS as i64);
        let known = self.known_end[from];
        let first_new = if known == i64::MIN {
            Some(end - 1) // the first report: its history is not news, its newest position is
        } else if end > known {
            let advance = end - known;
            let span = advance.min(self.last_advance[from]).max(1);
            self.last_advance[from] = advance;
            Some(end - span)
        } else {
            (oldest..newest).find(|&t| self.received_at(from, t).is_none())
        };
        for t in oldest..newest {
            let i = self.slot(t);
            self.received[i][from] = Some((t, tools.positions[(t - tools.first_tick) as usize]));
        }
        self.known_end[from] = known.max(end);
        if let Some(t) = first_new {
            let late_q = (self.now_tick - t).clamp(0, self.max_playout_ticks) * QUARTERS;
            if known != i64::MIN {
                let change = (late_q - self.last_late_q[from]).abs();
                self.jitter_q[from] = self.jitter_q[from].max(change);
            }
            self.last_late_q[from] = late_q;
            self.arrival_q[from] = self.arrival_q[from].max(late_q.max(1));
        }
    }

    /// The site that leads object `o`: the earliest current contact with it (ties: the lower
    /// index); when nobody touches it, the one whose user touched it last (its copy holds the
    /// newest push), as far as known.
    fn pick_leader(&mut self, o: usize) {
        let (since, last) = (&self.touch_since[o], &self.last_touch[o]);
        let mut best: Option<usize> = None;
        for k in 0..self.sites {
            if since[k].is_finite() && best.is_none_or(|b| since[k] < since[b]) {
                best = Some(k);
            }
        }
        if best.is_none() {
            for k in 0..self.sites {
                if last[k].is_finite() && best.is_none_or(|b| last[k] > last[b]) {
                    best = Some(k);
                }
            }
        }
        if let Some(b) = best {
            self.leader[o] = b;
        }
    }
}

impl Consistency for Coupled {
    fn name(&self) -> &'static str {
        "coupled"
    }
    fn start_at_tick(&mut self, tick: i64) {
        self.now_tick = tick.max(0);
        self.origin_tick = self.now_tick;
    }
    fn own_tool(&mut self, tool_pos: Vec3) {
        self.own = quantize(tool_pos);
    }
    fn peer_lost(&mut self, from: usize, _now_s: f64) {
        self.tracks.peer_lost(from);
    }
    fn remote_force(&self) -> Vec3 {
        self.remote_force
    }
    fn stats(&self) -> Stats {
        (0..self.sites)
            .filter(|&j| j != self.me)
            .map(|j| self.site_playout_ticks(j))
            .reduce(f64::max)
            .map_or(Stats::None, |ticks| Stats::Playout { ticks })
    }
    fn grid_history_ticks(&self) -> Option<u64> {
        Some(WINDOW_TICKS as u64)
    }
    fn physics_step(
        &mut self,
        world: &World,
        world_copy: &mut WorldCopy,
        _own: &[ContactForce],
        _dt: f64,
    ) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let t = self.now_tick;
        let sites = self.sites;
        let n = world_copy.len();
        // Every site's tool as played at this tick: position and velocity.
        let mut tools = [(Vec3::zeros(), Vec3::zeros()); MAX_SITES];
        for (j, tool) in tools.iter_mut().enumerate().take(sites) {
            let q = if j == self.me {
                self.own
            } else {
                self.adapt_playout(j);
                let at_q = t * QUARTERS - self.playout_q[j];
                match self.played_at(j, at_q) {
                    Some(q) => q,
                    None => {
                        // Missing at its playout tick: hold (once anything was played).
                        if self.played[j] != UNKNOWN {
                            self.held[j] += 1;
                        }
                        self.played[j]
                    }
                }
            };
            let p = position(q);
            let v = if self.played[j] != UNKNOWN && q != UNKNOWN {
                let v = (p - position(self.played[j])) / self.dt;
                let speed = v.norm();
                let max = MAX_TOOL_SPEED_M_PER_S;
                if speed > max {
                    v * (max / speed)
                } else {
                    v
                }
            } else {
                Vec3::zeros()
            };
            self.played[j] = q;
            *tool = (p, v);
        }
        // Every tool on every object, `sites` to an object, in site order.
        let mut users = [ContactForce::default(); MAX_SITES * MAX_OBJECTS];
        let mut remote = Vec3::zeros();
        let now_s = world_copy.first().time_s;
        let mut before = [0.0; MAX_OBJECTS];
        for (k, copy) in world_copy.objects().iter().enumerate() {
            let body = &world.bodies()[k];
            for j in 0..sites {
                let (p, v) = tools[j];
                let user = tool_contact(
                    &self.contact,
                    &mut self.contacts[k][j],
                    &body.shape,
                    &copy.state,
                    &body.mass,
                    p,
                    v,
                    self.radii[j],
                );
                if j != self.me {
                    remote += user.force;
                }
                users[k * sites + j] = user;
            }
            let own_touch = users[k * sites + self.me].touching;
            let since = &mut self.touch_since[k][self.me];
            match (own_touch, since.is_finite()) {
                (true, false) => *since = now_s,
                (false, true) => *since = f64::INFINITY,
                _ => {}
            }
            if own_touch {
                self.last_touch[k][self.me] = now_s;
            }
            self.pick_leader(k);
            before[k] = copy.energy.users_positive_j;
        }
        // Summed in site order; every user acts on this copy.
        integrate(
            world,
            world_copy,
            &users[..n * sites],
            sites,
            sites,
            self.dt,
            &mut [],
        );
        for (k, copy) in world_copy.objects().iter().enumerate() {
            self.tank_j[k] += copy.energy.users_positive_j - before[k];
        }
        self.remote_force = remote;
        self.own_hist[t.rem_euclid(WINDOW_TICKS as i64) as usize] = self.own;
        self.now_tick = t + 1;
    }
    /// The tool track, with one state per object this site leads or its user touches (in a world
    /// of one object, that object always); the track alone when there is none.
    fn report(&self, copy: &WorldCopy, _own: &[ContactForce], now_s: f64, out: Sink<'_>) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let end = self.now_tick;
        let first = self.tracks.next_window(end, self.origin_tick);
        let mut tools = ToolReport {
            first_tick: first,
            count: (end - first) as usize,
            loss: self.tracks.shares(),
            ..ToolReport::NONE
        };
        for (k, t) in (first..end).enumerate() {
            tools.positions[k] = self.own_hist[t.rem_euclid(WINDOW_TICKS as i64) as usize];
        }
        let n = copy.len();
        let mut sent = false;
        for (k, o) in copy.objects().iter().enumerate() {
            let touching = self.touch_since[k][self.me].is_finite();
            if n > 1 && self.leader[k] != self.me && !touching {
                continue;
            }
            // The track goes with the first state only.
            out(Report::Coupled(CoupledReport {
                tools: if sent { ToolReport::NONE } else { tools },
                object: k,
                t_s: now_s,
                state: o.state,
                accel: o.passive_accel,
                touch_since_s: self.touch_since[k][self.me],
                last_touch_s: self.last_touch[k][self.me],
            }));
            sent = true;
        }
        if !sent {
            out(Report::Tools(tools));
        }
    }
    fn receive(
        &mut self,
        world: &World,
        world_copy: &mut WorldCopy,
        from: usize,
        msg: &Report,
        now_s: f64,
    ) -> Option<Adoption> {
        if from >= self.sites || from == self.me {
            return None;
        }
        let r = match msg {
            // A station sends its tools as a track and its state apart (two rings, two keys).
            Report::Tools(tools) => {
                self.take_tools(from, tools);
                return None;
            }
            Report::Coupled(r) if r.state.is_finite() => r,
            _ => return None,
        };
        self.take_tools(from, &r.tools);
        let k = r.object;
        // (A value: the copy's other objects are read as they are to bound it, then it is put back.)
        let mut copy = *world_copy.objects().get(k)?;
        let body = world.bodies().get(k)?;
        if r.t_s <= self.newest_from[k][from] {
            return None; // an older state than one taken: its tools are kept, not its state
        }
        self.newest_from[k][from] = r.t_s;
        self.touch_since[k][from] = r.touch_since_s;
        self.last_touch[k][from] = r.last_touch_s;
        self.pick_leader(k);
        if from != self.leader[k] {
            return None;
        }
        // (Reckoned as `paper` adopts: with no more energy than the leader sent. The pull's budget
        // is the target's energy; a target flown on unslowed would have raised it.)
        let reckoned = dead_reckon(world, k, &r.state, r.accel, now_s - r.t_s, 2);
        let reckoned = passive_reckoned(world, k, &r.state, reckoned);
        let mut target = reckoned;
        // Along the normal of a plane the local copy rests on, its contact is local physics.
        for plane in world.planes() {
            if crate::world::plane_depth(&body.shape, plane, &copy.state) > -1e-4 {
                let n = plane.normal;
                target.pos += n * (copy.state.pos - target.pos).dot(&n);
                target.vel += n * (copy.state.vel - target.vel).dot(&n);
            }
        }
        let since = (now_s - self.last_pull_s[k]).max(0.0);
        self.last_pull_s[k] = now_s;
        let alpha = since / (since + PULL_TIME_S);
        let full = super::tank::blend(&copy.state, &target, alpha);
        let stored = |s: &BodyState| super::tank::stored_energy(world, k, s);
        // The leader's state is accounted for (its users gave it its energy, at its site): a pull
        // may bring the copy up to it, plus what this copy's tank holds.
        // The leader's energy is its state's as reckoned: the local height put under the leader's
        // tilt presses a rim into the table, a spring the leader never had (a tray's pull took a
        // 1.5 J budget from it and threw the tray).
        let (e_copy, e_leader) = (stored(&copy.state), stored(&reckoned));
        let tank = &mut self.tank_j[k];
        let budget = *tank + (e_leader - e_copy).max(0.0);
        let (new, clipped_j) =
            match super::tank::bound_gain(world, k, &copy.state, &full, budget, None) {
                Some((s, c)) => (s, c),
                None => (full, 0.0),
            };
        // What a pull adds beyond the leader's energy is drained; what it takes is returned (the
        // tank never exceeds the users' positive work less what pulls added net).
        let e_new = stored(&new);
        let beyond_leader = e_new - e_copy.max(e_leader);
        let taken = (e_copy - e_new).max(0.0);
        *tank = (*tank - beyond_leader.max(0.0) + taken).max(0.0);
        // Nor into another object here.
        let (new, clipped_j) =
            match super::tank::bound_pairs(world, world_copy, k, &copy.state, &new) {
                Some((s, c)) => (s, clipped_j + c),
                None => (new, clipped_j),
            };
        let e = |s: &BodyState| s.mechanical_energy(&body.mass, world.gravity);
        let adoption = Adoption {
            jump: copy.state.pos - new.pos,
            energy_j: e(&new) - e(&copy.state),
            work_j: 0.0,
            age_s: now_s - r.t_s,
            clipped_j,
        };
        copy.energy.adoption_j += adoption.energy_j;
        let turn = new.rot * copy.state.rot.inverse();
        copy.env.shift(new.pos - copy.state.pos, turn);
        for c in &mut self.contacts[k] {
            c.turn(turn);
        }
        copy.state = new;
        world_copy.objects_mut()[k] = copy;
        world_copy.corrected(k);
        Some(adoption)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyState;
    use crate::method::timewarp::track;
    use crate::scenario::Scenario;

    /// The leader's state reported resting on the table but leaving it fast (a disk its user's tool
    /// flicked up at 0.87 m/s), half a second old: the pull may bring this copy (2 cm above the
    /// table, at rest) up to the energy the leader sent and no further. Before, the target was
    /// reckoned unslowed 0.44 m up, its energy the pull's budget: the copy was lifted to 186 mJ,
    /// 135 mJ beyond the 51 mJ sent.
    #[test]
    fn a_pull_takes_no_more_energy_than_the_leader_sent() {
        let (w, sent) = crate::world::fixtures::on_a_table(Vec3::new(0.0, 0.87, 0.0));
        let sc = Scenario::default();
        let mut radii = [0.0; MAX_SITES];
        radii[..2].fill(0.005);
        let mut c = Coupled::new(0, 2, 1e-3, sc.contact, radii, 600);
        let mut copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.06, 0.0)));
        let r = Report::Coupled(CoupledReport {
            tools: ToolReport::NONE,
            object: 0,
            t_s: 1.0,
            state: sent,
            accel: crate::world::supported_gravity(&w, &w.bodies[0].shape, &sent),
            touch_since_s: 0.9,
            last_touch_s: 0.9,
        });
        let e = |s: &BodyState| crate::method::tank::stored_energy(&w, 0, s);
        let before = e(&copy.first().state);
        assert!(c.receive(&w, &mut copy, 1, &r, 1.5).is_some(), "pulled");
        let mut on_surface = sent;
        crate::world::push_out_of_environment(&w, &w.bodies[0].shape, &mut on_surface);
        assert!(e(&on_surface) > before, "the leader's state holds more");
        assert!(
            e(&copy.first().state)
                <= e(&on_surface) + crate::method::reckon::DEAD_RECKONING_SLACK_J,
            "{} J after the pull, {} J sent",
            e(&copy.first().state),
            e(&on_surface)
        );
        assert!(e(&copy.first().state) > before, "pulled up towards it");
    }

    /// A track carries the ticks since the last report and the last report's again (at no loss),
    /// and as many reports' again as the loss its receivers say needs (0.3: seven); the site
    /// measures the share of a partner's tracks it loses and says it in its own (every third
    /// lost: a third).
    #[test]
    fn a_track_carries_what_the_loss_its_receivers_measure_needs() {
        let sc = Scenario::default();
        let world = sc.world();
        let mut copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
        let mut radii = [0.0; MAX_SITES];
        radii[..2].fill(0.005);
        let mut c = Coupled::new(0, 2, 1e-3, sc.contact, radii, 600);
        let mut windows = Vec::new();
        let mut seq = 0;
        for t in 1..=2000_i64 {
            c.own_tool(Vec3::new(-0.2, 1e-5 * t as f64, 0.01));
            c.physics_step(&world, &mut copy, &[ContactForce::default()], 1e-3);
            if t % 10 != 0 {
                continue;
            }
            let mut out = None;
            c.report(&copy, &[], t as f64 * 1e-3, &mut |r| out = Some(r));
            let Some(Report::Coupled(r)) = out else {
                panic!("a coupled report at tick {t}");
            };
            windows.push((t, r.tools.first_tick, r.tools.count, r.tools.loss[1]));
            // Site 1's track: numbered, every third lost; from tick 1000 on it says it loses
            // 0.3 of this site's tracks.
            seq += 1;
            if seq % 3 != 0 {
                let Report::Tools(mut tr) = track(t - 10, t - 1, |_| [0, 0, 1000]) else {
                    unreachable!()
                };
                tr.seq = seq;
                tr.loss[0] = if t >= 1000 { 77 } else { 0 };
                c.receive(&world, &mut copy, 1, &Report::Tools(tr), t as f64 * 1e-3);
            }
        }
        // Each window ends with the last tick stepped (ticks 0 to t - 1 by the t-th report).
        for &(t, first, count, _) in &windows {
            assert_eq!(first + count as i64, t, "at tick {t}");
        }
        let at = |t: i64| {
            windows
                .iter()
                .find(|w| w.0 == t)
                .copied()
                .expect("a report")
        };
        // No loss said: this report's 10 ticks and the last one's.
        assert_eq!(at(900).2, 20);
        // 0.3 said: the last 7 reports' again besides.
        assert_eq!(at(1500).2, 80);
        let said = f64::from(at(2000).3) / 255.0;
        assert!((said - 1.0 / 3.0).abs() < 0.05, "{said}");
        // Site 1 fell silent for 1000 of its tracks and is back: those are not a loss rate.
        c.peer_lost(1, 2.0);
        let Report::Tools(mut tr) = track(2000, 2009, |_| [0, 0, 1000]) else {
            unreachable!()
        };
        tr.seq = seq + 1000;
        c.receive(&world, &mut copy, 1, &Report::Tools(tr), 2.0);
        let mut out = None;
        c.report(&copy, &[], 2.0, &mut |r| out = Some(r));
        let Some(Report::Coupled(r)) = out else {
            panic!("a coupled report");
        };
        assert_eq!(r.tools.loss[1], 0);
    }

    /// Site 0 of two, 1 kHz, playing at most 600 ticks late, receives site 1's tool (far from the
    /// disk, moving 1 quantum per tick along x) in 50-tick reports sent 300 ticks late, then 20
    /// (the first of those overtaking the last of these), then later and later again, up to 300
    /// over 4 s (the paper's swing rises at up to 0.25 s/s; this at 0.07): the playout starts at
    /// 600, shrinks to the first arrival measured (350 ticks: the delay and the report period),
    /// then to the second's (70), grows with the third back to 350, and the tool is never held;
    /// every played position lies on the tool's path, in order, and over any four ticks it moves
    /// at most 5/4 of the tool's own way (one quantum for the rounding).
    #[test]
    fn the_playout_follows_the_arrivals_measured() {
        let mut sc = Scenario::default();
        sc.objects[0].start_m = [0.0, 0.0, 0.01];
        let world = sc.world();
        let mut copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
        let mut radii = [0.0; MAX_SITES];
        radii[..2].fill(0.005);
        let mut c = Coupled::new(0, 2, 1e-3, sc.contact, radii, 600);
        let far = |t: i64| [10_000 + t as i32, 20_000, 1_000];
        let margin = (PLAYOUT_MARGIN_S / 1e-3).ceil();
        // The report sent at tick s (ticks s-50..s) arrives at s + its delay.
        let delay = |s: i64| match s {
            ..4000 => 300,
            4000..8000 => 20,
            _ => 20 + (s - 8000).min(4000) * 7 / 100,
        };
        let mut xs = Vec::new();
        let mut playout_at = std::collections::BTreeMap::new();
        for t in 0..12_400_i64 {
            for sent in (50..=t).step_by(50).filter(|&s| s + delay(s) == t) {
                let r = track(sent - 50, sent - 1, far);
                assert!(c
                    .receive(&world, &mut copy, 1, &r, t as f64 * 1e-3)
                    .is_none());
            }
            c.own_tool(Vec3::new(-0.2, 0.0, 0.01));
            c.physics_step(&world, &mut copy, &[ContactForce::default()], 1e-3);
            if t == 0 {
                assert_eq!(c.site_playout_ticks(1), 600.0, "nothing measured yet");
            }
            if [4000, 8000, 12_399].contains(&t) {
                playout_at.insert(t, c.site_playout_ticks(1));
            }
            if c.played[1] != UNKNOWN {
                assert_eq!(c.played[1][1..], [20_000, 1_000], "on the path");
                xs.push(c.played[1][0]);
            }
        }
        // At least the latest arrival (it decays a little between reports), at most that plus
        // the largest change between two arrivals and two margins (the target's, the hysteresis).
        for (t, arrival, change) in [(4000, 350.0, 0.0), (8000, 70.0, 0.0), (12_399, 350.0, 4.0)] {
            let p = playout_at[&t];
            assert!(
                (arrival - 7.0..=arrival + change + 2.0 * margin).contains(&p),
                "{p} ticks late at tick {t} (arrival {arrival})"
            );
        }
        assert_eq!(c.held_ticks(1), 0, "a position missed its playout");
        assert!(xs.windows(2).all(|w| w[1] >= w[0]), "never backwards");
        let most = xs.windows(5).map(|w| w[4] - w[0]).max();
        assert!(most <= Some(6), "{most:?} quanta in four ticks");
        assert!(c.max_playout_ticks() == 600);
    }
}
