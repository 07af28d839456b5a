//! Plots: placeholder replaced below.
use coop_model::{scenario::Scenario, sim::RunResult};
use std::path::Path;
/// Draws the figures.
///
/// # Errors
/// Never yet.
pub fn figures(
    _dir: &Path,
    _sc: &Scenario,
    _r: &RunResult,
    _reference: &RunResult,
) -> anyhow::Result<()> {
    Ok(())
}
