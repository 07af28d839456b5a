//! `sim sweep`: every method × constant delay × seed on one scenario, one row each — how the methods
//! hold up under delay during cooperative contact.
//!
//! At a delay `d` the network's delay is constant (`delay_min_ms = delay_max_ms = d`) with the
//! scenario's jitter, or none at 0 ms; seeds run 1 to N, overriding the scenario's. The reference
//! run has no network, so one per seed serves every method and delay. Runs are spread over the
//! machine's cores, the rows always come out in the same order (method, delay, seed as given), and
//! every run is deterministic, so the same command prints the same bytes.

pub mod completion;

use std::path::Path;

use anyhow::{bail, Context};
use coop_model::metrics::{self, Metrics};
use coop_model::scenario::{MethodName, Scenario};
use coop_model::sim::{self, Mode, RunResult};
use coop_rt::sync::{AtomicU64, Ordering};
use serde::Serialize;

/// The delays swept when none are given, ms.
pub const DEFAULT_DELAYS_MS: &str = "0,25,50,100,150,200,300,500";

/// One run's figures.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Row {
    /// Method name.
    pub method: String,
    /// Constant one-way delay, ms.
    pub delay_ms: f64,
    /// Seed.
    pub seed: u64,
    /// Task phases that happened, summed over sites.
    pub phases_passed: usize,
    /// Task phases checked, summed over sites.
    pub phases_total: usize,
    /// The phases that did not happen, as `site:phase`, in site and phase order.
    pub phases_failed: Vec<String>,
    /// Largest divergence while two or more users touch, m (null: they never do).
    pub co_contact_divergence_max_m: f64,
    /// RMS divergence while two or more users touch, m (null: they never do).
    pub co_contact_divergence_rms_m: f64,
    /// RMS distance from the reference object, worst site, m.
    pub error_vs_reference_rms_m: f64,
    /// Largest displayed-force step per servo tick, any site, N.
    pub max_force_step_n: f64,
    /// Servo ticks whose displayed-force step exceeded the JND, all sites.
    pub force_steps_over_jnd: u64,
    /// Energy corrections gave the copies beyond the work of the corrected history's forces, all
    /// sites, J: what no user and no wall put in.
    pub correction_energy_j: f64,
    /// Mechanical-energy change at corrections, all sites, J (a remote push learned late counts).
    pub correction_energy_gross_j: f64,
    /// The largest displayed-force step beyond the displayed object's own contact change (the
    /// display's step limiter bounds it), any site, N (null: the display stages are off).
    pub max_correction_force_step_n: f64,
    /// Servo ticks at which a display's step limiter held the force back, all sites.
    pub display_limited_ticks: u64,
    /// The most energy a display's deviation from the simulated contact had injected into its
    /// user, any site, J (≤ 0: passive; null: the display stages are off).
    pub display_energy_max_j: f64,
    /// Corrections the no-gain bound scaled back, all sites.
    pub bounded_corrections: usize,
    /// Energy the no-gain bound took out of corrections, all sites, J.
    pub bounded_energy_j: f64,
    /// The most a copy's energy exceeded its start beyond all users' positive work, J (≤ 0: passive).
    pub energy_beyond_users_j: f64,
    /// The farthest a copy's centre was from the reference object, m.
    pub farthest_from_reference_m: f64,
    /// Rollbacks per simulated second, busiest site.
    pub rollbacks_per_s: f64,
    /// Re-simulated ticks per simulated second, busiest site.
    pub resimulated_ticks_per_s: f64,
    /// 99th percentile of rollback depth, all sites, ticks.
    pub rollback_depth_p99_ticks: u64,
    /// Confirmed-state hash mismatches, all sites.
    pub hash_mismatches: u64,
    /// Confirmed states adopted after they differed, all sites.
    pub adopted_states: u64,
    /// Contact the users were never shown live though the confirmed history has it, all sites, ms.
    pub unfelt_contact_ms: f64,
    /// Contact the users were shown live that the confirmed history took back, all sites, ms.
    pub phantom_contact_ms: f64,
    /// Missed contacts replayed to the users from the confirmed history, all sites.
    pub replays: u64,
    /// The largest local lag of any site's own tool, ms (`timewarp`).
    pub local_lag_max_ms: f64,
    /// Payload the busiest site puts, kbit/s ([`crate::figures::sent_kbit_s`]).
    pub sent_kbit_s: f64,
    /// The live task done at every site (null: the scenario has no `[task]`).
    pub task_done: Option<bool>,
    /// When the last site saw the task done, s: the trial's completion time (NaN: not done at
    /// every site).
    pub completion_s: f64,
    /// The sites where it was not done, as `site:outcome` (`site:failed:fail[0]`, ...).
    pub task_missed: Vec<String>,
    /// The most contact one site was shown live that the confirmed history took back, ms.
    pub phantom_contact_site_max_ms: f64,
    /// The largest normal force a participant gripped with, any site, N (NaN: no grip).
    pub grip_peak_n: f64,
    /// Slips the participants' grips answered, all sites.
    pub slips: u64,
}

