//! What the study runner and its web page share: the progress, the experimenter's controls
//! (pause, resume, abort) and the questionnaires waiting for an answer.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::Duration;

use super::questionnaire::QuestionnaireSpec;

/// The experimenter's say over the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    /// Trials run.
    Running,
    /// No new block starts (the one running finishes).
    Paused,
    /// The run stops after the trials running; `--resume` goes on from there.
    Aborted,
}

/// How a wait for the questionnaires ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Waited {
    /// Every one owed is answered.
    Answered,
    /// The experimenter aborted the run.
    Aborted,
    /// The experimenter asked for the last trial again.
    Repeat,
}

/// A questionnaire a participant owes.
#[derive(Debug, Clone, PartialEq)]
pub struct Pending {
    /// The group's id.
    pub group: String,
    /// The participant's id.
    pub participant: String,
    /// Their site.
    pub site: String,
    /// The block just done.
    pub block: usize,
    /// Its condition's levels, one per factor.
    pub levels: Vec<String>,
}

/// The run as the page shows it.
#[derive(Debug, Clone)]
pub struct Board {
    /// The study's name.
    pub study: String,
    /// Trials in all, and done.
    pub total: usize,
    /// See `total`.
    pub done: usize,
    /// What runs now.
    pub now: String,
    /// The last trials' outcomes, newest first.
    pub recent: VecDeque<String>,
    /// The experimenter's say.
    pub control: Control,
    /// Every trial run (or the run aborted).
    pub finished: bool,
    /// Questionnaires owed.
    pub pending: Vec<Pending>,
    /// Questionnaires answered in this run.
    pub answered: usize,
    /// The experimenter closed the page (after the run finished): the runner exits.
    pub closed: bool,
    /// The experimenter asked for the last trial again (its next attempt).
    pub repeat: bool,
}

/// The board behind a lock, and a signal for whoever waits on it.
#[derive(Debug)]
pub struct Shared {
    board: Mutex<Board>,
    /// Held while an answer is checked, stored and taken off the owed list.
    answering: Mutex<()>,
    changed: Condvar,
    /// The questionnaire (none: nothing is asked).
    pub questionnaire: Option<QuestionnaireSpec>,
    /// The factors' names (the answers' columns).
    pub factors: Vec<String>,
}

/// How many outcomes the page lists.
const RECENT: usize = 10;

impl Shared {
    /// A board for `study`'s `total` trials.
    pub fn new(
        study: &str,
        total: usize,
        questionnaire: Option<QuestionnaireSpec>,
        factors: Vec<String>,
    ) -> Self {
        Self {
            board: Mutex::new(Board {
                study: study.to_owned(),
                total,
                done: 0,
                now: "starting".into(),
                recent: VecDeque::new(),
                control: Control::Running,
                finished: false,
                pending: Vec::new(),
                answered: 0,
                closed: false,
                repeat: false,
            }),
            answering: Mutex::new(()),
            changed: Condvar::new(),
            questionnaire,
            factors,
        }
    }

    /// The board (a poisoned lock is taken over: the board is plain data).
    pub fn lock(&self) -> MutexGuard<'_, Board> {
        self.board
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// One answer at a time: held by the page from the check that an answer is owed to its
    /// removal from the owed list.
    pub fn answering(&self) -> MutexGuard<'_, ()> {
        self.answering
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Changes the board and wakes whoever waits on it.
    pub fn update(&self, f: impl FnOnce(&mut Board)) {
        f(&mut self.lock());
        self.changed.notify_all();
    }

    /// A trial's outcome, for the page.
    pub fn trial_done(&self, line: String) {
        self.update(|b| {
            b.done += 1;
            b.recent.push_front(line);
            b.recent.truncate(RECENT);
        });
    }

    /// A repeated trial's outcome, for the page (the count of trials does not change).
    pub fn trial_repeated(&self, line: String) {
        self.update(|b| {
            b.recent.push_front(line);
            b.recent.truncate(RECENT);
        });
    }

    /// Waits while the run is paused; false when it is aborted.
    pub fn may_go_on(&self) -> bool {
        let mut b = self.lock();
        loop {
            match b.control {
                Control::Running => return true,
                Control::Aborted => return false,
                Control::Paused => {
                    b = self
                        .changed
                        .wait_timeout(b, Duration::from_millis(500))
                        .unwrap_or_else(std::sync::PoisonError::into_inner)
                        .0;
                }
            }
        }
    }

    /// Waits until the experimenter closes the page.
    pub fn wait_closed(&self) {
        let mut b = self.lock();
        while !b.closed {
            b = self
                .changed
                .wait_timeout(b, Duration::from_millis(500))
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
    }

    /// Takes the experimenter's ask for a repeat, if any.
    pub fn take_repeat(&self) -> bool {
        std::mem::take(&mut self.lock().repeat)
    }

    /// Waits until nothing is owed, the run is aborted, or a repeat is asked for.
    pub fn wait_answers(&self) -> Waited {
        let mut b = self.lock();
        loop {
            if b.control == Control::Aborted {
                return Waited::Aborted;
            }
            if std::mem::take(&mut b.repeat) {
                return Waited::Repeat;
            }
            if b.pending.is_empty() {
                return Waited::Answered;
            }
            b = self
                .changed
                .wait_timeout(b, Duration::from_millis(500))
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .0;
        }
    }
}
