//! The station's network process: a zenoh session that
//!
//! - publishes this site's reports (read from the physics → network ring) on its state key, express,
//!   real-time priority, dropped rather than queued under congestion ([`publish`]);
//! - hands the other sites' reports to physics (network → physics ring) the moment zenoh delivers
//!   them, after [`admit::Inbound::check`](crate::admit::Inbound::check) (typed refusals are counted,
//!   never applied), with their time corrected by the sender's clock offset, through the
//!   receive-side network emulation when configured (`receive`, [`emulate`]);
//! - declares a liveliness token (who is present) and watches everyone's (`presence`); answers
//!   queries for its newest state (late joiners start from the session's state) and for its clock
//!   (NTP-style offset and round trip per peer, [`clock`]);
//! - learns the session's time 0 from the launcher when the station waits for it, translated from
//!   the launcher's clock into its own with the launcher's measured clock offset ([`epoch`], which
//!   also holds the launcher's side, and [`clock`]);
//! - writes the station's MCAP recording (physics' trace ring, the states received, presence,
//!   clocks, final counters), and puts the newest sample for live viewers (`live`, ~60 Hz);
//! - with [`NetworkArgs::live_view`], serves the station's own live view to Foxglove
//!   ([`crate::live_view`]): its samples offered as they are drained, its events logged.
//!
//! When its session cannot open because its links fail, its error is their cause ([`probe`] finds
//! it, [`link`] words it, the station's supervisor says it); a peer's TLS links that keep failing
//! are watched, and their cause said.
//!
//! It is not a real-time loop: zenoh's own threads and this process's loop run at normal priority,
//! off the servo's CPU, and touch the rings (lock-free, non-blocking) only on the real-time side's
//! behalf.
//!
//! [`run`] wires the pieces: the session and its declarations, a delivery thread (received states),
//! a clock thread (the peers'), a launcher's clock thread (until time 0 is taken), a one-off epoch
//! query, and the loop (publish, release emulated states, record,
//! presence, heartbeat), until the control block's run state says stop.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard};

use coop_rt::msg::{SiteReport, ToolTrack, TraceRecord};
use coop_rt::shm::control::{Child, ControlBlock, RunState, Traffic, MAX_SITES};
use coop_rt::shm::{Consumer, Producer};
use coop_rt::sync::{AtomicU64, Ordering};
use coop_rt::timer::monotonic_ns;
use zenoh::{Session, Wait};

use crate::admit::Bounds;
use crate::live_view::LiveView;
use crate::recording::{LiveSample, Rotation, Scene, SessionMsg, StatusMsg};
use foxglove::messages::log::Level;

pub mod clock;
pub mod config;
pub mod emulate;
pub mod epoch;
mod error;
pub mod figures;
pub mod link;
mod live;
mod presence;
pub mod probe;
pub mod publish;
mod receive;
mod record;
mod ros2_publish;
pub mod trial;

pub use crate::live_view::LIVE_EVERY_NS;
pub use clock::{clock_estimate, CLOCK_EVERY, CLOCK_WINDOW};
pub use config::{concrete_listen, config, Locator, Mode, NetworkConfig, Tls, TRANSPORTS};
pub use emulate::Emulation;
pub use epoch::{EpochAnnouncer, EPOCH_HOLD_LIMIT};
pub use error::NetworkError;
pub use publish::{next_wake, GIVE_UP_NS, POLL, PUBLISH_LAG_NS, RETRY_NS, STALE_REPORT_NS};

