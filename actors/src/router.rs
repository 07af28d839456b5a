//! `station router`: a zenoh router for a session across machines, from a configuration file.
//! Stations in client mode connect to it (`network.mode = "client"`, `network.connect`); it
//! listens on the locators of the file, presents its own certificate, requires the others'
//! (mutual TLS), and enforces the session's access control (`session certs` writes the file) on
//! every link, so that a station holding one site's certificate cannot speak for another.
//!
//! It writes its status ([`coop_transport::router::RouterStatus`]) to a small JSON file every
//! `status_every_ms`, which `station router status` reads (a router has no shared memory with
//! anything), and removes it when it stops.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use coop_transport::network::link::{Far, Files, Side};
use coop_transport::network::probe::LinkWatch;
use coop_transport::network::{Locator, Tls};
use coop_transport::router::{self, Refusals, RouterEndpoints, RouterStatus};
use serde::{Deserialize, Serialize};

use crate::station::config::{
    certificates_name, listen_ports_free, readable, tls_files_readable, Problem,
};

/// Why a router could not be configured, run, or its status read.
#[derive(Debug, thiserror::Error)]
pub enum RouterError {
    /// The configuration file cannot be read.
    #[error("reading router config {}", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        error: std::io::Error,
    },
    /// The configuration file breaks a rule.
    #[error("router config {}", .path.display())]
    Config {
        /// The file.
        path: PathBuf,
        /// The field, the value and the rule.
        #[source]
        problem: Problem,
    },
    /// Values given whole (no file) break a rule that looks at the machine.
    #[error("router {name}")]
    Values {
        /// The router.
        name: String,
        /// The field, the value and the rule.
        #[source]
        problem: Problem,
    },
    /// Another running router writes this router's status file.
    #[error("router {name}: its status file {} is written by another running router (pid {pid}); give this one a status_file of its own", .file.display())]
    StatusFileTaken {
        /// This router.
        name: String,
        /// The status file.
        file: PathBuf,
        /// The other router's pid.
        pid: u32,
    },
    /// Zenoh did not open the router.
    #[error("router {name}: {error}")]
    Open {
        /// The router.
        name: String,
        /// Why.
        error: coop_transport::network::NetworkError,
    },
    /// The status does not serialise.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The status file cannot be written.
    #[error("writing the router's status to {}", .file.display())]
    Write {
        /// The file (or its temporary twin).
        file: PathBuf,
        /// Why.
        #[source]
        error: std::io::Error,
    },
    /// No status file: the router is not running, or writes it elsewhere.
    #[error("router {name} is not running (no status file {})", .file.display())]
    NotRunning {
        /// The router.
        name: String,
        /// The status file looked for.
        file: PathBuf,
        /// Why it cannot be read.
        #[source]
        error: std::io::Error,
    },
    /// The status file does not hold a status.
    #[error("reading the router's status {}", .file.display())]
    BadStatus {
        /// The status file.
        file: PathBuf,
        /// Why.
        #[source]
        error: serde_json::Error,
    },
    /// The router that wrote the status file is gone.
    #[error("router {name} is not running: its status file {} was left by pid {pid}, which is gone", .file.display())]
    Gone {
        /// The router.
        name: String,
        /// The status file.
        file: PathBuf,
        /// The pid that wrote it.
        pid: u32,
    },
}

/// The router's configuration file (TOML).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RouterConfig {
    /// Its name: its certificate's common name (what the access control knows it by).
    pub name: String,
    /// Zenoh locators to listen on, e.g. `tls/0.0.0.0:7447`.
    pub listen: Vec<String>,
    /// Other routers to connect to.
    #[serde(default)]
    pub connect: Vec<String>,
    /// TLS files (relative to the file's directory): the session's CA, this router's
    /// certificate and key, mutual TLS.
    pub tls: Option<Tls>,
    /// The session's access control (relative to the file's directory), as `session certs`
    /// writes it. Without it, anyone who can connect may say anything.
    pub access_control: Option<PathBuf>,
    /// Where the status goes (default `/tmp/coop_router_<name>_<port>.json`, the port of its first
    /// `listen` locator: two routers that share a name on one machine, say in two sessions or
    /// parallel tests, cannot share a port, so they do not share a status file either).
    pub status_file: Option<PathBuf>,
    /// How often the status is written, ms.
    #[serde(default = "default_status_every_ms")]
    pub status_every_ms: u64,
}

fn default_status_every_ms() -> u64 {
    500
}

/// A configuration with its paths made absolute and every value checked.
#[derive(Debug, Clone)]
pub struct ResolvedRouter {
    /// The file it was read from (none: values given whole).
    pub file: Option<PathBuf>,
    /// The file's values.
    pub config: RouterConfig,
    /// What zenoh is given.
    pub endpoints: RouterEndpoints,
    /// Where the status goes.
    pub status_file: PathBuf,
}

