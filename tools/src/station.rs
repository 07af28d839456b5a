//! The `station` command line: `station run|status|devices|clean`, `station router run|status` (a zenoh
//! router for sessions across machines), and the hidden loop processes the
//! supervisor spawns (`station servo|physics|network`). The `station` binary is this; the `session`
//! binary carries it too (`session station ...`), so one executable can run a whole session.

use std::collections::BTreeMap;
use std::path::PathBuf;

use clap::{Parser, Subcommand};

use coop_actors::station::{child, config::StationConfig, device, run, status};

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
    /// Run the station: servo, physics and network processes under a supervisor, until Ctrl-C/SIGTERM.
    ///
    /// The configuration is checked first (nothing starts if a value breaks a rule, or a listen
    /// port is taken). Restarts are per child. The servo and physics follow the `[supervisor]`
    /// fields: `restart` (never, on-failure, always), `backoff_initial_ms` doubling up to
    /// `backoff_max_ms`, at most `max_restarts` within `restart_window_s`; beyond that the station
    /// stops with an error naming the child and the policy. The network process is restarted after
    /// every exit without limit, backing off up to `network_backoff_max_ms`; while it is down the
    /// station runs on locally, degraded (said on stderr and by `station status`). A loop whose
    /// heartbeat stands still `heartbeat_timeout_ms` (`startup_timeout_ms` after a start; the
    /// servo's plus its device's own start wait) is killed as hung. A servo whose device does not
    /// open is not restarted: the station stops with the device's error.
    Run {
        #[command(flatten)]
        child: ChildArgs,
        /// Stop by itself after this many seconds.
        #[arg(long, value_name = "S")]
        duration_s: Option<f64>,
    },
    /// Show what a running station is doing (children, loop rates and latency, rings, network).
    Status {
        /// Station (site) name; default: the configuration's.
        #[arg(long)]
        station: Option<String>,
        /// Session name; default: the configuration's.
        #[arg(long)]
        session: Option<String>,
        /// Station configuration to take the defaults from.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// List the device backends built in and what each finds (library present, service
    /// reachable, devices and their info), marking the one the configuration selects.
    Devices {
        /// Station configuration (its scenario places the simulated arm; its `[device]` table
        /// selects a backend).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
    /// Remove the shared-memory segments of stations whose creator is gone (live ones stay).
    Clean {
        /// Only this session's segments.
        #[arg(long)]
        session: Option<String>,
        /// Only this station's (needs --session).
        #[arg(long, requires = "session")]
        station: Option<String>,
    },
    /// A zenoh router for sessions across machines: stations in client mode connect to it, and it
    /// enforces the session's access control (`session certs`) on every link.
    #[command(subcommand)]
    Router(RouterCommand),
    /// The servo loop process (started by the supervisor).
    #[command(hide = true)]
    Servo(ChildArgs),
    /// The physics loop process (started by the supervisor).
    #[command(hide = true)]
    Physics(ChildArgs),
    /// The network process (started by the supervisor).
    #[command(hide = true)]
    Network(ChildArgs),
}

#[derive(Debug, Subcommand)]
enum RouterCommand {
    /// Run the router until Ctrl-C/SIGTERM. The configuration (TOML) names the router (its
    /// certificate's common name), its `listen` and `connect` locators, `[tls]` (the session's
    /// CA, its certificate and key, `enable_mtls`), `access_control` (the file `session certs`
    /// writes), `status_file` and `status_every_ms` (default 500); it is checked before anything
    /// starts.
    Run {
        /// Router configuration (TOML).
        #[arg(long)]
        config: PathBuf,
        /// Stop by itself after this many seconds.
        #[arg(long, value_name = "S")]
        duration_s: Option<f64>,
    },
    /// Show what a running router sees: the zenoh sessions linked to it (zid, client/peer/router,
    /// links), the sites present, and the messages its access control refused (by kind, the
    /// latest with who and which key). A TLS link refused at the handshake (no certificate of the
    /// session's CA) never becomes a session and is not counted.
    Status {
        /// Router configuration (TOML).
        #[arg(long)]
        config: PathBuf,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
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
    /// The supervisor's pid: refuse to start if it is already gone (set by the supervisor).
    #[arg(long, hide = true)]
    parent: Option<u32>,
    /// Serve this station's own live view to Foxglove or Lichtblick (foxglove.websocket.v1) on
    /// ADDR, by default 127.0.0.1:8765 (loopback); port 0 picks a free one (printed). Overrides
    /// the configuration's `live`. From the network process: the real-time loops never wait for it.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, require_equals = false,
          default_missing_value = coop_transport::live_view::DEFAULT_ADDR)]
    live: Option<String>,
}

