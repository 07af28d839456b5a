//! The physics loop's body: take the newest tool sample from the servo (the own user's contact),
//! hand received reports to the consistency method (adoptions), integrate one fixed step with the own
//! user's force only (Eq. 10), publish the state to the servo every step and a report to the network at
//! the report rate. The periodic timer and scheduling around it belong to the station's physics
//! process.
//!
//! The method itself is stepped by [`coop_model::drive::SiteDrive`], as the simulator steps it:
//! this loop only moves what the rings carry in and out of it, and decides (from the clock) how
//! many ticks are due.

use coop_model::drive::{Put, Refused, SiteDrive, ToolAt};
use coop_model::method::{Consistency, WorldCopy};
use coop_model::world::{World, MAX_OBJECTS};

use coop_model::body::{BodyState, Vec3};
use coop_model::method::Report;

use crate::msg::{ObjectSample, SiteReport, ToolSample, ToolTrack, TraceRecord};
use crate::shm::control::{record_counted, ControlBlock, Ring};
use crate::shm::{Consumer, Producer};

/// Everything one physics loop owns.
#[derive(Debug)]
pub struct PhysicsLoop {
    site: usize,
    /// The method, the copy and the own contact, stepped as the simulator steps them.
    drive: SiteDrive,
    world: World,
    /// The world's objects (fixed at start: the rings' capacities are sized for them).
    n: usize,
    own_t_ns: u64,
    tool: ToolSample,
    tools: Consumer<ToolSample>,
    remote: Consumer<SiteReport>,
    objects: Producer<ObjectSample>,
    reports: Producer<SiteReport>,
    trace: Option<Producer<TraceRecord>>,
    tracks_out: Option<Producer<ToolTrack>>,
    tracks_in: Option<Consumer<ToolTrack>>,
    ticks: Ticks,
    trace_period_ns: u64,
    next_trace_ns: u64,
    period_ns: u64,
    seq: u64,
    adoptions: u64,
    adoptions_by_object: [u64; MAX_OBJECTS],
    /// Reports refused as malformed (non-finite, unknown site, unknown kind).
    pub rejected: u64,
    /// Remote reports taken from the ring (valid or not).
    pub received: u64,
    /// Object samples dropped because the ring to the servo was full (one per object).
    pub object_drops: u64,
    /// Reports dropped because the ring to the network was full.
    pub report_drops: u64,
    /// Trace records dropped because the recorder's ring was full.
    pub trace_drops: u64,
    /// Tool tracks (methods that exchange tools): received, refused as malformed, dropped because
    /// the ring to the network was full.
    pub tracks: TrackCounters,
    /// The pipeline's waits since the last publication.
    waits: Waits,
}

/// What a physics loop did with tool tracks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrackCounters {
    /// Remote tracks taken from the ring (valid or not).
    pub received: u64,
    /// ... refused as malformed (see [`ToolTrack::report`]) or naming this site.
    pub rejected: u64,
    /// Own tracks not pushed: the ring to the network was full.
    pub drops: u64,
    /// Physics periods that had to step more than one tick to stay on the session's grid
    /// (the loop was late), and the ticks stepped in them beyond the first.
    pub late_periods: u64,
    /// See `late_periods`.
    pub caught_up_ticks: u64,
}

/// The pipeline's waits measured since they were last published, ns: the own tool sample's age
/// when taken, and each partner's report or track's age when taken (at most [`MAX_WAITS`] a
/// period; more in one period are counted in none). Fixed size: measured inside the step.
#[derive(Debug, Clone, Copy, Default)]
struct Waits {
    tool: Option<u64>,
    remote: [u64; MAX_WAITS],
    remote_len: usize,
    /// The sender's time of the newest remote report or track taken, this machine's clock, ns.
    newest_remote_ns: u64,
}

/// Partner reports' waits kept per physics period until published.
const MAX_WAITS: usize = 16;

impl Waits {
    /// A partner's report or track of (corrected) time `t_ns` taken at `now_ns`.
    fn remote_taken(&mut self, t_ns: u64, now_ns: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        if t_ns == 0 || t_ns > now_ns {
            return;
        }
        self.newest_remote_ns = self.newest_remote_ns.max(t_ns);
        if let Some(w) = self.remote.get_mut(self.remote_len) {
            *w = now_ns - t_ns;
            self.remote_len += 1;
        }
    }
}