impl RouterConfig {
    /// Reads `path` and checks it.
    ///
    /// # Errors
    /// Unreadable file, bad TOML, unknown field, or a value that breaks a rule (the message names
    /// the file, the field, the value and the rule).
    pub fn load(path: &Path) -> Result<ResolvedRouter, RouterError> {
        let text = std::fs::read_to_string(path).map_err(|error| RouterError::Read {
            path: path.to_owned(),
            error,
        })?;
        let in_file = |problem| RouterError::Config {
            path: path.to_owned(),
            problem,
        };
        let c: RouterConfig = toml::from_str(&text).map_err(|e| in_file(Problem::Toml(e)))?;
        let mut r = c.resolve(path.parent()).map_err(in_file)?;
        r.file = Some(path.to_owned());
        Ok(r)
    }

    /// Checks every value (relative paths are relative to `base`).
    ///
    /// # Errors
    /// As [`RouterConfig::load`].
    /// # Errors
    /// As [`RouterConfig::load`], without the file.
    pub fn resolve(mut self, base: Option<&Path>) -> Result<ResolvedRouter, Problem> {
        self.check_values()?;
        let tls_used = self
            .listen
            .iter()
            .chain(&self.connect)
            .any(|l| Locator::parse(l).is_ok_and(|l| l.protocol == "tls"));
        let rebase = |p: &mut PathBuf| {
            if let Some(b) = base.filter(|_| p.is_relative()) {
                *p = b.join(&*p);
            }
        };
        if let Some(t) = &mut self.tls {
            tls_files_readable(t, base, "tls")?;
            let who = format!("router {}", self.name);
            certificates_name(t, "tls", &self.name, &who)?;
        }
        let t = self.tls.clone().unwrap_or_default();
        if tls_used {
            own_certificate_rules(&t, !self.connect.is_empty())?;
        }
        if let Some(acl) = &mut self.access_control {
            rebase(acl);
            readable("access_control", acl)?;
            if !t.enable_mtls {
                return Err(Problem::value(
                    "access_control",
                    format!("{:?}", acl.display().to_string()),
                    "needs tls.enable_mtls = true (its rules name the certificates the others present)",
                ));
            }
        }
        if !(50..=60_000).contains(&self.status_every_ms) {
            let rule = "must be from 50 to 60000";
            return Err(Problem::value(
                "status_every_ms",
                self.status_every_ms,
                rule,
            ));
        }
        let status_file = match &mut self.status_file {
            Some(p) => {
                rebase(p);
                p.clone()
            }
            None => {
                // Checked above: at least one locator, each of which parses.
                let port = Locator::parse(&self.listen[0]).map_or(0, |l| l.port);
                std::env::temp_dir().join(format!("coop_router_{}_{port}.json", self.name))
            }
        };
        let endpoints = RouterEndpoints {
            listen: self.listen.clone(),
            connect: self.connect.clone(),
            tls: self.tls.clone(),
            access_control: self.access_control.clone(),
        };
        // Zenoh's own checks of the files (the access control's rules, subjects and policies
        // are checked when it opens).
        router::router_config(&endpoints).map_err(|e| Problem::Zenoh(Box::new(e)))?;
        Ok(ResolvedRouter {
            file: None,
            config: self,
            endpoints,
            status_file,
        })
    }

    /// The rules that need only the file's values: the name, the locators, the status period.
    fn check_values(&self) -> Result<(), Problem> {
        if self.name.is_empty()
            || self.name.len() > 64
            || !self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            return Err(Problem::value(
                "name",
                format!("{:?}", self.name),
                "must be 1 to 64 letters, digits, - or _ (its certificate's common name)",
            ));
        }
        if self.listen.is_empty() {
            let rule = "a router listens on at least one locator";
            return Err(Problem::value("listen", "[]", rule));
        }
        for (field, list) in [("listen", &self.listen), ("connect", &self.connect)] {
            for l in list {
                Locator::parse(l).map_err(|e| Problem::entry(field, format!("{l:?}"), e))?;
            }
        }
        Ok(())
    }
}

/// A router with `tls/` locators presents its own certificate, its key and the session's CA; and
/// to connect to other routers (`connects`) its own client certificate.
fn own_certificate_rules(t: &Tls, connects: bool) -> Result<(), Problem> {
    for (field, ok) in [
        ("listen_certificate", t.listen_certificate.is_some()),
        ("listen_private_key", t.listen_private_key.is_some()),
        ("root_ca_certificate", t.root_ca_certificate.is_some()),
    ] {
        if !ok {
            return Err(Problem::missing(
                format!("tls.{field}"),
                "a router with tls/ locators needs its own certificate, its key and the session's CA",
            ));
        }
    }
    if connects && (t.connect_certificate.is_none() || t.connect_private_key.is_none()) {
        return Err(Problem::Stated("tls.connect_certificate and tls.connect_private_key are needed to connect to other routers over TLS (the router's own certificate)".into()));
    }
    Ok(())
}

