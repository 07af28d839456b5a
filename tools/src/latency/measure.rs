//! The measuring threads: each applies its scheduling request, preallocates its histograms, waits
//! for the others at a barrier, then runs the timer loop and hands back a [`ThreadResult`].

use std::sync::{mpsc, Arc, Barrier};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{bail, Context};
use coop_rt::sched::{self, InForce, Request, Warning};
use coop_rt::sync::{AtomicU64, Ordering};
use coop_rt::timer::{monotonic_ns, PeriodicTimer};
use hdrhistogram::Histogram;

use crate::cli::StopFlag;

/// Largest latency the histogram holds: 10 s (larger samples saturate at this value; max is kept).
const HIST_MAX_NS: u64 = 10_000_000_000;
/// Missed deadlines recorded per wake at most; the rest are still counted as overruns.
const MISSED_RECORD_CAP: u64 = 10_000;
/// Stack pre-faulted for each measuring thread.
pub(super) const PREFAULT_STACK: usize = 256 * 1024;

/// Live figures a measuring thread publishes for the monitor (single writer, relaxed).
#[derive(Debug, Default)]
pub(super) struct Live {
    pub(super) cycles: AtomicU64,
    pub(super) last_ns: AtomicU64,
    pub(super) min_ns: AtomicU64,
    pub(super) max_ns: AtomicU64,
    pub(super) sum_ns: AtomicU64,
    pub(super) overruns: AtomicU64,
}

/// What one measuring thread found.
#[derive(Debug, Clone)]
pub struct ThreadResult {
    /// Thread number, from 0.
    pub index: usize,
    /// Kernel thread id.
    pub tid: i32,
    /// Policy, priority and CPUs in force while measuring.
    pub in_force: InForce,
    /// Cycles measured.
    pub cycles: u64,
    /// Deadlines missed.
    pub overruns: u64,
    /// Smallest latency, ns.
    pub min_ns: u64,
    /// Latest latency, ns.
    pub last_ns: u64,
    /// Sum of latencies, ns.
    pub sum_ns: u64,
    /// Wake-up latencies, one per cycle (cyclictest's semantics), ns.
    pub hist: Histogram<u64>,
    /// Wake-up latencies plus the latency of every missed deadline (no coordinated omission), ns.
    pub hist_all: Histogram<u64>,
}

impl ThreadResult {
    pub(super) fn avg_ns(&self) -> u64 {
        self.sum_ns.checked_div(self.cycles).unwrap_or(0)
    }
    pub(super) fn pct_us(&self, q: f64) -> f64 {
        self.hist.value_at_quantile(q) as f64 / 1_000.0
    }
}

/// What a whole run found.
#[derive(Debug)]
pub struct Report {
    /// The command line, for the JSON.
    pub cmdline: String,
    /// Per thread.
    pub threads: Vec<ThreadResult>,
    /// Privilege warnings, each once.
    pub warnings: Vec<Warning>,
    /// Memory locked in force.
    pub mlocked: bool,
    /// Whether /dev/cpu_dma_latency is held at 0, or why not.
    pub dma_latency: Result<(), String>,
    /// Kernel facts.
    pub kernel: sched::KernelInfo,
    /// Whether the run was stopped by a signal.
    pub interrupted: bool,
}

/// What a thread reports once set up: its index, what is in force, and the privilege warnings.
type Setup = Result<(usize, InForce, Vec<Warning>), String>;

/// When each measuring thread wakes and when it stops.
#[derive(Debug, Clone, Copy)]
pub(super) struct Plan {
    /// Time between deadlines.
    pub(super) period: Duration,
    /// Stop after this many cycles (0: no limit).
    pub(super) loops: u64,
    /// Stop at this long after the start.
    pub(super) end_after: Option<Duration>,
}

/// The started measuring threads, each set up (or failing to) and then held at a barrier until
/// [`Threads::go`].
#[derive(Debug)]
pub(super) struct Threads {
    handles: Vec<JoinHandle<Option<ThreadResult>>>,
    live: Arc<Vec<Live>>,
    barrier: Arc<Barrier>,
    setup_rx: mpsc::Receiver<Setup>,
}

impl Threads {
    /// Starts one thread per request; each measures as `plan` says, or until `stop` is raised.
    pub(super) fn start(reqs: Vec<Request>, plan: Plan, stop: &StopFlag) -> anyhow::Result<Self> {
        let live: Arc<Vec<Live>> = Arc::new((0..reqs.len()).map(|_| Live::default()).collect());
        let barrier = Arc::new(Barrier::new(reqs.len() + 1));
        let (setup_tx, setup_rx) = mpsc::channel();
        let mut handles = Vec::new();
        for (index, req) in reqs.into_iter().enumerate() {
            let (live, barrier, setup_tx, stop) = (
                live.clone(),
                barrier.clone(),
                setup_tx.clone(),
                stop.clone(),
            );
            let handle = std::thread::Builder::new()
                .name(format!("latency-{index}"))
                .spawn(move || {
                    measuring_thread(index, &req, &live[index], &barrier, &setup_tx, plan, &stop)
                })
                .context("starting a measuring thread")?;
            handles.push(handle);
        }
        drop(setup_tx);
        Ok(Self {
            handles,
            live,
            barrier,
            setup_rx,
        })
    }

