//! Live task goals: when a site's task is done and when it has failed, judged on what that site
//! shows (its copy as displayed, and what its own tool touches), tick by tick, as a participant
//! would judge it. A condition is a conjunction of clauses on one object and the own tool.

use crate::body::{BodyState, Vec3};
use crate::rules::{bounded, err, finite3, ScenarioError};
use crate::world::MAX_OBJECTS;

/// A condition as a scenario writes it: every clause given must hold.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct ConditionSpec {
    /// The object the clauses below are about (by name).
    pub object: Option<String>,
    /// Its centre inside this box, `[min, max]`, world, m.
    pub in_region_m: Option<[[f64; 3]; 2]>,
    /// Its centre outside this box, world, m (a spill, a drop beside the table).
    pub outside_region_m: Option<[[f64; 3]; 2]>,
    /// Its speed below this, m/s.
    pub still_m_s: Option<f64>,
    /// Moved at least this far from where it was when the condition began to be asked, m.
    pub moved_m: Option<f64>,
    /// Its centre below this height, m (fallen off the table).
    pub below_m: Option<f64>,
    /// The own tool touches this object (by name).
    pub felt: Option<String>,
    /// The own tool touches nothing.
    pub released: bool,
    /// At least this long since the start, s: a cue all sites share (a go signal).
    pub after_s: Option<f64>,
}

/// A condition with its objects found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Condition {
    object: Option<usize>,
    in_region: Option<(Vec3, Vec3)>,
    outside_region: Option<(Vec3, Vec3)>,
    still: Option<f64>,
    moved: Option<f64>,
    below: Option<f64>,
    felt: Option<usize>,
    released: bool,
    after: Option<f64>,
}

/// What a site shows and feels at one instant: what conditions and participants read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// When, s.
    pub t_s: f64,
    /// How many objects the world has.
    pub objects: usize,
    /// Each object as shown.
    pub shown: [BodyState; MAX_OBJECTS],
    /// What the own tool feels of each object: the force it puts on the object, N (zero when
    /// not touching).
    pub felt: [Vec3; MAX_OBJECTS],
    /// Whether the own tool touches each object.
    pub touching: [bool; MAX_OBJECTS],
    /// Whether that contact's friction slips.
    pub slipping: [bool; MAX_OBJECTS],
    /// The own tool's position, world, m.
    pub tool: Vec3,
}

impl View {
    /// Nothing shown yet, the tool at `tool`.
    pub fn empty(tool: Vec3) -> Self {
        Self {
            t_s: 0.0,
            objects: 0,
            shown: [BodyState::at_rest(Vec3::zeros()); MAX_OBJECTS],
            felt: [Vec3::zeros(); MAX_OBJECTS],
            touching: [false; MAX_OBJECTS],
            slipping: [false; MAX_OBJECTS],
            tool,
        }
    }

    /// What a site shows at `t_s` (session time): its objects as `shown`, its own tool at `tool`
    /// and that tool's `contacts` with each object (what the simulator's servo tick and a
    /// station's read alike).
    pub fn of(
        t_s: f64,
        shown: &[BodyState],
        contacts: &[crate::contact::ContactForce],
        tool: Vec3,
    ) -> Self {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let mut v = View::empty(tool);
        v.t_s = t_s;
        v.objects = shown.len().min(MAX_OBJECTS);
        v.shown[..v.objects].copy_from_slice(&shown[..v.objects]);
        for (k, c) in contacts.iter().enumerate().take(MAX_OBJECTS) {
            v.touching[k] = c.touching;
            v.slipping[k] = c.touching && c.slipping;
            v.felt[k] = if c.touching { c.force } else { Vec3::zeros() };
        }
        v
    }

    /// The objects' centres, for a condition's `moved_m` origin.
    pub fn centres(&self) -> [Vec3; MAX_OBJECTS] {
        self.shown.map(|s| s.pos)
    }
}

/// Object `name`'s index in `names`, or the error naming `field` and the objects there are.
///
/// # Errors
/// `name` is not in `names`.
pub fn find_object(field: &str, name: &str, names: &[&str]) -> Result<usize, ScenarioError> {
    names.iter().position(|m| *m == name).ok_or_else(|| {
        err(
            field,
            name,
            format!(
                "names no object of the scenario (its objects: {})",
                names.join(", ")
            ),
        )
    })
}

fn region(field: &str, r: &[[f64; 3]; 2]) -> Result<(Vec3, Vec3), ScenarioError> {
    finite3(&format!("{field}[0]"), &r[0], 100.0)?;
    finite3(&format!("{field}[1]"), &r[1], 100.0)?;
    if (0..3).any(|k| r[0][k] > r[1][k]) {
        return Err(err(
            field,
            r,
            "is [min, max]: each of min's coordinates at most max's",
        ));
    }
    Ok((Vec3::from(r[0]), Vec3::from(r[1])))
}

