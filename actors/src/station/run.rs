//! `station run`: bring a station up in order, keep it going, and take it down leaving nothing.
//!
//! Up: clean stale segments a dead predecessor of this station left (refusing if one is alive),
//! check its listen ports are free, create the control block and rings, say once which real-time
//! privileges the loops will lack (they do not say it again), start the supervisor (which
//! starts servo, physics and network as process-group leaders that die with it), then declare the
//! station running.
//! Meanwhile: each child's restarts, health and last failure go to its slot of the control block
//! (for `station status`); while the network process is down the station runs on locally, degraded,
//! and says so on stderr when it enters and leaves that mode.
//! Down, on SIGINT/SIGTERM, a duration, the end of the session's scenario (for a station started by
//! the session's time 0, [`SESSION_END_GRACE`] after it), a child the policy gave up on, or a
//! servo whose device does not open (not restarted: the device's own words are the reason) — the
//! stop ladder:
//! cooperative stop through the run state (the servo first ramps its force to zero) → [`STOP_GRACE`]
//! → SIGTERM to each child's process group → [`TERM_GRACE`] → SIGKILL; then unlink every segment.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use crate::child::{ChildSpec, Watch};
use crate::policy::ChildPolicy;
use crate::supervisor::{
    ChildState, End, StationSupervisor, Status, SupervisorArgs, SupervisorMsg,
};
use coop_rt::shm::control::{Child, ControlBlock, Health, RunState};
use coop_rt::shm::{self, SegmentName, SegmentStatus};
use coop_rt::sync::Ordering;
use nix::sys::signal::Signal;
use ractor::Actor;
use tokio::signal::unix::{signal, SignalKind};
use tokio::sync::watch;

use super::config::{ConfigError, Resolved};
use super::link::LinkTeller;
use coop_rt::shm::station::{Names, StationSegments};

