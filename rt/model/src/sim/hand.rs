//! A simulated site's hand: a script of keyframes, or a participant acting on what the site
//! shows; and the live task judge, which reads what the site shows as a participant does.

use crate::body::Vec3;
use crate::participant::{GripFigures, Participant};
use crate::task::{Outcome, TaskFigures, TaskJudge, View};
use crate::user::{target_at, Keyframe};

/// What moves a site's hand.
#[derive(Debug, Clone)]
pub(super) enum Hand {
    /// Keyframes eased between.
    Script(Vec<Keyframe>),
    /// A simulated participant.
    Person(Box<Participant>),
}

impl Hand {
    /// The target the impedance hand follows at `t`, and its velocity.
    pub(super) fn target(&self, t: f64) -> (Vec3, Vec3) {
        match self {
            Hand::Script(s) => target_at(s, t),
            Hand::Person(p) => p.target(t),
        }
    }
}

/// How a site's task went, and what its participant did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteTask {
    /// The task's outcome as the site showed it (`Running` at the end: not decided in time; no
    /// `[task]`: `Running` too, see [`super::RunResult::task`]).
    pub outcome: Outcome,
    /// The participant's grip figures (`None`: a scripted hand).
    pub grip: Option<GripFigures>,
    /// The step the participant was on at the end, and its plan's length.
    pub steps: Option<(usize, usize)>,
}

impl SiteTask {
    /// The figures of a site's run (`None`: the scenario has no `[task]` and the hand is a
    /// script).
    pub fn figures(&self, has_task: bool) -> Option<TaskFigures> {
        if !has_task && self.grip.is_none() {
            return None;
        }
        let (outcome, time_s, failed_by) = match self.outcome {
            Outcome::Running => ("undecided", f64::NAN, String::new()),
            Outcome::Done(t) => ("done", t, String::new()),
            Outcome::Failed(t, None) => ("failed", t, "timeout".to_owned()),
            Outcome::Failed(t, Some(k)) => ("failed", t, format!("fail[{k}]")),
        };
        let g = self.grip.unwrap_or_default();
        let per = |sum: f64, n: u64| if n == 0 { f64::NAN } else { sum / n as f64 };
        Some(TaskFigures {
            outcome: outcome.to_owned(),
            time_s,
            failed_by,
            grip_mean_n: per(g.sum_n, g.ticks),
            grip_peak_n: if g.ticks == 0 { f64::NAN } else { g.peak_n },
            grip_margin: per(g.sum_margin, g.loaded_ticks),
            slips: g.slips,
            steps: self.steps.unwrap_or((0, 0)),
        })
    }
}

/// Steps the task judge and the participant at one servo tick of a site.
pub(super) fn tick(hand: &mut Hand, judge: Option<&mut TaskJudge>, view: &View) {
    if let Hand::Person(p) = hand {
        p.perceive(view);
    }
    if let Some(j) = judge {
        j.judge(view);
    }
}

/// The site's task figures at the end of a run.
pub(super) fn figures(hand: &Hand, judge: Option<&TaskJudge>) -> SiteTask {
    SiteTask {
        outcome: judge.map_or(Outcome::Running, TaskJudge::outcome),
        grip: match hand {
            Hand::Person(p) => Some(p.grip_figures),
            Hand::Script(_) => None,
        },
        steps: match hand {
            Hand::Person(p) => Some((p.step(), p.plan_len())),
            Hand::Script(_) => None,
        },
    }
}
