//! The supervisor with real processes (H10, H13): `false` fakes a child that crashes on every start,
//! `sleep` a long-running one, and a heartbeat that never moves a hung one. No sleeps to make tests
//! pass: each waits on the supervisor's status with a deadline.

use std::sync::Arc;
use std::time::Duration;

use coop_actors::child::{ChildSpec, Watch};
use coop_actors::policy::{RestartMode, RestartPolicy};
use coop_actors::supervisor::{End, StationSupervisor, Status, SupervisorArgs, SupervisorMsg};
use nix::sys::signal::Signal;
use ractor::Actor;
use tokio::sync::watch;

const LIMIT: Duration = Duration::from_secs(30);

fn spec(name: &str, program: &str, args: &[&str]) -> ChildSpec {
    ChildSpec {
        name: name.into(),
        program: program.into(),
        args: args.iter().map(|s| s.to_string()).collect(),
    }
}

fn policy(max_restarts: u32) -> RestartPolicy {
    RestartPolicy {
        mode: RestartMode::OnFailure,
        max_restarts,
        window: Duration::from_secs(60),
        backoff_initial: Duration::from_millis(10),
        backoff_max: Duration::from_millis(50),
    }
}

async fn wait_for(
    rx: &mut watch::Receiver<Status>,
    what: &str,
    f: impl FnMut(&Status) -> bool,
) -> Status {
    let got = match tokio::time::timeout(LIMIT, rx.wait_for(f)).await {
        Ok(Ok(s)) => Some(s.clone()),
        _ => None,
    };
    got.unwrap_or_else(|| {
        panic!(
            "timed out waiting for {what}; last status {:?}",
            *rx.borrow()
        )
    })
}

#[tokio::test]
async fn a_child_that_crashes_on_every_start_is_restarted_then_given_up() {
    let (tx, mut rx) = watch::channel(Status::default());
    let args = SupervisorArgs {
        children: vec![(spec("physics", "false", &[]), None)],
        policy: policy(2),
        status: tx,
    };
    let (sup, handle) = Actor::spawn(None, StationSupervisor, args)
        .await
        .expect("supervisor");
    let s = wait_for(&mut rx, "the supervisor to give up", |s| s.end.is_some()).await;
    assert_eq!(s.restarts, vec![2], "restarted per policy before giving up");
    match s.end {
        Some(End::Failed(msg)) => {
            assert!(msg.contains("child physics failed 3 times"), "{msg}");
            assert!(
                msg.contains("restart on-failure, at most 2 restarts"),
                "{msg}"
            );
            assert!(msg.contains("exited with status 1"), "{msg}");
        }
        other => panic!("expected a failure, got {other:?}"),
    }
    sup.stop(None);
    handle.await.expect("supervisor ends");
}

#[tokio::test]
async fn the_stop_ladder_ends_a_running_child_without_restart() {
    let (tx, mut rx) = watch::channel(Status::default());
    let args = SupervisorArgs {
        children: vec![(spec("servo", "sleep", &["30"]), None)],
        policy: policy(3),
        status: tx,
    };
    let (sup, handle) = Actor::spawn(None, StationSupervisor, args)
        .await
        .expect("supervisor");
    wait_for(&mut rx, "the child to run", |s| s.live == 1).await;
    sup.send_message(SupervisorMsg::BeginStop).expect("send");
    sup.send_message(SupervisorMsg::SignalAll(Signal::SIGTERM))
        .expect("send");
    let s = wait_for(&mut rx, "the child to end", |s| s.live == 0).await;
    assert_eq!(s.end, None, "an exit during a stop is not a failure");
    assert_eq!(s.restarts, vec![0], "and is not restarted");
    sup.stop(None);
    handle.await.expect("supervisor ends");
}

#[tokio::test]
async fn a_hung_child_is_killed_and_restarted() {
    let (tx, mut rx) = watch::channel(Status::default());
    // A heartbeat that never moves: the child is hung from the start.
    let watch = Watch {
        heartbeat: Arc::new(|| 0),
        timeout: Duration::from_millis(100),
        startup: Duration::from_millis(200),
    };
    let args = SupervisorArgs {
        children: vec![(spec("network", "sleep", &["30"]), Some(watch))],
        policy: policy(1),
        status: tx,
    };
    let (sup, handle) = Actor::spawn(None, StationSupervisor, args)
        .await
        .expect("supervisor");
    let s = wait_for(&mut rx, "the hung child to be given up", |s| {
        s.end.is_some()
    })
    .await;
    assert_eq!(s.restarts, vec![1]);
    match s.end {
        Some(End::Failed(msg)) => assert!(
            msg.contains("hung (no heartbeat) and was killed") && msg.contains("signal 9"),
            "{msg}"
        ),
        other => panic!("expected a failure, got {other:?}"),
    }
    sup.stop(None);
    handle.await.expect("supervisor ends");
}
