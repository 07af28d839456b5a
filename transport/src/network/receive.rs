//! Receiving the other sites' states: each one is checked ([`admit::Inbound::check`]: its site, its
//! time once corrected by the sender's clock offset, its plausibility, its sequence; typed refusals
//! are counted, never applied), passed through the emulated link when configured, checked against
//! the age limit again, and handed to physics through the network → physics ring. A late joiner
//! first asks for the session's current states. A site silent for longer than its loss limit is
//! *lost*: physics is told (so what it still applies of that site fades out), status and the
//! recording show it, and so they show when it is heard again.

use std::sync::Mutex;
use std::time::Duration;

use coop_model::world::MAX_OBJECTS;
use coop_rt::msg::{SiteReport, ToolTrack};
use coop_rt::shm::control::{
    record_counted, ControlBlock, CounterKey, Ring, WireKind, REFUSED_REASONS,
};
use coop_rt::shm::Producer;
use coop_rt::sync::{AtomicU64, Ordering};
use coop_rt::timer::monotonic_ns;
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::sample::{Locality, Sample};
use zenoh::{Session, Wait};

use super::clock::Sampler;
use super::emulate::{Emulation, Emulator};
use super::{lock, NetworkError};
use crate::admit::{self, Bounds, Refusal};
use crate::recording::{PeerMsg, RemoteMsg};
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
    sites: Vec<String>,
    control: &'a ControlBlock,
    pub(super) inbound: admit::Inbound,
    remote: Producer<SiteReport>,
    emulator: Option<Emulator<Delivery>>,
    pub(super) received: u64,
    pub(super) join_states: u64,
    pub(super) refused: [u64; REFUSED_REASONS],
    pub(super) emulated_lost: u64,
    /// Per site: how long it may be silent before it is lost, ns.
    silence_ns: Vec<u64>,
    /// Per site: when a state of it was last taken (our clock), if ever since it joined. Kept
    /// for a lost site when it leaves (zenoh drops a peer silent past its lease), so "heard
    /// again after" is the whole silence.
    last_heard: Vec<Option<u64>>,
    lost: u64,
    losses: u64,
    rejoins: u64,
    resyncs: u64,
    /// What was handed to physics since the loop last took it, for the recording.
    pub(super) log: Vec<RemoteMsg>,
    /// Sites lost and heard again since the loop last took them, for the recording.
    pub(super) peer_log: Vec<PeerMsg>,
    /// Per site and object (`site * MAX_OBJECTS + object`): its newest state that arrived before
    /// its clock offset was known.
    waiting: Vec<Option<Waiting>>,
    held: u64,
    /// Tool tracks (methods that exchange tools), if this station takes them.
    pub(super) tracks: Option<TrackIn>,
    /// What may reach physics (a study's station changing trials: nothing, then only what was
    /// sent from the new trial's time 0 on).
    pub(super) gate: Gate,
}

/// What a study's station lets through to physics while it changes trials.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Gate {
    /// Everything (no study, or a trial under way).
    Open,
    /// Nothing: the next trial is being set up; what arrives is of the last one.
    Closed,
    /// Only what was sent at or after this time (our clock, ns): the trial's time 0. Everything
    /// of the last trial was sent before it, since the runner announces it only once every
    /// station has stopped that trial.
    From(u64),
}

impl Gate {
    fn lets(self, sent_ns: u64) -> bool {
        match self {
            Gate::Open => true,
            Gate::Closed => false,
            Gate::From(t0) => sent_ns >= t0,
        }
    }
}

/// The receive side of tool tracks: checked by the same rules and counters as states
/// ([`admit::Inbound::check_track`]), delayed by their own emulated links when the station
/// emulates (the same law and seed as its states'), handed to physics through the track ring.
pub(super) struct TrackIn {
    ring: Producer<ToolTrack>,
    emulator: Option<Emulator<ToolTrack>>,
    /// Per site: its newest tracks that arrived before its clock offset was known (a burst may
    /// carry a world's objects, one a track: up to [`MAX_OBJECTS`] kept).
    waiting: Vec<Vec<ToolTrack>>,
    /// Tracks handed to physics.
    pub(super) received: u64,
}

