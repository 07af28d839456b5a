//! The `study` command line.

use std::path::PathBuf;

use anyhow::bail;
use clap::{Parser, Subcommand};

/// A user study from its file to its figures: the trial order of every group (a balanced Latin
/// square by default), a pilot with simulated participants in the simulator, and the analysis a
/// paper needs (completion time and success per condition with within-subject intervals, a
/// repeated-measures ANOVA, plots, and a table for R's afex or Python's pingouin). The study file
/// is TOML: see docs/study.md and scenarios/studies/.
#[derive(Debug, Parser)]
#[command(name = "study", version)]
pub struct Args {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// `study` subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Check a study file and print every group's trials in the order they do them
    Plan {
        /// Study file (TOML)
        file: PathBuf,
    },
    /// Run a study's trials and write trials.csv (one row per site and trial, appended as trials
    /// finish), study.toml and meta.json into --out
    Run {
        /// Study file (TOML)
        file: PathBuf,
        /// Run it in the simulator with simulated participants (each group's people drawn once,
        /// each trial its own run): a pilot before anyone is recruited
        #[arg(long, conflicts_with = "stations")]
        sim: bool,
        /// Run it on live stations of this machine (one per site, zenoh peers on loopback, the
        /// scenario's devices), started once for the whole run: between trials the stations
        /// rebuild themselves from the next trial's scenario without a restart and take its time
        /// 0 from the runner; one recording per station and trial in --out/stations
        #[arg(long)]
        stations: bool,
        /// Output directory (created; it must not hold a study's trials unless --resume)
        #[arg(long)]
        out: PathBuf,
        /// Go on with the run in --out: keep every trial its table holds whole, run the others
        /// (one that was begun and cut short is run again and marked `cut`)
        #[arg(long)]
        resume: bool,
        /// Serve the experimenter's page (progress, pause, resume, repeat, abort) and the
        /// participants' questionnaires at this address (e.g. 127.0.0.1:8700; port 0: any free
        /// one, printed): the trials then run group by group and block by block, each block's
        /// questionnaire answered before the next (on stations, pause and abort act between
        /// trials)
        #[arg(long, value_name = "ADDR")]
        serve: Option<String>,
    },
    /// Analyse a run: print and write report.txt, cells.csv and the plots (task.svg, task.png)
    /// into its directory
    Report {
        /// The --out directory of a `study run`
        dir: PathBuf,
    },
}

/// Runs the command line.
///
/// # Errors
/// A bad study file, output directory or table; a file that cannot be written.
pub fn main(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Plan { file } => {
            let study = super::Study::load(&file)?;
            print!("{}", study.plan_text());
        }
        Command::Run {
            file,
            sim,
            stations,
            out,
            resume,
            serve,
        } => {
            if !sim && !stations {
                bail!("study run: say where the trials run: --sim (simulated participants in the simulator) or --stations (live stations on this machine)");
            }
            let study = super::Study::load(&file)?;
            let total = study.plan().len();
            eprintln!(
                "study {}: {total} trials of {} groups {}, into {}",
                study.file.name,
                study.groups.len(),
                if stations {
                    "on live stations of this machine"
                } else {
                    "in the simulator"
                },
                out.display()
            );
            // On stations: every condition checked against the stations' world before anything
            // starts; the stations themselves start at the first trial.
            let mut on = if stations {
                let a = crate::session_cli::study_stations_args(&study.scenario_path, &out)?;
                Some(super::live::OnStations::new(&study, &out, a)?)
            } else {
                None
            };
            let ran = match serve {
                None => {
                    if study.file.questionnaire.is_some() {
                        eprintln!(
                            "study {}: its questionnaire is not asked without --serve",
                            study.file.name
                        );
                    }
                    match on.take() {
                        Some(on) => {
                            super::live::run_stations(&study, &out, resume, on, &mut |l| {
                                eprintln!("  {l}");
                            })?
                        }
                        None => super::run::run_sim(&study, &out, resume, &mut |done, total| {
                            eprintln!("  {done}/{total} trials");
                        })?,
                    }
                }
                Some(addr) => {
                    let shared = std::sync::Arc::new(super::board::Shared::new(
                        &study.file.name,
                        total,
                        study.file.questionnaire.clone(),
                        study.file.factor.iter().map(|f| f.name.clone()).collect(),
                    ));
                    let answers = super::web::answers_path(&out);
                    let kept = study.clone();
                    let store: std::sync::Arc<super::web::Store> = std::sync::Arc::new(
                        move |p: &super::board::Pending, a: &[(String, u32)]| {
                            super::run::store_answers(&kept, &answers, p, a)
                        },
                    );
                    let server =
                        super::web::Server::start(&addr, std::sync::Arc::clone(&shared), store)?;
                    // The line a script waits for: where the pages are.
                    eprintln!(
                        "study {}: serving http://{addr}/ : the experimenter's page http://{addr}/?key={key} (its key is its control: keep it to the experimenter); questionnaires at http://{addr}/q/<participant>",
                        study.file.name,
                        addr = server.addr,
                        key = server.key
                    );
                    let ran = match on.take() {
                        Some(mut on) => {
                            let ran = super::served::run_served(
                                &study,
                                &out,
                                resume,
                                &shared,
                                &mut super::served::Runner::Stations(&mut on),
                            );
                            // The stations stop at the run's end, before the page waits.
                            let said = on.finish();
                            let ran = ran?;
                            for line in said? {
                                eprintln!("  {line}");
                            }
                            ran
                        }
                        None => super::served::run_served(
                            &study,
                            &out,
                            resume,
                            &shared,
                            &mut super::served::Runner::Sim,
                        )?,
                    };
                    eprintln!("study {}: finished; the page stays until Close is pressed on it (or Ctrl-C)", study.file.name);
                    shared.wait_closed();
                    ran
                }
            };
            println!(
                "study {}: {} trials run{}, {} kept from before, in {:.0} s; table {}",
                study.file.name,
                ran.ran,
                if stations { " on stations" } else { "" },
                ran.kept,
                ran.seconds,
                out.join("trials.csv").display()
            );
        }
        Command::Report { dir } => {
            print!("{}", super::report::report(&dir)?);
        }
    }
    Ok(())
}
