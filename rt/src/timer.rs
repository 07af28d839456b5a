//! A periodic timer with absolute deadlines on CLOCK_MONOTONIC, as cyclictest measures it.
//!
//! Each cycle sleeps with `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, deadline)` and the next
//! deadline is `deadline + period` (H6), so jitter never accumulates into drift and an EINTR retry sleeps
//! to the *same* deadline. Wake-up latency is `actual wake − scheduled deadline`.
//!
//! No coordinated omission: if a wake comes after one or more *later* deadlines already passed, those
//! deadlines are not silently dropped. They are reported as [`Wake::missed`] (overruns), and the loop
//! resumes on the next future deadline rather than running a burst of catch-up cycles (a servo must not
//! jerk). The latency tool records each missed deadline's latency too.

use std::time::Duration;

use nix::errno::Errno;
use nix::sys::time::TimeSpec;
use nix::time::{clock_gettime, clock_nanosleep, ClockId, ClockNanosleepFlags};

/// Nanoseconds on CLOCK_MONOTONIC (vDSO: no system call on x86_64 with a TSC or kvm clock).
#[inline]
pub fn monotonic_ns() -> u64 {
    // CLOCK_MONOTONIC cannot fail on Linux; 0 would only show as a huge latency, never a crash.
    clock_gettime(ClockId::CLOCK_MONOTONIC).map_or(0, |t| {
        (t.tv_sec() as u64)
            .wrapping_mul(1_000_000_000)
            .wrapping_add(t.tv_nsec() as u64)
    })
}

/// Sleeps until `deadline_ns` on CLOCK_MONOTONIC (absolute; EINTR sleeps again to the same time).
#[inline]
pub fn sleep_until(deadline_ns: u64) {
    // REAL-TIME: the one system call a loop makes.
    let ts = TimeSpec::new(
        (deadline_ns / 1_000_000_000) as _,
        (deadline_ns % 1_000_000_000) as _,
    );
    while let Err(Errno::EINTR) = clock_nanosleep(
        ClockId::CLOCK_MONOTONIC,
        ClockNanosleepFlags::TIMER_ABSTIME,
        &ts,
    ) {}
}

/// One wake-up of a [`PeriodicTimer`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wake {
    /// The deadline this wake was scheduled for, ns on CLOCK_MONOTONIC.
    pub deadline_ns: u64,
    /// When the thread actually ran again.
    pub woke_ns: u64,
    /// `woke_ns - deadline_ns`.
    pub latency_ns: u64,
    /// Later deadlines that had already passed at wake-up and were skipped (overruns).
    pub missed: u64,
}

/// Sleeps to absolute, evenly spaced deadlines.
#[derive(Debug, Clone)]
pub struct PeriodicTimer {
    period_ns: u64,
    next_ns: u64,
    overruns: u64,
}

impl PeriodicTimer {
    /// A timer whose first deadline is one period from now.
    ///
    /// # Panics
    /// If `period` is zero.
    pub fn new(period: Duration) -> Self {
        Self::starting_at(monotonic_ns(), period)
    }

    /// A timer whose first deadline is `start_ns + period`.
    ///
    /// # Panics
    /// If `period` is zero.
    pub fn starting_at(start_ns: u64, period: Duration) -> Self {
        let period_ns = u64::try_from(period.as_nanos()).unwrap_or(u64::MAX);
        assert!(period_ns > 0, "a periodic timer needs a non-zero period");
        Self {
            period_ns,
            next_ns: start_ns.saturating_add(period_ns),
            overruns: 0,
        }
    }

    /// Sleeps until the next deadline and reports the wake-up.
    #[inline]
    pub fn wait(&mut self) -> Wake {
        // REAL-TIME: no allocation, no lock, no logging; the only system call is clock_nanosleep.
        let deadline = self.next_ns;
        sleep_until(deadline);
        let woke = monotonic_ns();
        self.advance(deadline, woke)
    }

    /// Schedules the deadline after `deadline` given a wake at `woke`; pure, so it can be tested.
    #[inline]
    fn advance(&mut self, deadline: u64, woke: u64) -> Wake {
        let mut next = deadline.saturating_add(self.period_ns);
        let mut missed = 0;
        if woke >= next {
            missed = (woke - next) / self.period_ns + 1;
            next = next.saturating_add(missed.saturating_mul(self.period_ns));
        }
        self.next_ns = next;
        self.overruns += missed;
        Wake {
            deadline_ns: deadline,
            woke_ns: woke,
            latency_ns: woke.saturating_sub(deadline),
            missed,
        }
    }

    /// The period in ns.
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// The deadline the next `wait` sleeps to.
    pub fn next_deadline_ns(&self) -> u64 {
        self.next_ns
    }

    /// Deadlines missed so far.
    pub fn overruns(&self) -> u64 {
        self.overruns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deadlines_are_absolute_and_overruns_counted() {
        let mut t = PeriodicTimer::starting_at(0, Duration::from_millis(1));
        assert_eq!(t.next_deadline_ns(), 1_000_000);
        // On time (+3 µs): the next deadline is deadline + period, not wake + period.
        let w = t.advance(1_000_000, 1_003_000);
        assert_eq!((w.latency_ns, w.missed), (3_000, 0));
        assert_eq!(t.next_deadline_ns(), 2_000_000);
        // Woke 3.5 periods late: deadlines 3 ms, 4 ms and 5 ms passed; resume at 6 ms.
        let w = t.advance(2_000_000, 5_500_000);
        assert_eq!((w.latency_ns, w.missed), (3_500_000, 3));
        assert_eq!(t.next_deadline_ns(), 6_000_000);
        assert_eq!(t.overruns(), 3);
        // Exactly on the next deadline counts as missing it.
        let w = t.advance(6_000_000, 7_000_000);
        assert_eq!(w.missed, 1);
    }

    #[test]
    fn real_waits_never_wake_early() {
        let mut t = PeriodicTimer::new(Duration::from_micros(200));
        for _ in 0..20 {
            let w = t.wait();
            assert!(w.woke_ns >= w.deadline_ns);
            assert!(t.next_deadline_ns() > w.woke_ns);
        }
    }
}
