//! `station status`: what a running station is doing, read from its control block and rings without
//! touching the loops (no claim, no lock; two snapshots 200 ms apart give the achieved rates).

use std::time::{Duration, Instant};

use anyhow::Context;
use coop_rt::msg::{ObjectSample, SiteReport, ToolSample};
use coop_rt::shm::control::{Child, ControlBlock, Ring, RunState};
use coop_rt::shm::{BlockSegment, RingOpenOptions, RingSegment};
use coop_rt::stats::LoopSnapshot;
use coop_rt::sync::Ordering;
use serde_json::json;

use super::segments::Names;

fn policy_name(n: u64) -> &'static str {
    match n {
        0 => "SCHED_OTHER",
        1 => "SCHED_FIFO",
        2 => "SCHED_RR",
        _ => "other",
    }
}

fn cpus(mask: u64) -> String {
    let v: Vec<String> = (0..64)
        .filter(|c| mask & (1 << c) != 0)
        .map(|c| c.to_string())
        .collect();
    if v.is_empty() {
        "-".into()
    } else {
        v.join(",")
    }
}

fn loop_json(s: &LoopSnapshot, rate: f64) -> serde_json::Value {
    let q = |p: f64| s.wake_us.value_at_quantile(p);
    json!({
        "period_us": s.period_ns as f64 / 1e3,
        "rate_hz": rate,
        "cycles": s.cycles,
        "overruns": s.overruns,
        "wake_us": { "min": s.wake_min_ns as f64 / 1e3, "p50": q(0.5), "p99": q(0.99), "p999": q(0.999), "max": s.wake_max_ns as f64 / 1e3 },
        "compute_us": { "p50": s.compute_us.value_at_quantile(0.5), "p99": s.compute_us.value_at_quantile(0.99), "max": s.compute_max_ns as f64 / 1e3 },
    })
}

/// The overrun counters of a running station's servo and physics loops (cheap: no snapshot).
///
/// # Errors
/// No such station.
pub fn overruns(session: &str, station: &str) -> anyhow::Result<[u64; 2]> {
    let names = Names::of(session, station)?;
    let ctl = BlockSegment::<ControlBlock>::open(&names.control, Duration::from_millis(500))?;
    Ok([
        ctl.servo.stats.overruns.load(Ordering::Relaxed),
        ctl.physics.stats.overruns.load(Ordering::Relaxed),
    ])
}

