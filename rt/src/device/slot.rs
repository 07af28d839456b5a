//! The newest force command, from the servo to a device's bridge thread: a single-writer seqlock
//! over atomics (the Haply and ROS 2 backends). The servo never waits; a bridge that reads while
//! the servo writes retries; a servo that commands faster than the bridge sends overwrites, never
//! queues.

use std::sync::atomic::fence;

use coop_model::body::Vec3;

use super::{Command, ConfigError, DeviceFault, Sample};
use crate::sync::{AtomicU64, Ordering};

/// The newest command, written by the servo (one writer) and read by the bridge: a seqlock over
/// atomics, so the writer never waits and a reader retries a torn read.
#[derive(Debug, Default)]
pub struct CommandSlot {
    /// Even when stable; odd while the writer is in the middle. Counts writes × 2.
    seq: AtomicU64,
    /// 0 = release, 1 = force.
    kind: AtomicU64,
    xyz: [AtomicU64; 3],
}

/// The checks every bridged device's table shares: the rate its bridge exchanges at (1 Hz to
/// 10 kHz), a stale limit of at least two of its periods and at most a second, and the maxima the
/// device reports (positive, within what any desk device could). `rate_hz`, `stale_limit_ms`,
/// `max_force_n`, `max_stiffness_n_per_m`, `max_damping_n_s_per_m` and `workspace_radius_m` are
/// those fields' values (positive containment: NaN fails).
///
/// # Errors
/// The first field that breaks its rule, with its value.
pub fn check_bridged(
    rate_hz: f64,
    stale_limit_ms: f64,
    maxima: [f64; 4],
) -> Result<(), ConfigError> {
    let bad = |field: &str, value: f64, rule: String| ConfigError {
        field: field.to_owned(),
        value: value.to_string(),
        rule,
    };
    if !(1.0..=10_000.0).contains(&rate_hz) {
        return Err(bad("rate_hz", rate_hz, "must be in 1..=10000 Hz".into()));
    }
    let period_ms = 1e3 / rate_hz;
    if !(stale_limit_ms >= 2.0 * period_ms && stale_limit_ms <= 1000.0) {
        return Err(bad(
            "stale_limit_ms",
            stale_limit_ms,
            format!(
                "must be at least two periods at rate_hz ({:.3} ms) and at most 1000 ms",
                2.0 * period_ms
            ),
        ));
    }
    let [force, stiffness, damping, radius] = maxima;
    for (field, v, max) in [
        ("max_force_n", force, 100.0),
        ("max_stiffness_n_per_m", stiffness, 1e5),
        ("max_damping_n_s_per_m", damping, 1e3),
        ("workspace_radius_m", radius, 2.0),
    ] {
        if !(v > 0.0 && v <= max) {
            return Err(bad(field, v, format!("must be > 0 and <= {max}")));
        }
    }
    Ok(())
}

impl CommandSlot {
    /// Stores `cmd` (servo side; one writer only).
    pub fn store(&self, cmd: Command) {
        // REAL-TIME: no allocation, no lock, no syscall.
        let s = self.seq.load(Ordering::Relaxed);
        self.seq.store(s.wrapping_add(1), Ordering::Relaxed);
        // SYNC: orders the odd seq before the field stores; pairs with the reader's Acquire fence.
        fence(Ordering::Release);
        let (kind, f) = match cmd {
            Command::Force(f) => (1, f),
            Command::Release => (0, Vec3::zeros()),
        };
        self.kind.store(kind, Ordering::Relaxed);
        for (a, v) in self.xyz.iter().zip(f.iter()) {
            a.store(v.to_bits(), Ordering::Relaxed);
        }
        // SYNC: publishes the fields; pairs with the reader's Acquire load of seq.
        self.seq.store(s.wrapping_add(2), Ordering::Release);
    }

    /// The newest command and its write count (bridge side).
    pub fn load(&self) -> (u64, Command) {
        loop {
            // SYNC: pairs with the writer's final Release store.
            let s1 = self.seq.load(Ordering::Acquire);
            if s1 % 2 == 1 {
                std::hint::spin_loop();
                continue;
            }
            let kind = self.kind.load(Ordering::Relaxed);
            let f = Vec3::new(
                f64::from_bits(self.xyz[0].load(Ordering::Relaxed)),
                f64::from_bits(self.xyz[1].load(Ordering::Relaxed)),
                f64::from_bits(self.xyz[2].load(Ordering::Relaxed)),
            );
            // SYNC: keeps the field loads before the re-check; pairs with the writer's Release fence.
            fence(Ordering::Acquire);
            if self.seq.load(Ordering::Relaxed) == s1 {
                let cmd = if kind == 1 {
                    Command::Force(f)
                } else {
                    Command::Release
                };
                return (s1 / 2, cmd);
            }
        }
    }
}

