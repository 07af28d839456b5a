//! What the tool prints: the `#` header of what is in force, the live cyclictest lines, the final
//! report (cyclictest lines, percentiles, the `-h` histogram) and the JSON.

use std::io::Write;

use coop_rt::sched::{self, InForce};
use coop_rt::sync::Ordering;
use hdrhistogram::Histogram;

use super::measure::{Live, Report, ThreadResult};
use super::Args;

/// Nanoseconds to whole microseconds, rounded to nearest.
pub(super) fn us(ns: u64) -> u64 {
    (ns + 500) / 1_000
}

/// The `#` header: the kernel, and per thread what is in force against what was asked for.
pub(super) fn print_header(
    args: &Args,
    k: &sched::KernelInfo,
    in_force: &[(usize, InForce)],
    mlocked: bool,
    dma: &Result<(), String>,
) {
    println!(
        "# latency (coop-haptics {}): wake-up latency, cyclictest semantics",
        env!("CARGO_PKG_VERSION")
    );
    println!(
        "# kernel: {} preempt: {} realtime: {} rt-throttling: {}/{} us",
        k.release,
        k.preempt,
        if k.realtime { "yes" } else { "no" },
        k.rt_runtime_us,
        k.rt_period_us
    );
    let requested_prio = args
        .priority
        .unwrap_or(if args.policy.is_realtime() { 80 } else { 0 });
    for (i, f) in in_force {
        println!(
            "# T:{i:2} policy: {} priority: {} (requested {} {}) affinity: {}",
            f.policy,
            f.priority,
            args.policy,
            requested_prio,
            cpus_text(&f.cpus)
        );
    }
    println!(
        "# mlockall: {} /dev/cpu_dma_latency: {}",
        if mlocked { "yes" } else { "no" },
        match dma {
            Ok(()) => "0 us (held)".to_owned(),
            Err(e) => format!("not held ({e})"),
        }
    );
    let limit = match (args.loops, args.duration) {
        (0, None) => "until Ctrl-C".to_owned(),
        (l, None) => format!("{l} loops"),
        (0, Some(d)) => format!("{} s", d.as_secs_f64()),
        (l, Some(d)) => format!("{l} loops or {} s", d.as_secs_f64()),
    };
    println!(
        "# interval: {} us threads: {} run: {limit}",
        args.interval_us,
        in_force.len()
    );
}

fn cpus_text(cpus: &[usize]) -> String {
    cpus.iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(",")
}

/// The live cyclictest lines, one per thread, over the previous ones when `again`.
pub(super) fn print_live(
    live: &[Live],
    in_force: &[(usize, InForce)],
    interval_us: u64,
    again: bool,
) {
    let mut out = std::io::stdout().lock();
    if again {
        let _ = write!(out, "\x1b[{}A", live.len());
    }
    for (i, l) in live.iter().enumerate() {
        let c = l.cycles.load(Ordering::Relaxed);
        let prio = in_force.get(i).map_or(0, |(_, f)| f.priority);
        let _ =
            writeln!(
            out,
            "T:{i:2} P:{prio:2} I:{interval_us} C:{c:8} Min:{:7} Act:{:5} Avg:{:5} Max:{:8}\x1b[K",
            us(if c == 0 { 0 } else { l.min_ns.load(Ordering::Relaxed) }),
            us(l.last_ns.load(Ordering::Relaxed)),
            us(l.sum_ns.load(Ordering::Relaxed).checked_div(c).unwrap_or(0)),
            us(l.max_ns.load(Ordering::Relaxed)),
        );
    }
    let _ = out.flush();
}

