//! Scenario files: TOML in, a validated [`Scenario`] out, or an error that names the file and the
//! field, the value and the rule (unknown fields included).

use std::path::Path;

use anyhow::Context;
use coop_model::scenario::Scenario;

/// Reads, parses and validates a scenario file.
///
/// # Errors
/// The file cannot be read, is not valid TOML for a scenario (unknown field, wrong type), or breaks
/// a rule of [`Scenario::validate`].
pub fn load(path: &Path) -> anyhow::Result<Scenario> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("reading scenario {}", path.display()))?;
    parse(&text).with_context(|| format!("scenario {}", path.display()))
}

/// Parses and validates scenario text.
///
/// # Errors
/// As [`load`].
pub fn parse(text: &str) -> anyhow::Result<Scenario> {
    let s: Scenario =
        toml::from_str(text).map_err(|e| anyhow::anyhow!("{}", e.to_string().trim_end()))?;
    s.validate()
        .map_err(|e| anyhow::anyhow!("invalid value: {e}"))?;
    Ok(s)
}