use crate::ros2::cdr::Log;
use live::Live;
use presence::Presence;
use publish::{Publish, TrackPublish};
use receive::Receiver;
use record::{Events, Recording};
use ros2_publish::Ros2Publisher;

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
    /// Its fingerprint ([`figures::scenario_hash`]), for a launcher attaching to the station.
    pub scenario_hash: u64,
    /// Method name (for the recording).
    pub method: String,
    /// NetworkConfig.
    pub endpoints: NetworkConfig,
    /// The control block.
    pub control: &'a ControlBlock,
    /// Reports from physics.
    pub reports: Consumer<SiteReport>,
    /// Reports to physics.
    pub remote: Producer<SiteReport>,
    /// Physics' trace records, for the recording.
    pub trace: Consumer<TraceRecord>,
    /// Tool tracks (methods that exchange tools): this site's from physics, and the others' to
    /// physics; `None` for methods that exchange states only.
    pub tracks: Option<(Consumer<ToolTrack>, Producer<ToolTrack>)>,
    /// Recording file (its first part), if any.
    pub record: Option<PathBuf>,
    /// Which run of the station this is (its control block's creator): a recording at `record`
    /// that an earlier network process of the same run wrote is continued, not replaced (this
    /// process was restarted); none, or another run's: a new recording.
    pub station_run: Option<String>,
    /// When the recording goes on in its next part, and how many parts are kept.
    pub record_rotation: Rotation,
    /// Receive-side emulation, if any.
    pub emulation: Option<Emulation>,
    /// What a received state may be ([`Bounds::from_scenario`]).
    pub bounds: Bounds,
    /// Per site: how long it may be silent before it is lost, ns.
    pub silence_ns: Vec<u64>,
    /// What this site shows (object, tool, environment), for the recording's Foxglove channels
    /// and the live view.
    pub scene: Scene,
    /// Write the recording's Foxglove channels (`/tf`, `/scene`, `/log`) too.
    pub record_foxglove: bool,
    /// Serve this station's own live view on this address (`host:port`), if any.
    pub live_view: Option<String>,
    /// Publish this site as ROS 2 topics (`crate::ros2`), if asked.
    pub ros2: Option<crate::ros2::Ros2Config>,
    /// A study's station: makes each trial's pieces from its scenario ([`trial`]). Its
    /// recordings are one per trial, named by it beside `record`; none before the first.
    pub trials: Option<trial::TrialSetupFn>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic in a callback must not take the network down with a poisoned lock.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Who this process is, for every piece.
struct Ctx<'a> {
    session_name: &'a str,
    sites: &'a [String],
    me: usize,
    site: &'a str,
    ctl: &'a ControlBlock,
    /// [`Emulation::describe`], or `none`.
    emulation: String,
}

