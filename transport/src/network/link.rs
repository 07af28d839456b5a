//! Why a link does not come up, in words a user can act on: [`LinkFailure`], a locator and its
//! [`Cause`], says the cause and its fix in the words of the side that met it ([`Side`]: a
//! station names its `network.tls` fields, a launcher its `--certs`). [`super::probe`] finds the
//! cause.

use std::path::{Path, PathBuf};

/// What is at the other end of a link, in messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Far {
    /// A zenoh router (`station router run`).
    Router,
    /// A station (peer mode).
    Station,
}

impl std::fmt::Display for Far {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Far::Router => "router",
            Far::Station => "station",
        })
    }
}

/// Where this side's TLS files were named: the words a message uses for them and for the fix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Files {
    /// A configuration table: `network.tls` (a station), `tls` (a router).
    Table(&'static str),
    /// The launcher's `--certs DIR`.
    CertsDir,
}

impl Files {
    /// `<table>.<field> (<path>)`, or `--certs (<path>)`.
    fn label(self, field: &str, path: &Path) -> String {
        match self {
            Files::Table(t) => format!("{t}.{field} ({})", path.display()),
            Files::CertsDir => format!("--certs ({})", path.display()),
        }
    }

    /// How to give this side the certificates it lacks.
    fn fix_no_certificates(self) -> String {
        match self {
            Files::Table(t) => format!(
                "name the session's CA and this side's own certificate in [{t}] (root_ca_certificate, connect_certificate, connect_private_key, enable_mtls = true; `session certs` makes them)"
            ),
            Files::CertsDir => "give --certs DIR, the directory `session certs` wrote (ca.pem, launcher.pem, launcher.key)".to_owned(),
        }
    }

    /// How to make this side present its certificate.
    fn fix_present(self) -> String {
        match self {
            Files::Table(t) => format!(
                "set {t}.enable_mtls = true with {t}.connect_certificate and {t}.connect_private_key (its own certificate from `session certs`)"
            ),
            Files::CertsDir => "give --certs DIR, the directory `session certs` wrote".to_owned(),
        }
    }
}

/// Who probes: the words of its messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Side {
    /// This side: `station`, `router` or `launcher`.
    pub me: &'static str,
    /// What it connects to.
    pub far: Far,
    /// Where its TLS files were named.
    pub files: Files,
}

/// Why a link fails, as found by [`probe`](super::probe::probe).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Cause {
    /// The TCP connect was refused.
    NothingListens,
    /// The TCP connect failed otherwise (a timeout, no route, a name that does not resolve).
    Unreachable(String),
    /// The far side's certificate is signed by a CA this side does not trust; `root_ca` the file
    /// of the CA it does trust (none: it has no certificates at all).
    UnknownIssuer {
        /// This side's `root_ca_certificate`.
        root_ca: Option<PathBuf>,
    },
    /// The far side's certificate does not name the host this side connects to.
    NotValidForName {
        /// The host of the locator.
        host: String,
        /// The names the certificate holds (empty: not told).
        presented: Vec<String>,
    },
    /// The far side's certificate is refused here for another reason (expired, not yet valid, ...).
    TheirCertificate(String),
    /// The far side refused this side's certificate (it sent this alert); `presented` the file
    /// this side presented (none: it presented no certificate).
    Refused {
        /// The alert, as rustls names it.
        alert: String,
        /// This side's `connect_certificate`, if it presented one.
        presented: Option<PathBuf>,
    },
    /// Something listens there, but does not answer TLS.
    NotTls(String),
    /// The far side closed the connection after the handshake, saying nothing.
    Closed,
    /// One of this side's own files cannot be used.
    OwnFile {
        /// Its field.
        field: &'static str,
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// TLS fails otherwise.
    Tls(String),
}

/// A link that fails, its cause, and whose words say it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkFailure {
    /// The locator.
    pub locator: String,
    /// Who probed.
    pub side: Side,
    /// Why it fails (boxed: a failure travels in `Result`s, and most of them succeed).
    pub cause: Box<Cause>,
}

impl std::error::Error for LinkFailure {}

