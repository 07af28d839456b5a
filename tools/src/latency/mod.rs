//! `latency`: wake-up latency of periodic real-time threads, measured as cyclictest does (H16).
//!
//! Each measuring thread applies the requested policy, priority and affinity (falling back loudly when
//! denied), then sleeps to absolute deadlines `interval` apart and records `actual wake − deadline` in
//! an hdrhistogram created and pre-faulted before the loop — one sample per wake-up, as cyclictest
//! records. Deadlines missed because a wake came too late are counted as overruns, and a second
//! histogram also records each missed deadline's latency (the coordinated-omission-corrected view:
//! a 30 ms stall at 1 kHz is 30 late deadlines, not one late wake), printed whenever there were
//! overruns. The header reports what is *in force*, read back from the kernel, not what was asked for.
//!
//! `measure` holds the threads and their timer loop, `report` everything printed (text and JSON,
//! which tests and the bench scripts parse), `attach` the reading of a running station; this file
//! the command line and the wiring of a run.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use clap::{ArgAction, Parser};
use coop_rt::sched::{self, Policy, Request};

use crate::cli::{parse_cpu_list, parse_duration, StopFlag};

mod attach;
mod measure;
mod report;
mod vendor;

pub use attach::attach;
pub use measure::{Report, ThreadResult};
pub use report::{print_report, report_json};
pub use vendor::vendor;

use measure::{Plan, Threads, PREFAULT_STACK};
use report::{print_header, print_live};

/// Command line of `latency`. Flags follow cyclictest's; `-h` is `--histogram` as there, and help is
/// `--help` only.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "latency",
    version,
    disable_help_flag = true,
    args_conflicts_with_subcommands = true,
    about = "Measure wake-up latency of periodic real-time threads (cyclictest-compatible).",
    long_about = "Measure wake-up latency of periodic real-time threads, the way cyclictest does.\n\n\
        Each thread sleeps to absolute CLOCK_MONOTONIC deadlines INTERVAL apart with \
        clock_nanosleep(TIMER_ABSTIME) and records actual wake minus deadline. Output: '#' header \
        lines with what is in force (policy, priority, affinity, mlock, kernel preempt model), a \
        cyclictest line per thread (T: P: I: C: Min: Act: Avg: Max:, microseconds), then percentiles \
        from an hdrhistogram. Missed deadlines are counted as overruns, never hidden.\n\n\
        Defaults differ from cyclictest in one way: the policy is SCHED_FIFO priority 80, since \
        that is what coop-haptics' servo loops run at. Without the privilege for it the tool warns \
        once and measures under SCHED_OTHER, saying so in the header. Stop early with Ctrl-C.",
    after_help = "Examples:\n  latency -D 5s -q                 5 s, one thread, FIFO 80, summary only\n  \
        latency -i 1000 -p 80 -a 1 -m -D 60s --json out.json\n  latency -t -a -h 100 -l 10000      one thread per CPU, pinned, histogram to 100 us\n  \
        latency attach user1 -D 60s       a running station's servo and physics loops\n  \
        latency vendor --library /usr/lib/libHD.so -D 10s   OpenHaptics' scheduler beside our loop"
)]
pub struct Args {
    /// Period of each thread in microseconds.
    #[arg(short = 'i', long = "interval", value_name = "US", default_value_t = 1000,
          value_parser = clap::value_parser!(u64).range(10..=10_000_000))]
    pub interval_us: u64,
    /// Cycles per thread, then stop (0 = no limit).
    #[arg(short = 'l', long, value_name = "N", default_value_t = 0)]
    pub loops: u64,
    /// Run for this long: a number with unit s, m, h or d (seconds if none).
    #[arg(short = 'D', long, value_name = "TIME", value_parser = parse_duration)]
    pub duration: Option<Duration>,
    /// Priority: 1..=99 for fifo and rr [default: 80], 0 for other.
    #[arg(short = 'p', long, value_name = "PRIO")]
    pub priority: Option<i32>,
    /// Scheduling policy: fifo, rr or other.
    #[arg(long, value_name = "POLICY", default_value = "fifo", value_parser = parse_policy)]
    pub policy: Policy,
    /// Pin threads to CPUs (e.g. 1, 0-1, 0,1), round-robin; `-a` alone pins thread N to CPU N.
    #[arg(short = 'a', long, value_name = "CPUS", num_args = 0..=1, default_missing_value = "auto")]
    pub affinity: Option<String>,
    /// Number of measuring threads; `-t` alone runs one per allowed CPU.
    #[arg(short = 't', long, value_name = "N", num_args = 0..=1, default_value = "1",
          default_missing_value = "0")]
    pub threads: usize,
    /// Lock all memory (mlockall) before measuring.
    #[arg(short = 'm', long)]
    pub mlockall: bool,
    /// Quiet: print only the summary at the end, no live updates.
    #[arg(short = 'q', long)]
    pub quiet: bool,
    /// Print a histogram of 1 us buckets up to US microseconds at the end.
    #[arg(short = 'h', long = "histogram", value_name = "US",
          value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    pub histogram: Option<u32>,
    /// Write the results as JSON to FILE.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Do not hold /dev/cpu_dma_latency at 0 us (saves power, adds idle-exit latency).
    #[arg(long)]
    pub laptop: bool,
    /// Print help.
    #[arg(long, action = ArgAction::Help)]
    pub help: Option<bool>,
    /// Attach to a running station instead of measuring here.
    #[command(subcommand)]
    pub attach: Option<Attach>,
}

