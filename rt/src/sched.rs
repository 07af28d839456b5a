//! Scheduling for real-time loops: CPU affinity, SCHED_FIFO / SCHED_RR / SCHED_OTHER with priority,
//! `mlockall`, stack pre-faulting, and a report of what is actually in force.
//!
//! A denied privilege never stops a run: the request falls back (to SCHED_OTHER, to no memory lock) and
//! the caller gets one [`Warning`] that names the fix; [`InForce`] is read back from the kernel, so a
//! report never claims what was merely asked for.
//!
//! `unsafe` is allowed here only for `sched_setscheduler` / `sched_getscheduler` / `sched_getparam`,
//! which nix does not wrap (H2).
#![allow(unsafe_code)]

use std::fmt;
use std::str::FromStr;

use nix::errno::Errno;
use nix::libc;
use nix::sched::{sched_getaffinity, sched_setaffinity, CpuSet};
use nix::sys::mman::{mlockall, MlockAllFlags};
use nix::unistd::Pid;

/// A scheduling policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Policy {
    /// SCHED_FIFO: real-time, runs until it blocks or a higher priority preempts it.
    Fifo,
    /// SCHED_RR: real-time, round-robin among equal priorities.
    Rr,
    /// SCHED_OTHER: the normal time-sharing policy.
    Other,
    /// Any other policy the kernel reports (SCHED_BATCH, SCHED_IDLE, SCHED_DEADLINE).
    Unknown(i32),
}

impl Policy {
    fn raw(self) -> i32 {
        match self {
            Self::Fifo => libc::SCHED_FIFO,
            Self::Rr => libc::SCHED_RR,
            Self::Other => libc::SCHED_OTHER,
            Self::Unknown(p) => p,
        }
    }
    fn from_raw(p: i32) -> Self {
        match p {
            libc::SCHED_FIFO => Self::Fifo,
            libc::SCHED_RR => Self::Rr,
            libc::SCHED_OTHER => Self::Other,
            p => Self::Unknown(p),
        }
    }
    /// Whether this is a real-time policy.
    pub fn is_realtime(self) -> bool {
        matches!(self, Self::Fifo | Self::Rr)
    }
}

impl fmt::Display for Policy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Fifo => f.write_str("SCHED_FIFO"),
            Self::Rr => f.write_str("SCHED_RR"),
            Self::Other => f.write_str("SCHED_OTHER"),
            Self::Unknown(p) => write!(f, "policy {p}"),
        }
    }
}

impl FromStr for Policy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().trim_start_matches("sched_") {
            "fifo" => Ok(Self::Fifo),
            "rr" => Ok(Self::Rr),
            "other" | "normal" => Ok(Self::Other),
            _ => Err(format!("unknown policy {s:?}: use fifo, rr or other")),
        }
    }
}

/// What a real-time thread asks for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Request {
    /// Policy wanted.
    pub policy: Policy,
    /// Priority: 1..=99 for FIFO/RR, 0 for OTHER.
    pub priority: i32,
    /// CPUs to pin to; `None` leaves the affinity alone.
    pub cpus: Option<Vec<usize>>,
    /// Bytes of stack to touch now so the loop never page-faults on it.
    pub prefault_stack_bytes: usize,
}

/// A request that can never be honoured: a usage error, not a privilege problem.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RequestError {
    /// Priority outside the policy's range.
    #[error("priority {priority} is out of range for {policy}: use {min}..={max}")]
    Priority {
        /// Policy asked for.
        policy: Policy,
        /// Priority asked for.
        priority: i32,
        /// Smallest allowed.
        min: i32,
        /// Largest allowed.
        max: i32,
    },
    /// A CPU that this process may not run on.
    #[error("CPU {cpu} is not available to this process (allowed: {allowed:?})")]
    Cpu {
        /// CPU asked for.
        cpu: usize,
        /// CPUs allowed.
        allowed: Vec<usize>,
    },
}

impl Request {
    /// Checks the request against the policy's priority range and the CPUs this process may use.
    ///
    /// # Errors
    /// [`RequestError`] naming the value and the rule.
    pub fn validate(&self) -> Result<(), RequestError> {
        let (min, max) = priority_range(self.policy);
        if !(min..=max).contains(&self.priority) {
            return Err(RequestError::Priority {
                policy: self.policy,
                priority: self.priority,
                min,
                max,
            });
        }
        if let Some(cpus) = &self.cpus {
            let allowed = allowed_cpus();
            if let Some(&cpu) = cpus.iter().find(|c| !allowed.contains(c)) {
                return Err(RequestError::Cpu { cpu, allowed });
            }
        }
        Ok(())
    }
}