/// Most extra ticks one physics period steps to catch up with the session's grid (a longer
/// stall is made up over the following periods).
pub const MAX_CATCH_UP_TICKS: u64 = 8;

/// The session's tick grid, for methods that step on it (`timewarp`, `coupled`): tick `k` starts
/// at `origin_ns + k × period`, the same at every site once each knows the session's time 0.
#[derive(Debug, Clone, Copy, Default)]
struct Ticks {
    /// Time 0 of the grid (the session's), once known.
    origin_ns: Option<u64>,
    /// Join the grid where the session is at the first step (if that is at least this tick),
    /// from these states of the world's objects (`None`: the copy given), not at tick 0.
    join: Option<(u64, Option<[BodyState; MAX_OBJECTS]>)>,
    /// The tick it joined at (0: at the start).
    joined: u64,
}

/// A physics loop's clock: its fixed step, its report period, and when it starts (ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PhysicsTiming {
    /// Fixed step, ns.
    pub period_ns: u64,
    /// Report period, ns.
    pub report_period_ns: u64,
    /// First step's time, ns on CLOCK_MONOTONIC.
    pub start_ns: u64,
    /// Trace sample period, ns (records fall on `start_ns + k * trace_period_ns`).
    pub trace_period_ns: u64,
    /// The last report sequence number used (a restarted physics continues after it).
    pub report_seq: u64,
}

/// The rings a physics loop uses.
#[derive(Debug)]
pub struct PhysicsRings {
    /// Tool samples from the servo.
    pub tools: Consumer<ToolSample>,
    /// Reports received from other sites (from the network process).
    pub remote: Consumer<SiteReport>,
    /// Object states to the servo.
    pub objects: Producer<ObjectSample>,
    /// Reports to the network process.
    pub reports: Producer<SiteReport>,
    /// Trace records to the recorder (the network process), if the station records.
    pub trace: Option<Producer<TraceRecord>>,
    /// Own tool tracks to the network process (methods that exchange tools; else `None`).
    pub tracks_out: Option<Producer<ToolTrack>>,
    /// Remote tool tracks from the network process (methods that exchange tools; else `None`).
    pub tracks_in: Option<Consumer<ToolTrack>>,
}

impl PhysicsRings {
    /// Empties the rings physics reads (tool samples, remote reports, remote tracks): what the
    /// servo and the network sent before. Not real-time.
    pub fn drain_inputs(&mut self) {
        while self.tools.pop().is_ok() {}
        while self.remote.pop().is_ok() {}
        if let Some(t) = &mut self.tracks_in {
            while t.pop().is_ok() {}
        }
    }
}

impl PhysicsLoop {
    /// A physics loop for `site` with `method`, starting from `copy`. A method that steps on the
    /// session's tick grid (it says so: [`Consistency::grid_history_ticks`]) holds the copy until
    /// [`PhysicsLoop::set_tick_origin`] gives the grid's time 0.
    pub fn new(
        site: usize,
        method: Box<dyn Consistency>,
        world: World,
        copy: WorldCopy,
        rings: PhysicsRings,
        timing: PhysicsTiming,
    ) -> Self {
        let drive = SiteDrive::new(
            site,
            method,
            copy,
            timing.report_period_ns,
            timing.start_ns,
            timing.report_seq,
        );
        Self {
            site,
            n: drive.objects(),
            ticks: Ticks::default(),
            drive,
            world,
            own_t_ns: 0,
            tool: ToolSample::default(),
            tools: rings.tools,
            remote: rings.remote,
            objects: rings.objects,
            reports: rings.reports,
            trace: rings.trace,
            trace_period_ns: timing.trace_period_ns.max(1),
            next_trace_ns: timing.start_ns,
            period_ns: timing.period_ns,
            seq: 0,
            adoptions: 0,
            adoptions_by_object: [0; MAX_OBJECTS],
            rejected: 0,
            received: 0,
            object_drops: 0,
            report_drops: 0,
            trace_drops: 0,
            tracks: TrackCounters::default(),
            tracks_out: rings.tracks_out,
            tracks_in: rings.tracks_in,
            waits: Waits::default(),
        }
    }

