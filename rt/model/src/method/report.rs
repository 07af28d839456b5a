//! What sites send each other, and what a site records when a received state replaces its own.

use crate::body::{BodyState, Vec3};
use crate::contact::ContactForce;
use crate::world::MAX_SITES;

use super::track::{CoupledReport, ToolReport};

/// What sites send each other.
#[derive(Debug, Clone, Copy, PartialEq)]
// NB: a report moves by value on the real-time path, where nothing allocates: a timewarp
// report's 3 KB are copied at the report rate instead of boxed.
#[allow(clippy::large_enum_variant)]
pub enum Report {
    /// `paper`: one object's state, the time it holds at, up to when each site's user's impulses are included
    /// in it, and the acceleration a receiver should extrapolate it with.
    State {
        /// Which object of the world ([`crate::world::World::bodies`] order).
        object: usize,
        /// Time of the state, s (sender's clock).
        t_s: f64,
        /// The state.
        state: BodyState,
        /// Gravity less the environment's support, m/s².
        accel: Vec3,
        /// Per site, the time up to which its user's impulses are included, s.
        included: [f64; MAX_SITES],
    },
    /// `naive`: the sender's own contact force on one object and where it acts.
    Force {
        /// Which object of the world it pushes.
        object: usize,
        /// Time, s.
        t_s: f64,
        /// The contact.
        force: ContactForce,
        /// The sender's user's positive work on the sender's copy so far, J
        /// ([`super::copy::EnergyAccount::own_positive_j`]): at most what this force may do on a receiver's.
        given_j: f64,
    },
    /// `timewarp`: the sender's tool positions on the tick grid, and its confirmed frontier.
    Tools(ToolReport),
    /// `coupled`: the sender's tool positions, its copy, and when its user's contact began.
    Coupled(CoupledReport),
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
    /// Energy the no-gain bound ([`crate::method::tank::bound_gain`]) took out of the correction, J (0: it
    /// fitted).
    pub clipped_j: f64,
}
