//! The non-real-time half of the Haply backend: a thread that owns the WebSocket to the Inverse
//! Service and exchanges with the servo through lock-free structures only.
//!
//! - service → servo: an rtrb SPSC ring of [`BridgeMsg`] (each state frame as a [`Sample`], or a
//!   fault); the servo pops them all and keeps the newest.
//! - servo → service: a [`CommandSlot`], a single-writer seqlock of the newest command (newest wins:
//!   a servo that commands faster than the bridge sends overwrites, never queues).
//!
//! The bridge paces itself at `rate_hz` (the service answers one frame per message, so our send rate
//! is the stream's rate), reconnects after `reconnect_ms` when the service goes, and sends zero force
//! whenever it cannot vouch for the command: until the servo commands after a (re)connection, and
//! after a frame it refused until the servo commands after the next good one.

use std::net::{TcpStream, ToSocketAddrs};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use coop_model::body::Vec3;
use tungstenite::{Message, WebSocket};

use super::wire::{self, FrameError};
use super::HaplyOpenError;
use crate::device::{Command, CommandSlot, DeviceFault, Sample};
use crate::sync::{AtomicU64, Ordering};
use crate::timer::{monotonic_ns, sleep_until};

/// What the bridge tells the servo.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum BridgeMsg {
    /// A state frame, stamped when it arrived.
    Frame {
        /// The sample.
        sample: Sample,
        /// `current_cursor_force`: what the service displays now.
        displayed_force_n: Option<Vec3>,
    },
    /// The connection is gone, or a frame was refused.
    Fault(DeviceFault),
}

/// Counters and status both halves and the station's status can read.
#[derive(Debug, Default)]
pub struct BridgeStats {
    /// Good state frames received.
    pub frames: AtomicU64,
    /// Frames refused (not JSON, wrong shape, out of range).
    pub bad_frames: AtomicU64,
    /// Successful reconnections after a loss.
    pub reconnects: AtomicU64,
    /// Connections lost (closed, reset, timed out).
    pub losses: AtomicU64,
    /// 1 while the socket is up.
    connected: AtomicU64,
    /// Force commands sent that were not zero.
    pub forces_sent: AtomicU64,
    last_error: Mutex<Option<String>>,
}

impl BridgeStats {
    /// Whether the socket is up now.
    pub fn connected(&self) -> bool {
        // SYNC: pairs with the bridge's Release stores on connect and loss.
        self.connected.load(Ordering::Acquire) == 1
    }
    pub(super) fn set_connected(&self, up: bool) {
        self.connected.store(u64::from(up), Ordering::Release);
    }
    /// The last thing that went wrong, in words (not for the servo path: it locks).
    pub fn last_error(&self) -> Option<String> {
        self.last_error.lock().map(|e| e.clone()).unwrap_or(None)
    }
    fn set_error(&self, e: String) {
        if let Ok(mut g) = self.last_error.lock() {
            *g = Some(e);
        }
    }
}

/// What both halves share.
#[derive(Debug, Default)]
pub(super) struct Shared {
    /// 1 once the servo side closes.
    pub(super) stop: AtomicU64,
    pub(super) cmd: CommandSlot,
    pub(super) stats: BridgeStats,
}

/// Where and how the bridge connects.
#[derive(Debug, Clone)]
pub(super) struct Target {
    pub(super) url: String,
    pub(super) connect_timeout: Duration,
    pub(super) io_timeout: Duration,
}

/// An open simulation channel.
pub(super) type Ws = WebSocket<TcpStream>;

