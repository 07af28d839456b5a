//! The station: one site — one user, one device, a full local copy of the world — as separate
//! processes for the servo loop, the physics loop and the network, connected by shared-memory rings
//! (named and laid out in [`coop_rt::shm::station`]).
//!
//! - [`config`]: the station's configuration, validated (field, value, rule, file), and written
//!   back as TOML for the stations a launcher starts;
//! - [`device`]: the `[device]` table (backend, placement, loop owner, safety limits), opening the
//!   backend in the servo process, and what each backend finds (`station devices`);
//! - [`child`]: the entry points of the servo, physics and network processes;
//! - [`run`]: `station run`, the supervisor bringing the children up and the stop ladder taking them
//!   down, leaving nothing behind; and, when the network process cannot link, saying why once
//!   (`link`);
//! - [`trials`]: a study's station running trial after trial without a restart;
//! - [`status`]: [`status::StationStatus`], what a running station is doing, read from its control
//!   block without touching the loops.

pub mod child;
pub mod config;
pub mod device;
mod error;
mod link;
pub mod run;
pub mod status;
pub mod trials;
