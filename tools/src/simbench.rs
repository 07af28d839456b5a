//! `sim bench`.
use std::path::Path;
/// Runs the benchmark.
///
/// # Errors
/// Bad scenario.
pub fn run(_scenario: &Path, _json: bool, _quick: bool) -> anyhow::Result<()> {
    Ok(())
}