impl Row {
    fn new(delay_ms: f64, seed: u64, m: &Metrics, duration_s: f64, has_task: bool) -> Self {
        let (done, completion) = crate::figures::task_completion(m);
        let task_done = has_task.then_some(done);
        Self {
            sent_kbit_s: crate::figures::busiest_sent_kbit_s(m, duration_s),
            method: m.method.clone(),
            delay_ms,
            seed,
            phases_passed: m.phases_passed,
            phases_total: m.phases_total,
            phases_failed: m
                .sites
                .iter()
                .flat_map(|s| {
                    s.phases
                        .iter()
                        .filter(|(_, ok)| !ok)
                        .map(move |(p, _)| format!("{}:{p}", s.name))
                })
                .collect(),
            co_contact_divergence_max_m: m.co_contact_divergence_max_m,
            co_contact_divergence_rms_m: m.co_contact_divergence_rms_m,
            error_vs_reference_rms_m: m
                .sites
                .iter()
                .map(|s| s.error_vs_reference_rms_m)
                .fold(0.0, f64::max),
            max_force_step_n: m.max_force_step_n,
            force_steps_over_jnd: m.force_steps_over_jnd,
            correction_energy_j: m.correction_energy_j,
            correction_energy_gross_j: m.correction_energy_gross_j,
            max_correction_force_step_n: m.max_correction_force_step_n,
            display_limited_ticks: m.display_limited_ticks,
            display_energy_max_j: m.display_energy_max_j,
            bounded_corrections: m.bounded_corrections,
            bounded_energy_j: m.bounded_energy_j,
            energy_beyond_users_j: m.energy_beyond_users_j,
            farthest_from_reference_m: m.farthest_from_reference_m,
            rollbacks_per_s: m.rollbacks_per_s,
            resimulated_ticks_per_s: m.resimulated_ticks_per_s,
            rollback_depth_p99_ticks: m.rollback_depth_p99_ticks,
            hash_mismatches: m.hash_mismatches,
            adopted_states: m.adopted_states,
            unfelt_contact_ms: m.unfelt_contact_ms,
            phantom_contact_ms: m.phantom_contact_ms,
            replays: m.replays,
            local_lag_max_ms: m.local_lag_max_ms,
            task_done,
            completion_s: if task_done == Some(true) {
                completion
            } else {
                f64::NAN
            },
            task_missed: m
                .sites
                .iter()
                .filter_map(|s| {
                    let t = s.task.as_ref()?;
                    (has_task && t.outcome != "done").then(|| {
                        if t.failed_by.is_empty() {
                            format!("{}:{}", s.name, t.outcome)
                        } else {
                            format!("{}:{}:{}", s.name, t.outcome, t.failed_by)
                        }
                    })
                })
                .collect(),
            phantom_contact_site_max_ms: m
                .sites
                .iter()
                .map(|s| s.phantom_contact_ms)
                .fold(0.0, f64::max),
            grip_peak_n: m
                .sites
                .iter()
                .filter_map(|s| s.task.as_ref().map(|t| t.grip_peak_n))
                .filter(|v| !v.is_nan())
                .fold(f64::NAN, f64::max),
            slips: m
                .sites
                .iter()
                .filter_map(|s| s.task.as_ref().map(|t| t.slips))
                .sum(),
        }
    }
}

