//! Finding why a link does not come up.
//!
//! Zenoh reports every failed link the same way (`Unable to connect to any of [...]`) and keeps
//! the cause in its log: a router that is down, a certificate of another CA, an address its
//! certificate does not name and a missing `--certs` all read alike. So when zenoh cannot open,
//! [`probe`] reaches the endpoint the way zenoh's link would: a TCP connect (refused: nothing
//! listens), then, for `tls/`, a TLS handshake with rustls (zenoh's own TLS library) from the same
//! files, the same roots (the session's CA and the web's) and the same protocol versions. rustls
//! tells the causes apart: an issuer it does not know, a name the certificate does not hold, or an
//! alert from the other side refusing ours. The cause comes back as a [`LinkFailure`], which says
//! it and its fix. [`LinkWatch`] probes the links zenoh retries without a word.
//!
//! [`certificate_names`] reads the names a certificate holds, so that a station can check at start
//! that its certificate is its own site's.

use std::io::{self, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName};
use rustls::{AlertDescription, CertificateError, ClientConnection, RootCertStore};

use super::config::{Locator, Tls};
use super::link::{Cause, LinkFailure, Side};

/// How long each step of a probe may take: the TCP connect, and each read or write of the TLS
/// handshake. A refusal comes at once; this only bounds an address that swallows packets.
pub const PROBE_TIMEOUT: Duration = Duration::from_secs(3);

/// Probes every locator of `connect`; the ones that fail (empty: zenoh's failure was not the
/// links').
pub fn diagnose(connect: &[String], tls: Option<&Tls>, side: Side) -> Vec<LinkFailure> {
    connect
        .iter()
        .filter_map(|l| probe(l, tls, side).err())
        .collect()
}

/// Reaches `locator` as zenoh's link would, with this side's `tls` files.
///
/// # Errors
/// Why the link fails, when it does.
pub fn probe(locator: &str, tls: Option<&Tls>, side: Side) -> Result<(), LinkFailure> {
    let fail = |cause| LinkFailure {
        locator: locator.to_owned(),
        side,
        cause: Box::new(cause),
    };
    let loc = Locator::parse(locator).map_err(|e| fail(Cause::Unreachable(e)))?;
    let tcp = connect(&loc).map_err(fail)?;
    if loc.protocol != "tls" {
        return Ok(());
    }
    handshake(tcp, &loc, tls).map_err(fail)
}

/// A TCP connection to the locator's address (the first of its addresses that takes one).
fn connect(loc: &Locator) -> Result<TcpStream, Cause> {
    let host = loc.host.trim_start_matches('[').trim_end_matches(']');
    let addrs: Vec<_> = (host, loc.port)
        .to_socket_addrs()
        .map_err(|e| Cause::Unreachable(format!("{host} does not resolve: {e}")))?
        .collect();
    let mut refused = false;
    let mut other = None;
    for a in &addrs {
        match TcpStream::connect_timeout(a, PROBE_TIMEOUT) {
            Ok(s) => return Ok(s),
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => refused = true,
            Err(e) => other = Some(e.to_string()),
        }
    }
    match (refused, other) {
        (true, None) => Err(Cause::NothingListens),
        (_, Some(why)) => Err(Cause::Unreachable(why)),
        (false, None) => Err(Cause::Unreachable(format!("{host} has no address"))),
    }
}

/// The TLS client zenoh's link would be: the web's roots and the session's CA; with mutual TLS,
/// TLS 1.3 only and this side's certificate (zenoh's `TlsClientConfig`).
fn client_config(tls: Option<&Tls>) -> Result<rustls::ClientConfig, Cause> {
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let t = tls.cloned().unwrap_or_default();
    let mut roots = RootCertStore {
        roots: webpki_roots::TLS_SERVER_ROOTS.to_vec(),
    };
    if let Some(ca) = &t.root_ca_certificate {
        let own = |reason: String| Cause::OwnFile {
            field: "root_ca_certificate",
            path: ca.clone(),
            reason,
        };
        let certs = CertificateDer::pem_file_iter(ca)
            .and_then(|i| i.collect::<Result<Vec<_>, _>>())
            .map_err(|e| own(e.to_string()))?;
        if certs.is_empty() {
            return Err(own("it holds no PEM certificate".into()));
        }
        for c in certs {
            roots.add(c).map_err(|e| own(e.to_string()))?;
        }
    }
    let versions: &[&rustls::SupportedProtocolVersion] = if t.enable_mtls {
        &[&rustls::version::TLS13]
    } else {
        rustls::DEFAULT_VERSIONS
    };
    let builder = rustls::ClientConfig::builder_with_provider(provider)
        .with_protocol_versions(versions)
        .map_err(|e| Cause::Tls(e.to_string()))?
        .with_root_certificates(roots);
    match (&t.connect_certificate, &t.connect_private_key) {
        (Some(cert), Some(key)) if t.enable_mtls => {
            let certs = CertificateDer::pem_file_iter(cert)
                .and_then(|i| i.collect::<Result<Vec<_>, _>>())
                .map_err(|e| Cause::OwnFile {
                    field: "connect_certificate",
                    path: cert.clone(),
                    reason: e.to_string(),
                })?;
            let key = PrivateKeyDer::from_pem_file(key).map_err(|e| Cause::OwnFile {
                field: "connect_private_key",
                path: key.clone(),
                reason: e.to_string(),
            })?;
            builder
                .with_client_auth_cert(certs, key)
                .map_err(|e| Cause::OwnFile {
                    field: "connect_certificate",
                    path: cert.clone(),
                    reason: e.to_string(),
                })
        }
        _ => Ok(builder.with_no_client_auth()),
    }
}