/// A message held until its sender's clock offset is known: decoded once, checked when it can be.
struct Waiting {
    key: String,
    report: SiteReport,
    zenoh_ts: Option<String>,
    join: bool,
}

impl<'a> Receiver<'a> {
    /// Site `me` of `sites` in a world of `bounds`, handing over into `remote`; site j is lost
    /// after `silence_ns[j]` without a state.
    pub(super) fn new(
        sites: &[String],
        me: usize,
        control: &'a ControlBlock,
        remote: Producer<SiteReport>,
        emulation: Option<&Emulation>,
        bounds: Bounds,
        silence_ns: Vec<u64>,
    ) -> Self {
        Self {
            me,
            sites: sites.to_vec(),
            control,
            inbound: admit::Inbound::new(sites.to_vec(), bounds),
            remote,
            emulator: emulation.map(|e| Emulator::new(e, sites.len(), me)),
            received: 0,
            join_states: 0,
            refused: [0; REFUSED_REASONS],
            emulated_lost: 0,
            silence_ns,
            last_heard: vec![None; sites.len()],
            lost: 0,
            losses: 0,
            rejoins: 0,
            resyncs: 0,
            log: Vec::new(),
            peer_log: Vec::new(),
            waiting: (0..sites.len() * MAX_OBJECTS).map(|_| None).collect(),
            held: 0,
            tracks: None,
            gate: Gate::Open,
        }
    }

    /// A study's next trial: nothing more reaches physics until [`Receiver::gate`] opens again,
    /// and what was held or known of the last trial is dropped (its emulated links, its sites'
    /// silences, its held states); the new trial's links are `emulation`, its bounds `bounds`,
    /// its silences `silence_ns`. The counters go on.
    pub(super) fn begin_trial(
        &mut self,
        emulation: Option<&Emulation>,
        bounds: Bounds,
        silence_ns: Vec<u64>,
    ) {
        self.gate = Gate::Closed;
        let n = self.sites.len();
        self.inbound = admit::Inbound::new(self.sites.clone(), bounds);
        self.emulator = emulation.map(|e| Emulator::new(e, n, self.me));
        self.silence_ns = silence_ns;
        self.last_heard = vec![None; n];
        self.lost = 0;
        self.control.network.peers_lost.store(0, Ordering::Relaxed);
        for w in &mut self.waiting {
            *w = None;
        }
        if let Some(tr) = &mut self.tracks {
            tr.emulator = emulation.map(|e| Emulator::new(e, n, self.me));
            for w in &mut tr.waiting {
                w.clear();
            }
        }
    }

    /// Takes the other sites' tool tracks too, handing them over into `ring`.
    pub(super) fn take_tracks(&mut self, ring: Producer<ToolTrack>, emulation: Option<&Emulation>) {
        self.tracks = Some(TrackIn {
            ring,
            emulator: emulation.map(|e| Emulator::new(e, self.sites.len(), self.me)),
            waiting: vec![Vec::new(); self.sites.len()],
            received: 0,
        });
    }

    /// A tool track on `key`, decoded once here.
    pub(super) fn on_track(&mut self, key: &str, bytes: &[u8]) {
        match wire::decode_track(bytes) {
            Ok(t) => self.on_decoded_track(key, t),
            Err(e) => self.refuse(key, &Refusal::from(e)),
        }
    }

