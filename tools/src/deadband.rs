//! `sim deadband`: what the perceptual deadband (`[timewarp.deadband]`) saves and what it costs
//! the users' feel. At each constant delay, `timewarp` runs twice on the same scenario and seed:
//! every tick's position sent (the full-rate run, the baseline), and through the deadband. Per
//! run: the share of the own ticks whose position was sent, the payload the busiest site puts,
//! the phases passed, hash mismatches; and per site and servo tick, the displayed force's
//! difference from the full-rate run's at the same tick in just-noticeable steps (a JND: 7 % of the
//! full-rate force, at least 0.05 N, `perception::force_jnd_n`): the share of ticks within one
//! JND and the 99th percentile. Two runs of a contact task part ways in time (a contact a tick
//! earlier, a push a little weaker), and a difference tick by tick counts that too; so a
//! third run is the baseline: a deadband of 1.5 quanta (0.015 mm) everywhere, the least change
//! the wire can express, compared the same way; and a fourth the noise floor: the full-rate run
//! again with the next seed (other draws of the force sensor's noise and of the delay's jitter),
//! which says how far two runs of the task part with no codec at all.

use anyhow::Context;
use coop_model::method::timewarp::DeadbandSpec;
use coop_model::scenario::{MethodName, Scenario};
use coop_model::sim::{self, Mode, RunResult};
use coop_model::{metrics, perception};

use crate::sweep::{par_map, scenario_at};

/// One delay's pair of runs.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// One-way delay, ms.
    pub delay_ms: f64,
    /// Own ticks whose position was sent, over every site: full rate 1.
    pub sent_share: f64,
    /// Payload the busiest site puts, kbit/s: full rate, deadband.
    pub kbit_s: [f64; 2],
    /// Phases passed: full rate, deadband...
    pub phases: [usize; 2],
    /// ... of this many.
    pub phases_total: usize,
    /// Hash mismatches (deadband run).
    pub hash_mismatches: u64,
    /// Servo ticks (every site's) whose displayed force is within one JND of the full-rate
    /// run's.
    pub within_jnd: f64,
    /// The 99th percentile of the force difference, JND.
    pub p99_jnd: f64,
    /// The same two figures for the baseline (a band of 1.5 quanta).
    pub baseline_within_jnd: f64,
    /// See `baseline_within_jnd`.
    pub baseline_p99_jnd: f64,
    /// The same two figures for the full-rate run with the next seed (the noise floor).
    pub reseeded_within_jnd: f64,
    /// See `reseeded_within_jnd`.
    pub reseeded_p99_jnd: f64,
}

/// The share of `e` (JND) within 1, and its 99th percentile.
fn within_and_p99(e: Vec<f64>) -> (f64, f64) {
    if e.is_empty() {
        return (0.0, 0.0);
    }
    let within = e.iter().filter(|&&x| x <= 1.0).count() as f64 / e.len() as f64;
    (within, crate::simbench::quantile(e, 0.99))
}

/// The displayed force's difference between `db` and `full`, servo tick by servo tick (the two
/// runs' sites tick at the same instants), in JND ([`perception::force_jnd_n`] of the full-rate
/// run's force: the one just-noticeable difference every figure of the project counts in, not
/// the deadband's own parameter).
fn force_error_jnd(full: &RunResult, db: &RunResult) -> Vec<f64> {
    let mut out = Vec::new();
    for (a, b) in full.servo_forces.iter().zip(&db.servo_forces) {
        for (fa, fb) in a.iter().zip(b) {
            out.push((fb - fa).norm() / perception::force_jnd_n(fa.norm()));
        }
    }
    out
}

