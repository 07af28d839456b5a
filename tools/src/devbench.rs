//! `devbench`: the servo loop's wake-up latency and overruns with the Haply backend (its bridge
//! thread talking to a stand-in Inverse Service on loopback) and the ROS 2 backend (its bridge
//! talking zenoh to a stand-in ROS 2 driver, `devbench/ros2_driver.rs`) against the simulated SCARA arm, in
//! the same run, and each bridge's device round trip.
//!
//! Each phase runs the servo's device path at the servo period on a periodic timer: sample through
//! the safety layer, a spring force toward the start point, display through the safety layer. The
//! phases alternate (sim, haply, sim, haply, ...) so machine noise hits both. Reported: wake-up
//! latency p50/p99/p99.9/max and overruns per backend, the ratio haply/sim of p99.9 (goal ≤ 1.2),
//! and the round trip: from the tick that commanded a force to the first tick whose sample carries
//! the service's `current_cursor_force` equal to it, p50/p99 (servo-observed, so in whole periods
//! of the bridge and the servo).
//!
//! The stand-in service is `rt/tests/fixtures/haply_service.py` (python3 with `websockets`). The
//! ROS 2 round trip is the driver's: from the put of a pose that steps the end effector to the
//! first wrench reflecting the step (pose in, force out).

mod ros2_driver;

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command as Proc, Stdio};
use std::time::Duration;

use anyhow::{bail, Context};
use clap::Parser;
use coop_model::body::Vec3;
use coop_model::device::Plant;
use coop_model::scenario::{KeyframeSpec, Scenario, SiteSpec};
use coop_rt::device::haply::{HaplyConfig, HaplyDevice};
use coop_rt::device::safety::{Guarded, SafetyLimits};
use coop_rt::device::{CartesianDevice, SimScara};
use coop_rt::sched::{self, Policy, Request};
use coop_rt::timer::{monotonic_ns, PeriodicTimer};
use hdrhistogram::Histogram;

/// Command line of `devbench`.
#[derive(Debug, Clone, Parser)]
#[command(
    name = "devbench",
    version,
    about = "Servo wake-up latency with the Haply and ROS 2 backends (against stand-ins) vs the simulated arm, and each bridge's round trip."
)]
pub struct Args {
    /// Seconds per phase.
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    pub seconds: f64,
    /// Rounds of (sim, haply).
    #[arg(long, value_name = "N", default_value_t = 3,
          value_parser = clap::value_parser!(u64).range(1..=100))]
    pub rounds: u64,
    /// The servo period.
    #[arg(long, value_name = "US", default_value_t = 1000)]
    pub period_us: u64,
    /// The Haply bridge's exchange rate.
    #[arg(long, value_name = "HZ", default_value_t = 1000.0)]
    pub bridge_rate_hz: f64,
    /// The stand-in service script.
    #[arg(long, value_name = "FILE", default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../rt/tests/fixtures/haply_service.py"))]
    pub mock: PathBuf,
    /// SCHED_FIFO priority of the servo thread, as a station's servo runs (0: SCHED_OTHER). Falls back
    /// to SCHED_OTHER, saying so, without the privilege.
    #[arg(long, value_name = "PRIO", default_value_t = 80,
          value_parser = clap::value_parser!(i32).range(0..=99))]
    pub fifo_priority: i32,
    /// A short run (1 s per phase, 1 round) to check the benchmark works.
    #[arg(long)]
    pub quick: bool,
    /// Print the figures as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Figures of one backend over all its phases.
#[derive(Debug)]
struct Figures {
    wake: Histogram<u64>,
    overruns: u64,
    ticks: u64,
}

impl Figures {
    fn new() -> anyhow::Result<Self> {
        Ok(Self {
            wake: Histogram::new_with_bounds(1, 10_000_000_000, 3)?,
            overruns: 0,
            ticks: 0,
        })
    }
}

/// The stand-in service, killed on drop.
struct Mock(Child);

impl Drop for Mock {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn start_mock(script: &PathBuf) -> anyhow::Result<(Mock, u16)> {
    let mut child = Proc::new("python3")
        .arg(script)
        .args(["--quiet", "--position", "0.0,-0.12,0.15"])
        .stdout(Stdio::piped())
        .spawn()
        .with_context(|| format!("starting python3 {}", script.display()))?;
    let mut line = String::new();
    BufReader::new(child.stdout.take().context("mock stdout")?)
        .read_line(&mut line)
        .context("reading the mock's port")?;
    let mock = Mock(child);
    let Some(port) = line.trim().strip_prefix("PORT ") else {
        bail!("the stand-in service did not start (needs python3 with websockets): {line:?}");
    };
    Ok((mock, port.parse().context("the mock's port")?))
}

fn sim_device(now_ns: u64) -> anyhow::Result<SimScara> {
    let mut sc = Scenario::default();
    sc.site.push(SiteSpec {
        name: "a".into(),
        device_base_m: [-0.3, -0.2, 0.0],
        script: vec![KeyframeSpec {
            t_s: 0.0,
            target_m: [-0.12, 0.0, 0.01],
        }],
        ..SiteSpec::default()
    });
    sc.validate().context("the benchmark's scenario")?;
    let script = sc.script(0);
    Ok(SimScara::new(
        Plant::at(sc.arm(0), sc.hand(0), script[0].target, 1.0),
        sc.force_loop(0),
        script,
        now_ns,
    ))
}

/// The spring the phases display toward where the hand started, N/m.
const SPRING_N_PER_M: f64 = 50.0;

/// Where a phase measuring the round trip records it, and how it reads the force the device shows
/// back.
type RoundTrip<'a, D> = (&'a mut Histogram<u64>, fn(&D) -> Option<Vec3>);

