//! Running a loop body as a station process does: record the scheduling in force (the caller applied
//! it with [`crate::sched::apply_to_current_thread`] and reported any fallback) in the child's slot
//! of the control block, sleep to absolute deadlines, record
//! each cycle's wake-up latency and compute time into the loop's live statistics, bump the heartbeat,
//! and leave when the body says so (it watches the run state: the servo first ramps its force to zero).

use std::time::Duration;

use crate::device::{VendorLoop, VendorLoopError};
use crate::sched::{InForce, Policy};
use crate::shm::control::{Child, ControlBlock};
use crate::stats::LoopStats;
use crate::sync::Ordering;
use crate::timer::{monotonic_ns, PeriodicTimer};

/// How a run went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunSummary {
    /// Cycles run.
    pub cycles: u64,
    /// Deadlines missed.
    pub overruns: u64,
}

/// Runs `step(now_ns) -> keep_going` every `period` on the calling thread until it returns false,
/// recording `in_force` in `child`'s slot and each cycle in `stats`.
pub fn run_periodic(
    control: &ControlBlock,
    child: Child,
    stats: &LoopStats,
    period: Duration,
    in_force: &InForce,
    mut step: impl FnMut(u64) -> bool,
) -> RunSummary {
    let slot = control.child(child);
    announce(control, child, in_force);
    stats.set_period_ns(u64::try_from(period.as_nanos()).unwrap_or(u64::MAX));
    let mut timer = PeriodicTimer::new(period);
    let mut cycles = 0u64;
    loop {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls but clock_nanosleep.
        let wake = timer.wait();
        let keep_going = step(wake.woke_ns);
        let done = monotonic_ns();
        stats.record(
            wake.latency_ns,
            done.saturating_sub(wake.woke_ns),
            wake.missed,
        );
        slot.heartbeat.fetch_add(1, Ordering::Relaxed);
        cycles += 1;
        if !keep_going {
            break;
        }
    }
    RunSummary {
        cycles,
        overruns: timer.overruns(),
    }
}

/// Runs `step(now_ns) -> keep_going` in a vendor's loop (`vendor` calls it on its own thread, at
/// its own rate) until it returns false, as [`run_periodic`] runs it in ours: `in_force` recorded
/// in `child`'s slot, each tick in `stats` (its lateness against the vendor's period) and in the
/// slot's heartbeat, so the supervisor sees a vendor loop that hangs as it sees ours.
///
/// # Errors
/// The vendor's loop did not start, or stopped calling back.
pub fn run_vendor(
    control: &ControlBlock,
    child: Child,
    stats: &LoopStats,
    in_force: &InForce,
    vendor: &dyn VendorLoop,
    step: &mut (dyn FnMut(u64) -> bool + Send),
) -> Result<RunSummary, VendorLoopError> {
    let slot = control.child(child);
    announce(control, child, in_force);
    let mut tick = |now: u64| {
        // REAL-TIME: no allocation, no lock, no logging; the vendor's thread.
        let keep_going = step(now);
        slot.heartbeat.fetch_add(1, Ordering::Relaxed);
        keep_going
    };
    let summary = vendor.run(Some(stats), &mut tick)?;
    Ok(RunSummary {
        cycles: summary.ticks,
        overruns: stats.overruns.load(Ordering::Relaxed),
    })
}

/// Records in `child`'s slot what scheduling is in force and which process runs it.
fn announce(control: &ControlBlock, child: Child, in_force: &InForce) {
    let slot = control.child(child);
    slot.policy
        .store(policy_number(in_force.policy), Ordering::Relaxed);
    slot.priority
        .store(in_force.priority.max(0) as u64, Ordering::Relaxed);
    slot.cpus.store(
        in_force
            .cpus
            .iter()
            .filter(|&&c| c < 64)
            .fold(0u64, |m, &c| m | (1 << c)),
        Ordering::Relaxed,
    );
    slot.pid
        .store(u64::from(std::process::id()), Ordering::Relaxed);
}

fn policy_number(p: Policy) -> u64 {
    match p {
        Policy::Other => 0,
        Policy::Fifo => 1,
        Policy::Rr => 2,
        Policy::Unknown(n) => n.max(0) as u64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shm::control::RunState;
    use crate::shm::{BlockSegment, SegmentName};

    /// A loop at 1 kHz under the test thread's own scheduling runs until the run state says stop,
    /// recording statistics, heartbeat, pid and what is in force.
    #[test]
    fn runs_until_stopped_and_records_what_it_did() {
        let name =
            SegmentName::new(&format!("run{}", std::process::id()), "t", "ctl").expect("name");
        let ctl = BlockSegment::<ControlBlock>::create(&name).expect("control");
        ctl.set_run_state(RunState::Running);
        let in_force = crate::sched::in_force();
        let mut n = 0u64;
        let summary = run_periodic(
            &ctl,
            Child::Physics,
            &ctl.physics.stats,
            Duration::from_millis(1),
            &in_force,
            |_| {
                n += 1;
                if n == 50 {
                    ctl.set_run_state(RunState::Stopping);
                }
                ctl.run_state() == RunState::Running
            },
        );
        assert_eq!(summary.cycles, 50);
        let s = ctl.physics.stats.snapshot();
        assert_eq!(s.cycles, 50);
        assert_eq!(s.period_ns, 1_000_000);
        assert_eq!(s.wake_us.len(), 50);
        assert_eq!(
            ctl.child(Child::Physics).heartbeat.load(Ordering::Relaxed),
            50
        );
        assert_eq!(
            ctl.child(Child::Physics).policy.load(Ordering::Relaxed),
            policy_number(in_force.policy)
        );
        assert_eq!(
            ctl.child(Child::Physics).pid.load(Ordering::Relaxed),
            u64::from(std::process::id())
        );
    }
}
