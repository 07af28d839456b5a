//! One site's copy of the world, and the integration step every method advances it with.

use crate::body::{self, BodyState, HalfStep, Vec3, Wrench};
use crate::contact::{
    environment_wrench, pair_wrench, ContactForce, EnvContactState, PairContactState, PairSide,
};
use crate::world::{
    pair_index, supported_gravity, Body, World, MAX_OBJECTS, MAX_SITES, STILL_SPEED_M_PER_S,
    STILL_SPIN_RAD_PER_S,
};

/// Where a site's copy got its energy (passivity check).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnergyAccount {
    /// Work of the own user's contact force, J.
    pub own_j: f64,
    /// Work of other users' (received) forces, J (naive only).
    pub remote_j: f64,
    /// Work of the environment, J.
    pub env_j: f64,
    /// Work of the other objects' contacts, J (what it gave them or got from them).
    pub objects_j: f64,
    /// Mechanical-energy change caused by adoptions, J.
    pub adoption_j: f64,
    /// The users' work on this copy counted only where positive, step by step (own and remote), J:
    /// what the users can have given it at most (the bound of [`crate::method::tank`]'s checks).
    pub users_positive_j: f64,
    /// The work of the forces [`integrate`] counts as own, only where positive, step by step, J
    /// (`naive`, `paper`: the own user's, what it has given this copy, which a `naive` report
    /// carries; `timewarp`: every user's, all computed here).
    pub own_positive_j: f64,
    /// Work received forces would have done on this copy beyond what their users had given their
    /// own copies, denied by `naive`'s no-gain bound, J.
    pub remote_denied_j: f64,
}

impl EnergyAccount {
    /// Both accounts together (a world's, from its objects').
    pub fn plus(&self, o: &EnergyAccount) -> EnergyAccount {
        EnergyAccount {
            own_j: self.own_j + o.own_j,
            remote_j: self.remote_j + o.remote_j,
            env_j: self.env_j + o.env_j,
            objects_j: self.objects_j + o.objects_j,
            adoption_j: self.adoption_j + o.adoption_j,
            users_positive_j: self.users_positive_j + o.users_positive_j,
            own_positive_j: self.own_positive_j + o.own_positive_j,
            remote_denied_j: self.remote_denied_j + o.remote_denied_j,
        }
    }
}

/// One site's copy of one object of the world.
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

/// One site's copy of the world: every object's copy, in the world's order, and the memory of the
/// objects' contacts with each other. Sized for its world when made; copying one into another of
/// the same world ([`WorldCopy::copy_from`]) allocates nothing.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldCopy {
    objects: Box<[ObjectCopy]>,
    /// Per pair of objects ([`pair_index`]), their contact's friction memory.
    pairs: Box<[PairContactState]>,
    /// Per object, the steps in a row it has been still ([`STILL_SPEED_M_PER_S`],
    /// [`STILL_SPIN_RAD_PER_S`]); at [`World::sleep_after_steps`] it sleeps.
    still: Box<[u32]>,
}

impl WorldCopy {
    /// A copy of a world whose objects are at `states` (1 to [`MAX_OBJECTS`] of them), time 0.
    pub fn new(states: &[BodyState]) -> Self {
        let n = states.len().clamp(1, MAX_OBJECTS);
        let first = states
            .first()
            .copied()
            .unwrap_or(BodyState::at_rest(Vec3::zeros()));
        let mut objects = vec![ObjectCopy::new(first); n];
        for (o, s) in objects.iter_mut().zip(states) {
            *o = ObjectCopy::new(*s);
        }
        Self {
            objects: objects.into_boxed_slice(),
            pairs: vec![PairContactState::default(); n * (n - 1) / 2].into_boxed_slice(),
            still: vec![0; n].into_boxed_slice(),
        }
    }

    /// A copy of one object at `state`.
    pub fn one(state: BodyState) -> Self {
        Self::new(std::slice::from_ref(&state))
    }

    /// How many objects.
    pub fn len(&self) -> usize {
        self.objects.len()
    }

    /// Never: a world has at least one object.
    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// Every object's copy.
    pub fn objects(&self) -> &[ObjectCopy] {
        &self.objects
    }

    /// Every object's copy, to change.
    pub fn objects_mut(&mut self) -> &mut [ObjectCopy] {
        &mut self.objects
    }

    /// The first object's copy (the one object of a world of one).
    pub fn first(&self) -> &ObjectCopy {
        &self.objects[0]
    }

    /// The first object's copy, to change.
    pub fn first_mut(&mut self) -> &mut ObjectCopy {
        &mut self.objects[0]
    }