/// Runs the device path for `ticks` periods; with `rtt`, measures the Haply round trip.
fn phase<D: CartesianDevice>(
    dev: &mut Guarded<D>,
    period: Duration,
    ticks: u64,
    fig: &mut Figures,
    mut rtt: Option<RoundTrip<'_, D>>,
) {
    let mut timer = PeriodicTimer::new(period);
    let anchor = dev
        .sample(monotonic_ns())
        .map_or(Vec3::zeros(), |s| s.position_m);
    // Commands still waiting to be seen back: (force, tick time).
    let mut pending = [(Vec3::zeros(), 0u64); 64];
    let mut head = 0usize;
    let mut oldest_live = 0usize;
    for k in 0..ticks {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls but clock_nanosleep.
        let w = timer.wait();
        fig.wake.saturating_record(w.latency_ns);
        fig.ticks += 1;
        let now = w.woke_ns;
        let pos = dev.sample(now).map_or(anchor, |s| s.position_m);
        if let Some((h, displayed)) = rtt.as_mut() {
            if let Some(f) = displayed(dev.device()) {
                // The newest pending command the service shows back closes its round trip.
                let mut i = head;
                while i != oldest_live {
                    i = (i + pending.len() - 1) % pending.len();
                    let (c, t) = pending[i];
                    if (c - f).norm() < 1e-9 && c.norm() > 0.0 {
                        h.saturating_record(now - t);
                        oldest_live = head;
                        break;
                    }
                }
            }
        }
        // A spring toward where the hand started, plus (measuring the Haply round trip) a
        // distinct bias per tick so each command can be recognised when the service reports it
        // back; the ROS 2 driver recognises its pose's steps in the spring's force instead.
        let vary = if rtt.is_some() {
            1e-4 * (k % 1000) as f64
        } else {
            0.0
        };
        let bias = Vec3::new(0.4 + vary, 0.0, 0.0);
        let shown = dev.display(now, bias - SPRING_N_PER_M * (pos - anchor), 1.0);
        pending[head] = (shown, now);
        head = (head + 1) % pending.len();
        if head == oldest_live {
            oldest_live = (oldest_live + 1) % pending.len();
        }
    }
    fig.overruns += timer.overruns();
}

