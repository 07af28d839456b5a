//! The zenoh configuration of a station (or of a tool that joins a session): where it listens, whom
//! it connects to, peer or client, TLS. [`NetworkConfig`] reads as the station configuration's
//! `[network]` fields, so the station's file can embed it.

use std::path::PathBuf;

use super::NetworkError;

/// How the session reaches the others.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Stations connect to each other.
    #[default]
    Peer,
    /// Through the zenohd routers in `connect`.
    Client,
}

impl Mode {
    /// `peer` or `client`, as zenoh and the configuration files spell it.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Peer => "peer",
            Mode::Client => "client",
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The network process's configuration, the station configuration's `[network]` table: where the
/// zenoh session listens and whom it connects to, peer or client, TLS, and whether the scenario's
/// link is emulated on receive.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct NetworkConfig {
    /// Zenoh locators to listen on, e.g. `tcp/127.0.0.1:7447` (port 0: a free port, chosen here).
    /// Default: a free TCP port on loopback.
    pub listen: Vec<String>,
    /// Zenoh locators of peers or routers to connect to.
    pub connect: Vec<String>,
    /// Peer (default) or client.
    pub mode: Mode,
    /// TLS files, for `tls/` locators.
    pub tls: Option<Tls>,
    /// Zenoh access control (its `access_control` object, JSON5, as `session certs` writes it)
    /// enforced on this station's links: on a link to another station it refuses what that
    /// station's certificate may not say. Needs mutual TLS (the rules name certificates).
    pub access_control: Option<PathBuf>,
    /// Emulate the scenario's `[network]` link (delay, jitter, loss, seeded) on receive, so long
    /// delays can be run on one machine. Shown as EMULATED in status and recordings.
    pub emulate: bool,
    /// The oldest a received state may be when physics gets it, ms (older: refused, counted).
    /// Default: the scenario's largest delay plus jitter, three of its slowest report periods and
    /// 100 ms.
    pub max_state_age_ms: Option<f64>,
    /// A site silent for this many of its report periods (at least [`MIN_SILENCE_S`]) is lost.
    pub lost_after_reports: u32,
}

/// The shortest silence that makes a site lost, s (a loaded machine stalls for tens of ms).
pub const MIN_SILENCE_S: f64 = 0.25;

impl NetworkConfig {
    /// How long a site reporting at `report_rate_hz` may be silent before it is lost, ns.
    pub fn silence_ns(&self, report_rate_hz: f64) -> u64 {
        let s = (f64::from(self.lost_after_reports) / report_rate_hz).max(MIN_SILENCE_S);
        (s * 1e9) as u64
    }
}

impl Default for NetworkConfig {
    fn default() -> Self {
        Self {
            listen: vec!["tcp/127.0.0.1:0".into()],
            connect: Vec::new(),
            mode: Mode::Peer,
            tls: None,
            access_control: None,
            emulate: false,
            max_state_age_ms: None,
            lost_after_reports: 10,
        }
    }
}

/// TLS for `tls/<host>:<port>` locators: PEM files (zenoh's `transport/link/tls`). The
/// certificates are this side's own: a station's has its site name as common name, which is what
/// the access control knows it by.
#[derive(
    Debug, Clone, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
#[serde(deny_unknown_fields, default)]
pub struct Tls {
    /// CA certificate that signed the peers' (or routers') certificates.
    pub root_ca_certificate: Option<PathBuf>,
    /// This station's certificate when it listens.
    pub listen_certificate: Option<PathBuf>,
    /// Its private key.
    pub listen_private_key: Option<PathBuf>,
    /// This station's certificate when it connects (mutual TLS).
    pub connect_certificate: Option<PathBuf>,
    /// Its private key.
    pub connect_private_key: Option<PathBuf>,
    /// Require the connecting side's certificate (mutual TLS).
    pub enable_mtls: bool,
}

