//! The configuration's rules: each check names the field, the value and the rule it breaks (the
//! caller adds the file). Checks use positive containment, so NaN fails. Only
//! [`Resolved::check_listen_ports_free`] looks at the machine as it is now; the others look at the
//! values, or at the files they name.

use std::path::Path;
use std::time::Duration;

use coop_model::scenario::Scenario;
use coop_rt::shm::control::Child;
use coop_rt::shm::SegmentName;
use coop_transport::network::{Locator, Mode, NetworkConfig, Tls};

use super::{Problem, Resolved, StationConfig, SupervisorSpec};

/// The session's name can make segment names.
pub(super) fn session(session: &str) -> Result<(), Problem> {
    SegmentName::station_prefix(session, "x")
        .map(drop)
        .map_err(|e| Problem::value("session", format!("{session:?}"), e.to_string()))
}

/// Methods that step on one tick grid for the session need every site at the same physics rate.
pub(super) fn one_tick_grid(scenario: &Scenario) -> Result<(), Problem> {
    if !scenario.steps_on_grid(scenario.method) {
        return Ok(());
    }
    let r0 = scenario.site[0].physics_rate_hz;
    let Some((k, s)) = scenario
        .site
        .iter()
        .enumerate()
        .find(|(_, s)| s.physics_rate_hz != r0)
    else {
        return Ok(());
    };
    Err(Problem::value(
        format!("site[{k}].physics_rate_hz"),
        format!("{} (scenario {:?})", s.physics_rate_hz, scenario.name),
        format!(
            "method {} steps every site on one tick grid, so every site's physics rate must equal site[0]'s ({r0} Hz)",
            scenario.method.as_str()
        ),
    ))
}

/// Publishing to ROS 2 needs site and object names that make ROS 2 names.
pub(super) fn ros2_names(scenario: &Scenario) -> Result<(), Problem> {
    coop_transport::ros2::check_names(
        scenario.site.iter().map(|s| s.name.as_str()),
        scenario.objects.iter().map(|o| o.name.as_str()),
    )
    .map_err(|e| {
        Problem::value(
            "ros2.publish",
            true,
            format!("scenario {:?}: {e}", scenario.name),
        )
    })
}

/// The site named `name`'s index in `scenario`.
pub(super) fn site_named(name: &str, scenario: &Scenario) -> Result<usize, Problem> {
    scenario
        .site
        .iter()
        .position(|s| s.name == name)
        .ok_or_else(|| {
            let sites: Vec<&str> = scenario.site.iter().map(|s| s.name.as_str()).collect();
            Problem::value(
                "station",
                format!("{name:?}"),
                format!(
                    "names no site of scenario {:?} (its sites: {})",
                    scenario.name,
                    sites.join(", ")
                ),
            )
        })
}

impl StationConfig {
    /// The rules that need only the file's values (no file they name, no look at the machine).
    pub(super) fn check_values(&self) -> Result<(), Problem> {
        self.check_rings()?;
        network_rules(&self.network)?;
        if let Some(age) = self.network.max_state_age_ms {
            if !(10.0..=60_000.0).contains(&age) {
                let rule = "must be from 10 to 60000 ms";
                return Err(Problem::value("network.max_state_age_ms", age, rule));
            }
        }
        let lost = self.network.lost_after_reports;
        if !(2..=10_000).contains(&lost) {
            let rule = "must be from 2 to 10000 report periods";
            return Err(Problem::value("network.lost_after_reports", lost, rule));
        }
        self.check_record_bounds()?;
        self.check_trials()?;
        if let Some(l) = &self.live {
            if coop_transport::live_view::parse_addr(l).is_err() {
                return Err(Problem::value(
                    "live",
                    format!("{l:?}"),
                    format!(
                        "not an address such as {} (host:port; port 0 picks a free one)",
                        coop_transport::live_view::DEFAULT_ADDR
                    ),
                ));
            }
        }
        self.ros2.validate().map_err(Problem::Stated)
    }

