//! The station's network process: a zenoh session that
//!
//! - publishes this site's reports (read from the physics → network ring) on its state key, express,
//!   real-time priority, dropped rather than queued under congestion;
//! - hands the other sites' reports to physics (network → physics ring) the moment zenoh delivers
//!   them, after [`wire::Inbound::check`] (typed refusals are counted, never applied), with their
//!   time corrected by the sender's clock offset, through the receive-side network emulation when
//!   configured;
//! - declares a liveliness token (who is present) and watches everyone's; answers queries for its
//!   newest state (late joiners start from the session's state) and for its clock (NTP-style offset
//!   and round trip per peer);
//! - learns the session's time 0 from the launcher when the station waits for it;
//! - writes the station's MCAP recording (physics' trace ring, the states received, presence,
//!   clocks, final counters).
//!
//! It is not a real-time loop: zenoh's own threads and this process's loop run at normal priority,
//! off the servo's CPU, and touch the rings (lock-free, non-blocking) only on the real-time side's
//! behalf.

use std::collections::{BTreeMap, BinaryHeap};
use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use coop_model::rng::Rng;
use coop_model::scenario::LinkSpec;
use coop_rt::msg::{SiteReport, TraceRecord};
use coop_rt::shm::control::{ControlBlock, CounterKey, Ring, RunState, MAX_SITES};
use coop_rt::shm::{Consumer, Producer};
use coop_rt::sync::Ordering;
use coop_rt::timer::monotonic_ns;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::sample::{Locality, Sample, SampleKind};
use zenoh::Wait;

use crate::recording::{
    AdoptionMsg, ClockMsg, PresenceMsg, PublishedMsg, Recorder, RemoteMsg, SampleMsg, SessionMsg,
    StatusMsg,
};
use crate::{keys, wire};

/// The loop's longest sleep: it drains the trace ring, releases emulated messages and beats its
/// heartbeat at least this often.
pub const POLL: Duration = Duration::from_millis(1);
/// How long after physics' expected next report the loop looks for it (physics' wake latency and
/// step), and how often it looks again while the report is late.
pub const PUBLISH_LAG_NS: u64 = 40_000;
/// See [`PUBLISH_LAG_NS`].
pub const RETRY_NS: u64 = 25_000;
/// Past this lateness physics is taken to be stopped (restarting), and the loop polls at [`POLL`].
pub const GIVE_UP_NS: u64 = 500_000;

/// When the loop wakes next: just after physics' next report is expected (it tells its last report
/// time and its period in the control block), soon again if that report is late, never later
/// than [`POLL`].
pub fn next_wake(period: u64, last: u64, now: u64) -> u64 {
    let poll = now + POLL.as_nanos() as u64;
    if period == 0 || last == 0 {
        return poll;
    }
    let expected = last + period;
    if now < expected + PUBLISH_LAG_NS {
        (expected + PUBLISH_LAG_NS).min(poll)
    } else if now < expected + GIVE_UP_NS {
        now + RETRY_NS
    } else {
        poll
    }
}
/// How often each peer's clock is sampled (the first few samples come faster).
pub const CLOCK_EVERY: Duration = Duration::from_millis(500);
/// A report older than this when the network process gets to it is not published (ns).
pub const STALE_REPORT_NS: u64 = 100_000_000;
/// Clock samples kept per peer; the offset comes from the one with the shortest round trip.
pub const CLOCK_WINDOW: usize = 8;

/// Where the session listens and whom it connects to.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Endpoints {
    /// Zenoh locators to listen on, e.g. `tcp/127.0.0.1:7447` (port 0: a free port, chosen here).
    pub listen: Vec<String>,
    /// Zenoh locators of peers or routers to connect to.
    pub connect: Vec<String>,
    /// `peer` or `client`.
    pub mode: String,
    /// TLS files, for `tls/` locators.
    pub tls: Option<Tls>,
}

/// TLS for `tls/<host>:<port>` locators: PEM file paths (zenoh's `transport/link/tls`).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Tls {
    /// CA certificate that signed the peers' (or router's) certificates.
    pub root_ca_certificate: Option<String>,
    /// This station's certificate when it listens.
    pub listen_certificate: Option<String>,
    /// Its private key.
    pub listen_private_key: Option<String>,
    /// This station's certificate when it connects (mutual TLS).
    pub connect_certificate: Option<String>,
    /// Its private key.
    pub connect_private_key: Option<String>,
    /// Require client certificates (mutual TLS).
    pub enable_mtls: bool,
}