impl Tls {
    /// Its files by zenoh's (and the configuration's) field names.
    pub fn files(&self) -> [(&'static str, &Option<PathBuf>); 5] {
        [
            ("root_ca_certificate", &self.root_ca_certificate),
            ("listen_certificate", &self.listen_certificate),
            ("listen_private_key", &self.listen_private_key),
            ("connect_certificate", &self.connect_certificate),
            ("connect_private_key", &self.connect_private_key),
        ]
    }
    /// The same, to rebase them.
    pub fn files_mut(&mut self) -> [(&'static str, &mut Option<PathBuf>); 5] {
        [
            ("root_ca_certificate", &mut self.root_ca_certificate),
            ("listen_certificate", &mut self.listen_certificate),
            ("listen_private_key", &mut self.listen_private_key),
            ("connect_certificate", &mut self.connect_certificate),
            ("connect_private_key", &mut self.connect_private_key),
        ]
    }
}

/// The zenoh transports this build has (its `transport_*` features of zenoh): the protocols a
/// locator may name.
pub const TRANSPORTS: [&str; 2] = ["tcp", "tls"];

/// A locator as the station uses it: `<protocol>/<host>:<port>[?<metadata>][#<config>]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Locator {
    /// One of [`TRANSPORTS`].
    pub protocol: String,
    /// Host name or address (IPv6 in brackets, as written).
    pub host: String,
    /// Port (0: a free one, chosen at start).
    pub port: u16,
}

impl Locator {
    /// Parses `l` as zenoh does (an endpoint) and checks it names a transport of this build and a
    /// `host:port` address.
    ///
    /// # Errors
    /// The rule it breaks, in words for a message that names the field and the value.
    pub fn parse(l: &str) -> Result<Self, String> {
        let form = "a zenoh locator looks like tcp/127.0.0.1:7447";
        let e: zenoh::config::EndPoint = l.parse().map_err(|_| form.to_owned())?;
        let protocol = e.protocol().as_str().to_owned();
        if !TRANSPORTS.contains(&protocol.as_str()) {
            return Err(format!(
                "transport {protocol:?} is not in this build (it has {})",
                TRANSPORTS.join(" and ")
            ));
        }
        let address = e.address();
        let (host, port) = address
            .as_str()
            .rsplit_once(':')
            .filter(|(h, _)| !h.is_empty())
            .ok_or_else(|| format!("{form} (the address is host:port)"))?;
        let port = port
            .parse()
            .map_err(|_| format!("port {port:?} is not a number from 0 to 65535"))?;
        Ok(Self {
            protocol,
            host: host.to_owned(),
            port,
        })
    }

    /// The host as a socket address, if it is an address (not a name).
    pub fn ip(&self) -> Option<std::net::IpAddr> {
        self.host
            .trim_start_matches('[')
            .trim_end_matches(']')
            .parse()
            .ok()
    }

    /// Whether listening on both would take the same port: the same port, on the same host or
    /// with either on every address.
    pub fn overlaps(&self, other: &Self) -> bool {
        self.port == other.port
            && (self.host == other.host
                || self.ip().is_some_and(|a| a.is_unspecified())
                || other.ip().is_some_and(|a| a.is_unspecified()))
    }

