//! One site's copy of the object, and the integration step every method advances it with.

use crate::body::{self, BodyState, Vec3, Wrench};
use crate::contact::{environment_wrench, ContactForce, EnvContactState};
use crate::world::{supported_gravity, World, MAX_SITES};

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