/// The TLS handshake over `tcp`, and the far side's verdict on this side's certificate.
fn handshake(mut tcp: TcpStream, loc: &Locator, tls: Option<&Tls>) -> Result<(), Cause> {
    let t = tls.cloned().unwrap_or_default();
    let config = client_config(tls)?;
    let host = loc.host.trim_start_matches('[').trim_end_matches(']');
    let name = ServerName::try_from(host.to_owned())
        .map_err(|e| Cause::Tls(format!("{host} is no server name: {e}")))?;
    let mut conn =
        ClientConnection::new(Arc::new(config), name).map_err(|e| Cause::Tls(e.to_string()))?;
    let timeouts = tcp
        .set_read_timeout(Some(PROBE_TIMEOUT))
        .and_then(|()| tcp.set_write_timeout(Some(PROBE_TIMEOUT)));
    timeouts.map_err(|e| Cause::Unreachable(e.to_string()))?;
    let refused = |e: rustls::Error| classify(e, host, &t);
    while conn.is_handshaking() {
        match conn.complete_io(&mut tcp) {
            Ok((0, 0)) => {
                return Err(Cause::NotTls(
                    "it closed the connection during the TLS handshake".into(),
                ))
            }
            Ok(_) => {}
            Err(e) => return Err(io_cause(e, &refused)),
        }
    }
    // NB: in TLS 1.3 this side's handshake is over before the far side has checked this side's
    // certificate: its verdict is the next thing it sends, session tickets (taken) or an alert
    // (refused). Nothing within the timeout is taken as taken: a refusal comes at once.
    let verdict = loop {
        match conn.read_tls(&mut tcp) {
            Ok(0) => break Err(Cause::Closed),
            Ok(_) => break conn.process_new_packets().map(drop).map_err(&refused),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                break Ok(())
            }
            Err(_) => break Err(Cause::Closed),
        }
    };
    conn.send_close_notify();
    let _ = conn.write_tls(&mut tcp);
    let _ = tcp.flush();
    verdict
}

/// An I/O error of the handshake: rustls' own error inside, or the socket's.
fn io_cause(e: io::Error, refused: &dyn Fn(rustls::Error) -> Cause) -> Cause {
    if let Some(r) = e.get_ref().and_then(|i| i.downcast_ref::<rustls::Error>()) {
        return refused(r.clone());
    }
    match e.kind() {
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut => Cause::NotTls(format!(
            "no TLS handshake within {} s",
            PROBE_TIMEOUT.as_secs()
        )),
        io::ErrorKind::UnexpectedEof
        | io::ErrorKind::ConnectionReset
        | io::ErrorKind::BrokenPipe => {
            Cause::NotTls("it closed the connection during the TLS handshake".into())
        }
        _ => Cause::Tls(e.to_string()),
    }
}