/// Why `station run` could not start, or stopped on a failure.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The session or station name cannot make segment names.
    #[error(transparent)]
    Name(#[from] coop_rt::shm::NameError),
    /// The segments could not be listed or removed, the runtime or a signal handler not set up.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// A station of the same name in the same session is running.
    #[error("station {station} of session {session} is already running ({segment}: {status}); stop it first, or choose another --station or --session")]
    AlreadyRunning {
        /// The station.
        station: String,
        /// Its session.
        session: String,
        /// One of its live segments.
        segment: String,
        /// What that segment is.
        status: SegmentStatus,
    },
    /// The configuration breaks a rule that looks at the machine (a listen port that is taken).
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The station's segments could not be created.
    #[error("creating the station's segments")]
    Segments(#[source] coop_rt::shm::CreateError),
    /// This executable, which each child re-runs, cannot be found.
    #[error("finding the station binary")]
    Exe(#[source] std::io::Error),
    /// The supervisor actor did not start.
    #[error("starting the supervisor: {0}")]
    Supervisor(ractor::SpawnErr),
    /// A servo or physics failure the restart policy gave up on.
    #[error("station {station} stopped: {why}")]
    Stopped {
        /// The station.
        station: String,
        /// The failure and the policy, in words.
        why: String,
    },
}

/// How long children get to stop by themselves after the run state says stop: the servo ramps its
/// force to zero (50 ms by default) and each loop notices within one cycle; two seconds leaves room
/// for a loaded two-core machine.
pub const STOP_GRACE: Duration = Duration::from_secs(2);
/// How long children get after SIGTERM before SIGKILL: they have no handler, so this only covers
/// the kernel delivering it.
pub const TERM_GRACE: Duration = Duration::from_secs(1);
/// A station that waits for the session's time 0 (`start = "session"`) stops by itself this long
/// after the scenario's end (time 0 + its duration): the users' scripts are over, and a launcher
/// that did not start it (`session run --attach`, on another machine) cannot signal it. A
/// launcher that did stops it before.
pub const SESSION_END_GRACE: Duration = Duration::from_secs(2);

/// What `station run` was asked.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// The config file the children should read too.
    pub config: Option<PathBuf>,
    /// Stop by itself after this long.
    pub duration: Option<Duration>,
    /// Arguments before the subcommand when this executable re-runs itself for a child.
    pub exe_prefix: Vec<String>,
}

/// When a station started by its session's time 0 stops, ns after it: at its scenario's end
/// (and a grace); never for one that waits for it otherwise, nor for a study's station, which
/// outlives every trial's scenario (the runner stops it).
fn session_end_ns(cfg: &Resolved) -> Option<u64> {
    (cfg.config.start == super::config::StartMode::Session && !cfg.config.trials).then(|| {
        ((cfg.scenario.duration_s * 1e9) as u64).saturating_add(SESSION_END_GRACE.as_nanos() as u64)
    })
}

/// Runs the station until a signal, the duration, or a servo or physics failure the policy gave up
/// on (network failures never end it: it runs on degraded while the network is retried).
///
/// # Errors
/// A live station of the same name, a listen port that is taken, segments that cannot be created,
/// or a child the policy gave up on (the message names the child and the policy).
pub fn run(cfg: &Resolved, opts: &RunOptions) -> Result<(), RunError> {
    let session = &cfg.config.session;
    let prefix = SegmentName::station_prefix(session, &cfg.name)?;
    let removed = shm::remove_stale(&prefix)?;
    if !removed.is_empty() {
        eprintln!(
            "station {}: removed {} stale segment(s) of a previous run",
            cfg.name,
            removed.len()
        );
    }
    if let Some(live) = shm::list(&prefix)?
        .into_iter()
        .find(|i| matches!(i.status, SegmentStatus::Live { .. }))
    {
        return Err(RunError::AlreadyRunning {
            station: cfg.name.clone(),
            session: session.clone(),
            segment: live.name,
            status: live.status,
        });
    }
    cfg.check_listen_ports_free()
        .map_err(|problem| ConfigError::in_file(opts.config.as_deref(), problem))?;
    let names = Names::of(session, &cfg.name)?;
    let segs = Arc::new(
        StationSegments::create(&names, &cfg.config.rings_for(cfg.scenario.objects.len()))
            .map_err(RunError::Segments)?,
    );
    segs.control.set_run_state(RunState::Starting);
    if cfg.config.start == super::config::StartMode::Now {
        // SYNC: Release pairs with `ControlBlock::epoch`'s Acquire.
        segs.control
            .epoch_ns
            .store(coop_rt::timer::monotonic_ns(), Ordering::Release);
    }
    // The supervisor stays off the servo's CPU too (its children set their own affinity).
    super::child::keep_off_the_servo(cfg);
    let said = say_missing_privileges(cfg);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let outcome = rt.block_on(supervise(cfg, opts, segs.clone(), &said));
    segs.control.set_run_state(RunState::Stopped);
    drop(segs); // unlinks every segment
    outcome
}

/// Tries once what the loop processes will ask of the kernel (`mlockall`, `/dev/cpu_dma_latency`,
/// a real-time policy) and says in ONE warning everything that is missing, with the fix; returns
/// the keys of what it said, for the children not to say it again (they still apply what they
/// can, and status shows what is in force).
fn say_missing_privileges(cfg: &Resolved) -> Vec<&'static str> {
    let realtime = [&cfg.servo_sched, &cfg.physics_sched]
        .into_iter()
        .find(|r| r.policy.is_realtime())
        .map(|r| (r.policy, r.priority));
    let missing = coop_rt::sched::missing_privileges(&coop_rt::sched::Wanted {
        lock_memory: cfg.config.mlockall,
        cpu_dma_latency: cfg.config.cpu_dma_latency_zero,
        realtime,
    });
    if missing.is_empty() {
        return Vec::new();
    }
    let list = |f: &dyn Fn(&coop_rt::sched::Missing) -> String, sep: &str| {
        missing.iter().map(f).collect::<Vec<_>>().join(sep)
    };
    let caps: Vec<&str> = missing
        .iter()
        .filter_map(|m| match m.key {
            "mlock" => Some("cap_ipc_lock"),
            "policy" => Some("cap_sys_nice"),
            _ => None,
        })
        .collect();
    let setcap = if caps.is_empty() {
        String::new()
    } else {
        let exe =
            std::env::current_exe().map_or("<station binary>".into(), |p| p.display().to_string());
        format!(" (setcap {}+ep {exe})", caps.join(","))
    };
    eprintln!(
        "station {}: WARN: missing real-time privileges: {}; the servo and physics run anyway ({}). Fix: run as root, or give it {}{setcap}",
        cfg.name,
        list(&|m| m.what.clone(), ", "),
        list(&|m| m.instead.to_owned(), ", "),
        list(&|m| m.grant.to_owned(), "; "),
    );
    missing.iter().map(|m| m.key).collect()
}

