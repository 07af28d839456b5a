//! A zenoh router for sessions that span machines: stations in client mode connect to it (or to
//! several), and it enforces the session's access control ([`crate::acl`]) on every link, so a
//! station holding one site's certificate cannot speak for another.
//!
//! What a router can show of itself: its zenoh id and locators; the zenoh sessions linked to it
//! (their zenoh id, whether client, peer or router, and each link's two addresses), from its own
//! admin space; the sites present, from the liveliness tokens it routes; and the messages its
//! access control refused. Zenoh counts refusals only in builds with its `stats` feature (not
//! ours); it does report each refusal as a trace event of its access-control interceptor, and
//! [`Refusals`] counts those. A link refused before zenoh sees it (a TLS handshake without a
//! certificate the CA signed) is not a message and is not counted: it shows as no session.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

use coop_rt::sync::{AtomicU64, Ordering};
use serde::{Deserialize, Serialize};
use zenoh::{Session, Wait};

use crate::network::{concrete_listen, config, NetworkConfig, NetworkError, Tls};

/// Where a router listens, whom it connects to (other routers), its TLS files and its access
/// control.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RouterEndpoints {
    /// Locators to listen on.
    pub listen: Vec<String>,
    /// Other routers to connect to.
    pub connect: Vec<String>,
    /// TLS files (this router's own certificate, the session's CA).
    pub tls: Option<Tls>,
    /// The access control file ([`crate::acl::session_acl`], as `session certs` writes it).
    pub access_control: Option<PathBuf>,
}

/// The zenoh configuration of a router: the station's settings (explicit endpoints, no
/// multicast scouting, bounded messages, TLS, access control) in router mode, with the admin
/// space readable (by this process: the access control denies it to every link).
///
/// # Errors
/// A value zenoh does not take, or an unreadable access control file.
pub fn router_config(r: &RouterEndpoints) -> Result<zenoh::Config, NetworkError> {
    let mut c = config(&NetworkConfig {
        listen: concrete_listen(&r.listen),
        connect: r.connect.clone(),
        tls: r.tls.clone(),
        access_control: r.access_control.clone(),
        ..NetworkConfig::default()
    })?;
    for (key, value) in [
        ("mode", "\"router\""),
        ("adminspace/enabled", "true"),
        ("adminspace/permissions/read", "true"),
        ("adminspace/permissions/write", "false"),
    ] {
        c.insert_json5(key, value)
            .map_err(|error| NetworkError::Config {
                key: key.to_owned(),
                error,
            })?;
    }
    Ok(c)
}

/// Opens the router.
///
/// # Errors
/// As [`router_config`], or zenoh cannot open it (a port taken, a certificate it cannot read, an
/// access control it refuses).
pub fn open(r: &RouterEndpoints) -> Result<Session, NetworkError> {
    zenoh::open(router_config(r)?)
        .wait()
        .map_err(NetworkError::Open)
}

/// Closes the router (its links go down; stations connected through it see their peers leave).
pub fn close(session: &Session) {
    let _ = session.close().wait();
}

/// A zenoh session linked to the router.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LinkedSession {
    /// Its zenoh id.
    pub zid: String,
    /// client, peer or router.
    pub whatami: String,
    /// Its links, `src -> dst` as the router sees them.
    pub links: Vec<String>,
}

/// One kind of refusal of the access control: who, what, on which key, and how often.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Refusal {
    /// The zenoh id of the link's other side.
    pub zid: String,
    /// What it was refused, as zenoh names it (`Put (ingress)`, `Declare Queryable (ingress)`,
    /// `Liveliness Token (ingress)`, …).
    pub action: String,
    /// On which key.
    pub key: String,
    /// How many times, since it was first refused.
    pub count: u64,
}

