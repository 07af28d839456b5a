//! A participant's task plan as a scenario writes it (`[[site.plan]]`), checked and resolved to
//! the objects' indices.

use crate::body::Vec3;
use crate::rules::{bounded, err, finite3, in_closed, ScenarioError};
use crate::task::{find_object, Condition, ConditionSpec};

/// What a step does.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(rename_all = "lowercase")
)]
pub enum Action {
    /// Reach a point (`to_m`) or an object's face (`object`, `side`, `gap_m` short of it).
    #[default]
    Reach,
    /// Push an object from its `side` face, `depth_m` past that face as seen when the push began;
    /// with `until`, push on until it holds.
    Push,
    /// Press on an object's `side` face until the felt normal force reaches `force_n`, and keep
    /// gripping (against slip) until a release.
    Grasp,
    /// Move the gripped object by `by_m` (in `for_s`, else in Fitts' time), until it is seen
    /// there.
    Carry,
    /// Let go: back off along the gripped (or last) side by `away_m`.
    Release,
    /// Hold still until `until` holds, or for `for_s`.
    Wait,
}

/// One step of a plan.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct StepSpec {
    /// What the step does.
    #[cfg_attr(feature = "serde", serde(rename = "do"))]
    pub action: Action,
    /// The object it is about (by name).
    pub object: Option<String>,
    /// The face taken: a direction from the object's centre, world (normalized here).
    pub side: Option<[f64; 3]>,
    /// A reach's point, world, m (instead of an object's face).
    pub to_m: Option<[f64; 3]>,
    /// How far short of the face a reach ends, m.
    pub gap_m: f64,
    /// How far past the face a push aims, m.
    pub depth_m: f64,
    /// The normal force a grasp presses with at least, N.
    pub force_n: f64,
    /// A carry's displacement of the object, world, m.
    pub by_m: Option<[f64; 3]>,
    /// How far a release backs off, m.
    pub away_m: f64,
    /// A wait's (or a push's) condition, on what the site shows.
    pub until: Option<ConditionSpec>,
    /// A wait's length, or a carry's, s.
    pub for_s: f64,
}

/// A step with its objects found and its values checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// What it does.
    pub action: Action,
    /// Its object.
    pub object: Option<usize>,
    /// Its face's direction, unit.
    pub side: Vec3,
    /// A reach's fixed point.
    pub to: Option<Vec3>,
    /// See [`StepSpec`].
    pub gap_m: f64,
    /// See [`StepSpec`].
    pub depth_m: f64,
    /// See [`StepSpec`].
    pub force_n: f64,
    /// See [`StepSpec`].
    pub by: Vec3,
    /// See [`StepSpec`].
    pub away_m: f64,
    /// See [`StepSpec`].
    pub until: Option<Condition>,
    /// See [`StepSpec`].
    pub for_s: f64,
}

impl StepSpec {
    /// Checks the step; `at` names it in errors (`site[0].plan[2]`).
    ///
    /// # Errors
    /// The first field that breaks a rule or does not belong to the step's action.
    pub fn resolve(&self, at: &str, names: &[&str]) -> Result<Step, ScenarioError> {
        let f = |name: &str| format!("{at}.{name}");
        let object = self
            .object
            .as_deref()
            .map(|n| find_object(&f("object"), n, names))
            .transpose()?;
        let side = match self.side {
            Some(s) => {
                finite3(&f("side"), &s, 100.0)?;
                let v = Vec3::from(s);
                if v.norm() < 1e-6 {
                    return Err(err(f("side"), s, "a direction: not zero"));
                }
                v.normalize()
            }
            None => Vec3::zeros(),
        };
        let act = self.action;
        let needs = |field: &str, given: bool| {
            if given {
                Ok(())
            } else {
                Err(err(
                    f(field),
                    "none",
                    format!("a {act:?} step needs it").to_lowercase(),
                ))
            }
        };
        match act {
            Action::Reach => {
                if self.to_m.is_none() {
                    needs("object", object.is_some())?;
                    needs("side", self.side.is_some())?;
                }
            }
            Action::Push | Action::Grasp => {
                needs("object", object.is_some())?;
                needs("side", self.side.is_some())?;
            }
            Action::Carry => needs("by_m", self.by_m.is_some())?,
            Action::Wait => needs("until or for_s", self.until.is_some() || self.for_s > 0.0)?,
            Action::Release => {}
        }
        if let Some(t) = &self.to_m {
            finite3(&f("to_m"), t, 100.0)?;
        }
        if let Some(b) = &self.by_m {
            finite3(&f("by_m"), b, 1.0)?;
        }
        in_closed(&f("gap_m"), self.gap_m, 0.0, 0.5)?;
        in_closed(&f("depth_m"), self.depth_m, 0.0, 0.2)?;
        in_closed(&f("away_m"), self.away_m, 0.0, 0.5)?;
        in_closed(&f("for_s"), self.for_s, 0.0, 3600.0)?;
        if act == Action::Grasp {
            bounded(&f("force_n"), self.force_n, 0.01, 50.0, "N")?;
        }
        Ok(Step {
            action: act,
            object,
            side,
            to: self.to_m.map(Vec3::from),
            gap_m: self.gap_m,
            depth_m: self.depth_m,
            force_n: self.force_n,
            by: self.by_m.map_or(Vec3::zeros(), Vec3::from),
            away_m: if self.away_m > 0.0 { self.away_m } else { 0.1 },
            until: self
                .until
                .as_ref()
                .map(|c| c.resolve(&f("until"), names))
                .transpose()?,
            for_s: self.for_s,
        })
    }
}