fn resolve(a: &ChildArgs) -> anyhow::Result<coop_actors::station::config::Resolved> {
    let mut r = StationConfig::load(a.config.as_deref())?;
    if a.station.is_some() || a.session.is_some() || a.live.is_some() {
        let mut c = r.config.clone();
        if let Some(s) = &a.station {
            c.station = Some(s.clone());
        }
        if let Some(s) = &a.session {
            c.session = s.clone();
        }
        if let Some(l) = &a.live {
            c.live = Some(l.clone());
        }
        r = c.resolve(a.config.as_deref().and_then(std::path::Path::parent))?;
    }
    Ok(r)
}

/// `v`, or JSON null where it is infinite (a replayed hand bounds nothing).
fn finite_or_null(v: f64) -> serde_json::Value {
    if v.is_finite() {
        serde_json::json!(v)
    } else {
        serde_json::Value::Null
    }
}

/// A backend's probe as `station devices --json` prints it.
fn probe_json(p: &coop_rt::device::cartesian::ProbeReport, selected: &str) -> serde_json::Value {
    serde_json::json!({
        "backend": p.backend,
        "built_in": p.built_in,
        "selected": p.backend == selected,
        "status": p.status,
        "devices": p.devices.iter().map(|i| serde_json::json!({
            "model": i.model,
            "serial": i.serial,
            "dof": i.dof,
            "max_force_n": finite_or_null(i.max_force_n),
            "max_stiffness_n_per_m": finite_or_null(i.max_stiffness_n_per_m),
            "max_damping_n_s_per_m": finite_or_null(i.max_damping_n_s_per_m),
            "workspace_radius_m": finite_or_null(i.workspace_radius_m),
            "native_rate_hz": finite_or_null(i.native_rate_hz),
            "senses_force": i.senses_force,
        })).collect::<Vec<_>>(),
    })
}

/// `station status`: the station of `--station`/`--session`, else the configuration's.
fn print_status(
    station: Option<String>,
    session: Option<String>,
    config: Option<PathBuf>,
    json: bool,
) -> anyhow::Result<()> {
    let r = StationConfig::load(config.as_deref())?;
    let session = session.unwrap_or(r.config.session);
    let station = station.unwrap_or(r.name);
    let sites: Vec<String> = r.scenario.site.iter().map(|s| s.name.clone()).collect();
    let mut v = status::read(&session, &station, &sites).map_err(|e| {
        let e = anyhow::Error::from(e);
        if config.is_some() {
            e
        } else {
            e.context(running_hint(&session, &station))
        }
    })?;
    v.name_objects(&r.scenario);
    if json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!("{v}");
    }
    Ok(())
}

/// What `station status` without `--config` says when the station it looked for is not there:
/// which one it looked for (the defaults), and the stations running on this machine (their
/// control segments, `coop_<session>_<station>_ctl`: neither name holds `_`).
fn running_hint(session: &str, station: &str) -> String {
    let mut running: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for e in std::fs::read_dir(coop_rt::shm::SHM_DIR)
        .into_iter()
        .flatten()
        .flatten()
    {
        let name = e.file_name().to_string_lossy().into_owned();
        let parts: Vec<&str> = name.split('_').collect();
        if let ["coop", session, station, "ctl"] = parts[..] {
            running
                .entry(session.to_owned())
                .or_default()
                .push(station.to_owned());
        }
    }
    let found = if running.is_empty() {
        "no station runs on this machine".to_owned()
    } else {
        let list: Vec<String> = running
            .iter_mut()
            .map(|(s, sites)| {
                sites.sort();
                format!("session {s}: {}", sites.join(", "))
            })
            .collect();
        format!("running here: {}", list.join("; "))
    };
    format!(
        "no --config: looked for station {station} of session {session} (the defaults); {found}. \
         Give the station's --config FILE, or --session and --station"
    )
}

