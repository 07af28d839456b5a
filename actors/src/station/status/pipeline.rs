//! The pipeline's own latency, hop by hop, as the station's loops measured it: how long a tool
//! sample takes to reach physics, a report to reach zenoh, a partner's report to reach this
//! physics and the force this station displays. Every figure is a difference of two times on this
//! machine's CLOCK_MONOTONIC (a partner's times corrected by its measured clock offset), so on one
//! machine they add up to the pipeline's latency from a tool sample at one station to the force
//! at another.

use std::fmt;

use coop_rt::shm::control::ControlBlock;
use coop_rt::stats::SharedHistogram;
use coop_rt::sync::AtomicU64;
use serde::Serialize;

use super::Latency;

/// One hop's figures (none before its first sample).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Hop {
    /// From where to where.
    pub hop: &'static str,
    /// Samples.
    pub count: u64,
    /// Median, µs.
    pub p50_us: u64,
    /// 99th percentile, µs.
    pub p99_us: u64,
    /// Largest, µs.
    pub max_us: u64,
}

/// The hops' names, in the order a tool sample travels: own ones, then a partner's report's.
pub const HOPS: [&str; 6] = [
    "servo -> physics",
    "physics -> zenoh put",
    "partner physics -> our physics ring",
    "partner physics -> our physics",
    "physics -> servo",
    "partner physics -> our displayed force",
];

impl Hop {
    fn of(hop: &'static str, h: &SharedHistogram, count: &AtomicU64) -> Option<Self> {
        Latency::of(h, count).map(|l| Self {
            hop,
            count: l.count,
            p50_us: l.p50,
            p99_us: l.p99,
            max_us: l.max,
        })
    }
}

/// Every hop measured so far at the station of `ctl`, in [`HOPS`] order.
pub fn hops(ctl: &ControlBlock) -> Vec<Hop> {
    let (p, n, s) = (&ctl.physics, &ctl.network, &ctl.servo);
    [
        Hop::of(HOPS[0], &p.tool_wait, &p.tool_wait_count),
        Hop::of(HOPS[1], &n.publish_wait, &n.publish_wait_count),
        Hop::of(HOPS[2], &n.latency, &n.latency_count),
        Hop::of(HOPS[3], &p.remote_wait, &p.remote_wait_count),
        Hop::of(HOPS[4], &s.state_wait, &s.state_wait_count),
        Hop::of(HOPS[5], &s.remote_display, &s.remote_display_count),
    ]
    .into_iter()
    .flatten()
    .collect()
}

/// The hops as `station status` prints them.
pub fn fmt_hops(hops: &[Hop], f: &mut fmt::Formatter<'_>) -> fmt::Result {
    if hops.is_empty() {
        return Ok(());
    }
    writeln!(
        f,
        "pipeline (one clock; a partner's times corrected by its offset):"
    )?;
    for h in hops {
        writeln!(
            f,
            "  {:<40} p50 {:>6} us  p99 {:>6} us  max {:>7} us  over {}",
            h.hop, h.p50_us, h.p99_us, h.max_us, h.count
        )?;
    }
    Ok(())
}