    /// A study's station waits for its trials' time 0, and runs its own servo loop (leaving the
    /// vendor's between trials is not supported).
    fn check_trials(&self) -> Result<(), Problem> {
        if !self.trials {
            return Ok(());
        }
        if self.start != super::StartMode::Session {
            let rule = "a study's station (trials = true) starts each trial at the time 0 the study runner announces: set start = \"session\"";
            return Err(Problem::value("start", "\"now\"", rule));
        }
        if self.device.loop_owner == crate::station::device::LoopOwner::Vendor {
            let rule = "a study's station (trials = true) runs the servo loop itself: the device's own loop is not left and re-entered between trials (set device.loop = \"station\")";
            return Err(Problem::value("device.loop", "\"vendor\"", rule));
        }
        Ok(())
    }

    /// Every ring's slots are a power of two the segment can hold.
    fn check_rings(&self) -> Result<(), Problem> {
        for (field, slots) in [
            ("rings.tool_slots", self.rings.tool_slots),
            ("rings.object_slots", self.rings.object_slots),
            ("rings.report_slots", self.rings.report_slots),
            ("rings.remote_slots", self.rings.remote_slots),
            ("rings.trace_slots", self.rings.trace_slots),
            ("rings.track_slots", self.rings.track_slots),
        ] {
            if !(slots.is_power_of_two() && (2..=65536).contains(&slots)) {
                let rule = "must be a power of two from 2 to 65536";
                return Err(Problem::value(field, slots, rule));
            }
        }
        Ok(())
    }

    /// Checks the recording's bounds.
    fn check_record_bounds(&self) -> Result<(), Problem> {
        for (field, v, hi) in [
            ("record_max_file_mib", self.record_max_file_mib, 65_536),
            ("record_max_file_s", self.record_max_file_s, 86_400),
        ] {
            if !(1..=hi).contains(&v) {
                return Err(Problem::value(field, v, format!("must be from 1 to {hi}")));
            }
        }
        if self.record_keep_files == 1 {
            return Err(Problem::value(
                "record_keep_files",
                1,
                "must be 0 (keep all) or at least 2 (1 would remove each part as soon as it is finished)",
            ));
        }
        Ok(())
    }
}

/// The supervisor's window and delays are within what a person would mean.
pub(super) fn supervisor_rules(sup: &SupervisorSpec) -> Result<(), Problem> {
    if !(sup.restart_window_s > 0.0 && sup.restart_window_s <= 3600.0) {
        let rule = "must be above 0 and at most 3600";
        return Err(Problem::value(
            "supervisor.restart_window_s",
            sup.restart_window_s,
            rule,
        ));
    }
    for (field, v, lo) in [
        ("supervisor.backoff_initial_ms", sup.backoff_initial_ms, 1),
        (
            "supervisor.backoff_max_ms",
            sup.backoff_max_ms,
            sup.backoff_initial_ms,
        ),
        (
            "supervisor.heartbeat_timeout_ms",
            sup.heartbeat_timeout_ms,
            10,
        ),
        ("supervisor.startup_timeout_ms", sup.startup_timeout_ms, 10),
        (
            "supervisor.network_backoff_max_ms",
            sup.network_backoff_max_ms,
            sup.backoff_initial_ms,
        ),
    ] {
        if !(lo..=600_000).contains(&v) {
            return Err(Problem::value(
                field,
                v,
                format!("must be from {lo} to 600000"),
            ));
        }
    }
    Ok(())
}

/// Which way a `[network]` locator list goes: what a `tls/` locator needs differs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Direction {
    /// `network.listen`.
    Listen,
    /// `network.connect`.
    Connect,
}

impl Direction {
    /// The list's field.
    fn field(self) -> &'static str {
        match self {
            Direction::Listen => "network.listen",
            Direction::Connect => "network.connect",
        }
    }
}