    /// Waits for every thread's setup and returns what is in force per thread, by index. New
    /// privilege warnings are added to `warnings`, each once. A thread's setup failure raises
    /// `stop` and is the error.
    pub(super) fn wait_for_setup(
        &self,
        stop: &StopFlag,
        warnings: &mut Vec<Warning>,
    ) -> anyhow::Result<Vec<(usize, InForce)>> {
        let mut in_force = Vec::new();
        // Exactly one setup message per thread: each keeps its sender while it measures, so
        // iterating until the channel closes would wait for the whole run.
        for _ in 0..self.handles.len() {
            let msg = self
                .setup_rx
                .recv()
                .context("a measuring thread died during setup")?;
            match msg {
                Ok((i, f, w)) => {
                    in_force.push((i, f));
                    for w in w {
                        if !warnings.iter().any(|x: &Warning| x.key == w.key) {
                            warnings.push(w);
                        }
                    }
                }
                Err(e) => {
                    stop.raise();
                    bail!("{e}");
                }
            }
        }
        in_force.sort_by_key(|(i, _)| *i);
        Ok(in_force)
    }

    /// Releases the threads into their loops.
    pub(super) fn go(&self) {
        self.barrier.wait();
    }

    /// The live figures, one per thread.
    pub(super) fn live(&self) -> &[Live] {
        &self.live
    }

    /// Whether any thread is still measuring.
    pub(super) fn running(&self) -> bool {
        self.handles.iter().any(|h| !h.is_finished())
    }

    /// Joins the threads; the results of those that finished, by index.
    pub(super) fn join(self) -> Vec<ThreadResult> {
        let mut threads: Vec<ThreadResult> = self
            .handles
            .into_iter()
            .filter_map(|h| h.join().ok().flatten())
            .collect();
        threads.sort_by_key(|t| t.index);
        threads
    }
}

/// One measuring thread's body: setup, report it, wait at the barrier, measure.
fn measuring_thread(
    index: usize,
    req: &Request,
    live: &Live,
    barrier: &Barrier,
    setup_tx: &mpsc::Sender<Setup>,
    plan: Plan,
    stop: &StopFlag,
) -> Option<ThreadResult> {
    let setup = sched::apply_to_current_thread(req);
    let (in_force, warns) = match setup {
        Ok(v) => v,
        Err(e) => {
            let _ = setup_tx.send(Err(e.to_string()));
            return None;
        }
    };
    let mut hist = Histogram::<u64>::new_with_bounds(1, HIST_MAX_NS, 3)
        .expect("1..10 s with 3 digits is a valid histogram");
    // Touch every counter page now so the loop never page-faults on first use.
    hist.reset();
    let mut hist_all = hist.clone();
    hist_all.reset();
    let tid = nix::unistd::gettid().as_raw();
    let _ = setup_tx.send(Ok((index, in_force.clone(), warns)));
    barrier.wait();
    let r = measure(
        live,
        &mut hist,
        &mut hist_all,
        plan.period,
        plan.loops,
        plan.end_after,
        stop,
    );
    Some(ThreadResult {
        index,
        tid,
        in_force,
        cycles: r.0,
        overruns: r.1,
        min_ns: r.2,
        last_ns: r.3,
        sum_ns: r.4,
        hist,
        hist_all,
    })
}

/// The measuring loop of one thread, into the histograms preallocated by its caller. Returns
/// (cycles, overruns, min, last, sum).
fn measure(
    live: &Live,
    hist: &mut Histogram<u64>,
    hist_all: &mut Histogram<u64>,
    period: Duration,
    loops: u64,
    end_after: Option<Duration>,
    stop: &StopFlag,
) -> (u64, u64, u64, u64, u64) {
    let start = monotonic_ns();
    let end_ns = end_after.map_or(u64::MAX, |d| start.saturating_add(d.as_nanos() as u64));
    let mut timer = PeriodicTimer::starting_at(start, period);
    let period_ns = timer.period_ns();
    let (mut cycles, mut overruns, mut min, mut sum, mut max) = (0u64, 0u64, u64::MAX, 0u64, 0);
    let mut last;
    loop {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls but clock_nanosleep.
        let w = timer.wait();
        let lat = w.latency_ns;
        hist.saturating_record(lat.max(1));
        hist_all.saturating_record(lat.max(1));
        // Deadlines that passed while we were late: their latency too (no coordinated omission).
        for k in 1..=w.missed.min(MISSED_RECORD_CAP) {
            hist_all.saturating_record(lat.saturating_sub(k * period_ns).max(1));
        }
        cycles += 1;
        overruns += w.missed;
        min = min.min(lat);
        max = max.max(lat);
        last = lat;
        sum = sum.wrapping_add(lat);
        live.cycles.store(cycles, Ordering::Relaxed);
        live.last_ns.store(lat, Ordering::Relaxed);
        live.min_ns.store(min, Ordering::Relaxed);
        live.max_ns.store(max, Ordering::Relaxed);
        live.sum_ns.store(sum, Ordering::Relaxed);
        live.overruns.store(overruns, Ordering::Relaxed);
        if (loops > 0 && cycles >= loops) || w.woke_ns >= end_ns || stop.is_raised() {
            break;
        }
    }
    (
        cycles,
        overruns,
        if cycles == 0 { 0 } else { min },
        last,
        sum,
    )
}
