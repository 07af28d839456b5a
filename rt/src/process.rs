//! Who a process is, robust to pid reuse: a pid plus its start time since boot.
//!
//! A pid alone cannot tell a dead creator from a new process that got the same pid, so segment headers
//! and ring claims record the start time too (from `/proc/<pid>/stat`, field 22, in clock ticks). Both
//! fit one `u64` token (pid < 2^22 on Linux, start ticks < 2^42, i.e. 1,390 years at 100 Hz), so a claim
//! can be taken with a single compare-and-swap.
//!
//! Not for the hot path: checking liveness reads a `/proc` file.

use std::fs;

const START_BITS: u32 = 42;
const START_MASK: u64 = (1 << START_BITS) - 1;
/// Linux's `PID_MAX_LIMIT` on 64-bit is 2^22.
const PID_LIMIT: u64 = 1 << 22;

/// A process identity: pid in the high 22 bits, start ticks in the low 42. Never 0 (pid 0 is not a
/// user process), so 0 can mean "nobody".
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ProcessToken(u64);

impl ProcessToken {
    /// Packs a pid and start time. `None` for a pid out of Linux's range.
    pub fn new(pid: u32, start_ticks: u64) -> Option<Self> {
        let pid = u64::from(pid);
        if pid == 0 || pid >= PID_LIMIT {
            return None;
        }
        Some(Self((pid << START_BITS) | (start_ticks & START_MASK)))
    }
    /// The token of the calling process (cached after the first call).
    pub fn current() -> Self {
        static ME: std::sync::OnceLock<ProcessToken> = std::sync::OnceLock::new();
        *ME.get_or_init(|| {
            let pid = std::process::id();
            // Our own /proc entry always exists; fall back to 0 ticks only if /proc is not mounted.
            let start = start_ticks(pid).unwrap_or(0);
            Self::new(pid, start).unwrap_or(Self(1 << START_BITS))
        })
    }
    /// From the raw word stored in shared memory; `None` for 0 (nobody) or a value no token can have.
    pub fn from_raw(raw: u64) -> Option<Self> {
        (raw != 0 && raw >> START_BITS != 0).then_some(Self(raw))
    }
    /// The raw word to store in shared memory.
    pub fn raw(self) -> u64 {
        self.0
    }
    /// The process id.
    pub fn pid(self) -> u32 {
        (self.0 >> START_BITS) as u32
    }
    /// The start time in clock ticks since boot, modulo 2^42.
    pub fn start_ticks(self) -> u64 {
        self.0 & START_MASK
    }
    /// Whether this exact process (same pid *and* same start time) still runs. A zombie counts as dead.
    pub fn is_alive(self) -> bool {
        matches!(liveness(self.pid(), self.start_ticks()), Liveness::Alive)
    }
}

/// What `/proc` says about a recorded (pid, start time).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Liveness {
    /// That process runs.
    Alive,
    /// No such pid, or a zombie.
    Gone,
    /// The pid runs but started at another time: the pid was reused.
    Reused {
        /// Start ticks of the process that has the pid now.
        found_start_ticks: u64,
    },
}

/// Checks whether the process `pid` that started at `start_ticks` (mod 2^42) still runs.
pub fn liveness(pid: u32, start_ticks: u64) -> Liveness {
    match stat_fields(pid) {
        None => Liveness::Gone,
        Some((state, _)) if state == 'Z' || state == 'X' => Liveness::Gone,
        Some((_, found)) if found & START_MASK == start_ticks & START_MASK => Liveness::Alive,
        Some((_, found)) => Liveness::Reused {
            found_start_ticks: found & START_MASK,
        },
    }
}

/// The start time of `pid` in clock ticks since boot, or `None` if there is no such process.
pub fn start_ticks(pid: u32) -> Option<u64> {
    stat_fields(pid).map(|(_, t)| t)
}

/// (state, starttime) from `/proc/<pid>/stat`. The command name (field 2) may hold spaces and
/// parentheses, so fields are counted after the *last* `)`.
fn stat_fields(pid: u32) -> Option<(char, u64)> {
    let text = fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    parse_stat(&text)
}

fn parse_stat(text: &str) -> Option<(char, u64)> {
    let rest = &text[text.rfind(')')? + 1..];
    let mut fields = rest.split_ascii_whitespace();
    let state = fields.next()?.chars().next()?;
    // After the state (field 3), starttime is field 22: 18 more fields on.
    let start = fields.nth(18)?.parse().ok()?;
    Some((state, start))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_stat_with_hostile_command_name() {
        let line = "1234 (a) b) c (d) S 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 98765 20 21";
        assert_eq!(parse_stat(line), Some(('S', 98765)));
        assert_eq!(parse_stat("garbage"), None);
    }

    #[test]
    fn token_round_trips_and_self_is_alive() {
        let me = ProcessToken::current();
        assert_eq!(me.pid(), std::process::id());
        assert_eq!(ProcessToken::from_raw(me.raw()), Some(me));
        assert!(me.is_alive());
        assert_eq!(ProcessToken::from_raw(0), None);
        assert_eq!(ProcessToken::new(0, 5), None);
        assert_eq!(ProcessToken::new(1 << 22, 5), None);
    }

    #[test]
    fn reused_pid_is_not_alive() {
        let me = ProcessToken::current();
        let other = ProcessToken::new(me.pid(), me.start_ticks() + 1).expect("valid token");
        assert!(!other.is_alive());
        assert!(matches!(
            liveness(me.pid(), me.start_ticks() + 1),
            Liveness::Reused { .. }
        ));
    }
}