/// The `[network]` rules that need no look at the machine: every locator is a zenoh endpoint of a
/// transport this build has; no port (but 0) is listened on twice; client mode has routers to go
/// through; a `tls/` locator has the TLS files it needs named.
fn network_rules(net: &NetworkConfig) -> Result<(), Problem> {
    let mut listening: Vec<(&String, Locator)> = Vec::new();
    for (dir, list) in [
        (Direction::Listen, &net.listen),
        (Direction::Connect, &net.connect),
    ] {
        let field = dir.field();
        for l in list {
            if l.len() > 256 {
                return Err(Problem::entry(
                    field,
                    format!("{l:?}"),
                    "a locator is at most 256 bytes",
                ));
            }
            let loc = Locator::parse(l).map_err(|e| Problem::entry(field, format!("{l:?}"), e))?;
            // Client mode does not listen (zenoh ignores `listen` there).
            let listens = dir == Direction::Listen && net.mode == Mode::Peer;
            if listens && loc.port != 0 {
                if let Some((other, _)) = listening.iter().find(|(_, o)| o.overlaps(&loc)) {
                    return Err(Problem::entry(
                        field,
                        format!("{other:?} and {l:?}"),
                        "the same port twice (each port is listened on once)",
                    ));
                }
            }
            if loc.protocol == "tls" && (listens || dir == Direction::Connect) {
                let missing = missing_tls_files(net, listens);
                if !missing.is_empty() {
                    let table = if net.tls.is_none() {
                        "a [network.tls] table with"
                    } else {
                        "[network.tls]"
                    };
                    let rule = format!("a tls/ locator needs {table} {}", missing.join(" and "));
                    return Err(Problem::entry(field, format!("{l:?}"), rule));
                }
            }
            if listens {
                listening.push((l, loc));
            }
        }
    }
    own_certificate_rules(net)?;
    if net.mode == Mode::Client && net.connect.is_empty() {
        return Err(Problem::Needs {
            field: "network.mode".into(),
            value: "\"client\"".into(),
            needs: "network.connect: the zenohd routers to go through".into(),
        });
    }
    Ok(())
}

/// The `[network.tls]` files a `tls/` locator needs that are not named: listening (`listens`) or
/// connecting.
fn missing_tls_files(net: &NetworkConfig, listens: bool) -> Vec<&'static str> {
    let t = net.tls.clone().unwrap_or_default();
    let needs: [(&'static str, bool); 3] = if listens {
        [
            ("listen_certificate", t.listen_certificate.is_some()),
            ("listen_private_key", t.listen_private_key.is_some()),
            (
                "root_ca_certificate (enable_mtls)",
                !t.enable_mtls || t.root_ca_certificate.is_some(),
            ),
        ]
    } else {
        [
            ("root_ca_certificate", t.root_ca_certificate.is_some()),
            (
                "connect_certificate (enable_mtls)",
                !t.enable_mtls || t.connect_certificate.is_some(),
            ),
            (
                "connect_private_key (enable_mtls)",
                !t.enable_mtls || t.connect_private_key.is_some(),
            ),
        ]
    };
    needs
        .iter()
        .filter(|(_, ok)| !ok)
        .map(|(n, _)| *n)
        .collect()
}

/// A station given TLS presents its own certificate (common name = its site name: what the
/// access control knows it by) in every direction it uses TLS, and access control needs mutual
/// TLS (its rules name certificates).
fn own_certificate_rules(net: &NetworkConfig) -> Result<(), Problem> {
    let access_control = |rule: &str| {
        let a = net.access_control.as_deref().unwrap_or(Path::new(""));
        Problem::value(
            "network.access_control",
            format!("{:?}", a.display().to_string()),
            format!("{rule} (its rules name the certificates stations present)"),
        )
    };
    let Some(t) = &net.tls else {
        if net.access_control.is_some() {
            return Err(access_control(
                "needs [network.tls] with enable_mtls = true",
            ));
        }
        return Ok(());
    };
    let tls = |l: &String| l.starts_with("tls/");
    let connects = net.connect.iter().any(tls);
    let listens = net.mode == Mode::Peer && net.listen.iter().any(tls);
    for (dir, uses, field, ok) in [
        (
            Direction::Connect,
            connects,
            "connect_certificate",
            t.connect_certificate.is_some(),
        ),
        (
            Direction::Connect,
            connects,
            "connect_private_key",
            t.connect_private_key.is_some(),
        ),
        (
            Direction::Listen,
            listens,
            "listen_certificate",
            t.listen_certificate.is_some(),
        ),
        (
            Direction::Listen,
            listens,
            "listen_private_key",
            t.listen_private_key.is_some(),
        ),
    ] {
        if uses && !ok {
            let how = match dir {
                Direction::Connect => "connects",
                Direction::Listen => "listens",
            };
            return Err(Problem::missing(
                format!("network.tls.{field}"),
                format!("a station that {how} over TLS presents its own certificate (common name = its site name; `session certs` makes one)"),
            ));
        }
    }
    if net.access_control.is_some() && !t.enable_mtls {
        return Err(access_control("needs network.tls.enable_mtls = true"));
    }
    Ok(())
}

