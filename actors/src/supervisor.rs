//! The station supervisor: starts one linked [`ChildProcess`] actor per child, restarts children per
//! the [`RestartPolicy`], and reports through a watch channel how many children live and whether the
//! station must end (and why). It never stops itself while a child process may still live; its owner
//! runs the stop ladder ([`SupervisorMsg::BeginStop`], then signals) and stops it once `live` is 0.

use std::time::Instant;

use nix::sys::signal::Signal;
use ractor::{Actor, ActorProcessingErr, ActorRef, SupervisionEvent};
use tokio::sync::watch;

use crate::child::{ChildMsg, ChildProcess, ChildSpec, Watch};
use crate::policy::{Decision, History, RestartPolicy};

/// Why the station must end.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum End {
    /// A child exited cleanly and the policy does not restart clean exits.
    Clean(String),
    /// A child failed and the policy does not (or no longer) restart it.
    Failed(String),
}

/// What the supervisor reports.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Status {
    /// Children whose process is running (or about to be restarted).
    pub live: usize,
    /// Restarts per child, in spec order.
    pub restarts: Vec<u32>,
    /// Set once the station must end.
    pub end: Option<End>,
}

/// The supervisor's start-up arguments.
#[derive(Debug)]
pub struct SupervisorArgs {
    /// The children, with their heartbeat watch.
    pub children: Vec<(ChildSpec, Option<Watch>)>,
    /// The restart policy.
    pub policy: RestartPolicy,
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
}

/// The supervisor actor.
#[derive(Debug)]
pub struct StationSupervisor;

/// Its state.
#[derive(Debug)]
pub struct SupervisorState {
    specs: Vec<(ChildSpec, Option<Watch>)>,
    policy: RestartPolicy,
    histories: Vec<History>,
    children: Vec<Option<ActorRef<ChildMsg>>>,
    pending: Vec<bool>,
    restarts: Vec<u32>,
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
        self.status.send_modify(|s| {
            s.live = live;
            s.restarts.clone_from(&self.restarts);
            if s.end.is_none() {
                s.end = end;
            }
        });
    }
}

async fn start(
    myself: &ActorRef<SupervisorMsg>,
    st: &mut SupervisorState,
    i: usize,
) -> Result<(), ActorProcessingErr> {
    let (spec, watch) = st.specs[i].clone();
    let name = format!("{}-{}-{}", spec.name, std::process::id(), st.restarts[i]);
    let (child, _) =
        Actor::spawn_linked(Some(name), ChildProcess, (spec, watch), myself.get_cell()).await?;
    st.children[i] = Some(child);
    st.pending[i] = false;
    Ok(())
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
            policy: args.policy,
            histories: vec![History::default(); n],
            children: vec![None; n],
            pending: vec![false; n],
            restarts: vec![0; n],
            stopping: false,
            status: args.status,
        };
        for i in 0..n {
            start(&myself, &mut st, i).await?;
        }
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
                    st.publish(Some(End::Failed(format!(
                        "{}: restart failed: {e}",
                        st.specs[i].0.name
                    ))));
                    return Ok(());
                }
                st.publish(None);
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
        let (cell, failure) = match evt {
            SupervisionEvent::ActorTerminated(cell, _, _) => (cell, None),
            SupervisionEvent::ActorFailed(cell, err) => (cell, Some(err.to_string())),
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
        let name = st.specs[i].0.name.clone();
        if st.stopping {
            st.publish(None);
            return Ok(());
        }
        let failed = failure.is_some();
        let what = failure.unwrap_or_else(|| format!("{name} exited cleanly"));
        match st.histories[i].decide(&st.policy, failed, Instant::now()) {
            Decision::RestartAfter(delay) => {
                st.restarts[i] += 1;
                st.pending[i] = true;
                myself.send_after(delay, move || SupervisorMsg::Restart(i));
                st.publish(None);
            }
            Decision::Stop { failed: false } => st.publish(Some(End::Clean(what))),
            Decision::Stop { failed: true } => st.publish(Some(End::Failed(format!(
                "{what}; policy ({}) does not restart it",
                st.policy
            )))),
            Decision::GiveUp => st.publish(Some(End::Failed(format!(
                "child {name} failed {} times within {} s ({}); last: {what}",
                st.histories[i].count() + 1,
                st.policy.window.as_secs_f64(),
                st.policy
            )))),
        }
        Ok(())
    }
}
