//! `sim deadband`: what the perceptual deadband (`[timewarp.deadband]`) saves and what it costs
//! the users' feel. At each constant delay, `timewarp` runs with every tick's position sent (the
//! full-rate run, the baseline) and through the deadband. Per run: the share of the own ticks
//! whose position was sent, the payload the busiest site puts, the phases passed, hash
//! mismatches.
//!
//! The codec's own measure, and its goal, is taken inside the deadband run, as the codec
//! literature measures a codec (its decoded signal against its own source): at every physics
//! tick, each site's tool's contact force is rendered twice from the same world state, at the
//! position every site decodes and steps with (the held one) and at the one the hand measured;
//! the share of contact ticks within one JND of the source's force, the 99th percentile, and the
//! distance from the measured position to the decoded one per tool
//! (`coop_model::method::timewarp::CodecError`). Goal: [`CODEC_GOAL`] of the contact ticks at
//! every delay from 0 to 300 ms.
//!
//! The run-vs-run figures that follow compare two runs, and show the friction model's chaos more
//! than the codec: a stuck contact keeps any perturbation for the rest of a grasp, so a second
//! full-rate run with only the jitter's draws changed parts as far. Per site and servo tick, the
//! displayed force's difference from the full-rate
//! run's at the same tick in just-noticeable steps (a JND: 7 % of the full-rate force, at least
//! 0.05 N, `perception::force_jnd_n`): the share of ticks within one JND and the 99th percentile.
//! Two runs of a contact task part ways in time (a contact a tick earlier, a push a little
//! weaker), and a difference tick by tick counts that too; so a third run is the baseline: a
//! deadband of 1.5 quanta (0.015 mm) everywhere, the least change the wire can express, compared
//! the same way; and a fourth the noise floor: the full-rate run again with the next seed (other
//! draws of the force sensor's noise and of the delay's jitter), which shows how far two runs of
//! the task part with no codec at all.
//!
//! The users' hands react to what they feel, so a force a little different moves the hand a
//! little differently, and the runs part further. The four runs are therefore made twice: with
//! the hands as the scenario has them, and with every site's tool replayed from the full-rate
//! run's servo ticks (a recorded hand, `coop_model::replay`), the same in all four, so that only
//! the world differs: what the codec itself changes in what the users feel. (A replay is not the
//! full-rate run again: between servo ticks, at the physics ticks, the hand moves on a straight
//! line, and a recorded hand has no force sensor. The full-rate run replayed is the baseline the
//! other three replayed are compared with.)
//!
//! Of the deadband run's ticks beyond one JND with the hands replayed, it counts those at which
//! both runs' tools press equally deep: the normal force's elastic part (the contact stiffness ×
//! the deepest penetration) within one JND of the full-rate run's. There the rest made the
//! difference: mostly the tangential force a stuck contact holds, which depends on where it
//! stuck (and the normal damping, and what the display's stages do to the force).

use anyhow::Context;
use coop_model::method::timewarp::{CodecError, DeadbandSpec};
use coop_model::replay::Trajectory;
use coop_model::scenario::{MethodName, Scenario};
use coop_model::sim::{self, Mode, RunResult, ServoTick};
use coop_model::{metrics, perception};

use crate::sweep::{par_map, scenario_at};

/// The displayed force's difference from a run's, tick by tick: the share of servo ticks within
/// one JND, and the 99th percentile, JND.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct ForceError {
    /// Servo ticks (every site's) whose displayed force is within one JND of the other run's.
    pub within_jnd: f64,
    /// The 99th percentile of the difference, JND.
    pub p99_jnd: f64,
    /// Of the ticks beyond one JND, the share at which the tool touches in both runs and presses
    /// equally deep (the normal force's elastic part, the contact stiffness × the deepest
    /// penetration, within one JND of the other run's): the rest made the difference, mostly the
    /// stuck friction force, which depends on where the contact stuck (0 with none beyond).
    pub normal_agrees: f64,
}

/// Three runs against the full-rate run: through the deadband, through the least band the wire
/// can express, and the full-rate run with the next seed.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct ForceErrors {
    /// Through the deadband.
    pub band: ForceError,
    /// Through a band of 1.5 quanta (0.015 mm) everywhere: what any change of the inputs costs.
    pub baseline: ForceError,
    /// The full-rate run with the next seed: how far two runs part with no codec at all.
    pub reseeded: ForceError,
}

