//! `session bench`: how long a state takes from one station's physics to another's, next to a bare
//! zenoh ping-pong of the same payload between two processes, in the same run.
//!
//! - **Stations**: a two-station session of `scenarios/zero-delay.toml` (14 s, 1 kHz reports, no
//!   emulation). Each state handed to physics is recorded with the sender's time; the latency is
//!   receive time minus send time on the one CLOCK_MONOTONIC of this machine (the clock-offset
//!   correction is taken back out). The path: physics A → ring → network A (polls every
//!   [`coop_transport::network::POLL`]) → zenoh → network B → ring into physics B.
//! - **Bare zenoh**: this process publishes the same payload, one encoded state
//!   (`bare_payload`: a moving object's, as big as a station's), express, at real-time priority, dropped on congestion; a child
//!   process (`session bench-pong`) echoes it; one way = round trip / 2. Paced at 1 kHz like the
//!   states.
//!
//! - **The pipeline, hop by hop**: each station's own measures in the same session
//!   (`coop_actors::station::status::HOPS`): its tool sample's age when physics takes it, its
//!   reports' wait from physics to the zenoh put, a partner's report's age on reaching its physics
//!   ring, its physics and its displayed force, and the age of each state the servo shows. A tool
//!   sample at A reaches B's displayed force in A's first hop plus B's last; the goal is that
//!   sum's p99 within [`PIPELINE_GOAL_P99_US`].
//!
//! `session bench-router` ([`router`]) sets the same station path through one zenoh router next to
//! peer to peer and to the bare ping-pong through that router.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use coop_actors::station::status::{Hop, HOPS};
use coop_model::scenario::MethodName;
use coop_transport::network::{self, NetworkConfig};
use coop_transport::recording;
use hdrhistogram::Histogram;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::Wait;

pub mod router;

/// Figures of one path, µs.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Figures {
    /// Median.
    pub p50_us: f64,
    /// 99th percentile.
    pub p99_us: f64,
    /// Largest.
    pub max_us: f64,
    /// Samples.
    pub samples: u64,
}

pub(crate) fn figures(h: &Histogram<u64>) -> Figures {
    let us = |ns: u64| ns as f64 / 1e3;
    Figures {
        p50_us: us(h.value_at_quantile(0.5)),
        p99_us: us(h.value_at_quantile(0.99)),
        max_us: us(h.max()),
        samples: h.len(),
    }
}

pub(crate) fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 60_000_000_000, 3).expect("valid bounds")
}

/// Runs `scenarios/<name>.toml` (paper method) as a session in a temporary directory: the scenario,
/// the outcome, and the directory with the recordings (the caller removes it).
fn bench_session(
    root: &Path,
    name: &str,
    emulate: bool,
    station_bin: &crate::session::StationBin,
) -> anyhow::Result<(
    coop_model::scenario::Scenario,
    crate::session::MethodOutcome,
    PathBuf,
)> {
    bench_scenario(
        &root.join(format!("scenarios/{name}.toml")),
        name,
        emulate,
        station_bin,
    )
}

/// Runs `scenario` (paper method) as a session on this machine (`name` tags its directory and
/// session): as [`bench_session`].
pub(crate) fn bench_scenario(
    scenario: &Path,
    name: &str,
    emulate: bool,
    station_bin: &crate::session::StationBin,
) -> anyhow::Result<(
    coop_model::scenario::Scenario,
    crate::session::MethodOutcome,
    PathBuf,
)> {
    let scenario = scenario.to_owned();
    let sc = coop_actors::scenario_file::load(&scenario)?;
    let dir = std::env::temp_dir().join(format!("coop-bench-{name}-{}", std::process::id()));
    let a = crate::session::RunArgs {
        trials: false,
        live: None,
        scenario,
        out: dir.clone(),
        methods: vec![MethodName::Paper],
        session: None,
        late: vec![],
        emulate,
        start_timeout: Duration::from_secs(30),
        station_bin: station_bin.clone(),
        progress: false,
        stop: crate::cli::StopFlag::manual(),
        record_max_file_s: None,
        attach: None,
        ros2: None,
    };
    let session = format!("b{}{}", std::process::id(), &name[..1]);
    let o = crate::session::run_method(&a, &sc, MethodName::Paper, &session)?;
    Ok((sc, o, dir))
}

/// Each station's pipeline hops at the session's end ([`coop_actors::station::status::Hop`]).
type Pipelines = std::collections::BTreeMap<String, Vec<Hop>>;

