//! `ringbench`: the shared-memory ring between two processes against rtrb between two threads.
//!
//! Both transports run the same two measurements, alternating in rounds so machine noise hits both:
//! - **round trip**: a 64-byte message ping-pongs between two cores over two rings, busy-polling;
//!   each round trip's time goes into an hdrhistogram;
//! - **throughput**: one side pushes M messages as fast as the ring takes them, the other pops and
//!   counts, then acknowledges; messages per second in one direction.
//!
//! The baseline (rtrb, two threads, heap memory) is in the same run, and the report gives ratios.
//! Busy-polling is bounded by the message counts; run it on an otherwise idle machine.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use clap::{Parser, Subcommand};
use coop_rt::sched::{self, Policy, Request};
use coop_rt::shm::{Consumer, Producer, RingOpenOptions, RingSegment, SegmentName, SeqMsg};
use hdrhistogram::Histogram;

use crate::cli::parse_cpu_list;

/// Command line of `ringbench`.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "ringbench",
    version,
    about = "Benchmark the shared-memory SPSC ring across processes against rtrb across threads.",
    long_about = "Benchmark the shared-memory SPSC ring across two processes against rtrb between two \
        threads, in the same run, on the same two cores. Prints round-trip p50/p99/p99.9/max in ns \
        and one-way throughput in messages/s for both, and the ratios shm/rtrb. Both sides \
        busy-poll (SCHED_OTHER): run it on an otherwise idle machine."
)]
pub struct Args {
    /// Round trips per transport (split over the rounds).
    #[arg(long, value_name = "N", default_value_t = 1_000_000)]
    pub round_trips: u64,
    /// Messages per transport for the throughput measurement (split over the rounds).
    #[arg(long, value_name = "N", default_value_t = 20_000_000)]
    pub messages: u64,
    /// Alternating rounds (shm, rtrb, shm, rtrb, ...).
    #[arg(long, value_name = "N", default_value_t = 4,
          value_parser = clap::value_parser!(u64).range(1..=100))]
    pub rounds: u64,
    /// Ring capacity in slots (a power of two).
    #[arg(long, value_name = "SLOTS", default_value_t = 1024)]
    pub capacity: usize,
    /// The two CPUs to pin the sides to, e.g. 0,1.
    #[arg(long, value_name = "A,B", default_value = "0,1")]
    pub cpus: String,
    /// A short run (20k round trips, 1M messages, 1 round) to check the benchmark works.
    #[arg(long)]
    pub quick: bool,
    /// Print the figures as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    #[command(subcommand)]
    #[allow(missing_docs)]
    pub internal: Option<Internal>,
}

/// The hidden side of the benchmark that `ringbench` spawns as its second process.
#[derive(Debug, Clone, Subcommand)]
pub enum Internal {
    /// Serve pings from ring PING on ring PONG, pinned to CPU.
    #[command(hide = true)]
    Pong {
        /// Ring to read.
        ping: String,
        /// Ring to answer on.
        pong: String,
        /// CPU to pin to.
        cpu: usize,
    },
}

/// Message kinds, in `payload[0]`.
const ECHO: u64 = 1;
const COUNT: u64 = 2;
const FLUSH: u64 = 3;
const QUIT: u64 = 4;

fn msg(kind: u64, seq: u64) -> SeqMsg {
    let mut m = SeqMsg::new(seq);
    m.payload[0] = kind;
    m
}

/// A pair of rings seen from one side: send on one, receive on the other, busy-polling.
trait Link {
    fn send(&mut self, m: SeqMsg);
    fn recv(&mut self) -> SeqMsg;
}

struct ShmLink(Producer<SeqMsg>, Consumer<SeqMsg>);
impl Link for ShmLink {
    #[inline]
    fn send(&mut self, mut m: SeqMsg) {
        while let Err(e) = self.0.push(m) {
            m = match e {
                coop_rt::shm::PushError::Full(m) => m,
                coop_rt::shm::PushError::Corrupt(_, c) => panic!("{c}"),
            };
            std::hint::spin_loop();
        }
    }
    #[inline]
    fn recv(&mut self) -> SeqMsg {
        let mut spins = 0u64;
        loop {
            match self.1.pop() {
                Ok(m) => return m,
                Err(coop_rt::shm::PopError::Empty) => {
                    spins += 1;
                    // A dead peer would leave us spinning forever; checking reads /proc, so rarely.
                    if spins.is_multiple_of(1 << 24) && self.1.is_abandoned() {
                        panic!("the other ringbench process died");
                    }
                    std::hint::spin_loop();
                }
                Err(coop_rt::shm::PopError::Corrupt(c)) => panic!("{c}"),
            }
        }
    }
}

struct RtrbLink(rtrb::Producer<SeqMsg>, rtrb::Consumer<SeqMsg>);
impl Link for RtrbLink {
    #[inline]
    fn send(&mut self, mut m: SeqMsg) {
        while let Err(rtrb::PushError::Full(back)) = self.0.push(m) {
            m = back;
            std::hint::spin_loop();
        }
    }
    #[inline]
    fn recv(&mut self) -> SeqMsg {
        loop {
            if let Ok(m) = self.1.pop() {
                return m;
            }
            std::hint::spin_loop();
        }
    }
}

