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

use anyhow::{bail, Context};
use coop_transport::network::{Locator, Tls};
use coop_transport::router::{self, Refusals, RouterEndpoints, RouterStatus};
use serde::{Deserialize, Serialize};

use crate::station::config::{readable, tls_files_readable};

/// The router's configuration file (TOML).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    pub fn load(path: &Path) -> anyhow::Result<ResolvedRouter> {
        let shown = path.display();
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading router config {shown}"))?;
        let c: RouterConfig = toml::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}", e.to_string().trim_end()))
            .with_context(|| format!("router config {shown}"))?;
        c.resolve(path.parent())
            .with_context(|| format!("router config {shown}"))
    }

    /// Checks every value (relative paths are relative to `base`).
    ///
    /// # Errors
    /// As [`RouterConfig::load`].
    pub fn resolve(mut self, base: Option<&Path>) -> anyhow::Result<ResolvedRouter> {
        if self.name.is_empty()
            || self.name.len() > 64
            || !self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            bail!(
                "name = {:?}: must be 1 to 64 letters, digits, - or _ (its certificate's common name)",
                self.name
            );
        }
        if self.listen.is_empty() {
            bail!("listen = []: a router listens on at least one locator");
        }
        let mut tls_used = false;
        for (field, list) in [("listen", &self.listen), ("connect", &self.connect)] {
            for l in list {
                let loc = Locator::parse(l)
                    .map_err(|e| anyhow::anyhow!("{field} contains {l:?}: {e}"))?;
                tls_used |= loc.protocol == "tls";
            }
        }
        let rebase = |p: &mut PathBuf| {
            if let Some(b) = base.filter(|_| p.is_relative()) {
                *p = b.join(&*p);
            }
        };
        if let Some(t) = &mut self.tls {
            tls_files_readable(t, base, "tls")?;
        }
        let t = self.tls.clone().unwrap_or_default();
        if tls_used {
            for (field, ok) in [
                ("listen_certificate", t.listen_certificate.is_some()),
                ("listen_private_key", t.listen_private_key.is_some()),
                ("root_ca_certificate", t.root_ca_certificate.is_some()),
            ] {
                if !ok {
                    bail!("tls.{field} is missing: a router with tls/ locators needs its own certificate, its key and the session's CA");
                }
            }
            if !self.connect.is_empty()
                && (t.connect_certificate.is_none() || t.connect_private_key.is_none())
            {
                bail!("tls.connect_certificate and tls.connect_private_key are needed to connect to other routers over TLS (the router's own certificate)");
            }
        }
        if let Some(acl) = &mut self.access_control {
            rebase(acl);
            readable("access_control", acl)?;
            if !t.enable_mtls {
                bail!(
                    "access_control = {:?}: needs tls.enable_mtls = true (its rules name the certificates the others present)",
                    acl.display().to_string()
                );
            }
        }
        if !(50..=60_000).contains(&self.status_every_ms) {
            bail!(
                "status_every_ms = {}: must be from 50 to 60000",
                self.status_every_ms
            );
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
        router::router_config(&endpoints).map_err(|e| anyhow::anyhow!("{e}"))?;
        Ok(ResolvedRouter {
            config: self,
            endpoints,
            status_file,
        })
    }
}

/// Writes `s` to `path` whole (a reader never sees half a file).
fn write_status(path: &Path, s: &RouterStatus) -> anyhow::Result<()> {
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    std::fs::write(&tmp, serde_json::to_vec_pretty(s)?)
        .with_context(|| format!("writing the router's status to {}", tmp.display()))?;
    std::fs::rename(&tmp, path)
        .with_context(|| format!("writing the router's status to {}", path.display()))
}

/// Runs the router until `stop` says so (or `duration` passes); its last status.
///
/// # Errors
/// The router cannot open (a port taken, a file zenoh refuses), or its status cannot be written.
pub fn run(
    r: &ResolvedRouter,
    duration: Option<Duration>,
    stop: &dyn Fn() -> bool,
) -> anyhow::Result<RouterStatus> {
    let refusals = Refusals::install().map_err(anyhow::Error::msg)?;
    if let Some(pid) = live_writer(&r.status_file) {
        bail!(
            "router {}: its status file {} is written by another running router (pid {pid}); give this one a status_file of its own",
            r.config.name,
            r.status_file.display()
        );
    }
    let session =
        router::open(&r.endpoints).map_err(|e| anyhow::anyhow!("router {}: {e}", r.config.name))?;
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
pub fn read_status(r: &ResolvedRouter) -> anyhow::Result<RouterStatus> {
    let p = &r.status_file;
    let text = std::fs::read(p).with_context(|| {
        format!(
            "router {} is not running (no status file {})",
            r.config.name,
            p.display()
        )
    })?;
    let s: RouterStatus = serde_json::from_slice(&text)
        .with_context(|| format!("reading the router's status {}", p.display()))?;
    if nix::sys::signal::kill(nix::unistd::Pid::from_raw(s.pid as i32), None).is_err() {
        bail!(
            "router {} is not running: its status file {} was left by pid {}, which is gone",
            r.config.name,
            p.display(),
            s.pid
        );
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
            let msg = format!("{err:#}");
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
        let msg = format!("{:#}", RouterConfig::load(&f).expect_err("no mtls"));
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
        let e = run(&r, Some(Duration::from_millis(10)), &|| true).expect_err("a live clash");
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
