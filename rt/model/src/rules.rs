//! The rules a scenario's values keep, and the error that names the one broken: shared by every
//! part of a scenario that validates itself (the scenario, its display settings).

/// A scenario value breaks a rule.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScenarioError {
    /// Field path, e.g. `site[1].servo_rate_hz`.
    pub field: String,
    /// The value found.
    pub value: String,
    /// The rule it breaks.
    pub rule: String,
}

impl std::fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} = {}: {}", self.field, self.value, self.rule)
    }
}

impl std::error::Error for ScenarioError {}

pub(crate) fn err(
    field: impl Into<String>,
    value: impl std::fmt::Debug,
    rule: impl Into<String>,
) -> ScenarioError {
    ScenarioError {
        field: field.into(),
        value: format!("{value:?}"),
        rule: rule.into(),
    }
}

/// `lo < v <= hi` and finite (NaN fails: positive containment, H8).
pub(crate) fn in_range(field: &str, v: f64, lo: f64, hi: f64) -> Result<(), ScenarioError> {
    if v > lo && v <= hi && v.is_finite() {
        Ok(())
    } else {
        Err(err(
            field,
            v,
            format!("must be a finite number above {lo} and at most {hi}"),
        ))
    }
}

/// `lo <= v <= hi` and finite.
pub(crate) fn in_closed(field: &str, v: f64, lo: f64, hi: f64) -> Result<(), ScenarioError> {
    if v >= lo && v <= hi && v.is_finite() {
        Ok(())
    } else {
        Err(err(
            field,
            v,
            format!("must be a finite number from {lo} to {hi}"),
        ))
    }
}

pub(crate) fn finite3(field: &str, v: &[f64; 3], bound: f64) -> Result<(), ScenarioError> {
    if v.iter().all(|x| x.is_finite() && x.abs() <= bound) {
        Ok(())
    } else {
        Err(err(
            field,
            v,
            format!("every component must be finite and within ±{bound}"),
        ))
    }
}

/// `lo <= v <= hi` and finite, with the unit in the rule: a lower bound that keeps the value
/// meaningful (a rate of 1e-300 Hz, a mass of 1e-300 kg), not only positive.
pub(crate) fn bounded(
    field: &str,
    v: f64,
    lo: f64,
    hi: f64,
    unit: &str,
) -> Result<(), ScenarioError> {
    if v >= lo && v <= hi && v.is_finite() {
        Ok(())
    } else {
        Err(err(
            field,
            v,
            format!("must be a finite number from {lo} to {hi} {unit}"),
        ))
    }
}