/// The answering side: echoes ECHO, counts COUNT, acknowledges FLUSH with the count, stops on QUIT.
fn serve(link: &mut impl Link) {
    let mut counted = 0u64;
    loop {
        let m = link.recv();
        match m.payload[0] {
            ECHO => link.send(m),
            COUNT => counted += 1,
            FLUSH => {
                link.send(msg(FLUSH, counted));
                counted = 0;
            }
            _ => return,
        }
    }
}

fn round_trips(link: &mut impl Link, n: u64, hist: &mut Histogram<u64>) {
    let warmup = (n / 100).max(100);
    for i in 0..warmup + n {
        let t0 = Instant::now();
        link.send(msg(ECHO, i));
        let back = link.recv();
        let dt = t0.elapsed().as_nanos() as u64;
        assert_eq!(back.seq, i, "echo out of order");
        if i >= warmup {
            hist.saturating_record(dt.max(1));
        }
    }
}

fn throughput(link: &mut impl Link, n: u64) -> Duration {
    let t0 = Instant::now();
    for i in 0..n {
        link.send(msg(COUNT, i));
    }
    link.send(msg(FLUSH, 0));
    let ack = link.recv();
    let dt = t0.elapsed();
    assert_eq!(ack.seq, n, "receiver counted {} of {n}", ack.seq);
    dt
}

fn pin(cpu: usize) -> anyhow::Result<()> {
    let (_, warnings) = sched::apply_to_current_thread(&Request {
        policy: Policy::Other,
        priority: 0,
        cpus: Some(vec![cpu]),
        prefault_stack_bytes: 0,
    })?;
    if let Some(w) = warnings.first() {
        bail!("{w}");
    }
    Ok(())
}

/// Figures of one transport.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Figures {
    /// Round-trip percentiles and max, ns.
    pub p50_ns: u64,
    /// p99, ns.
    pub p99_ns: u64,
    /// p99.9, ns.
    pub p999_ns: u64,
    /// Max, ns.
    pub max_ns: u64,
    /// Round trips measured.
    pub round_trips: u64,
    /// One-way messages per second.
    pub throughput_msgs_per_s: f64,
}

fn figures(hist: &Histogram<u64>, msgs: u64, time: Duration) -> Figures {
    Figures {
        p50_ns: hist.value_at_quantile(0.5),
        p99_ns: hist.value_at_quantile(0.99),
        p999_ns: hist.value_at_quantile(0.999),
        max_ns: hist.max(),
        round_trips: hist.len(),
        throughput_msgs_per_s: msgs as f64 / time.as_secs_f64(),
    }
}

/// Runs the benchmark (or, with the hidden `pong` subcommand, its second process).
///
/// # Errors
/// Bad CPUs, failures to create rings or start the second process.
pub fn run(args: &Args) -> anyhow::Result<()> {
    if let Some(Internal::Pong { ping, pong, cpu }) = &args.internal {
        nix::sys::prctl::set_pdeathsig(nix::sys::signal::Signal::SIGKILL)?;
        pin(*cpu)?;
        let opts = RingOpenOptions::default();
        let mut link = ShmLink(
            Producer::open(&pong.parse()?, &opts).context("opening the pong ring")?,
            Consumer::open(&ping.parse()?, &opts).context("opening the ping ring")?,
        );
        serve(&mut link);
        return Ok(());
    }
    let cpus = parse_cpu_list(&args.cpus).map_err(anyhow::Error::msg)?;
    let [a, b] = cpus[..] else {
        bail!("--cpus needs exactly two CPUs, got {:?}", args.cpus);
    };
    let (rts, msgs, rounds) = if args.quick {
        (20_000, 1_000_000, 1)
    } else {
        (args.round_trips, args.messages, args.rounds)
    };
    let session = format!("rb{}", std::process::id());
    let ping_name = SegmentName::new(&session, "bench", "ping")?;
    let pong_name = SegmentName::new(&session, "bench", "pong")?;
    let ping = RingSegment::<SeqMsg>::create(&ping_name, args.capacity)?;
    let pong = RingSegment::<SeqMsg>::create(&pong_name, args.capacity)?;
    unlink_on_signal(vec![ping_name.clone(), pong_name.clone()])?;
    pin(a)?;
    let mut child = Command::new(std::env::current_exe()?)
        .args([
            "pong",
            ping_name.as_str(),
            pong_name.as_str(),
            &b.to_string(),
        ])
        .stdin(Stdio::null())
        .spawn()
        .context("starting the pong process")?;
    let mut shm = ShmLink(ping.producer()?, pong.consumer()?);
    let (rp, rc) = rtrb::RingBuffer::<SeqMsg>::new(args.capacity);
    let (tp, tc) = rtrb::RingBuffer::<SeqMsg>::new(args.capacity);
    let server = std::thread::spawn(move || -> anyhow::Result<()> {
        pin(b)?;
        serve(&mut RtrbLink(tp, rc));
        Ok(())
    });
    let mut rtrb_link = RtrbLink(rp, tc);

    let new_hist = || Histogram::<u64>::new_with_bounds(1, 1_000_000_000, 3).expect("valid bounds");
    let (mut h_shm, mut h_rtrb) = (new_hist(), new_hist());
    let (mut t_shm, mut t_rtrb) = (Duration::ZERO, Duration::ZERO);
    for _ in 0..rounds {
        round_trips(&mut shm, rts / rounds, &mut h_shm);
        round_trips(&mut rtrb_link, rts / rounds, &mut h_rtrb);
        t_shm += throughput(&mut shm, msgs / rounds);
        t_rtrb += throughput(&mut rtrb_link, msgs / rounds);
    }
    shm.send(msg(QUIT, 0));
    rtrb_link.send(msg(QUIT, 0));
    let status = child.wait()?;
    if !status.success() {
        bail!("the pong process failed: {status}");
    }
    server
        .join()
        .map_err(|_| anyhow::anyhow!("rtrb server thread panicked"))??;
    let total = (msgs / rounds) * rounds;
    let s = figures(&h_shm, total, t_shm);
    let r = figures(&h_rtrb, total, t_rtrb);
    report(args, a, b, rounds, &s, &r);
    Ok(())
}

