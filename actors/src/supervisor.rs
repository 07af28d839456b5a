//! The station supervisor: starts one linked [`ChildProcess`] actor per child, restarts children per
//! their [`ChildPolicy`] (except one that says it cannot start: that ends the station), and reports through a watch channel how many children live, how each is
//! (starting, up, down), whether the station is degraded (a degradable child is down), and whether
//! the station must end (and why). It never stops itself while a child process may still live; its
//! owner runs the stop ladder ([`SupervisorMsg::BeginStop`], then signals) and stops it once `live`
//! is 0.

use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use ractor::{Actor, ActorProcessingErr, ActorRef, SupervisionEvent};
use tokio::sync::watch;

use crate::child::{ChildFailed, ChildMsg, ChildProcess, ChildSpec, Watch};
use crate::policy::{ChildPolicy, Decision, History, Retries};

/// How often the supervisor looks at the heartbeats of children it has not seen up yet.
const UP_CHECK: Duration = Duration::from_millis(50);
/// A child without a heartbeat counts as up once it has lived this long.
const UP_WITHOUT_HEARTBEAT: Duration = Duration::from_secs(1);

/// Why the station must end.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum End {
    /// A child exited cleanly and the policy does not restart clean exits.
    Clean(String),
    /// A child failed and the policy does not (or no longer) restart it.
    Failed(String),
}

/// How a child is.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum ChildState {
    /// Started for the first time, no heartbeat yet.
    #[default]
    Starting,
    /// Its heartbeat moves.
    Up,
    /// It failed since it was last up: waiting for its restart, or restarted and not beating yet.
    Down,
}

impl ChildState {
    /// `starting`, `up` or `down`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Starting => "starting",
            Self::Up => "up",
            Self::Down => "down",
        }
    }
}

/// One child as the supervisor sees it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Health {
    /// Starting, up or down.
    pub state: ChildState,
    /// Its last failure (kept once it is up again).
    pub last_failure: Option<String>,
    /// When it went down, CLOCK_MONOTONIC ns (while it is down).
    pub down_since_ns: Option<u64>,
}

/// What the supervisor reports.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Status {
    /// Children whose process is running (or about to be restarted).
    pub live: usize,
    /// Restarts per child, in spec order.
    pub restarts: Vec<u32>,
    /// Per child, in spec order.
    pub health: Vec<Health>,
    /// Degradable children that are down, in spec order: the station goes on without them.
    pub degraded: Vec<String>,
    /// Set once the station must end.
    pub end: Option<End>,
}

/// The supervisor's start-up arguments.
#[derive(Debug)]
pub struct SupervisorArgs {
    /// The children, with their heartbeat watch and how the station depends on them.
    pub children: Vec<(ChildSpec, Option<Watch>, ChildPolicy)>,
    /// Where to report.
    pub status: watch::Sender<Status>,
}

/// Messages of the supervisor.
#[derive(Debug)]
pub enum SupervisorMsg {
    /// Start child `i` again (after its backoff).
    Restart(usize),
    /// The station is stopping: exits are expected now and never restart.
    BeginStop,
    /// Send a signal to every live child's process group.
    SignalAll(Signal),
    /// Look whether the children not seen up yet are up now.
    CheckUp,
}

/// The supervisor actor.
#[derive(Debug)]
pub struct StationSupervisor;

/// Its state.
#[derive(Debug)]
pub struct SupervisorState {
    specs: Vec<(ChildSpec, Option<Watch>, ChildPolicy)>,
    histories: Vec<History>,
    retries: Vec<Retries>,
    children: Vec<Option<ActorRef<ChildMsg>>>,
    pending: Vec<bool>,
    restarts: Vec<u32>,
    health: Vec<Health>,
    /// Per child: when its current process started, and its heartbeat then.
    started: Vec<(Instant, u64)>,
    stopping: bool,
    status: watch::Sender<Status>,
}