/// Runs the network process until the run state says stop.
///
/// # Errors
/// The zenoh session or a declaration cannot be set up, or the recording cannot be created.
pub fn run(a: NetworkArgs<'_>) -> Result<StatusMsg, NetworkError> {
    let site = a
        .sites
        .get(a.site_index)
        .cloned()
        .ok_or(NetworkError::NoSuchSite(a.site_index))?;
    if a.sites.len() > MAX_SITES {
        return Err(NetworkError::TooManySites(a.sites.len()));
    }
    let ctx = Ctx {
        session_name: a.session,
        sites: &a.sites,
        me: a.site_index,
        site: &site,
        ctl: a.control,
        emulation: a
            .emulation
            .as_ref()
            .map_or("none".into(), Emulation::describe),
    };
    let mut metadata = BTreeMap::from([
        ("session".into(), ctx.session_name.to_owned()),
        ("site".into(), site.clone()),
        ("scenario".into(), a.scenario.clone()),
        ("method".into(), a.method.clone()),
        ("emulation".into(), ctx.emulation.clone()),
    ]);
    if let Some(run) = &a.station_run {
        metadata.insert(crate::recording::STATION_RUN.into(), run.clone());
    }
    let studied = a.trials.is_some();
    let recording = Recording::create(
        a.record.as_deref().filter(|_| !studied),
        metadata.clone(),
        a.record_rotation,
        a.record_foxglove.then(|| a.scene.clone()),
    )?;
    let record = RecordSpec {
        path: a.record.clone(),
        metadata,
        rotation: a.record_rotation,
        foxglove: a.record_foxglove,
    };
    let events = Events::new(ctx.ctl, recording.continued());
    let view = match &a.live_view {
        Some(addr) => {
            let v = LiveView::start(addr)?;
            v.show(
                ctx.session_name,
                vec![a.scene.clone()],
                &site,
                format!(
                    "station {site} of session {}: scenario {}, method {}, emulation {}",
                    ctx.session_name, a.scenario, a.method, ctx.emulation
                ),
            );
            eprintln!(
                "network {site}: live view: {} (foxglove.websocket.v1: open it in Foxglove or Lichtblick)",
                v.url()
            );
            Some(v)
        }
        None => None,
    };
    ctx.ctl
        .network
        .emulated
        .store(u64::from(a.emulation.is_some()), Ordering::Relaxed);
    let _watch = watch_peers(&a.endpoints, &site);
    let session = open(&ctx, a.endpoints)?;
    let mut publish = Publish::declare(&session, ctx.session_name, &site, a.bounds.object_count)?;
    let mut rx = Receiver::new(
        ctx.sites,
        ctx.me,
        ctx.ctl,
        a.remote,
        a.emulation.as_ref(),
        a.bounds,
        a.silence_ns,
    );
    if studied {
        // Nothing reaches physics before a trial is set up (a restarted network process takes up
        // the trial running, and opens the gate at its time 0).
        rx.gate = receive::Gate::Closed;
    }
    let tracks = match a.tracks {
        Some((from_physics, to_physics)) => {
            rx.take_tracks(to_physics, a.emulation.as_ref());
            Some((
                TrackPublish::declare(&session, ctx.session_name, &site)?,
                from_physics,
            ))
        }
        None => None,
    };
    let receiver = Mutex::new(rx);
    let runs = figures::StationRuns {
        scenario: a.scenario.clone(),
        scenario_hash: a.scenario_hash,
        method: a.method.clone(),
        emulated: a.emulation.is_some(),
    };
    let names = (a.scenario, a.method);
    let live = Live::declare(&session, ctx.session_name, &site)?;
    let ros2 = match &a.ros2 {
        Some(c) => {
            let p = Ros2Publisher::declare(&session, ctx.session_name, &a.scene, c)?;
            eprintln!(
                "network {site}: ROS 2: node {}/station in domain {}, at most {} Hz",
                crate::ros2::namespace(ctx.session_name, &site),
                c.domain_id,
                c.rate_hz
            );
            Some(p)
        }
        None => None,
    };
    let status = serve(
        &ctx,
        &session,
        &mut publish,
        &receiver,
        Loop {
            reports: a.reports,
            trace: a.trace,
            tracks,
            recording,
            events,
            live,
            view,
            ros2,
            names,
            runs,
            record,
            trials: a.trials,
            emulation: ctx.emulation.clone(),
        },
    )?;
    drop(publish);
    session.close().wait().map_err(NetworkError::Close)?;
    Ok(status)
}

/// Opens the session on `endpoints` (port 0 made concrete) and shows where it is in the control
/// block.
fn open(ctx: &Ctx<'_>, mut endpoints: NetworkConfig) -> Result<Session, NetworkError> {
    endpoints.listen = match endpoints.mode {
        // A client listens on nothing (`config` gives zenoh no listen endpoints in client mode):
        // status must not show the default loopback locator as if it did.
        Mode::Client => Vec::new(),
        Mode::Peer => concrete_listen(&endpoints.listen),
    };
    let session = zenoh::open(config(&endpoints)?)
        .wait()
        .map_err(|e| explain_open(e, &endpoints, station_side(endpoints.mode)))?;
    ctx.ctl.set_locators(&format!(
        "zid {} mode {} listen [{}] connect [{}]",
        session.zid(),
        endpoints.mode,
        endpoints.listen.join(", "),
        endpoints.connect.join(", ")
    ));
    Ok(session)
}

