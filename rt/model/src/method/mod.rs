//! Consistency methods: how each site's copy of the world is kept in step with the others'.
//!
//! A method is a [`Consistency`]: it integrates the site's copy on each physics tick, says what the
//! site reports to the others, and handles their reports. The simulator, the station's physics
//! process and the tests build one through [`crate::scenario::Scenario::method`] only, so a method
//! is the same wherever it runs.
//!
//! - [`Naive`] — Eq. 8 across the network: every site integrates its own copy with its own user's
//!   force plus the *latest received* forces of the others, and only forces are exchanged. With
//!   delay and different rates the copies see different force histories and diverge (the paper's
//!   first experiment).
//! - [`Paper`] — Eq. 10/11: a site integrates its copy with its **own** user's force only (and the
//!   environment), reports its state with the time of that state, and **adopts** any received state
//!   newer than the newest it has adopted, dead-reckoned from the state's time to now
//!   ([`reckon`]).
//! - [`TimeWarp`] — the users' tools travel instead of the object's state; every site steps every
//!   tool on a common tick grid and rolls back when a late position differs from its prediction.
//! - [`Coupled`] — each site steps the others' tools from a jitter buffer and pulls its copy
//!   towards the leader's within an energy tank.
//!
//! Layout: one file per method; beside them what they share, each depending only on the ones
//! above it in this list: [`copy`] (a site's copy and the integration step), [`track`] (the tool
//! tracks `timewarp` and `coupled` send), [`window`] (which own ticks a track carries, and a
//! receiver's measure of the tracks it loses), [`report`] (what sites send), [`stats`] (what methods count), [`tank`] (the energy
//! bounds), [`reckon`] (dead reckoning), [`consistency`] (the trait). A method's file imports
//! from those, never from this module or another method.

pub mod consistency;
pub mod copy;
pub mod coupled;
pub mod naive;
pub mod paper;
pub mod reckon;
pub mod report;
pub mod stats;
pub mod tank;
pub mod timewarp;
pub mod track;
pub mod window;

pub use crate::world::MAX_SITES;
pub use consistency::{Consistency, Sink, LOST_FADE_S};
pub use copy::{integrate, integrate_some, EnergyAccount, ObjectCopy, WorldCopy};
pub use coupled::Coupled;
pub use naive::{Naive, NAIVE_SLACK_FRACTION, NAIVE_SLACK_J};
pub use paper::Paper;
pub use reckon::{dead_reckon, passive_reckoned, DEAD_RECKONING_SLACK_J};
pub use report::{Adoption, Report};
pub use stats::{RollbackStats, Stats};
pub use timewarp::TimeWarp;