impl SupervisorState {
    fn publish(&self, end: Option<End>) {
        let live = self
            .children
            .iter()
            .zip(&self.pending)
            .filter(|(c, p)| c.is_some() || **p)
            .count();
        let degraded = self
            .specs
            .iter()
            .zip(&self.health)
            .filter(|((_, _, p), h)| {
                matches!(p, ChildPolicy::Degradable(_)) && h.state == ChildState::Down
            })
            .map(|((spec, _, _), _)| spec.name.clone())
            .collect();
        self.status.send_modify(|s| {
            s.live = live;
            s.restarts.clone_from(&self.restarts);
            s.health.clone_from(&self.health);
            s.degraded = degraded;
            if s.end.is_none() {
                s.end = end;
            }
        });
    }

    /// Whether child `i`'s current process shows it is up.
    fn is_up(&self, i: usize) -> bool {
        let (at, beat) = self.started[i];
        self.children[i].is_some()
            && match &self.specs[i].1 {
                Some(w) => (w.heartbeat)() != beat,
                None => at.elapsed() >= UP_WITHOUT_HEARTBEAT,
            }
    }
}

async fn start(
    myself: &ActorRef<SupervisorMsg>,
    st: &mut SupervisorState,
    i: usize,
) -> Result<(), ActorProcessingErr> {
    let (spec, watch, _) = st.specs[i].clone();
    let name = format!("{}-{}-{}", spec.name, std::process::id(), st.restarts[i]);
    let beat = watch.as_ref().map_or(0, |w| (w.heartbeat)());
    st.started[i] = (Instant::now(), beat);
    let (child, _) =
        Actor::spawn_linked(Some(name), ChildProcess, (spec, watch), myself.get_cell()).await?;
    st.children[i] = Some(child);
    st.pending[i] = false;
    Ok(())
}

/// How a child ended, as its actor said.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Ending {
    /// Exit status 0.
    Clean,
    /// Any other end, in words.
    Failed(String),
    /// It cannot start, and a restart would fail the same way
    /// ([`crate::child::EXIT_CANNOT_START`]).
    CannotStart(String),
}

/// Child `i` ended: restart it or end the station, per its policy (one that cannot start ends
/// the station whatever the policy: restarting it would only hide why).
fn exited(myself: &ActorRef<SupervisorMsg>, st: &mut SupervisorState, i: usize, ending: Ending) {
    let (failure, cannot_start) = match ending {
        Ending::Clean => (None, false),
        Ending::Failed(why) => (Some(why), false),
        Ending::CannotStart(why) => (Some(why), true),
    };
    let name = st.specs[i].0.name.clone();
    let failed = failure.is_some();
    let what = failure.unwrap_or_else(|| format!("{name} exited cleanly"));
    if failed {
        let h = &mut st.health[i];
        h.last_failure = Some(what.clone());
        if h.state != ChildState::Down {
            h.state = ChildState::Down;
            h.down_since_ns = Some(coop_rt::timer::monotonic_ns());
        }
    }
    if cannot_start {
        st.publish(Some(End::Failed(what)));
        return;
    }
    let restart = |st: &mut SupervisorState, delay| {
        st.restarts[i] += 1;
        st.pending[i] = true;
        myself.send_after(delay, move || SupervisorMsg::Restart(i));
        st.publish(None);
    };
    match st.specs[i].2 {
        ChildPolicy::Degradable(backoff) => {
            let delay = st.retries[i].next(&backoff);
            restart(st, delay);
        }
        ChildPolicy::Essential(policy) => {
            match st.histories[i].decide(&policy, failed, Instant::now()) {
                Decision::RestartAfter(delay) => restart(st, delay),
                Decision::Stop { failed: false } => st.publish(Some(End::Clean(what))),
                Decision::Stop { failed: true } => st.publish(Some(End::Failed(format!(
                    "{what}; policy ({policy}) does not restart it"
                )))),
                Decision::GiveUp => st.publish(Some(End::Failed(format!(
                    "child {name} failed {} times within {} s ({policy}); last: {what}",
                    st.histories[i].count() + 1,
                    policy.window.as_secs_f64(),
                )))),
            }
        }
    }
}

