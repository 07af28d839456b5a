//! Helpers for coop-haptics' multi-process tests: unique names so tests run in parallel without
//! sharing a segment, bounded waits that fail with what was seen, and child processes that are killed
//! (never leaked) when a test fails.
#![forbid(unsafe_code)]

pub mod forgery;
mod kit;
mod scenario;

pub use kit::{load_scenario, repo, scenario_path, TempDir};
pub use scenario::ScenarioToml;

pub use coop_actors::station::config::StationConfig;
use coop_rt::sync::{AtomicU64, Ordering};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A session name unique to this test process and call: `t<pid>x<n>`.
pub fn unique_session() -> String {
    static N: AtomicU64 = AtomicU64::new(0);
    format!(
        "t{}x{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// Polls `f` until it returns `Some`, or panics after `limit` naming `what` and the last value seen.
///
/// # Panics
/// When `limit` passes first.
pub fn wait_until<T>(what: &str, limit: Duration, mut f: impl FnMut() -> Option<T>) -> T {
    let start = Instant::now();
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(
            start.elapsed() < limit,
            "timed out after {limit:?} waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Polls `f` until it returns `Ok`, or panics after `limit` naming `what` and the last `Err` seen
/// (what the condition looked like when time ran out).
///
/// # Panics
/// When `limit` passes first.
pub fn wait_for<T>(what: &str, limit: Duration, mut f: impl FnMut() -> Result<T, String>) -> T {
    let start = Instant::now();
    let mut last;
    loop {
        match f() {
            Ok(v) => return v,
            Err(seen) => last = seen,
        }
        assert!(
            start.elapsed() < limit,
            "timed out after {limit:?} waiting for {what}; last seen: {last}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// A station's status in one line, for a wait's "last seen": its run state, each child's health
/// and restarts (and last failure), the network's counts and peers, and what physics took.
pub fn brief(s: &coop_actors::station::status::StationStatus) -> String {
    let children = s
        .children
        .iter()
        .map(|c| {
            let failed = c
                .last_failure
                .as_deref()
                .map_or(String::new(), |f| format!(" ({f})"));
            format!("{} {} r{}{failed}", c.name, c.health, c.restarts)
        })
        .collect::<Vec<_>>()
        .join(", ");
    let peers = s
        .network
        .peers
        .iter()
        .map(|p| {
            format!(
                "{}{}{} offset {}",
                p.site,
                if p.present { " present" } else { " absent" },
                if p.lost { " lost" } else { "" },
                p.clock_offset_us
                    .map_or("unknown".to_owned(), |o| format!("{o:.0} µs"))
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    format!(
        "{} {}{} [{children}] network {{{}; published {} received {} rejected {} refused {:?} \
         held for offset {}; peers: {peers}}} physics {{remote {} rejected {} adoptions {}}}",
        s.station,
        s.run_state,
        if s.degraded { " degraded" } else { "" },
        s.network.locators,
        s.network.published,
        s.network.received,
        s.network.rejected,
        s.network.refused,
        s.network.held_for_offset,
        s.physics.remote_received,
        s.physics.remote_rejected,
        s.physics.adoptions,
    )
}

/// `station status --json --config CFG` run by the `station` binary at `station`: the status as
/// JSON.
///
/// # Panics
/// The command cannot run, fails (its stderr is shown), or prints no JSON.
pub fn station_status_json(station: &str, cfg: &std::path::Path) -> serde_json::Value {
    let out = Command::new(station)
        .args(["status", "--json", "--config"])
        .arg(cfg)
        .output()
        .expect("station status");
    assert!(
        out.status.success(),
        "station status: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("station status: JSON")
}

/// A child process that is SIGKILLed and reaped when dropped, so a failing test leaves no process.
#[derive(Debug)]
pub struct Reaped(pub Option<Child>);

impl Reaped {
    /// Spawns `cmd` with stdout piped.
    ///
    /// # Panics
    /// If the program cannot be started.
    pub fn spawn(cmd: &mut Command) -> Self {
        Self(Some(
            cmd.stdout(Stdio::piped())
                .spawn()
                .unwrap_or_else(|e| panic!("cannot start {cmd:?}: {e}")),
        ))
    }
    /// The child's pid.
    pub fn pid(&self) -> u32 {
        self.0.as_ref().map_or(0, Child::id)
    }
    /// Sends SIGKILL.
    pub fn kill(&mut self) {
        if let Some(c) = self.0.as_mut() {
            let _ = c.kill();
        }
    }
    /// Waits up to `limit` for the child to exit; its status, or `None` (it is left running).
    pub fn wait_timeout(&mut self, limit: Duration) -> Option<std::process::ExitStatus> {
        let start = Instant::now();
        let c = self.0.as_mut()?;
        while start.elapsed() < limit {
            if let Ok(Some(s)) = c.try_wait() {
                return Some(s);
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        None
    }
    /// Waits for exit and returns (success, stdout).
    ///
    /// # Panics
    /// If waiting fails.
    pub fn finish(mut self) -> (std::process::ExitStatus, String) {
        let child = self.0.take().expect("child present");
        let out = child.wait_with_output().expect("wait for child");
        (
            out.status,
            String::from_utf8_lossy(&out.stdout).into_owned(),
        )
    }
}

impl Drop for Reaped {
    fn drop(&mut self) {
        // A failing test (unwinding) first asks the child to stop (SIGTERM), so a station removes
        // its shared-memory segments as it does on Ctrl-C; SIGKILL after 3 s, or at once otherwise.
        if std::thread::panicking() {
            if let Some(c) = self.0.as_ref() {
                if let Ok(pid) = i32::try_from(c.id()) {
                    let _ = nix::sys::signal::kill(
                        nix::unistd::Pid::from_raw(pid),
                        nix::sys::signal::Signal::SIGTERM,
                    );
                }
            }
            let _ = self.wait_timeout(Duration::from_secs(3));
        }
        if let Some(mut c) = self.0.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Reads the first line a child printed on stdout (fixtures print `ready` once set up).
///
/// # Panics
/// If the child closed stdout without a line.
pub fn first_line(child: &mut Reaped) -> String {
    use std::io::BufRead;
    let out = child
        .0
        .as_mut()
        .and_then(|c| c.stdout.as_mut())
        .expect("piped stdout");
    let mut line = String::new();
    std::io::BufReader::new(out)
        .read_line(&mut line)
        .expect("read child stdout");
    assert!(!line.is_empty(), "child exited before printing a line");
    line.trim().to_owned()
}

/// Names of every entry in /dev/shm that starts with `prefix`.
pub fn shm_entries(prefix: &str) -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.filter_map(|e| e.ok()?.file_name().into_string().ok())
                .filter(|n| n.starts_with(prefix))
                .collect()
        })
        .unwrap_or_default()
}

/// One user pressing a disk against a wall: a one-site scenario (`name = "press"`, servo at
/// 1 kHz) with the disk at rest at the origin on a table under g/3 and a wall at x = 4.5 cm, its
/// user's `script` (TOML inline array of keyframes), `tables` added before the site (whole TOML
/// tables: `[contact]`, `[display]`, …) and `site_fields` added to the site (TOML lines).
pub fn press_scenario(tables: &str, site_fields: &str, script: &str) -> String {
    format!(
        "name = \"press\"\nduration_s = 600.0\n\
         [object]\nstart_m = [0.0, 0.0, 0.0099]\n\
         [world]\ngravity_m_per_s2 = [0.0, 0.0, -3.27]\n\
         planes = [{{ normal = [0.0, 0.0, 1.0], offset_m = 0.0 }}, {{ normal = [-1.0, 0.0, 0.0], offset_m = -0.045 }}]\n\
         {tables}\
         [[site]]\nname = \"user1\"\nservo_rate_hz = 1000.0\ndevice_base_m = [-0.3, -0.2, 0.0]\n\
         {site_fields}\
         script = {script}\n"
    )
}

/// Writes a station configuration for a test into `dir` and returns its path: the session, the
/// station, no mlockall, no `/dev/cpu_dma_latency`, and both loops under SCHED_OTHER priority 0
/// (parallel tests need no privilege and starve nothing; the loops still sleep to absolute
/// deadlines); `edit` changes what the test needs. Written by the configuration's own serialiser.
///
/// # Panics
/// If the directory or file cannot be written.
pub fn station_config(
    dir: &std::path::Path,
    session: &str,
    station: &str,
    edit: impl FnOnce(&mut StationConfig),
) -> std::path::PathBuf {
    let mut c = StationConfig {
        session: session.to_owned(),
        station: Some(station.to_owned()),
        mlockall: false,
        cpu_dma_latency_zero: false,
        ..StationConfig::default()
    };
    for l in [&mut c.servo, &mut c.physics] {
        l.policy = "other".into();
        l.priority = Some(0);
    }
    edit(&mut c);
    std::fs::create_dir_all(dir).expect("config dir");
    let path = dir.join(format!("{station}.toml"));
    std::fs::write(&path, c.to_toml().expect("config as TOML")).expect("write config");
    path
}

/// The paper's world (`scenarios/paper.toml`: object, contacts, both sites' devices and rates)
/// with other users' scripts and duration, and no phases: `user1` and `user2` are TOML keyframe
/// arrays, e.g. `[{ t_s = 0.0, target_m = [-0.2, 0.0, 0.01] }]`.
///
/// # Panics
/// If `scenarios/paper.toml` has not two sites, or a script is not TOML.
pub fn paper_with_scripts(name: &str, duration_s: f64, user1: &str, user2: &str) -> String {
    ScenarioToml::paper()
        .set("name", name)
        .set("duration_s", duration_s)
        .set_toml("site.0.script", user1)
        .set_toml("site.1.script", user2)
        .remove("phase")
        .text()
}

/// Runs `ip` with `args`; `Err` with its message when it fails (network-namespace tests).
///
/// # Errors
/// `ip` is missing or refuses (no root, no CAP_SYS_ADMIN, no iproute2).
pub fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip {args:?}: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// Network namespaces a test made; deleted on drop, whatever happened (deleting a namespace
/// deletes the veth ends inside it, and with them their peers).
#[derive(Debug)]
pub struct Namespaces {
    /// Their names.
    pub names: Vec<String>,
}

impl Drop for Namespaces {
    fn drop(&mut self) {
        for n in &self.names {
            let _ = ip(&["netns", "delete", n]);
        }
    }
}

/// Whether time namespaces are permitted here (`unshare --time`: root or CAP_SYS_ADMIN, Linux ≥
/// 5.6); `Err` with `unshare`'s message when not.
///
/// # Errors
/// `unshare` is missing or refuses.
pub fn time_namespaces_work() -> Result<(), String> {
    let out = Command::new("unshare")
        .args(["--time", "--monotonic", "1", "--fork", "true"])
        .output()
        .map_err(|e| format!("unshare: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).trim().to_owned())
    }
}

/// The arguments that run a program (appended after them) in a new time namespace whose
/// CLOCK_MONOTONIC is `shift_s` ahead, as another machine's clock is: `unshare --time --monotonic
/// SHIFT --fork --kill-child=SIGTERM --` (the program gets SIGTERM when `unshare` dies).
pub fn shifted_clock(shift_s: i64) -> Vec<String> {
    [
        "unshare",
        "--time",
        "--monotonic",
        &shift_s.to_string(),
        "--fork",
        "--kill-child=SIGTERM",
        "--",
    ]
    .map(str::to_owned)
    .to_vec()
}

/// Python with `packages` importable (module names), or `None` (skip) when one is missing and
/// CI does not require them (`COOP_REQUIRE_MCAP_PY`, set by `.ci/run`: then a missing package
/// fails the test).
///
/// # Panics
/// A package missing while CI requires them.
pub fn python_with(packages: &[&str]) -> Option<()> {
    let imports = packages.join(", ");
    let ok = Command::new("python3")
        .args(["-c", &format!("import {imports}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(());
    }
    if std::env::var_os("COOP_REQUIRE_MCAP_PY").is_some() {
        panic!("python3 with {imports} is required (pip install {imports})");
    }
    eprintln!("SKIPPED the foreign-reader check: python3 -c 'import {imports}' fails");
    None
}
