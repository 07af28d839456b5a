//! The supervisor with real processes (H10, H13): `false` fakes a child that crashes on every start,
//! `sleep` a long-running one, a heartbeat that never moves a hung one, and `sh` one that fails
//! until a file appears. No sleeps to make tests
//! pass: each waits on the supervisor's status with a deadline.

use std::sync::Arc;
use std::time::Duration;

use coop_actors::child::{ChildSpec, Watch};
use coop_actors::policy::{Backoff, ChildPolicy, RestartMode, RestartPolicy};
use coop_actors::supervisor::{
    ChildState, End, StationSupervisor, Status, SupervisorArgs, SupervisorMsg,
};
use nix::sys::signal::Signal;
use ractor::Actor;
use tokio::sync::watch;

const LIMIT: Duration = Duration::from_secs(30);

fn spec(name: &str, program: &str, args: &[&str]) -> ChildSpec {
    ChildSpec {
        name: name.into(),
        program: program.into(),
        args: args.iter().map(|s| s.to_string()).collect(),
        env: Vec::new(),
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

/// A supervisor of the one child `child` under `policy`, until the station ends: its status then.
async fn until_the_end(child: ChildSpec, policy: ChildPolicy) -> Status {
    let (tx, mut rx) = watch::channel(Status::default());
    let args = SupervisorArgs {
        children: vec![(child, None, policy)],
        status: tx,
    };
    let (sup, handle) = Actor::spawn(None, StationSupervisor, args)
        .await
        .expect("supervisor");
    let s = wait_for(&mut rx, "the station to end", |s| s.end.is_some()).await;
    sup.stop(None);
    handle.await.expect("supervisor ends");
    s
}

#[tokio::test]
async fn a_child_that_crashes_on_every_start_is_restarted_then_given_up() {
    let s = until_the_end(
        spec("physics", "false", &[]),
        ChildPolicy::Essential(policy(2)),
    )
    .await;
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
}

/// A child that says it cannot start (its exit status: a restart would fail the same way, its
/// device does not open, say) is not restarted, whatever the policy: the station ends at once.
#[tokio::test]
async fn a_child_that_cannot_start_ends_the_station_without_a_restart() {
    let code = coop_actors::child::EXIT_CANNOT_START.to_string();
    let s = until_the_end(
        spec("servo", "sh", &["-c", &format!("exit {code}")]),
        ChildPolicy::Essential(policy(3)),
    )
    .await;
    assert_eq!(s.restarts, vec![0], "not restarted");
    match s.end {
        Some(End::Failed(msg)) => assert!(
            msg.contains("servo (pid ")
                && msg.contains(&format!("cannot start (exited with status {code}")),
            "{msg}"
        ),
        other => panic!("expected a failure, got {other:?}"),
    }
}

#[tokio::test]
async fn the_stop_ladder_ends_a_running_child_without_restart() {
    let (tx, mut rx) = watch::channel(Status::default());
    let args = SupervisorArgs {
        children: vec![(
            spec("servo", "sleep", &["30"]),
            None,
            ChildPolicy::Essential(policy(3)),
        )],
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
        children: vec![(
            spec("network", "sleep", &["30"]),
            Some(watch),
            ChildPolicy::Essential(policy(1)),
        )],
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

/// A degradable child (the network's policy) that fails on every start never ends the station: it
/// is restarted without limit with a capped backoff, shows down and the station degraded, and once
/// it comes up (here: `sh` runs long once a file exists, and its heartbeat moves) it shows up and
/// the station is no longer degraded.
#[tokio::test]
async fn a_degradable_child_failing_every_start_degrades_the_station_until_it_comes_up() {
    let flag = std::env::temp_dir().join(format!("coop-degradable-{}", std::process::id()));
    let _ = std::fs::remove_file(&flag);
    let beat = Arc::new(coop_rt::sync::AtomicU64::new(0));
    let b = beat.clone();
    let watch = Watch {
        heartbeat: Arc::new(move || b.load(coop_rt::sync::Ordering::Relaxed)),
        timeout: Duration::from_secs(30),
        startup: Duration::from_secs(30),
    };
    let script = format!("test -e {} && exec sleep 30; exit 3", flag.display());
    let (tx, mut rx) = watch::channel(Status::default());
    let args = SupervisorArgs {
        children: vec![
            (
                spec("servo", "sleep", &["30"]),
                None,
                ChildPolicy::Essential(policy(1)),
            ),
            (
                spec("network", "sh", &["-c", &script]),
                Some(watch),
                ChildPolicy::Degradable(Backoff {
                    initial: Duration::from_millis(5),
                    max: Duration::from_millis(20),
                }),
            ),
        ],
        status: tx,
    };
    let (sup, handle) = Actor::spawn(None, StationSupervisor, args)
        .await
        .expect("supervisor");
    let s = wait_for(&mut rx, "many restarts, beyond any policy", |s| {
        s.restarts[1] > 10
    })
    .await;
    assert_eq!(s.end, None, "a degradable child never ends the station");
    assert_eq!(s.degraded, vec!["network".to_owned()]);
    assert_eq!(s.health[1].state, ChildState::Down);
    assert!(s.health[1].down_since_ns.is_some());
    let last = s.health[1].last_failure.clone().unwrap_or_default();
    assert!(last.contains("exited with status 3"), "{last}");
    assert_eq!(s.restarts[0], 0, "the essential child ran on");

    // From now on a start runs long, and beats (as a network process does once its session is
    // open).
    std::fs::write(&flag, "").expect("flag");
    let beating = tokio::spawn(async move {
        loop {
            beat.fetch_add(1, coop_rt::sync::Ordering::Relaxed);
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
    let s = wait_for(
        &mut rx,
        "the child up, the station no longer degraded",
        |s| s.health[1].state == ChildState::Up,
    )
    .await;
    assert!(s.degraded.is_empty(), "{s:?}");
    assert_eq!(s.health[1].down_since_ns, None);
    assert_eq!(s.end, None);
    beating.abort();
    sup.send_message(SupervisorMsg::BeginStop).expect("send");
    sup.send_message(SupervisorMsg::SignalAll(Signal::SIGTERM))
        .expect("send");
    wait_for(&mut rx, "the children to end", |s| s.live == 0).await;
    sup.stop(None);
    handle.await.expect("supervisor ends");
    let _ = std::fs::remove_file(&flag);
}