/// The station path: a two-station session, latencies from the receivers' recordings, and each
/// station's pipeline hops as its loops measured them.
fn stations(
    root: &Path,
    station_bin: &crate::session::StationBin,
) -> anyhow::Result<(Histogram<u64>, Pipelines)> {
    let (sc, o, dir) = bench_session(root, "zero-delay", false, station_bin)?;
    let paths: Vec<PathBuf> = sc
        .site
        .iter()
        .map(|s| dir.join("paper").join(format!("{}.mcap", s.name)))
        .collect();
    let h = latencies(&paths);
    let _ = std::fs::remove_dir_all(&dir);
    let pipelines = o
        .stations
        .iter()
        .map(|(site, st)| {
            let hops = st.live.as_ref().map(|l| l.status.pipeline.clone());
            (site.clone(), hops.unwrap_or_default())
        })
        .collect();
    Ok((h?, pipelines))
}

/// The pipeline's own latency a tool sample adds on its way to the partner's displayed force,
/// p99, µs: at most the sum of its two measured parts' (own servo -> physics at the sender, and
/// partner physics -> displayed force at the receiver); the goal.
pub const PIPELINE_GOAL_P99_US: u64 = 3_000;

/// Each station's hops, then per direction the sample-to-force figures and the goal.
fn print_pipelines(pipelines: &Pipelines) {
    println!("\n# the pipeline's own latency on loopback, no emulation, hop by hop as each station's loops measured it (one clock; a partner's times corrected by its measured offset)");
    println!(
        "{:<10}{:<42}{:>10}{:>10}{:>10}{:>10}",
        "station", "hop", "p50 us", "p99 us", "max us", "samples"
    );
    for (site, hops) in pipelines {
        for h in hops {
            println!(
                "{:<10}{:<42}{:>10}{:>10}{:>10}{:>10}",
                site, h.hop, h.p50_us, h.p99_us, h.max_us, h.count
            );
        }
    }
    let hop = |site: &str, name: &str| {
        pipelines
            .get(site)
            .and_then(|h| h.iter().find(|h| h.hop == name))
    };
    let mut met = true;
    for (from, to) in pipelines.keys().flat_map(|a| {
        pipelines
            .keys()
            .filter(move |b| *b != a)
            .map(move |b| (a.as_str(), b.as_str()))
    }) {
        let (Some(first), Some(rest)) = (hop(from, HOPS[0]), hop(to, HOPS[5])) else {
            println!("# {from} -> {to}: not measured");
            met = false;
            continue;
        };
        let p99 = first.p99_us + rest.p99_us;
        met &= p99 <= PIPELINE_GOAL_P99_US;
        println!(
            "# {from}'s tool sample -> {to}'s displayed force: p50 about {} us, p99 at most {} us (the sum of the parts' p99), max at most {} us",
            first.p50_us + rest.p50_us,
            p99,
            first.max_us + rest.max_us
        );
    }
    println!(
        "# goal: p99 added by the pipeline <= {} us in each direction: {}",
        PIPELINE_GOAL_P99_US,
        if met { "met" } else { "NOT met" }
    );
}

/// Each state handed to physics in the recordings at `paths`: receive time minus send time, on
/// this machine's one clock.
///
/// # Errors
/// A recording cannot be read.
pub(crate) fn latencies(paths: &[PathBuf]) -> anyhow::Result<Histogram<u64>> {
    let mut h = histogram();
    for p in paths {
        let rec = recording::read(p)?;
        // Same machine, one clock: take the clock-offset correction back out.
        for m in rec.remote.iter().filter(|m| m.via == "live") {
            let sent = i128::from(m.sent_ns) + i128::from(m.offset_ns);
            let lat = i128::from(m.t_ns) - sent;
            h.saturating_record(u64::try_from(lat).unwrap_or(0));
        }
    }
    Ok(h)
}

/// One end of the ping-pong: a zenoh peer (listening or connecting), publishing on `out` the way
/// stations publish states, subscribed to `inp`.
type End = (
    zenoh::Session,
    zenoh::pubsub::Publisher<'static>,
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
);

fn end(
    listen: Vec<String>,
    connect: Vec<String>,
    mode: network::Mode,
    out: &'static str,
    inp: &str,
) -> anyhow::Result<End> {
    let ep = NetworkConfig {
        listen,
        connect,
        mode,
        tls: None,
        emulate: false,
        ..NetworkConfig::default()
    };
    let err = |e: zenoh::Error| anyhow::anyhow!("{e}");
    let z = zenoh::open(network::config(&ep).map_err(anyhow::Error::msg)?)
        .wait()
        .map_err(err)?;
    let publisher = z
        .declare_publisher(out)
        .congestion_control(CongestionControl::Drop)
        .priority(Priority::RealTime)
        .express(true)
        .wait()
        .map_err(err)?;
    let sub = z.declare_subscriber(inp).wait().map_err(err)?;
    Ok((z, publisher, sub))
}