fn child_spec(
    cfg: &Resolved,
    opts: &RunOptions,
    child: Child,
    said: &[&str],
) -> Result<ChildSpec, RunError> {
    let mut args = opts.exe_prefix.clone();
    args.extend([
        child.name().to_owned(),
        "--session".into(),
        cfg.config.session.clone(),
        "--station".into(),
        cfg.name.clone(),
        "--parent".into(),
        std::process::id().to_string(),
    ]);
    if let Some(c) = &opts.config {
        args.push("--config".into());
        args.push(c.display().to_string());
    }
    // `station run --live` overrides the file, for the network process too.
    if let Some(l) = &cfg.config.live {
        args.push(format!("--live={l}"));
    }
    Ok(ChildSpec {
        name: child.name().to_owned(),
        program: std::env::current_exe().map_err(RunError::Exe)?,
        args,
        env: vec![(super::child::PRIVILEGES_SAID_ENV.to_owned(), said.join(","))],
    })
}

/// Writes each child's restarts, health and last failure to its slot of the control block; the
/// network's with `network_cause`, why its links fail, when that is known.
fn publish(ctl: &ControlBlock, status: &Status, network_cause: Option<String>) {
    for (i, c) in Child::ALL.into_iter().enumerate() {
        let slot = ctl.child(c);
        if let Some(n) = status.restarts.get(i) {
            slot.restarts.store(u64::from(*n), Ordering::Relaxed);
        }
        let Some(h) = status.health.get(i) else {
            continue;
        };
        if let Some(f) = &h.last_failure {
            let f = match (&network_cause, c) {
                (Some(cause), Child::Network) => format!("{f}: {cause}"),
                _ => f.clone(),
            };
            if f != slot.last_failure() {
                slot.set_last_failure(&f);
            }
        }
        slot.down_since_ns
            .store(h.down_since_ns.unwrap_or(0), Ordering::Relaxed);
        slot.set_health(match h.state {
            ChildState::Starting => Health::Starting,
            ChildState::Up => Health::Up,
            ChildState::Down => Health::Down,
        });
    }
}

/// One line on stderr for each child entering or leaving degraded mode (the network going down or
/// coming back).
fn say_degraded(cfg: &Resolved, status: &Status, before: &[String]) {
    let index = |name: &str| Child::ALL.iter().position(|c| c.name() == name);
    for name in status.degraded.iter().filter(|n| !before.contains(n)) {
        let last = index(name)
            .and_then(|i| status.health.get(i)?.last_failure.clone())
            .unwrap_or_default();
        eprintln!(
            "station {}: DEGRADED: the {name} process is down ({last}); servo and physics go on locally, the {name} is restarted with backoff (up to {} ms)",
            cfg.name, cfg.config.supervisor.network_backoff_max_ms
        );
    }
    for name in before.iter().filter(|n| !status.degraded.contains(n)) {
        let restarts = index(name)
            .and_then(|i| status.restarts.get(i).copied())
            .unwrap_or(0);
        eprintln!(
            "station {}: no longer degraded: the {name} process is up again (restarts so far: {restarts})",
            cfg.name
        );
    }
}

/// Hands the network's failures to `link` (which probes the links and says why, once) and tells
/// it when the network is up again.
fn watch_links(cfg: &Resolved, status: &Status, link: &mut LinkTeller) {
    let Some(i) = Child::ALL.iter().position(|c| *c == Child::Network) else {
        return;
    };
    let Some(h) = status.health.get(i) else {
        return;
    };
    match (h.state, &h.last_failure) {
        (ChildState::Down, Some(f)) if status.end.is_none() => link.failed(cfg, f),
        (ChildState::Up, _) => {
            if let Some(line) = link.up() {
                eprintln!("station {}: {line}", cfg.name);
            }
        }
        _ => {}
    }
}

/// Why the servo's device did not open, in its own words, if that is why the servo could not start
/// (it writes them before it exits with `EXIT_CANNOT_START`): the station's reason to stop, said
/// once, instead of the servo's exit status.
fn device_words(ctl: &ControlBlock) -> Option<String> {
    let words = ctl.device.open_error.load();
    (!words.is_empty()).then(|| format!("the servo cannot open its device: {words}"))
}