/// Zenoh's failure to open a session on `endpoints`, explained: in client mode a session opens only
/// when one of its links does, so when every `connect` locator fails its probe ([`probe`]) the
/// causes are the error; otherwise (or when a probe passes) zenoh's own words are.
pub fn explain_open(e: zenoh::Error, endpoints: &NetworkConfig, side: link::Side) -> NetworkError {
    if endpoints.mode == Mode::Client && !endpoints.connect.is_empty() {
        let found = probe::diagnose(&endpoints.connect, endpoints.tls.as_ref(), side);
        if found.len() == endpoints.connect.len() {
            return NetworkError::Link(link::LinkFailures(found));
        }
    }
    NetworkError::Open(e)
}

/// A peer's session opens whether or not its TLS links to the other stations work, and zenoh
/// retries them without a word: their certificate problems are watched and said ([`probe::LinkWatch`];
/// a station not up yet says nothing, peers start in any order).
fn watch_peers(endpoints: &NetworkConfig, site: &str) -> Option<probe::LinkWatch> {
    let tls: Vec<String> = endpoints
        .connect
        .iter()
        .filter(|l| l.starts_with("tls/"))
        .cloned()
        .collect();
    if endpoints.mode != Mode::Peer || tls.is_empty() {
        return None;
    }
    let site = site.to_owned();
    let side = station_side(endpoints.mode);
    let say = move |m: &str| eprintln!("network {site}: {m}");
    match probe::LinkWatch::start(tls, endpoints.tls.clone(), side, false, say) {
        Ok(w) => Some(w),
        Err(e) => {
            eprintln!("network: its TLS links to the other stations are not watched ({e}): a certificate problem shows only in zenoh's log (RUST_LOG=zenoh=warn)");
            None
        }
    }
}

/// How a station's link failures are worded: its `[network.tls]`, towards routers (client mode)
/// or other stations.
pub fn station_side(mode: Mode) -> link::Side {
    link::Side {
        me: "station",
        far: match mode {
            Mode::Client => link::Far::Router,
            Mode::Peer => link::Far::Station,
        },
        files: link::Files::Table("network.tls"),
    }
}

/// What the loop owns.
struct Loop {
    reports: Consumer<SiteReport>,
    /// This site's tool-track publisher and physics' tracks, if the method exchanges tools.
    tracks: Option<(TrackPublish, Consumer<ToolTrack>)>,
    trace: Consumer<TraceRecord>,
    recording: Recording,
    /// The station events the control block shows, for the recording and the live view.
    events: Events,
    /// The newest sample for live viewers.
    live: Live,
    /// The station's own live view, if it serves one.
    view: Option<LiveView>,
    /// The station's ROS 2 node, if it publishes one.
    ros2: Option<Ros2Publisher>,
    /// Scenario and method names, for the recording's session message.
    names: (String, String),
    /// What the station runs, for a launcher attaching to it.
    runs: figures::StationRuns,
    /// How the recording was made (a study's station makes one per trial).
    record: RecordSpec,
    /// A study's station: what makes each trial's pieces.
    trials: Option<trial::TrialSetupFn>,
    /// The emulated link, as the recording says it: the station's own, or the trial's running.
    emulation: String,
}

/// How a station's recording is made: where, with what metadata, in what parts, with which
/// channels.
struct RecordSpec {
    path: Option<PathBuf>,
    metadata: BTreeMap<String, String>,
    rotation: Rotation,
    foxglove: bool,
}