impl ConditionSpec {
    /// Checks the clauses and finds the objects in `names`; `field` names the condition in
    /// errors.
    ///
    /// # Errors
    /// The first clause that breaks a rule, or an object that is not in `names`.
    pub fn resolve(&self, field: &str, names: &[&str]) -> Result<Condition, ScenarioError> {
        let find = |f: &str, n: &str| find_object(&format!("{field}.{f}"), n, names);
        let object = self
            .object
            .as_deref()
            .map(|n| find("object", n))
            .transpose()?;
        let felt = self.felt.as_deref().map(|n| find("felt", n)).transpose()?;
        let about_object = self.in_region_m.is_some()
            || self.outside_region_m.is_some()
            || self.still_m_s.is_some()
            || self.moved_m.is_some()
            || self.below_m.is_some();
        if about_object && object.is_none() {
            return Err(err(
                format!("{field}.object"),
                "none",
                "in_region_m, outside_region_m, still_m_s, moved_m and below_m are about an object: name it",
            ));
        }
        if !about_object && felt.is_none() && !self.released && self.after_s.is_none() {
            return Err(err(
                field,
                "{}",
                "a condition needs a clause (in_region_m, outside_region_m, still_m_s, moved_m, below_m, felt, released, after_s)",
            ));
        }
        if let Some(v) = self.after_s {
            crate::rules::in_closed(&format!("{field}.after_s"), v, 0.0, 3600.0)?;
        }
        if let Some(v) = self.still_m_s {
            bounded(&format!("{field}.still_m_s"), v, 1e-4, 10.0, "m/s")?;
        }
        if let Some(v) = self.moved_m {
            bounded(&format!("{field}.moved_m"), v, 1e-4, 10.0, "m")?;
        }
        if let Some(v) = self.below_m {
            crate::rules::in_closed(&format!("{field}.below_m"), v, -100.0, 100.0)?;
        }
        Ok(Condition {
            object,
            in_region: self
                .in_region_m
                .as_ref()
                .map(|r| region(&format!("{field}.in_region_m"), r))
                .transpose()?,
            outside_region: self
                .outside_region_m
                .as_ref()
                .map(|r| region(&format!("{field}.outside_region_m"), r))
                .transpose()?,
            still: self.still_m_s,
            moved: self.moved_m,
            below: self.below_m,
            felt,
            released: self.released,
            after: self.after_s,
        })
    }
}

fn inside(p: Vec3, (lo, hi): (Vec3, Vec3)) -> bool {
    (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k])
}

impl Condition {
    /// Whether it holds in `view`, with `origin` the objects' centres when it began to be asked.
    pub fn holds(&self, view: &View, origin: &[Vec3; MAX_OBJECTS]) -> bool {
        if let Some(k) = self.felt {
            if !view.touching[k] {
                return false;
            }
        }
        if self.released && view.touching[..view.objects].iter().any(|&t| t) {
            return false;
        }
        if self.after.is_some_and(|a| view.t_s < a) {
            return false;
        }
        let Some(k) = self.object else {
            return true;
        };
        let s = &view.shown[k];
        self.in_region.is_none_or(|r| inside(s.pos, r))
            && self.outside_region.is_none_or(|r| !inside(s.pos, r))
            && self.still.is_none_or(|v| s.vel.norm() < v)
            && self.moved.is_none_or(|d| (s.pos - origin[k]).norm() >= d)
            && self.below.is_none_or(|z| s.pos.z < z)
    }
}

/// A scenario's `[task]`: when a site's task is done and when it has failed.
#[derive(Debug, Clone, Default, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct TaskSpec {
    /// Done when this holds at the site for `hold_s`.
    pub done: Option<ConditionSpec>,
    /// And each of these with it (a condition is about one object: a task on several objects
    /// names the others here).
    pub done_also: Vec<ConditionSpec>,
    /// How long `done` must hold, s.
    pub hold_s: f64,
    /// Failed when not done by then, s from the start (0: the scenario's duration).
    pub timeout_s: f64,
    /// Failed as soon as any of these holds (an object dropped, a cup spilled).
    pub fail: Vec<ConditionSpec>,
}

/// How a site's task ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// Not yet decided.
    Running,
    /// Done: the goal began to hold at this time, s (and held for the hold time).
    Done(f64),
    /// Failed at this time, s: the fail condition that held (its index), or `None` for the
    /// timeout.
    Failed(f64, Option<usize>),
}

