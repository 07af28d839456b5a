//! Scenario files: TOML in, a validated [`Scenario`] out, or an error that names the file and the
//! field, the value and the rule (unknown fields included).

use std::path::{Path, PathBuf};

use coop_model::scenario::{Scenario, ScenarioError};

use crate::trajectory_file::TrajectoryFileError;

/// A scenario file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The file cannot be read.
    #[error("reading scenario {}", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        error: std::io::Error,
    },
    /// The file's text is not a valid scenario.
    #[error("scenario {}", .path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong in it.
        #[source]
        error: ParseError,
    },
}

/// Scenario text that is not a valid scenario.
#[derive(Debug, thiserror::Error)]
pub enum ParseError {
    /// Not TOML of a scenario (a syntax error, an unknown field, a wrong type).
    #[error("{}", .0.to_string().trim_end())]
    Toml(toml::de::Error),
    /// A site's recorded hand does not load.
    #[error("invalid value: site[{site}].hand_replay = {file:?}")]
    HandReplay {
        /// The site's index.
        site: usize,
        /// The file, as written.
        file: String,
        /// Why.
        #[source]
        error: Box<TrajectoryFileError>,
    },
    /// A value breaks a rule of [`Scenario::validate`].
    #[error("invalid value: {0}")]
    Rule(ScenarioError),
}

/// Reads, parses and validates a scenario file.
///
/// # Errors
/// The file cannot be read, is not valid TOML for a scenario (unknown field, wrong type), or breaks
/// a rule of [`Scenario::validate`].
pub fn load(path: &Path) -> Result<Scenario, LoadError> {
    let text = std::fs::read_to_string(path).map_err(|error| LoadError::Read {
        path: path.to_owned(),
        error,
    })?;
    parse_at(&text, path.parent()).map_err(|error| LoadError::Invalid {
        path: path.to_owned(),
        error,
    })
}

/// Parses and validates scenario text (a recorded hand's file relative to the working directory).
///
/// # Errors
/// As [`load`].
pub fn parse(text: &str) -> Result<Scenario, ParseError> {
    parse_at(text, None)
}

/// Parses scenario text, loads its sites' recorded hands (`hand_replay`, relative to `base`) and
/// validates it.
///
/// # Errors
/// As [`load`].
pub fn parse_at(text: &str, base: Option<&Path>) -> Result<Scenario, ParseError> {
    let mut s: Scenario = toml::from_str(text).map_err(ParseError::Toml)?;
    for (i, site) in s.site.iter_mut().enumerate() {
        if let Some(file) = &site.hand_replay {
            let p = Path::new(file);
            let full = match base {
                Some(b) if p.is_relative() => b.join(p),
                _ => p.to_path_buf(),
            };
            let t = crate::trajectory_file::load_trajectory(&full).map_err(|error| {
                ParseError::HandReplay {
                    site: i,
                    file: file.clone(),
                    error: Box::new(error),
                }
            })?;
            site.hand_trajectory = Some(t);
        }
    }
    s.validate().map_err(ParseError::Rule)?;
    Ok(s)
}