    /// The objects' contacts with each other, in [`pair_index`] order.
    pub fn pairs(&self) -> &[PairContactState] {
        &self.pairs
    }

    /// Per object, the steps in a row it has been still.
    pub fn still(&self) -> &[u32] {
        &self.still
    }

    /// Object `k` was moved from outside the physics (an adopted or pulled state): it is awake,
    /// and sleeps again only once it has been still long enough ([`World::sleep_after_steps`]);
    /// and its contacts with the other objects begin again where they are, their friction
    /// springs unstretched. A sleeper left asleep keeps the new state's velocity without moving
    /// or being slowed (a box adopted sliding glided on through every later adoption); a stick
    /// point left where it was on the other object is a friction spring stretched by the whole
    /// correction (a tray pulled 7 mm under its cup threw both, 245 mJ beyond every user's work).
    /// Allocates nothing.
    pub fn corrected(&mut self, k: usize) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let n = self.objects.len();
        if k >= n {
            return;
        }
        self.still[k] = 0;
        for j in (0..n).filter(|&j| j != k) {
            self.pairs[pair_index(k.min(j), k.max(j), n)] = PairContactState::default();
        }
    }

    /// Object `k` takes an adopted snapshot's parts: its state, its environment's friction
    /// memory, its sleep count and its contacts' memory with each later object (`later[m]`: with
    /// object `k + 1 + m`). Allocates nothing.
    pub fn set_object(
        &mut self,
        k: usize,
        (state, env): (BodyState, EnvContactState),
        still: u32,
        later: &[PairContactState],
    ) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let n = self.objects.len();
        if k >= n {
            return;
        }
        self.objects[k].state = state;
        self.objects[k].env = env;
        self.still[k] = still;
        for (j, p) in (k + 1..n).zip(later) {
            self.pairs[pair_index(k, j, n)] = *p;
        }
    }

    /// Takes from `other` (a copy of the same world) the objects in `objects` (their copies and
    /// sleep counts) and the memory of the contacts `pairs(i, j)` says (`i < j`). Allocates
    /// nothing.
    pub fn copy_some_from(
        &mut self,
        other: &WorldCopy,
        objects: &[bool; MAX_OBJECTS],
        pairs: impl Fn(usize, usize) -> bool,
    ) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let n = self.objects.len().min(other.objects.len());
        for k in (0..n).filter(|&k| objects[k]) {
            self.objects[k] = other.objects[k];
            self.still[k] = other.still[k];
        }
        for i in 0..n {
            for j in i + 1..n {
                if pairs(i, j) {
                    let p = pair_index(i, j, n);
                    self.pairs[p] = other.pairs[p];
                }
            }
        }
    }

    /// Every object's time, s (they advance together).
    pub fn set_time(&mut self, time_s: f64) {
        for o in self.objects.iter_mut() {
            o.time_s = time_s;
        }
    }

    /// Becomes `other`, a copy of the same world. Allocates nothing.
    pub fn copy_from(&mut self, other: &WorldCopy) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        debug_assert_eq!(
            self.objects.len(),
            other.objects.len(),
            "copies of one world"
        );
        self.objects.copy_from_slice(&other.objects);
        self.pairs.copy_from_slice(&other.pairs);
        self.still.copy_from_slice(&other.still);
    }

    /// The objects' mechanical energy in `world`, J, summed in the world's order from the
    /// first object's (for one object: its own, to the bit).
    pub fn mechanical_energy(&self, world: &World) -> f64 {
        let mut e = self
            .objects
            .iter()
            .zip(world.bodies())
            .map(|(o, b)| o.state.mechanical_energy(&b.mass, world.gravity));
        let first = e.next().unwrap_or(0.0);
        e.fold(first, |a, b| a + b)
    }

    /// Whether every number is finite.
    pub fn is_finite(&self) -> bool {
        self.objects.iter().all(|o| o.state.is_finite())
    }
}

/// What one wrench evaluation of a world step saw per object, by source: the own users', the
/// remote users', the environment's, the other objects'.
type Seen = [[Wrench; 4]; MAX_OBJECTS];

