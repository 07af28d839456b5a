//! coop-model: the pure model of cooperative haptic manipulation (Choi & Ryew) — object dynamics,
//! contact, the SCARA device, the force controller, the consistency methods — and a deterministic
//! multi-site simulator built on them.
//!
//! Pure and deterministic by construction: it depends on nalgebra only (serde optionally, for
//! scenario files), has no `unsafe`, does no I/O, and takes time as an argument. The station's servo
//! and physics loops call the same functions; equations are cited by the paper's numbers where they
//! are implemented. The step functions (`body::step`, `contact::*`, `servo::Servo::step`,
//! `method::*::physics_step`) do not allocate.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod body;
pub mod contact;
pub mod controller;
pub mod device;
pub mod display;
pub mod drive;
pub mod histogram;
pub mod link;
pub mod method;
pub mod metrics;
pub mod participant;
pub mod perception;
pub mod replay;
pub mod rng;
pub mod rules;
pub mod scenario;
pub mod servo;
pub mod shape;
pub mod sim;
pub mod task;
pub mod user;
pub mod world;

/// Sites a session can have: the one bound every fixed-size table (a report's inclusion times, the
/// control block's per-peer slots, the wire's `included` field) is sized by.
pub use world::MAX_SITES;
