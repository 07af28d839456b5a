//! Command-line pieces shared by the tools: durations with units, CPU lists, signal-driven stop.

use std::time::Duration;

use coop_rt::sync::{AtomicU64, Ordering};

/// Parses a duration as cyclictest does: a number with an optional unit `s`, `m`, `h` or `d`
/// (seconds when none), e.g. `90`, `5s`, `10m`, `1h`, `0.5s`.
///
/// # Errors
/// A message naming the value and the accepted forms.
pub fn parse_duration(s: &str) -> Result<Duration, String> {
    let bad = || {
        format!("invalid duration {s:?}: use a number with an optional unit s, m, h or d (e.g. 5s, 10m)")
    };
    let (num, unit) = match s.char_indices().find(|(_, c)| c.is_ascii_alphabetic()) {
        Some((i, _)) => (&s[..i], &s[i..]),
        None => (s, "s"),
    };
    let scale = match unit {
        "s" => 1.0,
        "m" => 60.0,
        "h" => 3600.0,
        "d" => 86_400.0,
        _ => return Err(bad()),
    };
    let v: f64 = num.parse().map_err(|_| bad())?;
    if !(v.is_finite() && v > 0.0 && v * scale < 1e9) {
        return Err(bad());
    }
    Ok(Duration::from_secs_f64(v * scale))
}

/// Parses a CPU list: `0`, `0,1`, `0-3`, `0-1,3`.
///
/// # Errors
/// A message naming the value and the accepted forms.
pub fn parse_cpu_list(s: &str) -> Result<Vec<usize>, String> {
    let bad = || format!("invalid CPU list {s:?}: use numbers and ranges, e.g. 0 or 0,1 or 0-3");
    let mut cpus = Vec::new();
    for part in s.split(',') {
        let part = part.trim();
        if let Some((a, b)) = part.split_once('-') {
            let (a, b): (usize, usize) =
                (a.parse().map_err(|_| bad())?, b.parse().map_err(|_| bad())?);
            if a > b || b >= 4096 {
                return Err(bad());
            }
            cpus.extend(a..=b);
        } else {
            let c: usize = part.parse().map_err(|_| bad())?;
            if c >= 4096 {
                return Err(bad());
            }
            cpus.push(c);
        }
    }
    cpus.dedup();
    Ok(cpus)
}

/// A stop flag raised by SIGINT or SIGTERM, without a signal handler: the signals are blocked in every
/// thread (the mask is inherited, so call this before spawning any) and one thread waits for them with
/// `sigwait`. Loops poll [`StopFlag::is_raised`], a relaxed atomic load.
#[derive(Debug, Clone)]
pub struct StopFlag(std::sync::Arc<AtomicU64>);

impl StopFlag {
    /// Blocks SIGINT and SIGTERM in the calling thread (and so in threads it spawns later) and starts the
    /// thread that raises the flag when one arrives.
    ///
    /// # Errors
    /// If the signal mask cannot be changed.
    pub fn on_sigint_sigterm() -> nix::Result<Self> {
        use nix::sys::signal::{SigSet, SigmaskHow, Signal};
        let mut set = SigSet::empty();
        set.add(Signal::SIGINT);
        set.add(Signal::SIGTERM);
        nix::sys::signal::pthread_sigmask(SigmaskHow::SIG_BLOCK, Some(&set), None)?;
        let flag = Self(std::sync::Arc::new(AtomicU64::new(0)));
        let raised = flag.clone();
        std::thread::Builder::new()
            .name("signals".into())
            .spawn(move || {
                if set.wait().is_ok() {
                    raised.raise();
                }
            })
            .map_err(|_| nix::errno::Errno::EAGAIN)?;
        Ok(flag)
    }
    /// A flag no signal raises (for library callers and tests).
    pub fn manual() -> Self {
        Self(std::sync::Arc::new(AtomicU64::new(0)))
    }
    /// Raises the flag.
    pub fn raise(&self) {
        self.0.store(1, Ordering::Relaxed);
    }
    /// Whether the flag was raised.
    #[inline]
    pub fn is_raised(&self) -> bool {
        self.0.load(Ordering::Relaxed) != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations() {
        assert_eq!(parse_duration("5s"), Ok(Duration::from_secs(5)));
        assert_eq!(parse_duration("90"), Ok(Duration::from_secs(90)));
        assert_eq!(parse_duration("2m"), Ok(Duration::from_secs(120)));
        assert_eq!(parse_duration("1h"), Ok(Duration::from_secs(3600)));
        assert_eq!(parse_duration("0.5s"), Ok(Duration::from_millis(500)));
        for bad in ["", "s", "5x", "-1s", "0", "NaNs", "inf", "1e12d"] {
            assert!(parse_duration(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn cpu_lists() {
        assert_eq!(parse_cpu_list("0"), Ok(vec![0]));
        assert_eq!(parse_cpu_list("0,1"), Ok(vec![0, 1]));
        assert_eq!(parse_cpu_list("0-3,5"), Ok(vec![0, 1, 2, 3, 5]));
        for bad in ["", "a", "3-1", "1-", "99999"] {
            assert!(parse_cpu_list(bad).is_err(), "{bad}");
        }
    }
}
