//! `sim`: runs the deterministic multi-site simulator on a scenario file.
//!
//! - `sim run SCENARIO --out DIR`: one method; writes the trace, adoptions, metrics, the
//!   Fig. 9–12 style plots, and `session.mcap`: every site and the reference copy in Foxglove's
//!   terms, as `session run` writes it for real stations
//!   ([`coop_transport::recording::session`]).
//! - `sim compare SCENARIO`: every method on the same scenario next to the reference run, one table
//!   (or `--json`).
//! - `sim sweep SCENARIO`: every method × constant delay × seed, one row each (or `--json`), and
//!   with `--out` a plot of phases passed and co-contact divergence against delay. A scenario
//!   with a live `[task]` and participants adds what a user study would publish: per method and
//!   delay, trials done and mean completion time with 95 % intervals, and the best method at each
//!   delay (`task.png` with `--out`); each seed draws other participants.
//! - `sim bench`: cost of a physics step and a servo step, and the simulator's speed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Parser, Subcommand};
use coop_model::metrics::{self, Metrics};
use coop_model::scenario::{MethodName, Scenario};
use coop_model::sim::{self, Mode, RunResult};

use coop_actors::scenario_file;
use coop_transport::recording;

/// Command line of `sim`.
#[derive(Debug, Parser)]
#[command(
    name = "sim",
    version,
    about = "Run the deterministic multi-site simulator of cooperative haptic manipulation.",
    long_about = "Run the deterministic multi-site simulator: N sites, each with its own device, \
        servo/physics/report rates and user script, a virtual network with delay, jitter and loss, \
        in virtual time. Same scenario and seed give byte-identical outputs. Scenario files are TOML \
        (see scenarios/paper.toml); errors name the field, the value and the rule."
)]
pub struct Args {
    #[command(subcommand)]
    #[allow(missing_docs)]
    pub command: Command,
}