/// `base` with a constant delay of `delay_ms` (the scenario's jitter, none at 0) and `seed`,
/// checked.
///
/// # Errors
/// The delay is negative or not a number, or makes the scenario invalid (e.g. above 10 s).
pub fn scenario_at(base: &Scenario, delay_ms: f64, seed: u64) -> anyhow::Result<Scenario> {
    if !(delay_ms.is_finite() && delay_ms >= 0.0) {
        bail!("delay {delay_ms} ms: a delay must be a number of ms, 0 or more");
    }
    let mut sc = base.clone();
    sc.seed = seed;
    sc.network.delay_min_ms = delay_ms;
    sc.network.delay_max_ms = delay_ms;
    if delay_ms == 0.0 {
        sc.network.jitter_ms = 0.0;
    }
    sc.validate()
        .map_err(|e| anyhow::anyhow!("{e}"))
        .with_context(|| format!("scenario {} at a delay of {delay_ms} ms", base.name))?;
    Ok(sc)
}

/// `f` over `items` on up to every core; results in the order of `items`.
pub fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(items.len())
        .max(1);
    let next = AtomicU64::new(0);
    let mut out: Vec<Option<R>> = (0..items.len()).map(|_| None).collect();
    std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let k = next.fetch_add(1, Ordering::Relaxed) as usize;
                        let Some(item) = items.get(k) else { break };
                        mine.push((k, f(item)));
                    }
                    mine
                })
            })
            .collect();
        for w in workers {
            match w.join() {
                Ok(done) => {
                    for (k, r) in done {
                        out[k] = Some(r);
                    }
                }
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
    });
    out.into_iter()
        .map(|r| r.expect("every item was taken by a worker"))
        .collect()
}

/// Runs the grid: rows by method, then delay, then seed (1 to `seeds`).
///
/// # Errors
/// A delay is negative or makes the scenario invalid; `seeds` is 0; no method or delay.
pub fn sweep(
    base: &Scenario,
    delays_ms: &[f64],
    seeds: u64,
    methods: &[MethodName],
) -> anyhow::Result<Vec<Row>> {
    if seeds == 0 {
        bail!("--seeds 0: at least one seed is needed");
    }
    if delays_ms.is_empty() {
        bail!("--delays-ms: at least one delay is needed");
    }
    if methods.is_empty() {
        bail!("--methods: at least one method is needed");
    }
    // Every scenario is checked before anything runs.
    let mut jobs = Vec::new();
    for &m in methods {
        for &d in delays_ms {
            for seed in 1..=seeds {
                jobs.push((m, d, seed, scenario_at(base, d, seed)?));
            }
        }
    }
    let refs: Vec<(Scenario, RunResult)> = par_map(
        &(1..=seeds).collect::<Vec<_>>(),
        |&seed| -> (Scenario, RunResult) {
            let mut sc = base.clone();
            sc.seed = seed;
            let r = sim::run(&sc, Mode::Reference, &mut |_| {});
            (sc, r)
        },
    );
    Ok(par_map(&jobs, |(m, d, seed, sc)| {
        let r = sim::run_wired(
            sc,
            Mode::Distributed(*m),
            &mut |_| {},
            &coop_transport::wire::StationWire,
        );
        let reference = &refs[(*seed - 1) as usize].1;
        Row::new(
            *d,
            *seed,
            &metrics::compute(sc, &r, reference),
            sc.duration_s,
            sc.task.done.is_some(),
        )
    }))
}

fn cell(v: f64, width: usize, prec: usize) -> String {
    format!("{:>width$}", crate::figures::or_dash(v, prec))
}

/// The line above a table: what ran (`what` of scenario …), its length, sites, delays and seeds.
fn heading(what: &str, sc: &Scenario, seeds: u64) -> String {
    format!(
        "# {what} of scenario {} ({} s, {} sites): constant delay, jitter {} ms (none at 0), seeds 1..={seeds}",
        sc.name,
        sc.duration_s,
        sc.site.len(),
        sc.network.jitter_ms
    )
}

