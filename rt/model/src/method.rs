//! Consistency methods: how each site's copy of the object is kept in step with the others'.
//!
//! A method is a [`Consistency`]: it integrates the site's copy on each physics tick, says what the site
//! reports to the others, and handles their reports. Two are implemented; coupling between copies,
//! local lag or rollback plug in the same way.
//!
//! - [`Naive`] — Eq. 8 across the network: every site integrates its own copy with its own user's
//!   force plus the *latest received* forces of the others, and only forces are exchanged. With delay
//!   and different rates the copies see different force histories and diverge (the paper's first
//!   experiment).
//! - [`Paper`] — Eq. 10/11: a site integrates its copy with its **own** user's force only (and the
//!   environment), reports its state with the time of that state, and **adopts** any received state
//!   newer than the newest it has adopted, dead-reckoned from the state's time to now.
//!
//! **Dead reckoning** ([`dead_reckon`]), order selectable: 0 adopts the state as it was; 1 extrapolates
//! with constant velocity; 2 also with gravity less what the environment supports
//! ([`supported_gravity`]; not the sender's user's transient push, which the receiver cannot predict),
//! and with kinetic friction slowing a slide on a supporting plane until it stops. "Gravity-aware": a state in
//! free flight falls along the parabola, and a state resting on the floor, whose support cancels
//! gravity, stays put. An extrapolated state is never left inside the environment: it is moved out of
//! any plane it penetrates and its velocity into the plane removed.

use crate::body::{self, BodyState, MassProps, Vec3, Wrench};
use crate::contact::{
    environment_wrench, ContactForce, ContactParams, EnvContactState, Plane, MAX_PLANES,
};
use crate::shape::Shape;
use nalgebra::UnitQuaternion;

/// Most sites a session may have.
pub const MAX_SITES: usize = 8;

/// The static world every site shares: the object's shape and mass, gravity, environment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct World {
    /// Object shape.
    pub shape: Shape,
    /// Object mass properties.
    pub mass: MassProps,
    /// Gravity, m/s².
    pub gravity: Vec3,
    /// Environment planes (first `plane_count` are used).
    pub planes: [Plane; MAX_PLANES],
    /// How many planes.
    pub plane_count: usize,
    /// Object–environment contact law.
    pub env_contact: ContactParams,
}

impl World {
    /// The planes in use.
    pub fn planes(&self) -> &[Plane] {
        &self.planes[..self.plane_count.min(MAX_PLANES)]
    }
}

/// Where a site's copy got its energy (passivity check).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnergyAccount {
    /// Work of the own user's contact force, J.
    pub own_j: f64,
    /// Work of other users' (received) forces, J (naive only).
    pub remote_j: f64,
    /// Work of the environment, J.
    pub env_j: f64,
    /// Mechanical-energy change caused by adoptions, J.
    pub adoption_j: f64,
    /// The users' work on this copy counted only where positive, step by step (own and remote), J:
    /// what the users can have given it at most (the bound of [`crate::tank`]'s checks).
    pub users_positive_j: f64,
    /// The work of the forces [`integrate`] counts as own, only where positive, step by step, J
    /// (`naive`, `paper`: the own user's, what it has given this copy, which a `naive` report
    /// carries; `timewarp`: every user's, all computed here).
    pub own_positive_j: f64,
    /// Work received forces would have done on this copy beyond what their users had given their
    /// own copies, denied by `naive`'s no-gain bound, J.
    pub remote_denied_j: f64,
}

/// One site's copy of the object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectCopy {
    /// The state this site believes.
    pub state: BodyState,
    /// Its time, s.
    pub time_s: f64,
    /// Environment friction memory.
    pub env: EnvContactState,
    /// Energy bookkeeping.
    pub energy: EnergyAccount,
    /// Whether the object touched the environment at the last step.
    pub env_touching: bool,
    /// Gravity less the environment's support at the last step (what a report carries), m/s².
    pub passive_accel: Vec3,
    /// Per site: the time up to which that site's user's impulses are included in this state (the
    /// paper's "time of the state change", one per contributor), s; negative: none yet.
    pub included: [f64; MAX_SITES],
}

impl ObjectCopy {
    /// A copy at `state`, time 0.
    pub fn new(state: BodyState) -> Self {
        Self {
            state,
            time_s: 0.0,
            env: EnvContactState::default(),
            energy: EnergyAccount::default(),
            env_touching: false,
            passive_accel: Vec3::zeros(),
            included: [-1.0; MAX_SITES],
        }
    }
}

/// What sites send each other.
#[derive(Debug, Clone, Copy, PartialEq)]
// NB: a report moves by value on the real-time path, where nothing allocates: a timewarp
// report's 3 KB are copied at the report rate instead of boxed.
#[allow(clippy::large_enum_variant)]
pub enum Report {
    /// `paper`: a state, the time it holds at, up to when each site's user's impulses are included
    /// in it, and the acceleration a receiver should extrapolate it with.
    State {
        /// Time of the state, s (sender's clock).
        t_s: f64,
        /// The state.
        state: BodyState,
        /// Gravity less the environment's support, m/s².
        accel: Vec3,
        /// Per site, the time up to which its user's impulses are included, s.
        included: [f64; MAX_SITES],
    },
    /// `naive`: the sender's own contact force and where it acts.
    Force {
        /// Time, s.
        t_s: f64,
        /// The contact.
        force: ContactForce,
        /// The sender's user's positive work on the sender's copy so far, J
        /// ([`EnergyAccount::own_positive_j`]): at most what this force may do on a receiver's.
        given_j: f64,
    },
    /// `timewarp`: the sender's tool positions on the tick grid, and its confirmed frontier.
    Tools(crate::timewarp::ToolReport),
    /// `coupled`: the sender's tool positions, its copy, and when its user's contact began.
    Coupled(crate::coupled::CoupledReport),
}