/// `sim` subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run one method; write trace.csv, adoptions.csv, metrics.json and plots to DIR.
    Run {
        /// Scenario file (TOML).
        scenario: PathBuf,
        /// Output directory (created if missing).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Method, overriding the scenario's: naive, paper, timewarp or coupled.
        #[arg(long, value_parser = parse_method)]
        method: Option<MethodName>,
        /// Seed, overriding the scenario's.
        #[arg(long)]
        seed: Option<u64>,
    },
    /// Run every method (or those of --methods) and the reference on the scenario; print one table.
    Compare {
        /// Scenario file (TOML).
        scenario: PathBuf,
        /// Methods, comma-separated (default: every one: naive,paper,timewarp,coupled).
        #[arg(long, value_delimiter = ',', value_parser = parse_method)]
        methods: Vec<MethodName>,
        /// Print the figures as JSON instead of a table.
        #[arg(long)]
        json: bool,
        /// Also write each method's outputs and plots under DIR/<method>/.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
    },
    /// Run every method at each constant delay and seed; print one row per run. With a live
    /// `[task]` (a participant scenario: each seed draws other people), also the share of trials
    /// done and the mean completion time per method and delay with 95 % intervals, and the best
    /// method at each delay.
    Sweep {
        /// Scenario file (TOML).
        scenario: PathBuf,
        /// One-way delays, ms, comma-separated (constant; the scenario's jitter, none at 0).
        #[arg(long, value_delimiter = ',', value_parser = parse_delay, allow_hyphen_values = true,
              default_value = crate::sweep::DEFAULT_DELAYS_MS)]
        delays_ms: Vec<f64>,
        /// Seeds 1 to N (overriding the scenario's); with participants, N people (pairs,
        /// groups) per delay.
        #[arg(long, default_value_t = 1, value_parser = parse_seeds)]
        seeds: u64,
        /// Methods, comma-separated (default: every one: naive,paper,timewarp,coupled).
        #[arg(long, value_delimiter = ',', value_parser = parse_method)]
        methods: Vec<MethodName>,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
        /// Print only the live task's summary (trials done and completion time per method and
        /// delay), not a row per run; needs a scenario with a `[task]`.
        #[arg(long, conflicts_with = "json")]
        summary: bool,
        /// Also write sweep.json, sweep.png and sweep.svg (and task.png, task.svg with a live
        /// task) into DIR.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
    },
    /// `timewarp` with every tick's position sent vs through the scenario's perceptual deadband
    /// (`[timewarp.deadband]`, turned on), at each constant delay: positions sent, kbit/s,
    /// phases, hash mismatches; the codec's own measure (each tool's contact force from the same
    /// world state at the decoded and at the measured position: share of contact ticks within one
    /// JND, goal 99 %, and the position error per tool); and, run against run (the friction
    /// model's chaos more than the codec's), the displayed force's difference in JND,
    /// twice: with the hands reacting to what they feel, and with every site's tool replayed
    /// from the full-rate run (only the world differs), and of the ticks beyond one JND those
    /// whose tools pressed as deep (mostly the stuck friction force differs).
    Deadband {
        /// Scenario file (TOML).
        scenario: PathBuf,
        /// One-way delays, ms, comma-separated (constant; the scenario's jitter, none at 0).
        #[arg(long, value_delimiter = ',', value_parser = parse_delay, default_value = "0,100,200,300")]
        delays_ms: Vec<f64>,
        /// Seeds 1 to N (overriding the scenario's), each seed's tables and then each figure's
        /// range over them (default: the scenario's seed alone).
        #[arg(long, value_parser = parse_seeds)]
        seeds: Option<u64>,
        /// Print JSON instead of a table (one row per seed and delay).
        #[arg(long)]
        json: bool,
    },
    /// Measure simulated participants (seeds 1 to N) the way a psychophysics lab measures
    /// people: reaches against Fitts' law and the minimum-jerk profile, end-point spread, visual
    /// and haptic reaction times, grip over load and the grip's response to a slip; each figure
    /// as the participants' mean ± SD beside the published human one, with a verdict.
    People {
        /// Participants 1 to N: the people a scenario with seed 1 to N draws for its first site.
        #[arg(long, default_value_t = crate::people::DEFAULT_PARTICIPANTS)]
        participants: u64,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
        /// Also write fitts.png/svg (MT against ID) and profile.png/svg (a reach's speed
        /// profile against minimum jerk's) into DIR.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
    },
    /// Print a commented scenario to start from: every table a scenario may hold (two sites, a
    /// simulated participant and a scripted hand, a phase, a live task). Every field:
    /// docs/reference/scenario.md.
    Template,
    /// Check a scenario file without running it: every rule, as `sim run` would (the error names
    /// the file, the field, the value and the rule); prints what it holds when valid.
    Check {
        /// Scenario file (TOML).
        scenario: PathBuf,
    },
    /// Write the reference pages of scenario, station and router files (docs/reference/*.md)
    /// from the code: each field's type, unit, default, rule and meaning.
    Reference {
        /// The repository's root (the pages go into its docs/reference/).
        #[arg(long, default_value = ".")]
        root: PathBuf,
        /// Write nothing; fail if a page differs from what the code generates.
        #[arg(long)]
        check: bool,
    },
    /// Benchmark: physics step, servo step (ns) and simulator speed on a scenario.
    Bench {
        /// Scenario for the speed figure.
        #[arg(default_value = "scenarios/paper.toml")]
        scenario: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
        /// Fewer iterations (CI smoke run).
        #[arg(long)]
        quick: bool,
    },
}

fn parse_delay(s: &str) -> Result<f64, String> {
    let d: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("delay {s:?} is not a number of ms"))?;
    if !(d.is_finite() && d >= 0.0) {
        return Err(format!("delay {s} ms: a delay cannot be negative"));
    }
    Ok(d)
}

fn parse_seeds(s: &str) -> Result<u64, String> {
    match s.trim().parse::<u64>() {
        Ok(0) => Err("0 seeds: at least 1 is needed (seeds run 1 to N)".into()),
        Ok(n) => Ok(n),
        Err(_) => Err(format!("{s:?} is not a whole number of seeds")),
    }
}

fn parse_method(s: &str) -> Result<MethodName, String> {
    MethodName::ALL
        .into_iter()
        .find(|m| m.as_str() == s)
        .ok_or_else(|| format!("unknown method {s:?}: use naive, paper, timewarp or coupled"))
}