/// The rows as a table.
pub fn table(sc: &Scenario, seeds: u64, rows: &[Row]) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(out, "{}", heading("sweep", sc, seeds));
    let _ = writeln!(
        out,
        "{:<10}{:>7}{:>5}{:>8}{:>8}{:>10}{:>10}{:>12}{:>9}{:>7}{:>9}{:>9}{:>12}{:>8}{:>9}{:>10}{:>6}{:>14}{:>9}  missed phases",
        "method",
        "delay",
        "seed",
        "phases",
        "task",
        "co-div",
        "co-div",
        "err ref",
        "f step",
        ">JND",
        "c step",
        "E disp",
        "E corr",
        "bound",
        "rollback",
        "depth",
        "hash",
        "unfelt/phant",
        "sent"
    );
    let _ = writeln!(
        out,
        "{:<10}{:>7}{:>5}{:>8}{:>8}{:>10}{:>10}{:>12}{:>9}{:>7}{:>9}{:>9}{:>12}{:>8}{:>9}{:>10}{:>6}{:>14}{:>9}",
        "",
        "ms",
        "",
        "",
        "s",
        "max mm",
        "rms mm",
        "rms mm",
        "max N",
        "steps",
        "max N",
        "mJ",
        "mJ",
        "count",
        "per s",
        "p99 ticks",
        "miss",
        "ms",
        "kbit/s"
    );
    for r in rows {
        let _ = writeln!(
            out,
            "{:<10}{:>7}{:>5}{:>8}{:>8}{} {}{}{}{:>7}{}{}{}{:>8}{:>9.1}{:>10}{:>6}{:>14}{:>9.0}  {}",
            r.method,
            r.delay_ms,
            r.seed,
            format!("{}/{}", r.phases_passed, r.phases_total),
            match r.task_done {
                None => "-".to_owned(),
                Some(false) => "miss".to_owned(),
                Some(true) => format!("{:.2}", r.completion_s),
            },
            cell(r.co_contact_divergence_max_m * 1e3, 10, 2),
            cell(r.co_contact_divergence_rms_m * 1e3, 9, 2),
            cell(r.error_vs_reference_rms_m * 1e3, 12, 2),
            cell(r.max_force_step_n, 9, 3),
            r.force_steps_over_jnd,
            cell(r.max_correction_force_step_n, 9, 3),
            cell(r.display_energy_max_j * 1e3, 9, 3),
            cell(r.correction_energy_j * 1e3, 12, 2),
            r.bounded_corrections,
            r.rollbacks_per_s,
            r.rollback_depth_p99_ticks,
            r.hash_mismatches,
            format!("{:.0}/{:.0}", r.unfelt_contact_ms, r.phantom_contact_ms),
            r.sent_kbit_s,
            if r.phases_failed.is_empty() && r.task_missed.is_empty() {
                "-".to_string()
            } else {
                r.phases_failed
                    .iter()
                    .cloned()
                    .chain(r.task_missed.iter().map(|t| format!("task:{t}")))
                    .collect::<Vec<_>>()
                    .join(" ")
            }
        );
    }
    let _ = writeln!(
        out,
        "# task = when the last site saw the live task done, s ('miss': not done at every site; '-': no [task]); co-div = largest/RMS distance between the sites' copies while two or more users touch ('-': never); err ref = worst site; f step = largest change of a displayed force per servo tick; >JND = servo ticks changing it by more than {:.0} % (at least {} N); c step = largest step beyond the displayed object's own contact change (what the display's step limiter bounds); E disp = most energy the display's deviation from the simulated contact put into a user (passivity observer; <= 0 passive); E corr = energy corrections gave the copies beyond what the forces of the corrected history did (what no user or wall put in; a remote push learned late is the pushing user's work, counted in --json's correction_energy_gross_j); bound = corrections the no-gain bound scaled back; rollback per s = busiest site; depth p99 = all sites' rollbacks; unfelt/phant = confirmed contact time a user was never shown live / contact time shown live that the confirmed history took back, all sites (timewarp); sent = payload the busiest site puts (reports and tool tracks at their encoded sizes, each put once); missed phases = site:phase, and task:site:outcome where the task was not done",
        metrics::FORCE_JND_FRACTION * 100.0,
        metrics::FORCE_JND_FLOOR_N
    );
    out
}