/// Declares the rest, starts the threads and runs the loop; the threads end with it.
fn serve(
    ctx: &Ctx<'_>,
    session: &Session,
    publish: &mut Publish,
    receiver: &Mutex<Receiver<'_>>,
    mut lp: Loop,
) -> Result<StatusMsg, NetworkError> {
    let (name, site) = (ctx.session_name, ctx.site);
    // Zenoh's callbacks own what they touch; the threads here borrow the control block (mapped
    // for longer than the session lives) and the receiver, so they are scoped.
    let stop = &AtomicU64::new(0);
    let clocks = &clock::Sampler::new(session, name, ctx.sites, ctx.me, ctx.ctl);
    let epoch = &epoch::EpochListener::declare(session, name, site)?;
    let mut trials = match lp.trials.take() {
        Some(setup) => Some(trial::TrialListener::declare(session, name, setup)?),
        None => None,
    };
    std::thread::scope(|scope| {
        // Answered before the presence shows: a launcher that sees it may ask at once.
        let mut figures = figures::Figures::declare(session, name, site, lp.runs.clone())?;
        let mut presence = Presence::declare(session, name, site)?;
        ctx.ctl
            .network
            .traffic
            .sent(coop_rt::shm::control::WireKind::Presence, 0);
        receive::join_from_current(session, name, receiver, clocks);
        let states = receive::subscribe(session, name)?;
        let tracks = match lp.tracks {
            Some(_) => Some(receive::subscribe_tracks(session, name)?),
            None => None,
        };
        publish.serve_current(session, name, site)?;
        let (_clock, clock_answers) = clock::serve(session, name, site)?;
        // Every declaration is made before the threads start: an error returns before anything
        // would wait for `stop`.
        scope.spawn(move || receive::deliver(&states, receiver, stop));
        if let Some(t) = tracks {
            scope.spawn(move || receive::deliver_tracks(&t, receiver, stop));
        }
        if trials.is_none() {
            scope.spawn(move || epoch::ask(session, name, ctx.ctl, epoch));
        }
        scope.spawn(move || clocks.run(stop));
        let through_run = trials.is_some();
        scope.spawn(move || clocks.run_launcher(stop, through_run));

        let slot = ctx.ctl.child(Child::Network);
        slot.pid
            .store(u64::from(std::process::id()), Ordering::Relaxed);
        let mut session_recorded = false;
        loop {
            let now = lp.turn(ctx, publish, receiver, &mut presence, clocks);
            clock_answers.count(&ctx.ctl.network.traffic);
            figures.turn(ctx.ctl, now);
            // A study's station takes each trial's time 0 from its trial, never the session's.
            if trials.is_none() {
                epoch.poll(ctx.ctl, clocks.launcher_offset());
            }
            if let Some(t) = &mut trials {
                match t.poll(ctx.ctl, clocks.launcher_offset(), site, receiver) {
                    Some(trial::Change::Rebuild(setup)) => {
                        let status = status_now(ctx.ctl, publish, receiver);
                        let name = t.name().unwrap_or("").to_owned();
                        let set_up = lp.next_trial(ctx, receiver, &setup, &name, &status);
                        figures.begin_trial(lp.runs.clone());
                        session_recorded = false;
                        match set_up {
                            Ok(()) => t.network_ready(ctx.ctl),
                            // The station goes on; the runner sees the trial refused.
                            Err(e) => t.fail(format!("its recording: {e}"), site),
                        }
                    }
                    Some(trial::Change::End) => {
                        let status = status_now(ctx.ctl, publish, receiver);
                        lp.end_trial(ctx.site, &status);
                        // The servo ramps its force out until the next trial.
                        ctx.ctl.trial.set_ended(t.asked());
                    }
                    Some(trial::Change::Started(t0)) => {
                        lock(receiver).gate =
                            receive::Gate::From(t0.saturating_sub(trial::GATE_SLACK_NS));
                    }
                    None => {}
                }
                figures.trial = Some(t.figures(ctx.ctl));
            }
            if !session_recorded {
                session_recorded = lp.record_session(ctx, now);
            }
            ctx.ctl
                .network
                .published
                .store(publish.published, Ordering::Relaxed);
            slot.heartbeat.fetch_add(1, Ordering::Relaxed);
            lp.recording.stop_on_error(site);
            if !matches!(ctx.ctl.run_state(), RunState::Starting | RunState::Running) {
                break;
            }
            let wake = next_wake(
                ctx.ctl.physics.report_period_ns.load(Ordering::Relaxed),
                ctx.ctl.physics.last_report_ns.load(Ordering::Relaxed),
                monotonic_ns(),
            );
            // A ROS 2 sample due before the next report is put on time.
            let ros2_due = lp.ros2.as_ref().and_then(Ros2Publisher::due_ns);
            coop_rt::timer::sleep_until(ros2_due.map_or(wake, |d| d.max(now).min(wake)));
        }
        stop.store(1, Ordering::Relaxed);
        let status = status_now(ctx.ctl, publish, receiver);
        lp.recording.finish(site, &status);
        Ok(status)
    })
}