fn priority_range(policy: Policy) -> (i32, i32) {
    // SAFETY: plain libc queries with no pointers; they only read the policy constant.
    unsafe {
        (
            libc::sched_get_priority_min(policy.raw()),
            libc::sched_get_priority_max(policy.raw()),
        )
    }
}

/// A privilege was missing and the run goes on without it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Warning {
    /// A short key, so a process with several threads prints each warning once.
    pub key: &'static str,
    /// The message, naming what fell back and how to fix it.
    pub message: String,
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "WARN: {}", self.message)
    }
}

/// What the kernel says is in force for the calling thread.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InForce {
    /// Policy in force.
    pub policy: Policy,
    /// Priority in force.
    pub priority: i32,
    /// CPUs the thread may run on.
    pub cpus: Vec<usize>,
}

/// Applies `req` to the **calling thread**: affinity, then policy and priority, then touches
/// `prefault_stack_bytes` of stack. Returns what is in force afterwards and any warnings.
///
/// # Errors
/// [`RequestError`] if the request can never be honoured (bad priority or CPU).
pub fn apply_to_current_thread(req: &Request) -> Result<(InForce, Vec<Warning>), RequestError> {
    req.validate()?;
    let mut warnings = Vec::new();
    if let Some(cpus) = &req.cpus {
        let mut set = CpuSet::new();
        for &c in cpus {
            // validate() checked c is an allowed CPU, hence < CpuSet::count().
            let _ = set.set(c);
        }
        if let Err(e) = sched_setaffinity(Pid::from_raw(0), &set) {
            warnings.push(Warning {
                key: "affinity",
                message: format!(
                    "cannot pin to CPUs {cpus:?} ({e}); running unpinned. Fix: check the cpuset \
                     cgroup (cpuset.cpus) of this process"
                ),
            });
        }
    }
    if let Err(e) = set_scheduler(req.policy, req.priority) {
        warnings.push(Warning {
            key: "policy",
            message: format!(
                "cannot set {} priority {} ({e}); running SCHED_OTHER instead. Fix: run as root or \
                 grant CAP_SYS_NICE (setcap cap_sys_nice+ep <binary>), or raise the rtprio limit \
                 (ulimit -r 99, or 'rtprio' in /etc/security/limits.conf); with cgroup v1 \
                 CONFIG_RT_GROUP_SCHED also give the group cpu.rt_runtime_us",
                req.policy, req.priority
            ),
        });
    }
    prefault_stack(req.prefault_stack_bytes);
    Ok((in_force(), warnings))
}

fn set_scheduler(policy: Policy, priority: i32) -> Result<(), Errno> {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: `param` is a valid sched_param that outlives the call; pid 0 means the calling thread.
    let rc = unsafe { libc::sched_setscheduler(0, policy.raw(), &param) };
    Errno::result(rc).map(drop)
}

/// Reads back the calling thread's policy, priority and affinity.
pub fn in_force() -> InForce {
    // SAFETY: pid 0 is the calling thread; no pointers.
    let policy = unsafe { libc::sched_getscheduler(0) };
    let mut param = libc::sched_param { sched_priority: 0 };
    // SAFETY: `param` is a valid, writable sched_param for the duration of the call.
    let rc = unsafe { libc::sched_getparam(0, &mut param) };
    InForce {
        policy: Policy::from_raw(policy),
        priority: if rc == 0 { param.sched_priority } else { -1 },
        cpus: current_cpus(),
    }
}

fn current_cpus() -> Vec<usize> {
    match sched_getaffinity(Pid::from_raw(0)) {
        Ok(set) => (0..CpuSet::count())
            .filter(|&c| set.is_set(c).unwrap_or(false))
            .collect(),
        Err(_) => Vec::new(),
    }
}

/// Makes the calling thread an ordinary one: SCHED_OTHER at priority 0, on any CPU the process
/// may use. For a thread that is not real-time (a device's bridge) started from one that is: a
/// thread takes its creator's policy and affinity, and would compete with the servo at its
/// priority on its CPU. Best effort: a thread that cannot be changed stays as it was.
pub fn make_ordinary() {
    let _ = apply_to_current_thread(&Request {
        policy: Policy::Other,
        priority: 0,
        cpus: Some(allowed_cpus()),
        prefault_stack_bytes: 0,
    });
}

/// CPUs this process may be pinned to: the cgroup's effective cpuset, or else the online CPUs.
///
/// Not the calling thread's mask: a thread already pinned to one CPU may still pin a new thread to
/// another.
pub fn allowed_cpus() -> Vec<usize> {
    [
        "/sys/fs/cgroup/cpuset.cpus.effective",
        "/sys/devices/system/cpu/online",
    ]
    .iter()
    .find_map(|p| {
        std::fs::read_to_string(p)
            .ok()
            .and_then(|s| parse_cpu_ranges(s.trim()))
    })
    .filter(|v| !v.is_empty())
    .unwrap_or_else(current_cpus)
}