/// The codec's own measure in the deadband run (hands reacting): each site's own tool's contact
/// force rendered from the same world state at the held (decoded) and at the measured (source)
/// position, every physics tick ([`coop_model::method::timewarp::CodecError`]).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Codec {
    /// Every site's ticks in which its tool touched an object, the share within one JND.
    pub contact_within_jnd: f64,
    /// Their 99th percentile, JND (the histogram's bin edge: at most 12.5 % high).
    pub contact_p99_jnd: f64,
    /// Every tick, out of contact too (where both forces are zero), the share within one JND.
    pub within_jnd: f64,
    /// Per site's tool: the share of its contact ticks within one JND...
    pub tool_contact_within_jnd: Vec<f64>,
    /// ... and the distance from the measured position to the decoded one, mm: p99, max.
    pub tool_position_mm: Vec<[f64; 2]>,
}

impl Codec {
    /// From the deadband run's per-site figures.
    fn of(run: &RunResult) -> Self {
        let per_site: Vec<CodecError> = run
            .rollback
            .iter()
            .map(|r| r.map(|r| r.deadband_error).unwrap_or_default())
            .collect();
        let mut all = CodecError::default();
        for e in &per_site {
            all.merge(e);
        }
        Self {
            contact_within_jnd: all.contact_within_jnd_share().unwrap_or(1.0),
            contact_p99_jnd: all.contact_p99_jnd().unwrap_or(0.0),
            within_jnd: all.within_jnd_share().unwrap_or(1.0),
            tool_contact_within_jnd: per_site
                .iter()
                .map(|e| e.contact_within_jnd_share().unwrap_or(1.0))
                .collect(),
            tool_position_mm: per_site
                .iter()
                .map(|e| {
                    let (p99, max) = e.position_p99_max_m().unwrap_or((0.0, 0.0));
                    [1e3 * p99, 1e3 * max]
                })
                .collect(),
        }
    }
}

/// The codec's goal: at least this share of the contact ticks within one JND of the source's
/// force, at every delay from 0 to 300 ms.
pub const CODEC_GOAL: f64 = 0.99;

/// One delay's runs.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// The scenario's seed.
    pub seed: u64,
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
    /// The codec's own measure: the decoded input against its source, in the deadband run.
    pub codec: Codec,
    /// The users' hands as the scenario has them, reacting to what they feel.
    pub closed_loop: ForceErrors,
    /// Every site's tool replayed from the full-rate run's servo ticks in every run (the full-rate
    /// one too): the same hands, which do not react, so what differs is the world alone.
    pub replayed: ForceErrors,
}

/// The share of `e` (JND) within 1 and its 99th percentile, with `normal_agrees` of the `beyond`
/// ticks beyond 1.
fn within_and_p99(e: Vec<f64>, (beyond, normal_agrees): (usize, usize)) -> ForceError {
    if e.is_empty() {
        return ForceError {
            within_jnd: 0.0,
            p99_jnd: 0.0,
            normal_agrees: 0.0,
        };
    }
    let within = e.iter().filter(|&&x| x <= 1.0).count() as f64 / e.len() as f64;
    ForceError {
        within_jnd: within,
        p99_jnd: crate::simbench::quantile(e, 0.99),
        normal_agrees: normal_agrees as f64 / beyond.max(1) as f64,
    }
}

/// How far `b`'s displayed force is from `a`'s, JND of `a`'s, and whether both tools touch with
/// the normal force's elastic part (`stiffness` × the penetration, N/m × m) within one JND of
/// `a`'s.
fn tick_error(a: &ServoTick, b: &ServoTick, stiffness: f64) -> (f64, bool) {
    let (na, nb) = (stiffness * a.depth_m, stiffness * b.depth_m);
    let touch = a.depth_m > 0.0 && b.depth_m > 0.0;
    (
        (b.f_desired - a.f_desired).norm() / perception::force_jnd_n(a.f_desired.norm()),
        touch && (na - nb).abs() <= perception::force_jnd_n(na),
    )
}

