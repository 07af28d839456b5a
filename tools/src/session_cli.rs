//! The `session` command line (its binary is a thin main over [`main`]): a multi-site session of
//! real stations on this machine, its benchmarks and its certificates. See `session --help`.

use std::path::PathBuf;

use clap::{Parser, Subcommand};
use coop_model::scenario::MethodName;

/// Command line of `session`.
#[derive(Debug, Parser)]
#[command(
    name = "session",
    version,
    about = "Run a multi-site coop-haptics session: one real station per site of a scenario, over zenoh.",
    long_about = "Run a multi-site coop-haptics session on this machine: one real station (servo, \
        physics and network processes under a supervisor) per site of a scenario file, connected as \
        zenoh peers on loopback, the scenario's network delay, jitter and loss emulated on receive. \
        The launcher waits until every station is present, starts the users' scripts together, \
        stops the stations cleanly, reads their MCAP recordings and prints the metrics table of \
        `sim compare` for the real run next to the simulator's figures."
)]
struct Args {
    #[command(subcommand)]
    command: Command,
}

// Parsed once per run: the size of its largest variant costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Subcommand)]
enum Command {
    /// Run the scenario on real stations, once per method; print the metrics table.
    Run(RunCmd),
    /// Benchmark: station-to-station state latency on loopback next to a bare zenoh ping-pong of
    /// the same payload (run from the repository root).
    Bench {
        /// Print JSON.
        #[arg(long)]
        json: bool,
        /// A separate station binary to run (default: this executable, as `session station`).
        #[arg(long)]
        station_bin: Option<PathBuf>,
    },
    /// Make what a session across machines needs: a session CA, a certificate per site (common
    /// name = the site's name), one for the launcher and one per router, and the access control
    /// that follows from the scenario (acl.json5: each site may put only its own state and tool,
    /// declare and answer only its own current, clock and presence; only the launcher puts the
    /// epoch; everything else is denied). Keys are written owner-only.
    Certs {
        /// Scenario file (TOML): its sites.
        scenario: PathBuf,
        /// Output directory (made if absent).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Session name, as in the stations' configurations.
        #[arg(long, default_value = "local")]
        session: String,
        /// A router's name (repeatable).
        #[arg(long = "router", value_name = "NAME")]
        routers: Vec<String>,
        /// Addresses or host names NAME is reached at, added to its certificate (repeatable),
        /// e.g. `r1=192.0.2.1,router.example.org`. Each certificate has its name, localhost,
        /// 127.0.0.1 and ::1 already.
        #[arg(long = "host", value_name = "NAME=ADDR[,ADDR]", value_parser = crate::certs::parse_host)]
        hosts: Vec<(String, Vec<String>)>,
        /// Days the certificates are valid.
        #[arg(long, default_value_t = 365)]
        days: u32,
        /// The ROS 2 domain the stations publish in (`[ros2] publish = true`): each site may
        /// also put its own ROS 2 topics, /tf and /rosout, and declare its own node's tokens.
        #[arg(long, value_name = "ID")]
        ros2_domain: Option<u32>,
        /// A ROS 2 tool (RViz, ros2 bag, a bridge) that may look at that domain through the
        /// routers: it gets a certificate and may subscribe, query and declare graph tokens, but
        /// put nothing (repeatable; needs --ros2-domain).
        #[arg(long = "ros2-viewer", value_name = "NAME", requires = "ros2_domain")]
        ros2_viewers: Vec<String>,
    },
    /// Benchmark: station-to-station state latency through one zenoh router (`station router`,
    /// loopback) next to peer to peer and to a bare zenoh ping-pong through the same router, in
    /// the same run (run from the repository root).
    BenchRouter {
        /// Print JSON.
        #[arg(long)]
        json: bool,
        /// 4 s sessions instead of 14 s (CI).
        #[arg(long)]
        quick: bool,
        /// A separate station binary to run (default: this executable, as `session station`).
        #[arg(long)]
        station_bin: Option<PathBuf>,
    },
    /// Print a TCP port on 127.0.0.1 that is free now, outside the kernel's ephemeral range, as
    /// this launcher picks its stations' ports: for a script that starts a router. (A port the
    /// kernel picks for a bind to port 0 is one any outgoing connection may take first.)
    FreePort,
    /// The benchmark's echo process.
    #[command(hide = true)]
    BenchPong {
        /// Where to listen (or with --via-router, the router to connect to).
        #[arg(long)]
        listen: String,
        /// Connect to the router at --listen as a client.
        #[arg(long)]
        via_router: bool,
    },
}

