//! What can be wrong with a station's configuration: [`Problem`] says which field, which value and
//! which rule; [`ConfigError`] adds the file it is in.
//!
//! A problem that wraps another error (a file that does not load, a scenario that breaks a rule)
//! shows its own words and gives the other error as its `source`, so that `{:#}` (anyhow at the
//! binary's edge) prints the whole chain and `{}` only the first link, as the messages always have.

use std::path::{Path, PathBuf};

use crate::scenario_file;
use crate::trajectory_file::TrajectoryFileError;

/// A station's configuration that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("reading station config {}", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        error: std::io::Error,
    },
    /// A problem in a file, or in the defaults when there is none.
    #[error("station config {}", shown(.file.as_deref()))]
    InFile {
        /// The file (`None`: no file, the defaults).
        file: Option<PathBuf>,
        /// What is wrong in it.
        #[source]
        problem: Problem,
    },
    /// A problem in values that came from no file (as [`super::config::StationConfig::resolve`] is given
    /// them).
    #[error(transparent)]
    Invalid(#[from] Problem),
}

impl ConfigError {
    /// `problem`, found in `file` (`None`: the defaults).
    pub fn in_file(file: Option<&Path>, problem: Problem) -> Self {
        Self::InFile {
            file: file.map(Path::to_path_buf),
            problem,
        }
    }
}

/// How a configuration file is named in messages.
fn shown(file: Option<&Path>) -> String {
    file.map_or("(defaults)".into(), |p| p.display().to_string())
}

/// A field, its value and the rule it breaks (or a file it names that does not load).
#[derive(Debug, thiserror::Error)]
pub enum Problem {
    /// `field = value` breaks `rule`.
    #[error("{field} = {value}: {rule}")]
    Value {
        /// The field, as written in the file (`network.max_state_age_ms`).
        field: String,
        /// Its value as written (strings quoted).
        value: String,
        /// The rule it breaks.
        rule: String,
    },
    /// The list `field` holds `entry`, which breaks `rule`.
    #[error("{field} contains {entry}: {rule}")]
    Entry {
        /// The list's field.
        field: String,
        /// The entry (quoted), or the entries that clash.
        entry: String,
        /// The rule it breaks.
        rule: String,
    },
    /// `field = value` needs another field, `needs` saying which and why.
    #[error("{field} = {value} needs {needs}")]
    Needs {
        /// The field.
        field: String,
        /// Its value as written.
        value: String,
        /// The field it needs, and why.
        needs: String,
    },
    /// `field` is absent where `rule` needs it.
    #[error("{field} is missing: {rule}")]
    Missing {
        /// The absent field.
        field: String,
        /// Why it is needed.
        rule: String,
    },
    /// The table `table` breaks `rule` as a whole: a field it does not have, a wrong type, a table
    /// for a backend not selected, a scheduling request that can never be honoured.
    #[error("{table}: {rule}")]
    Table {
        /// The table (`device.haply`, `servo`).
        table: String,
        /// The rule it breaks.
        rule: String,
    },
    /// A rule stated whole by the crate that owns the value (its words name the field).
    #[error("{0}")]
    Stated(String),
    /// The text is not TOML of a configuration (a syntax error, an unknown field, a wrong type).
    #[error("{}", .0.to_string().trim_end())]
    Toml(toml::de::Error),
    /// The scenario file the configuration names does not load.
    #[error(transparent)]
    Scenario(Box<scenario_file::LoadError>),
    /// The paper's scenario, embedded in the binary, does not parse (a build that broke it).
    #[error("the embedded paper scenario")]
    EmbeddedScenario(#[source] Box<scenario_file::ParseError>),
    /// The recorded hand of `device = "replay"` does not load.
    #[error("device.replay.file = {file:?}")]
    ReplayFile {
        /// The file, as resolved.
        file: String,
        /// Why.
        #[source]
        error: Box<TrajectoryFileError>,
    },
    /// Zenoh refuses the endpoints (its own checks of the files it is given).
    #[error("{0}")]
    Zenoh(Box<coop_transport::network::NetworkError>),
}

impl Problem {
    /// `field = value: rule`.
    pub(crate) fn value(
        field: impl Into<String>,
        value: impl std::fmt::Display,
        rule: impl Into<String>,
    ) -> Self {
        Self::Value {
            field: field.into(),
            value: value.to_string(),
            rule: rule.into(),
        }
    }

    /// `field contains entry: rule`.
    pub(crate) fn entry(
        field: impl Into<String>,
        entry: impl std::fmt::Display,
        rule: impl Into<String>,
    ) -> Self {
        Self::Entry {
            field: field.into(),
            entry: entry.to_string(),
            rule: rule.into(),
        }
    }

    /// `field is missing: rule`.
    pub(crate) fn missing(field: impl Into<String>, rule: impl Into<String>) -> Self {
        Self::Missing {
            field: field.into(),
            rule: rule.into(),
        }
    }

    /// `table: rule`.
    pub(crate) fn table(table: impl Into<String>, rule: impl std::fmt::Display) -> Self {
        Self::Table {
            table: table.into(),
            rule: rule.to_string(),
        }
    }
}
