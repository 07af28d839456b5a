//! `latency attach`: a running station's servo and physics loops, read from its control block (the
//! loops are not disturbed) and printed in this tool's format.

use std::io::{IsTerminal, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context;
use coop_rt::shm::control::{Child, ControlBlock};
use coop_rt::shm::BlockSegment;
use coop_rt::stats::{LoopSnapshot, TAIL_END_US};
use coop_rt::sync::Ordering;

use super::report::us;
use crate::cli::StopFlag;

/// The station's loops: name, control-block slot, and thread number in the output.
const LOOPS: [(&str, Child, usize); 2] =
    [("servo", Child::Servo, 0), ("physics", Child::Physics, 1)];

/// `latency attach`: a running station's loops, in this tool's format. Live lines on a terminal
/// unless quiet; the summary (header, T: lines, percentiles) at the end.
///
/// # Errors
/// No such station, or its control block fails validation.
pub fn attach(
    station: &str,
    session: &str,
    duration: Option<Duration>,
    quiet: bool,
    json: Option<&Path>,
) -> anyhow::Result<()> {
    let names = coop_rt::shm::station::Names::of(session, station)?;
    let ctl = BlockSegment::<ControlBlock>::open(&names.control, Duration::from_millis(500))
        .with_context(|| format!("attaching to station {station} of session {session}"))?;
    let stop = StopFlag::on_sigint_sigterm().context("blocking SIGINT/SIGTERM")?;
    let start = LOOPS.map(|(_, _, i)| snapshot(&ctl, i));
    let began = Instant::now();
    let live = !quiet && std::io::stdout().is_terminal();
    watch(&ctl, &start, &stop, duration, began, live);
    // The summary covers the attach window only: the histograms now, less the ones at attach start
    // (a station's start-up, mlockall faulting its pages in, is not what the loop does once running).
    let windows = LOOPS.map(|(_, _, i)| window(snapshot(&ctl, i), &start[i]));
    println!(
        "# latency attach: station {station} of session {session}, {:.1} s attached",
        began.elapsed().as_secs_f64()
    );
    print_in_force(&ctl);
    let threads = print_summary(&ctl, &windows);
    let roundtrip = print_roundtrip(&ctl);
    if let Some(path) = json {
        let v = serde_json::json!({ "file_version": 1, "tool": "coop-haptics latency attach", "station": station, "session": session, "thread": threads, "roundtrip": roundtrip, "return_code": 0 });
        std::fs::write(path, serde_json::to_string_pretty(&v)? + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Loop `i`'s statistics now.
fn snapshot(ctl: &ControlBlock, i: usize) -> LoopSnapshot {
    if i == 0 {
        ctl.servo.stats.snapshot()
    } else {
        ctl.physics.stats.snapshot()
    }
}

/// Waits until `stop` is raised or `duration` has passed since `began`, printing the live lines
/// (since `start`) every 200 ms when `live`.
fn watch(
    ctl: &ControlBlock,
    start: &[LoopSnapshot; 2],
    stop: &StopFlag,
    duration: Option<Duration>,
    began: Instant,
    live: bool,
) {
    let mut printed = false;
    loop {
        std::thread::sleep(Duration::from_millis(200));
        let done = stop.is_raised() || duration.is_some_and(|d| began.elapsed() >= d);
        if live && !done {
            let mut out = std::io::stdout().lock();
            if printed {
                let _ = write!(out, "\x1b[{}A", LOOPS.len());
            }
            for (_, c, i) in LOOPS {
                let now = snapshot(ctl, i);
                let _ = writeln!(out, "{}\x1b[K", line(ctl, c, i, &start[i], &now));
            }
            let _ = out.flush();
            printed = true;
        }
        if done {
            break;
        }
    }
}

/// Loop `c`'s cyclictest line: cycles since `base`, the rest from `now`.
fn line(ctl: &ControlBlock, c: Child, i: usize, base: &LoopSnapshot, now: &LoopSnapshot) -> String {
    let slot = ctl.child(c);
    let cycles = now.cycles.saturating_sub(base.cycles);
    format!(
        "T:{i:2} ({:6}) P:{:2} I:{} C:{cycles:8} Min:{:7} Act:{:5} Avg:{:5} Max:{:8}",
        slot.pid.load(Ordering::Relaxed),
        slot.priority.load(Ordering::Relaxed),
        now.period_ns / 1000,
        us(now.wake_min_ns),
        us(now.last_wake_ns),
        us(now.wake_sum_ns.checked_div(now.cycles).unwrap_or(0)),
        us(now.wake_max_ns),
    )
}

/// `now` less `base`: the statistics of the window between them.
fn window(now: LoopSnapshot, base: &LoopSnapshot) -> LoopSnapshot {
    let mut w = now.clone();
    w.wake_us = histogram_between(&now.wake_us, &base.wake_us);
    w.compute_us = histogram_between(&now.compute_us, &base.compute_us);
    w.cycles = now.cycles.saturating_sub(base.cycles);
    w.overruns = now.overruns.saturating_sub(base.overruns);
    w.wake_sum_ns = now.wake_sum_ns.saturating_sub(base.wake_sum_ns);
    w.wake_min_ns = w.wake_us.min() * 1_000;
    w.wake_max_ns = w.wake_us.max() * 1_000;
    w
}

/// The samples recorded between `base` and `now` (two snapshots of one histogram). Below
/// [`TAIL_END_US`] every value is a fixed bucket, so this is an exact difference. The overflow beyond
/// it is recorded at the lifetime maximum, which may have grown in between: those are counted
/// together and put at `now`'s maximum (hdrhistogram's `subtract` would fail there and keep the
/// whole lifetime's overflow in the window).
fn histogram_between(
    now: &hdrhistogram::Histogram<u64>,
    base: &hdrhistogram::Histogram<u64>,
) -> hdrhistogram::Histogram<u64> {
    let mut w = hdrhistogram::Histogram::new_from(now);
    let mut over = 0;
    for v in now.iter_recorded() {
        let value = v.value_iterated_to();
        if value >= TAIL_END_US {
            over += v.count_at_value();
        } else {
            let n = v.count_at_value().saturating_sub(base.count_at(value));
            // Recording none would still move the window's min and max to `value`.
            if n > 0 {
                w.saturating_record_n(value, n);
            }
        }
    }
    let over_before: u64 = base
        .iter_recorded()
        .filter(|v| v.value_iterated_to() >= TAIL_END_US)
        .map(|v| v.count_at_value())
        .sum();
    if over > over_before {
        w.saturating_record_n(now.max(), over - over_before);
    }
    w
}

/// The `#` lines of what is in force per loop, as the station's children published it.
fn print_in_force(ctl: &ControlBlock) {
    let policy = |c: Child| match ctl.child(c).policy.load(Ordering::Relaxed) {
        1 => "SCHED_FIFO",
        2 => "SCHED_RR",
        _ => "SCHED_OTHER",
    };
    for (name, c, i) in LOOPS {
        let mask = ctl.child(c).cpus.load(Ordering::Relaxed);
        let cpus: Vec<String> = (0..64)
            .filter(|b| mask & (1 << b) != 0)
            .map(|b| b.to_string())
            .collect();
        println!(
            "# T:{i:2} {name}: policy: {} priority: {} affinity: {}",
            policy(c),
            ctl.child(c).priority.load(Ordering::Relaxed),
            cpus.join(",")
        );
    }
}

/// Prints each loop's cyclictest line and percentiles over its window; returns them as the JSON's
/// `thread` object.
fn print_summary(
    ctl: &ControlBlock,
    windows: &[LoopSnapshot; 2],
) -> serde_json::Map<String, serde_json::Value> {
    let mut threads = serde_json::Map::new();
    for (name, c, i) in LOOPS {
        let snap = &windows[i];
        let zero = LoopSnapshot {
            cycles: 0,
            ..snap.clone()
        };
        println!("{}", line(ctl, c, i, &zero, snap));
        let q = |p: f64| snap.wake_us.value_at_quantile(p);
        println!(
            "# T:{i:2} latency us: p50 {} p99 {} p99.9 {} p99.99 {} max {:.1} overruns {}",
            q(0.5),
            q(0.99),
            q(0.999),
            q(0.9999),
            snap.wake_max_ns as f64 / 1e3,
            snap.overruns
        );
        let hist: serde_json::Map<String, serde_json::Value> = snap
            .wake_us
            .iter_recorded()
            .map(|v| (v.value_iterated_to().to_string(), v.count_at_value().into()))
            .collect();
        threads.insert(
            i.to_string(),
            serde_json::json!({
                "loop": name, "cycles": snap.cycles, "overruns": snap.overruns, "interval_us": snap.period_ns / 1000,
                "min_us": snap.wake_min_ns as f64 / 1e3, "max_us": snap.wake_max_ns as f64 / 1e3,
                "p50_us": q(0.5), "p99_us": q(0.99), "p999_us": q(0.999), "p9999_us": q(0.9999),
                "histogram_us": hist,
            }),
        );
    }
    threads
}

/// Prints the servo → physics → servo round trip since the station started; returns it as the
/// JSON's `roundtrip` object.
fn print_roundtrip(ctl: &ControlBlock) -> serde_json::Value {
    let rt = ctl.servo.roundtrip.to_hdr();
    let rt_count = ctl.servo.roundtrip_count.load(Ordering::Relaxed);
    let rt_max = ctl.servo.roundtrip.max_ns.load(Ordering::Relaxed) as f64 / 1e3;
    println!(
        "# servo -> physics -> servo round trip us ({rt_count} samples): p50 {} p99 {} max {rt_max:.1}",
        rt.value_at_quantile(0.5),
        rt.value_at_quantile(0.99)
    );
    serde_json::json!({ "samples": rt_count, "p50_us": rt.value_at_quantile(0.5), "p99_us": rt.value_at_quantile(0.99), "max_us": rt_max })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hist(samples: &[(u64, u64)]) -> hdrhistogram::Histogram<u64> {
        let mut h = hdrhistogram::Histogram::new_with_bounds(1, 1_000_000, 3).expect("bounds");
        for &(v, n) in samples {
            h.record_n(v, n).expect("in range");
        }
        h
    }

    #[test]
    fn a_window_holds_only_its_own_samples_even_when_the_maximum_grew() {
        // Before the window: 100 at 20 us, 3 tail samples at 7 ms, 2 beyond the tail at 150 ms
        // (the lifetime maximum then). In it: 50 at 20 us, one at 9 ms, one beyond at 400 ms.
        let base = hist(&[(20, 100), (7_000, 3), (150_000, 2)]);
        let now = hist(&[(20, 150), (7_000, 3), (9_000, 1), (400_000, 3)]);
        let w = histogram_between(&now, &base);
        assert_eq!(w.len(), 52);
        assert_eq!(w.count_at(20), 50);
        assert_eq!(w.count_at(7_000), 0);
        assert_eq!(w.count_at(9_000), 1);
        assert_eq!(w.count_at(400_000), 1);
        assert!(w.equivalent(w.max(), 400_000));
        // A window without the lifetime's largest samples has its own maximum and minimum.
        let later = hist(&[(10, 1), (20, 160), (7_000, 3), (9_000, 2), (400_000, 3)]);
        let w = histogram_between(&later, &now);
        assert_eq!(w.len(), 12);
        assert!(w.equivalent(w.max(), 9_000));
        assert_eq!(w.min(), 10);
    }
}