// `session run`'s arguments (the help text is the `Run` variant's doc comment).
#[derive(Debug, clap::Args)]
struct RunCmd {
    /// Scenario file (TOML), as for `sim`.
    scenario: PathBuf,
    /// Output directory: per method the station configs, logs, MCAP recordings, metrics.json
    /// and plots.
    #[arg(long, value_name = "DIR", default_value = "out/session")]
    out: PathBuf,
    /// naive, paper, timewarp, coupled, or all (each, one session each).
    #[arg(long, default_value = "all", value_parser = parse_methods)]
    method: Methods,
    /// Print JSON instead of the table.
    #[arg(long)]
    json: bool,
    /// Session name prefix (default: s<pid>); each method's session is <prefix>-<method>.
    #[arg(long)]
    session: Option<String>,
    /// Start a site late: SITE=SECONDS after the session's start (repeatable).
    #[arg(long, value_name = "SITE=S", value_parser = parse_late)]
    late: Vec<(String, f64)>,
    /// Do not emulate the scenario's network delay, jitter and loss (loopback only).
    #[arg(long)]
    no_emulation: bool,
    /// Seconds the stations get to be present.
    #[arg(long, default_value_t = 30.0)]
    start_timeout_s: f64,
    /// A separate station binary to run (default: this executable, as `session station`).
    #[arg(long)]
    station_bin: Option<PathBuf>,
    /// Each station's recording goes on in its next part after this many seconds (the
    /// station's `record_max_file_s`; default: the station's default).
    #[arg(long, value_name = "S")]
    record_max_file_s: Option<u64>,
    /// Serve the session live to Foxglove or Lichtblick (foxglove.websocket.v1) on ADDR, by
    /// default 127.0.0.1:8765 (loopback); port 0 picks a free one. The address is printed.
    #[arg(long, value_name = "ADDR", num_args = 0..=1,
          default_missing_value = coop_transport::live_view::DEFAULT_ADDR)]
    live: Option<String>,
    /// Drive stations already running (started by hand, with `start = "session"`, on this or
    /// other machines) instead of starting them: wait for every site's presence through
    /// --connect, announce time 0 in this launcher's clock (each station translates it with
    /// its measured offset to it), and read their recordings from --recording/--recordings.
    /// Needs --session and one --method, those of the stations' configurations.
    #[arg(long)]
    attach: bool,
    /// With --attach: a zenoh locator to connect to (repeatable): a router's, e.g.
    /// tls/192.0.2.1:7447, or with --peer a station's.
    #[arg(long, value_name = "LOCATOR", requires = "attach")]
    connect: Vec<String>,
    /// With --attach: connect as a zenoh peer of the stations (default: a client of routers).
    #[arg(long, requires = "attach")]
    peer: bool,
    /// With --attach: the directory `session certs` wrote; the launcher connects with mutual
    /// TLS as `launcher` (DIR/ca.pem, DIR/launcher.pem, DIR/launcher.key).
    #[arg(long, value_name = "DIR", requires = "attach")]
    certs: Option<PathBuf>,
    /// With --attach: where a site's recording is, as this machine sees it (its station's
    /// `record`; repeatable).
    #[arg(long, value_name = "SITE=PATH", value_parser = parse_recording, requires = "attach")]
    recording: Vec<(String, PathBuf)>,
    /// With --attach: the recordings of the sites not given by --recording are DIR/<site>.mcap
    /// (a directory the stations write to that this machine sees).
    #[arg(long, value_name = "DIR", requires = "attach")]
    recordings: Option<PathBuf>,
    /// Publish every site as ROS 2 topics under rmw_zenoh's conventions (poses, force, /tf,
    /// /rosout under /coop/<session>/<site>; docs/ros2.md): `ros2 topic list` on a machine
    /// with rmw_zenoh sees them, with no ROS installed here.
    #[arg(long)]
    ros2: bool,
    /// With --ros2: the ROS domain (default: $ROS_DOMAIN_ID, else 0).
    #[arg(long, value_name = "ID", requires = "ros2")]
    ros2_domain: Option<u32>,
    /// With --ros2: the zenoh router of the ROS 2 graph, which every station connects to
    /// (rmw_zenoh's default, where `ros2 run rmw_zenoh_cpp rmw_zenohd` listens), or `none`.
    #[arg(
        long,
        value_name = "LOCATOR",
        requires = "ros2",
        default_value = "tcp/127.0.0.1:7447"
    )]
    ros2_router: String,
}

#[derive(Debug, Clone)]
struct Methods(Vec<MethodName>);

