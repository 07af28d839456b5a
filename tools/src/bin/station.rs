//! `station`: one site of a coop-haptics session. See `station --help`.
//!
//! Built so far: `station clean` and the loop processes the supervisor will spawn (`station servo`,
//! `station physics`, hidden). `station run` and `station status` arrive with the supervisor.

use std::path::PathBuf;

use clap::{Parser, Subcommand};
use coop_tools::station::{child, config::StationConfig};

/// Command line of `station`.
#[derive(Debug, Parser)]
#[command(
    name = "station",
    version,
    about = "One site of a coop-haptics session: servo, physics and network processes over shared memory."
)]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Remove the shared-memory segments of stations whose creator is gone (live ones stay).
    Clean {
        /// Only this session's segments.
        #[arg(long)]
        session: Option<String>,
        /// Only this station's (needs --session).
        #[arg(long, requires = "session")]
        station: Option<String>,
    },
    /// The servo loop process (started by the supervisor).
    #[command(hide = true)]
    Servo(ChildArgs),
    /// The physics loop process (started by the supervisor).
    #[command(hide = true)]
    Physics(ChildArgs),
}

#[derive(Debug, clap::Args)]
struct ChildArgs {
    /// Station configuration (TOML); defaults when absent.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Station (site) name, overriding the configuration's.
    #[arg(long)]
    station: Option<String>,
    /// Session name, overriding the configuration's.
    #[arg(long)]
    session: Option<String>,
    /// The supervisor's pid: refuse to start if it is already gone.
    #[arg(long)]
    parent: Option<u32>,
}

fn resolve(a: &ChildArgs) -> anyhow::Result<coop_tools::station::config::Resolved> {
    let mut r = StationConfig::load(a.config.as_deref())?;
    if a.station.is_some() || a.session.is_some() {
        let mut c = r.config.clone();
        if let Some(s) = &a.station {
            c.station = Some(s.clone());
        }
        if let Some(s) = &a.session {
            c.session = s.clone();
        }
        r = c.resolve(a.config.as_deref().and_then(std::path::Path::parent))?;
    }
    Ok(r)
}

fn main() -> std::process::ExitCode {
    let args = Args::parse();
    coop_tools::run_main(|| match args.command {
        Command::Clean { session, station } => {
            let prefix = match (&session, &station) {
                (Some(s), Some(t)) => coop_rt::shm::SegmentName::station_prefix(s, t)?,
                (Some(s), None) => format!("{}{s}_", coop_rt::shm::PREFIX),
                _ => coop_rt::shm::PREFIX.to_owned(),
            };
            let removed = coop_rt::shm::remove_stale(&prefix)?;
            for r in &removed {
                println!("removed {} ({})", r.name, r.status);
            }
            let left = coop_rt::shm::list(&prefix)?;
            for l in &left {
                println!("kept {} ({})", l.name, l.status);
            }
            println!(
                "# {} stale segment(s) removed, {} kept",
                removed.len(),
                left.len()
            );
            Ok(())
        }
        Command::Servo(a) => child::run_servo(&resolve(&a)?, a.parent),
        Command::Physics(a) => child::run_physics(&resolve(&a)?, a.parent),
    })
}