/// Runs the pairs at each of `delays_ms` (the scenario's deadband settings, turned on).
///
/// # Errors
/// A delay makes the scenario invalid.
pub fn rows(base: &Scenario, delays_ms: &[f64]) -> anyhow::Result<Vec<Row>> {
    let mut jobs = Vec::new();
    for &d in delays_ms {
        let full = scenario_at(base, d, base.seed)?;
        let mut db = full.clone();
        db.timewarp.deadband.enabled = true;
        db.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
        let mut least = db.clone();
        let q = 1.5 * coop_model::method::track::QUANTUM_M;
        least.timewarp.deadband = DeadbandSpec {
            enabled: true,
            weber_fraction: 1e-9,
            floor_n: q * base.contact.stiffness_n_per_m,
            near_m: 0.0,
            free_space_m: q,
        };
        let reseeded = scenario_at(base, d, base.seed.wrapping_add(1))?;
        jobs.push((d, full, db, least, reseeded));
    }
    let reference = sim::run(base, Mode::Reference, &mut |_| {});
    let runs = par_map(&jobs, |(d, full, db, least, reseeded)| {
        let mode = Mode::Distributed(MethodName::Timewarp);
        let size = &crate::sim::wire_bytes;
        let a = sim::run_keeping_servo_forces(full, mode, &mut |_| {}, size);
        let b = sim::run_keeping_servo_forces(db, mode, &mut |_| {}, size);
        let c = sim::run_keeping_servo_forces(least, mode, &mut |_| {}, &|_, _, _, _| 0);
        let e = sim::run_keeping_servo_forces(reseeded, mode, &mut |_| {}, &|_, _, _, _| 0);
        (*d, a, b, c, e)
    });
    Ok(runs
        .into_iter()
        .map(|(delay_ms, a, b, c, e)| {
            let (ma, mb) = (
                metrics::compute(base, &a, &reference),
                metrics::compute(base, &b, &reference),
            );
            let (ticks, samples) = b.rollback.iter().flatten().fold((0, 0), |(t, s), r| {
                (t + r.deadband_ticks, s + r.deadband_samples)
            });
            let (within, p99) = within_and_p99(force_error_jnd(&a, &b));
            let (base_within, base_p99) = within_and_p99(force_error_jnd(&a, &c));
            let (seed_within, seed_p99) = within_and_p99(force_error_jnd(&a, &e));
            Row {
                delay_ms,
                sent_share: samples as f64 / ticks.max(1) as f64,
                kbit_s: [
                    crate::sim::busiest_sent_kbit_s(&ma, base.duration_s),
                    crate::sim::busiest_sent_kbit_s(&mb, base.duration_s),
                ],
                phases: [ma.phases_passed, mb.phases_passed],
                phases_total: mb.phases_total,
                hash_mismatches: mb.hash_mismatches,
                within_jnd: within,
                p99_jnd: p99,
                baseline_within_jnd: base_within,
                baseline_p99_jnd: base_p99,
                reseeded_within_jnd: seed_within,
                reseeded_p99_jnd: seed_p99,
            }
        })
        .collect())
}

/// Prints the table (or JSON) for `scenario` at `delays_ms`.
///
/// # Errors
/// As [`rows`].
pub fn main(sc: &Scenario, delays_ms: &[f64], json: bool) -> anyhow::Result<()> {
    let rows = rows(sc, delays_ms).context("sim deadband")?;
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    let d = sc.timewarp.deadband;
    println!(
        "# scenario {} (seed {}, {} s): timewarp, every tick's position sent vs a perceptual deadband (Weber {} of the contact force, floor {} N, near {} m, free space {} m)",
        sc.name, sc.seed, sc.duration_s, d.weber_fraction, d.floor_n, d.near_m, d.free_space_m
    );
    println!(
        "{:>8}{:>10}{:>14}{:>14}{:>12}{:>12}{:>11}{:>12}{:>10}{:>12}{:>10}{:>12}{:>10}",
        "delay",
        "sent",
        "kbit/s full",
        "kbit/s band",
        "phases",
        "phases",
        "hash",
        "force",
        "force",
        "baseline",
        "baseline",
        "reseeded",
        "reseeded"
    );
    println!(
        "{:>8}{:>10}{:>14}{:>14}{:>12}{:>12}{:>11}{:>12}{:>10}{:>12}{:>10}{:>12}{:>10}",
        "ms",
        "of ticks",
        "",
        "",
        "full",
        "band",
        "mismatch",
        "<=1 JND",
        "p99 JND",
        "<=1 JND",
        "p99 JND",
        "<=1 JND",
        "p99 JND"
    );
    for r in &rows {
        println!(
            "{:>8.0}{:>9.1}%{:>14.1}{:>14.1}{:>12}{:>12}{:>11}{:>11.2}%{:>10.2}{:>11.2}%{:>10.2}{:>11.2}%{:>10.2}",
            r.delay_ms,
            100.0 * r.sent_share,
            r.kbit_s[0],
            r.kbit_s[1],
            format!("{}/{}", r.phases[0], r.phases_total),
            format!("{}/{}", r.phases[1], r.phases_total),
            r.hash_mismatches,
            100.0 * r.within_jnd,
            r.p99_jnd,
            100.0 * r.baseline_within_jnd,
            r.baseline_p99_jnd,
            100.0 * r.reseeded_within_jnd,
            r.reseeded_p99_jnd
        );
    }
    println!("# sent = own ticks whose position left the band and was sent (every site); kbit/s = payload the busiest site puts; force = each site's displayed force (F_h, every servo tick) against the full-rate run's at the same tick, in JND (7 % of the full-rate force, at least 0.05 N); baseline = the same against a run through a band of 1.5 quanta (0.015 mm), the least change the wire can express; reseeded = the full-rate run with the next seed (other draws of sensor noise and jitter), against the full-rate run: how far two runs of the task part with no codec at all");
    Ok(())
}