/// The receive-side emulation of a link.
#[derive(Debug, Clone, PartialEq)]
pub struct Emulation {
    /// Delay, jitter and loss, as in the scenario's `[network]`.
    pub link: LinkSpec,
    /// The scenario's seed (each link draws from its own stream of it, as in the simulator).
    pub seed: u64,
}

impl Emulation {
    /// A one-line description, as status and recordings show it.
    pub fn describe(&self) -> String {
        let l = &self.link;
        format!(
            "EMULATED: delay {}–{} ms (period {} s), jitter ±{} ms, loss {:.1} %, seed {}",
            l.delay_min_ms,
            l.delay_max_ms,
            l.delay_period_s,
            l.jitter_ms,
            l.loss * 100.0,
            self.seed
        )
    }
}

/// What the network process needs.
#[derive(Debug)]
pub struct NetworkArgs<'a> {
    /// Session name.
    pub session: &'a str,
    /// The scenario's site names, in order.
    pub sites: Vec<String>,
    /// This site's index.
    pub site_index: usize,
    /// Scenario name (for the recording).
    pub scenario: String,
    /// Method name (for the recording).
    pub method: String,
    /// Endpoints.
    pub endpoints: Endpoints,
    /// The control block.
    pub control: &'a ControlBlock,
    /// Reports from physics.
    pub reports: Consumer<SiteReport>,
    /// Reports to physics.
    pub remote: Producer<SiteReport>,
    /// Physics' trace records, for the recording.
    pub trace: Consumer<TraceRecord>,
    /// Recording file, if any.
    pub record: Option<PathBuf>,
    /// Receive-side emulation, if any.
    pub emulation: Option<Emulation>,
}

/// A zenoh configuration: the mode, explicit endpoints, no multicast scouting, timestamps on.
///
/// # Errors
/// An endpoint or mode zenoh does not accept.
pub fn config(endpoints: &Endpoints) -> Result<zenoh::Config, String> {
    let json = |v: &[String]| {
        format!(
            "[{}]",
            v.iter()
                .map(|e| format!("{e:?}"))
                .collect::<Vec<_>>()
                .join(",")
        )
    };
    let mode = if endpoints.mode.is_empty() {
        "peer"
    } else {
        endpoints.mode.as_str()
    };
    let mut c = zenoh::Config::default();
    c.insert_json5("mode", &format!("{mode:?}"))
        .map_err(|e| format!("mode {mode:?}: {e}"))?;
    c.insert_json5("scouting/multicast/enabled", "false")
        .map_err(|e| e.to_string())?;
    c.insert_json5("timestamping/enabled", "true")
        .map_err(|e| format!("timestamping: {e}"))?;
    // A peer that stops reading (stalled, or hostile) must not stall the session: zenoh closes a
    // link a blocking message cannot enter within 0.2 s (default 5 s, longer than the watchdog's
    // 0.5 s), and a state that cannot go within 0.2 ms is dropped (the next one replaces it).
    let q = "transport/link/tx/queue/congestion_control";
    c.insert_json5(&format!("{q}/block/wait_before_close"), "200000")
        .map_err(|e| format!("congestion control: {e}"))?;
    c.insert_json5(&format!("{q}/drop/wait_before_drop"), "200")
        .map_err(|e| format!("congestion control: {e}"))?;
    // The size bound: zenoh reassembles fragmented messages up to this (default 1 GiB, which a
    // hostile peer could use to make us allocate); a state is 289 bytes.
    c.insert_json5("transport/link/rx/max_message_size", "65536")
        .map_err(|e| format!("max message size: {e}"))?;
    if let Some(t) = &endpoints.tls {
        let tls = "transport/link/tls";
        for (key, v) in [
            ("root_ca_certificate", &t.root_ca_certificate),
            ("listen_certificate", &t.listen_certificate),
            ("listen_private_key", &t.listen_private_key),
            ("connect_certificate", &t.connect_certificate),
            ("connect_private_key", &t.connect_private_key),
        ] {
            if let Some(path) = v {
                c.insert_json5(&format!("{tls}/{key}"), &format!("{path:?}"))
                    .map_err(|e| format!("tls {key}: {e}"))?;
            }
        }
        c.insert_json5(&format!("{tls}/enable_mtls"), &t.enable_mtls.to_string())
            .map_err(|e| format!("tls enable_mtls: {e}"))?;
    }
    if mode != "client" {
        c.insert_json5("listen/endpoints", &json(&endpoints.listen))
            .map_err(|e| format!("listen endpoints: {e}"))?;
    }
    c.insert_json5("connect/endpoints", &json(&endpoints.connect))
        .map_err(|e| format!("connect endpoints: {e}"))?;
    Ok(c)
}