/// Connects, and reads the snapshot the service sends on connect.
pub(super) fn connect(t: &Target) -> Result<(Ws, serde_json::Value), HaplyOpenError> {
    let unreachable = |reason: String| HaplyOpenError::Unreachable {
        url: t.url.clone(),
        reason,
    };
    let uri: tungstenite::http::Uri = t
        .url
        .parse()
        .map_err(|e: tungstenite::http::uri::InvalidUri| unreachable(e.to_string()))?;
    let host = uri.host().unwrap_or("localhost").to_owned();
    let port = uri.port_u16().unwrap_or(80);
    let addrs: Vec<_> = (host.as_str(), port)
        .to_socket_addrs()
        .map_err(|e| unreachable(e.to_string()))?
        .collect();
    let mut last = String::from("no address");
    let mut stream = None;
    for a in addrs {
        match TcpStream::connect_timeout(&a, t.connect_timeout) {
            Ok(s) => {
                stream = Some(s);
                break;
            }
            Err(e) => last = e.to_string(),
        }
    }
    let stream = stream.ok_or_else(|| unreachable(last))?;
    let setup = |s: &TcpStream| -> std::io::Result<()> {
        s.set_nodelay(true)?;
        s.set_read_timeout(Some(t.connect_timeout))?;
        s.set_write_timeout(Some(t.io_timeout))
    };
    setup(&stream).map_err(|e| unreachable(e.to_string()))?;
    let (mut ws, _) = tungstenite::client::client(t.url.as_str(), stream).map_err(|e| {
        HaplyOpenError::Handshake {
            url: t.url.clone(),
            reason: e.to_string(),
        }
    })?;
    let snapshot = read_frame(&mut ws).map_err(|e| match e {
        ReadError::Io(reason) => HaplyOpenError::NoSnapshot {
            url: t.url.clone(),
            reason,
        },
        ReadError::Bad(e) => HaplyOpenError::BadSnapshot {
            url: t.url.clone(),
            reason: e.to_string(),
        },
    })?;
    ws.get_ref()
        .set_read_timeout(Some(t.io_timeout))
        .map_err(|e| unreachable(e.to_string()))?;
    Ok((ws, snapshot))
}

enum ReadError {
    Io(String),
    Bad(FrameError),
}

/// Reads the next data frame (control frames are answered by tungstenite and skipped).
fn read_frame(ws: &mut Ws) -> Result<serde_json::Value, ReadError> {
    loop {
        match ws.read() {
            Ok(Message::Text(t)) => return wire::parse(t.as_str()).map_err(ReadError::Bad),
            Ok(Message::Binary(_)) => {
                return Err(ReadError::Bad(FrameError {
                    what: "haply frame is binary",
                    detail: "the service speaks JSON text".into(),
                }))
            }
            Ok(Message::Close(c)) => {
                return Err(ReadError::Io(format!("closed by the service: {c:?}")))
            }
            Ok(_) => {}
            Err(e) => return Err(ReadError::Io(e.to_string())),
        }
    }
}

/// Everything the bridge thread owns.
pub(super) struct Bridge {
    pub(super) target: Target,
    pub(super) device_id: String,
    pub(super) period_ns: u64,
    pub(super) reconnect: Duration,
    pub(super) shared: Arc<Shared>,
    pub(super) tx: rtrb::Producer<BridgeMsg>,
    /// The command count when the connection `run` starts on was made.
    pub(super) gate: u64,
}