/// The displayed force's difference between `db` and `full`, servo tick by servo tick (the two
/// runs' sites tick at the same instants), in JND ([`perception::force_jnd_n`] of the full-rate
/// run's force: the one just-noticeable difference every figure of the project counts in, not
/// the deadband's own parameter).
fn force_error_jnd(full: &RunResult, db: &RunResult, stiffness: f64) -> ForceError {
    let (mut out, mut beyond, mut normal_agrees) = (Vec::new(), 0, 0);
    for (a, b) in full.servo_ticks.iter().zip(&db.servo_ticks) {
        debug_assert_eq!(a.len(), b.len(), "the same servo ticks");
        for (ta, tb) in a.iter().zip(b) {
            debug_assert_eq!(ta.t_s, tb.t_s, "the same servo ticks");
            let (e, normal) = tick_error(ta, tb, stiffness);
            if e > 1.0 {
                beyond += 1;
                normal_agrees += usize::from(normal);
            }
            out.push(e);
        }
    }
    within_and_p99(out, (beyond, normal_agrees))
}

/// Every site's hand replayed from `run`'s servo ticks (its tool's position at each; between
/// them, as at the physics ticks between, the hand moves on a straight line).
///
/// # Errors
/// `run` kept no servo ticks for a site of `sc` (the runs would not be replayed).
fn hands_of(sc: &Scenario, run: &RunResult) -> anyhow::Result<Vec<Trajectory>> {
    anyhow::ensure!(
        run.servo_ticks.len() == sc.site.len() && run.servo_ticks.iter().all(|t| !t.is_empty()),
        "the full-rate run kept servo ticks for {} of {} sites",
        run.servo_ticks.iter().filter(|t| !t.is_empty()).count(),
        sc.site.len()
    );
    run.servo_ticks
        .iter()
        .enumerate()
        .map(|(i, ticks)| {
            Trajectory::new(ticks.iter().map(|k| (k.t_s, k.tool_pos)))
                .with_context(|| format!("site {i}'s servo ticks as a hand"))
        })
        .collect()
}

/// `sc` with its sites' hands replayed from `hands`.
fn with_hands(sc: &Scenario, hands: &[Trajectory]) -> Scenario {
    let mut sc = sc.clone();
    for (spec, hand) in sc.site.iter_mut().zip(hands) {
        spec.hand_trajectory = Some(hand.clone());
    }
    sc
}

/// One delay's scenarios: full rate, through the deadband, through the least band, reseeded.
type Quad = [Scenario; 4];

/// The four runs of `q`, each through the stations' wire, keeping servo ticks.
fn run_quad(q: &Quad) -> [RunResult; 4] {
    let mode = Mode::Distributed(MethodName::Timewarp);
    let wire = &coop_transport::wire::StationWire;
    q.each_ref()
        .map(|sc| sim::run_keeping_servo_ticks(sc, mode, &mut |_| {}, wire))
}

/// The last three of `r` against the first (`stiffness`: the tool contact's, N/m).
fn errors(r: &[RunResult; 4], stiffness: f64) -> ForceErrors {
    ForceErrors {
        band: force_error_jnd(&r[0], &r[1], stiffness),
        baseline: force_error_jnd(&r[0], &r[2], stiffness),
        reseeded: force_error_jnd(&r[0], &r[3], stiffness),
    }
}

/// Runs the comparisons at each of `delays_ms` (the scenario's deadband settings, turned on).
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
        jobs.push((d, [full, db, least, reseeded]));
    }
    let reference = sim::run(base, Mode::Reference, &mut |_| {});
    let closed = par_map(&jobs, |(_, q)| run_quad(q));
    // The same four, every hand replayed from the full-rate run's.
    let mut replays = Vec::with_capacity(jobs.len());
    for ((_, q), r) in jobs.iter().zip(&closed) {
        let hands = hands_of(&q[0], &r[0])?;
        replays.push(q.each_ref().map(|sc| with_hands(sc, &hands)));
    }
    let replayed = par_map(&replays, run_quad);
    Ok(jobs
        .iter()
        .zip(closed.iter().zip(&replayed))
        .map(|((delay_ms, _), (c, r))| {
            let (ma, mb) = (
                metrics::compute(base, &c[0], &reference),
                metrics::compute(base, &c[1], &reference),
            );
            let (ticks, samples) = c[1].rollback.iter().flatten().fold((0, 0), |(t, s), r| {
                (t + r.deadband_ticks, s + r.deadband_samples)
            });
            Row {
                seed: base.seed,
                delay_ms: *delay_ms,
                sent_share: samples as f64 / ticks.max(1) as f64,
                kbit_s: [
                    crate::figures::busiest_sent_kbit_s(&ma, base.duration_s),
                    crate::figures::busiest_sent_kbit_s(&mb, base.duration_s),
                ],
                phases: [ma.phases_passed, mb.phases_passed],
                phases_total: mb.phases_total,
                hash_mismatches: mb.hash_mismatches,
                codec: Codec::of(&c[1]),
                closed_loop: errors(c, base.contact.stiffness_n_per_m),
                replayed: errors(r, base.contact.stiffness_n_per_m),
            }
        })
        .collect())
}