/// `latency attach`.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum Attach {
    /// Print a running station's servo and physics loop latency, live, in this tool's format
    /// (read from the station's control block; the loops are not disturbed).
    Attach {
        /// Station (site) name.
        station: String,
        /// Session name.
        #[arg(long, default_value = "local")]
        session: String,
        /// Stop after this long (s, m, h, d); default: until Ctrl-C.
        #[arg(short = 'D', long, value_name = "TIME", value_parser = parse_duration)]
        duration: Option<Duration>,
        /// Quiet: print only the summary at the end.
        #[arg(short = 'q', long)]
        quiet: bool,
        /// Write the summary as JSON to FILE.
        #[arg(long, value_name = "FILE")]
        json: Option<PathBuf>,
        /// Print help (the top level gives `-h` to the histogram, as cyclictest does, and turns
        /// clap's own help flag off, which a subcommand inherits).
        #[arg(short = 'h', long, action = ArgAction::Help)]
        help: Option<bool>,
    },
    /// Run a vendor's own servo loop (OpenHaptics' HD scheduler, on the device its library finds)
    /// beside ours, same run, same period and scheduling, and print how late each loop's ticks
    /// start (against the previous tick's start plus the period) to p99.9.
    Vendor {
        /// OpenHaptics' libHD.so (or the mock the tests build).
        #[arg(long, value_name = "FILE")]
        library: PathBuf,
        /// Run for this long (s, m, h, d).
        #[arg(short = 'D', long, value_name = "TIME", value_parser = parse_duration, default_value = "10s")]
        duration: Duration,
        /// SCHED_FIFO priority of both loops (0: SCHED_OTHER); warns once if refused.
        #[arg(short = 'p', long, default_value_t = 80)]
        priority: i32,
        /// Write both loops' figures as JSON to FILE.
        #[arg(long, value_name = "FILE")]
        json: Option<PathBuf>,
        /// Print help.
        #[arg(short = 'h', long, action = ArgAction::Help)]
        help: Option<bool>,
    },
}

fn parse_policy(s: &str) -> Result<Policy, String> {
    s.parse()
}

fn thread_requests(args: &Args) -> anyhow::Result<Vec<Request>> {
    let allowed = sched::allowed_cpus();
    let n = if args.threads == 0 {
        allowed.len().max(1)
    } else {
        args.threads
    };
    if n > 256 {
        bail!("--threads {n} is more than 256");
    }
    let list = match args.affinity.as_deref() {
        None => None,
        Some("auto") => Some(allowed.clone()),
        Some(s) => Some(parse_cpu_list(s).map_err(anyhow::Error::msg)?),
    };
    let priority = args
        .priority
        .unwrap_or(if args.policy.is_realtime() { 80 } else { 0 });
    let mut reqs = Vec::with_capacity(n);
    for i in 0..n {
        let req = Request {
            policy: args.policy,
            priority,
            cpus: list.as_ref().map(|l| vec![l[i % l.len()]]),
            prefault_stack_bytes: PREFAULT_STACK,
        };
        req.validate()?;
        reqs.push(req);
    }
    Ok(reqs)
}