/// A received state replaced the local one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Adoption {
    /// Position before minus after, m.
    pub jump: Vec3,
    /// Mechanical energy after minus before, J.
    pub energy_j: f64,
    /// The work the forces (users' and environment's) did in the corrected history minus what
    /// they did in the one it replaced, J: the part of `energy_j` some force accounts for (a
    /// remote push learned late). 0 where the method does not re-simulate (an adopted state or a
    /// pull): its whole energy change is the correction's own.
    pub work_j: f64,
    /// How far the state was extrapolated, s.
    pub age_s: f64,
    /// Energy the no-gain bound ([`crate::tank::bound_gain`]) took out of the correction, J (0: it
    /// fitted).
    pub clipped_j: f64,
}

/// A consistency method (see the module docs).
pub trait Consistency: std::fmt::Debug + Send {
    /// Its name, as in scenario files.
    fn name(&self) -> &'static str;
    /// Integrates `copy` by `dt` with the own user's (held) contact `own`.
    fn physics_step(&mut self, world: &World, copy: &mut ObjectCopy, own: &ContactForce, dt: f64);
    /// The report this site sends now.
    fn report(&self, copy: &ObjectCopy, own: &ContactForce, now_s: f64) -> Report;
    /// Handles a report from site `from`; `Some` when the local copy jumped to a received state.
    fn receive(
        &mut self,
        world: &World,
        copy: &mut ObjectCopy,
        from: usize,
        msg: &Report,
        now_s: f64,
    ) -> Option<Adoption>;
    /// Sum of the other sites' forces this method applies to the local copy (for traces), N.
    fn remote_force(&self) -> Vec3 {
        Vec3::zeros()
    }
    /// Site `from` went silent at `now_s` (it is lost): whatever this method still applies of it
    /// must fade out rather than freeze at its last value. Hearing from it again ends that.
    fn peer_lost(&mut self, from: usize, now_s: f64) {
        let _ = (from, now_s);
    }
    /// The own tool is at `tool_pos` (world, m) at the tick about to be stepped: methods that
    /// compute every tool's contact themselves (`timewarp`) take it here.
    fn own_tool(&mut self, tool_pos: Vec3) {
        let _ = tool_pos;
    }
    /// Rollback figures, for a method that rolls back.
    fn timewarp_stats(&self) -> Option<crate::timewarp::Stats> {
        None
    }
    /// For a method that plays the other sites' tools from a jitter buffer (`coupled`): how late
    /// they are played now, ticks, the largest over them.
    fn playout_ticks(&self) -> Option<f64> {
        None
    }
    /// For a method that steps on the session's tick grid (`timewarp`, `coupled`): the copy it
    /// is stepped with is the state at the start of tick `tick`, not tick 0, and nothing
    /// before it was simulated here (a restarted or late physics process joins the grid where it
    /// is now instead of re-simulating the session from its start). Called before the first step.
    fn start_at_tick(&mut self, tick: i64) {
        let _ = tick;
    }
    /// The object state the own user is shown (the servo renders against it): the copy's,
    /// unless the method replays a contact the user missed (`timewarp`: see [`crate::timewarp`]).
    fn shown(&self, copy: &ObjectCopy) -> crate::body::BodyState {
        copy.state
    }
}

/// How long a lost site's influence takes to fade to nothing, s.
pub const LOST_FADE_S: f64 = 0.1;

/// Integrates a copy by `dt` under `users` (contacts held over the step) and the environment, keeping
/// the energy account. `own_count` of the users are the site's own (the rest are remote). Returns the
/// own users' impulse over the step (linear in `force`, angular in `torque`).
pub fn integrate(
    world: &World,
    copy: &mut ObjectCopy,
    users: &[ContactForce],
    own_count: usize,
    dt: f64,
) -> Wrench {
    let before = copy.state;
    let mut env_state = copy.env;
    // Wrenches at the start and end of the step, per source, for the work estimate.
    let mut seen = [[Wrench::default(); 3]; 2];
    let mut calls = 0usize;
    let mut touching = false;
    let next = body::step(&copy.state, &world.mass, world.gravity, dt, |s| {
        let (env, touch) = environment_wrench(
            &world.env_contact,
            &mut env_state,
            world.planes(),
            &world.shape,
            s,
            &world.mass,
        );
        touching = touch;
        let mut own = Wrench::default();
        let mut remote = Wrench::default();
        for (i, u) in users.iter().enumerate() {
            if i < own_count {
                own = own + u.wrench(s.pos);
            } else {
                remote = remote + u.wrench(s.pos);
            }
        }
        seen[calls.min(1)] = [own, remote, env];
        calls += 1;
        own + remote + env
    });
    let omega_mid = (before.omega(&world.mass) + next.omega(&world.mass)) * 0.5;
    let dx = next.pos - before.pos;
    let work = |k: usize| {
        let (a, b) = (seen[0][k], seen[1][k]);
        (a.force + b.force).dot(&dx) * 0.5 + (a.torque + b.torque).dot(&omega_mid) * 0.5 * dt
    };
    let (w_own, w_remote) = (work(0), work(1));
    copy.energy.own_j += w_own;
    copy.energy.remote_j += w_remote;
    copy.energy.users_positive_j += w_own.max(0.0) + w_remote.max(0.0);
    copy.energy.own_positive_j += w_own.max(0.0);
    copy.energy.env_j += work(2);
    copy.passive_accel = supported_gravity(world, &next);
    copy.env_touching = touching;
    copy.env = env_state;
    copy.state = next;
    copy.time_s += dt;
    // The own users' impulse over the step (trapezoid of the two evaluations).
    Wrench {
        force: (seen[0][0].force + seen[1][0].force) * (0.5 * dt),
        torque: (seen[0][0].torque + seen[1][0].torque) * (0.5 * dt),
    }
}