/// Busy-polling loops never look at a stop flag, so on SIGINT/SIGTERM a watcher thread unlinks the
/// rings itself and exits: a benchmark stopped by Ctrl-C or `timeout` leaves nothing in /dev/shm.
/// (The pong process dies with us through its parent-death signal.)
fn unlink_on_signal(names: Vec<SegmentName>) -> anyhow::Result<()> {
    use nix::sys::signal::{SigSet, SigmaskHow, Signal};
    let mut set = SigSet::empty();
    set.add(Signal::SIGINT);
    set.add(Signal::SIGTERM);
    nix::sys::signal::pthread_sigmask(SigmaskHow::SIG_BLOCK, Some(&set), None)?;
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            if let Ok(sig) = set.wait() {
                for n in &names {
                    let _ = nix::sys::mman::shm_unlink(n.as_str());
                }
                eprintln!("ringbench: stopped by {sig}; rings removed");
                std::process::exit(128 + sig as i32);
            }
        })?;
    Ok(())
}

fn report(args: &Args, a: usize, b: usize, rounds: u64, s: &Figures, r: &Figures) {
    let ratio = |x: u64, y: u64| x as f64 / y.max(1) as f64;
    let ratios = serde_json::json!({
        "p50": ratio(s.p50_ns, r.p50_ns),
        "p99": ratio(s.p99_ns, r.p99_ns),
        "p999": ratio(s.p999_ns, r.p999_ns),
        "max": ratio(s.max_ns, r.max_ns),
        "throughput": s.throughput_msgs_per_s / r.throughput_msgs_per_s,
    });
    let goal_met = ratios["p50"].as_f64().unwrap_or(f64::MAX) <= 1.3
        && ratios["p99"].as_f64().unwrap_or(f64::MAX) <= 1.3
        && ratios["throughput"].as_f64().unwrap_or(0.0) >= 0.8;
    if args.json {
        let v = serde_json::json!({
            "message_bytes": std::mem::size_of::<SeqMsg>(),
            "capacity": args.capacity,
            "cpus": [a, b],
            "rounds": rounds,
            "shm_processes": s,
            "rtrb_threads": r,
            "ratio_shm_over_rtrb": ratios,
            "goal": "p50, p99 <= 1.3x rtrb; throughput >= 0.8x rtrb",
            "goal_met": goal_met,
        });
        println!("{}", serde_json::to_string_pretty(&v).unwrap_or_default());
        return;
    }
    println!(
        "# ringbench: {}-byte messages, {}-slot rings, busy-poll ping-pong between CPUs {a} and {b}, {rounds} alternating round(s)",
        std::mem::size_of::<SeqMsg>(),
        args.capacity
    );
    println!(
        "{:<22}{:>10}{:>10}{:>11}{:>12}{:>12}{:>18}",
        "transport", "p50 ns", "p99 ns", "p99.9 ns", "max ns", "round trips", "throughput msg/s"
    );
    for (name, f) in [("shm, 2 processes", s), ("rtrb, 2 threads", r)] {
        println!(
            "{name:<22}{:>10}{:>10}{:>11}{:>12}{:>12}{:>18.0}",
            f.p50_ns, f.p99_ns, f.p999_ns, f.max_ns, f.round_trips, f.throughput_msgs_per_s
        );
    }
    let f = |k: &str| ratios[k].as_f64().unwrap_or(f64::NAN);
    println!(
        "{:<22}{:>10.2}{:>10.2}{:>11.2}{:>12.2}{:>12}{:>18.2}",
        "ratio shm / rtrb",
        f("p50"),
        f("p99"),
        f("p999"),
        f("max"),
        "",
        f("throughput")
    );
    println!(
        "# goal: p50 and p99 <= 1.3x rtrb, throughput >= 0.8x rtrb: {}",
        if goal_met { "met" } else { "NOT met" }
    );
}
