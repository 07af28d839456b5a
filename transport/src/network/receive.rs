//! Receiving the other sites' states: each one is checked ([`wire::Inbound::check`]: typed refusals
//! are counted, never applied), its time corrected by the sender's clock offset, passed through the
//! emulated link when configured, and handed to physics through the network → physics ring. A late
//! joiner first asks for the session's current states.

use std::sync::Mutex;
use std::time::Duration;

use coop_rt::msg::SiteReport;
use coop_rt::shm::control::{ControlBlock, CounterKey, Ring};
use coop_rt::shm::Producer;
use coop_rt::sync::{AtomicU64, Ordering};
use coop_rt::timer::monotonic_ns;
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::sample::{Locality, Sample};
use zenoh::{Session, Wait};

use super::emulate::{Emulation, Emulator};
use super::{lock, NetworkError};
use crate::recording::RemoteMsg;
use crate::{keys, wire};

/// A checked state on its way to physics (now, or when the emulated link delivers it).
#[derive(Debug, Clone, Copy)]
pub(super) struct Delivery {
    from: usize,
    report: SiteReport,
    /// The emulated delay still to wait when it arrived, s.
    delay_s: f64,
    /// The sender's clock offset it was corrected by, ns.
    offset_ns: i64,
}

/// Everything that handles received states, shared by the delivery thread and the loop.
pub(super) struct Receiver<'a> {
    me: usize,
    control: &'a ControlBlock,
    pub(super) inbound: wire::Inbound,
    remote: Producer<SiteReport>,
    emulator: Option<Emulator>,
    pub(super) received: u64,
    pub(super) join_states: u64,
    pub(super) refused: [u64; 5],
    pub(super) emulated_lost: u64,
    /// What was handed to physics since the loop last took it, for the recording.
    pub(super) log: Vec<RemoteMsg>,
}

impl<'a> Receiver<'a> {
    /// Site `me` of `sites`, handing over into `remote`.
    pub(super) fn new(
        sites: &[String],
        me: usize,
        control: &'a ControlBlock,
        remote: Producer<SiteReport>,
        emulation: Option<&Emulation>,
    ) -> Self {
        Self {
            me,
            control,
            inbound: wire::Inbound::new(sites.to_vec()),
            remote,
            emulator: emulation.map(|e| Emulator::new(e, sites.len(), me)),
            received: 0,
            join_states: 0,
            refused: [0; 5],
            emulated_lost: 0,
            log: Vec::new(),
        }
    }

    /// A message on `key`; `join`: a late joiner's catch-up state (not a message on a link).
    pub(super) fn on_bytes(
        &mut self,
        key: &str,
        bytes: &[u8],
        zenoh_ts: Option<String>,
        join: bool,
    ) {
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
        let (release, delay_s) = match &mut self.emulator {
            Some(emu) if !join => {
                let Some(at) = emu.arrival(from, r.t_ns, self.control.epoch()) else {
                    self.emulated_lost += 1;
                    self.control
                        .network
                        .emulated_lost
                        .store(self.emulated_lost, Ordering::Relaxed);
                    return;
                };
                (at.max(now), (at.saturating_sub(now)) as f64 * 1e-9)
            }
            _ => (now, 0.0),
        };
        let d = Delivery {
            from,
            report: r,
            delay_s,
            offset_ns: offset,
        };
        match &mut self.emulator {
            Some(emu) if release > now => emu.hold(release, d),
            _ => self.hand_over(d, zenoh_ts, join, now),
        }
    }

    /// Hands over the held states the emulated link has delivered by `now`.
    pub(super) fn release_due(&mut self, now: u64) {
        while let Some(d) = self.emulator.as_mut().and_then(|e| e.pop_due(now)) {
            self.hand_over(d, None, false, now);
        }
    }

    fn hand_over(&mut self, d: Delivery, zenoh_ts: Option<String>, join: bool, now: u64) {
        if self.remote.push(d.report).is_err() {
            self.control.network.drops.add(Ring::Remote, 1);
            return;
        }
        self.received += 1;
        self.control
            .network
            .received
            .store(self.received, Ordering::Relaxed);
        let age = now.saturating_sub(d.report.t_ns);
        if !join && self.emulator.is_none() {
            let count = self.control.network.latency_count.load(Ordering::Relaxed);
            self.control.network.latency.record(age, count == 0);
            self.control
                .network
                .latency_count
                .store(count + 1, Ordering::Relaxed);
        }
        self.log.push(RemoteMsg {
            t_ns: now,
            from: d.from,
            seq: d.report.seq,
            sent_ns: d.report.t_ns,
            offset_ns: d.offset_ns,
            age_s: age as f64 * 1e-9,
            emulated_delay_s: d.delay_s,
            zenoh_ts,
            via: if join { "join" } else { "live" }.into(),
        });
    }
}

/// Late join: the session's current states, asked for before subscribing (so they are what physics
/// adopts first, not refused as older than a live state that overtook them).
pub(super) fn join_from_current(session: &Session, session_name: &str, rx: &Mutex<Receiver<'_>>) {
    let Ok(replies) = session
        .get(keys::all_current(session_name, 0))
        .allowed_destination(Locality::Remote)
        .timeout(Duration::from_secs(1))
        .wait()
    else {
        return;
    };
    while let Ok(reply) = replies.recv() {
        if let Ok(s) = reply.result() {
            // The replying site's own key carries its name.
            let key = s.key_expr().as_str().to_owned();
            lock(rx).on_bytes(&key, &s.payload().to_bytes(), None, true);
        }
    }
}

/// The other sites' live states, queued by zenoh for [`deliver`].
pub(super) type States = Subscriber<FifoChannelHandler<Sample>>;

/// Subscribes to the other sites' live states.
pub(super) fn subscribe(session: &Session, session_name: &str) -> Result<States, NetworkError> {
    session
        .declare_subscriber(keys::all_states(session_name, 0))
        .allowed_origin(Locality::Remote)
        .with(zenoh::handlers::FifoChannel::new(1024))
        .wait()
        .map_err(NetworkError::declare("subscriber"))
}

/// The delivery thread: each state is handled the moment zenoh hands it over, until `stop`.
pub(super) fn deliver(states: &States, rx: &Mutex<Receiver<'_>>, stop: &AtomicU64) {
    while stop.load(Ordering::Relaxed) == 0 {
        match states.recv_timeout(Duration::from_millis(50)) {
            Ok(Some(s)) => {
                let ts = s.timestamp().map(ToString::to_string);
                lock(rx).on_bytes(s.key_expr().as_str(), &s.payload().to_bytes(), ts, false);
            }
            Ok(None) => {}
            Err(_) => break,
        }
    }
}