/// The station's final counters as they are now, for a recording's end.
fn status_now(ctl: &ControlBlock, publish: &Publish, receiver: &Mutex<Receiver<'_>>) -> StatusMsg {
    let rx = lock(receiver);
    StatusMsg {
        t_ns: monotonic_ns(),
        published: publish.published,
        received: rx.received,
        refused: rx.refused,
        emulated_lost: rx.emulated_lost,
        join_states: rx.join_states,
        stale_skipped: publish.stale_skipped,
        traffic: crate::recording::TrafficMsg::of(&ctl.network.traffic),
        device: crate::recording::DeviceMsg::of(&ctl.device),
    }
}

impl Loop {
    /// A study's next trial, once the servo and physics have stopped the last one: what physics
    /// sent of it is recorded (its trace) or dropped (its reports and tracks, which no station
    /// would take now), the last trial's recording is finished with `status` and the new one's
    /// started (named `name`), and the receiver takes the new trial's links.
    ///
    /// # Errors
    /// The new recording cannot be created.
    fn next_trial(
        &mut self,
        ctx: &Ctx<'_>,
        receiver: &Mutex<Receiver<'_>>,
        setup: &trial::TrialSetup,
        name: &str,
        status: &StatusMsg,
    ) -> Result<(), NetworkError> {
        while self.reports.pop().is_ok() {}
        if let Some((_, ring)) = &mut self.tracks {
            while ring.pop().is_ok() {}
        }
        // (The last trial's recording, if its end was not heard.)
        self.end_trial(ctx.site, status);
        lock(receiver).begin_trial(
            setup.emulation.as_ref(),
            setup.bounds,
            setup.silence_ns.clone(),
        );
        self.names.clone_from(&setup.names);
        self.emulation.clone_from(&setup.emulation_text);
        self.runs = figures::StationRuns {
            scenario: setup.names.0.clone(),
            scenario_hash: setup.scenario_hash,
            method: setup.names.1.clone(),
            emulated: setup.emulation.is_some(),
        };
        let mut metadata = self.record.metadata.clone();
        metadata.insert("scenario".into(), setup.names.0.clone());
        metadata.insert("method".into(), setup.names.1.clone());
        metadata.insert("emulation".into(), setup.emulation_text.clone());
        metadata.insert("trial".into(), name.to_owned());
        let path = self
            .record
            .path
            .as_deref()
            .map(|p| trial::record_path(p, name));
        self.recording = Recording::create(
            path.as_deref(),
            metadata,
            self.record.rotation,
            self.record.foxglove.then(|| setup.scene.clone()),
        )?;
        Ok(())
    }

    /// A study's trial is over: what physics sent of it is recorded, and its recording finished;
    /// nothing is recorded until the next trial.
    fn end_trial(&mut self, site: &str, status: &StatusMsg) {
        self.recording.drain_trace(&mut self.trace);
        std::mem::replace(&mut self.recording, Recording::none()).finish(site, status);
    }

