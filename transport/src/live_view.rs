//! The live view: a site's or a whole session's copies of the object, tools and forces in one 3-D
//! scene, served to Foxglove or Lichtblick over the `foxglove.websocket.v1` protocol while they
//! run — `session run --live` (the launcher follows every site's live key, [`LiveView::follow`])
//! and `station run --live` (the network process offers its own samples, [`LiveView::offer`]).
//!
//! A publishing thread wakes every [`PERIOD`] (about 60 Hz) and sends, for what arrived since its
//! last turn, the frames `world → object/<site>` and `world → tool/<site>` on `/tf`, the events on
//! `/log`, and on `/scene` (the same entities as the recordings', [`Scene`]) what changed: the
//! objects, tools and environment are locked to their frames and move with `/tf`, so the whole
//! scene goes when a site first shows and every [`WHOLE_SCENE_EVERY`], and in between only the
//! force arrows that changed. A viewer that subscribes gets the last whole scene at once.
//!
//! Nothing that feeds it waits for a viewer: [`LiveView::offer`] only replaces the newest sample
//! under a short lock (the publishing thread encodes and sends outside it), the stations' live key
//! is put at background priority and dropped under congestion, and each viewer has its own thread
//! and a bounded queue of turns: a viewer too slow to take a turn loses it.
//!
//! The server is ours, small (the protocol's `serverInfo`, `advertise`, `subscribe`,
//! `unsubscribe` and binary `messageData`, on `tungstenite`): the `foxglove` crate's server speaks
//! its newer `foxglove.sdk.v1` subprotocol only, which Lichtblick and older Foxglove builds do not.
//!
//! Loopback by default ([`DEFAULT_ADDR`]); any address can be given, port 0 picks a free one.

use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use base64::Engine as _;
use coop_model::scenario::Scenario;
use coop_rt::sync::{AtomicU64, Ordering};
use foxglove::messages::{log::Level, FrameTransform, Log, SceneUpdate};
use foxglove::Encode;
use tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tungstenite::Message;
use zenoh::Wait;

use crate::keys;
use crate::recording::scene::{arrow, encode, timestamp};
use crate::recording::{LiveSample, SampleMsg, Scene};

/// The shortest time between two live samples a station puts (about 60 Hz: a viewer's frame
/// rate), ns.
pub const LIVE_EVERY_NS: u64 = 16_666_667;

/// The WebSocket subprotocol spoken.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// Turns a viewer may be behind before it loses the next ones.
const QUEUE: usize = 64;
/// How long a viewer's thread waits for frames before it looks at the viewer's requests (and its
/// stop) anyway. While frames come (~60 Hz) it wakes for them only: it does not poll the viewer.
const CLIENT_IDLE: Duration = Duration::from_millis(50);
/// How often the listener looks for new viewers (and for its stop).
const ACCEPT_POLL: Duration = Duration::from_millis(50);