fn parse_methods(s: &str) -> Result<Methods, String> {
    match s {
        "naive" => Ok(Methods(vec![MethodName::Naive])),
        "paper" => Ok(Methods(vec![MethodName::Paper])),
        "timewarp" => Ok(Methods(vec![MethodName::Timewarp])),
        "coupled" => Ok(Methods(vec![MethodName::Coupled])),
        "all" => Ok(Methods(MethodName::ALL.to_vec())),
        _ => Err(format!(
            "unknown method {s:?}: use naive, paper, timewarp, coupled or all"
        )),
    }
}

fn parse_late(s: &str) -> Result<(String, f64), String> {
    let (site, t) = s
        .split_once('=')
        .ok_or_else(|| format!("{s:?}: expected SITE=SECONDS, e.g. user2=3"))?;
    let t: f64 = t
        .parse()
        .map_err(|e| format!("{s:?}: seconds {t:?}: {e}"))?;
    Ok((site.to_owned(), t))
}

fn parse_recording(s: &str) -> Result<(String, PathBuf), String> {
    let (site, path) = s
        .split_once('=')
        .filter(|(n, p)| !n.is_empty() && !p.is_empty())
        .ok_or_else(|| format!("{s:?}: expected SITE=PATH, e.g. user2=/shared/user2.mcap"))?;
    Ok((site.to_owned(), PathBuf::from(path)))
}

/// `session`'s main: `session station ...` is the station command line (the launcher runs its
/// stations, and they their loop processes, from this one executable); the rest are its
/// subcommands.
pub fn main() -> std::process::ExitCode {
    // `session station ...` is the station command line: the launcher runs its stations (and they
    // their loop processes) from this one executable.
    let argv: Vec<String> = std::env::args().collect();
    if argv.get(1).map(String::as_str) == Some("station") {
        let mut rest = vec![format!("{} station", argv[0])];
        rest.extend(argv[2..].iter().cloned());
        return crate::station::main(rest, vec!["station".into()]);
    }
    let args = Args::parse();
    crate::run_main(|| match args.command {
        Command::Run(cmd) => run(cmd),
        Command::Bench { json, station_bin } => {
            crate::netbench::run(json, &station_bin_or_default(station_bin)?)
        }
        Command::BenchRouter {
            json,
            quick,
            station_bin,
        } => crate::netbench::router::run(json, quick, &station_bin_or_default(station_bin)?),
        Command::FreePort => {
            let l = coop_transport::network::concrete_listen(&["tcp/127.0.0.1:0".into()]);
            let port = l[0].rsplit(':').next().unwrap_or_default();
            anyhow::ensure!(port != "0", "no free port on 127.0.0.1");
            println!("{port}");
            Ok(())
        }
        Command::BenchPong { listen, via_router } => crate::netbench::pong(&listen, via_router),
        Command::Certs {
            scenario,
            out,
            session,
            routers,
            hosts,
            days,
            ros2_domain,
            ros2_viewers,
        } => {
            let sc = coop_actors::scenario_file::load(&scenario)?;
            let mut by_name = std::collections::BTreeMap::<String, Vec<String>>::new();
            for (n, a) in hosts {
                by_name.entry(n).or_default().extend(a);
            }
            let w = crate::certs::make(&crate::certs::CertsArgs {
                session,
                sites: sc.site.iter().map(|s| s.name.clone()).collect(),
                routers,
                hosts: by_name,
                days,
                out,
                ros2_domain,
                ros2_viewers,
            })?;
            println!("ca {}", w.ca.display());
            for (n, (c, k)) in &w.certs {
                println!("{n} {} {}", c.display(), k.display());
            }
            println!("acl {}", w.acl.display());
            Ok(())
        }
    })
}

/// `session run`: the sessions, then the report (or JSON).
fn run(cmd: RunCmd) -> anyhow::Result<()> {
    let json = cmd.json;
    let a = run_args(cmd)?;
    let (sc, run) = crate::session::run(&a)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&run.to_json()?)?);
    } else {
        crate::session::print_report(&sc, &run, a.attach.is_some());
    }
    Ok(())
}