/// Per method, the mean over seeds of phases passed and of co-contact divergence (mm) at each delay.
pub fn per_method_means(rows: &[Row]) -> Vec<crate::plots::SweepLine> {
    completion::first_seen(rows.iter().map(|r| r.method.as_str()))
        .into_iter()
        .map(|m| {
            let mut delays: Vec<f64> = Vec::new();
            for r in rows.iter().filter(|r| r.method == m) {
                if !delays.contains(&r.delay_ms) {
                    delays.push(r.delay_ms);
                }
            }
            delays.sort_by(f64::total_cmp);
            let mean = |d: f64, f: &dyn Fn(&Row) -> f64| {
                let v: Vec<f64> = rows
                    .iter()
                    .filter(|r| r.method == m && r.delay_ms == d)
                    .map(f)
                    .filter(|x| !x.is_nan())
                    .collect();
                (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
            };
            crate::plots::SweepLine {
                label: m.to_owned(),
                phases: delays
                    .iter()
                    .filter_map(|&d| mean(d, &|r| r.phases_passed as f64).map(|y| (d, y)))
                    .collect(),
                co_div_mm: delays
                    .iter()
                    .filter_map(|&d| {
                        mean(d, &|r| r.co_contact_divergence_max_m * 1e3).map(|y| (d, y))
                    })
                    .collect(),
            }
        })
        .collect()
}

/// What `sim sweep` prints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Print {
    /// A row per run, and the live task's summary when the scenario has one.
    Table,
    /// The live task's summary alone.
    Summary,
    /// Everything as JSON.
    Json,
}

/// Runs `sim sweep` and prints its table, summary or JSON; with `out`, writes `sweep.json` and
/// the plots.
///
/// # Errors
/// As [`sweep`]; a summary asked of a scenario without a `[task]`; the output directory cannot
/// be written.
pub fn main(
    base: &Scenario,
    delays_ms: &[f64],
    seeds: u64,
    methods: &[MethodName],
    print: Print,
    out: Option<&Path>,
) -> anyhow::Result<()> {
    if print == Print::Summary && base.task.done.is_none() {
        bail!(
            "--summary: scenario {} has no [task] (no done condition) to summarize; drop --summary for a row per run",
            base.name
        );
    }
    let rows = sweep(base, delays_ms, seeds, methods)?;
    let cells = if base.task.done.is_some() {
        completion::cells(&rows)
    } else {
        Vec::new()
    };
    let doc = serde_json::json!({
        "scenario": base.name,
        "seeds": seeds,
        "jitter_ms": base.network.jitter_ms,
        "rows": rows,
        "task": cells,
    });
    match print {
        Print::Json => println!("{}", serde_json::to_string_pretty(&doc)?),
        Print::Table => {
            print!("{}", table(base, seeds, &rows));
            if !cells.is_empty() {
                print!("{}", completion::table(&cells));
            }
        }
        Print::Summary => {
            println!("{}", heading("live task", base, seeds));
            print!("{}", completion::table(&cells));
        }
    }
    if let Some(dir) = out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let path = dir.join("sweep.json");
        std::fs::write(&path, serde_json::to_string_pretty(&doc)? + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
        let total = rows.first().map_or(0, |r| r.phases_total);
        crate::plots::sweep(
            dir,
            &format!(
                "scenario {}: phases and co-contact divergence against constant delay (mean over {seeds} seed{})",
                base.name,
                if seeds == 1 { "" } else { "s" }
            ),
            total,
            &per_method_means(&rows),
        )?;
        if !cells.is_empty() {
            crate::plots::task(
                dir,
                &format!(
                    "scenario {}: the live task against constant delay ({seeds} participant draw{} per delay)",
                    base.name,
                    if seeds == 1 { "" } else { "s" }
                ),
                &completion::lines(&cells),
            )?;
            eprintln!("# task.png and task.svg in {}", dir.display());
        }
        eprintln!("# sweep.json, sweep.png and sweep.svg in {}", dir.display());
    }
    Ok(())
}