/// Runs the station command line `args` (the first is the program name). `exe_prefix` are the
/// arguments that come before the subcommand when this executable re-runs itself (empty for the
/// `station` binary, `["station"]` inside `session`).
pub fn main(args: Vec<String>, exe_prefix: Vec<String>) -> std::process::ExitCode {
    // A station must always be stoppable: a parent may have spawned us with SIGINT/SIGTERM blocked
    // (a launcher waiting for them with sigwait; spawned processes inherit the mask). Blocked, they
    // would keep the stop ladder and the children's parent-death signal from ever acting.
    {
        use nix::sys::signal::{SigSet, SigmaskHow, Signal};
        let mut set = SigSet::empty();
        set.add(Signal::SIGINT);
        set.add(Signal::SIGTERM);
        if let Err(e) = nix::sys::signal::pthread_sigmask(SigmaskHow::SIG_UNBLOCK, Some(&set), None)
        {
            eprintln!("station: cannot unblock SIGINT/SIGTERM ({e}); it may not stop on a signal");
        }
    }
    let args = match Args::try_parse_from(args) {
        Ok(a) => a,
        Err(e) => e.exit(),
    };
    crate::run_main(|| match args.command {
        Command::Status {
            station,
            session,
            config,
            json,
        } => print_status(station, session, config, json),
        Command::Devices { config, json } => {
            let r = StationConfig::load(config.as_deref())?;
            let selected = r.device.backend.name();
            let reports = device::probe_all(&r.device, &r.scenario, r.site);
            if json {
                let v: Vec<serde_json::Value> =
                    reports.iter().map(|p| probe_json(p, selected)).collect();
                println!("{}", serde_json::to_string_pretty(&v)?);
            } else {
                for p in &reports {
                    let mark = if p.backend == selected { "*" } else { " " };
                    println!("{mark} {:<7} {}", p.backend, p.status);
                    for i in &p.devices {
                        println!("          {}", device::info_line(i));
                    }
                }
                println!("# * the configuration's device");
            }
            Ok(())
        }
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
        Command::Run {
            child: a,
            duration_s,
        } => {
            let duration = match duration_s {
                Some(d) if d > 0.0 && d.is_finite() => Some(std::time::Duration::from_secs_f64(d)),
                Some(d) => anyhow::bail!("--duration-s {d}: must be a positive number of seconds"),
                None => None,
            };
            if a.parent.is_some() {
                // Started by a launcher (`session`): stop (SIGTERM: the stop ladder) when it dies.
                child::die_with_parent(a.parent)?;
            }
            let opts = run::RunOptions {
                config: a.config.clone(),
                duration,
                exe_prefix,
            };
            Ok(run::run(&resolve(&a)?, &opts)?)
        }
        Command::Router(RouterCommand::Run { config, duration_s }) => {
            let r = coop_actors::router::RouterConfig::load(&config)?;
            let duration = match duration_s {
                Some(d) if d > 0.0 && d.is_finite() => Some(std::time::Duration::from_secs_f64(d)),
                Some(d) => anyhow::bail!("--duration-s {d}: must be a positive number of seconds"),
                None => None,
            };
            // The process's tracing subscriber counts the access control's refusals: installed
            // by the binary, before anything else could claim it.
            let refusals =
                coop_transport::router::Refusals::install().map_err(anyhow::Error::msg)?;
            // Before zenoh's threads start: SIGINT/SIGTERM stop the router cleanly.
            let stop = crate::cli::StopFlag::on_sigint_sigterm()?;
            let s = coop_actors::router::run(&r, duration, &|| stop.is_raised(), refusals)?;
            eprintln!("{s}");
            Ok(())
        }
        Command::Router(RouterCommand::Status { config, json }) => {
            let r = coop_actors::router::RouterConfig::load(&config)?;
            let s = coop_actors::router::read_status(&r)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&s)?);
            } else {
                print!("{s}");
            }
            Ok(())
        }
        Command::Servo(a) => match child::run_servo(&resolve(&a)?, a.parent) {
            // Its supervisor ends the station with the words it left in the control block.
            Err(e) if a.parent.is_some() && e.cannot_start() => {
                std::process::exit(coop_actors::child::EXIT_CANNOT_START)
            }
            r => Ok(r?),
        },
        Command::Physics(a) => Ok(child::run_physics(&resolve(&a)?, a.parent)?),
        Command::Network(a) => {
            // The network process's zenoh speaks on stderr when RUST_LOG asks: installed here, by
            // the binary, as a library must not install a process's log subscriber.
            coop_transport::log::zenoh_to_stderr();
            match child::run_network(&resolve(&a)?, a.parent) {
                // Its supervisor says why, once: not one line per restart here.
                Err(e) if a.parent.is_some() && e.said_by_the_station() => std::process::exit(1),
                r => Ok(r?),
            }
        }
    })
}