/// Runs the benchmark and prints its figures.
///
/// # Errors
/// The stand-in service does not start, or the Haply backend cannot open.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let (seconds, rounds) = if args.quick {
        (1.0, 1)
    } else {
        (args.seconds, args.rounds)
    };
    if !(seconds > 0.0 && seconds <= 3600.0) {
        bail!("--seconds {seconds}: must be in (0, 3600]");
    }
    if args.period_us == 0 {
        bail!("--period-us 0: must be > 0");
    }
    let period = Duration::from_micros(args.period_us);
    let ticks = (seconds * 1e6 / args.period_us as f64) as u64;
    let (_mock, port) = start_mock(&args.mock)?;
    let driver = ros2_driver::Driver::start()?;
    // The servo's scheduling, after the stand-in started (it must not inherit it). The Haply bridge
    // thread, started from this thread, drops back to SCHED_OTHER itself.
    let policy = if args.fifo_priority > 0 {
        let req = Request {
            policy: Policy::Fifo,
            priority: args.fifo_priority,
            cpus: None,
            prefault_stack_bytes: 256 * 1024,
        };
        match sched::apply_to_current_thread(&req) {
            Ok((in_force, warnings)) => {
                for w in warnings {
                    eprintln!("devbench: {w}");
                }
                format!("{in_force:?}")
            }
            Err(e) => bail!("--fifo-priority {}: {e}", args.fifo_priority),
        }
    } else {
        "SCHED_OTHER".to_owned()
    };
    let cfg = HaplyConfig {
        url: format!("ws://127.0.0.1:{port}"),
        rate_hz: args.bridge_rate_hz,
        ..HaplyConfig::default()
    };
    cfg.validate()
        .map_err(|e| anyhow::anyhow!("--bridge-rate-hz: {e}"))?;
    let mut sim_fig = Figures::new()?;
    let mut haply_fig = Figures::new()?;
    let mut rtt = Histogram::<u64>::new_with_bounds(1, 10_000_000_000, 3)?;
    let mut ros2_fig = Figures::new()?;
    let mut ros2_rtt = Histogram::<u64>::new_with_bounds(1, 10_000_000_000, 3)?;
    let ros2_cfg = coop_transport::ros2_device::Ros2DeviceConfig {
        pose_topic: ros2_driver::POSE_TOPIC.into(),
        wrench_topic: ros2_driver::WRENCH_TOPIC.into(),
        connect: vec![driver.locator.clone()],
        rate_hz: ros2_driver::RATE_HZ,
        ..Default::default()
    };
    for _ in 0..rounds {
        let now = monotonic_ns();
        let mut sim = Guarded::new(sim_device(now)?, SafetyLimits::default(), now);
        phase(&mut sim, period, ticks, &mut sim_fig, None);
        sim.close(monotonic_ns());

        let dev = HaplyDevice::open(&cfg).context("opening the Haply backend on the stand-in")?;
        let mut haply = Guarded::new(dev, SafetyLimits::default(), monotonic_ns());
        phase(
            &mut haply,
            period,
            ticks,
            &mut haply_fig,
            Some((&mut rtt, HaplyDevice::displayed_force_n)),
        );
        haply.close(monotonic_ns());

        let dev = coop_transport::ros2_device::Ros2Device::open(&ros2_cfg)
            .context("opening the ROS 2 backend on the stand-in driver")?;
        let mut ros2 = Guarded::new(dev, SafetyLimits::default(), monotonic_ns());
        driver.recording.store(1, coop_rt::sync::Ordering::Relaxed);
        phase(&mut ros2, period, ticks, &mut ros2_fig, None);
        driver.recording.store(0, coop_rt::sync::Ordering::Relaxed);
        ros2.close(monotonic_ns());
    }
    driver.round_trips(SPRING_N_PER_M, &mut ros2_rtt);
    let q = |h: &Histogram<u64>, p: f64| h.value_at_quantile(p) as f64 / 1e3;
    let ratio = q(&haply_fig.wake, 0.999) / q(&sim_fig.wake, 0.999).max(1e-3);
    let ros2_ratio = q(&ros2_fig.wake, 0.999) / q(&sim_fig.wake, 0.999).max(1e-3);
    if args.json {
        let side = |f: &Figures| {
            serde_json::json!({
                "ticks": f.ticks, "overruns": f.overruns,
                "wake_p50_us": q(&f.wake, 0.5), "wake_p99_us": q(&f.wake, 0.99),
                "wake_p999_us": q(&f.wake, 0.999), "wake_max_us": f.wake.max() as f64 / 1e3,
            })
        };
        println!(
            "{}",
            serde_json::json!({
                "period_us": args.period_us, "seconds_per_phase": seconds, "rounds": rounds,
                "servo_thread": policy,
                "sim": side(&sim_fig), "haply": side(&haply_fig), "ros2": side(&ros2_fig),
                "p999_ratio_haply_over_sim": ratio,
                "p999_ratio_ros2_over_sim": ros2_ratio,
                "roundtrip": { "count": rtt.len(), "p50_us": q(&rtt, 0.5), "p99_us": q(&rtt, 0.99) },
                "ros2_roundtrip": { "count": ros2_rtt.len(), "p50_us": q(&ros2_rtt, 0.5), "p99_us": q(&ros2_rtt, 0.99) },
            })
        );
    } else {
        println!(
            "devbench: servo period {} µs, {rounds} round(s) of {seconds} s per backend, Haply bridge at {} Hz",
            args.period_us, args.bridge_rate_hz
        );
        println!("servo thread: {policy}");
        println!("backend  ticks    overruns  wake p50 µs  p99 µs   p99.9 µs  max µs");
        for (name, f) in [
            ("sim", &sim_fig),
            ("haply", &haply_fig),
            ("ros2", &ros2_fig),
        ] {
            println!(
                "{name:<8} {:<8} {:<9} {:<12.1} {:<8.1} {:<9.1} {:.1}",
                f.ticks,
                f.overruns,
                q(&f.wake, 0.5),
                q(&f.wake, 0.99),
                q(&f.wake, 0.999),
                f.wake.max() as f64 / 1e3
            );
        }
        println!("wake-up p99.9 haply/sim: {ratio:.2} (goal <= 1.2), ros2/sim: {ros2_ratio:.2}");
        println!(
            "Haply round trip (command to the first sample reflecting it, servo-observed): n = {}, p50 {:.0} µs, p99 {:.0} µs",
            rtt.len(),
            q(&rtt, 0.5),
            q(&rtt, 0.99)
        );
        println!(
            "ROS 2 round trip (a pose step put by the driver to the first wrench reflecting it, driver-observed): n = {}, p50 {:.0} µs, p99 {:.0} µs",
            ros2_rtt.len(),
            q(&ros2_rtt, 0.5),
            q(&ros2_rtt, 0.99)
        );
    }
    if ros2_rtt.is_empty() {
        bail!("no ROS 2 round trip was observed: the stand-in driver never got a force reflecting its pose");
    }
    if rtt.is_empty() {
        bail!("no Haply round trip was observed: the stand-in never showed a commanded force back");
    }
    Ok(())
}
