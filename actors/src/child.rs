//! One child OS process, owned by one actor.
//!
//! The actor starts the process as a process-group leader (so a signal reaches everything it
//! started), waits for it on a tokio task, and watches its heartbeat: a child whose heartbeat stops
//! for longer than the timeout is hung and gets SIGKILL. When the process exits the actor ends: with
//! a clean stop for exit status 0 (supervisors see `ActorTerminated`), with an error otherwise
//! (`ActorFailed`, carrying a [`ChildFailed`]: a child that exits with [`EXIT_CANNOT_START`] says
//! a restart would fail the same way).

use std::path::PathBuf;
use std::process::Stdio;
use std::sync::Arc;
use std::time::{Duration, Instant};

use nix::sys::signal::{killpg, Signal};
use nix::unistd::Pid;
use ractor::{Actor, ActorProcessingErr, ActorRef};

/// What to run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChildSpec {
    /// Its role ("servo", "physics", "network"): names it in every message.
    pub name: String,
    /// The program.
    pub program: PathBuf,
    /// Its arguments.
    pub args: Vec<String>,
    /// Environment variables set for it (on top of the supervisor's own).
    pub env: Vec<(String, String)>,
}

/// The exit status a child uses to say it cannot start and a restart would fail the same way (its
/// device does not open, say): its supervisor ends the station instead of restarting it, and the
/// child has left its words where the station reads them. Sysexits' `EX_CONFIG`.
pub const EXIT_CANNOT_START: i32 = 78;

/// Why a child's actor failed (the error its supervisor gets).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{text}")]
pub struct ChildFailed {
    /// What happened, naming the child and its pid.
    pub text: String,
    /// It exited with [`EXIT_CANNOT_START`]: a restart would fail the same way.
    pub cannot_start: bool,
}

/// Reads a child's heartbeat counter.
pub type HeartbeatFn = Arc<dyn Fn() -> u64 + Send + Sync>;

/// How to tell a hung child.
#[derive(Clone)]
pub struct Watch {
    /// The counter the child bumps.
    pub heartbeat: HeartbeatFn,
    /// How long the counter may stand still once it moved.
    pub timeout: Duration,
    /// How long the child may take to produce its first beat.
    pub startup: Duration,
}

impl std::fmt::Debug for Watch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Watch")
            .field("timeout", &self.timeout)
            .field("startup", &self.startup)
            .finish()
    }
}

/// How a child process ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Exit {
    /// Exit code, if it exited.
    pub code: Option<i32>,
    /// Signal, if one killed it.
    pub signal: Option<i32>,
}

impl std::fmt::Display for Exit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.code, self.signal) {
            (Some(c), _) => write!(f, "exited with status {c}"),
            (None, Some(s)) => write!(f, "was killed by signal {s}"),
            (None, None) => f.write_str("ended"),
        }
    }
}

/// Messages of a [`ChildProcess`].
#[derive(Debug)]
pub enum ChildMsg {
    /// The process ended.
    Exited(Exit),
    /// Send this signal to the child's process group.
    Signal(Signal),
    /// Check the heartbeat.
    Tick,
}

/// The actor owning one child process.
#[derive(Debug)]
pub struct ChildProcess;

/// A running child.
#[derive(Debug)]
pub struct ChildState {
    spec: ChildSpec,
    pid: u32,
    watch: Option<Watch>,
    last_beat: u64,
    /// The heartbeat moved since this process started (the counter outlives a process: a
    /// restarted child continues its predecessor's count).
    beating: bool,
    last_change: Instant,
    started: Instant,
    hung: bool,
    exited: bool,
}

impl ChildState {
    /// The child's pid.
    pub fn pid(&self) -> u32 {
        self.pid
    }
}

fn signal_group(pid: u32, sig: Signal) {
    if let Ok(p) = i32::try_from(pid) {
        // ESRCH: already gone, which is what we wanted.
        let _ = killpg(Pid::from_raw(p), sig);
    }
}

impl Actor for ChildProcess {
    type Msg = ChildMsg;
    type State = ChildState;
    type Arguments = (ChildSpec, Option<Watch>);

    async fn pre_start(
        &self,
        myself: ActorRef<ChildMsg>,
        (spec, watch): Self::Arguments,
    ) -> Result<ChildState, ActorProcessingErr> {
        let mut child = tokio::process::Command::new(&spec.program)
            .args(&spec.args)
            .envs(spec.env.iter().map(|(k, v)| (k, v)))
            .process_group(0)
            .stdin(Stdio::null())
            .spawn()
            .map_err(|e| {
                format!(
                    "{}: cannot start {}: {e}",
                    spec.name,
                    spec.program.display()
                )
            })?;
        let pid = child.id().unwrap_or(0);
        let me = myself.clone();
        tokio::spawn(async move {
            use std::os::unix::process::ExitStatusExt;
            let exit = match child.wait().await {
                Ok(s) => Exit {
                    code: s.code(),
                    signal: s.signal(),
                },
                Err(_) => Exit {
                    code: None,
                    signal: None,
                },
            };
            let _ = me.send_message(ChildMsg::Exited(exit));
        });
        if watch.is_some() {
            myself.send_interval(Duration::from_millis(50), || ChildMsg::Tick);
        }
        let now = Instant::now();
        let last_beat = watch.as_ref().map_or(0, |w| (w.heartbeat)());
        Ok(ChildState {
            spec,
            pid,
            watch,
            last_beat,
            beating: false,
            last_change: now,
            started: now,
            hung: false,
            exited: false,
        })
    }

    async fn handle(
        &self,
        myself: ActorRef<ChildMsg>,
        msg: ChildMsg,
        st: &mut ChildState,
    ) -> Result<(), ActorProcessingErr> {
        match msg {
            ChildMsg::Exited(exit) => {
                st.exited = true;
                if exit.code == Some(0) && !st.hung {
                    myself.stop(Some(format!(
                        "{} (pid {}) exited cleanly",
                        st.spec.name, st.pid
                    )));
                } else {
                    let cannot_start = !st.hung && exit.code == Some(EXIT_CANNOT_START);
                    let why = if st.hung {
                        format!("hung (no heartbeat) and was killed; it {exit}")
                    } else if cannot_start {
                        format!("cannot start ({exit}: a restart would fail the same way)")
                    } else {
                        exit.to_string()
                    };
                    return Err(Box::new(ChildFailed {
                        text: format!("{} (pid {}) {why}", st.spec.name, st.pid),
                        cannot_start,
                    }));
                }
            }
            ChildMsg::Signal(sig) => {
                if !st.exited {
                    signal_group(st.pid, sig);
                }
            }
            ChildMsg::Tick => {
                let Some(w) = &st.watch else { return Ok(()) };
                let beat = (w.heartbeat)();
                let now = Instant::now();
                if beat != st.last_beat {
                    st.last_beat = beat;
                    st.last_change = now;
                    st.beating = true;
                } else if !st.hung && !st.exited {
                    let (limit, since) = if st.beating {
                        (w.timeout, st.last_change)
                    } else {
                        (w.startup, st.started)
                    };
                    if now.duration_since(since) > limit {
                        st.hung = true;
                        signal_group(st.pid, Signal::SIGKILL);
                    }
                }
            }
        }
        Ok(())
    }

    async fn post_stop(
        &self,
        _myself: ActorRef<ChildMsg>,
        st: &mut ChildState,
    ) -> Result<(), ActorProcessingErr> {
        // An actor never outlives its process silently: if it stops first, the process goes too.
        if !st.exited {
            signal_group(st.pid, Signal::SIGKILL);
        }
        Ok(())
    }
}