/// Runs the measurement: sets up, prints the header (unless `print` is false), measures, and returns
/// the report. Live lines go to stdout when it is a terminal and `--quiet` is not given.
///
/// # Errors
/// A bad request (priority out of range, CPU not allowed) or a failure to start threads.
pub fn run(args: &Args, cmdline: String, print: bool) -> anyhow::Result<Report> {
    let reqs = thread_requests(args)?;
    let stop =
        StopFlag::on_sigint_sigterm().context("blocking SIGINT/SIGTERM for the stop flag")?;
    let mut warnings = Vec::new();
    if args.mlockall {
        if let Err(w) = sched::lock_memory() {
            warnings.push(w);
        }
    }
    let dma = if args.laptop {
        Err("not requested (--laptop)".to_owned())
    } else {
        sched::hold_cpu_dma_latency_zero().map_err(|e| e.kind().to_string())
    };
    let end_after = args.duration;
    let plan = Plan {
        period: Duration::from_micros(args.interval_us),
        loops: args.loops,
        end_after,
    };
    let threads = Threads::start(reqs, plan, &stop)?;
    let in_force = threads.wait_for_setup(&stop, &mut warnings)?;
    let kernel = sched::kernel_info();
    let mlocked = sched::memory_locked();
    if print {
        for w in &warnings {
            eprintln!("{w}");
        }
        print_header(
            args,
            &kernel,
            &in_force,
            mlocked,
            &dma.as_ref().map(drop).map_err(Clone::clone),
        );
    }
    threads.go();
    let started = Instant::now();
    let live_lines = print && !args.quiet && std::io::stdout().is_terminal();
    let mut printed = false;
    while threads.running() {
        std::thread::sleep(Duration::from_millis(100));
        if end_after.is_some_and(|d| started.elapsed() >= d + Duration::from_millis(200)) {
            stop.raise(); // threads stop on their own at the deadline; this is the backstop
        }
        if live_lines {
            print_live(threads.live(), &in_force, args.interval_us, printed);
            printed = true;
        }
    }
    let interrupted = stop.is_raised() && end_after.is_none_or(|d| started.elapsed() < d);
    Ok(Report {
        cmdline,
        threads: threads.join(),
        warnings,
        mlocked,
        dma_latency: dma.map(drop),
        kernel,
        interrupted,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_parse_like_cyclictest() {
        let a = Args::try_parse_from([
            "latency", "-i", "500", "-l", "10", "-p", "70", "-a", "1", "-t", "2", "-m", "-q", "-h",
            "50", "--json", "x.json",
        ])
        .expect("valid flags");
        assert_eq!(
            (a.interval_us, a.loops, a.priority, a.threads),
            (500, 10, Some(70), 2)
        );
        assert_eq!(a.affinity.as_deref(), Some("1"));
        assert!(a.mlockall && a.quiet);
        assert_eq!(a.histogram, Some(50));
        let a = Args::try_parse_from(["latency", "-t", "-a", "-D", "1m"]).expect("valid flags");
        assert_eq!((a.threads, a.affinity.as_deref()), (0, Some("auto")));
        assert_eq!(a.duration, Some(Duration::from_secs(60)));
        for bad in [
            vec!["latency", "-i", "0"],
            vec!["latency", "-D", "5x"],
            vec!["latency", "--policy", "deadline"],
            vec!["latency", "--bogus"],
        ] {
            assert!(Args::try_parse_from(&bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn bad_priority_and_cpu_are_errors_before_anything_runs() {
        let a = Args::try_parse_from(["latency", "-p", "120"]).expect("parses");
        assert!(thread_requests(&a)
            .unwrap_err()
            .to_string()
            .contains("priority 120"));
        let a = Args::try_parse_from(["latency", "-a", "4000"]).expect("parses");
        assert!(thread_requests(&a)
            .unwrap_err()
            .to_string()
            .contains("CPU 4000"));
        let a = Args::try_parse_from(["latency", "--policy", "other", "-p", "5"]).expect("parses");
        assert!(thread_requests(&a).is_err());
    }
}