/// Extrapolates `s` by `dt` seconds (see the module docs for the orders).
pub fn dead_reckon(world: &World, s: &BodyState, accel: Vec3, dt: f64, order: u8) -> BodyState {
    if order == 0 || dt <= 0.0 {
        return *s;
    }
    let omega = s.omega(&world.mass);
    let mut out = BodyState {
        pos: s.pos + s.vel * dt,
        rot: UnitQuaternion::from_scaled_axis(omega * dt) * s.rot,
        ..*s
    };
    if order >= 2 {
        out.pos += accel * (0.5 * dt * dt);
        out.vel += accel * dt;
        slide_with_friction(world, s, accel, dt, &mut out);
    }
    push_out_of_environment(world, &mut out);
    out
}

/// [`dead_reckon`] of a passive object, as every method that adopts or follows a sent state must
/// reckon it: the reckoned state holds no more energy than the state sent, as the reckoner puts it
/// on the environment's surface, up to [`DEAD_RECKONING_SLACK_J`]. A state reported resting on a
/// table but leaving it fast (a disk a tool flicked up) is reckoned with the support's zero
/// acceleration: unbounded, it flies on unslowed by gravity (0.44 m up after 0.5 s at 0.87 m/s).
pub fn dead_reckon_passive(
    world: &World,
    s: &BodyState,
    accel: Vec3,
    dt: f64,
    order: u8,
) -> BodyState {
    let new = dead_reckon(world, s, accel, dt, order);
    let mut sent = *s;
    push_out_of_environment(world, &mut sent);
    crate::tank::bound_gain(world, &sent, &new, DEAD_RECKONING_SLACK_J, None)
        .map_or(new, |(bounded, _)| bounded)
}

/// Order 2 on a supporting plane: the tangential velocity decays under kinetic friction
/// (μ_k times the supported part of gravity) and stops, rather than sliding on for ever.
fn slide_with_friction(world: &World, s: &BodyState, accel: Vec3, dt: f64, out: &mut BodyState) {
    for plane in world.planes() {
        let n = plane.normal;
        let support = -(world.gravity.dot(&n));
        if support <= 0.0 || plane_depth(world, plane, s) <= -1e-4 {
            continue;
        }
        let v_t = s.vel - n * s.vel.dot(&n);
        let speed = v_t.norm();
        let decel = world.env_contact.friction_kinetic * support;
        if speed < 1e-12 || decel <= 0.0 {
            continue;
        }
        let dir = v_t / speed;
        let t = dt.min(speed / decel);
        let along = speed * t - 0.5 * decel * t * t;
        // Replace the frictionless tangential advance with the decelerating one.
        let a_t = accel - n * accel.dot(&n);
        out.pos += dir * along - v_t * dt - a_t * (0.5 * dt * dt);
        out.vel += dir * (speed - decel * t) - v_t - a_t * dt;
    }
}

/// Deepest penetration of `s` into `plane` (negative when clear of it).
pub(crate) fn plane_depth(world: &World, plane: &Plane, s: &BodyState) -> f64 {
    let n = plane.normal;
    match world.shape {
        Shape::Sphere { radius } => plane.offset - n.dot(&(s.pos - n * radius)),
        _ => {
            let mut probes = [Vec3::zeros(); 16];
            let count = world.shape.probe_points(&mut probes);
            // The plane normal in body coordinates: one rotation instead of one per probe point.
            let n_body = s.rot.inverse() * n;
            let centre = plane.offset - n.dot(&s.pos);
            probes[..count]
                .iter()
                .map(|p| centre - n_body.dot(p))
                .fold(f64::NEG_INFINITY, f64::max)
        }
    }
}

/// The energy a dead-reckoned state may hold beyond the state it was reckoned from, J: rounding
/// only (a ballistic flight keeps its energy, but not to the bit).
pub const DEAD_RECKONING_SLACK_J: f64 = 1e-9;

/// Gravity less what the environment planes the object rests on support: what a dead reckoner should
/// extrapolate with. Zero for a disk on a table, g in free flight, the slope component on an incline.
/// (The environment's *instantaneous* force is not used: on a stiff contact it oscillates around the
/// support, and extrapolating a spring's peak over tens of milliseconds kicks the receiver's copy.)
pub fn supported_gravity(world: &World, s: &BodyState) -> Vec3 {
    let mut a = world.gravity;
    for plane in world.planes() {
        if plane_depth(world, plane, s) > -1e-4 {
            let into = a.dot(&plane.normal);
            if into < 0.0 {
                a -= plane.normal * into;
            }
        }
    }
    a
}

/// Moves `s` out of any plane it penetrates and removes its velocity into that plane.
pub(crate) fn push_out_of_environment(world: &World, s: &mut BodyState) {
    for plane in world.planes() {
        let depth = plane_depth(world, plane, s);
        if depth > 0.0 {
            let n = plane.normal;
            s.pos += n * depth;
            let into = s.vel.dot(&n);
            if into < 0.0 {
                s.vel -= n * into;
            }
        }
    }
}

