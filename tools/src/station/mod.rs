//! The station: one site — one user, one device, a full local copy of the world — as separate
//! processes for the servo loop, the physics loop and the network, connected by shared-memory rings.
//!
//! Built so far: the configuration ([`config`]), the set of segments a supervisor creates before it
//! spawns anything ([`segments`]), and the servo and physics child processes ([`child`]). The
//! supervisor (`station run`/`status`) and the network process come next.

pub mod child;
pub mod config;
pub mod segments;
