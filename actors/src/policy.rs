//! When a child that exited is started again: a restart policy as data (dora's fields), per child.
//!
//! A station's children do not matter equally, and [`ChildPolicy`] says how much each does:
//!
//! - the servo and physics loops are [`ChildPolicy::Essential`]: they follow the station's
//!   `[supervisor]` [`RestartPolicy`] — restarted after a failure (per `restart`), the delay
//!   doubling from `backoff_initial_ms` up to `backoff_max_ms`, at most `max_restarts` times within
//!   `restart_window_s`; one more failure, or an exit the policy does not restart, stops the station;
//! - the network process is [`ChildPolicy::Degradable`]: the station goes on locally without it
//!   (degraded, and saying so), and it is restarted after every exit, without limit, the delay
//!   doubling from `backoff_initial_ms` with each failure since it last came up, capped at
//!   `network_backoff_max_ms`. Its failures never stop the station.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// Which exits lead to a restart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RestartMode {
    /// Never restart: any exit of a child ends the station.
    Never,
    /// Restart after a failure (non-zero exit, signal, hung heartbeat); a clean exit ends the station.
    OnFailure,
    /// Restart after any exit.
    Always,
}

impl std::fmt::Display for RestartMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Never => "never",
            Self::OnFailure => "on-failure",
            Self::Always => "always",
        })
    }
}

impl std::str::FromStr for RestartMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "never" => Ok(Self::Never),
            "on-failure" => Ok(Self::OnFailure),
            "always" => Ok(Self::Always),
            _ => Err(format!(
                "unknown restart mode {s:?}: use never, on-failure or always"
            )),
        }
    }
}

/// The policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RestartPolicy {
    /// Which exits restart.
    pub mode: RestartMode,
    /// Most restarts of one child within `window`; one more ends the station.
    pub max_restarts: u32,
    /// The window restarts are counted in.
    pub window: Duration,
    /// Delay before the first restart; it doubles with each restart in the window.
    pub backoff_initial: Duration,
    /// Longest delay.
    pub backoff_max: Duration,
}

impl Default for RestartPolicy {
    fn default() -> Self {
        Self {
            mode: RestartMode::OnFailure,
            max_restarts: 3,
            window: Duration::from_secs(10),
            backoff_initial: Duration::from_millis(100),
            backoff_max: Duration::from_secs(2),
        }
    }
}

impl std::fmt::Display for RestartPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "restart {}, at most {} restarts in {} s",
            self.mode,
            self.max_restarts,
            self.window.as_secs_f64()
        )
    }
}

/// A retry schedule without limit: the delay doubles with each consecutive failure, up to `max`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    /// Delay after the first failure.
    pub initial: Duration,
    /// Longest delay.
    pub max: Duration,
}

impl Backoff {
    /// The delay after `failures` earlier consecutive failures.
    pub fn delay(&self, failures: usize) -> Duration {
        let doublings = u32::try_from(failures).unwrap_or(u32::MAX).min(20);
        self.initial.saturating_mul(1 << doublings).min(self.max)
    }
}

/// How the station depends on one child.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChildPolicy {
    /// The station cannot go on without it: restarted per the policy; an exit the policy does not
    /// (or no longer) restart stops the station.
    Essential(RestartPolicy),
    /// The station goes on without it, degraded: restarted after every exit, without limit, on
    /// this schedule (reset once it comes up); its exits never stop the station.
    Degradable(Backoff),
}

impl std::fmt::Display for ChildPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Essential(p) => p.fmt(f),
            Self::Degradable(b) => write!(
                f,
                "restart always, without limit, backoff up to {} s; the station goes on without it",
                b.max.as_secs_f64()
            ),
        }
    }
}

/// What to do about one exit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Start the child again after this delay.
    RestartAfter(Duration),
    /// The policy does not restart this exit: stop the station (cleanly if `failed` is false).
    Stop {
        /// Whether the exit was a failure.
        failed: bool,
    },
    /// The child failed more often than the policy allows.
    GiveUp,
}