/// Integrates a copy of the world by `dt` together: velocity Verlet ([`body::step`]) with every
/// object's wrench evaluated at every object's start pose, every object drifted, and every wrench
/// evaluated again at the end poses, so a contact between two objects acts on both from the same
/// poses. Keeps each object's energy account.
///
/// `users` are the tools' contacts, held over the step: `per_object` of them for each object in
/// turn (object `k`'s at `k * per_object ..`), of which the first `own_count` are the site's own
/// (the rest are remote). `impulse`, when not empty, gets each object's own users' impulse over
/// the step (linear in `force`, angular in `torque`).
///
/// The order is fixed: each object's wrench is its own users' (in site order), plus the remote
/// users', plus the environment's, plus (with several objects) the other objects' summed in
/// [`pair_index`] order; so every site sums the same floating-point terms in the same order and
/// gets the same bits. Fixtures and sleeping objects ([`World::sleep_after_steps`]) do not move.
/// Allocates nothing.
pub fn integrate(
    world: &World,
    copy: &mut WorldCopy,
    users: &[ContactForce],
    per_object: usize,
    own_count: usize,
    dt: f64,
    impulse: &mut [Wrench],
) {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    let none = [false; MAX_OBJECTS];
    integrate_some(
        world,
        copy,
        (users, per_object, own_count),
        dt,
        impulse,
        &none,
    );
}

/// [`integrate`] of the objects not in `skip`: a skipped object is neither stepped nor evaluated
/// (its copy, its sleep count and its contacts with the other skipped ones are left as they are,
/// for the caller to set), and its contact with a stepped one is taken as apart. The caller
/// guarantees that: no skipped object is within reach of a stepped one, nor touching it, so the
/// stepped objects get the same bits as in a whole step (a rollback re-simulates only the
/// objects a changed input can reach: see `timewarp`).
pub fn integrate_some(
    world: &World,
    copy: &mut WorldCopy,
    (users, per_object, own_count): (&[ContactForce], usize, usize),
    dt: f64,
    impulse: &mut [Wrench],
    skip: &[bool; MAX_OBJECTS],
) {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    let n = copy.len().min(world.bodies().len());
    let bodies = &world.bodies()[..n];
    let frozen = sleepers(world, bodies, copy, users, per_object);
    let mut seen: [Seen; 2] = [[[Wrench::default(); 4]; MAX_OBJECTS]; 2];
    let mut half = [HalfStep::default(); MAX_OBJECTS];
    let mut touching = [false; MAX_OBJECTS];
    let before: [BodyState; MAX_OBJECTS] =
        std::array::from_fn(|k| copy.objects[k.min(n - 1)].state);
    let mut w = [Wrench::default(); MAX_OBJECTS];
    for (pass, seen) in seen.iter_mut().enumerate() {
        evaluate(
            world,
            bodies,
            copy,
            (&frozen, skip),
            users,
            (per_object, own_count),
            seen,
            &mut touching,
        );
        for k in (0..n).filter(|&k| !frozen[k] && !skip[k]) {
            let [own, remote, env, objects] = seen[k];
            w[k] = own + remote + env;
            if n > 1 {
                w[k] = w[k] + objects;
            }
        }
        for k in (0..n).filter(|&k| !frozen[k] && !skip[k]) {
            let o = &mut copy.objects[k];
            let m = &bodies[k].mass;
            if pass == 0 {
                (o.state, half[k]) = body::kick_drift(&o.state, m, world.gravity, dt, &w[k]);
            } else {
                body::kick(&mut o.state, m, world.gravity, dt, &half[k], &w[k]);
            }
        }
    }
    for k in (0..n).filter(|&k| !skip[k]) {
        let b = &bodies[k];
        let o = &mut copy.objects[k];
        o.time_s += dt;
        if frozen[k] {
            continue;
        }
        let next = o.state;
        let omega_mid = (before[k].omega(&b.mass) + next.omega(&b.mass)) * 0.5;
        let dx = next.pos - before[k].pos;
        let work = |source: usize| {
            let (a, c) = (seen[0][k][source], seen[1][k][source]);
            (a.force + c.force).dot(&dx) * 0.5 + (a.torque + c.torque).dot(&omega_mid) * 0.5 * dt
        };
        let (w_own, w_remote) = (work(0), work(1));
        let e = &mut o.energy;
        e.own_j += w_own;
        e.remote_j += w_remote;
        e.users_positive_j += w_own.max(0.0) + w_remote.max(0.0);
        e.own_positive_j += w_own.max(0.0);
        e.env_j += work(2);
        if n > 1 {
            e.objects_j += work(3);
        }
        o.passive_accel = supported_gravity(world, &b.shape, &next);
        o.env_touching = touching[k];
        let still = next.vel.norm() < STILL_SPEED_M_PER_S
            && next.omega(&b.mass).norm() < STILL_SPIN_RAD_PER_S;
        copy.still[k] = if still {
            copy.still[k].saturating_add(1)
        } else {
            0
        };
    }
    for (k, i) in impulse.iter_mut().enumerate().take(n) {
        // The own users' impulse over the step (trapezoid of the two evaluations).
        let (a, c) = (seen[0][k][0], seen[1][k][0]);
        *i = Wrench {
            force: (a.force + c.force) * (0.5 * dt),
            torque: (a.torque + c.torque) * (0.5 * dt),
        };
    }
}