/// Prints the tables (or JSON) for `sc` at `delays_ms`: with its own seed, or with each of seeds
/// 1 to `seeds` and then the range of each figure over them.
///
/// # Errors
/// As [`rows`].
pub fn main(
    sc: &Scenario,
    delays_ms: &[f64],
    seeds: Option<u64>,
    json: bool,
) -> anyhow::Result<()> {
    let seeds: Vec<u64> = seeds.map_or(vec![sc.seed], |n| (1..=n).collect());
    let mut all = Vec::with_capacity(seeds.len());
    for &seed in &seeds {
        let sc = Scenario { seed, ..sc.clone() };
        let rows = rows(&sc, delays_ms).with_context(|| format!("sim deadband, seed {seed}"))?;
        all.push(rows);
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&all.concat())?);
        return Ok(());
    }
    let d = sc.timewarp.deadband;
    for (rows, seed) in all.iter().zip(&seeds) {
        println!(
            "# scenario {} (seed {seed}, {} s): timewarp, every tick's position sent vs a perceptual deadband (Weber {:.4} of the contact force, floor {:.4} N, near {} m, free space {} m)",
            sc.name, sc.duration_s, d.weber_fraction, d.floor_n, d.near_m, d.free_space_m
        );
        print_seed(rows);
        print_codec(rows);
    }
    if all.len() > 1 {
        print_range(&all, &seeds);
    }
    print_codec_goal(&all);
    Ok(())
}

/// One seed's codec table: the decoded input against its source.
fn print_codec(rows: &[Row]) {
    println!("# the codec's own measure, deadband run (hands reacting): every physics tick, each site's tool's contact force rendered from the same world state at the position decoded (held) and at the one measured (the source)");
    println!(
        "{:>8}{:>12}{:>10}{:>12}   {:<28}per tool: position decoded-measured",
        "delay", "contact", "contact", "all ticks", "per tool: contact"
    );
    println!(
        "{:>8}{:>12}{:>10}{:>12}   {:<28}p99/max mm",
        "ms", "<=1 JND", "p99 JND", "<=1 JND", "<=1 JND"
    );
    for r in rows {
        let c = &r.codec;
        let tools: Vec<String> = c
            .tool_contact_within_jnd
            .iter()
            .map(|x| format!("{:.2}%", 100.0 * x))
            .collect();
        let pos: Vec<String> = c
            .tool_position_mm
            .iter()
            .map(|[p99, max]| format!("{p99:.3}/{max:.3}"))
            .collect();
        println!(
            "{:>8.0}{:>11.2}%{:>10.2}{:>11.2}%   {:<28}{}",
            r.delay_ms,
            100.0 * c.contact_within_jnd,
            c.contact_p99_jnd,
            100.0 * c.within_jnd,
            tools.join(" "),
            pos.join(" ")
        );
    }
    println!("# contact = ticks in which the tool touched an object in either rendering (out of contact both forces are zero: all ticks counts those too); JND of the source's force (7 %, at least 0.05 N); p99 at most 12.5 % high (a histogram bin's edge); the run-vs-run columns above compare two runs, which the friction model's stick points part for the rest of a grasp after any perturbation (its chaos), not the codec's error");
}