    /// Its rings back, for a study's next trial to build its loop on, emptied of what the servo
    /// and the network sent into them (of the last trial: call it once both produce nothing more
    /// of it). Not real-time.
    pub fn into_rings(self) -> PhysicsRings {
        let mut rings = PhysicsRings {
            tools: self.tools,
            remote: self.remote,
            objects: self.objects,
            reports: self.reports,
            trace: self.trace,
            tracks_out: self.tracks_out,
            tracks_in: self.tracks_in,
        };
        rings.drain_inputs();
        rings
    }

    /// The session's time 0 (ns on this machine's CLOCK_MONOTONIC): tick `k` of the grid starts at
    /// `origin_ns + k × period`. Set once; later calls change nothing (the grid never moves).
    pub fn set_tick_origin(&mut self, origin_ns: u64) {
        self.ticks.origin_ns.get_or_insert(origin_ns);
    }

    /// For a method on the session's tick grid: if its first step on the grid falls in tick
    /// `after` or later (the session's time 0 may only be learnt then), this loop joins the grid
    /// at that tick, from `states` (the world's objects in order; `None`: the copy it was
    /// given), not at tick 0: a restarted or
    /// late physics process starts where the session is instead of re-simulating it from its
    /// start (at most [`MAX_CATCH_UP_TICKS`] extra ticks a period: a restart ten minutes in took
    /// 75 s to catch up, showing the user the session's past). Before the first step; nothing
    /// off the grid.
    pub fn join_late(&mut self, after: u64, states: Option<[BodyState; MAX_OBJECTS]>) {
        if self.drive.on_grid() && self.drive.ticks() == 0 {
            self.ticks.join = Some((after, states));
        }
    }

    /// Ticks of the session's grid stepped so far (methods that step on it).
    pub fn ticks(&self) -> u64 {
        self.drive.ticks()
    }

    /// What the method did so far (rollbacks, jitter-buffer playout).
    pub fn method_stats(&self) -> coop_model::method::Stats {
        self.drive.stats()
    }

    /// Adoptions or steps that would have made the copy non-finite (the copy kept its state).
    pub fn nonfinite_kept(&self) -> u64 {
        self.drive.nonfinite_kept
    }

    /// How many ticks to step at `now_ns`: one per physics period on the grid (up to
    /// [`MAX_CATCH_UP_TICKS`] more when late, the rest skipped and counted), none before the
    /// grid's time 0 is known or reached; one for a method off the grid.
    fn ticks_due(&mut self, now_ns: u64) -> u64 {
        if !self.drive.on_grid() {
            return 1;
        }
        let Some(origin) = self.ticks.origin_ns.filter(|&o| now_ns >= o) else {
            return 0;
        };
        // Ticks whose start has come: 0 ..= (now - origin) / period.
        let due = (now_ns - origin) / self.period_ns.max(1) + 1;
        if let Some((after, state)) = self.ticks.join.take() {
            if due > after {
                // Joining late: the copy is the state at the start of the current tick.
                self.ticks.joined = due - 1;
                self.drive.start_at_tick(due - 1, state.as_ref());
            }
        }
        let behind = due.saturating_sub(self.drive.ticks());
        if behind > 1 {
            // Late (an overrun, a stall): catch up at most MAX_CATCH_UP_TICKS extra per period,
            // never skip one (the method counts its steps: a skipped tick would shift this
            // site's grid against the others').
            self.tracks.late_periods += 1;
            self.tracks.caught_up_ticks += (behind - 1).min(MAX_CATCH_UP_TICKS);
        }
        behind.min(1 + MAX_CATCH_UP_TICKS)
    }