/// What the servo knows of a device behind a bridge thread (Haply's, ROS 2's): the newest sample
/// the bridge delivered and the fault it last reported, and how old a sample may be before the
/// device counts as gone.
#[derive(Debug, Clone, Copy)]
pub struct BridgedState {
    newest: Sample,
    fault: Option<DeviceFault>,
    stale_limit_ns: u64,
}

impl BridgedState {
    /// Starts from the bridge's first sample.
    pub fn new(first: Sample, stale_limit_ns: u64) -> Self {
        Self {
            newest: first,
            fault: None,
            stale_limit_ns,
        }
    }

    /// A new sample from the bridge: the newest, and the fault (if any) is over.
    pub fn take(&mut self, s: Sample) {
        self.newest = s;
        self.fault = None;
    }

    /// A fault the bridge reports: it stands until the next sample.
    pub fn fail(&mut self, f: DeviceFault) {
        self.fault = Some(f);
    }

    /// The newest sample, fresh or not.
    pub fn newest(&self) -> Sample {
        self.newest
    }

    /// The stale limit, ns.
    pub fn stale_limit_ns(&self) -> u64 {
        self.stale_limit_ns
    }

    /// The newest sample if the device is known at `now_ns`: no fault, and not older than the
    /// stale limit (else [`DeviceFault::Disconnected`]).
    ///
    /// # Errors
    /// The bridge's fault, or a sample too old.
    pub fn fresh(&self, now_ns: u64) -> Result<Sample, DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        if let Some(f) = self.fault {
            return Err(f);
        }
        if now_ns.saturating_sub(self.newest.t_ns) > self.stale_limit_ns {
            return Err(DeviceFault::Disconnected);
        }
        Ok(self.newest)
    }
}

impl CommandSlot {
    /// The servo's command for a bridged device in `state` at `now_ns`: stored as given, except a
    /// force that is not finite or meant for a device not known now, which stores a release
    /// instead (no force on a hand whose device we cannot see) and says why.
    ///
    /// # Errors
    /// A non-finite force, or the device's fault or staleness.
    pub fn command(
        &self,
        state: &BridgedState,
        now_ns: u64,
        cmd: Command,
    ) -> Result<(), DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls (one seqlock write).
        if let Command::Force(f) = cmd {
            if !f.iter().all(|c| c.is_finite()) {
                self.store(Command::Release);
                return Err(DeviceFault::BadValue {
                    what: "force command",
                });
            }
            if let Err(e) = state.fresh(now_ns) {
                self.store(Command::Release);
                return Err(e);
            }
        }
        self.store(cmd);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;

    #[test]
    fn command_slot_keeps_the_newest_and_counts_writes() {
        let s = CommandSlot::default();
        assert_eq!(s.load(), (0, Command::Release));
        s.store(Command::Force(Vec3::new(1.0, 2.0, 3.0)));
        s.store(Command::Force(Vec3::new(4.0, 5.0, 6.0)));
        assert_eq!(s.load(), (2, Command::Force(Vec3::new(4.0, 5.0, 6.0))));
        s.store(Command::Release);
        assert_eq!(s.load(), (3, Command::Release));
    }

    #[test]
    fn command_slot_never_tears_across_threads() {
        let s = Arc::new(CommandSlot::default());
        let w = {
            let s = Arc::clone(&s);
            std::thread::spawn(move || {
                for i in 1..=100_000u32 {
                    let v = f64::from(i);
                    s.store(Command::Force(Vec3::new(v, v, v)));
                }
            })
        };
        let mut last = 0;
        while last < 100_000 {
            let (n, c) = s.load();
            assert!(n >= last, "write count went back");
            last = n;
            if let Command::Force(f) = c {
                assert!(f.x == f.y && f.y == f.z, "torn read {f:?}");
            }
        }
        w.join().expect("writer");
    }
}