/// Reads the status of station `station` in `session` as JSON.
///
/// # Errors
/// No such station, or its segments fail validation (stale: run `station clean`).
pub fn read(session: &str, station: &str, sites: &[String]) -> anyhow::Result<serde_json::Value> {
    let names = Names::of(session, station)?;
    let ctl = BlockSegment::<ControlBlock>::open(&names.control, Duration::from_millis(500))
        .with_context(|| format!("station {station} of session {session}"))?;
    let (s0, p0, t0) = (ctl.servo.stats.snapshot(), ctl.physics.stats.snapshot(), Instant::now());
    std::thread::sleep(Duration::from_millis(200));
    let (s1, p1) = (ctl.servo.stats.snapshot(), ctl.physics.stats.snapshot());
    let dt = t0.elapsed().as_secs_f64();
    let rate = |a: &LoopSnapshot, b: &LoopSnapshot| (b.cycles.saturating_sub(a.cycles)) as f64 / dt;
    let opts = RingOpenOptions {
        capacity: None,
        ready_timeout: Duration::from_millis(500),
    };
    let fill = |r: Result<coop_rt::shm::RingFill, _>| match r {
        Ok(f) => json!({ "used": f.used, "capacity": f.capacity, "pushed": f.pushed }),
        Err(e) => json!({ "error": format!("{e}") }),
    };
    let children: Vec<serde_json::Value> = [
        ("servo", Child::Servo),
        ("physics", Child::Physics),
        ("network", Child::Network),
    ]
    .iter()
    .map(|(name, c)| {
        let slot = ctl.child(*c);
        json!({
            "name": name,
            "pid": slot.pid.load(Ordering::Relaxed),
            "heartbeat": slot.heartbeat.load(Ordering::Relaxed),
            "restarts": slot.restarts.load(Ordering::Relaxed),
            "policy": policy_name(slot.policy.load(Ordering::Relaxed)),
            "priority": slot.priority.load(Ordering::Relaxed),
            "cpus": cpus(slot.cpus.load(Ordering::Relaxed)),
        })
    })
    .collect();
    Ok(json!({
        "session": session,
        "station": station,
        "run_state": format!("{:?}", ctl.run_state()).to_lowercase(),
        "children": children,
        "loops": { "servo": loop_json(&s1, rate(&s0, &s1)), "physics": loop_json(&p1, rate(&p0, &p1)) },
        "rings": {
            "tool": fill(RingSegment::<ToolSample>::inspect(&names.tool, &opts)),
            "object": fill(RingSegment::<ObjectSample>::inspect(&names.object, &opts)),
            "report": fill(RingSegment::<SiteReport>::inspect(&names.report, &opts)),
            "remote": fill(RingSegment::<SiteReport>::inspect(&names.remote, &opts)),
            "drops": { "tool": ctl.ring_drops(Ring::Tool), "object": ctl.ring_drops(Ring::Object),
                       "report": ctl.ring_drops(Ring::Report), "remote": ctl.ring_drops(Ring::Remote) },
        },
        "network": network_json(&ctl, sites),
        "physics": {
            "remote_received": ctl.physics.received.load(Ordering::Relaxed),
            "adoptions": ctl.physics.adoptions.load(Ordering::Relaxed),
        },
        "servo": {
            "command_n": ControlBlock::load_f64(&ctl.servo.command_n),
            "display_scale": ControlBlock::load_f64(&ctl.servo.scale),
        },
        "running": ctl.run_state() == RunState::Running,
    }))
}

fn network_json(ctl: &ControlBlock, sites: &[String]) -> serde_json::Value {
    let refused: Vec<u64> = ctl.network.refused.all().map(|(_, n)| n).collect();
    let present = ctl.network.peers_present.load(Ordering::Relaxed);
    let peers: Vec<serde_json::Value> = sites
        .iter()
        .enumerate()
        .map(|(j, name)| {
            let rtt = ctl.network.clock_rtt_ns[j].load(Ordering::Relaxed);
            json!({
                "site": name,
                "present": present & (1 << j) != 0,
                "clock_offset_us": (rtt > 0).then(|| ctl.network.clock_offset_ns[j].load(Ordering::Relaxed) as i64 as f64 / 1e3),
                "clock_rtt_us": (rtt > 0).then(|| rtt as f64 / 1e3),
            })
        })
        .collect();
    let lat = ctl.network.latency.to_hdr();
    let n = ctl.network.latency_count.load(Ordering::Relaxed);
    let q = |p: f64| lat.value_at_quantile(p);
    json!({
        "locators": ctl.locators(),
        "published": ctl.network.published.load(Ordering::Relaxed),
        "received": ctl.network.received.load(Ordering::Relaxed),
        "rejected": refused.iter().sum::<u64>(),
        "refused": { "version": refused[0], "length": refused[1], "contents": refused[2], "foreign": refused[3], "duplicate_or_reordered": refused[4] },
        "emulation": if ctl.network.emulated.load(Ordering::Relaxed) == 1 { "EMULATED (delay, jitter, loss on receive)" } else { "none" },
        "emulated_lost": ctl.network.emulated_lost.load(Ordering::Relaxed),
        "join_states": ctl.network.join_states.load(Ordering::Relaxed),
        "joins": ctl.network.peer_joins.load(Ordering::Relaxed),
        "leaves": ctl.network.peer_leaves.load(Ordering::Relaxed),
        "peers": peers,
        "latency_us": if n > 0 { json!({ "count": n, "p50": q(0.5), "p99": q(0.99), "max": lat.max() }) } else { json!(null) },
        "epoch_ns": ctl.epoch(),
    })
}