    /// One step at `now_ns`.
    pub fn step(&mut self, now_ns: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls but clock_nanosleep (outside).
        if let Ok(n) = self.tools.pop_newest() {
            // A malformed sample leaves the last good contacts in place.
            if let Some(c) = n.value.contacts() {
                self.drive.set_own(&c);
                self.own_t_ns = n.value.t_ns;
                self.tool = n.value;
                self.waits.tool = now_ns.checked_sub(n.value.t_ns);
            }
        }
        while let Ok(r) = self.remote.pop() {
            self.received += 1;
            // The one validating conversion (see `SiteReport::report`): the network's decode
            // already refused bad reports; this guards the model against any other ring writer.
            if r.kind == SiteReport::KIND_LOST {
                match usize::try_from(r.site) {
                    Ok(from) if from != self.site => self.drive.peer_lost(from, now_ns),
                    _ => self.rejected += 1,
                }
                continue;
            }
            match r.report() {
                Some((from, msg)) => {
                    if self.take(from, &msg, now_ns).is_err() {
                        self.rejected += 1;
                    } else {
                        self.waits.remote_taken(r.t_ns, now_ns);
                    }
                }
                None => self.rejected += 1,
            }
        }
        self.receive_tracks(now_ns);
        let steps = self.ticks_due(now_ns);
        // The tool as last sampled (the same sample over catch-up ticks: one sample a tick, so a
        // local lag counts ticks).
        let tool = ToolAt {
            pos: Vec3::from(self.tool.tool_pos),
            vel: Vec3::from(self.tool.tool_vel),
            t_ns: self.tool.t_ns,
        };
        for _ in 0..steps {
            self.drive.tick(&self.world, &tool, now_ns, self.period_ns);
        }
        self.seq += 1;
        for k in 0..self.n {
            let mut sample = ObjectSample::new(
                now_ns,
                self.seq,
                k,
                // What the user is shown: the copy, or a missed contact replayed (timewarp).
                &self.drive.shown(k),
                self.adoptions,
                self.own_t_ns,
            );
            sample.remote_t_ns = self.waits.newest_remote_ns;
            if self.objects.push(sample).is_err() {
                self.object_drops += 1;
            }
        }
        if now_ns >= self.next_trace_ns {
            self.next_trace_ns = next_on_grid(self.next_trace_ns, now_ns, self.trace_period_ns);
            for k in 0..self.n {
                let rec = self.record(TraceRecord::SAMPLE, now_ns, k);
                self.push_trace(rec);
            }
        }
        let site = self.site;
        let (tracks_out, track_drops) = (&mut self.tracks_out, &mut self.tracks.drops);
        let (reports, report_drops) = (&mut self.reports, &mut self.report_drops);
        self.drive.report(now_ns, &mut |put| match put {
            // Tools go out as a track: its own ring and sequence.
            Put::Track(r) => {
                let t = ToolTrack::new(site, r.seq, now_ns, &r);
                if tracks_out.as_mut().map(|p| p.push(t).is_ok()) != Some(true) {
                    *track_drops += 1;
                }
            }
            Put::Report { seq, report } => {
                if reports.push(SiteReport::new(site, seq, &report)).is_err() {
                    *report_drops += 1;
                }
            }
        });
    }

    /// Hands every received tool track to the method (it rolls back where a received position
    /// differs from what it predicted), through the one validating conversion.
    fn receive_tracks(&mut self, now_ns: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        while let Some(Ok(t)) = self.tracks_in.as_mut().map(Consumer::pop) {
            self.tracks.received += 1;
            match t.report() {
                Some((from, msg)) => {
                    if self.take(from, &msg, now_ns).is_err() {
                        self.tracks.rejected += 1;
                    } else {
                        self.waits.remote_taken(t.t_ns, now_ns);
                    }
                }
                None => self.tracks.rejected += 1,
            }
        }
    }