/// Prints the per-thread cyclictest lines, percentiles and (with `-h`) the histogram.
pub fn print_report(args: &Args, r: &Report) {
    if r.interrupted {
        println!("# stopped by signal");
    }
    for t in &r.threads {
        println!(
            "T:{:2} ({:6}) P:{:2} I:{} C:{:8} Min:{:7} Act:{:5} Avg:{:5} Max:{:8}",
            t.index,
            t.tid,
            t.in_force.priority,
            args.interval_us,
            t.cycles,
            us(t.min_ns),
            us(t.last_ns),
            us(t.avg_ns()),
            us(t.hist.max()),
        );
    }
    for t in &r.threads {
        println!(
            "# T:{:2} latency us: p50 {:.1} p99 {:.1} p99.9 {:.1} p99.99 {:.1} max {:.1} overruns {}",
            t.index,
            t.pct_us(0.5),
            t.pct_us(0.99),
            t.pct_us(0.999),
            t.pct_us(0.9999),
            t.hist.max() as f64 / 1_000.0,
            t.overruns
        );
        if t.overruns > 0 {
            let q = |p: f64| t.hist_all.value_at_quantile(p) as f64 / 1_000.0;
            println!(
                "# T:{:2} with the {} missed deadlines (no coordinated omission) us: p50 {:.1} p99 {:.1} p99.9 {:.1} p99.99 {:.1}",
                t.index,
                t.overruns,
                q(0.5),
                q(0.99),
                q(0.999),
                q(0.9999)
            );
        }
    }
    if let Some(limit) = args.histogram {
        println!("# Histogram");
        let buckets: Vec<_> = r.threads.iter().map(|t| us_buckets(&t.hist)).collect();
        for b in 0..u64::from(limit) {
            let cols: Vec<String> = buckets
                .iter()
                .map(|m| format!("{:06}", m.get(&b).copied().unwrap_or(0)))
                .collect();
            println!("{b:06} {}", cols.join("\t"));
        }
        let col = |f: &dyn Fn(&ThreadResult) -> u64| {
            r.threads
                .iter()
                .map(|t| format!(" {:05}", f(t)))
                .collect::<String>()
        };
        println!("# Total:{}", col(&|t| t.hist.len()));
        println!("# Min Latencies:{}", col(&|t| us(t.min_ns)));
        println!("# Avg Latencies:{}", col(&|t| us(t.avg_ns())));
        println!("# Max Latencies:{}", col(&|t| us(t.hist.max())));
        println!(
            "# Histogram Overflows:{}",
            col(&|t| us_buckets(&t.hist)
                .range(u64::from(limit)..)
                .map(|(_, n)| n)
                .sum())
        );
    }
}

/// The samples in 1 µs buckets. Each hdrhistogram sub-bucket goes wholly to the µs bucket of its
/// median value (`count_between` on µs boundaries would count a straddling sub-bucket twice).
fn us_buckets(h: &Histogram<u64>) -> std::collections::BTreeMap<u64, u64> {
    let mut out = std::collections::BTreeMap::new();
    for v in h.iter_recorded() {
        let us = h.median_equivalent(v.value_iterated_to()) / 1_000;
        *out.entry(us).or_insert(0) += v.count_at_value();
    }
    out
}

/// The report as JSON: cyclictest's top-level keys (`file_version`, `cmdline`, `sysinfo`, `thread`,
/// `return_code`) plus percentiles and what was in force.
pub fn report_json(args: &Args, r: &Report) -> serde_json::Value {
    let threads: serde_json::Map<String, serde_json::Value> = r
        .threads
        .iter()
        .map(|t| {
            let to_json = |h: &Histogram<u64>| -> serde_json::Map<String, serde_json::Value> {
                us_buckets(h)
                    .into_iter()
                    .map(|(b, n)| (b.to_string(), n.into()))
                    .collect()
            };
            let hist = to_json(&t.hist);
            let all = |q: f64| t.hist_all.value_at_quantile(q) as f64 / 1_000.0;
            (
                t.index.to_string(),
                serde_json::json!({
                    "tid": t.tid,
                    "policy": t.in_force.policy.to_string(),
                    "priority": t.in_force.priority,
                    "cpus": t.in_force.cpus,
                    "interval_us": args.interval_us,
                    "cycles": t.cycles,
                    "overruns": t.overruns,
                    "min_us": t.min_ns as f64 / 1_000.0,
                    "avg_us": t.avg_ns() as f64 / 1_000.0,
                    "max_us": t.hist.max() as f64 / 1_000.0,
                    "p50_us": t.pct_us(0.5),
                    "p99_us": t.pct_us(0.99),
                    "p999_us": t.pct_us(0.999),
                    "p9999_us": t.pct_us(0.9999),
                    "histogram_us": hist,
                    "with_missed_deadlines": {
                        "samples": t.hist_all.len(),
                        "p99_us": all(0.99),
                        "p999_us": all(0.999),
                        "p9999_us": all(0.9999),
                        "histogram_us": to_json(&t.hist_all),
                    },
                }),
            )
        })
        .collect();
    serde_json::json!({
        "file_version": 1,
        "tool": "coop-haptics latency",
        "cmdline": r.cmdline,
        "sysinfo": {
            "kernel": r.kernel.release,
            "preempt": r.kernel.preempt,
            "realtime": r.kernel.realtime,
            "rt_runtime_us": r.kernel.rt_runtime_us,
            "rt_period_us": r.kernel.rt_period_us,
            "cpus_allowed": sched::allowed_cpus(),
        },
        "in_force": {
            "mlockall": r.mlocked,
            "cpu_dma_latency_held": r.dma_latency.is_ok(),
        },
        "warnings": r.warnings.iter().map(|w| w.message.clone()).collect::<Vec<_>>(),
        "interrupted": r.interrupted,
        "thread": threads,
        "return_code": 0,
    })
}