/// Eq. 8 across the network: own force plus the latest received forces; forces are exchanged.
///
/// No gain: a received force is another user's push on *their* copy, and it may do on this one at
/// most the positive work that user has done on theirs. Each report carries that work up to its
/// time (`given_j`); this copy counts how much positive work each site's forces have done here,
/// and once it is more than the newest report's (beyond [`NAIVE_SLACK_J`] and
/// [`NAIVE_SLACK_FRACTION`] of it: the copies differ, so do the works), that site's force may do
/// no more positive work until its user gives more (what it was denied is counted in
/// [`EnergyAccount::remote_denied_j`]). So a copy gains at most what the users gave, as far as this
/// site knows, plus the slack. Without it a user holding their copy still (a squeeze, a lift: no
/// work there) pushes a copy that has left their grasp for as long as they hold: on `lift.toml`'s
/// open table a real station's naive copy flew 613 m (481 J). Nor may a force spend ahead of what
/// its user gave while the report that would show it is on the way: with three users 120° apart
/// at 500 ms (`three-lift-balanced.toml`, seed 1) a user pressing a disk that had left the other
/// copies' grasp pushed them at 0.8 N for a delay, to 4 m/s, and the table's penalty spring then
/// threw one 44 m up. Forces that take energy (resist the motion) always apply.
#[derive(Debug, Clone)]
pub struct Naive {
    remote: [Option<(f64, ContactForce)>; MAX_SITES],
    /// Per site: when it was lost (its force fades out over [`LOST_FADE_S`] from then).
    lost_at: [Option<f64>; MAX_SITES],
    /// Per site: the positive work its forces have done on this copy, J.
    spent_j: [f64; MAX_SITES],
    /// Per site: the most positive work its forces may do here, as its newest report allows, J.
    allowed_j: [f64; MAX_SITES],
}

/// How much more work a received force may have done here than its user gave there, J...
pub const NAIVE_SLACK_J: f64 = 1e-3;
/// ...plus this fraction of what was given.
pub const NAIVE_SLACK_FRACTION: f64 = 0.1;

impl Default for Naive {
    fn default() -> Self {
        Self {
            remote: [None; MAX_SITES],
            lost_at: [None; MAX_SITES],
            spent_j: [0.0; MAX_SITES],
            allowed_j: [NAIVE_SLACK_J; MAX_SITES],
        }
    }
}

impl Consistency for Naive {
    fn remote_force(&self) -> Vec3 {
        self.remote.iter().flatten().map(|(_, f)| f.force).sum()
    }
    fn name(&self) -> &'static str {
        "naive"
    }
    fn physics_step(&mut self, world: &World, copy: &mut ObjectCopy, own: &ContactForce, dt: f64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let mut users = [ContactForce::default(); MAX_SITES + 1];
        // Per received force: its site and its torque about the centre of mass at the step's start.
        let mut sites = [(0usize, Vec3::zeros()); MAX_SITES + 1];
        users[0] = *own;
        let mut n = 1;
        let before = copy.state;
        let omega = before.omega(&world.mass);
        for (k, slot) in self.remote.iter_mut().enumerate() {
            let Some((_, f)) = slot else { continue };
            let mut f = *f;
            if let Some(at) = self.lost_at[k] {
                let left = 1.0 - (copy.time_s - at) / LOST_FADE_S;
                if left <= 0.0 {
                    *slot = None;
                    self.lost_at[k] = None;
                    continue;
                }
                f.force *= left.min(1.0);
            }
            // The no-gain bound (see the type's docs): a site's force that has done here what
            // its user gave does no more positive work.
            let torque = f.wrench(before.pos).torque;
            let power = f.force.dot(&before.vel) + torque.dot(&omega);
            if self.spent_j[k] > self.allowed_j[k] && power > 0.0 {
                copy.energy.remote_denied_j += power * dt;
                continue;
            }
            users[n] = f;
            sites[n] = (k, torque);
            n += 1;
        }
        integrate(world, copy, &users[..n], 1, dt);
        // What each received force did (the step's mean motion, as `integrate` counts work).
        let dx = copy.state.pos - before.pos;
        let omega_mid = (omega + copy.state.omega(&world.mass)) * 0.5;
        for (f, &(k, torque)) in users[1..n].iter().zip(&sites[1..n]) {
            let w = f.force.dot(&dx) + torque.dot(&omega_mid) * dt;
            self.spent_j[k] += w.max(0.0);
        }
    }
    fn peer_lost(&mut self, from: usize, now_s: f64) {
        if let Some(at) = self.lost_at.get_mut(from) {
            if self.remote[from].is_some() {
                at.get_or_insert(now_s);
            }
        }
    }
    fn report(&self, copy: &ObjectCopy, own: &ContactForce, now_s: f64) -> Report {
        Report::Force {
            t_s: now_s,
            force: *own,
            given_j: copy.energy.own_positive_j,
        }
    }
    fn receive(
        &mut self,
        _w: &World,
        _c: &mut ObjectCopy,
        from: usize,
        msg: &Report,
        _now: f64,
    ) -> Option<Adoption> {
        if let (
            Report::Force {
                t_s,
                force,
                given_j,
            },
            Some(slot),
        ) = (msg, self.remote.get_mut(from))
        {
            if slot.is_none_or(|(t, _)| *t_s > t) {
                *slot = Some((*t_s, *force));
                // Heard again; a NaN gives nothing.
                self.lost_at[from] = None;
                let given = if given_j.is_finite() { *given_j } else { 0.0 };
                self.allowed_j[from] = given * (1.0 + NAIVE_SLACK_FRACTION) + NAIVE_SLACK_J;
            }
        }
        None
    }
}