impl std::fmt::Display for LinkFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (l, far, me, files) = (&self.locator, self.side.far, self.side.me, self.side.files);
        match &*self.cause {
            Cause::NothingListens => write!(f, "nothing listens on {l}: is the {far} running?"),
            Cause::Unreachable(why) => write!(
                f,
                "{l} cannot be reached ({why}): is the address right, and the {far}'s machine up and reachable from here?"
            ),
            Cause::UnknownIssuer { root_ca: Some(ca) } => write!(
                f,
                "the {far}'s certificate is not signed by the CA in {}: give the {me} the ca.pem that `session certs` wrote with the {far}'s certificate ({l} presented one of another CA)",
                files.label("root_ca_certificate", ca)
            ),
            Cause::UnknownIssuer { root_ca: None } => write!(
                f,
                "{l} is a TLS {far} and this {me} has no certificates: {}",
                files.fix_no_certificates()
            ),
            Cause::NotValidForName { host, presented } => {
                write!(f, "the {far}'s certificate does not name {host}")?;
                if !presented.is_empty() {
                    write!(f, " (it names {})", presented.join(", "))?;
                }
                write!(
                    f,
                    "; connect to {l} by a name it holds, or make the {far}'s certificate again with `session certs --host <its name>={host}`"
                )
            }
            Cause::TheirCertificate(why) => {
                write!(f, "the {far}'s certificate at {l} is refused here: {why}")
            }
            Cause::Refused {
                alert,
                presented: None,
            } => write!(
                f,
                "the {far} at {l} refused the handshake ({alert}): it wants this {me}'s certificate and none was presented; {}",
                files.fix_present()
            ),
            Cause::Refused {
                alert,
                presented: Some(p),
            } => write!(
                f,
                "the {far} at {l} refused this {me}'s certificate, {} ({alert}): is it signed by the CA the {far} trusts (made by the same `session certs` as the {far}'s)?",
                files.label("connect_certificate", p)
            ),
            Cause::NotTls(why) => write!(
                f,
                "{l} does not answer TLS ({why}): is it the {far}'s tcp/ locator? Give the one it listens on with TLS"
            ),
            Cause::Closed => write!(
                f,
                "the {far} at {l} closed the connection after the TLS handshake without saying why (its log may)"
            ),
            Cause::OwnFile {
                field,
                path,
                reason,
            } => write!(
                f,
                "{} cannot be used for TLS: {reason}",
                files.label(field, path)
            ),
            Cause::Tls(why) => write!(f, "TLS with the {far} at {l} fails: {why}"),
        }
    }
}

/// Several links that fail (each locator of a list), said one after the other.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkFailures(pub Vec<LinkFailure>);

impl std::error::Error for LinkFailures {}

impl std::fmt::Display for LinkFailures {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, l) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str("; and ")?;
            }
            write!(f, "{l}")?;
        }
        Ok(())
    }
}

/// A client station's side, for the tests of the link's words.
#[cfg(test)]
pub(crate) const STATION: Side = Side {
    me: "station",
    far: Far::Router,
    files: Files::Table("network.tls"),
};

#[cfg(test)]
mod tests {
    use super::*;

    fn failure(cause: Cause) -> String {
        LinkFailure {
            locator: "tls/127.0.0.1:7447".into(),
            side: STATION,
            cause: Box::new(cause),
        }
        .to_string()
    }

    /// Each cause says what is wrong and what to do, naming the field or the flag to change.
    #[test]
    fn each_cause_says_its_fix() {
        assert_eq!(
            failure(Cause::NothingListens),
            "nothing listens on tls/127.0.0.1:7447: is the router running?"
        );
        let s = failure(Cause::UnknownIssuer {
            root_ca: Some("/c/ca.pem".into()),
        });
        assert!(s.starts_with("the router's certificate is not signed by the CA in network.tls.root_ca_certificate (/c/ca.pem): "), "{s}");
        let s = failure(Cause::NotValidForName {
            host: "127.0.0.2".into(),
            presented: vec!["r1".into(), "127.0.0.1".into()],
        });
        assert!(
            s.starts_with(
                "the router's certificate does not name 127.0.0.2 (it names r1, 127.0.0.1); "
            ),
            "{s}"
        );
        let s = failure(Cause::Refused {
            alert: "it answered UnknownCA: not signed by a CA it trusts".into(),
            presented: Some("/c/user1.pem".into()),
        });
        assert!(s.contains("refused this station's certificate, network.tls.connect_certificate (/c/user1.pem) (it answered UnknownCA"), "{s}");
        let launcher = LinkFailure {
            locator: "tls/127.0.0.1:7447".into(),
            side: Side {
                me: "launcher",
                far: Far::Router,
                files: Files::CertsDir,
            },
            cause: Box::new(Cause::UnknownIssuer { root_ca: None }),
        };
        assert!(launcher.to_string().starts_with(
            "tls/127.0.0.1:7447 is a TLS router and this launcher has no certificates: give --certs DIR"
        ));
    }
}