/// A site's task, judged live.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskJudge {
    done: Condition,
    done_also: Vec<Condition>,
    hold_s: f64,
    timeout_s: f64,
    fail: Vec<Condition>,
    origin: Option<[Vec3; MAX_OBJECTS]>,
    since: Option<f64>,
    outcome: Outcome,
}

impl TaskSpec {
    /// Checks it against the scenario's objects and its duration.
    ///
    /// # Errors
    /// The first rule broken, naming the `task.` field.
    pub fn judge(
        &self,
        names: &[&str],
        duration_s: f64,
    ) -> Result<Option<TaskJudge>, ScenarioError> {
        let Some(done) = &self.done else {
            if !self.fail.is_empty()
                || !self.done_also.is_empty()
                || self.hold_s != 0.0
                || self.timeout_s != 0.0
            {
                return Err(err("task.done", "none", "a task needs its done condition"));
            }
            return Ok(None);
        };
        crate::rules::in_closed("task.hold_s", self.hold_s, 0.0, 3600.0)?;
        crate::rules::in_closed("task.timeout_s", self.timeout_s, 0.0, duration_s).map_err(
            |e| ScenarioError {
                rule: format!("{} (the scenario's duration_s; 0: all of it)", e.rule),
                ..e
            },
        )?;
        let fail = resolve_each(&self.fail, "task.fail", names)?;
        let done_also = resolve_each(&self.done_also, "task.done_also", names)?;
        Ok(Some(TaskJudge {
            done: done.resolve("task.done", names)?,
            done_also,
            hold_s: self.hold_s,
            timeout_s: if self.timeout_s > 0.0 {
                self.timeout_s
            } else {
                duration_s
            },
            fail,
            origin: None,
            since: None,
            outcome: Outcome::Running,
        }))
    }
}

/// Each condition of a list, its objects found; errors name `field[k]`.
fn resolve_each(
    list: &[ConditionSpec],
    field: &str,
    names: &[&str],
) -> Result<Vec<Condition>, ScenarioError> {
    list.iter()
        .enumerate()
        .map(|(k, c)| c.resolve(&format!("{field}[{k}]"), names))
        .collect()
}

impl TaskJudge {
    /// Judges one instant of what the site shows; the outcome once decided stays.
    pub fn judge(&mut self, view: &View) -> Outcome {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls (a station's servo judges).
        if self.outcome != Outcome::Running || view.objects == 0 {
            return self.outcome;
        }
        let origin = *self.origin.get_or_insert_with(|| view.centres());
        if let Some(k) = self.fail.iter().position(|c| c.holds(view, &origin)) {
            self.outcome = Outcome::Failed(view.t_s, Some(k));
            return self.outcome;
        }
        if self.done.holds(view, &origin) && self.done_also.iter().all(|c| c.holds(view, &origin)) {
            let since = *self.since.get_or_insert(view.t_s);
            if view.t_s - since >= self.hold_s {
                self.outcome = Outcome::Done(since);
            }
        } else {
            self.since = None;
        }
        if self.outcome == Outcome::Running && view.t_s >= self.timeout_s {
            self.outcome = Outcome::Failed(view.t_s, None);
        }
        self.outcome
    }

    /// The run ended at `t_s`: a task still undecided was not done in time.
    pub fn finish(&mut self, t_s: f64) {
        if self.outcome == Outcome::Running {
            self.outcome = Outcome::Failed(t_s, None);
        }
    }

    /// The outcome so far.
    pub fn outcome(&self) -> Outcome {
        self.outcome
    }
}

/// A site's task as the metrics and the tables give it.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct TaskFigures {
    /// `done`, `failed` or `undecided` (no outcome when the run ended).
    pub outcome: String,
    /// When the goal began to hold (done) or the failure happened, s (NaN: undecided).
    pub time_s: f64,
    /// What failed it: `timeout` or `fail[k]` (empty otherwise).
    pub failed_by: String,
    /// The participant's mean felt normal force while gripping, N (NaN: no grip or a script).
    pub grip_mean_n: f64,
    /// Its largest, N (NaN as above).
    pub grip_peak_n: f64,
    /// Its mean margin over what friction needed for the felt load (0.25: 25 % over the slip
    /// limit; NaN: never loaded).
    pub grip_margin: f64,
    /// Slips the participant's grip answered.
    pub slips: u64,
    /// Steps of the plan done, and its length (0 and 0 for a script).
    pub steps: (usize, usize),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(t_s: f64, pos: Vec3, touching: bool) -> View {
        let mut v = View::empty(Vec3::zeros());
        v.t_s = t_s;
        v.objects = 1;
        v.shown[0] = BodyState::at_rest(pos);
        v.touching[0] = touching;
        v
    }