/// One own step's impulse: (end of the step, middle of the step, linear impulse, angular impulse,
/// the own user's work in the step), s, s, N·s, N·m·s, J.
type LoggedImpulse = (f64, f64, Vec3, Vec3, f64);

/// Own impulses a site remembers for replay: 8 s at 1 kHz.
const LOG_CAP: usize = 8192;

/// Eq. 9–11: each site integrates its copy with its **own** user's force only, and the newest state
/// travels between the sites; "the force of each user only updates the newest state"
/// (superposition at the acceleration level).
///
/// Every report carries, per site, the time up to which that site's user's impulses are included in
/// the state: the paper's "time of the state change", one per contributor. A site adopts a received
/// state when it includes newer contributions of the others and none older; it dead-reckons it to now
/// and **replays its own user's impulses the sender had not yet seen** (each impulse moves the object
/// by Δv·(now − t) and changes its momentum by Δp). So a site never takes back its own user's push,
/// and during a simultaneous grasp each copy carries both users' forces, each from its own site. With
/// zero delay this is the reference run's sum of forces (for free motion exactly).
///
/// When nothing new is known the sites follow the copy of the site whose user touched last (it
/// includes the newest impulse): its later snapshots are adopted, so a released object slides to
/// rest identically everywhere.
///
/// Along the normal of an environment plane the local copy rests on, the local position and velocity
/// are kept: the contact equilibrium there is local physics, and transplanting another copy's
/// micro-bounce would pump energy into every adoption. The environment's friction stick points move
/// with the adopted object.
#[derive(Debug, Clone)]
pub struct Paper {
    /// Dead-reckoning order (0, 1, 2).
    pub order: u8,
    me: usize,
    newest_from: [f64; MAX_SITES],
    /// Own impulses: (end of the step, middle of the step, linear impulse, angular impulse, the
    /// own user's work in the step on the local copy), a ring.
    log: Box<[LoggedImpulse]>,
    log_next: usize,
    log_len: usize,
    /// The own tool as a spring, for the no-gain bound (position from [`Consistency::own_tool`]).
    tool: Option<crate::tank::ToolSpring>,
    /// The own user's positive work on the local copy not yet spent by replays, J: each joule the
    /// user put in is granted to replays once ([`crate::tank`]).
    tank_j: f64,
}

impl Paper {
    /// For site `me`, with dead-reckoning `order`.
    pub fn new(order: u8, me: usize) -> Self {
        Self {
            order,
            me,
            newest_from: [f64::NEG_INFINITY; MAX_SITES],
            log: vec![(0.0, 0.0, Vec3::zeros(), Vec3::zeros(), 0.0); LOG_CAP].into_boxed_slice(),
            log_next: 0,
            log_len: 0,
            tool: None,
            tank_j: 0.0,
        }
    }

    /// With the own tool's radius and contact stiffness known: the no-gain bound then counts the
    /// tool's spring ([`crate::tank::ToolSpring`]) once the tool's position is given.
    pub fn with_tool(mut self, radius_m: f64, stiffness_n_per_m: f64) -> Self {
        self.tool = Some(crate::tank::ToolSpring {
            pos: Vec3::repeat(f64::INFINITY),
            radius_m,
            stiffness_n_per_m,
        });
        self
    }

    /// The site whose user's impulse is the newest in `included` (ties: the lowest index).
    fn author(included: &[f64; MAX_SITES]) -> usize {
        (0..MAX_SITES).fold(0, |best, k| {
            if included[k] > included[best] {
                k
            } else {
                best
            }
        })
    }
}