/// One child's restart history.
#[derive(Debug, Clone, Default)]
pub struct History {
    restarts: VecDeque<Instant>,
}

impl History {
    /// Decides about an exit at `now` (`failed`: non-zero, signal or hung) and records a restart.
    pub fn decide(&mut self, policy: &RestartPolicy, failed: bool, now: Instant) -> Decision {
        let restart = match policy.mode {
            RestartMode::Never => false,
            RestartMode::OnFailure => failed,
            RestartMode::Always => true,
        };
        if !restart {
            return Decision::Stop { failed };
        }
        while self
            .restarts
            .front()
            .is_some_and(|t| now.duration_since(*t) > policy.window)
        {
            self.restarts.pop_front();
        }
        if self.restarts.len() >= policy.max_restarts as usize {
            return Decision::GiveUp;
        }
        let delay = Backoff {
            initial: policy.backoff_initial,
            max: policy.backoff_max,
        }
        .delay(self.restarts.len());
        self.restarts.push_back(now);
        Decision::RestartAfter(delay)
    }
    /// Restarts within the window so far.
    pub fn count(&self) -> usize {
        self.restarts.len()
    }
}

/// A degradable child's failures since it last came up.
#[derive(Debug, Clone, Default)]
pub struct Retries {
    since_up: usize,
}

impl Retries {
    /// The delay before restarting after an exit, and one more failure counted.
    pub fn next(&mut self, b: &Backoff) -> Duration {
        let d = b.delay(self.since_up);
        self.since_up += 1;
        d
    }
    /// The child came up: the next failure starts the schedule again.
    pub fn came_up(&mut self) {
        self.since_up = 0;
    }
    /// Failures since it last came up.
    pub fn count(&self) -> usize {
        self.since_up
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn restarts_back_off_and_give_up_in_the_window() {
        let p = RestartPolicy::default();
        let mut h = History::default();
        let t0 = Instant::now();
        assert_eq!(
            h.decide(&p, true, t0),
            Decision::RestartAfter(Duration::from_millis(100))
        );
        assert_eq!(
            h.decide(&p, true, t0),
            Decision::RestartAfter(Duration::from_millis(200))
        );
        assert_eq!(
            h.decide(&p, true, t0),
            Decision::RestartAfter(Duration::from_millis(400))
        );
        assert_eq!(h.decide(&p, true, t0), Decision::GiveUp);
        // Outside the window the count starts again.
        assert_eq!(
            h.decide(&p, true, t0 + Duration::from_secs(11)),
            Decision::RestartAfter(Duration::from_millis(100))
        );
        assert_eq!(
            h.decide(&p, false, t0),
            Decision::Stop { failed: false },
            "a clean exit under on-failure"
        );
        let never = RestartPolicy {
            mode: RestartMode::Never,
            ..p
        };
        assert_eq!(
            History::default().decide(&never, true, t0),
            Decision::Stop { failed: true }
        );
        let always = RestartPolicy {
            mode: RestartMode::Always,
            ..p
        };
        assert!(matches!(
            History::default().decide(&always, false, t0),
            Decision::RestartAfter(_)
        ));
        let capped = RestartPolicy {
            max_restarts: 10,
            backoff_max: Duration::from_millis(300),
            ..p
        };
        let mut h = History::default();
        let last = (0..5).map(|_| h.decide(&capped, true, t0)).last();
        assert_eq!(
            last,
            Some(Decision::RestartAfter(Duration::from_millis(300)))
        );
    }

    #[test]
    fn a_degradable_child_is_retried_without_limit_and_starts_over_once_up() {
        let b = Backoff {
            initial: Duration::from_millis(100),
            max: Duration::from_millis(5000),
        };
        let mut r = Retries::default();
        let delays: Vec<u128> = (0..10).map(|_| r.next(&b).as_millis()).collect();
        assert_eq!(
            delays,
            [100, 200, 400, 800, 1600, 3200, 5000, 5000, 5000, 5000]
        );
        assert_eq!(r.count(), 10);
        r.came_up();
        assert_eq!(r.next(&b), Duration::from_millis(100));
    }
}