    fn spec() -> TaskSpec {
        TaskSpec {
            done: Some(ConditionSpec {
                object: Some("disk".into()),
                in_region_m: Some([[0.0, 0.03, -1.0], [0.1, 0.1, 1.0]]),
                released: true,
                ..ConditionSpec::default()
            }),
            done_also: vec![],
            hold_s: 0.5,
            timeout_s: 0.0,
            fail: vec![ConditionSpec {
                object: Some("disk".into()),
                below_m: Some(-0.05),
                ..ConditionSpec::default()
            }],
        }
    }

    #[test]
    fn done_once_the_goal_held_for_the_hold_time_timed_from_its_start() {
        let mut j = spec().judge(&["disk"], 10.0).unwrap().unwrap();
        let there = Vec3::new(0.05, 0.05, 0.01);
        assert_eq!(j.judge(&view(1.0, there, true)), Outcome::Running);
        assert_eq!(j.judge(&view(1.1, there, false)), Outcome::Running);
        // Touched again: the hold starts over.
        assert_eq!(j.judge(&view(1.3, there, true)), Outcome::Running);
        assert_eq!(j.judge(&view(1.4, there, false)), Outcome::Running);
        assert_eq!(j.judge(&view(1.89, there, false)), Outcome::Running);
        assert_eq!(j.judge(&view(1.9, there, false)), Outcome::Done(1.4));
        assert_eq!(
            j.judge(&view(2.0, Vec3::new(0.0, 0.0, -1.0), false)),
            Outcome::Done(1.4)
        );
    }

    #[test]
    fn done_only_while_every_further_condition_holds_too() {
        let mut s = spec();
        s.done_also = vec![ConditionSpec {
            object: Some("puck".into()),
            moved_m: Some(0.02),
            ..ConditionSpec::default()
        }];
        let mut j = s.judge(&["disk", "puck"], 10.0).unwrap().unwrap();
        let there = Vec3::new(0.05, 0.05, 0.01);
        let two = |t_s: f64, puck_x: f64| {
            let mut v = view(t_s, there, false);
            v.objects = 2;
            v.shown[1] = BodyState::at_rest(Vec3::new(puck_x, 0.0, 0.0));
            v
        };
        // The disk is where it should be, the puck not yet moved: not done, however long.
        assert_eq!(j.judge(&two(1.0, 0.0)), Outcome::Running);
        assert_eq!(j.judge(&two(2.0, 0.01)), Outcome::Running);
        // Moved far enough: the hold starts then.
        assert_eq!(j.judge(&two(2.5, 0.03)), Outcome::Running);
        assert_eq!(j.judge(&two(3.0, 0.03)), Outcome::Done(2.5));
        s.done_also[0].object = Some("cup".into());
        assert_eq!(
            s.judge(&["disk", "puck"], 10.0).unwrap_err().field,
            "task.done_also[0].object"
        );
        let lone = TaskSpec {
            done: None,
            fail: vec![],
            hold_s: 0.0,
            ..s
        };
        assert_eq!(
            lone.judge(&["disk", "puck"], 10.0).unwrap_err().field,
            "task.done"
        );
    }

    #[test]
    fn a_drop_or_the_timeout_fails_it() {
        let mut j = spec().judge(&["disk"], 10.0).unwrap().unwrap();
        assert_eq!(
            j.judge(&view(2.0, Vec3::new(0.0, 0.0, -0.2), false)),
            Outcome::Failed(2.0, Some(0))
        );
        let mut j = spec().judge(&["disk"], 10.0).unwrap().unwrap();
        assert_eq!(
            j.judge(&view(10.0, Vec3::zeros(), false)),
            Outcome::Failed(10.0, None)
        );
    }

    #[test]
    fn bad_conditions_name_their_field() {
        let mut s = spec();
        s.done.as_mut().unwrap().object = Some("cup".into());
        let e = s.judge(&["disk"], 10.0).unwrap_err();
        assert_eq!(e.field, "task.done.object");
        assert!(e.rule.contains("its objects: disk"), "{e}");
        let mut s = spec();
        s.fail[0].object = None;
        assert_eq!(
            s.judge(&["disk"], 10.0).unwrap_err().field,
            "task.fail[0].object"
        );
        let mut s = spec();
        s.done.as_mut().unwrap().in_region_m = Some([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]]);
        assert_eq!(
            s.judge(&["disk"], 10.0).unwrap_err().field,
            "task.done.in_region_m"
        );
        let s = TaskSpec {
            timeout_s: 20.0,
            ..spec()
        };
        assert_eq!(
            s.judge(&["disk"], 10.0).unwrap_err().field,
            "task.timeout_s"
        );
    }
}