async fn supervise(
    cfg: &Resolved,
    opts: &RunOptions,
    segs: Arc<StationSegments>,
    said: &[&str],
) -> Result<(), RunError> {
    let sup_cfg = &cfg.config.supervisor;
    let watch_of = |c: Child| {
        let s = segs.clone();
        Some(Watch {
            heartbeat: Arc::new(move || s.control.child(c).heartbeat.load(Ordering::Relaxed)),
            timeout: Duration::from_millis(sup_cfg.heartbeat_timeout_ms),
            startup: cfg.startup_timeout(c),
        })
    };
    // The servo and physics are the station; the network is what it shares, and the station goes
    // on without it (see `crate::policy`).
    let essential = ChildPolicy::Essential(cfg.policy);
    let children = vec![
        (
            child_spec(cfg, opts, Child::Servo, said)?,
            watch_of(Child::Servo),
            essential,
        ),
        (
            child_spec(cfg, opts, Child::Physics, said)?,
            watch_of(Child::Physics),
            essential,
        ),
        (
            child_spec(cfg, opts, Child::Network, said)?,
            watch_of(Child::Network),
            ChildPolicy::Degradable(cfg.network_backoff),
        ),
    ];
    let (tx, mut rx) = watch::channel(Status::default());
    let args = SupervisorArgs {
        children,
        status: tx,
    };
    let (sup, handle) = Actor::spawn(
        Some(format!("station-{}-{}", cfg.name, std::process::id())),
        StationSupervisor,
        args,
    )
    .await
    .map_err(RunError::Supervisor)?;
    segs.control.set_run_state(RunState::Running);
    eprintln!(
        "station {} (session {}): running servo at {} Hz, physics at {} Hz and the network; Ctrl-C to stop",
        cfg.name,
        cfg.config.session,
        cfg.scenario.site[cfg.site].servo_rate_hz,
        cfg.scenario.site[cfg.site].physics_rate_hz
    );
    let mut sigint = signal(SignalKind::interrupt())?;
    let mut sigterm = signal(SignalKind::terminate())?;
    let until = async {
        match opts.duration {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    tokio::pin!(until);
    let session_end_ns = session_end_ns(cfg);
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    let mut degraded: Vec<String> = Vec::new();
    let mut link = LinkTeller::default();
    let end = loop {
        tokio::select! {
            _ = sigint.recv() => break None,
            _ = sigterm.recv() => break None,
            _ = &mut until => break None,
            _ = tick.tick() => {
                let over = session_end_ns.zip(segs.control.epoch()).is_some_and(|(after, epoch)| {
                    coop_rt::timer::monotonic_ns() >= epoch.saturating_add(after)
                });
                if over {
                    break Some(End::Clean(format!(
                        "the session's scenario is over ({} s from its time 0)",
                        cfg.scenario.duration_s
                    )));
                }
            }
            found = link.probed(), if link.probing() => {
                if let Some(line) = link.tell(found) {
                    eprintln!("station {}: {line}", cfg.name);
                }
                publish(&segs.control, &rx.borrow().clone(), link.cause());
            }
            changed = rx.changed() => {
                let status = rx.borrow_and_update().clone();
                publish(&segs.control, &status, link.cause());
                if status.degraded != degraded && status.end.is_none() {
                    say_degraded(cfg, &status, &degraded);
                    degraded.clone_from(&status.degraded);
                }
                watch_links(cfg, &status, &mut link);
                if changed.is_err() || status.end.is_some() {
                    break status.end;
                }
            }
        }
    };
    // The stop ladder.
    let _ = sup.send_message(SupervisorMsg::BeginStop);
    segs.control.set_run_state(RunState::Stopping);
    for (grace, signal) in [
        (STOP_GRACE, Some(Signal::SIGTERM)),
        (TERM_GRACE, Some(Signal::SIGKILL)),
        (TERM_GRACE, None),
    ] {
        let gone = tokio::time::timeout(grace, rx.wait_for(|s| s.live == 0))
            .await
            .is_ok();
        if gone {
            break;
        }
        match signal {
            Some(sig) => {
                eprintln!(
                    "station {}: children still running after {:?}; sending {sig}",
                    cfg.name, grace
                );
                let _ = sup.send_message(SupervisorMsg::SignalAll(sig));
            }
            None => eprintln!("station {}: children did not die after SIGKILL", cfg.name),
        }
    }
    sup.stop(None);
    let _ = handle.await;
    match end {
        Some(End::Failed(why)) => Err(RunError::Stopped {
            station: cfg.name.clone(),
            why: device_words(&segs.control).unwrap_or(why),
        }),
        Some(End::Clean(why)) => {
            eprintln!("station {} stopped: {why}", cfg.name);
            Ok(())
        }
        None => {
            eprintln!("station {} stopped", cfg.name);
            Ok(())
        }
    }
}
