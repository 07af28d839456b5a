//! `session bench-router`: the state latency between two stations through one zenoh router, next
//! to the same two stations peer to peer and to a bare zenoh ping-pong through the same router, in
//! one run on this machine (loopback, plain TCP: what the router adds, not what TLS does).
//!
//! - **Peer to peer**: a `session run` of `scenarios/zero-delay.toml` (paper method, 1 kHz
//!   reports, no emulation), as `session bench` runs it.
//! - **Through the router**: a `station router` (its own process, the `zenoh` crate in router
//!   mode), two stations started as separate processes in client mode connected to it only, and
//!   the launcher driving them as `session run --attach` does (itself a client of the router).
//!   Latency: as peer to peer, from the receivers' recordings (receive minus send time, one clock).
//! - **Bare zenoh through the router**: this process and a child (`session bench-pong
//!   --via-router`), both clients of the same router, ping-pong the same payload (one encoded state) with the
//!   stations' publisher settings (express, real-time priority, drop on congestion), at 1 kHz; one
//!   way = round trip / 2, each way through the router once. No station, ring or protocol of ours.
//!   For scale, the same ping-pong peer to peer after it.
//!
//! Goal: stations through the router within 1.5× the bare router path (p50 and p99). Quick mode
//! (`--quick`, CI) runs 4 s sessions (the scenario without its phases) instead of 14 s.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use coop_actors::station::config::{StartMode, StationConfig};
use coop_model::scenario::MethodName;
use coop_transport::network::{self, NetworkConfig};

use super::{bare_zenoh, bench_scenario, figures, latencies, Figures};
use crate::session::attach::{run_attached, Attach};
use crate::session::{RunArgs, StationBin};

/// A child process that is stopped (SIGTERM, then SIGKILL) when dropped.
struct Reaped(Child, &'static str);

impl Reaped {
    /// SIGTERM, then up to `limit` for it to exit (SIGKILL after); whether it exited by itself
    /// with success.
    fn stop(&mut self, limit: Duration) -> bool {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(self.0.id() as i32),
            nix::sys::signal::Signal::SIGTERM,
        );
        self.wait(limit)
    }

    /// Up to `limit` for it to exit (SIGKILL after); whether it exited with success.
    fn wait(&mut self, limit: Duration) -> bool {
        let deadline = Instant::now() + limit;
        while Instant::now() < deadline {
            if let Ok(Some(s)) = self.0.try_wait() {
                return s.success();
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
        false
    }
}

impl Drop for Reaped {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            eprintln!("bench-router: stopping the {} left running", self.1);
            self.stop(Duration::from_secs(5));
        }
    }
}

/// The scenario the benchmark runs: `zero-delay.toml`, or in quick mode a 4 s copy of it without
/// its phases (they go beyond 4 s) in `dir`.
fn scenario(root: &Path, quick: bool, dir: &Path) -> anyhow::Result<PathBuf> {
    let full = root.join("scenarios/zero-delay.toml");
    if !quick {
        return Ok(full);
    }
    let text =
        std::fs::read_to_string(&full).with_context(|| format!("reading {}", full.display()))?;
    let world = text.split("[[phase]]").next().unwrap_or(&text);
    if !world.contains("\nduration_s = 14.0") {
        bail!("{}: no `duration_s = 14.0` to shorten", full.display());
    }
    let short = dir.join("zero-delay-quick.toml");
    std::fs::write(
        &short,
        world.replacen("\nduration_s = 14.0", "\nduration_s = 4.0", 1),
    )?;
    Ok(short)
}

