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
    parse_at(&text, path.parent()).with_context(|| format!("scenario {}", path.display()))
}

/// Parses and validates scenario text (a recorded hand's file relative to the working directory).
///
/// # Errors
/// As [`load`].
pub fn parse(text: &str) -> anyhow::Result<Scenario> {
    parse_at(text, None)
}

/// Parses scenario text, loads its sites' recorded hands (`hand_replay`, relative to `base`) and
/// validates it.
///
/// # Errors
/// As [`load`].
pub fn parse_at(text: &str, base: Option<&Path>) -> anyhow::Result<Scenario> {
    let mut s: Scenario =
        toml::from_str(text).map_err(|e| anyhow::anyhow!("{}", e.to_string().trim_end()))?;
    for (i, site) in s.site.iter_mut().enumerate() {
        if let Some(file) = &site.hand_replay {
            let p = Path::new(file);
            let full = match base {
                Some(b) if p.is_relative() => b.join(p),
                _ => p.to_path_buf(),
            };
            let t = crate::station::device::load_trajectory(&full)
                .with_context(|| format!("invalid value: site[{i}].hand_replay = {file:?}"))?;
            site.hand_trajectory = Some(t);
        }
    }
    s.validate()
        .map_err(|e| anyhow::anyhow!("invalid value: {e}"))?;
    Ok(s)
}