/// Replaces port 0 of `tcp/<ip>:0` locators with a port that is free now, so the station knows (and
/// status shows) where it listens.
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
                Ok(sa) if sa.port() == 0 => std::net::TcpListener::bind(sa)
                    .and_then(|s| s.local_addr())
                    .map_or_else(|_| l.clone(), |a| format!("tcp/{a}{tail}")),
                _ => l.clone(),
            }
        })
        .collect()
}

/// A message held back by the emulation.
#[derive(Debug, Clone, Copy)]
struct Held {
    at_ns: u64,
    order: u64,
    from: usize,
    report: SiteReport,
    delay_s: f64,
    offset_ns: i64,
}
impl PartialEq for Held {
    fn eq(&self, o: &Self) -> bool {
        (self.at_ns, self.order) == (o.at_ns, o.order)
    }
}
impl Eq for Held {}
impl PartialOrd for Held {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Held {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        // Reversed: BinaryHeap is a max-heap, the earliest release comes first.
        (o.at_ns, o.order).cmp(&(self.at_ns, self.order))
    }
}

/// Everything that handles received states, shared by zenoh's callbacks and the loop.
struct Receiver<'a> {
    me: usize,
    control: &'a ControlBlock,
    inbound: wire::Inbound,
    remote: Producer<SiteReport>,
    emulation: Option<(Emulation, Vec<Rng>)>,
    held: BinaryHeap<Held>,
    order: u64,
    received: u64,
    join_states: u64,
    refused: [u64; 5],
    emulated_lost: u64,
    log: Vec<RemoteMsg>,
}

impl Receiver<'_> {
    fn on_bytes(&mut self, key: &str, bytes: &[u8], zenoh_ts: Option<String>, join: bool) {
        let (from, mut r) = match self.inbound.check(keys::site_of(key), bytes) {
            Ok(x) => x,
            Err(e) => {
                let reason = e.reason();
                let slot = reason.slot();
                if self.refused[slot] == 0 {
                    // The first of each kind, once: an operator sees what is arriving; the counts
                    // are in status.
                    eprintln!(
                        "network: refused a message on {key}: {e} (further ones are only counted)"
                    );
                }
                self.refused[slot] += 1;
                self.control.network.refused.set(reason, self.refused[slot]);
                return;
            }
        };
        if from == self.me {
            return; // our own, echoed back
        }
        let offset = self.control.network.clock_offset_ns[from].load(Ordering::Relaxed) as i64;
        r.t_ns = r.t_ns.saturating_add_signed(-offset);
        if join {
            self.join_states += 1;
            self.control
                .network
                .join_states
                .store(self.join_states, Ordering::Relaxed);
        }
        let now = monotonic_ns();
        let (release, delay_s) = match &mut self.emulation {
            // A late joiner's catch-up state is not a message on a link.
            Some((emu, rngs)) if !join => {
                let l = &emu.link;
                let rng = &mut rngs[from];
                let lost = rng.uniform() < l.loss;
                let since_epoch = self
                    .control
                    .epoch()
                    .map_or(0.0, |e| r.t_ns.saturating_sub(e) as f64 * 1e-9);
                let swing =
                    0.5 - 0.5 * (std::f64::consts::TAU * since_epoch / l.delay_period_s).cos();
                let delay_ms = l.delay_min_ms
                    + (l.delay_max_ms - l.delay_min_ms) * swing
                    + rng.range(-l.jitter_ms, l.jitter_ms);
                if lost {
                    self.emulated_lost += 1;
                    self.control
                        .network
                        .emulated_lost
                        .store(self.emulated_lost, Ordering::Relaxed);
                    return;
                }
                let at = r.t_ns + (delay_ms.max(0.0) * 1e6) as u64;
                (at.max(now), (at.saturating_sub(now)) as f64 * 1e-9)
            }
            _ => (now, 0.0),
        };
        self.order += 1;
        let held = Held {
            at_ns: release,
            order: self.order,
            from,
            report: r,
            delay_s,
            offset_ns: offset,
        };
        if release <= now {
            self.hand_over(held, zenoh_ts, join, now);
        } else {
            self.held.push(held);
        }
    }

    fn release_due(&mut self, now: u64) {
        while self.held.peek().is_some_and(|h| h.at_ns <= now) {
            if let Some(h) = self.held.pop() {
                self.hand_over(h, None, false, now);
            }
        }
    }

    fn hand_over(&mut self, h: Held, zenoh_ts: Option<String>, join: bool, now: u64) {
        if self.remote.push(h.report).is_err() {
            self.control.network.drops.add(Ring::Remote, 1);
            return;
        }
        self.received += 1;
        self.control
            .network
            .received
            .store(self.received, Ordering::Relaxed);
        let age = now.saturating_sub(h.report.t_ns);
        if !join && self.emulation.is_none() {
            let count = self.control.network.latency_count.load(Ordering::Relaxed);
            self.control.network.latency.record(age, count == 0);
            self.control
                .network
                .latency_count
                .store(count + 1, Ordering::Relaxed);
        }
        self.log.push(RemoteMsg {
            t_ns: now,
            from: h.from,
            seq: h.report.seq,
            sent_ns: h.report.t_ns,
            offset_ns: h.offset_ns,
            age_s: age as f64 * 1e-9,
            emulated_delay_s: h.delay_s,
            zenoh_ts,
            via: if join { "join" } else { "live" }.into(),
        });
    }
}