    /// Binds the port now and lets it go: whether a listener could take it.
    ///
    /// # Errors
    /// Why it cannot (taken, an address of another machine, a name that does not resolve).
    pub fn bind_check(&self) -> std::io::Result<()> {
        let host = self.host.trim_start_matches('[').trim_end_matches(']');
        std::net::TcpListener::bind((host, self.port)).map(drop)
    }
}

/// A zenoh configuration: the mode, explicit endpoints, no multicast scouting, timestamps on.
///
/// # Errors
/// An endpoint or file zenoh does not accept.
pub fn config(endpoints: &NetworkConfig) -> Result<zenoh::Config, NetworkError> {
    let json = |v: &[String]| {
        format!(
            "[{}]",
            v.iter()
                .map(|e| format!("{e:?}"))
                .collect::<Vec<_>>()
                .join(",")
        )
    };
    let mut c = zenoh::Config::default();
    let mut set = |key: &str, value: &str| {
        c.insert_json5(key, value)
            .map_err(|error| NetworkError::Config {
                key: key.to_owned(),
                error,
            })
    };
    set("mode", &format!("{:?}", endpoints.mode.as_str()))?;
    set("scouting/multicast/enabled", "false")?;
    set("timestamping/enabled", "true")?;
    // A peer that stops reading (stalled, or hostile) must not stall the session: zenoh closes a
    // link a blocking message cannot enter within 0.2 s (default 5 s, longer than the watchdog's
    // 0.5 s), and a state that cannot go within 0.2 ms is dropped (the next one replaces it).
    let q = "transport/link/tx/queue/congestion_control";
    set(&format!("{q}/block/wait_before_close"), "200000")?;
    set(&format!("{q}/drop/wait_before_drop"), "200")?;
    // The size bound: zenoh reassembles fragmented messages up to this (default 1 GiB, which a
    // hostile peer could use to make us allocate); a state is 289 bytes.
    set("transport/link/rx/max_message_size", "65536")?;
    if let Some(t) = &endpoints.tls {
        let tls = "transport/link/tls";
        for (key, v) in t.files() {
            if let Some(path) = v {
                let path = path.display().to_string();
                set(&format!("{tls}/{key}"), &format!("{path:?}"))?;
            }
        }
        set(&format!("{tls}/enable_mtls"), &t.enable_mtls.to_string())?;
    }
    if endpoints.mode != Mode::Client {
        set("listen/endpoints", &json(&endpoints.listen))?;
    }
    set("connect/endpoints", &json(&endpoints.connect))?;
    if let Some(path) = &endpoints.access_control {
        let text = std::fs::read_to_string(path).map_err(|e| NetworkError::AccessControl {
            path: path.clone(),
            reason: e.to_string(),
        })?;
        c.insert_json5("access_control", &text)
            .map_err(|e| NetworkError::AccessControl {
                path: path.clone(),
                reason: e.to_string(),
            })?;
    }
    Ok(c)
}

/// The kernel's ephemeral port range, from which it picks the local port of every outgoing
/// connection and of a bind to port 0 (Linux's default where it cannot be read).
fn ephemeral_ports() -> (u16, u16) {
    std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
        .ok()
        .and_then(|s| {
            let mut w = s.split_whitespace().map(|w| w.parse::<u16>().ok());
            Some((w.next()??, w.next()??))
        })
        .filter(|(lo, hi)| lo <= hi)
        .unwrap_or((32768, 60999))
}

/// The lowest port [`free_port`] picks from (below it, the registered services).
const FIRST_PICKED_PORT: u16 = 10000;

/// A TCP port on `ip` that is free now and outside the kernel's ephemeral range, tried at random
/// (64 tries); `None` if none was free. A port the kernel picks for a bind to port 0 comes from
/// the ephemeral range, and so does the local port of every outgoing connection: between the
/// moment a launcher picks a station's port and the moment the station binds it, the stations'
/// and the launcher's own connections to each other could take it ("Address already in use").
/// Outside that range only another listener can.
fn free_port(ip: std::net::IpAddr) -> Option<u16> {
    use std::hash::{BuildHasher, Hasher};
    let (lo, hi) = ephemeral_ports();
    let below = u64::from(lo.saturating_sub(FIRST_PICKED_PORT));
    let above = u64::from(u16::MAX - hi);
    if below + above == 0 {
        return None;
    }
    let random = std::collections::hash_map::RandomState::new();
    (0..64u64).find_map(|i| {
        let mut h = random.build_hasher();
        h.write_u64(i);
        let k = h.finish() % (below + above);
        let port = if k < below {
            u64::from(FIRST_PICKED_PORT) + k
        } else {
            u64::from(hi) + 1 + (k - below)
        };
        let port = u16::try_from(port).ok()?;
        std::net::TcpListener::bind((ip, port)).ok().map(|_| port)
    })
}

/// Replaces port 0 of `tcp/<ip>:0` locators with a port that is free now, so the station knows (and
/// status shows) where it listens: outside the kernel's ephemeral range where one is free there
/// (`free_port` says why), else the kernel's choice.
pub fn concrete_listen(listen: &[String]) -> Vec<String> {
    listen
        .iter()
        .map(|l| {
            let Some(addr) = l.strip_prefix("tcp/") else {
                return l.clone();
            };
            let (host, tail) = match addr.split_once('#') {
                Some((h, t)) => (h, format!("#{t}")),
                None => (addr, String::new()),
            };
            match host.parse::<std::net::SocketAddr>() {
                Ok(sa) if sa.port() == 0 => match free_port(sa.ip()) {
                    Some(port) => format!("tcp/{}{tail}", std::net::SocketAddr::new(sa.ip(), port)),
                    None => std::net::TcpListener::bind(sa)
                        .and_then(|s| s.local_addr())
                        .map_or_else(|_| l.clone(), |a| format!("tcp/{a}{tail}")),
                },
                _ => l.clone(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A station's port 0 becomes a port free now, outside the range outgoing connections take
    /// their local ports from, and the same for every locator in a list (the suffix kept).
    #[test]
    fn port_zero_becomes_a_free_port_outside_the_ephemeral_range() {
        let (lo, hi) = ephemeral_ports();
        let got = concrete_listen(&[
            "tcp/127.0.0.1:0".into(),
            "tcp/127.0.0.1:0#iface=lo".into(),
            "tcp/127.0.0.1:7447".into(),
            "tls/127.0.0.1:0".into(),
        ]);
        let port = |l: &str| -> u16 {
            let a = l.strip_prefix("tcp/").expect("tcp");
            let a = a.split('#').next().expect("address");
            a.parse::<std::net::SocketAddr>().expect("address").port()
        };
        // (A kernel whose ephemeral range leaves no port from FIRST_PICKED_PORT up gets its own
        // choice.)
        let room = lo > FIRST_PICKED_PORT || hi < u16::MAX;
        for l in &got[..2] {
            let p = port(l);
            assert!(
                !room || (p >= FIRST_PICKED_PORT && !(lo..=hi).contains(&p)),
                "{l}: outside {lo}-{hi}"
            );
            std::net::TcpListener::bind(("127.0.0.1", p)).expect("free");
        }
        assert!(got[1].ends_with("#iface=lo"), "{}", got[1]);
        assert_eq!(got[2], "tcp/127.0.0.1:7447", "a given port is kept");
        assert_eq!(got[3], "tls/127.0.0.1:0", "only tcp is resolved here");
    }

    #[test]
    fn configurations_zenoh_accepts() {
        let mut e = NetworkConfig {
            listen: vec!["tcp/127.0.0.1:0".into()],
            connect: vec!["tcp/127.0.0.1:7447".into()],
            mode: Mode::Peer,
            tls: None,
            emulate: false,
            ..NetworkConfig::default()
        };
        assert!(config(&e).is_ok());
        e.mode = Mode::Client;
        assert!(config(&e).is_ok());
        e.tls = Some(Tls {
            root_ca_certificate: Some("/etc/coop/ca.pem".into()),
            listen_certificate: Some("/etc/coop/station.pem".into()),
            listen_private_key: Some("/etc/coop/station.key".into()),
            enable_mtls: true,
            ..Tls::default()
        });
        assert!(config(&e).is_ok());
        assert!(
            serde_json::from_str::<NetworkConfig>(r#"{"mode": "router-ish"}"#).is_err(),
            "an unknown mode is refused"
        );
        e.mode = Mode::Peer;
        e.listen = vec!["nonsense".into()];
        assert!(config(&e).is_err(), "a bad locator is refused");
    }

    #[test]
    fn endpoints_read_as_the_station_configuration_writes_them() {
        let e: NetworkConfig = serde_json::from_str(
            r#"{"connect": ["tls/r:7447"], "mode": "client",
                "tls": {"root_ca_certificate": "ca.pem", "enable_mtls": true}}"#,
        )
        .expect("the station's field names");
        assert_eq!(
            e.listen,
            NetworkConfig::default().listen,
            "defaults fill the rest"
        );
        assert_eq!(e.mode, Mode::Client);
        assert_eq!(
            e.tls.and_then(|t| t.root_ca_certificate),
            Some(PathBuf::from("ca.pem"))
        );
        assert_eq!(NetworkConfig::default().mode, Mode::Peer);
        assert!(serde_json::from_str::<NetworkConfig>(r#"{"lisen": []}"#).is_err());
    }

    #[test]
    fn locators_of_this_build_parse_and_others_are_refused() {
        let l = Locator::parse("tcp/127.0.0.1:7447").expect("tcp");
        assert_eq!(
            (l.protocol.as_str(), l.host.as_str(), l.port),
            ("tcp", "127.0.0.1", 7447)
        );
        let l = Locator::parse("tls/[::1]:0#iface=lo").expect("tls, v6, config");
        assert_eq!((l.host.as_str(), l.port), ("[::1]", 0));
        for (bad, why) in [
            ("localhost", "looks like"),
            ("tcp/", "looks like"),
            ("tcp/127.0.0.1", "host:port"),
            ("tcp/127.0.0.1:99999", "port \"99999\""),
            (
                "udp/127.0.0.1:7447",
                "transport \"udp\" is not in this build",
            ),
            ("quic/127.0.0.1:7447", "transport \"quic\""),
        ] {
            let e = Locator::parse(bad).expect_err(bad);
            assert!(e.contains(why), "{bad}: {e}");
        }
        let p = |l: &str| Locator::parse(l).expect("locator");
        assert!(p("tcp/0.0.0.0:7447").overlaps(&p("tls/127.0.0.1:7447")));
        assert!(p("tcp/localhost:7447").overlaps(&p("tcp/localhost:7447")));
        assert!(!p("tcp/127.0.0.1:7447").overlaps(&p("tcp/127.0.0.2:7447")));
        assert!(!p("tcp/127.0.0.1:7447").overlaps(&p("tcp/127.0.0.1:7448")));
        let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = taken.local_addr().expect("addr").port();
        assert!(p(&format!("tcp/127.0.0.1:{port}")).bind_check().is_err());
        drop(taken);
        assert!(p("tcp/127.0.0.1:0").bind_check().is_ok());
    }

    #[test]
    fn port_zero_becomes_a_concrete_free_port() {
        let l = concrete_listen(&["tcp/127.0.0.1:0".into(), "tcp/127.0.0.1:7447".into()]);
        assert!(
            l[0].starts_with("tcp/127.0.0.1:") && !l[0].ends_with(":0"),
            "{l:?}"
        );
        assert_eq!(l[1], "tcp/127.0.0.1:7447");
    }
}