impl Bridge {
    /// Runs until `shared.stop`, starting on the connection `open` made.
    pub(super) fn run(mut self, ws: Ws) {
        // A thread inherits its creator's policy and affinity: a bridge started from the servo
        // thread would be SCHED_FIFO on the servo's CPU. It is not real-time: make it an ordinary
        // thread that may run on any CPU, so it never competes with the servo at its priority.
        crate::sched::make_ordinary();
        let id_json = serde_json::Value::from(self.device_id.as_str()).to_string();
        let mut out = String::with_capacity(160);
        let mut conn = Some(ws);
        // Commands written up to this count are not ours to send (sent as zero instead). Taken when
        // the connection was made (in `open`), not when this thread got going: a command the servo
        // wrote in between is the servo's, and must not be mistaken for a stale one.
        let mut gate = self.gate;
        let mut refused = false;
        let mut next = monotonic_ns();
        while !self.stopped() {
            let Some(ws) = conn.as_mut() else {
                conn = self.reconnect_until_stopped(&mut gate);
                next = monotonic_ns();
                continue;
            };
            next = next.saturating_add(self.period_ns).max(monotonic_ns());
            sleep_until(next);
            let (seq, cmd) = self.shared.cmd.load();
            let force = match cmd {
                Command::Force(f) if seq > gate && !refused => f,
                _ => Vec3::zeros(),
            };
            wire::encode_force(&mut out, &id_json, force);
            if let Err(e) = ws.send(Message::text(out.as_str())) {
                self.lost(format!("sending to the service: {e}"));
                conn = None;
                continue;
            }
            if force != Vec3::zeros() {
                self.shared
                    .stats
                    .forces_sent
                    .fetch_add(1, Ordering::Relaxed);
            }
            let got = read_frame(ws)
                .and_then(|f| wire::device_state(&f, &self.device_id).map_err(ReadError::Bad));
            match got {
                Ok(s) => {
                    if refused {
                        // A good frame again: forces resume once the servo commands after it.
                        refused = false;
                        gate = self.shared.cmd.load().0;
                    }
                    self.shared.stats.frames.fetch_add(1, Ordering::Relaxed);
                    let sample = Sample {
                        t_ns: monotonic_ns(),
                        position_m: s.position_m,
                        velocity_m_s: s.velocity_m_s,
                        orientation: s.orientation,
                        buttons: s.buttons,
                        force_sensed_n: None,
                    };
                    self.send(BridgeMsg::Frame {
                        sample,
                        displayed_force_n: s.displayed_force_n,
                    });
                }
                Err(ReadError::Bad(e)) => {
                    refused = true;
                    self.shared.stats.bad_frames.fetch_add(1, Ordering::Relaxed);
                    self.shared.stats.set_error(e.to_string());
                    self.send(BridgeMsg::Fault(DeviceFault::BadValue { what: e.what }));
                }
                Err(ReadError::Io(e)) => {
                    self.lost(format!("reading from the service: {e}"));
                    conn = None;
                }
            }
        }
        if let Some(mut ws) = conn {
            // Leave the device at zero force, then say goodbye.
            wire::encode_force(&mut out, &id_json, Vec3::zeros());
            let _ = ws.send(Message::text(out.as_str()));
            let _ = ws.close(None);
            let _ = ws.flush();
        }
        self.shared.stats.set_connected(false);
    }

    fn stopped(&self) -> bool {
        // SYNC: pairs with the servo side's Release store in `close`.
        self.shared.stop.load(Ordering::Acquire) == 1
    }

    fn send(&mut self, m: BridgeMsg) {
        // A full ring means the servo is not reading; the newest is what matters, so drop this one.
        let _ = self.tx.push(m);
    }

    fn lost(&mut self, why: String) {
        self.shared.stats.set_connected(false);
        self.shared.stats.losses.fetch_add(1, Ordering::Relaxed);
        self.shared.stats.set_error(why);
        self.send(BridgeMsg::Fault(DeviceFault::Disconnected));
    }

    /// Tries again every `reconnect` until connected with our device listed, or stopped.
    fn reconnect_until_stopped(&mut self, gate: &mut u64) -> Option<Ws> {
        while !self.stopped() {
            let wake = monotonic_ns().saturating_add(self.reconnect.as_nanos() as u64);
            while monotonic_ns() < wake && !self.stopped() {
                std::thread::sleep(Duration::from_millis(5));
            }
            match connect(&self.target) {
                Ok((ws, snapshot)) => {
                    let listed = wire::list_devices(&snapshot)
                        .map(|l| l.iter().any(|d| d.device_id == self.device_id))
                        .unwrap_or(false);
                    if !listed {
                        self.shared.stats.set_error(format!(
                            "reconnected, but Inverse3 {} is not listed",
                            self.device_id
                        ));
                        continue;
                    }
                    // Whatever the servo commanded before is not ours to send now.
                    *gate = self.shared.cmd.load().0;
                    self.shared.stats.reconnects.fetch_add(1, Ordering::Relaxed);
                    self.shared.stats.set_connected(true);
                    return Some(ws);
                }
                Err(e) => self.shared.stats.set_error(e.to_string()),
            }
        }
        None
    }
}