fn write_to(
    rec: &mut Option<Recorder>,
    err: &mut Option<String>,
    f: impl FnOnce(&mut Recorder) -> Result<(), mcap::McapError>,
) {
    if let Some(r) = rec {
        if let Err(e) = f(r) {
            err.get_or_insert(format!("writing the recording: {e}"));
        }
    }
}

fn lock<'m, T>(m: &'m Mutex<T>) -> MutexGuard<'m, T> {
    // A panic in a callback must not take the network down with a poisoned lock.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Per-peer clock samples.
#[derive(Debug, Default, Clone)]
struct ClockPeer {
    samples: Vec<(u64, i64)>,
}

impl ClockPeer {
    /// Adds a sample (round trip, offset) and returns the best estimate.
    fn add(&mut self, rtt: u64, offset: i64) -> (u64, i64) {
        if self.samples.len() == CLOCK_WINDOW {
            self.samples.remove(0);
        }
        self.samples.push((rtt, offset));
        self.samples
            .iter()
            .copied()
            .min_by_key(|s| s.0)
            .unwrap_or((rtt, offset))
    }
}

/// One NTP-style exchange: our time before, theirs, ours after → (round trip, their − our clock).
pub fn clock_estimate(t0: u64, remote: u64, t2: u64) -> (u64, i64) {
    let rtt = t2.saturating_sub(t0);
    let mid = t0 as i128 + (rtt / 2) as i128;
    (rtt, (remote as i128 - mid) as i64)
}