/// Each delay's codec figure over every seed, and whether the goal holds.
fn print_codec_goal(all: &[Vec<Row>]) {
    let Some(first) = all.first() else {
        return;
    };
    println!(
        "# the codec's goal: at least {:.0} % of every site's contact ticks within one JND of the source's force, at every delay",
        100.0 * CODEC_GOAL
    );
    println!(
        "{:>8}{:>18}{:>14}{:>20}{:>8}",
        "delay", "contact <=1 JND", "p99 JND", "position max mm", "goal"
    );
    println!(
        "{:>8}{:>18}{:>14}{:>20}",
        "ms", "lowest", "highest", "highest"
    );
    let mut met = true;
    for (k, row) in first.iter().enumerate() {
        let at = all.iter().map(|rows| &rows[k].codec);
        let lowest = at.clone().map(|c| c.contact_within_jnd).fold(1.0, f64::min);
        let p99 = at.clone().map(|c| c.contact_p99_jnd).fold(0.0, f64::max);
        let pos = at
            .flat_map(|c| c.tool_position_mm.iter().map(|p| p[1]))
            .fold(0.0, f64::max);
        let ok = lowest >= CODEC_GOAL;
        met &= ok;
        println!(
            "{:>8.0}{:>17.2}%{:>14.2}{:>20.3}{:>8}",
            row.delay_ms,
            100.0 * lowest,
            p99,
            pos,
            if ok { "met" } else { "MISSED" }
        );
    }
    println!(
        "# goal {}",
        if met {
            "met at every delay"
        } else {
            "MISSED at a delay above"
        }
    );
}

/// One seed's two tables.
fn print_seed(rows: &[Row]) {
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
        "{:>8}{:>10}{:>14}{:>14}{:>12}{:>12}{:>11}{}",
        "ms", "of ticks", "", "", "full", "band", "mismatch", ERROR_UNITS
    );
    for r in rows {
        println!(
            "{:>8.0}{:>9.1}%{:>14.1}{:>14.1}{:>12}{:>12}{:>11}{}",
            r.delay_ms,
            100.0 * r.sent_share,
            r.kbit_s[0],
            r.kbit_s[1],
            format!("{}/{}", r.phases[0], r.phases_total),
            format!("{}/{}", r.phases[1], r.phases_total),
            r.hash_mismatches,
            error_cells(&r.closed_loop)
        );
    }
    println!("# sent = own ticks whose position left the band and was sent (every site); kbit/s = payload the busiest site puts; force = each site's displayed force (F_h, every servo tick) against the full-rate run's at the same tick, in JND (7 % of the full-rate force, at least 0.05 N); baseline = the same against a run through a band of 1.5 quanta (0.015 mm), the least change the wire can express; reseeded = the full-rate run with the next seed (other draws of sensor noise and jitter), against the full-rate run: how far two runs of the task part with no codec at all");
    println!("# the same hands: every run again (the full-rate one too) with each site's tool replayed from the full-rate run's servo ticks, so the hands do not react to what they feel and only the world differs");
    println!(
        "{:>8}{:>12}{:>10}{:>12}{:>10}{:>12}{:>10}{:>16}",
        "delay", "force", "force", "baseline", "baseline", "reseeded", "reseeded", "force > 1 JND"
    );
    println!("{:>8}{}{:>16}", "ms", ERROR_UNITS, "normal agrees");
    for r in rows {
        println!(
            "{:>8.0}{}{:>15.0}%",
            r.delay_ms,
            error_cells(&r.replayed),
            100.0 * r.replayed.band.normal_agrees
        );
    }
    println!("# reseeded here: the next seed's draws of the delay's jitter alone (a replayed hand has no force sensor); normal agrees = of the deadband run's ticks beyond one JND, those at which both runs' tools press equally deep (stiffness x penetration within one JND of the full-rate run's): the rest, mostly the stuck friction force, made the difference");
}