/// One evaluation of every object's wrenches at the copy's poses, by source (see [`integrate`]).
#[allow(clippy::too_many_arguments)]
fn evaluate(
    world: &World,
    bodies: &[Body],
    copy: &mut WorldCopy,
    (frozen, skip): (&[bool; MAX_OBJECTS], &[bool; MAX_OBJECTS]),
    users: &[ContactForce],
    (per_object, own_count): (usize, usize),
    seen: &mut Seen,
    touching: &mut [bool; MAX_OBJECTS],
) {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    let n = bodies.len();
    for k in (0..n).filter(|&k| !skip[k]) {
        let o = &mut copy.objects[k];
        let mut own = Wrench::default();
        let mut remote = Wrench::default();
        let tools = users
            .get(k * per_object..(k + 1) * per_object)
            .unwrap_or(&[]);
        for (j, u) in tools.iter().enumerate() {
            if j < own_count {
                own = own + u.wrench(o.state.pos);
            } else {
                remote = remote + u.wrench(o.state.pos);
            }
        }
        let (env, touch) = if frozen[k] {
            (Wrench::default(), o.env_touching)
        } else {
            environment_wrench(
                &world.env_contact,
                &mut o.env,
                world.planes(),
                &bodies[k].shape,
                &o.state,
                &bodies[k].mass,
            )
        };
        touching[k] = touch;
        seen[k] = [own, remote, env, Wrench::default()];
    }
    for i in 0..n {
        for j in i + 1..n {
            let memory = &mut copy.pairs[pair_index(i, j, n)];
            if skip[i] && skip[j] {
                continue; // neither stepped: the caller's
            }
            if bodies[i].fixed && bodies[j].fixed {
                *memory = PairContactState::default();
                continue;
            }
            if frozen[i] && frozen[j] {
                continue; // two sleepers (or a sleeper on a fixture): their contact as it was
            }
            if skip[i] || skip[j] {
                // Out of reach of each other (the caller's guarantee): as `pair_wrench` has it.
                *memory = PairContactState::default();
                continue;
            }
            let side = |k: usize| PairSide {
                shape: &bodies[k].shape,
                body: &copy.objects[k].state,
                mass: &bodies[k].mass,
            };
            let (a, b) = (side(i), side(j));
            let (on_i, on_j, _) = pair_wrench(&world.object_contact, memory, a, b);
            seen[i][3] = seen[i][3] + on_i;
            seen[j][3] = seen[j][3] + on_j;
        }
    }
}

/// Which objects do not move this step: the fixtures and the sleepers. An object sleeps once it
/// has been still for [`World::sleep_after_steps`] steps. A tool touching it wakes it and its
/// count starts again; an awake object touching it (as the contact memory of the last step has
/// it) wakes it until it has been still for one step again: a row pushed at one end wakes down
/// the row, a box set down on a sleeping one wakes it until both rest, and a resting stack falls
/// asleep when its last member has been still long enough. A sleeper newly touched holds like a
/// fixture for that one step (its reaction is not applied to it). Every site decides the same
/// from the same state.
fn sleepers(
    world: &World,
    bodies: &[Body],
    copy: &mut WorldCopy,
    users: &[ContactForce],
    per_object: usize,
) -> [bool; MAX_OBJECTS] {
    let n = bodies.len();
    let after = world.sleep_after_steps;
    for k in 0..n {
        let tools = users
            .get(k * per_object..(k + 1) * per_object)
            .unwrap_or(&[]);
        if tools.iter().any(|u| u.touching || u.force != Vec3::zeros()) {
            copy.still[k] = 0;
        }
    }
    for i in 0..n {
        for j in i + 1..n {
            if !copy.pairs[pair_index(i, j, n)].touching() {
                continue;
            }
            let moved = |k: usize| !bodies[k].fixed && copy.still[k] < after;
            let (wake_i, wake_j) = (moved(j), moved(i));
            if wake_i {
                copy.still[i] = copy.still[i].min(after.saturating_sub(1));
            }
            if wake_j {
                copy.still[j] = copy.still[j].min(after.saturating_sub(1));
            }
        }
    }
    std::array::from_fn(|k| k < n && (bodies[k].fixed || (after > 0 && copy.still[k] >= after)))
}
