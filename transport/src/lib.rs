//! coop-transport: Zenoh between stations.
//!
//! - [`keys`]: every key expression, from one place.
//! - [`wire`]: the one encode and the one decode of what stations send each other.
//! - [`admit`]: what a receiver takes of a decoded report (its site, its time, its plausibility,
//!   its sequence), every refusal typed and counted.
//! - [`acl`]: who may say what in a session (zenoh's access control, by certificate name).
//! - [`router`]: a zenoh router enforcing it, for sessions across machines, and its status.
//! - [`recording`]: the station's MCAP recording, written and read, and a run's session file.
//! - [`live_view`]: a site or a whole session served live to Foxglove (`foxglove.websocket.v1`).
//! - [`ros2`]: `rmw_zenoh`'s messages and graph conventions; [`ros2_device`]: a ROS 2 haptic
//!   driver as a station's device.
//! - [`network`]: the station's network process — reports from physics out to the session, the
//!   other stations' reports in to physics, through the station's shared-memory rings.
//!
//! The network process is not a real-time loop: it runs its threads and zenoh's at normal priority, and only
//! touches the rings (lock-free, non-blocking) on the real-time side's behalf.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod acl;
pub mod admit;
pub mod keys;
pub mod live_view;
pub mod log;
pub mod network;
pub mod recording;
pub mod ros2;
pub mod ros2_device;
pub mod router;
pub mod wire;