/// Runs one mode with a progress bar on a terminal.
pub fn run_mode(scenario: &Scenario, mode: Mode) -> RunResult {
    use std::io::IsTerminal;
    let bar = if std::io::stderr().is_terminal() && scenario.duration_s > 5.0 {
        let b = indicatif::ProgressBar::new(1000);
        b.set_style(
            indicatif::ProgressStyle::with_template("{msg:>10} [{bar:40}] {percent:>3}%")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b.set_message(mode.name());
        Some(b)
    } else {
        None
    };
    let mut progress = |f: f64| {
        if let Some(b) = &bar {
            b.set_position((f * 1000.0) as u64);
        }
    };
    let r = sim::run_wired(
        scenario,
        mode,
        &mut progress,
        &coop_transport::wire::StationWire,
    );
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    r
}

/// Runs `sim`.
///
/// # Errors
/// Bad scenario files, unwritable output directories.
pub fn main(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Run {
            scenario,
            out,
            method,
            seed,
        } => {
            let mut sc = scenario_file::load(&scenario)?;
            if let Some(m) = method {
                sc.method = m;
            }
            if let Some(s) = seed {
                sc.seed = s;
            }
            let reference = run_mode(&sc, Mode::Reference);
            let r = run_mode(&sc, Mode::Distributed(sc.method));
            let m = metrics::compute(&sc, &r, &reference);
            write_outputs(&out, &sc, &r, &reference, &m)?;
            print_table(&sc, &[m]);
            println!("# outputs in {}", out.display());
        }
        Command::Compare {
            scenario,
            methods,
            json,
            out,
        } => {
            let sc = scenario_file::load(&scenario)?;
            let methods = chosen(methods)?;
            let reference = run_mode(&sc, Mode::Reference);
            let mut all = vec![metrics::compute(&sc, &reference, &reference)];
            for method in methods {
                let r = run_mode(&sc, Mode::Distributed(method));
                print_rollbacks(&r);
                let m = metrics::compute(&sc, &r, &reference);
                if let Some(dir) = &out {
                    write_outputs(&dir.join(method.as_str()), &sc, &r, &reference, &m)?;
                }
                all.push(m);
            }
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&compare_json(&sc, &all))?
                );
            } else {
                print_table(&sc, &all);
            }
        }
        Command::Sweep {
            scenario,
            delays_ms,
            seeds,
            methods,
            json,
            summary,
            out,
        } => {
            let sc = scenario_file::load(&scenario)?;
            let methods = chosen(methods)?;
            let print = if json {
                crate::sweep::Print::Json
            } else if summary {
                crate::sweep::Print::Summary
            } else {
                crate::sweep::Print::Table
            };
            crate::sweep::main(&sc, &delays_ms, seeds, &methods, print, out.as_deref())?;
        }
        Command::Deadband {
            scenario,
            delays_ms,
            seeds,
            json,
        } => crate::deadband::main(&scenario_file::load(&scenario)?, &delays_ms, seeds, json)?,
        Command::Bench {
            scenario,
            json,
            quick,
        } => crate::simbench::run(&scenario, json, quick)?,
        Command::People {
            participants,
            json,
            out,
        } => crate::people::main(participants, json, out.as_deref())?,
        Command::Template => print!("{}", crate::reference::TEMPLATE),
        Command::Check { scenario } => {
            let sc = scenario_file::load(&scenario)?;
            println!("{}: valid", scenario.display());
            println!("{}", check_summary(&sc));
        }
        Command::Reference { root, check } => crate::reference::write(&root, check)?,
    }
    Ok(())
}

/// What a valid scenario holds, in a few lines: what `sim check` prints.
fn check_summary(sc: &Scenario) -> String {
    let names = |v: Vec<&str>| v.join(", ");
    let hands: Vec<String> = sc
        .site
        .iter()
        .map(|s| {
            let hand = if !s.plan.is_empty() {
                format!("a participant, {} steps", s.plan.len())
            } else if s.hand_replay.is_some() {
                "a recorded hand".to_owned()
            } else {
                format!("a script, {} keyframes", s.script.len())
            };
            format!("  {}: {hand}", s.name)
        })
        .collect();
    format!(
        "{} ({} s, method {}, seed {})\nobjects: {}\nsites:\n{}\nphases: {}\ntask: {}\nnetwork: {}–{} ms one way, jitter ±{} ms, loss {}",
        sc.name,
        sc.duration_s,
        sc.method.as_str(),
        sc.seed,
        names(sc.objects.iter().map(|o| o.name.as_str()).collect()),
        hands.join("\n"),
        if sc.phase.is_empty() {
            "none".to_owned()
        } else {
            names(sc.phase.iter().map(|p| p.name.as_str()).collect())
        },
        if sc.task.done.is_some() { "judged live (done and fail conditions)" } else { "none" },
        sc.network.delay_min_ms,
        sc.network.delay_max_ms,
        sc.network.jitter_ms,
        sc.network.loss,
    )
}