impl Consistency for Paper {
    fn name(&self) -> &'static str {
        "paper"
    }
    fn own_tool(&mut self, tool_pos: Vec3) {
        if let Some(t) = &mut self.tool {
            t.pos = tool_pos;
        }
    }
    fn physics_step(&mut self, world: &World, copy: &mut ObjectCopy, own: &ContactForce, dt: f64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let work_before = copy.energy.own_j;
        let impulse = integrate(world, copy, std::slice::from_ref(own), 1, dt);
        self.tank_j += (copy.energy.own_j - work_before).max(0.0);
        if own.touching {
            self.log[self.log_next] = (
                copy.time_s,
                copy.time_s - 0.5 * dt,
                impulse.force,
                impulse.torque,
                copy.energy.own_j - work_before,
            );
            self.log_next = (self.log_next + 1) % LOG_CAP;
            self.log_len = (self.log_len + 1).min(LOG_CAP);
            if let Some(mine) = copy.included.get_mut(self.me) {
                *mine = copy.time_s;
            }
        }
    }
    fn report(&self, copy: &ObjectCopy, _own: &ContactForce, now_s: f64) -> Report {
        Report::State {
            t_s: now_s,
            state: copy.state,
            accel: copy.passive_accel,
            included: copy.included,
        }
    }
    fn receive(
        &mut self,
        world: &World,
        copy: &mut ObjectCopy,
        from: usize,
        msg: &Report,
        now_s: f64,
    ) -> Option<Adoption> {
        let Report::State {
            t_s,
            state,
            accel,
            included,
        } = *msg
        else {
            return None;
        };
        let newest = self.newest_from.get_mut(from)?;
        if t_s <= *newest || !state.is_finite() || included.iter().any(|v| !v.is_finite()) {
            return None; // a replay, an older snapshot, or garbage
        }
        *newest = t_s;
        let others = (0..MAX_SITES).filter(|&k| k != self.me);
        let gains = others.clone().any(|k| included[k] > copy.included[k]);
        let loses = others.clone().any(|k| included[k] < copy.included[k]);
        let same = others.clone().all(|k| included[k] == copy.included[k]);
        let follows_author = same && from == Self::author(&copy.included) && from != self.me;
        if !((gains && !loses) || follows_author) {
            return None;
        }
        // Dead reckoning predicts a passive object: unbounded, on `three-users.toml` at 500 ms a
        // disk a user's tool had flicked up at 0.87 m/s was adopted 0.45 m up, 129 mJ beyond every
        // user's work.
        let mut new = dead_reckon_passive(world, &state, accel, now_s - t_s, self.order);
        let given = new;
        // Replay our own impulses the sender had not seen.
        let seen_until = included.get(self.me).copied().unwrap_or(f64::NEG_INFINITY);
        let inv_i = new.inv_inertia_world(&world.mass);
        let mut own_work_j = 0.0;
        for k in 0..self.log_len {
            let (t_end, t_mid, dp, dl, w) = self.log[(self.log_next + LOG_CAP - 1 - k) % LOG_CAP];
            if t_end <= seen_until {
                break;
            }
            own_work_j += w;
            // The impulse acted over its step: it has moved the object for (now − step middle).
            let age = (now_s - t_mid).max(0.0);
            let dv = dp / world.mass.mass_kg;
            new.vel += dv;
            new.pos += dv * age;
            new.ang_mom += dl;
            new.rot = UnitQuaternion::from_scaled_axis(inv_i * dl * age) * new.rot;
        }
        let mut base = given;
        for plane in world.planes() {
            if plane_depth(world, plane, &copy.state) > -1e-4 {
                let n = plane.normal;
                for s in [&mut new, &mut base] {
                    s.pos += n * (copy.state.pos - s.pos).dot(&n);
                    s.vel += n * (copy.state.vel - s.vel).dot(&n);
                }
            }
        }
        // Never more energy than the sender's copy or this one had, plus the replayed work.
        let (new, clipped_j, spent_j) = crate::tank::bound_adoption(
            world,
            &crate::tank::Adopted {
                local: copy.state,
                given,
                base,
                full: new,
                tool: self.tool.filter(|t| t.pos.iter().all(|v| v.is_finite())),
            },
            own_work_j.min(self.tank_j),
        );
        self.tank_j = (self.tank_j - spent_j).max(0.0);
        let e = |s: &BodyState| s.mechanical_energy(&world.mass, world.gravity);
        let adoption = Adoption {
            jump: copy.state.pos - new.pos,
            energy_j: e(&new) - e(&copy.state),
            work_j: 0.0,
            age_s: now_s - t_s,
            clipped_j,
        };
        copy.energy.adoption_j += adoption.energy_j;
        copy.env.shift(new.pos - copy.state.pos);
        copy.state = new;
        let mine = copy.included.get(self.me).copied().unwrap_or(-1.0);
        copy.included = included;
        if let Some(m) = copy.included.get_mut(self.me) {
            *m = m.max(mine);
        }
        Some(adoption)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn a_lost_sites_force_fades_out_instead_of_freezing() {
        let w = world();
        let mut naive = Naive::default();
        let mut copy = ObjectCopy::new(BodyState::at_rest(Vec3::new(0.0, 0.0, 1.0)));
        let push = ContactForce {
            force: Vec3::new(1.0, 0.0, 0.0),
            point: Vec3::new(0.0, 0.0, 1.0),
            depth: 1e-3,
            touching: true,
            slipping: false,
        };
        let msg = Report::Force {
            t_s: 0.0,
            force: push,
            given_j: 0.0,
        };
        naive.receive(&w, &mut copy, 1, &msg, 0.0);
        assert_eq!(naive.remote_force().x, 1.0);
        naive.peer_lost(1, 0.0);
        let none = ContactForce::default();
        let mut seen = Vec::new();
        for k in 1..=200 {
            copy.time_s = k as f64 * 1e-3;
            naive.physics_step(&w, &mut copy, &none, 1e-3);
            seen.push(naive.remote_force().x);
        }
        assert_eq!(naive.remote_force(), Vec3::zeros(), "gone after the fade");
        assert!(
            naive.remote.iter().all(Option::is_none),
            "the lost site's force is dropped"
        );
        // Heard again: its new force applies in full.
        naive.receive(
            &w,
            &mut copy,
            1,
            &Report::Force {
                t_s: 0.3,
                force: push,
                given_j: 0.0,
            },
            0.3,
        );
        assert_eq!(naive.remote_force().x, 1.0);
    }

    /// `naive`'s no-gain bound: a received force does on this copy at most the work its user did
    /// on their own (`given_j`, plus the slack), takes energy freely, and applies unchanged while
    /// it fits.
    #[test]
    fn a_received_force_gives_at_most_what_its_user_gave() {
        // Weightless: the push acts along the line through the centre of mass, no torque.
        let w = World {
            gravity: Vec3::zeros(),
            ..world()
        };
        let push = |x: f64| ContactForce {
            force: Vec3::new(x, 0.0, 0.0),
            point: Vec3::new(0.0, 1.0, 0.0),
            depth: 1e-3,
            touching: true,
            slipping: false,
        };
        // A free copy (1 m above the plane) pushed by a remote 1 N whose user has given
        // `given_j`, reported every `every` steps and arriving at once (`run`: every 10 ms).
        let reported = |vel: Vec3, force: f64, given_j: f64, steps: usize, every: usize| {
            let mut naive = Naive::default();
            let start = BodyState {
                vel,
                ..BodyState::at_rest(Vec3::new(0.0, 1.0, 0.0))
            };
            let mut copy = ObjectCopy::new(start);
            for k in 0..steps {
                if k % every == 0 {
                    let now = copy.time_s;
                    let msg = Report::Force {
                        t_s: now,
                        force: push(force),
                        given_j,
                    };
                    naive.receive(&w, &mut copy, 1, &msg, now);
                }
                naive.physics_step(&w, &mut copy, &ContactForce::default(), 1e-3);
            }
            let e = |s: &BodyState| s.mechanical_energy(&w.mass, w.gravity);
            (e(&copy.state) - e(&start), copy)
        };
        let run = |vel: Vec3, force: f64, given_j: f64, steps: usize| {
            reported(vel, force, given_j, steps, 10)
        };
        let given = 1e-2;
        let most = given * (1.0 + NAIVE_SLACK_FRACTION) + NAIVE_SLACK_J;
        let (gain, copy) = run(Vec3::zeros(), 1.0, given, 2000);
        // At most one report period (10 ms at up to 0.2 m/s) beyond it.
        assert!(gain <= most + 2e-3, "gained {gain} J, {given} J given");
        assert!(gain > given, "the given work is used: {gain} J");
        assert!(copy.energy.remote_denied_j > 0.0);
        // Ample: Eq. 8 unchanged, 1 N on 0.1 kg for 0.1 s.
        let (_, copy) = run(Vec3::zeros(), 1.0, 10.0, 100);
        assert!(
            (copy.state.vel.x - 1.0).abs() < 0.01,
            "{}",
            copy.state.vel.x
        );
        assert_eq!(copy.energy.remote_denied_j, 0.0);
        // Reported once, its next report still on the way (a 2 s delay): the force stops doing
        // work as soon as it has done here what its user gave, not when a report shows it.
        let (gain, _) = reported(Vec3::zeros(), 1.0, given, 2000, 4000);
        assert!(gain <= most + 1e-3, "gained {gain} J, {given} J given");
        // Taking energy needs nothing given: a copy at 1 m/s stopped by a 1 N brake in 0.1 s.
        let (gain, copy) = run(Vec3::new(1.0, 0.0, 0.0), -1.0, 0.0, 100);
        assert!(copy.state.vel.x.abs() < 0.01, "{}", copy.state.vel.x);
        assert!(gain < -0.04, "{gain}");
    }

    fn world() -> World {
        let shape = Shape::Cylinder {
            radius: 0.04,
            half_height: 0.01,
        };
        let mut planes = [Plane {
            normal: Vec3::y(),
            offset: 0.0,
        }; MAX_PLANES];
        planes[0] = Plane {
            normal: Vec3::y(),
            offset: -0.1,
        };
        World {
            shape,
            mass: MassProps {
                mass_kg: 0.1,
                inertia_body: shape.inertia(0.1),
            },
            gravity: Vec3::new(0.0, -9.81 / 3.0, 0.0),
            planes,
            plane_count: 1,
            env_contact: ContactParams {
                stiffness_n_per_m: 2000.0,
                damping_n_s_per_m: 5.0,
                tangential_stiffness_n_per_m: 2000.0,
                tangential_damping_n_s_per_m: 5.0,
                friction_static: 0.6,
                friction_kinetic: 0.5,
            },
        }
    }

    /// [`world`] with its plane through the origin (a table, `y` up), and the disk resting on it
    /// (within the support's band) moving at `vel`.
    pub(crate) fn on_a_table(vel: Vec3) -> (World, BodyState) {
        let mut w = world();
        w.planes[0] = Plane {
            normal: Vec3::y(),
            offset: 0.0,
        };
        let s = BodyState {
            vel,
            ..BodyState::at_rest(Vec3::new(0.0, 0.0399, 0.0))
        };
        (w, s)
    }

    /// Second-order dead reckoning is exact in free flight; first order misses ½ g Δ².
    #[test]
    fn gravity_aware_dead_reckoning_follows_the_parabola() {
        let w = world();
        let s = BodyState {
            vel: Vec3::new(0.2, 0.5, 0.0),
            ..BodyState::at_rest(Vec3::new(0.0, 0.2, 0.0))
        };
        let dt = 0.3;
        let exact = s.pos + s.vel * dt + w.gravity * (0.5 * dt * dt);
        assert!((dead_reckon(&w, &s, w.gravity, dt, 2).pos - exact).norm() < 1e-12);
        assert!((dead_reckon(&w, &s, w.gravity, dt, 1).pos - exact).norm() > 0.1);
    }

    /// A resting object (support cancels gravity) is not extrapolated through the floor.
    #[test]
    fn dead_reckoning_never_enters_the_environment() {
        let w = world();
        let s = BodyState {
            vel: Vec3::new(0.0, -0.5, 0.0),
            ..BodyState::at_rest(Vec3::new(0.0, -0.06, 0.0))
        };
        let r = dead_reckon(&w, &s, w.gravity, 0.5, 2);
        assert!(r.pos.y >= -0.06 - 1e-12, "{}", r.pos.y);
        assert!(r.vel.y >= 0.0);
    }

    #[test]
    fn paper_adopts_newer_contributions_and_replays_its_own() {
        let w = World {
            plane_count: 0,
            gravity: Vec3::zeros(),
            ..world()
        };
        let mut m = Paper::new(2, 0);
        let mut copy = ObjectCopy::new(BodyState::at_rest(Vec3::zeros()));
        let msg = |t: f64, x: f64, mine: f64, theirs: f64| {
            let mut included = [-1.0; MAX_SITES];
            included[0] = mine;
            included[1] = theirs;
            Report::State {
                t_s: t,
                state: BodyState::at_rest(Vec3::new(x, 0.0, 0.0)),
                accel: Vec3::zeros(),
                included,
            }
        };
        assert!(
            m.receive(&w, &mut copy, 1, &msg(1.0, 0.5, -1.0, 0.9), 1.0)
                .is_some(),
            "newer contribution"
        );
        assert_eq!((copy.state.pos.x, copy.included[1]), (0.5, 0.9));
        assert!(
            m.receive(&w, &mut copy, 1, &msg(0.9, 0.7, -1.0, 0.95), 1.1)
                .is_none(),
            "older snapshot"
        );
        assert!(
            m.receive(&w, &mut copy, 1, &msg(1.0, 0.7, -1.0, 0.95), 1.1)
                .is_none(),
            "replay"
        );
        // Our own user pushes: +0.1 m/s at t = 1.0 (impulse 0.01 N·s on 0.1 kg).
        let push = ContactForce {
            force: Vec3::new(1.0, 0.0, 0.0),
            point: copy.state.pos,
            depth: 0.001,
            touching: true,
            slipping: false,
        };
        copy.time_s = 0.99;
        m.physics_step(&w, &mut copy, &push, 0.01);
        assert!((copy.state.vel.x - 0.1).abs() < 1e-9);
        // A state from site 1 that has not seen our push: adopted, and our push replayed on it.
        assert!(m
            .receive(&w, &mut copy, 1, &msg(1.2, 0.6, -1.0, 1.1), 1.2)
            .is_some());
        assert!(
            (copy.state.vel.x - 0.1).abs() < 1e-9,
            "own impulse replayed: {:?}",
            copy.state.vel
        );
        // Pushed during [0.99, 1.0]: it has moved the object for 1.2 − 0.995 s.
        assert!(
            (copy.state.pos.x - (0.6 + 0.1 * 0.205)).abs() < 1e-9,
            "{:?}",
            copy.state.pos
        );
        // One that has seen it: adopted as it is.
        assert!(m
            .receive(&w, &mut copy, 1, &msg(1.3, 0.65, 1.0, 1.25), 1.3)
            .is_some());
        assert!(copy.state.vel.x.abs() < 1e-12 && (copy.state.pos.x - 0.65).abs() < 1e-12);
    }

    /// A state reported resting on the table (within the support's band) but leaving it fast, as a
    /// disk a tool flicks up: reckoned with the support's zero acceleration it would fly on
    /// unslowed (0.44 m up after 0.5 s); `paper` adopts it with no more energy than the state sent.
    #[test]
    fn paper_never_adopts_more_energy_than_the_state_sent() {
        let (w, sent) = on_a_table(Vec3::new(0.0, 0.87, 0.0));
        let accel = supported_gravity(&w, &sent);
        assert!(accel.norm() < 1e-12, "reported as resting: {accel:?}");
        let reckoned = dead_reckon(&w, &sent, accel, 0.5, 2);
        assert!(reckoned.pos.y > 0.4, "unslowed: {:?}", reckoned.pos);
        let mut m = Paper::new(2, 0);
        // This copy's disk is off the table (an earlier adoption lifted it): nothing of the
        // local state is kept along the table's normal.
        let mut copy = ObjectCopy::new(BodyState::at_rest(Vec3::new(0.0, 0.06, 0.0)));
        let mut included = [-1.0; MAX_SITES];
        included[1] = 1.0;
        let msg = Report::State {
            t_s: 1.0,
            state: sent,
            accel,
            included,
        };
        assert!(m.receive(&w, &mut copy, 1, &msg, 1.5).is_some());
        // (The sent state as the reckoner puts it: on the table's surface.)
        let mut on_surface = sent;
        push_out_of_environment(&w, &mut on_surface);
        let e = |s: &BodyState| crate::tank::stored_energy(&w, s);
        assert!(
            e(&copy.state) <= e(&on_surface) + DEAD_RECKONING_SLACK_J,
            "{} J adopted, {} J sent",
            e(&copy.state),
            e(&on_surface)
        );
        assert!(copy.state.pos.y < 0.1, "{:?}", copy.state.pos);
    }

    /// Order 2 on a table: a slide decelerates under kinetic friction and stops where physics stops it.
    #[test]
    fn dead_reckoning_slides_to_a_stop() {
        let (w, s) = on_a_table(Vec3::new(0.2, 0.0, 0.0));
        let a = supported_gravity(&w, &s);
        assert!(a.norm() < 1e-12, "a table carries all of gravity: {a:?}");
        let decel = w.env_contact.friction_kinetic * 9.81 / 3.0;
        let stop = 0.2 * 0.2 / (2.0 * decel);
        let r = dead_reckon(&w, &s, a, 5.0, 2);
        assert!(
            (r.pos.x - stop).abs() < 1e-12 && r.vel.norm() < 1e-12,
            "{:?}",
            r.pos
        );
    }
}