/// Parses the kernel's CPU list format (`0-3,5`).
fn parse_cpu_ranges(s: &str) -> Option<Vec<usize>> {
    let mut cpus = Vec::new();
    for part in s.split(',').filter(|p| !p.is_empty()) {
        match part.split_once('-') {
            Some((a, b)) => cpus.extend(a.parse::<usize>().ok()?..=b.parse().ok()?),
            None => cpus.push(part.parse().ok()?),
        }
    }
    Some(cpus)
}

/// Locks all current and future memory of the process (`mlockall(MCL_CURRENT | MCL_FUTURE)`) so the
/// loops never page-fault. Process-wide: call once.
///
/// # Errors
/// A [`Warning`] naming the fix when the kernel refuses; the run goes on unlocked.
pub fn lock_memory() -> Result<(), Warning> {
    mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE).map_err(|e| Warning {
        key: "mlock",
        message: format!(
            "cannot lock memory ({e}); running with pageable memory. Fix: run as root or grant \
             CAP_IPC_LOCK, or raise the memlock limit (ulimit -l unlimited, or 'memlock' in \
             /etc/security/limits.conf)"
        ),
    })
}

/// What a process about to start real-time loops will ask of the kernel ([`missing_privileges`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wanted {
    /// Every page locked, now and later ([`lock_memory`]).
    pub lock_memory: bool,
    /// `/dev/cpu_dma_latency` held at 0 ([`hold_cpu_dma_latency_zero`]).
    pub cpu_dma_latency: bool,
    /// A real-time policy at a priority (none: SCHED_OTHER only, which needs no privilege).
    pub realtime: Option<(Policy, i32)>,
}

/// A privilege a process lacks, found by trying it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Missing {
    /// The [`Warning::key`] of the warning a loop process would print for it: `mlock`,
    /// `cpu_dma_latency` or `policy`.
    pub key: &'static str,
    /// What cannot be done, with the kernel's reason.
    pub what: String,
    /// How the loops run without it.
    pub instead: &'static str,
    /// What gives it, short of running as root.
    pub grant: &'static str,
}

/// Tries each privilege `want` names, undoing each at once, and returns those the kernel refused:
/// `mlockall` (then `munlockall`), opening `/dev/cpu_dma_latency` for writing (closed again: an
/// open descriptor is what holds a request), and the real-time policy on a thread of its own that
/// ends right after. For a supervisor that says once what its children will lack, before they
/// start.
pub fn missing_privileges(want: &Wanted) -> Vec<Missing> {
    let mut missing = Vec::new();
    if want.lock_memory {
        match mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE) {
            Ok(()) => {
                // Locked only to see whether it could be: the loop processes lock their own.
                let _ = nix::sys::mman::munlockall();
            }
            Err(e) => missing.push(Missing {
                key: "mlock",
                what: format!("cannot lock memory ({e})"),
                instead: "memory pageable",
                grant: "CAP_IPC_LOCK (or a memlock limit: ulimit -l unlimited, 'memlock' in /etc/security/limits.conf)",
            }),
        }
    }
    if want.cpu_dma_latency {
        if let Err(e) = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/cpu_dma_latency")
        {
            missing.push(Missing {
                key: "cpu_dma_latency",
                what: format!("cannot hold /dev/cpu_dma_latency at 0 ({e})"),
                instead: "CPUs free to enter deep idle states between cycles",
                grant: "write access to /dev/cpu_dma_latency",
            });
        }
    }
    if let Some((policy, priority)) = want.realtime {
        let tried = std::thread::Builder::new()
            .name("privilege-check".into())
            .spawn(move || set_scheduler(policy, priority))
            .map(|t| t.join());
        if let Ok(Ok(Err(e))) = tried {
            missing.push(Missing {
                key: "policy",
                what: format!("cannot set {policy} priority {priority} ({e})"),
                instead: "SCHED_OTHER",
                grant: "CAP_SYS_NICE (or an rtprio limit: ulimit -r 99, 'rtprio' in /etc/security/limits.conf)",
            });
        }
    }
    missing
}

/// Whether the process has memory locked (`VmLck` in `/proc/self/status` is non-zero).
pub fn memory_locked() -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmLck:"))
                .and_then(|l| l.split_whitespace().nth(1).map(|v| v != "0"))
        })
        .unwrap_or(false)
}

/// Touches `bytes` of stack below the caller so later growth into it does not page-fault.
#[inline(never)]
pub fn prefault_stack(bytes: usize) {
    const CHUNK: usize = 4096;
    fn touch(remaining: usize) {
        let mut page = [0u8; CHUNK];
        std::hint::black_box(&mut page);
        if remaining > CHUNK {
            touch(remaining - CHUNK);
        }
        std::hint::black_box(&page);
    }
    if bytes > 0 {
        touch(bytes);
    }
}