/// What `session run` is asked, from its command line: the station program, the stations to
/// attach to, the signal handlers, the live view and the ROS 2 graph.
fn run_args(cmd: RunCmd) -> anyhow::Result<crate::session::RunArgs> {
    let RunCmd {
        scenario,
        out,
        method,
        json,
        session,
        late,
        no_emulation,
        start_timeout_s,
        station_bin,
        record_max_file_s,
        live,
        attach,
        connect,
        peer,
        certs,
        recording,
        recordings,
        ros2,
        ros2_domain,
        ros2_router,
    } = cmd;
    if !(start_timeout_s.is_finite() && start_timeout_s > 0.0) {
        anyhow::bail!("--start-timeout-s {start_timeout_s}: must be a positive number");
    }
    let station_bin = station_bin_or_default(station_bin)?;
    let attach = if attach {
        let sc = coop_actors::scenario_file::load(&scenario)?;
        Some(crate::session::attach::Attach {
            connect,
            mode: if peer {
                coop_transport::network::Mode::Peer
            } else {
                coop_transport::network::Mode::Client
            },
            tls: certs
                .as_deref()
                .map(crate::session::attach::Attach::tls_from_certs),
            recordings: crate::session::attach::Attach::recordings_for(
                &sc,
                &recording,
                recordings.as_deref(),
            )?,
        })
    } else {
        None
    };
    // Before any thread (zenoh's) starts: SIGINT/SIGTERM stop the session cleanly.
    let stop = crate::cli::StopFlag::on_sigint_sigterm()?;
    Ok(crate::session::RunArgs {
        trials: false,
        scenario,
        out,
        methods: method.0,
        session,
        late,
        emulate: !no_emulation,
        start_timeout: std::time::Duration::from_secs_f64(start_timeout_s),
        station_bin,
        progress: !json,
        stop,
        record_max_file_s,
        live: live.map(|addr| live_view(&addr)).transpose()?,
        attach,
        ros2: ros2
            .then(|| ros2_run(ros2_domain, &ros2_router))
            .transpose()?,
    })
}

/// How `study run --stations` starts a study's stations: the `station` program beside this one,
/// the defaults of `session run` (emulated network, progress off), the stations waiting for
/// trials.
///
/// # Errors
/// No `station` program beside this one; the signal handlers cannot be set.
pub fn study_stations_args(
    scenario: &std::path::Path,
    out: &std::path::Path,
) -> anyhow::Result<crate::session::RunArgs> {
    let program = std::env::current_exe()?.with_file_name("station");
    if !program.is_file() {
        anyhow::bail!(
            "study run --stations starts its stations with the `station` program, which is not beside this one ({}): build it (cargo build --release -p coop-tools --bin station)",
            program.display()
        );
    }
    Ok(crate::session::RunArgs {
        trials: true,
        scenario: scenario.to_owned(),
        out: out.to_owned(),
        methods: Vec::new(),
        session: None,
        late: Vec::new(),
        emulate: true,
        start_timeout: std::time::Duration::from_secs(20),
        station_bin: crate::session::StationBin {
            program,
            prefix: vec![],
        },
        progress: false,
        stop: crate::cli::StopFlag::on_sigint_sigterm()?,
        record_max_file_s: None,
        live: None,
        attach: None,
        ros2: None,
    })
}

/// `--live`: the Foxglove server, its address printed.
fn live_view(addr: &str) -> anyhow::Result<std::sync::Arc<coop_transport::live_view::LiveView>> {
    let view = coop_transport::live_view::LiveView::start(addr)?;
    eprintln!(
        "live view: {} (foxglove.websocket.v1: open it in Foxglove or Lichtblick)",
        view.url()
    );
    Ok(std::sync::Arc::new(view))
}

/// The station program and the arguments before its subcommand.
fn station_bin_or_default(b: Option<PathBuf>) -> anyhow::Result<crate::session::StationBin> {
    Ok(match b {
        Some(program) => crate::session::StationBin {
            program,
            prefix: vec![],
        },
        None => crate::session::StationBin {
            program: std::env::current_exe()?,
            prefix: vec!["station".into()],
        },
    })
}

/// `--ros2`'s domain (given, or `$ROS_DOMAIN_ID`, or 0) and router (`none`: none).
fn ros2_run(domain: Option<u32>, router: &str) -> anyhow::Result<crate::session::Ros2Run> {
    let domain_id = match domain {
        Some(d) => d,
        None => match std::env::var("ROS_DOMAIN_ID") {
            Ok(v) if !v.trim().is_empty() => v
                .trim()
                .parse()
                .map_err(|_| anyhow::anyhow!("ROS_DOMAIN_ID = {v:?}: not a domain id (0..=232)"))?,
            _ => 0,
        },
    };
    let max = coop_transport::ros2::MAX_DOMAIN_ID;
    if domain_id > max {
        anyhow::bail!("--ros2-domain {domain_id}: must be 0..={max} (ROS 2's range)");
    }
    Ok(crate::session::Ros2Run {
        domain_id,
        router: (router != "none").then(|| router.to_owned()),
    })
}