    /// A decoded tool track on `key`: checked, held for its sender's clock offset, or handed on.
    fn on_decoded_track(&mut self, key: &str, track: ToolTrack) {
        let now = monotonic_ns();
        let offsets = self.offsets();
        let epoch = self.control.epoch();
        let Some(tr) = self.tracks.as_mut() else {
            return;
        };
        let a = match self
            .inbound
            .check_track_decoded(keys::site_of(key), track, now, &offsets)
        {
            Ok(a) => a,
            Err(Refusal::NoOffset { site }) => {
                // As a state: the newest are held until its sender's time can be read.
                let w = &mut tr.waiting[site];
                if w.len() == MAX_OBJECTS {
                    w.remove(0);
                }
                w.push(track);
                return;
            }
            Err(e) => return self.refuse(key, &e),
        };
        if a.site == self.me {
            return;
        }
        tr.waiting[a.site].clear();
        let release = match &mut tr.emulator {
            Some(emu) => match emu.arrival(a.site, a.track.t_ns, epoch) {
                Some(at) => at,
                None => {
                    self.emulated_lost += 1;
                    self.control
                        .network
                        .emulated_lost
                        .store(self.emulated_lost, Ordering::Relaxed);
                    return;
                }
            },
            None => now,
        };
        match &mut tr.emulator {
            Some(emu) if release > now => emu.hold(release, a.track),
            _ => self.hand_over_track(a.track, now),
        }
    }

    /// Hands over the held tracks the emulated links have delivered by `now`, and checks again
    /// those held for their sender's clock offset.
    pub(super) fn release_tracks(&mut self, now: u64) {
        let offsets = self.offsets();
        let Some(tr) = self.tracks.as_mut() else {
            return;
        };
        let mut retry: Vec<(usize, ToolTrack)> = Vec::new();
        for (j, known) in offsets.iter().enumerate() {
            if let (Some(_), Some(w)) = (known, tr.waiting.get_mut(j)) {
                retry.extend(w.drain(..).map(|b| (j, b)));
            }
        }
        let mut due = Vec::new();
        while let Some(t) = tr.emulator.as_mut().and_then(|e| e.pop_due(now)) {
            due.push(t);
        }
        for (j, t) in retry {
            let key = keys::tool("", 0, &self.sites[j]);
            self.on_decoded_track(&key, t);
        }
        for t in due {
            self.hand_over_track(t, now);
        }
    }

    fn hand_over_track(&mut self, t: ToolTrack, now: u64) {
        let from = t.site as usize;
        if !self.gate.lets(t.t_ns) {
            return;
        }
        if let Err(e) = self.inbound.age_ok(from, t.t_ns, now) {
            let key = format!("{}'s tool track, at hand-over", self.sites[from]);
            return self.refuse(&key, &e);
        }
        let Some(tr) = self.tracks.as_mut() else {
            return;
        };
        if tr.ring.push(t).is_err() {
            self.control.network.drops.add(Ring::Remote, 1);
            return;
        }
        tr.received += 1;
        self.heard(from, now);
    }

    /// Checks again the held messages whose sender's clock offset is now known.
    pub(super) fn retry_waiting(&mut self) {
        let offsets = self.offsets();
        for (j, known) in offsets.iter().enumerate() {
            if known.is_some() {
                for k in 0..MAX_OBJECTS {
                    if let Some(w) = self.waiting[j * MAX_OBJECTS + k].take() {
                        self.on_report(&w.key, w.report, w.zenoh_ts, w.join);
                    }
                }
            }
        }
    }

    /// Each site's clock offset where it is known (a measured round trip), ours being 0.
    fn offsets(&self) -> Vec<Option<i64>> {
        let net = &self.control.network;
        (0..self.sites.len())
            .map(|j| {
                if j == self.me {
                    Some(0)
                } else if net.clock_rtt_ns[j].load(Ordering::Acquire) > 0 {
                    // SYNC: Acquire pairs with the sampler's Release of the round trip, stored
                    // after the offset.
                    Some(net.clock_offset_ns[j].load(Ordering::Relaxed) as i64)
                } else {
                    None
                }
            })
            .collect()
    }