    /// One turn: publish the newest report, release the emulated states due, and record what
    /// happened since the last turn; returns the time the states were released at.
    fn turn(
        &mut self,
        ctx: &Ctx<'_>,
        publish: &mut Publish,
        receiver: &Mutex<Receiver<'_>>,
        presence: &mut Presence,
        clocks: &clock::Sampler<'_>,
    ) -> u64 {
        let traffic = &ctx.ctl.network.traffic;
        for m in publish.newest(&mut self.reports, &ctx.ctl.network) {
            self.recording.write(|w| w.published(&m));
        }
        publish.count_replies(traffic);
        if let Some((p, ring)) = &mut self.tracks {
            p.all(ring, &ctx.ctl.network);
        }
        let now = monotonic_ns();
        let (log, peers) = {
            let mut rx = lock(receiver);
            rx.retry_waiting();
            rx.release_due(now);
            rx.release_tracks(now);
            rx.check_lost(now);
            (
                std::mem::take(&mut rx.log),
                std::mem::take(&mut rx.peer_log),
            )
        };
        for m in &log {
            self.recording.write(|w| w.remote(m));
        }
        for m in &peers {
            self.recording.write(|w| w.peer(m));
            let level = if m.event == "lost" {
                Level::Warning
            } else {
                Level::Info
            };
            let text = || {
                format!(
                    "{} {} after {:.3} s of silence",
                    m.site, m.event, m.silent_s
                )
            };
            self.tell(level, text, traffic);
        }
        let newest = self.recording.drain_trace(&mut self.trace);
        if let (Some(v), Some((t, others))) = (&self.view, &newest) {
            v.offer(0, LiveSample::from_trace(t, others));
        }
        if let Some(r) = &mut self.ros2 {
            r.offer(newest.as_ref(), now, traffic);
        }
        self.live.offer(newest, now, &ctx.ctl.network.traffic);
        for (level, text) in self.events.look(ctx.ctl) {
            self.tell(level, || text.clone(), traffic);
            self.recording.write(|w| w.event(now, level, text));
        }
        if let Some(m) = self.events.task(ctx.ctl, now) {
            let (level, text) = m.said();
            self.tell(level, || text, traffic);
            self.recording.write(|w| w.task(&m));
        }
        for m in presence.update(ctx.sites, ctx.ctl, receiver) {
            self.recording.write(|w| w.presence(&m));
            let what = if m.present { "joined" } else { "left" };
            self.tell(Level::Info, || format!("{} {what}", m.site), traffic);
        }
        for m in clocks.take_log() {
            self.recording.write(|w| w.clock(&m));
        }
        now
    }

    /// Tells whoever watches the station's events (its live view, `/rosout`) one of them; the
    /// text is made only if someone does.
    fn tell(&mut self, level: Level, text: impl FnOnce() -> String, traffic: &Traffic) {
        if self.view.is_none() && self.ros2.is_none() {
            return;
        }
        let text = text();
        if let Some(r) = &mut self.ros2 {
            r.log(ros2_level(level), &text, traffic);
        }
        if let Some(v) = &self.view {
            v.log(level, text);
        }
    }

    /// Records the session (names, time 0, emulation) once time 0 is known; whether it did.
    fn record_session(&mut self, ctx: &Ctx<'_>, now: u64) -> bool {
        let Some(epoch_ns) = ctx.ctl.epoch() else {
            return false;
        };
        let m = SessionMsg {
            t_ns: now,
            session: ctx.session_name.to_owned(),
            site: ctx.site.to_owned(),
            site_index: ctx.me,
            scenario: self.names.0.clone(),
            method: self.names.1.clone(),
            epoch_ns,
            emulation: self.emulation.clone(),
        };
        self.recording.write(|w| w.session(&m));
        true
    }
}

/// A station event's level as `/rosout` writes it.
fn ros2_level(l: Level) -> u8 {
    match l {
        Level::Warning => Log::WARN,
        Level::Error | Level::Fatal => Log::ERROR,
        _ => Log::INFO,
    }
}