/// The methods of `--methods`, every one if none is given; a method given twice is refused.
fn chosen(methods: Vec<MethodName>) -> anyhow::Result<Vec<MethodName>> {
    if methods.is_empty() {
        return Ok(MethodName::ALL.to_vec());
    }
    for (k, m) in methods.iter().enumerate() {
        if methods[..k].contains(m) {
            anyhow::bail!(
                "--methods: {} is given twice (each method runs once)",
                m.as_str()
            );
        }
    }
    Ok(methods)
}

/// One line per site of a method that rolls back.
fn print_rollbacks(r: &RunResult) {
    for (i, st) in r.rollback.iter().enumerate() {
        if let Some(st) = st {
            eprintln!("# {} site {i}: {st}", r.mode.name());
        }
    }
}

fn compare_json(sc: &Scenario, all: &[Metrics]) -> serde_json::Value {
    serde_json::json!({ "scenario": sc.name, "seed": sc.seed, "duration_s": sc.duration_s, "methods": all })
}

/// Prints the comparison table.
pub fn print_table(sc: &Scenario, all: &[Metrics]) {
    println!(
        "# scenario {} (seed {}, {} s, {} sites)",
        sc.name,
        sc.seed,
        sc.duration_s,
        sc.site.len()
    );
    println!(
        "{:<10}{:>10}{:>10}{:>12}{:>10}{:>11}{:>11}{:>11}{:>11}{:>11}{:>10}{:>8}{:>9}  phases",
        "method",
        "div max",
        "div rms",
        "div after",
        "co-div",
        "err ref",
        "force rms",
        "adopt step",
        "E others",
        "others did",
        "adoptions",
        "bounded",
        "sent"
    );
    println!(
        "{:<10}{:>10}{:>10}{:>12}{:>10}{:>11}{:>11}{:>11}{:>11}{:>11}{:>10}{:>8}{:>9}",
        "",
        "mm",
        "mm",
        "contact mm",
        "max mm",
        "rms mm",
        "N",
        "max N",
        "mJ",
        "mJ",
        "",
        "",
        "kbit/s"
    );
    for m in all {
        // The worst site; NaN (not measured, e.g. on real stations) if any site's is.
        let worst = |f: &dyn Fn(&coop_model::metrics::SiteMetrics) -> f64| {
            m.sites.iter().map(f).fold(0.0, |a: f64, b| {
                if a.is_nan() || b.is_nan() {
                    f64::NAN
                } else {
                    a.max(b)
                }
            })
        };
        let cell = |v: f64, width: usize, prec: usize| {
            if v.is_nan() {
                format!("{:>width$}", "-")
            } else {
                format!("{v:>width$.prec$}")
            }
        };
        let phases: Vec<String> = m
            .sites
            .iter()
            .map(|s| {
                let ok = s.phases.iter().filter(|(_, ok)| *ok).count();
                format!("{} {}/{}", s.name, ok, s.phases.len())
            })
            .collect();
        println!(
            "{:<10}{:>10.2}{:>10.2}{}{}{:>11.2}{:>11.3}{}{}{}{:>10}{:>8}{}  {}",
            m.method,
            m.divergence_max_m * 1e3,
            m.divergence_rms_m * 1e3,
            cell(m.divergence_after_contact_m * 1e3, 12, 3),
            cell(m.co_contact_divergence_max_m * 1e3, 10, 2),
            worst(&|s| s.error_vs_reference_rms_m) * 1e3,
            worst(&|s| s.force_tracking_rms_n),
            cell(worst(&|s| s.max_adoption_force_step_n), 11, 3),
            cell(worst(&|s| s.energy_from_others_j) * 1e3, 11, 2),
            cell(worst(&|s| s.others_work_j) * 1e3, 11, 2),
            m.sites.iter().map(|s| s.adoptions).sum::<usize>(),
            // Counted where the bound's work is known (the simulator); a station's recording does
            // not carry it, and 0 would read as "never scaled back".
            if m.bounded_energy_j.is_nan() {
                "-".to_owned()
            } else {
                m.bounded_corrections.to_string()
            },
            match crate::figures::busiest_sent_kbit_s(m, sc.duration_s) {
                0.0 => format!("{:>9}", "-"),
                k => format!("{k:>9.0}"),
            },
            phases.join(", ")
        );
    }
    let radius = sc.objects[0].radius_m;
    println!(
        "# div = largest distance between sites' copies; 'after contact' from {} (contacts over, object at rest, + max delay + 2 report periods; '-': contacts never ended); co-div = div while two or more users touch ('-': never); object radius {:.0} mm\n# E others = energy a copy gained beyond its own user's and environment's work; others did = the other users' work at their own sites (worst site shown); bounded = corrections the no-gain bound scaled back; sent = payload a site puts (site reports and tool tracks at their encoded sizes, each put once: a peer-to-peer mesh sends it to every other site), worst site, over the scenario's duration",
        all.iter()
            .map(|m| format!("{:.2} s ({})", m.after_contact_from_s, m.method))
            .collect::<Vec<_>>()
            .join(", "),
        radius * 1e3
    );
    for line in missed_phase_lines(all) {
        println!("{line}");
    }
    print_tasks(all);
}