/// Rebases `t`'s files on `base` (relative paths are relative to the configuration file) and
/// checks each one opens as a regular file (opened, not only looked at: zenoh reads them at every
/// start of the network); `prefix` names the table in messages.
///
/// # Errors
/// A file that cannot be read or is not a regular file, naming `<prefix>.<field>` and the path.
pub(crate) fn tls_files_readable(
    t: &mut Tls,
    base: Option<&Path>,
    prefix: &str,
) -> Result<(), Problem> {
    for (field, f) in t.files_mut() {
        let Some(p) = f else { continue };
        if let Some(b) = base.filter(|_| p.is_relative()) {
            *p = b.join(&*p);
        }
        readable(&format!("{prefix}.{field}"), p)?;
    }
    Ok(())
}

/// The certificates `t` names for this side to present are `name`'s: each one's common name (what
/// the access control knows a certificate by) or one of its alternative names is `name`. A station
/// (or router) holding another's certificate would start and link, and then speak under the other's
/// name; `prefix` names the table, `who` this side in the message (`station user1`).
///
/// # Errors
/// A certificate that does not parse, or names another, naming the field, the file, the name it
/// holds and the one it should.
pub(crate) fn certificates_name(
    t: &Tls,
    prefix: &str,
    name: &str,
    who: &str,
) -> Result<(), Problem> {
    for (field, path) in [
        ("connect_certificate", &t.connect_certificate),
        ("listen_certificate", &t.listen_certificate),
    ] {
        let Some(p) = path else { continue };
        let field = format!("{prefix}.{field}");
        let shown = format!("{:?}", p.display().to_string());
        let names = coop_transport::network::probe::certificate_names(p)
            .map_err(|e| Problem::value(&field, &shown, e))?;
        if !names.names(name) {
            let holds = names.common_name.map_or_else(
                || {
                    format!(
                        "has no common name and names {}",
                        names.alt_names.join(", ")
                    )
                },
                |cn| format!("is {cn}'s certificate (common name {cn:?})"),
            );
            return Err(Problem::value(
                field,
                shown,
                format!("{holds}, not {who}'s: each side presents its own certificate, which the access control knows it by (`session certs` wrote {name}.pem for {name})"),
            ));
        }
    }
    Ok(())
}

/// `field = path` opens and is a regular file.
///
/// # Errors
/// It cannot be read, or it is a directory or a special file.
pub(crate) fn readable(field: &str, p: &Path) -> Result<(), Problem> {
    let shown = format!("{:?}", p.display().to_string());
    if let Err(e) = std::fs::File::open(p) {
        return Err(Problem::value(field, shown, format!("cannot be read: {e}")));
    }
    if !p.is_file() {
        return Err(Problem::value(field, shown, "must be a regular file"));
    }
    Ok(())
}

/// `network.access_control` opens.
pub(super) fn access_control_readable(a: &Path) -> Result<(), Problem> {
    std::fs::File::open(a).map(drop).map_err(|e| {
        let shown = format!("{:?}", a.display().to_string());
        Problem::value(
            "network.access_control",
            shown,
            format!("cannot be read: {e}"),
        )
    })
}