/// rustls' error, as a cause (`host` the name connected to, `t` this side's files).
fn classify(e: rustls::Error, host: &str, t: &Tls) -> Cause {
    use rustls::Error as E;
    match e {
        E::InvalidCertificate(CertificateError::UnknownIssuer) => Cause::UnknownIssuer {
            root_ca: t.root_ca_certificate.clone(),
        },
        E::InvalidCertificate(CertificateError::NotValidForNameContext { presented, .. }) => {
            Cause::NotValidForName {
                host: host.to_owned(),
                presented: presented.iter().map(|n| plain_name(n)).collect(),
            }
        }
        E::InvalidCertificate(CertificateError::NotValidForName) => Cause::NotValidForName {
            host: host.to_owned(),
            presented: Vec::new(),
        },
        E::InvalidCertificate(c) => Cause::TheirCertificate(format!("{c:?}")),
        E::AlertReceived(a) if refuses_certificate(a) => Cause::Refused {
            alert: alert_words(a),
            presented: t
                .enable_mtls
                .then(|| t.connect_certificate.clone())
                .flatten(),
        },
        E::InvalidMessage(_)
        | E::InappropriateMessage { .. }
        | E::InappropriateHandshakeMessage { .. } => {
            Cause::NotTls(format!("it answered something else: {e}"))
        }
        other => Cause::Tls(other.to_string()),
    }
}

/// A name as rustls' verifier presents it (`DnsName("r1")`, `IpAddress(0::1)`), as a person
/// would write it (`r1`, `::1`).
fn plain_name(n: &str) -> String {
    let inner = n
        .strip_prefix("DnsName(\"")
        .and_then(|r| r.strip_suffix("\")"))
        .or_else(|| {
            n.strip_prefix("IpAddress(")
                .and_then(|r| r.strip_suffix(')'))
        })
        .unwrap_or(n);
    inner
        .parse::<std::net::IpAddr>()
        .map_or_else(|_| inner.to_owned(), |ip| ip.to_string())
}

/// Whether an alert is the far side refusing this side's certificate.
fn refuses_certificate(a: AlertDescription) -> bool {
    matches!(
        a,
        AlertDescription::BadCertificate
            | AlertDescription::UnsupportedCertificate
            | AlertDescription::CertificateRevoked
            | AlertDescription::CertificateExpired
            | AlertDescription::CertificateUnknown
            | AlertDescription::UnknownCA
            | AlertDescription::AccessDenied
            | AlertDescription::CertificateRequired
            | AlertDescription::DecryptError
    )
}

/// The alert's name and what it means for this side's certificate.
fn alert_words(a: AlertDescription) -> String {
    let means = match a {
        AlertDescription::UnknownCA => "not signed by a CA it trusts",
        AlertDescription::CertificateExpired => "expired, or not valid yet",
        AlertDescription::CertificateRequired => "it requires one",
        AlertDescription::DecryptError => "its signature does not check",
        AlertDescription::CertificateRevoked => "revoked",
        _ => "it does not take it",
    };
    format!("it answered {a:?}: {means}")
}

/// How often [`LinkWatch`] probes: a cause is said within this of appearing or going.
pub const WATCH_EVERY: Duration = Duration::from_secs(5);

/// Watches links zenoh keeps retrying in the background without a word: a router's connects to
/// other routers and a peer's to other stations (their sessions open without them). Each locator
/// is probed every [`WATCH_EVERY`], and a cause is said (through `say`) when it is new, then
/// `<locator> answers now` once it goes; the same cause again says nothing. The thread ends when
/// the watch is dropped (at once when it waits; after its probe when it probes, which the drop
/// does not wait for: a probe of an address that swallows packets would hold a stop ladder).
#[derive(Debug)]
pub struct LinkWatch {
    /// Dropped to stop the thread.
    _stop: std::sync::mpsc::Sender<()>,
}

impl LinkWatch {
    /// Starts watching `connect` with this side's `tls` files. With `down_too` false, a locator
    /// where nothing listens (or that cannot be reached) says nothing: a peer that is not up yet is
    /// how a session of peers starts.
    ///
    /// # Errors
    /// The thread cannot be started.
    pub fn start(
        connect: Vec<String>,
        tls: Option<Tls>,
        side: Side,
        down_too: bool,
        say: impl Fn(&str) + Send + 'static,
    ) -> io::Result<Self> {
        let (stop, stopped) = std::sync::mpsc::channel::<()>();
        std::thread::Builder::new()
            .name("link-watch".into())
            .spawn(move || {
                let mut said: Vec<Option<Cause>> = vec![None; connect.len()];
                loop {
                    for (l, last) in connect.iter().zip(&mut said) {
                        watch_one(l, tls.as_ref(), side, down_too, last, &say);
                    }
                    match stopped.recv_timeout(WATCH_EVERY) {
                        Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                        _ => return,
                    }
                }
            })?;
        Ok(Self { _stop: stop })
    }
}