/// Per method with a phase that did not happen, a heading and one line per site and phase
/// saying why: its first failed check, measured against the phase's threshold, and when.
fn missed_phase_lines(all: &[Metrics]) -> Vec<String> {
    let mut out = Vec::new();
    for m in all {
        if m.sites.iter().all(|s| s.missed_phases.is_empty()) {
            continue;
        }
        out.push(format!(
            "# {}: phases that did not happen, each with its first failed check:",
            m.method
        ));
        for s in &m.sites {
            for p in &s.missed_phases {
                out.push(format!("#   {} {}: {}", s.name, p.phase, p.miss));
            }
        }
    }
    out
}

/// The live task per method and site: the outcome as the site showed it, when, and the
/// participant's grip (a table only when the scenario has a `[task]` or a participant).
pub fn print_tasks(all: &[Metrics]) {
    if !all.iter().any(|m| m.sites.iter().any(|s| s.task.is_some())) {
        return;
    }
    println!(
        "{:<15}{:<10}{:>10}{:>10}  {:<10}{:>8}{:>8}{:>8}{:>7}{:>8}",
        "task", "site", "outcome", "time s", "by", "grip N", "peak N", "margin", "slips", "steps"
    );
    let cell = crate::figures::or_dash;
    for m in all {
        for s in &m.sites {
            let Some(t) = &s.task else { continue };
            // A station keeps its participant's grip and steps to itself: none in its row.
            let person = t.steps.1 > 0;
            println!(
                "{:<15}{:<10}{:>10}{:>10}  {:<10}{:>8}{:>8}{:>8}{:>7}{:>8}",
                m.method,
                s.name,
                t.outcome,
                cell(t.time_s, 2),
                if t.failed_by.is_empty() {
                    "-"
                } else {
                    &t.failed_by
                },
                cell(t.grip_mean_n, 2),
                cell(t.grip_peak_n, 2),
                cell(t.grip_margin, 2),
                if person {
                    t.slips.to_string()
                } else {
                    "-".to_owned()
                },
                if person {
                    format!("{}/{}", t.steps.0, t.steps.1)
                } else {
                    "-".to_owned()
                },
            );
        }
    }
    println!("# task: outcome as each site showed it; time = when the goal began to hold (done) or the failure; grip = the participant's mean felt normal force while gripping, margin = over what friction needed for the felt load ('-': a scripted hand, or a station's, which keeps its participant's figures)")
}

/// Writes a run's trace, adoptions, metrics, session file (`session.mcap`) and plots into `dir`.
///
/// # Errors
/// The directory or a file cannot be written.
pub fn write_outputs(
    dir: &Path,
    sc: &Scenario,
    r: &RunResult,
    reference: &RunResult,
    m: &Metrics,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let write = |name: &str, text: String| {
        std::fs::write(dir.join(name), text)
            .with_context(|| format!("writing {}", dir.join(name).display()))
    };
    write("trace.csv", r.trace_csv())?;
    write("reference_trace.csv", reference.trace_csv())?;
    write("adoptions.csv", r.adoptions_csv())?;
    write("metrics.json", serde_json::to_string_pretty(m)? + "\n")?;
    let session = dir.join("session.mcap");
    recording::session::write(
        &session,
        BTreeMap::from([
            ("scenario".into(), sc.name.clone()),
            ("method".into(), r.mode.name().to_owned()),
            ("seed".into(), sc.seed.to_string()),
        ]),
        sc,
        r,
        Some(reference),
        recording::session::Source::Simulated,
        recording::session::SIM_EPOCH_UNIX_NS,
    )
    .with_context(|| format!("writing {}", session.display()))?;
    crate::layout::write(dir, sc)?;
    crate::plots::figures(dir, sc, r, reference)
}