/// Writes `s` to `path` whole (a reader never sees half a file).
fn write_status(path: &Path, s: &RouterStatus) -> Result<(), RouterError> {
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    let writing = |file: &Path| {
        let file = file.to_owned();
        move |error| RouterError::Write { file, error }
    };
    std::fs::write(&tmp, serde_json::to_vec_pretty(s)?).map_err(writing(&tmp))?;
    std::fs::rename(&tmp, path).map_err(writing(path))
}

/// Runs the router until `stop` says so (or `duration` passes), `refusals` counting what its
/// access control refuses (the process's tracing subscriber, which the binary installs with
/// [`Refusals::install`]: a library does not choose a process's subscriber); its last status.
///
/// # Errors
/// Another running router writes its status file, the router cannot open (a port taken, a file
/// zenoh refuses), or its status cannot be written.
pub fn run(
    r: &ResolvedRouter,
    duration: Option<Duration>,
    stop: &dyn Fn() -> bool,
    refusals: &Refusals,
) -> Result<RouterStatus, RouterError> {
    if let Some(pid) = live_writer(&r.status_file) {
        return Err(RouterError::StatusFileTaken {
            name: r.config.name.clone(),
            file: r.status_file.clone(),
            pid,
        });
    }
    // Checked here, as a station checks its own: zenoh's listener error says neither the field
    // nor the fix.
    listen_ports_free("listen", &r.endpoints.listen).map_err(|problem| match &r.file {
        Some(path) => RouterError::Config {
            path: path.clone(),
            problem,
        },
        None => RouterError::Values {
            name: r.config.name.clone(),
            problem,
        },
    })?;
    let session = router::open(&r.endpoints).map_err(|error| RouterError::Open {
        name: r.config.name.clone(),
        error,
    })?;
    let _watch = watch_links(r);
    let start = Instant::now();
    let every = Duration::from_millis(r.config.status_every_ms);
    let result = (|| loop {
        let s = router::status(&session, &r.config.name, &r.endpoints, refusals);
        write_status(&r.status_file, &s)?;
        let due = Instant::now() + every;
        while Instant::now() < due {
            if stop() || duration.is_some_and(|d| start.elapsed() >= d) {
                return Ok(s);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    })();
    // Ours to remove only while it is ours: a router started later with the same file (it was
    // refused above while this one ran, but not after) keeps its own.
    if status_pid(&r.status_file) == Some(std::process::id()) {
        let _ = std::fs::remove_file(&r.status_file);
    }
    router::close(&session);
    result
}

/// A router's session opens whether or not its links to other routers work, and zenoh retries
/// them without a word: they are watched, and each cause said once on stderr
/// ([`LinkWatch`]).
fn watch_links(r: &ResolvedRouter) -> Option<LinkWatch> {
    if r.endpoints.connect.is_empty() {
        return None;
    }
    let side = Side {
        me: "router",
        far: Far::Router,
        files: Files::Table("tls"),
    };
    let name = r.config.name.clone();
    let say = move |m: &str| eprintln!("router {name}: {m}");
    let connect = r.endpoints.connect.clone();
    match LinkWatch::start(connect, r.endpoints.tls.clone(), side, true, say) {
        Ok(w) => Some(w),
        Err(e) => {
            eprintln!(
                "router {}: its links to other routers are not watched ({e}): a link that fails will not be explained",
                r.config.name
            );
            None
        }
    }
}

/// The pid that wrote the status file at `path`, if it holds one.
fn status_pid(path: &Path) -> Option<u32> {
    let text = std::fs::read(path).ok()?;
    serde_json::from_slice::<RouterStatus>(&text)
        .ok()
        .map(|s| s.pid)
}

/// The pid of another process, still running, that writes the status file at `path`.
fn live_writer(path: &Path) -> Option<u32> {
    status_pid(path).filter(|&pid| {
        pid != std::process::id()
            && nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), None).is_ok()
    })
}