/// Holds `/dev/cpu_dma_latency` at 0 µs while alive, keeping CPUs out of deep idle states (what
/// cyclictest does by default). Dropping it restores the default.
#[derive(Debug)]
pub struct DmaLatencyGuard {
    _file: std::fs::File,
}

/// Asks the kernel to keep CPU wake-up latency at 0 µs for as long as the guard lives.
///
/// # Errors
/// The I/O error when the file cannot be opened or written (not root, or no PM QoS interface).
pub fn hold_cpu_dma_latency_zero() -> std::io::Result<DmaLatencyGuard> {
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/cpu_dma_latency")?;
    f.write_all(&0i32.to_ne_bytes())?;
    Ok(DmaLatencyGuard { _file: f })
}

/// What the kernel offers real-time loops.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KernelInfo {
    /// Kernel release (`uname -r`).
    pub release: String,
    /// Preemption model: `PREEMPT_RT`, `PREEMPT_DYNAMIC`, `PREEMPT`, or `none/voluntary` (from
    /// `/sys/kernel/realtime` and the kernel version string).
    pub preempt: String,
    /// `/sys/kernel/realtime` says 1 (a PREEMPT_RT kernel).
    pub realtime: bool,
    /// `kernel.sched_rt_runtime_us` / `sched_rt_period_us`: the RT throttling budget (-1 = none).
    pub rt_runtime_us: i64,
    /// RT throttling period.
    pub rt_period_us: i64,
}

/// Reads the kernel's real-time facts.
pub fn kernel_info() -> KernelInfo {
    let read = |p: &str| std::fs::read_to_string(p).map(|s| s.trim().to_owned());
    let uname = nix::sys::utsname::uname().ok();
    let release = uname
        .as_ref()
        .map(|u| u.release().to_string_lossy().into_owned())
        .unwrap_or_default();
    let version = uname
        .as_ref()
        .map(|u| u.version().to_string_lossy().into_owned())
        .unwrap_or_default();
    let realtime = read("/sys/kernel/realtime").is_ok_and(|s| s == "1");
    let preempt = if realtime || version.contains("PREEMPT_RT") {
        "PREEMPT_RT"
    } else if version.contains("PREEMPT_DYNAMIC") {
        "PREEMPT_DYNAMIC"
    } else if version.contains("PREEMPT") {
        "PREEMPT"
    } else {
        "none/voluntary"
    };
    let num = |p: &str| read(p).ok().and_then(|s| s.parse().ok()).unwrap_or(-1);
    KernelInfo {
        release,
        preempt: preempt.to_owned(),
        realtime,
        rt_runtime_us: num("/proc/sys/kernel/sched_rt_runtime_us"),
        rt_period_us: num("/proc/sys/kernel/sched_rt_period_us"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_requests_are_usage_errors() {
        let req = Request {
            policy: Policy::Fifo,
            priority: 100,
            cpus: None,
            prefault_stack_bytes: 0,
        };
        assert!(matches!(
            req.validate(),
            Err(RequestError::Priority {
                priority: 100,
                min: 1,
                max: 99,
                ..
            })
        ));
        let req = Request {
            policy: Policy::Other,
            priority: 0,
            cpus: Some(vec![4096]),
            prefault_stack_bytes: 0,
        };
        assert!(matches!(
            req.validate(),
            Err(RequestError::Cpu { cpu: 4096, .. })
        ));
    }

    #[test]
    fn other_policy_applies_and_reads_back() {
        let cpus = allowed_cpus();
        let req = Request {
            policy: Policy::Other,
            priority: 0,
            cpus: Some(vec![cpus[0]]),
            prefault_stack_bytes: 64 * 1024,
        };
        let handle = std::thread::spawn(move || apply_to_current_thread(&req));
        let (in_force, warnings) = handle.join().expect("thread").expect("valid request");
        assert_eq!(in_force.policy, Policy::Other);
        assert_eq!(in_force.cpus, vec![cpus[0]]);
        assert!(warnings.is_empty(), "{warnings:?}");
    }

    #[test]
    fn kernel_cpu_lists_parse() {
        assert_eq!(parse_cpu_ranges("0-3,5"), Some(vec![0, 1, 2, 3, 5]));
        assert_eq!(parse_cpu_ranges("1"), Some(vec![1]));
        assert_eq!(parse_cpu_ranges("x"), None);
    }

    #[test]
    fn policy_names_parse() {
        assert_eq!("fifo".parse(), Ok(Policy::Fifo));
        assert_eq!("SCHED_RR".parse(), Ok(Policy::Rr));
        assert_eq!("other".parse(), Ok(Policy::Other));
        assert!("deadline".parse::<Policy>().is_err());
    }
}
