//! Scenarios for tests, built from the shipped ones by naming the fields that change: the rest
//! follows the original as it is edited, and a field the original no longer has fails loudly
//! where cutting its text at a marker would silently build another scenario.

use std::path::Path;

use coop_model::scenario::Scenario;

/// A scenario file's TOML, changed field by field, then written or parsed.
///
/// Fields are named by dotted paths: `"duration_s"`, `"network.delay_min_ms"`,
/// `"site.0.script"` (a number picks an element of an array, here the first `[[site]]`).
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioToml(toml::Value);

impl ScenarioToml {
    /// The shipped scenario `scenarios/<file>`.
    ///
    /// # Panics
    /// If it cannot be read or is not TOML.
    pub fn shipped(file: &str) -> Self {
        let path = crate::scenario_path(file);
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        Self::parse(&text)
    }

    /// The paper's experiment, `scenarios/paper.toml`.
    ///
    /// # Panics
    /// As [`ScenarioToml::shipped`].
    pub fn paper() -> Self {
        Self::shipped("paper.toml")
    }

    /// Scenario text.
    ///
    /// # Panics
    /// If it is not TOML.
    pub fn parse(text: &str) -> Self {
        let table: toml::Table =
            toml::from_str(text).unwrap_or_else(|e| panic!("scenario TOML: {e}"));
        Self(toml::Value::Table(table))
    }

    /// Sets the field at `path` to `value`. Every step but the last must exist; the last may be
    /// new (a field the original leaves to its default).
    ///
    /// # Panics
    /// If a step before the last is missing or not a table or array.
    #[must_use]
    pub fn set(mut self, path: &str, value: impl Into<toml::Value>) -> Self {
        let (parent, last) = self.parent_mut(path);
        match parent {
            toml::Value::Table(t) => {
                t.insert(last.to_owned(), value.into());
            }
            toml::Value::Array(a) => {
                let slot = last
                    .parse::<usize>()
                    .ok()
                    .and_then(|i| a.get_mut(i))
                    .unwrap_or_else(|| panic!("{path}: no element {last}"));
                *slot = value.into();
            }
            other => panic!("{path}: {other} holds no fields"),
        }
        self
    }

    /// Sets the field at `path` to a value written as TOML, as in a scenario file:
    /// `"[{ t_s = 0.0, target_m = [-0.2, 0.0, 0.01] }]"`.
    ///
    /// # Panics
    /// If `value` is not a TOML value, or as [`ScenarioToml::set`].
    #[must_use]
    pub fn set_toml(self, path: &str, value: &str) -> Self {
        let mut one: toml::Table = toml::from_str(&format!("v = {value}"))
            .unwrap_or_else(|e| panic!("{path} = {value}: {e}"));
        let v = one.remove("v").expect("the value just parsed");
        self.set(path, v)
    }

    /// Removes the field at `path` (`"phase"`: every `[[phase]]`).
    ///
    /// # Panics
    /// If it is not there.
    #[must_use]
    pub fn remove(mut self, path: &str) -> Self {
        let (parent, last) = self.parent_mut(path);
        let gone = match parent {
            toml::Value::Table(t) => t.remove(last).is_some(),
            toml::Value::Array(a) => match last.parse::<usize>() {
                Ok(i) if i < a.len() => {
                    a.remove(i);
                    true
                }
                _ => false,
            },
            _ => false,
        };
        assert!(gone, "{path}: not in the scenario");
        self
    }

    /// The field at `path`, if it is there.
    pub fn get(&self, path: &str) -> Option<&toml::Value> {
        path.split('.').try_fold(&self.0, |at, step| match at {
            toml::Value::Table(t) => t.get(step),
            toml::Value::Array(a) => a.get(step.parse::<usize>().ok()?),
            _ => None,
        })
    }

    /// As TOML text.
    ///
    /// # Panics
    /// If the table cannot be written as TOML (it always can).
    pub fn text(&self) -> String {
        toml::to_string(&self.0).expect("a TOML table as text")
    }

    /// Writes it to `path`.
    ///
    /// # Panics
    /// If the file cannot be written.
    pub fn write(&self, path: &Path) {
        std::fs::write(path, self.text())
            .unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
    }

    /// Parsed and validated as a scenario, as `sim` would (a recorded hand relative to the
    /// working directory).
    ///
    /// # Panics
    /// If it is refused (the error is shown).
    pub fn scenario(&self) -> Scenario {
        coop_actors::scenario_file::parse(&self.text()).unwrap_or_else(|e| panic!("{e:#}"))
    }

    /// The table or array holding the last step of `path`, and that step.
    fn parent_mut<'a>(&mut self, path: &'a str) -> (&mut toml::Value, &'a str) {
        let (before, last) = path.rsplit_once('.').map_or(("", path), |(b, l)| (b, l));
        let mut at = Some(&mut self.0);
        for step in before.split('.').filter(|s| !s.is_empty()) {
            at = match at {
                Some(toml::Value::Table(t)) => t.get_mut(step),
                Some(toml::Value::Array(a)) => {
                    step.parse::<usize>().ok().and_then(|i| a.get_mut(i))
                }
                _ => None,
            };
        }
        let parent = at.unwrap_or_else(|| panic!("{path}: {before} not in the scenario"));
        (parent, last)
    }
}