    /// Hands a valid report (a state or a tool track) from site `from` to the method, through
    /// the drive (which undoes and counts a result that is not finite). A jump (an adoption, or
    /// a rollback that moved the copy) is counted and traced.
    fn take(&mut self, from: usize, msg: &Report, now_ns: u64) -> Result<(), Refused> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let Some(a) = self.drive.receive(&self.world, from, msg, now_ns)? else {
            return Ok(());
        };
        self.adoptions += 1;
        match *msg {
            Report::State { object, .. } | Report::Force { object, .. } => {
                self.adoptions_by_object[object.min(MAX_OBJECTS - 1)] += 1;
            }
            Report::Coupled(ref c) => self.adoptions_by_object[c.object.min(MAX_OBJECTS - 1)] += 1,
            // A confirmed world, adopted whole.
            Report::Tools(_) => {
                for n in &mut self.adoptions_by_object[..self.n] {
                    *n += 1;
                }
            }
        }
        let mut rec = self.record(TraceRecord::ADOPTION, now_ns, 0);
        rec.from = from as u64;
        rec.jump_m = a.jump.norm();
        rec.age_s = a.age_s;
        self.push_trace(rec);
        Ok(())
    }

    fn record(&self, kind: u64, now_ns: u64, k: usize) -> TraceRecord {
        // The others' force (naive) is on the first object's record: the method sums it over
        // the world.
        let remote = if k == 0 {
            self.drive.remote_force()
        } else {
            Vec3::zeros()
        };
        let mut r = TraceRecord::new(
            kind,
            now_ns,
            k,
            &self.drive.copy().objects()[k].state,
            &self.tool,
            self.drive.own()[k].force + remote,
        );
        r.adoptions = self.adoptions;
        r
    }

    fn push_trace(&mut self, r: TraceRecord) {
        if let Some(t) = &mut self.trace {
            if t.push(r).is_err() {
                self.trace_drops += 1;
            }
        }
    }

    /// Publishes this loop's counters in the control block's physics group (the one writer).
    pub fn publish_counters(&mut self, ctl: &ControlBlock) {
        // REAL-TIME: relaxed stores only.
        let p = &ctl.physics;
        if let Some(w) = self.waits.tool.take() {
            record_counted(&p.tool_wait, &p.tool_wait_count, w);
        }
        for &w in &self.waits.remote[..self.waits.remote_len] {
            record_counted(&p.remote_wait, &p.remote_wait_count, w);
        }
        self.waits.remote_len = 0;
        p.received
            .store(self.received, crate::sync::Ordering::Relaxed);
        p.rejected
            .store(self.rejected, crate::sync::Ordering::Relaxed);
        p.adoptions
            .store(self.adoptions, crate::sync::Ordering::Relaxed);
        p.objects
            .store(self.n as u64, crate::sync::Ordering::Relaxed);
        for (a, &v) in p.adoptions_by_object.iter().zip(&self.adoptions_by_object) {
            a.store(v, crate::sync::Ordering::Relaxed);
        }
        p.nonfinite_kept
            .store(self.drive.nonfinite_kept, crate::sync::Ordering::Relaxed);
        p.drops.set(Ring::Object, self.object_drops);
        p.drops.set(Ring::Report, self.report_drops);
        p.drops.set(Ring::Trace, self.trace_drops);
        let stats = self.drive.stats();
        let mut r = crate::shm::rollback::RollbackFigures {
            tracks_received: self.tracks.received,
            tracks_rejected: self.tracks.rejected,
            track_drops: self.tracks.drops,
            late_periods: self.tracks.late_periods,
            ticks: self.drive.ticks(),
            joined_tick: self.ticks.joined,
            playout_ticks: stats.playout_ticks().map_or(0, |p| p.ceil() as u64),
            ..Default::default()
        };
        if let Some(st) = stats.rollback() {
            r.take_method(st);
        }
        p.rollback.store(&r);
    }

    /// The last report sequence number used.
    pub fn report_seq(&self) -> u64 {
        self.drive.report_seq()
    }
    /// Object `k`'s state in the copy now, as a sample (what a restarted physics resumes from:
    /// the copy, not what the user is shown).
    pub fn object_sample(&self, now_ns: u64, k: usize) -> ObjectSample {
        ObjectSample::new(
            now_ns,
            self.seq,
            k,
            &self.drive.copy().objects()[k].state,
            self.adoptions,
            self.own_t_ns,
        )
    }

    /// The world's objects (fixed at start).
    pub fn objects(&self) -> usize {
        self.n
    }

    /// The copy this site believes.
    pub fn copy(&self) -> &WorldCopy {
        self.drive.copy()
    }
    /// Adoptions so far.
    pub fn adoptions(&self) -> u64 {
        self.adoptions
    }
}

/// The first point of the grid `last + k * period` (k ≥ 1) after `now`.
fn next_on_grid(last: u64, now: u64, period: u64) -> u64 {
    last + ((now - last) / period + 1) * period
}
