//! `latency vendor`: a vendor's own servo loop (OpenHaptics' HD scheduler, driving the device the
//! library finds) beside ours (`clock_nanosleep` to absolute deadlines), in the same run, at the
//! same period and scheduling: how late each tick starts against the one before plus the period
//! (the one figure both loops have), as percentiles to p99.9.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context;
use coop_rt::device::openhaptics::{OpenHapticsConfig, OpenHapticsDevice};
use coop_rt::sched::{self, Policy, Request};
use coop_rt::shm::{BlockSegment, SegmentName};
use coop_rt::stats::{LoopSnapshot, LoopStats};
use coop_rt::sync::{AtomicU64, Ordering};
use coop_rt::timer::PeriodicTimer;

/// What the two loops did: `(name, snapshot)`, the vendor's first.
pub type Loops = [(&'static str, LoopSnapshot); 2];

/// Runs the HD scheduler of the device `library` finds, and our loop beside it, for `duration`
/// under SCHED_FIFO `priority` (warning once where that is refused), printing both loops' tick
/// lateness (and writing it as JSON to `json`).
///
/// # Errors
/// The library or device does not open, or the vendor's loop fails.
pub fn vendor(
    library: &Path,
    duration: Duration,
    priority: i32,
    json: Option<&Path>,
) -> anyhow::Result<Loops> {
    let config = OpenHapticsConfig {
        library: Some(library.to_path_buf()),
        ..OpenHapticsConfig::default()
    };
    let dev = OpenHapticsDevice::open(&config).context("opening the OpenHaptics device")?;
    let period_ns = 1_000_000_000 / u64::from(config.scheduler_rate_hz);
    let session = format!("latv{}", std::process::id());
    let segment = |what: &str| -> anyhow::Result<BlockSegment<LoopStats>> {
        Ok(BlockSegment::<LoopStats>::create(&SegmentName::new(
            &session, "vendor", what,
        )?)?)
    };
    let (theirs, ours) = (segment("hd")?, segment("ours")?);
    ours.set_period_ns(period_ns);
    let request = Request {
        policy: if priority > 0 {
            Policy::Fifo
        } else {
            Policy::Other
        },
        priority,
        cpus: None,
        prefault_stack_bytes: 64 * 1024,
    };
    // The scheduler's thread inherits this thread's scheduling, as it would a servo process's.
    let (_, warnings) = sched::apply_to_current_thread(&request)?;
    if let Some(w) = warnings.first() {
        eprintln!("latency vendor: {w}");
    }
    let stop = AtomicU64::new(0);
    let sched = dev.scheduler();
    let started = Instant::now();
    std::thread::scope(|s| -> anyhow::Result<()> {
        s.spawn(|| {
            let _ = sched::apply_to_current_thread(&request);
            let mut timer = PeriodicTimer::new(Duration::from_nanos(period_ns));
            let mut last = 0u64;
            while stop.load(Ordering::Relaxed) == 0 {
                // REAL-TIME: no allocation, no lock, no logging, no syscalls but the sleep.
                let wake = timer.wait();
                // The vendor's figure, on our loop: start against the previous start.
                ours.record_tick(wake.woke_ns, last, 0);
                last = wake.woke_ns;
            }
        });
        let ran = sched.run_hd(Some(&theirs), &mut |_| started.elapsed() < duration);
        stop.store(1, Ordering::Relaxed);
        ran.map(|_| ()).map_err(anyhow::Error::from)
    })?;
    drop(dev);
    let loops: Loops = [
        ("HD scheduler", theirs.snapshot()),
        ("ours (clock_nanosleep)", ours.snapshot()),
    ];
    println!(
        "# latency vendor: {library} at {} Hz for {:.1} s, {}: each tick's start against the previous one's plus the period",
        config.scheduler_rate_hz,
        started.elapsed().as_secs_f64(),
        if priority > 0 { format!("SCHED_FIFO {priority} asked") } else { "SCHED_OTHER".into() },
        library = library.display()
    );
    println!("# loop                      ticks   late p50 us  p99 us  p99.9 us  max us  overruns");
    for (name, s) in &loops {
        let q = |p: f64| s.wake_us.value_at_quantile(p);
        println!(
            "{name:<24} {:>8} {:>11} {:>7} {:>9} {:>7} {:>9}",
            s.cycles,
            q(0.5),
            q(0.99),
            q(0.999),
            s.wake_us.max(),
            s.overruns
        );
    }
    if let Some(path) = json {
        let v: Vec<_> = loops
            .iter()
            .map(|(name, s)| {
                serde_json::json!({
                    "loop": name,
                    "ticks": s.cycles,
                    "late_us": {
                        "p50": s.wake_us.value_at_quantile(0.5),
                        "p99": s.wake_us.value_at_quantile(0.99),
                        "p999": s.wake_us.value_at_quantile(0.999),
                        "max": s.wake_us.max(),
                    },
                    "overruns": s.overruns,
                })
            })
            .collect();
        std::fs::write(path, serde_json::to_string_pretty(&v)? + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(loops)
}