/// What a router shows (`station router status`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RouterStatus {
    /// The router's name (its certificate's common name).
    pub name: String,
    /// Its process id.
    pub pid: u32,
    /// When this was taken, CLOCK_MONOTONIC ns.
    pub t_ns: u64,
    /// Its zenoh id.
    pub zid: String,
    /// Where it listens.
    pub listen: Vec<String>,
    /// Routers it connects to.
    pub connect: Vec<String>,
    /// Whether an access control is enforced.
    pub access_control: bool,
    /// The zenoh sessions linked to it.
    pub sessions: Vec<LinkedSession>,
    /// Presence tokens routed (`coop/<session>/presence/<site>`).
    pub present: Vec<String>,
    /// Messages refused by the access control, in all.
    pub refused: u64,
    /// …by what was refused.
    pub refused_by_action: BTreeMap<String, u64>,
    /// The most recently refused (who, what, key), oldest first, at most [`RECENT`] of them,
    /// each with its count: a repeat moves its entry to the end, so a flood of one refusal (an
    /// impostor's puts) does not push out the one-off ones (its declarations).
    pub recent_refusals: Vec<Refusal>,
}

/// Distinct refusals kept for status.
pub const RECENT: usize = 16;

impl std::fmt::Display for RouterStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "router {} (pid {}) zid {}",
            self.name, self.pid, self.zid
        )?;
        writeln!(
            f,
            "  listen [{}] connect [{}] access control {}",
            self.listen.join(", "),
            self.connect.join(", "),
            if self.access_control { "on" } else { "OFF" }
        )?;
        writeln!(f, "  sessions: {}", self.sessions.len())?;
        for s in &self.sessions {
            writeln!(f, "    {} {} {}", s.zid, s.whatami, s.links.join(", "))?;
        }
        writeln!(f, "  present: {}", self.present.join(", "))?;
        let by: Vec<String> = self
            .refused_by_action
            .iter()
            .map(|(a, n)| format!("{a}: {n}"))
            .collect();
        writeln!(f, "  refused: {} ({})", self.refused, by.join(", "))?;
        for r in &self.recent_refusals {
            writeln!(f, "    {} {} on {} ×{}", r.zid, r.action, r.key, r.count)?;
        }
        Ok(())
    }
}

/// Counts the access control's refusals from zenoh's trace events (see the module's
/// documentation). Install it once per process with [`Refusals::install`].
#[derive(Debug, Default)]
pub struct Refusals {
    total: AtomicU64,
    detail: Mutex<(BTreeMap<String, u64>, Vec<Refusal>)>,
}

/// Zenoh's access-control interceptor, the events' target.
const ACL_TARGET: &str = "zenoh::net::routing::interceptor::access_control";

thread_local! {
    /// Whether this thread is computing a permission cache: zenoh then evaluates every message
    /// kind for a key (tracing a decision for each) without any message being refused.
    static CACHING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

impl Refusals {
    /// The process's counter, installed as its tracing subscriber (it records nothing else) on
    /// the first call.
    ///
    /// # Errors
    /// Another tracing subscriber was installed first.
    pub fn install() -> Result<&'static Refusals, String> {
        static R: OnceLock<&'static Refusals> = OnceLock::new();
        if let Some(r) = R.get() {
            return Ok(r);
        }
        let r: &'static Refusals = Box::leak(Box::default());
        tracing::subscriber::set_global_default(Counter(r))
            .map_err(|e| format!("counting access-control refusals: {e}"))?;
        Ok(*R.get_or_init(|| r))
    }

    /// Messages refused so far.
    pub fn total(&self) -> u64 {
        self.total.load(Ordering::Relaxed)
    }

    /// One event of zenoh's access control, its message formatted.
    fn event(&self, message: &str) {
        const DENIED: &str = " is unauthorized to ";
        let cached = message.strip_prefix("Using cached result: ");
        if message.contains("caching permissions for") {
            CACHING.with(|c| c.set(true));
            return;
        }
        let is_decision = message.contains(DENIED) || message.contains(" is authorized to ");
        if cached.is_some() || !is_decision {
            CACHING.with(|c| c.set(false));
        } else if CACHING.with(std::cell::Cell::get) {
            return;
        }
        let Some((who, rest)) = cached.unwrap_or(message).split_once(DENIED) else {
            return;
        };
        let (action, key) = rest.rsplit_once(" on ").unwrap_or((rest, ""));
        let zid = who.split_whitespace().next().unwrap_or("").to_owned();
        self.total.fetch_add(1, Ordering::Relaxed);
        let mut d = self.detail.lock().unwrap_or_else(|e| e.into_inner());
        *d.0.entry(action.to_owned()).or_default() += 1;
        let recent = &mut d.1;
        let same = |r: &Refusal| r.zid == zid && r.action == action && r.key == key;
        let entry = match recent.iter().position(same) {
            Some(i) => recent.remove(i),
            None => {
                if recent.len() == RECENT {
                    recent.remove(0);
                }
                Refusal {
                    zid,
                    action: action.to_owned(),
                    key: key.to_owned(),
                    count: 0,
                }
            }
        };
        recent.push(Refusal {
            count: entry.count + 1,
            ..entry
        });
    }

    fn detail(&self) -> (BTreeMap<String, u64>, Vec<Refusal>) {
        self.detail
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }
}