    /// Counts a refusal (the first of each kind is said once: an operator sees what is arriving;
    /// the counts are in status).
    fn refuse(&mut self, key: &str, e: &Refusal) {
        let reason = e.reason();
        let slot = reason.slot();
        if self.refused[slot] == 0 {
            eprintln!("network: refused a message on {key}: {e} (further ones are only counted)");
        }
        self.refused[slot] += 1;
        self.control.network.refused.set(reason, self.refused[slot]);
        // Which object's states are refused (a world of several), by the object the key names.
        if key.contains("/state/")
            && matches!(e, Refusal::Implausible { .. } | Refusal::OtherObject { .. })
        {
            let by = &self.control.network.refused_by_object;
            if let Some(c) = keys::object_of(key).and_then(|k| by.get(k as usize)) {
                c.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// A state of `site` was taken at `now`: a lost site is heard again.
    fn heard(&mut self, site: usize, now: u64) {
        let before = self.last_heard[site].replace(now);
        if self.lost & (1 << site) != 0 {
            self.lost &= !(1 << site);
            self.rejoins += 1;
            let net = &self.control.network;
            net.peers_lost.store(self.lost, Ordering::Relaxed);
            net.peer_rejoins.store(self.rejoins, Ordering::Relaxed);
            let silent_s = before.map_or(0.0, |b| now.saturating_sub(b) as f64 * 1e-9);
            eprintln!(
                "network: site {} heard again after {silent_s:.2} s",
                self.sites[site]
            );
            self.peer_log.push(PeerMsg {
                t_ns: now,
                site: self.sites[site].clone(),
                event: "rejoined".into(),
                silent_s,
            });
        }
    }

    /// Marks the sites silent past their limit at `now` as lost, and tells physics.
    pub(super) fn check_lost(&mut self, now: u64) {
        if self.gate == Gate::Closed {
            return;
        }
        for j in 0..self.sites.len() {
            let Some(t) = self.last_heard[j] else {
                continue;
            };
            let silent = now.saturating_sub(t);
            if j == self.me || self.lost & (1 << j) != 0 || silent <= self.silence_ns[j] {
                continue;
            }
            if self.remote.push(SiteReport::lost(j, now)).is_err() {
                // Physics must hear of it: try again next turn.
                self.control.network.drops.add(Ring::Remote, 1);
                continue;
            }
            self.lost |= 1 << j;
            self.losses += 1;
            let net = &self.control.network;
            net.peers_lost.store(self.lost, Ordering::Relaxed);
            net.peer_losses.store(self.losses, Ordering::Relaxed);
            let silent_s = silent as f64 * 1e-9;
            eprintln!(
                "network: site {} lost: silent for {silent_s:.2} s",
                self.sites[j]
            );
            self.peer_log.push(PeerMsg {
                t_ns: now,
                site: self.sites[j].clone(),
                event: "lost".into(),
                silent_s,
            });
        }
    }

    /// Site `j` left the session (its liveliness token went away): a new run of it starts its
    /// sequence, its clock and (unless it is lost, whose silence goes on) its silence afresh.
    pub(super) fn left(&mut self, j: usize) {
        self.inbound.forget(j);
        if self.lost & (1 << j) == 0 {
            self.last_heard[j] = None;
        }
        for w in &mut self.waiting[j * MAX_OBJECTS..(j + 1) * MAX_OBJECTS] {
            *w = None;
        }
        self.control.network.clock_rtt_ns[j].store(0, Ordering::Relaxed);
    }

    /// A message on `key`, decoded once here; `join`: a late joiner's catch-up state (not a
    /// message on a link).
    pub(super) fn on_bytes(
        &mut self,
        key: &str,
        bytes: &[u8],
        zenoh_ts: Option<String>,
        join: bool,
    ) {
        match wire::decode(bytes) {
            Ok(r) => self.on_report(key, r, zenoh_ts, join),
            Err(e) => self.refuse(key, &Refusal::from(e)),
        }
    }

    /// A decoded report on `key`: checked, held for its sender's clock offset, or handed on.
    fn on_report(&mut self, key: &str, report: SiteReport, zenoh_ts: Option<String>, join: bool) {
        let now = monotonic_ns();
        let offsets = self.offsets();
        // (A key naming no object of the largest world: refused as not the object it names.)
        let key_object = keys::object_of(key)
            .filter(|&k| k < MAX_OBJECTS as u64)
            .unwrap_or(u64::MAX);
        let a =
            match self
                .inbound
                .check_decoded(keys::site_of(key), key_object, report, now, &offsets)
            {
                Ok(a) => a,
                Err(Refusal::NoOffset { site }) => {
                    // Its time cannot be read yet: held (the newest of the site) until it can.
                    self.held += 1;
                    self.control
                        .network
                        .held_for_offset
                        .store(self.held, Ordering::Relaxed);
                    self.waiting[site * MAX_OBJECTS + key_object as usize] = Some(Waiting {
                        key: key.to_owned(),
                        report,
                        zenoh_ts,
                        join,
                    });
                    return;
                }
                Err(e) => return self.refuse(key, &e),
            };
        let (from, r, offset) = (a.site, a.report, a.offset_ns);
        if from == self.me {
            return; // our own, echoed back
        }
        // A state held for its sender's clock offset is superseded by this newer one.
        self.waiting[from * MAX_OBJECTS + key_object as usize] = None;
        if a.resync {
            self.resyncs += 1;
            self.control
                .network
                .resyncs
                .store(self.resyncs, Ordering::Relaxed);
        }
        self.heard(from, now);
        if join {
            self.join_states += 1;
            self.control
                .network
                .join_states
                .store(self.join_states, Ordering::Relaxed);
        }
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
        if !self.gate.lets(d.report.t_ns) {
            return;
        }
        // Held by the emulated link, or queued by zenoh behind a partition: still within the age
        // limit when physics gets it, or not at all.
        if let Err(e) = self.inbound.age_ok(d.from, d.report.t_ns, now) {
            let key = format!("{}'s state, at hand-over", self.sites[d.from]);
            return self.refuse(&key, &e);
        }
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
            let net = &self.control.network;
            record_counted(&net.latency, &net.latency_count, age);
        }
        self.log.push(RemoteMsg {
            t_ns: now,
            from: d.from,
            seq: d.report.seq,
            sent_ns: d.report.t_ns,
            pos: d.report.pos,
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
pub(super) fn join_from_current(
    session: &Session,
    session_name: &str,
    rx: &Mutex<Receiver<'_>>,
    clocks: &Sampler<'_>,
) {
    let Ok(replies) = session
        .get(keys::all_object_current(session_name))
        .allowed_destination(Locality::Remote)
        .timeout(Duration::from_secs(1))
        .wait()
    else {
        return;
    };
    while let Ok(reply) = replies.recv() {
        if let Ok(s) = reply.result() {
            // The replying site's own key carries its name. Its time is read only with its
            // clock offset: measure it now rather than refuse the session's state.
            let key = s.key_expr().as_str().to_owned();
            let payload = s.payload().to_bytes();
            let site = {
                let rx = lock(rx);
                rx.control
                    .network
                    .traffic
                    .received(WireKind::State, payload.len());
                rx.inbound.index_of(keys::site_of(&key))
            };
            if let Some(j) = site {
                clocks.sample_if_unknown(j);
            }
            lock(rx).on_bytes(&key, &payload, None, true);
        }
    }
}

/// The other sites' live states, queued by zenoh for [`deliver`].
pub(super) type States = Subscriber<FifoChannelHandler<Sample>>;

/// Subscribes to the other sites' live states.
pub(super) fn subscribe(session: &Session, session_name: &str) -> Result<States, NetworkError> {
    session
        .declare_subscriber(keys::all_object_states(session_name))
        .allowed_origin(Locality::Remote)
        .with(zenoh::handlers::FifoChannel::new(1024))
        .wait()
        .map_err(NetworkError::declare("subscriber"))
}

/// The other sites' tool tracks, queued by zenoh for [`deliver_tracks`].
pub(super) fn subscribe_tracks(
    session: &Session,
    session_name: &str,
) -> Result<States, NetworkError> {
    session
        .declare_subscriber(keys::all_tools(session_name, 0))
        .allowed_origin(Locality::Remote)
        .with(zenoh::handlers::FifoChannel::new(1024))
        .wait()
        .map_err(NetworkError::declare("tool track subscriber"))
}

/// The tool tracks' delivery thread, as [`deliver`] is the states'.
pub(super) fn deliver_tracks(tracks: &States, rx: &Mutex<Receiver<'_>>, stop: &AtomicU64) {
    while stop.load(Ordering::Relaxed) == 0 {
        match tracks.recv_timeout(Duration::from_millis(50)) {
            Ok(Some(s)) => {
                let payload = s.payload().to_bytes();
                let mut rx = lock(rx);
                rx.control
                    .network
                    .traffic
                    .received(WireKind::Track, payload.len());
                rx.on_track(s.key_expr().as_str(), &payload);
            }
            Ok(None) => {}
            Err(_) => break,
        }
    }
}

/// The delivery thread: each state is handled the moment zenoh hands it over, until `stop`.
pub(super) fn deliver(states: &States, rx: &Mutex<Receiver<'_>>, stop: &AtomicU64) {
    while stop.load(Ordering::Relaxed) == 0 {
        match states.recv_timeout(Duration::from_millis(50)) {
            Ok(Some(s)) => {
                let ts = s.timestamp().map(ToString::to_string);
                let payload = s.payload().to_bytes();
                let mut rx = lock(rx);
                rx.control
                    .network
                    .traffic
                    .received(WireKind::State, payload.len());
                rx.on_bytes(s.key_expr().as_str(), &payload, ts, false);
            }
            Ok(None) => {}
            Err(_) => break,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::admit::ObjectBounds;
    use coop_rt::shm::{BlockSegment, RingSegment, SegmentName};

    /// A world of two objects: each refused state is counted by the object its key names (what
    /// `station status` shows per object), and a valid one of the second object reaches physics.
    #[test]
    fn refused_states_are_counted_by_the_object_their_key_names() {
        let session = format!("ur{}", std::process::id());
        let name = |w: &str| SegmentName::new(&session, "a", w).expect("valid name");
        let ctl: BlockSegment<ControlBlock> = BlockSegment::create(&name("ctl")).expect("ctl");
        let ring = RingSegment::<SiteReport>::create(&name("rem"), 16).expect("ring");
        let mut to_physics = ring.consumer().expect("consumer");
        // Site b's clock is ours (its offset known).
        ctl.network.clock_rtt_ns[1].store(1, Ordering::Relaxed);
        let mut bounds = Bounds::unbounded();
        bounds.object_count = 2;
        bounds.objects[1] = ObjectBounds {
            speed_m_per_s: 1.0,
            ang_mom: 1.0,
        };
        let sites = ["a".to_owned(), "b".to_owned()];
        let mut rx = Receiver::new(
            &sites,
            0,
            &ctl,
            ring.producer().expect("producer"),
            None,
            bounds,
            vec![u64::MAX; 2],
        );
        let state = |object: u64, seq: u64, speed: f64| {
            let r = SiteReport {
                kind: 1,
                t_ns: monotonic_ns(),
                seq,
                site: 1,
                object,
                rot: [1.0, 0.0, 0.0, 0.0],
                vel: [speed, 0.0, 0.0],
                included: [-1.0; coop_model::MAX_SITES],
                ..SiteReport::default()
            };
            crate::wire::encode(&r)
        };
        let key1 = keys::state("s", 1, "b");
        rx.on_bytes(&key1, &state(1, 1, 5.0), None, false);
        rx.on_bytes(&key1, &state(0, 2, 0.1), None, false);
        let by = |k: usize| ctl.network.refused_by_object[k].load(Ordering::Relaxed);
        assert_eq!(
            (by(0), by(1)),
            (0, 2),
            "too fast, and another object's state on its key"
        );
        rx.on_bytes(&key1, &state(1, 3, 0.5), None, false);
        let got = to_physics
            .pop()
            .expect("a valid state of the second object reached physics");
        assert_eq!((got.object, got.seq), (1, 3));
        assert_eq!((by(0), by(1)), (0, 2), "a taken state is not counted");
    }
}