/// The child: echoes every ping as a pong until stdin closes; a peer listening on `listen`, or
/// with `via_router`, a client of the router there.
///
/// # Errors
/// Zenoh cannot be set up.
pub fn pong(listen: &str, via_router: bool) -> anyhow::Result<()> {
    let (_z, publisher, sub) = if via_router {
        end(
            vec![],
            vec![listen.to_owned()],
            network::Mode::Client,
            "coop/bench/pong",
            "coop/bench/ping",
        )?
    } else {
        end(
            vec![listen.to_owned()],
            vec![],
            network::Mode::Peer,
            "coop/bench/pong",
            "coop/bench/ping",
        )?
    };
    println!("ready");
    std::thread::spawn(|| {
        let mut s = String::new();
        let _ = std::io::stdin().read_line(&mut s);
        std::process::exit(0);
    });
    while let Ok(s) = sub.recv() {
        let _ = publisher.put(s.payload().clone()).wait();
    }
    Ok(())
}

/// Bare zenoh: one-way = ping-pong round trip / 2, between this process and a child, as peers, or
/// with `router` both clients of the router at that locator.
pub(crate) fn bare_zenoh(samples: u64, router: Option<&str>) -> anyhow::Result<Histogram<u64>> {
    let listen = match router {
        Some(r) => r.to_owned(),
        None => network::concrete_listen(&["tcp/127.0.0.1:0".into()]).remove(0),
    };
    let mut child = Command::new(std::env::current_exe()?)
        .args(["bench-pong", "--listen", &listen])
        .args(router.map(|_| "--via-router"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .context("starting the pong process")?;
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(child.stdout.take().context("pong stdout")?),
        &mut line,
    )?;
    if line.trim() != "ready" {
        let _ = child.kill();
        bail!("the pong process did not start: {line:?}");
    }
    let mode = if router.is_some() {
        network::Mode::Client
    } else {
        network::Mode::Peer
    };
    let (z, publisher, sub) = end(
        vec![],
        vec![listen],
        mode,
        "coop/bench/ping",
        "coop/bench/pong",
    )?;
    let payload = bare_payload();
    let mut h = histogram();
    let start = Instant::now();
    let mut k = 0u64;
    // Warm up (routes, connections), then measure.
    while h.len() < samples && start.elapsed() < Duration::from_secs(120) {
        let t0 = Instant::now();
        publisher
            .put(payload.clone())
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        if let Ok(Some(_)) = sub.recv_timeout(Duration::from_millis(100)) {
            k += 1;
            if k > 200 {
                h.saturating_record(t0.elapsed().as_nanos() as u64 / 2);
            }
        }
        let next = t0 + Duration::from_millis(1);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    drop(child.stdin.take());
    let _ = child.wait();
    let _ = z.close().wait();
    Ok(h)
}

/// Four stations at 1 kHz: each servo's overruns during the session, next to the standalone
/// `latency` tool's over the same time at the same settings (FIFO 80 on the servo's CPU, 1 kHz).
fn four_stations(
    root: &Path,
    station_bin: &crate::session::StationBin,
) -> anyhow::Result<serde_json::Value> {
    let (sc, o, dir) = bench_session(root, "four-users", true, station_bin)?;
    let _ = std::fs::remove_dir_all(&dir);
    let mut rows = Vec::new();
    for s in &sc.site {
        let live = o.stations.get(&s.name).and_then(|r| r.live.as_ref());
        let overruns = live.and_then(|l| l.overruns_during_session);
        let wake = live.map(|l| &l.status.loops.servo.wake_us);
        rows.push(serde_json::json!({
            "site": s.name.clone(),
            "servo_hz": s.servo_rate_hz,
            "servo_overruns": overruns.map(|o| o.servo),
            "physics_overruns": overruns.map(|o| o.physics),
            "servo_wake_p999_us": wake.and_then(|w| w.p999),
            "servo_wake_max_us": wake.map(|w| w.max),
        }));
    }
    let cpu = coop_rt::sched::allowed_cpus().last().copied().unwrap_or(0);
    let la = <crate::latency::Args as clap::Parser>::try_parse_from([
        "latency".to_owned(),
        "-D".into(),
        format!("{}s", sc.duration_s),
        "-a".into(),
        cpu.to_string(),
        "-m".into(),
        "-q".into(),
    ])?;
    let r = crate::latency::run(&la, "latency (session bench baseline)".into(), false)?;
    let t = r.threads.first().context("no latency thread")?;
    Ok(serde_json::json!({
        "duration_s": sc.duration_s,
        "stations": rows,
        "standalone_latency": {
            "overruns": t.overruns,
            "cycles": t.cycles,
            "wake_p999_us": t.hist.value_at_quantile(0.999) as f64 / 1e3,
            "wake_max_us": t.hist.max() as f64 / 1e3,
        },
    }))
}

/// Runs the benchmark and prints the table (or JSON).
///
/// # Errors
/// A session or zenoh failure.
pub fn run(json: bool, station_bin: &crate::session::StationBin) -> anyhow::Result<()> {
    let root: PathBuf = std::env::current_dir()?;
    if !root.join("scenarios/zero-delay.toml").exists() {
        bail!("run from the repository root (scenarios/zero-delay.toml not found)");
    }
    let (st, pipelines) = stations(&root, station_bin)?;
    let st = figures(&st);
    let bare = figures(&bare_zenoh(st.samples.clamp(1000, 20_000), None)?);
    let ratio = |a: f64, b: f64| a / b.max(1e-9);
    let (r50, r99) = (ratio(st.p50_us, bare.p50_us), ratio(st.p99_us, bare.p99_us));
    let four = four_stations(&root, station_bin)?;
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "stations": st, "bare_zenoh": bare, "ratio_p50": r50, "ratio_p99": r99,
                "pipeline": pipelines, "four_stations": four,
            }))?
        );
        return Ok(());
    }
    println!("# state latency on loopback: a two-station session of scenarios/zero-delay.toml (14 s, 1 kHz reports) vs bare zenoh ping-pong ({} B, two processes)", bare_payload().len());
    println!(
        "{:<44}{:>10}{:>10}{:>10}{:>10}",
        "path", "p50 us", "p99 us", "max us", "samples"
    );
    for (name, f) in [
        ("station physics A -> ring into physics B", st),
        ("bare zenoh one way (round trip / 2)", bare),
    ] {
        println!(
            "{:<44}{:>10.1}{:>10.1}{:>10.1}{:>10}",
            name, f.p50_us, f.p99_us, f.max_us, f.samples
        );
    }
    println!("{:<44}{:>10.2}{:>10.2}", "ratio stations / bare", r50, r99);
    println!(
        "# goal: <= 1.5x bare zenoh at p50 and p99: {}",
        if r50 <= 1.5 && r99 <= 1.5 {
            "met"
        } else {
            "NOT met"
        }
    );
    print_pipelines(&pipelines);
    println!(
        "\n# four stations (scenarios/four-users.toml, {} s, emulated network) vs the standalone latency tool on the servo CPU, same duration, after it",
        four["duration_s"]
    );
    println!(
        "{:<22}{:>10}{:>16}{:>18}{:>14}{:>14}",
        "loop", "rate Hz", "servo overruns", "physics overruns", "wake p99.9 us", "wake max us"
    );
    // serde_json's Display ignores widths: make strings first.
    let c = |v: &serde_json::Value| v.to_string();
    for r in four["stations"].as_array().into_iter().flatten() {
        println!(
            "{:<22}{:>10}{:>16}{:>18}{:>14}{:>14.0}",
            format!("station {}", r["site"].as_str().unwrap_or("?")),
            c(&r["servo_hz"]),
            c(&r["servo_overruns"]),
            c(&r["physics_overruns"]),
            c(&r["servo_wake_p999_us"]),
            r["servo_wake_max_us"].as_f64().unwrap_or(0.0)
        );
    }
    let s = &four["standalone_latency"];
    println!(
        "{:<22}{:>10}{:>16}{:>18}{:>14.0}{:>14.0}",
        "standalone latency",
        1000,
        c(&s["overruns"]),
        "-",
        s["wake_p999_us"].as_f64().unwrap_or(0.0),
        s["wake_max_us"].as_f64().unwrap_or(0.0)
    );
    println!(
        "# goal: no servo overruns at 1 kHz; the standalone row is what this machine does alone"
    );
    Ok(())
}

/// The bare zenoh payload: one encoded state of a moving object, every field a station's state
/// has set (the compact encoding sends what is not zero: a state at rest would be smaller than
/// the stations' own).
fn bare_payload() -> Vec<u8> {
    coop_transport::wire::encode(&coop_rt::msg::SiteReport {
        kind: 1,
        t_ns: 1_234_567_890_123,
        seq: 1000,
        site: 1,
        pos: [0.012, -0.034, 0.01],
        rot: [0.9, 0.1, -0.2, 0.3],
        vel: [0.1, -0.2, 0.003],
        ang_mom: [1e-5, -2e-5, 3e-5],
        accel: [0.5, -0.1, 0.2],
        included: [1.5, 1.49, -1.0, -1.0, -1.0, -1.0, -1.0, -1.0],
        ..Default::default()
    })
}