/// The tracing subscriber: interested in the access control's events only.
struct Counter(&'static Refusals);

impl Counter {
    fn wants(m: &tracing::Metadata<'_>) -> bool {
        m.is_event() && m.target().starts_with(ACL_TARGET)
    }
}

struct Message(String);

impl tracing::field::Visit for Message {
    fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}");
        }
    }
}

impl tracing::Subscriber for Counter {
    fn register_callsite(
        &self,
        m: &'static tracing::Metadata<'static>,
    ) -> tracing::subscriber::Interest {
        if Self::wants(m) {
            tracing::subscriber::Interest::always()
        } else {
            tracing::subscriber::Interest::never()
        }
    }
    fn enabled(&self, m: &tracing::Metadata<'_>) -> bool {
        Self::wants(m)
    }
    fn max_level_hint(&self) -> Option<tracing::level_filters::LevelFilter> {
        Some(tracing::level_filters::LevelFilter::TRACE)
    }
    fn new_span(&self, _: &tracing::span::Attributes<'_>) -> tracing::span::Id {
        tracing::span::Id::from_u64(1)
    }
    fn record(&self, _: &tracing::span::Id, _: &tracing::span::Record<'_>) {}
    fn record_follows_from(&self, _: &tracing::span::Id, _: &tracing::span::Id) {}
    fn event(&self, e: &tracing::Event<'_>) {
        let mut m = Message(String::new());
        e.record(&mut m);
        self.0.event(&m.0);
    }
    fn enter(&self, _: &tracing::span::Id) {}
    fn exit(&self, _: &tracing::span::Id) {}
}

/// How long status waits for the admin space and the liveliness tokens.
const ASK: Duration = Duration::from_millis(500);

/// The router's status now: `name`, `endpoints` as configured, `refusals` as counted.
pub fn status(
    session: &Session,
    name: &str,
    endpoints: &RouterEndpoints,
    refusals: &Refusals,
) -> RouterStatus {
    let zid = session.zid().to_string();
    let mut sessions = Vec::new();
    if let Ok(replies) = session.get(format!("@/{zid}/router")).timeout(ASK).wait() {
        while let Ok(r) = replies.recv() {
            let Ok(s) = r.result() else { continue };
            let Ok(v) = serde_json::from_slice::<serde_json::Value>(&s.payload().to_bytes()) else {
                continue;
            };
            for t in v["sessions"].as_array().into_iter().flatten() {
                sessions.push(LinkedSession {
                    zid: t["peer"].as_str().unwrap_or("").to_owned(),
                    whatami: t["whatami"].as_str().unwrap_or("").to_owned(),
                    links: t["links"]
                        .as_array()
                        .into_iter()
                        .flatten()
                        .map(|l| {
                            format!(
                                "{} -> {}",
                                l["src"].as_str().unwrap_or("?"),
                                l["dst"].as_str().unwrap_or("?")
                            )
                        })
                        .collect(),
                });
            }
        }
    }
    let mut present = Vec::new();
    if let Ok(replies) = session
        .liveliness()
        .get("coop/*/presence/*")
        .timeout(ASK)
        .wait()
    {
        while let Ok(r) = replies.recv() {
            if let Ok(s) = r.result() {
                present.push(s.key_expr().to_string());
            }
        }
    }
    present.sort();
    present.dedup();
    let (refused_by_action, recent_refusals) = refusals.detail();
    RouterStatus {
        name: name.to_owned(),
        pid: std::process::id(),
        t_ns: coop_rt::timer::monotonic_ns(),
        zid,
        listen: concrete_listen(&endpoints.listen),
        connect: endpoints.connect.clone(),
        access_control: endpoints.access_control.is_some(),
        sessions,
        present,
        refused: refusals.total(),
        refused_by_action,
        recent_refusals,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_count_decisions_but_not_permission_caches() {
        let r = Refusals::default();
        r.event("ACL (ingress): caching permissions for `coop/s/obj/0/state/user1` ...");
        r.event(
            "aa on Subject(user2) is unauthorized to Put (ingress) on coop/s/obj/0/state/user1",
        );
        r.event(
            "aa on Subject(user2) is unauthorized to Query (ingress) on coop/s/obj/0/state/user1",
        );
        assert_eq!(r.total(), 0, "a cache being computed refuses nothing");
        r.event(
            "Using cached result: aa is unauthorized to Put (ingress) on coop/s/obj/0/state/user1",
        );
        assert_eq!(r.total(), 1);
        r.event("bb on Subject(user2) is unauthorized to Declare/Undeclare Queryable (ingress) on coop/s/clock/user1");
        r.event(
            "Using cached result: aa is authorized to Put (ingress) on coop/s/obj/0/state/user2",
        );
        assert_eq!(r.total(), 2);
        let (by, recent) = r.detail();
        assert_eq!(by.get("Put (ingress)"), Some(&1));
        assert_eq!(
            recent[1],
            Refusal {
                zid: "bb".into(),
                action: "Declare/Undeclare Queryable (ingress)".into(),
                key: "coop/s/clock/user1".into(),
                count: 1,
            }
        );
    }

    #[test]
    fn a_flood_of_one_refusal_keeps_the_others_in_recent() {
        let r = Refusals::default();
        let put =
            "Using cached result: aa is unauthorized to Put (ingress) on coop/s/obj/0/state/user1";
        r.event("aa on Subject(user2) is unauthorized to Declare Queryable (ingress) on coop/s/clock/user1");
        r.event("aa on Subject(user2) is unauthorized to Liveliness Token (ingress) on coop/s/presence/user1");
        for _ in 0..3 * RECENT {
            r.event(put);
        }
        assert_eq!(r.total(), 2 + 3 * RECENT as u64);
        let (_, recent) = r.detail();
        let seen: Vec<(&str, &str, u64)> = recent
            .iter()
            .map(|x| (x.action.as_str(), x.key.as_str(), x.count))
            .collect();
        assert_eq!(
            seen,
            [
                ("Declare Queryable (ingress)", "coop/s/clock/user1", 1),
                ("Liveliness Token (ingress)", "coop/s/presence/user1", 1),
                (
                    "Put (ingress)",
                    "coop/s/obj/0/state/user1",
                    3 * RECENT as u64
                ),
            ]
        );
        // Distinct refusals beyond RECENT push out the oldest.
        for k in 0..RECENT {
            r.event(&format!(
                "Using cached result: aa is unauthorized to Put (ingress) on coop/s/k{k}"
            ));
        }
        let (_, recent) = r.detail();
        assert_eq!(recent.len(), RECENT);
        assert_eq!(recent[0].key, "coop/s/k0");
    }
}