/// The channels advertised: id, topic, schema name, schema (a FileDescriptorSet).
fn channels() -> [(u32, &'static str, foxglove::Schema); 3] {
    let schema = |s: Option<foxglove::Schema>| {
        s.unwrap_or_else(|| foxglove::Schema::new("", "", Vec::new()))
    };
    [
        (1, "/tf", schema(FrameTransform::get_schema())),
        (2, "/scene", schema(SceneUpdate::get_schema())),
        (3, "/log", schema(Log::get_schema())),
    ]
}
const TF: u32 = 1;
const SCENE: u32 = 2;
const LOG: u32 = 3;

/// One message for every viewer: channel, wall time (ns), protobuf bytes.
type Frame = Arc<(u32, u64, Vec<u8>)>;
/// A publishing turn's frames, queued to a viewer as one: its thread wakes once per turn and
/// writes them in one flush (one loopback send, not one per frame).
type Turn = Arc<[Frame]>;

/// Where the live view listens unless told: loopback, Foxglove's usual port.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";
/// How often the viewer gets the newest state: about 60 Hz.
pub const PERIOD: Duration = Duration::from_nanos(16_666_667);
/// How often `/scene` carries the whole scene while samples come (between: the force arrows that
/// changed). It bounds how long a viewer that lost a turn (its queue was full) misses an entity.
pub const WHOLE_SCENE_EVERY: Duration = Duration::from_secs(1);

/// The live view could not be started or could not follow a session.
#[derive(Debug, thiserror::Error)]
pub enum LiveViewError {
    /// The address is not `host:port`.
    #[error("{addr:?}: not an address such as {DEFAULT_ADDR}")]
    Address {
        /// What was given.
        addr: String,
    },
    /// The server cannot listen there.
    #[error("{addr}: cannot listen there: {error}")]
    Listen {
        /// Where.
        addr: String,
        /// Why.
        error: std::io::Error,
    },
    /// A thread of the view could not be started.
    #[error("starting the live view's {what} thread: {error}")]
    Thread {
        /// Which thread.
        what: &'static str,
        /// Why.
        error: std::io::Error,
    },
    /// The session's live samples cannot be subscribed to.
    #[error("subscribing to the live samples: {0}")]
    Subscribe(zenoh::Error),
}

/// What the publishing thread shows.
#[derive(Default)]
struct Shown {
    /// The followed session and its sites' scenes.
    session: String,
    scenes: Vec<Scene>,
    /// Per site, the newest sample not yet shown.
    newest: Vec<Option<LiveSample>>,
    /// Per site, its last sample shown (the scene keeps every site seen so far).
    shown: Vec<Option<SampleMsg>>,
    /// Log lines to send.
    logs: Vec<(Level, String)>,
    /// The name on the log lines (`session`, or the station's site).
    log_name: String,
}

/// A publishing turn, before encoding: the frames, the scene (and whether it is the whole one),
/// the log lines.
struct Turned {
    frames: Vec<FrameTransform>,
    scene: Option<(SceneUpdate, bool)>,
    logs: Vec<Log>,
}

impl Shown {
    /// This turn at wall time `now` (ns): the frames of the sites with a new sample; the whole
    /// scene if a site shows for the first time, or if `whole_due` and a sample came; else the
    /// force arrows that changed (no scene if none did); the log lines.
    fn turn(&mut self, now: u64, whole_due: bool) -> Turned {
        let mut frames = Vec::new();
        let mut arrows = Vec::new();
        let mut new_site = false;
        for i in 0..self.scenes.len() {
            let Some(live) = self.newest[i].take() else {
                continue;
            };
            let scene = &self.scenes[i];
            let m = live.sample;
            frames.extend(scene.transforms(&m, now));
            frames.extend(scene.other_transforms(&live.other_poses(), now));
            match &self.shown[i] {
                None => new_site = true,
                Some(before) if arrow(before.f_object) != arrow(m.f_object) => {
                    arrows.push(scene.force(&m, now));
                }
                Some(_) => {}
            }
            self.shown[i] = Some(m);
        }
        let update = |entities| SceneUpdate {
            deletions: Vec::new(),
            entities,
        };
        let scene = if new_site || (whole_due && !frames.is_empty()) {
            let mut entities = Vec::new();
            if let Some(first) = self.scenes.first() {
                entities.push(first.environment(now));
            }
            for (scene, m) in self.scenes.iter().zip(&self.shown) {
                if let Some(m) = m {
                    entities.extend(scene.entities(m, now));
                    entities.extend(scene.other_entities(now));
                }
            }
            Some((update(entities), true))
        } else {
            (!arrows.is_empty()).then(|| (update(arrows), false))
        };
        let logs = std::mem::take(&mut self.logs)
            .into_iter()
            .map(|(level, message)| Log {
                timestamp: Some(timestamp(now)),
                level: level as i32,
                message,
                name: self.log_name.clone(),
                ..Log::default()
            })
            .collect();
        Turned {
            frames,
            scene,
            logs,
        }
    }

    /// Site `i`'s newest sample (the first says the site is live).
    fn offer(&mut self, i: usize, m: LiveSample) {
        if i >= self.scenes.len() {
            return;
        }
        if self.shown[i].is_none() && self.newest[i].is_none() {
            let text = format!("{}: live", self.scenes[i].site);
            self.logs.push((Level::Info, text));
        }
        self.newest[i] = Some(m);
    }
}

/// The viewers' queues.
type Viewers = Arc<Mutex<Vec<SyncSender<Turn>>>>;
/// What a viewer gets when it subscribes, sent before the turns' frames: the `/log` frames so far
/// (the newest [`LOG_KEPT`]; events that happened before it connected are not lost to it) and the
/// last whole `/scene` (the turns between carry only what changed).
#[derive(Default)]
struct Backlog {
    logs: Vec<Frame>,
    scene: Option<Frame>,
}
/// Log frames kept for late viewers.
const LOG_KEPT: usize = 256;

/// The live view: the WebSocket server and the thread that feeds it.
pub struct LiveView {
    addr: SocketAddr,
    shown: Arc<Mutex<Shown>>,
    stop: Arc<AtomicU64>,
    threads: Vec<JoinHandle<()>>,
}

impl std::fmt::Debug for LiveView {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveView")
            .field("addr", &self.addr)
            .finish()
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn unix_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// Who follows a session: the subscription to its live key (undeclared when dropped).
#[derive(Debug)]
pub struct Following {
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

/// `addr` as a socket address, or why not.
///
/// # Errors
/// It is not `host:port`.
pub fn parse_addr(addr: &str) -> Result<SocketAddr, LiveViewError> {
    addr.parse().map_err(|_| LiveViewError::Address {
        addr: addr.to_owned(),
    })
}

impl LiveView {
    /// Starts the server on `addr` (`host:port`) and the publishing thread.
    ///
    /// # Errors
    /// `addr` is not `host:port`, the server cannot listen there, or a thread cannot start.
    pub fn start(addr: &str) -> Result<Self, LiveViewError> {
        let want = parse_addr(addr)?;
        let listen_err = |error| LiveViewError::Listen {
            addr: addr.to_owned(),
            error,
        };
        let listener = TcpListener::bind(want).map_err(listen_err)?;
        let addr = listener.local_addr().map_err(listen_err)?;
        listener.set_nonblocking(true).map_err(listen_err)?;
        let shown: Arc<Mutex<Shown>> = Arc::default();
        let stop = Arc::new(AtomicU64::new(0));
        let viewers: Viewers = Arc::default();
        let backlog: Arc<Mutex<Backlog>> = Arc::default();
        let spawn = |what: &'static str, f: Box<dyn FnOnce() + Send>| {
            std::thread::Builder::new()
                .name(what.into())
                .spawn(f)
                .map_err(|error| LiveViewError::Thread { what, error })
        };
        let mut threads = vec![spawn("live-view", {
            let (shown, stop) = (shown.clone(), stop.clone());
            let (viewers, backlog) = (viewers.clone(), backlog.clone());
            Box::new(move || publish(&viewers, &backlog, &shown, &stop))
        })?];
        let accepting = spawn("live-accept", {
            let (stop, viewers) = (stop.clone(), viewers.clone());
            Box::new(move || accept(&listener, &viewers, &backlog, &stop))
        });
        match accepting {
            Ok(t) => threads.push(t),
            Err(e) => {
                stop.store(1, Ordering::Relaxed);
                for t in threads {
                    let _ = t.join();
                }
                return Err(e);
            }
        }
        Ok(Self {
            addr,
            shown,
            stop,
            threads,
        })
    }

    /// Where viewers connect: `ws://host:port`.
    pub fn url(&self) -> String {
        format!("ws://{}", self.addr)
    }

    /// Shows `session`'s sites `scenes` from now on (forgetting what was shown before), and says
    /// `intro` on `/log`, where `log_name` names the lines.
    pub fn show(&self, session: &str, scenes: Vec<Scene>, log_name: &str, intro: String) {
        let mut s = lock(&self.shown);
        s.session = session.to_owned();
        log_name.clone_into(&mut s.log_name);
        s.newest = vec![None; scenes.len()];
        s.shown = vec![None; scenes.len()];
        s.scenes = scenes;
        s.logs.push((Level::Info, intro));
    }

    /// Site `i`'s (of the scenes shown) newest sample: shown at the next turn unless a newer one
    /// comes first. Takes a short lock and copies; never waits for a viewer.
    pub fn offer(&self, i: usize, m: LiveSample) {
        lock(&self.shown).offer(i, m);
    }

    /// An event for `/log`.
    pub fn log(&self, level: Level, text: String) {
        lock(&self.shown).logs.push((level, text));
    }

    /// Shows `session` (of scenario `sc`) from now on, through the launcher's zenoh session `z`,
    /// until the returned [`Following`] is dropped.
    ///
    /// # Errors
    /// The subscription cannot be declared.
    pub fn follow(
        &self,
        z: &zenoh::Session,
        session: &str,
        sc: &Scenario,
    ) -> Result<Following, LiveViewError> {
        self.show(
            session,
            (0..sc.site.len())
                .filter_map(|i| Scene::from_scenario(sc, i))
                .collect(),
            "session",
            format!(
                "session {session}: scenario {}, method {}, sites {}",
                sc.name,
                sc.method.as_str(),
                sc.site
                    .iter()
                    .map(|s| s.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        );
        let shown = self.shown.clone();
        let name = session.to_owned();
        let subscriber = z
            .declare_subscriber(keys::all_live(session))
            .callback(move |sample| {
                let site = keys::site_of(sample.key_expr().as_str());
                let Ok(m) = serde_json::from_slice::<LiveSample>(&sample.payload().to_bytes())
                else {
                    return;
                };
                let mut s = lock(&shown);
                // A sample of an earlier session still in flight is not this one's.
                if s.session != name {
                    return;
                }
                if let Some(i) = s.scenes.iter().position(|sc| sc.site == site) {
                    s.offer(i, m);
                }
            })
            .wait()
            .map_err(LiveViewError::Subscribe)?;
        Ok(Following {
            _subscriber: subscriber,
        })
    }
}

/// The publishing thread: every [`PERIOD`], what arrived since the last turn.
fn publish(
    viewers: &Mutex<Vec<SyncSender<Turn>>>,
    backlog: &Mutex<Backlog>,
    shown: &Mutex<Shown>,
    stop: &AtomicU64,
) {
    // The stations put at most every LIVE_EVERY_NS; faster turns would only repeat frames.
    let period = PERIOD.max(Duration::from_nanos(LIVE_EVERY_NS));
    let mut next = Instant::now() + period;
    let mut next_whole = Instant::now();
    while stop.load(Ordering::Relaxed) == 0 {
        let now = unix_ns();
        let turned = lock(shown).turn(now, Instant::now() >= next_whole);
        // Encoding and sending happen outside the lock: the zenoh callback never waits for them.
        let mut out: Vec<Frame> = turned
            .frames
            .iter()
            .map(|f| Arc::new((TF, now, encode(f))))
            .collect();
        if let Some((update, whole)) = &turned.scene {
            let frame = Arc::new((SCENE, now, encode(update)));
            if *whole {
                next_whole = Instant::now() + WHOLE_SCENE_EVERY;
                lock(backlog).scene = Some(frame.clone());
            }
            out.push(frame);
        }
        let logs: Vec<Frame> = turned
            .logs
            .iter()
            .map(|l| Arc::new((LOG, now, encode(l))))
            .collect();
        if !logs.is_empty() {
            let h = &mut lock(backlog).logs;
            h.extend(logs.iter().cloned());
            let excess = h.len().saturating_sub(LOG_KEPT);
            h.drain(..excess);
        }
        out.extend(logs);
        if !out.is_empty() {
            // A viewer that is gone is dropped; one that is behind loses this turn.
            let turn: Turn = out.into();
            lock(viewers).retain(|q| {
                !matches!(q.try_send(turn.clone()), Err(TrySendError::Disconnected(_)))
            });
        }
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
            next += period;
        } else {
            // Behind (a stalled machine): start again from now rather than bursting.
            next = now + period;
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        self.stop.store(1, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// The listener: a thread per viewer, until stopped.
fn accept(
    listener: &TcpListener,
    viewers: &Viewers,
    backlog: &Arc<Mutex<Backlog>>,
    stop: &Arc<AtomicU64>,
) {
    while stop.load(Ordering::Relaxed) == 0 {
        match listener.accept() {
            Ok((stream, peer)) => {
                let (tx, rx) = sync_channel(QUEUE);
                lock(viewers).push(tx);
                let (stop, backlog) = (stop.clone(), backlog.clone());
                let _ = std::thread::Builder::new()
                    .name("live-viewer".into())
                    .spawn(move || {
                        if let Err(e) = serve(stream, &rx, &backlog, &stop) {
                            eprintln!("live view: viewer {peer}: {e}");
                        }
                    });
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(ACCEPT_POLL);
            }
            Err(e) => {
                eprintln!("live view: accepting a viewer: {e}");
                std::thread::sleep(ACCEPT_POLL);
            }
        }
    }
}

/// Whether a read or write error is only "nothing yet".
fn would_block(e: &tungstenite::Error) -> bool {
    matches!(e, tungstenite::Error::Io(io)
        if matches!(io.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut))
}

/// One viewer: the handshake (which must offer [`SUBPROTOCOL`]), `serverInfo` and `advertise`,
/// then its subscriptions and the frames of the channels it subscribed to, until it leaves.
fn serve(
    stream: TcpStream,
    frames: &Receiver<Turn>,
    backlog: &Mutex<Backlog>,
    stop: &AtomicU64,
) -> Result<(), tungstenite::Error> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    stream.set_read_timeout(Some(Duration::from_secs(5)))?;
    // The handshake callback's error is tungstenite's own (an HTTP response) type.
    #[allow(clippy::result_large_err)]
    let check = |req: &Request, mut res: Response| -> Result<Response, ErrorResponse> {
        let offered = req
            .headers()
            .get_all("sec-websocket-protocol")
            .iter()
            .filter_map(|h| h.to_str().ok())
            .flat_map(|h| h.split(','))
            .any(|p| p.trim() == SUBPROTOCOL);
        if !offered {
            let mut e = ErrorResponse::new(Some(format!("offer subprotocol {SUBPROTOCOL}")));
            *e.status_mut() = tungstenite::http::StatusCode::BAD_REQUEST;
            return Err(e);
        }
        res.headers_mut().insert(
            "sec-websocket-protocol",
            tungstenite::http::HeaderValue::from_static(SUBPROTOCOL),
        );
        Ok(res)
    };
    let mut ws = tungstenite::accept_hdr(stream, check)
        .map_err(|e| tungstenite::Error::Io(std::io::Error::other(format!("handshake: {e}"))))?;
    ws.get_ref().set_read_timeout(None)?;
    ws.get_ref()
        .set_write_timeout(Some(Duration::from_secs(2)))?;
    let b64 = base64::engine::general_purpose::STANDARD;
    let advertised: Vec<serde_json::Value> = channels()
        .iter()
        .map(|(id, topic, s)| {
            serde_json::json!({
                "id": id, "topic": topic, "encoding": "protobuf",
                "schemaName": s.name, "schemaEncoding": s.encoding, "schema": b64.encode(&s.data),
            })
        })
        .collect();
    for m in [
        serde_json::json!({
            "op": "serverInfo", "name": "coop-haptics session", "capabilities": [],
            "supportedEncodings": [], "metadata": {}, "sessionId": format!("{}", std::process::id()),
        }),
        serde_json::json!({ "op": "advertise", "channels": advertised }),
    ] {
        ws.send(Message::text(m.to_string()))?;
    }
    // Subscription id per channel id.
    let mut subs: Vec<(u32, u32)> = Vec::new();
    let mut pending: Vec<Frame> = Vec::new();
    while stop.load(Ordering::Relaxed) == 0 {
        // One wake per publishing turn (or per CLIENT_IDLE without frames): the frames, then
        // whatever the viewer asked meanwhile (read without waiting), then one write and flush.
        match frames.recv_timeout(CLIENT_IDLE) {
            Ok(t) => pending.extend(t.iter().cloned()),
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        for t in std::iter::from_fn(|| frames.try_recv().ok()) {
            pending.extend(t.iter().cloned());
        }
        ws.get_ref().set_nonblocking(true)?;
        let read = loop {
            match ws.read() {
                Ok(Message::Text(t)) => {
                    let had =
                        |subs: &[(u32, u32)], channel| subs.iter().any(|(c, _)| *c == channel);
                    let (had_log, had_scene) = (had(&subs, LOG), had(&subs, SCENE));
                    on_request(&t, &mut subs);
                    // The events so far and the last whole scene go first, before this turn's
                    // frames.
                    let b = lock(backlog);
                    let mut first = Vec::new();
                    if !had_log && had(&subs, LOG) {
                        first.extend(b.logs.iter().cloned());
                    }
                    if let Some(whole) =
                        b.scene.as_ref().filter(|_| !had_scene && had(&subs, SCENE))
                    {
                        // Arrows older than it are in it already.
                        pending.retain(|f| f.0 != SCENE || f.1 > whole.1);
                        first.push(whole.clone());
                    }
                    drop(b);
                    first.append(&mut pending);
                    pending = first;
                }
                Ok(Message::Close(_)) => break Ok(false),
                Ok(_) => {}
                Err(e) if would_block(&e) => break Ok(true),
                Err(tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed) => {
                    break Ok(false)
                }
                Err(e) => break Err(e),
            }
        };
        ws.get_ref().set_nonblocking(false)?;
        if !read? {
            return Ok(());
        }
        let mut sent = false;
        for f in pending.drain(..) {
            let (channel, t_ns, data) = &*f;
            if let Some(&(_, sub)) = subs.iter().find(|(c, _)| c == channel) {
                let mut m = Vec::with_capacity(13 + data.len());
                m.push(0x01); // messageData
                m.extend_from_slice(&sub.to_le_bytes());
                m.extend_from_slice(&t_ns.to_le_bytes());
                m.extend_from_slice(data);
                match ws.write(Message::binary(m)) {
                    Ok(()) => sent = true,
                    Err(e) if would_block(&e) => sent = true,
                    Err(e) => return Err(e),
                }
            }
        }
        if sent {
            match ws.flush() {
                Ok(()) => {}
                Err(e) if would_block(&e) => {}
                Err(e) => return Err(e),
            }
        }
    }
    let _ = ws.close(None);
    Ok(())
}

/// A viewer's `subscribe` or `unsubscribe` (others are ignored, as the protocol allows).
fn on_request(text: &str, subs: &mut Vec<(u32, u32)>) {
    let Ok(v) = serde_json::from_str::<serde_json::Value>(text) else {
        return;
    };
    let as_u32 = |v: &serde_json::Value| v.as_u64().and_then(|n| u32::try_from(n).ok());
    match v["op"].as_str() {
        Some("subscribe") => {
            for s in v["subscriptions"].as_array().into_iter().flatten() {
                if let (Some(id), Some(channel)) = (as_u32(&s["id"]), as_u32(&s["channelId"])) {
                    if channels().iter().any(|c| c.0 == channel) {
                        subs.retain(|(c, _)| *c != channel);
                        subs.push((channel, id));
                    }
                }
            }
        }
        Some("unsubscribe") => {
            let ids: Vec<u32> = v["subscriptionIds"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(as_u32)
                .collect();
            subs.retain(|(_, id)| !ids.contains(id));
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::scene::{site_colour, Body, ARROW_MIN_N};

    fn shown(sites: &[&str]) -> Shown {
        let scenes = sites
            .iter()
            .enumerate()
            .map(|(i, site)| Scene {
                site: (*site).into(),
                colour: site_colour(i),
                object: Body::Sphere { radius: 0.04 },
                tool_radius_m: 0.005,
                planes: vec![([0.0, 0.0, 1.0], 0.0)],
                others: Vec::new(),
                first_name: String::new(),
            })
            .collect::<Vec<_>>();
        Shown {
            session: "s".into(),
            newest: vec![None; scenes.len()],
            shown: vec![None; scenes.len()],
            scenes,
            ..Shown::default()
        }
    }

    fn sample(f_object: [f64; 3]) -> LiveSample {
        LiveSample {
            sample: SampleMsg {
                rot: [1.0, 0.0, 0.0, 0.0],
                f_object,
                ..SampleMsg::default()
            },
            others: Vec::new(),
        }
    }

    /// Entity ids of a turn's scene and whether it is the whole one.
    fn scene_of(t: &Turned) -> Option<(Vec<String>, bool)> {
        t.scene
            .as_ref()
            .map(|(u, whole)| (u.entities.iter().map(|e| e.id.clone()).collect(), *whole))
    }

    fn ids(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| (*s).to_owned()).collect()
    }

    #[test]
    fn a_scene_goes_whole_when_a_site_shows_or_it_is_due_and_else_only_the_changed_arrows() {
        let mut s = shown(&["a", "b"]);
        s.offer(0, sample([0.0; 3]));
        let t = s.turn(1, false);
        assert_eq!(t.frames.len(), 2);
        assert_eq!(
            scene_of(&t),
            Some((ids(&["environment", "object/a", "tool/a", "force/a"]), true))
        );
        assert_eq!(t.logs.len(), 1, "a: live");
        // The same arrow (none: below the least drawn) moves with the frames only.
        s.offer(0, sample([0.0, 0.0, ARROW_MIN_N / 2.0]));
        let t = s.turn(2, false);
        assert_eq!((t.frames.len(), scene_of(&t)), (2, None));
        // A changed force: its arrow alone.
        s.offer(0, sample([0.0, 0.0, 1.0]));
        assert_eq!(
            scene_of(&s.turn(3, false)),
            Some((ids(&["force/a"]), false))
        );
        // A site showing for the first time: every site's entities.
        s.offer(1, sample([0.0; 3]));
        let (all, whole) = scene_of(&s.turn(4, false)).expect("a scene");
        assert_eq!((all.len(), whole), (7, true));
        // Due: the whole scene, if a sample came.
        assert!(scene_of(&s.turn(5, true)).is_none());
        s.offer(1, sample([0.0; 3]));
        let (all, whole) = scene_of(&s.turn(6, true)).expect("a scene");
        assert_eq!((all.len(), whole), (7, true));
    }
}
