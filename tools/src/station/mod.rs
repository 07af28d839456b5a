//! The station: one site — one user, one device, a full local copy of the world — as separate
//! processes for the servo loop, the physics loop and the network, connected by shared-memory rings.
//!
//! Built so far: the configuration ([`config`]), the set of segments created before anything is
//! spawned ([`segments`]), the servo and physics child processes ([`child`]), and `station run`
//! under the ractor supervisor ([`run`]) with the zenoh network process, and `station status`
//! ([`status`]).

pub mod child;
pub mod cli;
pub mod config;
pub mod run;
pub mod segments;
pub mod status;