/// Runs the network process until the run state says stop.
///
/// # Errors
/// The zenoh session or a declaration cannot be set up, or the recording cannot be created.
pub fn run(a: NetworkArgs<'_>) -> Result<StatusMsg, String> {
    let NetworkArgs {
        session: session_name,
        sites,
        site_index: me,
        scenario,
        method,
        endpoints,
        control: ctl,
        mut reports,
        remote,
        mut trace,
        record,
        emulation,
    } = a;
    let site = sites
        .get(me)
        .cloned()
        .ok_or_else(|| format!("site index {me} is not in the scenario"))?;
    if sites.len() > MAX_SITES {
        return Err(format!("{} sites: at most {MAX_SITES}", sites.len()));
    }
    let mut endpoints = endpoints;
    endpoints.listen = concrete_listen(&endpoints.listen);
    let mut recorder = match &record {
        Some(p) => Some(
            Recorder::create(
                p,
                BTreeMap::from([
                    ("session".into(), session_name.to_owned()),
                    ("site".into(), site.clone()),
                    ("scenario".into(), scenario.clone()),
                    ("method".into(), method.clone()),
                    (
                        "emulation".into(),
                        emulation
                            .as_ref()
                            .map_or("none".into(), Emulation::describe),
                    ),
                ]),
            )
            .map_err(|e| format!("creating the recording: {e}"))?,
        ),
        None => None,
    };
    ctl.network
        .emulated
        .store(u64::from(emulation.is_some()), Ordering::Relaxed);
    let session = zenoh::open(config(&endpoints)?)
        .wait()
        .map_err(|e| format!("opening the zenoh session: {e}"))?;
    let zid = session.zid();
    ctl.set_locators(&format!(
        "zid {zid} mode {} listen [{}] connect [{}]",
        if endpoints.mode.is_empty() {
            "peer"
        } else {
            &endpoints.mode
        },
        endpoints.listen.join(", "),
        endpoints.connect.join(", ")
    ));
    let publisher = session
        .declare_publisher(keys::state(session_name, 0, &site))
        .congestion_control(CongestionControl::Drop)
        .priority(Priority::RealTime)
        .express(true)
        .wait()
        .map_err(|e| format!("declaring the publisher: {e}"))?;

    let n = sites.len();
    let receiver = Arc::new(Mutex::new(Receiver {
        me,
        control: ctl,
        inbound: wire::Inbound::new(sites.clone()),
        remote,
        emulation: emulation.clone().map(|e| {
            let seed = e.seed;
            // Link from→me draws from stream from·n + me, as the simulator's links do.
            let rngs = (0..n)
                .map(|from| Rng::derive(seed, (from * n + me) as u64))
                .collect();
            (e, rngs)
        }),
        held: BinaryHeap::new(),
        order: 0,
        received: 0,
        join_states: 0,
        refused: [0; 5],
        emulated_lost: 0,
        log: Vec::new(),
    }));

    // Zenoh's threads call back here; the lifetime of `ctl` (the mapped control block) outlives the
    // session, which is closed before this function returns, so the callbacks borrow it through a
    // scoped thread's guarantee: everything below runs inside `std::thread::scope`.
    std::thread::scope(|scope| -> Result<StatusMsg, String> {
        let _token = session
            .liveliness()
            .declare_token(keys::presence(session_name, &site))
            .wait()
            .map_err(|e| format!("declaring the liveliness token: {e}"))?;
        // (site, present, when zenoh told us)
        let presence_events: Arc<Mutex<Vec<(String, bool, u64)>>> = Arc::default();
        let pe = presence_events.clone();
        let _presence = session
            .liveliness()
            .declare_subscriber(keys::all_presence(session_name))
            .history(true)
            .callback(move |s: Sample| {
                let name = keys::site_of(s.key_expr().as_str()).to_owned();
                lock(&pe).push((name, s.kind() == SampleKind::Put, monotonic_ns()));
            })
            .wait()
            .map_err(|e| format!("declaring the presence subscriber: {e}"))?;
        // Late join, before subscribing: the session's current state first (so it is what physics
        // adopts first, not refused as older than a live state that overtook it).
        if let Ok(replies) = session
            .get(keys::all_current(session_name, 0))
            .allowed_destination(Locality::Remote)
            .timeout(Duration::from_secs(1))
            .wait()
        {
            while let Ok(reply) = replies.recv() {
                if let Ok(s) = reply.result() {
                    // The replying site's own key carries its name.
                    let key = s.key_expr().as_str().to_owned();
                    lock(&receiver).on_bytes(&key, &s.payload().to_bytes(), None, true);
                }
            }
        }
        let rx = receiver.clone();
        let subscriber = session
            .declare_subscriber(keys::all_states(session_name, 0))
            .allowed_origin(Locality::Remote)
            .with(zenoh::handlers::FifoChannel::new(1024))
            .wait()
            .map_err(|e| format!("declaring the subscriber: {e}"))?;
        // Deliveries are handled on a thread of ours the moment zenoh hands them over.
        let stop = Arc::new(coop_rt::sync::AtomicU64::new(0));
        {
            let rx = rx.clone();
            let stop = stop.clone();
            let sub = subscriber;
            scope.spawn(move || {
                while stop.load(Ordering::Relaxed) == 0 {
                    match sub.recv_timeout(Duration::from_millis(50)) {
                        Ok(Some(s)) => {
                            let ts = s.timestamp().map(ToString::to_string);
                            lock(&rx).on_bytes(
                                s.key_expr().as_str(),
                                &s.payload().to_bytes(),
                                ts,
                                false,
                            );
                        }
                        Ok(None) => {}
                        Err(_) => break,
                    }
                }
            });
        }

        let last_report: Arc<Mutex<Option<Vec<u8>>>> = Arc::new(Mutex::new(None));
        let lr = last_report.clone();
        let current_key = keys::current(session_name, 0, &site);
        let reply_key = current_key.clone();
        let _current = session
            .declare_queryable(current_key)
            .callback(move |q| {
                // Replies carry this site's own key (the query's may be a wildcard).
                if let Some(bytes) = lock(&lr).clone() {
                    let _ = q.reply(reply_key.as_str(), bytes).wait();
                }
            })
            .wait()
            .map_err(|e| format!("declaring the current-state queryable: {e}"))?;
        let clock_key = keys::clock(session_name, &site);
        let reply_key = clock_key.clone();
        let _clock = session
            .declare_queryable(clock_key)
            .callback(move |q| {
                let _ = q
                    .reply(
                        reply_key.as_str(),
                        wire::encode_u64(monotonic_ns()).to_vec(),
                    )
                    .wait();
            })
            .wait()
            .map_err(|e| format!("declaring the clock queryable: {e}"))?;
        let epoch_sub = session
            .declare_subscriber(keys::epoch(session_name))
            .wait()
            .map_err(|e| format!("declaring the epoch subscriber: {e}"))?;

        // The session's time 0, asked for once at start (and put by the launcher when decided).
        {
            let session = &session;
            scope.spawn(move || {
                if ctl.epoch().is_none() {
                    if let Ok(replies) = session
                        .get(keys::epoch(session_name))
                        .timeout(Duration::from_secs(2))
                        .wait()
                    {
                        while let Ok(reply) = replies.recv() {
                            if let Ok(s) = reply.result() {
                                if let Ok(e) = wire::decode_u64(&s.payload().to_bytes()) {
                                    let _ = ctl.epoch_ns.compare_exchange(
                                        0,
                                        e,
                                        Ordering::AcqRel,
                                        Ordering::Relaxed,
                                    );
                                }
                            }
                        }
                    }
                }
            });
        }

        // Clocks: every present peer, NTP-style, best of the last few exchanges.
        let clock_log: Arc<Mutex<Vec<ClockMsg>>> = Arc::default();
        {
            let (stop, cl, session, sites) = (stop.clone(), clock_log.clone(), &session, &sites);
            scope.spawn(move || {
                let mut peers = vec![ClockPeer::default(); n];
                let mut round = 0u32;
                while stop.load(Ordering::Relaxed) == 0 {
                    let present = ctl.network.peers_present.load(Ordering::Relaxed);
                    for (j, name) in sites.iter().enumerate() {
                        if j == me || present & (1 << j) == 0 {
                            continue;
                        }
                        let t0 = monotonic_ns();
                        let Ok(replies) = session
                            .get(keys::clock(session_name, name))
                            .timeout(Duration::from_millis(200))
                            .wait()
                        else {
                            continue;
                        };
                        if let Ok(reply) = replies.recv() {
                            let t2 = monotonic_ns();
                            if let Some(remote) = reply
                                .result()
                                .ok()
                                .and_then(|s| wire::decode_u64(&s.payload().to_bytes()).ok())
                            {
                                let (rtt, offset) = clock_estimate(t0, remote, t2);
                                let (rtt, offset) = peers[j].add(rtt, offset);
                                ctl.network.clock_offset_ns[j]
                                    .store(offset as u64, Ordering::Relaxed);
                                ctl.network.clock_rtt_ns[j].store(rtt, Ordering::Relaxed);
                                lock(&cl).push(ClockMsg {
                                    t_ns: t2,
                                    site: j,
                                    offset_ns: offset,
                                    rtt_ns: rtt,
                                });
                            }
                        }
                    }
                    round += 1;
                    let pause = if round < 5 {
                        CLOCK_EVERY / 5
                    } else {
                        CLOCK_EVERY
                    };
                    let until = std::time::Instant::now() + pause;
                    while std::time::Instant::now() < until && stop.load(Ordering::Relaxed) == 0 {
                        std::thread::sleep(Duration::from_millis(20));
                    }
                }
            });
        }

        // The loop.
        let slot = ctl.child(coop_rt::shm::control::Child::Network);
        slot.pid
            .store(u64::from(std::process::id()), Ordering::Relaxed);
        let mut published = 0u64;
        let mut stale_skipped = 0u64;
        let mut session_recorded = false;
        let mut present_mask = 0u64;
        let (mut joins, mut leaves) = (0u64, 0u64);
        let mut write_err: Option<String> = None;
        loop {
            // Only the newest report: states replace each other, and a backlog (physics ran
            // before this process was up, or while it restarted) is stale by definition.
            if let Ok(newest) = reports.pop_newest().map_err(|_| ()).and_then(|n| {
                stale_skipped += n.skipped;
                // A ring that filled up before this process was up holds old states only.
                if monotonic_ns().saturating_sub(n.value.t_ns) > STALE_REPORT_NS {
                    stale_skipped += 1;
                    Err(())
                } else {
                    Ok(n)
                }
            }) {
                let r = newest.value;
                let bytes = wire::encode(&r);
                if publisher.put(bytes.clone()).wait().is_ok() {
                    published += 1;
                    let m = PublishedMsg {
                        t_ns: monotonic_ns(),
                        seq: r.seq,
                        state_ns: r.t_ns,
                    };
                    write_to(&mut recorder, &mut write_err, |w| w.published(&m));
                }
                *lock(&last_report) = Some(bytes);
            }
            let now = monotonic_ns();
            let log = {
                let mut rx = lock(&receiver);
                rx.release_due(now);
                std::mem::take(&mut rx.log)
            };
            for m in &log {
                write_to(&mut recorder, &mut write_err, |w| w.remote(m));
            }
            while let Ok(t) = trace.pop() {
                let s = SampleMsg {
                    t_ns: t.t_ns,
                    pos: t.pos,
                    rot: t.rot,
                    vel: t.vel,
                    adoptions: t.adoptions,
                    tool_pos: t.tool_pos,
                    f_desired: t.f_desired,
                    f_measured: t.f_measured,
                    f_object: t.f_object,
                    touching: t.touching != 0,
                };
                if t.kind == TraceRecord::ADOPTION {
                    let m = AdoptionMsg {
                        t_ns: t.t_ns,
                        from: t.from as usize,
                        jump_m: t.jump_m,
                        age_s: t.age_s,
                    };
                    write_to(&mut recorder, &mut write_err, |w| w.adoption(&m));
                } else {
                    write_to(&mut recorder, &mut write_err, |w| w.sample(&s));
                }
            }
            for (name, present, at) in std::mem::take(&mut *lock(&presence_events)) {
                let Some(j) = sites.iter().position(|s| *s == name) else {
                    continue;
                };
                if present {
                    present_mask |= 1 << j;
                    joins += 1;
                } else {
                    present_mask &= !(1 << j);
                    leaves += 1;
                    // A site that left and comes back starts its sequence afresh.
                    lock(&receiver).inbound.forget(j);
                }
                ctl.network
                    .peers_present
                    .store(present_mask, Ordering::Relaxed);
                ctl.network.peer_joins.store(joins, Ordering::Relaxed);
                ctl.network.peer_leaves.store(leaves, Ordering::Relaxed);
                let m = PresenceMsg {
                    t_ns: at,
                    site: name,
                    present,
                };
                write_to(&mut recorder, &mut write_err, |w| w.presence(&m));
            }
            for m in std::mem::take(&mut *lock(&clock_log)) {
                write_to(&mut recorder, &mut write_err, |w| w.clock(&m));
            }
            while let Ok(Some(s)) = epoch_sub.try_recv() {
                if let Ok(e) = wire::decode_u64(&s.payload().to_bytes()) {
                    let _ =
                        ctl.epoch_ns
                            .compare_exchange(0, e, Ordering::AcqRel, Ordering::Relaxed);
                }
            }
            if !session_recorded {
                if let Some(epoch_ns) = ctl.epoch() {
                    session_recorded = true;
                    let m = SessionMsg {
                        t_ns: now,
                        session: session_name.to_owned(),
                        site: site.clone(),
                        site_index: me,
                        scenario: scenario.clone(),
                        method: method.clone(),
                        epoch_ns,
                        emulation: emulation
                            .as_ref()
                            .map_or("none".into(), Emulation::describe),
                    };
                    write_to(&mut recorder, &mut write_err, |w| w.session(&m));
                }
            }
            ctl.network.published.store(published, Ordering::Relaxed);
            slot.heartbeat.fetch_add(1, Ordering::Relaxed);
            if let Some(e) = write_err.take() {
                // A full disk must not take the station down; say it once and stop recording.
                eprintln!("network {site}: {e}; recording stopped");
                recorder = None;
            }
            if !matches!(ctl.run_state(), RunState::Starting | RunState::Running) {
                break;
            }
            coop_rt::timer::sleep_until(next_wake(
                ctl.physics.report_period_ns.load(Ordering::Relaxed),
                ctl.physics.last_report_ns.load(Ordering::Relaxed),
                monotonic_ns(),
            ));
        }
        stop.store(1, Ordering::Relaxed);
        let status = {
            let rx = lock(&receiver);
            StatusMsg {
                t_ns: monotonic_ns(),
                published,
                received: rx.received,
                refused: rx.refused,
                emulated_lost: rx.emulated_lost,
                join_states: rx.join_states,
                stale_skipped,
            }
        };
        if let Some(mut r) = recorder.take() {
            let _ = r.status(&status);
            if let Err(e) = r.finish() {
                eprintln!("network {site}: finishing the recording: {e}");
            }
        }
        Ok(status)
    })
    .and_then(|status| {
        drop(publisher);
        session
            .close()
            .wait()
            .map_err(|e| format!("closing the zenoh session: {e}"))?;
        Ok(status)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_estimates_take_the_shortest_round_trip() {
        // Their clock is 1000 ns ahead; the exchange took 200 ns.
        assert_eq!(clock_estimate(10_000, 11_100, 10_200), (200, 1000));
        let mut p = ClockPeer::default();
        assert_eq!(p.add(500, 40), (500, 40));
        assert_eq!(p.add(100, 5), (100, 5));
        assert_eq!(
            p.add(900, 300),
            (100, 5),
            "a slow exchange does not move the estimate"
        );
        for _ in 0..CLOCK_WINDOW {
            p.add(400, 20);
        }
        assert_eq!(p.add(400, 20), (400, 20), "old samples leave the window");
    }

    #[test]
    fn the_loop_wakes_just_after_the_next_report() {
        let ms = 1_000_000;
        // Nothing known yet: poll.
        assert_eq!(next_wake(0, 0, 10 * ms), 11 * ms);
        // Last report at 10 ms, every 1 ms, now 10.5 ms: wake 40 µs after 11 ms.
        assert_eq!(
            next_wake(ms, 10 * ms, 10 * ms + ms / 2),
            11 * ms + PUBLISH_LAG_NS
        );
        // Late: look again soon.
        assert_eq!(
            next_wake(ms, 10 * ms, 11 * ms + 100_000),
            11 * ms + 100_000 + RETRY_NS
        );
        // Long late (physics restarting): poll.
        assert_eq!(next_wake(ms, 10 * ms, 12 * ms), 13 * ms);
        // A slow report rate: never sleep past the poll period.
        assert_eq!(next_wake(50 * ms, 10 * ms, 10 * ms), 11 * ms);
    }

    #[test]
    fn configurations_zenoh_accepts() {
        let mut e = Endpoints {
            listen: vec!["tcp/127.0.0.1:0".into()],
            connect: vec!["tcp/127.0.0.1:7447".into()],
            mode: "peer".into(),
            tls: None,
        };
        assert!(config(&e).is_ok());
        e.mode = "client".into();
        assert!(config(&e).is_ok());
        e.tls = Some(Tls {
            root_ca_certificate: Some("/etc/coop/ca.pem".into()),
            listen_certificate: Some("/etc/coop/station.pem".into()),
            listen_private_key: Some("/etc/coop/station.key".into()),
            enable_mtls: true,
            ..Tls::default()
        });
        assert!(config(&e).is_ok());
        e.mode = "router-ish".into();
        assert!(config(&e).is_err(), "an unknown mode is refused");
        e.mode = "peer".into();
        e.listen = vec!["nonsense".into()];
        assert!(config(&e).is_err(), "a bad locator is refused");
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

    #[test]
    fn emulation_is_described_as_emulated() {
        let e = Emulation {
            link: LinkSpec::default(),
            seed: 3,
        };
        assert!(e.describe().starts_with("EMULATED"));
    }
}