/// Reads a running router's status from its status file.
///
/// # Errors
/// No file (the router is not running, or writes it elsewhere), or the router that wrote it is
/// gone.
pub fn read_status(r: &ResolvedRouter) -> Result<RouterStatus, RouterError> {
    let p = &r.status_file;
    let text = std::fs::read(p).map_err(|error| RouterError::NotRunning {
        name: r.config.name.clone(),
        file: p.clone(),
        error,
    })?;
    let s: RouterStatus =
        serde_json::from_slice(&text).map_err(|error| RouterError::BadStatus {
            file: p.clone(),
            error,
        })?;
    if nix::sys::signal::kill(nix::unistd::Pid::from_raw(s.pid as i32), None).is_err() {
        return Err(RouterError::Gone {
            name: r.config.name.clone(),
            file: p.clone(),
            pid: s.pid,
        });
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_rule_names_field_value_and_rule() {
        let dir = std::env::temp_dir().join(format!("coop-router-cfg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        std::fs::write(dir.join("acl.json5"), "{}").expect("acl");
        let cases = [
            (
                "name = \"a b\"\nlisten = [\"tcp/127.0.0.1:0\"]",
                "name = \"a b\": must be",
            ),
            (
                "name = \"r1\"\nlisten = []",
                "listen = []: a router listens",
            ),
            (
                "name = \"r1\"\nlisten = [\"udp/127.0.0.1:0\"]",
                "listen contains \"udp/127.0.0.1:0\": transport \"udp\" is not in this build",
            ),
            (
                "name = \"r1\"\nlisten = [\"tls/127.0.0.1:0\"]",
                "tls.listen_certificate is missing",
            ),
            (
                "name = \"r1\"\nlisten = [\"tcp/127.0.0.1:0\"]\naccess_control = \"acl.json5\"",
                "access_control = ",
            ),
            (
                "name = \"r1\"\nlisten = [\"tcp/127.0.0.1:0\"]\naccess_control = \"nothere.json5\"",
                "access_control = \"",
            ),
            (
                "name = \"r1\"\nlisten = [\"tcp/127.0.0.1:0\"]\nstatus_every_ms = 1",
                "status_every_ms = 1: must be from 50",
            ),
            (
                "name = \"r1\"\nlisten = [\"tcp/127.0.0.1:0\"]\nlisen = []",
                "unknown field `lisen`",
            ),
        ];
        for (i, (text, needle)) in cases.iter().enumerate() {
            let f = dir.join(format!("r{i}.toml"));
            std::fs::write(&f, text).expect("config");
            let err = RouterConfig::load(&f).expect_err(text);
            let msg = crate::testing::chain(&err);
            assert!(msg.contains(needle), "{text}: {msg}");
            assert!(
                msg.contains(&f.display().to_string()),
                "names the file: {msg}"
            );
        }
        let f = dir.join("acl-mtls.toml");
        std::fs::write(
            &f,
            "name = \"r1\"\nlisten = [\"tcp/127.0.0.1:0\"]\naccess_control = \"acl.json5\"",
        )
        .expect("config");
        let msg = crate::testing::chain(&RouterConfig::load(&f).expect_err("no mtls"));
        assert!(msg.contains("needs tls.enable_mtls = true"), "{msg}");
        let ok = dir.join("ok.toml");
        std::fs::write(&ok, "name = \"r1\"\nlisten = [\"tcp/127.0.0.1:0\"]").expect("config");
        let r = RouterConfig::load(&ok).expect("valid");
        assert_eq!(
            r.status_file,
            std::env::temp_dir().join("coop_router_r1_0.json")
        );
        let ok7447 = dir.join("ok7447.toml");
        std::fs::write(&ok7447, "name = \"r1\"\nlisten = [\"tcp/127.0.0.1:7447\"]")
            .expect("config");
        assert_eq!(
            RouterConfig::load(&ok7447).expect("valid").status_file,
            std::env::temp_dir().join("coop_router_r1_7447.json"),
            "two routers r1 on one machine listen on different ports"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_status_file_another_running_router_writes_is_refused_and_left_alone() {
        let dir = std::env::temp_dir().join(format!("coop-router-clash-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let f = dir.join("r1.toml");
        let status = dir.join("r1.json");
        std::fs::write(
            &f,
            format!("name = \"r1\"\nlisten = [\"tcp/127.0.0.1:0\"]\nstatus_file = {status:?}"),
        )
        .expect("config");
        let r = RouterConfig::load(&f).expect("valid");
        // Another live process (this test's parent) wrote it.
        let other = RouterStatus {
            name: "r1".into(),
            pid: std::os::unix::process::parent_id(),
            t_ns: 0,
            zid: String::new(),
            listen: Vec::new(),
            connect: Vec::new(),
            access_control: false,
            sessions: Vec::new(),
            present: Vec::new(),
            refused: 0,
            refused_by_action: std::collections::BTreeMap::new(),
            recent_refusals: Vec::new(),
        };
        let written = serde_json::to_vec(&other).expect("json");
        std::fs::write(&status, &written).expect("status");
        // A counter not installed as the subscriber: the clash is refused before it counts.
        let refusals = Refusals::default();
        let e = run(&r, Some(Duration::from_millis(10)), &|| true, &refusals)
            .expect_err("a live clash");
        let msg = format!("{e:#}");
        assert!(
            msg.contains("written by another running router")
                && msg.contains(&other.pid.to_string()),
            "{msg}"
        );
        assert_eq!(std::fs::read(&status).expect("still there"), written);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