/// The recording's rules: its directory exists and is writable (none is created), and the path
/// is a regular file or not there yet (not a directory, a device or a pipe: `/dev/full` would take
/// the recording and fail every write).
pub(super) fn record_rules(path: &Path) -> Result<(), Problem> {
    let shown = format!("{:?}", path.display().to_string());
    let broken = |rule: String| Problem::value("record", &shown, rule);
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let dir_shown = format!("{:?}", dir.display().to_string());
    match std::fs::metadata(dir) {
        Err(e) => {
            return Err(broken(format!(
                "its directory {dir_shown} cannot be used ({e}); it is not created, make it first"
            )))
        }
        Ok(m) if !m.is_dir() => return Err(broken(format!("{dir_shown} is not a directory"))),
        Ok(_) => {}
    }
    if let Err(e) = nix::unistd::access(dir, nix::unistd::AccessFlags::W_OK) {
        return Err(broken(format!(
            "its directory {dir_shown} is not writable ({e})"
        )));
    }
    match std::fs::metadata(path) {
        Ok(m) if !m.is_file() => Err(broken(format!(
            "must be a regular file (it is {})",
            not_a_file(&m)
        ))),
        Ok(_) => nix::unistd::access(path, nix::unistd::AccessFlags::W_OK)
            .map_err(|e| broken(format!("is not writable ({e})"))),
        Err(_) => Ok(()),
    }
}

/// What a path that is not a regular file is, in words.
fn not_a_file(m: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = m.file_type();
    if t.is_dir() {
        "a directory"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_fifo() {
        "a pipe"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a file"
    }
}

/// The fix of a listen port that is taken.
const TAKEN: &str = "choose a free port, or 0 for one chosen at start";

impl Resolved {
    /// How long `child` has from its start to its first heartbeat before the supervisor kills it
    /// as hung: `supervisor.startup_timeout_ms`, and for the servo that plus its device's own
    /// start wait ([`crate::station::device::DeviceSetup::start_wait`]), so a device that is allowed
    /// to take its time opening is not killed for it, and a device that does not open ends with
    /// its own error rather than as a hung servo.
    pub fn startup_timeout(&self, child: Child) -> Duration {
        let limit = Duration::from_millis(self.config.supervisor.startup_timeout_ms);
        match child {
            Child::Servo => limit + self.device.start_wait(),
            Child::Physics | Child::Network => limit,
        }
    }

    /// The rules that look at the machine as it is now, checked by `station run` before it creates
    /// anything (not by every resolve: a child re-reads the configuration while its station's
    /// network process holds the ports): every listen port that is not 0 is free, the live
    /// view's too.
    ///
    /// # Errors
    /// A taken port (or an address of another machine), naming the field and the value; the
    /// caller adds the file ([`super::ConfigError::in_file`]).
    pub fn check_listen_ports_free(&self) -> Result<(), Problem> {
        if let Some(l) = &self.config.live {
            let shown = format!("{l:?}");
            let addr = coop_transport::live_view::parse_addr(l)
                .map_err(|_| Problem::value("live", &shown, "not an address (host:port)"))?;
            if addr.port() != 0 {
                if let Err(e) = std::net::TcpListener::bind(addr) {
                    let rule = format!("cannot listen there now ({e}); {TAKEN}");
                    return Err(Problem::value("live", shown, rule));
                }
            }
        }
        let net = &self.config.network;
        if net.mode == Mode::Client {
            return Ok(());
        }
        listen_ports_free("network.listen", &net.listen)
    }
}

/// Every locator of the list `field` whose port is not 0 can be listened on now (a station's
/// `network.listen`, a router's `listen`): zenoh would fail on it with its raw listener error.
///
/// # Errors
/// A taken port (or an address of another machine), naming the field, the locator and the rule.
pub(crate) fn listen_ports_free(field: &str, listen: &[String]) -> Result<(), Problem> {
    for l in listen {
        let shown = format!("{l:?}");
        let loc = Locator::parse(l).map_err(|e| Problem::entry(field, &shown, e))?;
        if loc.port != 0 {
            if let Err(e) = loc.bind_check() {
                let rule = format!("cannot listen there now ({e}); {TAKEN}");
                return Err(Problem::entry(field, shown, rule));
            }
        }
    }
    Ok(())
}