/// Starts the router: `station router run` on a free loopback port; its locator once its status
/// file is written.
fn start_router(bin: &StationBin, dir: &Path) -> anyhow::Result<(Reaped, String)> {
    let locator = network::concrete_listen(&["tcp/127.0.0.1:0".into()]).remove(0);
    let cfg = dir.join("router.toml");
    let status = dir.join("router.json");
    std::fs::write(
        &cfg,
        format!("name = \"bench\"\nlisten = [{locator:?}]\nstatus_file = {status:?}\n"),
    )?;
    let log = std::fs::File::create(dir.join("router.log"))?;
    let child = Command::new(&bin.program)
        .args(&bin.prefix)
        .args(["router", "run", "--config"])
        .arg(&cfg)
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .context("starting the router")?;
    let mut r = Reaped(child, "router");
    let resolved = coop_actors::router::RouterConfig::load(&cfg)?;
    let deadline = Instant::now() + Duration::from_secs(30);
    while coop_actors::router::read_status(&resolved).is_err() {
        if let Ok(Some(s)) = r.0.try_wait() {
            bail!("the router exited at start ({s})");
        }
        if Instant::now() > deadline {
            bail!("the router wrote no status in 30 s ({})", status.display());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok((r, locator))
}

/// The two stations through the router: started as their own processes (client mode, connected
/// to the router only, waiting for the session's time 0), driven by [`run_attached`]; the
/// latencies from their recordings.
fn through_router(
    scenario: &Path,
    router: &str,
    bin: &StationBin,
    dir: &Path,
) -> anyhow::Result<hdrhistogram::Histogram<u64>> {
    let sc = coop_actors::scenario_file::load(scenario)?;
    let session = format!("b{}r", std::process::id());
    let mut stations = Vec::new();
    let mut recordings = std::collections::BTreeMap::new();
    for s in &sc.site {
        let record = dir.join(format!("{}.mcap", s.name));
        let _ = std::fs::remove_file(&record);
        let c = StationConfig {
            session: session.clone(),
            station: Some(s.name.clone()),
            scenario: Some(scenario.to_owned()),
            method: Some(MethodName::Paper),
            start: StartMode::Session,
            record: Some(record.clone()),
            network: NetworkConfig {
                mode: network::Mode::Client,
                connect: vec![router.to_owned()],
                emulate: false,
                ..NetworkConfig::default()
            },
            ..StationConfig::default()
        };
        let cfg = dir.join(format!("{}.toml", s.name));
        std::fs::write(&cfg, c.to_toml()?)?;
        let log = std::fs::File::create(dir.join(format!("{}.log", s.name)))?;
        let child = crate::session::station_run(bin, &cfg, log)?
            .spawn()
            .with_context(|| format!("starting station {}", s.name))?;
        stations.push(Reaped(child, "station"));
        recordings.insert(s.name.clone(), record);
    }
    let a = RunArgs {
        trials: false,
        scenario: scenario.to_owned(),
        out: dir.join("attached"),
        methods: vec![MethodName::Paper],
        session: Some(session.clone()),
        late: vec![],
        emulate: false,
        start_timeout: Duration::from_secs(30),
        station_bin: bin.clone(),
        progress: false,
        stop: crate::cli::StopFlag::manual(),
        record_max_file_s: None,
        live: None,
        attach: None,
        ros2: None,
    };
    let at = Attach {
        connect: vec![router.to_owned()],
        mode: network::Mode::Client,
        tls: None,
        recordings: recordings.clone(),
    };
    run_attached(&a, &at, &sc, MethodName::Paper, &session)
        .with_context(|| format!("the session through the router (logs in {})", dir.display()))?;
    for s in &mut stations {
        // They stop by themselves at the scenario's end; run_attached waited for their recordings.
        s.wait(Duration::from_secs(10));
    }
    latencies(&recordings.into_values().collect::<Vec<_>>())
}

/// Runs the benchmark and prints the table (or JSON).
///
/// # Errors
/// A session, router or zenoh failure.
pub fn run(json: bool, quick: bool, bin: &StationBin) -> anyhow::Result<()> {
    let root: PathBuf = std::env::current_dir()?;
    if !root.join("scenarios/zero-delay.toml").exists() {
        bail!("run from the repository root (scenarios/zero-delay.toml not found)");
    }
    let dir = std::env::temp_dir().join(format!("coop-bench-router-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let result = (|| {
        let scenario = scenario(&root, quick, &dir)?;
        let (_, _, p2p_dir) = bench_scenario(&scenario, "p2p", false, bin)?;
        let p2p = figures(&latencies(&[
            p2p_dir.join("paper/user1.mcap"),
            p2p_dir.join("paper/user2.mcap"),
        ])?);
        let _ = std::fs::remove_dir_all(&p2p_dir);
        let (mut router, locator) = start_router(bin, &dir)?;
        let routed = figures(&through_router(&scenario, &locator, bin, &dir)?);
        let samples = routed
            .samples
            .clamp(1000, if quick { 3000 } else { 14_000 });
        let bare = figures(&bare_zenoh(samples, Some(&locator))?);
        if !router.stop(Duration::from_secs(10)) {
            bail!("the router did not stop cleanly");
        }
        let bare_p2p = figures(&bare_zenoh(samples, None)?);
        Ok::<_, anyhow::Error>(Paths {
            p2p,
            routed,
            bare,
            bare_p2p,
        })
    })();
    let _ = std::fs::remove_dir_all(&dir);
    print(json, quick, &result?)
}

/// The four paths' figures.
struct Paths {
    /// Stations peer to peer.
    p2p: Figures,
    /// Stations through the router.
    routed: Figures,
    /// Bare zenoh through the router.
    bare: Figures,
    /// Bare zenoh peer to peer (for scale: what the router adds without any station).
    bare_p2p: Figures,
}

fn print(json: bool, quick: bool, p: &Paths) -> anyhow::Result<()> {
    let Paths {
        p2p,
        routed,
        bare,
        bare_p2p,
    } = *p;
    let ratio = |a: f64, b: f64| a / b.max(1e-9);
    let vs_bare = (
        ratio(routed.p50_us, bare.p50_us),
        ratio(routed.p99_us, bare.p99_us),
    );
    let vs_p2p = (
        ratio(routed.p50_us, p2p.p50_us),
        ratio(routed.p99_us, p2p.p99_us),
    );
    let met = vs_bare.0 <= 1.5 && vs_bare.1 <= 1.5;
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "quick": quick,
                "stations_peer_to_peer": p2p,
                "stations_through_router": routed,
                "bare_zenoh_through_router": bare,
                "bare_zenoh_peer_to_peer": bare_p2p,
                "ratio_router_vs_bare": { "p50": vs_bare.0, "p99": vs_bare.1 },
                "ratio_router_vs_peer_to_peer": { "p50": vs_p2p.0, "p99": vs_p2p.1 },
                "goal_met": met,
            }))?
        );
        return Ok(());
    }
    println!(
        "# state latency through one zenoh router (station router, loopback TCP) vs peer to peer vs bare zenoh through the same router; scenarios/zero-delay.toml ({} s, 1 kHz reports, no emulation)",
        if quick { 4 } else { 14 }
    );
    println!(
        "{:<50}{:>10}{:>10}{:>10}{:>10}",
        "path", "p50 us", "p99 us", "max us", "samples"
    );
    for (name, f) in [
        ("stations peer to peer (physics A -> physics B)", p2p),
        ("stations through the router", routed),
        ("bare zenoh through the router (round trip / 2)", bare),
        ("bare zenoh peer to peer (round trip / 2)", bare_p2p),
    ] {
        println!(
            "{:<50}{:>10.1}{:>10.1}{:>10.1}{:>10}",
            name, f.p50_us, f.p99_us, f.max_us, f.samples
        );
    }
    println!(
        "{:<50}{:>10.2}{:>10.2}",
        "ratio router / bare router", vs_bare.0, vs_bare.1
    );
    println!(
        "{:<50}{:>10.2}{:>10.2}",
        "ratio router / peer to peer", vs_p2p.0, vs_p2p.1
    );
    println!(
        "# goal: stations through the router <= 1.5x bare zenoh through it at p50 and p99: {}",
        if met { "met" } else { "NOT met" }
    );
    Ok(())
}
