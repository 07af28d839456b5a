//! A station's configuration: which session and site it is, where the world comes from (a scenario
//! file, by default the paper's experiment embedded in the binary), and how its loops are scheduled.
//! Every field has a default, so a station starts with no file at all; a file is TOML with unknown
//! fields refused, and validation names the field, the value and the rule.
//!
//! - `schema`: the tables and fields of the file, with their defaults;
//! - `resolve`: loading a file and resolving it into [`Resolved`], what the station runs;
//! - `rules`: the checks, each naming the field, the value and the rule;
//! - `station::error`, beside this module (the device's setup names its problems too):
//!   [`ConfigError`] (a file that cannot be read, or a [`Problem`] and its file).

mod resolve;
mod rules;
mod schema;

pub use super::error::{ConfigError, Problem};
pub use resolve::Resolved;
pub(crate) use rules::{certificates_name, listen_ports_free, readable, tls_files_readable};
pub use schema::{LoopSpec, StartMode, StationConfig, SupervisorSpec};

/// The paper's experiment, the default world.
pub const DEFAULT_SCENARIO: &str = include_str!("../../../../scenarios/paper.toml");

#[cfg(test)]
mod tests;