impl Actor for StationSupervisor {
    type Msg = SupervisorMsg;
    type State = SupervisorState;
    type Arguments = SupervisorArgs;

    async fn pre_start(
        &self,
        myself: ActorRef<SupervisorMsg>,
        args: SupervisorArgs,
    ) -> Result<SupervisorState, ActorProcessingErr> {
        let n = args.children.len();
        let mut st = SupervisorState {
            specs: args.children,
            histories: vec![History::default(); n],
            retries: vec![Retries::default(); n],
            children: vec![None; n],
            pending: vec![false; n],
            restarts: vec![0; n],
            health: vec![Health::default(); n],
            started: vec![(Instant::now(), 0); n],
            stopping: false,
            status: args.status,
        };
        for i in 0..n {
            start(&myself, &mut st, i).await?;
        }
        myself.send_interval(UP_CHECK, || SupervisorMsg::CheckUp);
        st.publish(None);
        Ok(st)
    }

    async fn handle(
        &self,
        myself: ActorRef<SupervisorMsg>,
        msg: SupervisorMsg,
        st: &mut SupervisorState,
    ) -> Result<(), ActorProcessingErr> {
        match msg {
            SupervisorMsg::Restart(i) => {
                if st.stopping {
                    st.pending[i] = false;
                } else if let Err(e) = start(&myself, st, i).await {
                    st.pending[i] = false;
                    let why = format!("{}: restart failed: {e}", st.specs[i].0.name);
                    if let ChildPolicy::Degradable(_) = st.specs[i].2 {
                        exited(&myself, st, i, Ending::Failed(why));
                    } else {
                        st.publish(Some(End::Failed(why)));
                    }
                    return Ok(());
                }
                st.publish(None);
            }
            SupervisorMsg::CheckUp => {
                let mut changed = false;
                for i in 0..st.specs.len() {
                    if st.health[i].state != ChildState::Up && !st.stopping && st.is_up(i) {
                        st.health[i].state = ChildState::Up;
                        st.health[i].down_since_ns = None;
                        st.retries[i].came_up();
                        changed = true;
                    }
                }
                if changed {
                    st.publish(None);
                }
            }
            SupervisorMsg::BeginStop => {
                st.stopping = true;
                st.pending.iter_mut().for_each(|p| *p = false);
                st.publish(None);
            }
            SupervisorMsg::SignalAll(sig) => {
                for c in st.children.iter().flatten() {
                    let _ = c.send_message(ChildMsg::Signal(sig));
                }
            }
        }
        Ok(())
    }

    async fn handle_supervisor_evt(
        &self,
        myself: ActorRef<SupervisorMsg>,
        evt: SupervisionEvent,
        st: &mut SupervisorState,
    ) -> Result<(), ActorProcessingErr> {
        let (cell, ending) = match evt {
            SupervisionEvent::ActorTerminated(cell, _, _) => (cell, Ending::Clean),
            SupervisionEvent::ActorFailed(cell, err) => {
                let why = err.to_string();
                match err.downcast_ref::<ChildFailed>() {
                    Some(f) if f.cannot_start => (cell, Ending::CannotStart(why)),
                    _ => (cell, Ending::Failed(why)),
                }
            }
            _ => return Ok(()),
        };
        let Some(i) = st
            .children
            .iter()
            .position(|c| c.as_ref().is_some_and(|c| c.get_id() == cell.get_id()))
        else {
            return Ok(());
        };
        st.children[i] = None;
        if st.stopping {
            st.publish(None);
            return Ok(());
        }
        exited(&myself, st, i, ending);
        Ok(())
    }
}