/// One probe of `locator` for [`LinkWatch`]: says its cause if it differs from `last` (the one
/// said before), or that it answers now, and keeps what it said in `last`.
fn watch_one(
    locator: &str,
    tls: Option<&Tls>,
    side: Side,
    down_too: bool,
    last: &mut Option<Cause>,
    say: &dyn Fn(&str),
) {
    let now = match probe(locator, tls, side) {
        Ok(()) => None,
        Err(f)
            if !down_too && matches!(*f.cause, Cause::NothingListens | Cause::Unreachable(_)) =>
        {
            return
        }
        Err(f) => Some(f),
    };
    match (&now, &*last) {
        (Some(f), Some(c)) if *f.cause == *c => {}
        (Some(f), _) => say(&f.to_string()),
        (None, Some(_)) => say(&format!("{locator} answers now")),
        (None, None) => {}
    }
    *last = now.map(|f| *f.cause);
}

/// The names a certificate holds: its subject's common name (what zenoh's access control knows it
/// by) and its subject alternative names (host names and addresses).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CertificateNames {
    /// The subject's common name, if it has one.
    pub common_name: Option<String>,
    /// Its DNS names and IP addresses.
    pub alt_names: Vec<String>,
}

impl CertificateNames {
    /// Whether `name` is its common name or one of its alternative names.
    pub fn names(&self, name: &str) -> bool {
        self.common_name.as_deref() == Some(name) || self.alt_names.iter().any(|n| n == name)
    }
}

/// The names the first certificate of the PEM file at `path` holds.
///
/// # Errors
/// The file cannot be read or holds no certificate that parses (in words for a message that
/// names the field and the file).
pub fn certificate_names(path: &Path) -> Result<CertificateNames, String> {
    let mut bytes = Vec::new();
    std::fs::File::open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(|e| format!("cannot be read: {e}"))?;
    let (_, pem) = x509_parser::pem::parse_x509_pem(&bytes)
        .map_err(|_| "holds no PEM certificate".to_owned())?;
    let cert = pem
        .parse_x509()
        .map_err(|e| format!("holds no certificate that parses: {e}"))?;
    let common_name = cert
        .subject()
        .iter_common_name()
        .next()
        .and_then(|cn| cn.as_str().ok())
        .map(str::to_owned);
    let mut alt_names = Vec::new();
    if let Ok(Some(san)) = cert.subject_alternative_name() {
        for n in &san.value.general_names {
            match n {
                x509_parser::extensions::GeneralName::DNSName(d) => alt_names.push((*d).to_owned()),
                x509_parser::extensions::GeneralName::IPAddress(b) => {
                    let ip = match b.len() {
                        4 => <[u8; 4]>::try_from(*b).ok().map(std::net::IpAddr::from),
                        16 => <[u8; 16]>::try_from(*b).ok().map(std::net::IpAddr::from),
                        _ => None,
                    };
                    alt_names.extend(ip.map(|i| i.to_string()));
                }
                _ => {}
            }
        }
    }
    Ok(CertificateNames {
        common_name,
        alt_names,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::link::STATION;

    #[test]
    fn names_read_as_written() {
        assert_eq!(plain_name("DnsName(\"r1\")"), "r1");
        assert_eq!(plain_name("IpAddress(127.0.0.1)"), "127.0.0.1");
        assert_eq!(plain_name("IpAddress(0::1)"), "::1");
        assert_eq!(plain_name("other"), "other");
    }

    /// A port nobody listens on reads as nothing listening, tcp or tls alike; a plain TCP
    /// listener takes a tcp/ probe and does not answer a tls/ one.
    #[test]
    fn nothing_listening_and_no_tls_are_told_apart() {
        let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = l.local_addr().expect("addr").port();
        // Takes each connection and closes it, answering nothing.
        let server = std::thread::spawn(move || {
            for _ in 0..2 {
                drop(l.accept().expect("accept"));
            }
        });
        assert_eq!(
            probe(&format!("tcp/127.0.0.1:{port}"), None, STATION),
            Ok(())
        );
        let e = probe(&format!("tls/127.0.0.1:{port}"), None, STATION).expect_err("no TLS");
        assert!(matches!(*e.cause, Cause::NotTls(_)), "{e}");
        server.join().expect("server");
        let free = std::net::TcpListener::bind("127.0.0.1:0")
            .expect("bind")
            .local_addr()
            .expect("addr")
            .port();
        for proto in ["tcp", "tls"] {
            let e = probe(&format!("{proto}/127.0.0.1:{free}"), None, STATION)
                .expect_err("nothing there");
            assert_eq!(*e.cause, Cause::NothingListens, "{e}");
        }
    }
}