/// Prints the status for people.
pub fn print(v: &serde_json::Value) {
    let s = |v: &serde_json::Value| v.as_str().unwrap_or("?").to_owned();
    println!(
        "station {} (session {}): {}",
        s(&v["station"]),
        s(&v["session"]),
        s(&v["run_state"])
    );
    println!(
        "{:<9}{:>8}{:>11}{:>10}  {:<12}{:>5}  cpus",
        "child", "pid", "heartbeat", "restarts", "policy", "prio"
    );
    let n = |v: &serde_json::Value| v.as_u64().unwrap_or(0);
    for c in v["children"].as_array().into_iter().flatten() {
        println!(
            "{:<9}{:>8}{:>11}{:>10}  {:<12}{:>5}  {}",
            s(&c["name"]),
            n(&c["pid"]),
            n(&c["heartbeat"]),
            n(&c["restarts"]),
            s(&c["policy"]),
            n(&c["priority"]),
            s(&c["cpus"])
        );
    }
    println!(
        "{:<9}{:>9}{:>10}{:>10}{:>10}  {:<26}{:>14}",
        "loop",
        "rate Hz",
        "period us",
        "cycles",
        "overruns",
        "wake p50/p99/p99.9/max us",
        "compute max us"
    );
    for name in ["servo", "physics"] {
        let l = &v["loops"][name];
        let w = &l["wake_us"];
        println!(
            "{:<9}{:>9.1}{:>10.1}{:>10}{:>10}  {:<26}{:>14.1}",
            name,
            l["rate_hz"].as_f64().unwrap_or(0.0),
            l["period_us"].as_f64().unwrap_or(0.0),
            n(&l["cycles"]),
            n(&l["overruns"]),
            format!(
                "{}/{}/{}/{:.0}",
                w["p50"],
                w["p99"],
                w["p999"],
                w["max"].as_f64().unwrap_or(0.0)
            ),
            l["compute_us"]["max"].as_f64().unwrap_or(0.0)
        );
    }
    let r = &v["rings"];
    let f = |x: &serde_json::Value| format!("{}/{}", x["used"], x["capacity"]);
    println!(
        "rings (used/slots): tool {}, object {}, report {}, remote {}; drops: tool {}, object {}, report {}, remote {}",
        f(&r["tool"]), f(&r["object"]), f(&r["report"]), f(&r["remote"]),
        r["drops"]["tool"], r["drops"]["object"], r["drops"]["report"], r["drops"]["remote"]
    );
    let net = &v["network"];
    println!("zenoh: {}", s(&net["locators"]));
    println!(
        "network: published {}, received {}, refused {} {}; emulation: {} (lost {}); late-join states {}",
        net["published"], net["received"], net["rejected"], net["refused"], s(&net["emulation"]), net["emulated_lost"], net["join_states"]
    );
    for p in net["peers"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|p| p["site"] != v["station"])
    {
        println!(
            "  peer {:<10} {:<8} clock offset {} us, rtt {} us",
            s(&p["site"]),
            if p["present"].as_bool() == Some(true) {
                "present"
            } else {
                "absent"
            },
            p["clock_offset_us"],
            p["clock_rtt_us"]
        );
    }
    if !net["latency_us"].is_null() {
        let l = &net["latency_us"];
        println!(
            "state latency (sender physics -> our physics ring): p50 {} us, p99 {} us, max {} us over {}",
            l["p50"], l["p99"], l["max"], l["count"]
        );
    }
    println!(
        "physics: took {} remote reports, adopted {}",
        v["physics"]["remote_received"], v["physics"]["adoptions"]
    );
    println!(
        "servo: commanding {:.2} N, display scale {:.2}",
        v["servo"]["command_n"].as_f64().unwrap_or(0.0),
        v["servo"]["display_scale"].as_f64().unwrap_or(0.0)
    );
}