/// Each delay's figures over every seed, lowest to highest.
fn print_range(all: &[Vec<Row>], seeds: &[u64]) {
    println!(
        "# over seeds {}-{}: each figure's lowest and highest (force: share of servo ticks within one JND of the full-rate run)",
        seeds[0],
        seeds[seeds.len() - 1]
    );
    println!(
        "{:>8}{:>14}{:>14}{:>9}{:>7}{:>17}{:>17}{:>17}{:>17}{:>17}{:>17}{:>16}",
        "delay",
        "sent",
        "kbit/s band",
        "phases",
        "hash",
        "force",
        "baseline",
        "reseeded",
        "force",
        "baseline",
        "reseeded",
        "force > 1 JND"
    );
    println!(
        "{:>8}{:>14}{:>14}{:>9}{:>7}{:>17}{:>17}{:>17}{:>17}{:>17}{:>17}{:>16}",
        "ms",
        "of ticks",
        "",
        "band",
        "mism.",
        "reacting",
        "reacting",
        "reacting",
        "replayed",
        "replayed",
        "replayed",
        "normal agrees"
    );
    for (k, first) in all[0].iter().enumerate() {
        let at: Vec<&Row> = all.iter().map(|rows| &rows[k]).collect();
        let range = |f: &dyn Fn(&Row) -> f64, scale: f64, unit: &str| {
            let (lo, hi) = at
                .iter()
                .map(|r| f(r) * scale)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                    (lo.min(x), hi.max(x))
                });
            format!("{lo:.1}-{hi:.1}{unit}")
        };
        let pct = |f: &dyn Fn(&Row) -> f64| range(f, 100.0, " %");
        let phases = at.iter().map(|r| r.phases[1]).min().unwrap_or(0);
        let mismatches = at.iter().map(|r| r.hash_mismatches).max().unwrap_or(0);
        println!(
            "{:>8.0}{:>14}{:>14}{:>9}{:>7}{:>17}{:>17}{:>17}{:>17}{:>17}{:>17}{:>16}",
            first.delay_ms,
            pct(&|r| r.sent_share),
            range(&|r| r.kbit_s[1], 1.0, ""),
            format!("{phases}/{}", first.phases_total),
            mismatches,
            pct(&|r| r.closed_loop.band.within_jnd),
            pct(&|r| r.closed_loop.baseline.within_jnd),
            pct(&|r| r.closed_loop.reseeded.within_jnd),
            pct(&|r| r.replayed.band.within_jnd),
            pct(&|r| r.replayed.baseline.within_jnd),
            pct(&|r| r.replayed.reseeded.within_jnd),
            range(&|r| r.replayed.band.normal_agrees, 100.0, " %"),
        );
    }
    println!("# phases band = the fewest phases any seed's deadband run passed; hash mism. = the most hash mismatches of any; normal agrees = of the deadband run's ticks beyond one JND with the hands replayed, those at which both runs' tools press equally deep (the rest, mostly the stuck friction force, made the difference)");
}

/// The second header line of the three comparisons' columns.
const ERROR_UNITS: &str = "     <=1 JND   p99 JND     <=1 JND   p99 JND     <=1 JND   p99 JND";

/// The three comparisons' cells.
fn error_cells(e: &ForceErrors) -> String {
    [e.band, e.baseline, e.reseeded]
        .iter()
        .map(|x| format!("{:>11.2}%{:>10.2}", 100.0 * x.within_jnd, x.p99_jnd))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use coop_model::body::Vec3;

    fn tick(f: [f64; 3], depth_m: f64) -> ServoTick {
        ServoTick {
            t_s: 0.0,
            tool_pos: Vec3::zeros(),
            f_desired: Vec3::from(f),
            depth_m,
        }
    }

    #[test]
    fn a_difference_is_the_friction_s_when_the_normal_forces_agree() {
        let k = 800.0;
        // 3 N pressed 3.75 mm deep: one JND is 0.21 N.
        let a = tick([-3.0, 0.0, 0.0], 3.75e-3);
        // Pressed as deep, 0.4 N more stuck tangential force: 1.9 JND, and the press agrees.
        let (e, normal) = tick_error(&a, &tick([-3.0, 0.4, 0.0], 3.75e-3), k);
        assert!(e > 1.9 && e < 2.0 && normal, "{e} {normal}");
        // 0.5 mm deeper: 0.4 N more normal force, beyond a JND of it.
        let (e, normal) = tick_error(&a, &tick([-3.4, 0.0, 0.0], 4.25e-3), k);
        assert!(e > 1.0 && !normal, "{e} {normal}");
        // 0.1 mm deeper (0.08 N, within the normal force's JND) with 0.3 N more along the
        // surface: agrees.
        let (e, normal) = tick_error(&a, &tick([-3.08, 0.3, 0.0], 3.85e-3), k);
        assert!(e > 1.0 && normal, "{e} {normal}");
        // The same force error with the tool touching nothing in one run: no press to agree.
        let (e, normal) = tick_error(&a, &tick([-3.0, 0.4, 0.0], 0.0), k);
        assert!(e > 1.0 && !normal, "{e} {normal}");
    }
}
