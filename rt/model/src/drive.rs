//! One drive for a site's consistency method: the simulator and the station's physics loop both
//! step a site through a [`SiteDrive`], so a method behaves the same wherever it runs.
//!
//! Before there was one drive, each caller fed the method in its own way, and they differed in
//! ways nobody could see from either side: one gave the own tool's position only to the methods
//! whose name it matched, the other to every method; one refused a step that made the copy
//! non-finite, the other kept it; each decided on its own which report goes out as a state, which
//! as a tool track and how they are numbered. Now everything a method is given and everything it
//! puts goes through here, and what a method needs is the method's to say:
//! - the own tool's position at every tick ([`crate::method::Consistency::own_tool`]: a method
//!   that has no use for it ignores it);
//! - whether it steps on the session's tick grid
//!   ([`crate::method::Consistency::grid_history_ticks`] is `Some`);
//! - what a report carries ([`Put::split`]: a state, a tool track, or both).
//!
//! What stays the caller's is time: the station's physics process decides how many ticks are due
//! at a wake-up (catching up after an overrun, joining a session late) and pops its rings; the
//! simulator decides when the instant comes in virtual time and what the virtual network
//! delivers. Both hand the drive, at a physics tick, what arrived since the last one (states
//! first, then tracks, in arrival order, as a station's two rings hold them), then step it, then
//! let it report.

use crate::body::{BodyState, Vec3};
use crate::contact::ContactForce;
use crate::method::track::{CoupledReport, ToolReport};
use crate::method::{Adoption, Consistency, ObjectCopy, Report, Stats, WorldCopy};
use crate::world::{World, MAX_OBJECTS};

/// One message a site puts on the network.
#[derive(Debug, Clone, Copy, PartialEq)]
// NB: moved by value on the real-time path, where nothing allocates (as `Report` is).
#[allow(clippy::large_enum_variant)]
pub enum Put {
    /// A site report (`naive`'s force, `paper`'s state, `coupled`'s state without its tools),
    /// numbered among the site's reports from 1.
    Report {
        /// Its sequence number.
        seq: u64,
        /// The report.
        report: Report,
    },
    /// A tool track (`timewarp`'s tools, `coupled`'s), numbered among the site's tracks from 1
    /// (the number is in [`ToolReport::seq`] too).
    Track(ToolReport),
}

impl Put {
    /// What `report` puts on the network: its tools as a track, if it has any, and its site
    /// report, if it has one (`coupled` sends its state, without its tools, besides its track;
    /// `timewarp` only the track).
    pub fn split(report: Report) -> (Option<ToolReport>, Option<Report>) {
        match report {
            Report::Tools(r) => (Some(r), None),
            Report::Coupled(c) => (
                (c.tools.count > 0).then_some(c.tools),
                Some(Report::Coupled(CoupledReport {
                    tools: ToolReport::NONE,
                    ..c
                })),
            ),
            r @ (Report::State { .. } | Report::Force { .. }) => (None, Some(r)),
        }
    }
}

/// The own tool as the servo sampled it: where, how fast, when.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ToolAt {
    /// Position, world, m.
    pub pos: Vec3,
    /// Velocity, world, m/s.
    pub vel: Vec3,
    /// When it was sampled, ns (the caller's clock: the physics tick's).
    pub t_ns: u64,
}

impl ToolAt {
    /// The longest a sample is carried forward by its velocity, ns: a few servo periods. An older
    /// sample (the servo stalled) is held where it was rather than flown on.
    pub const MAX_EXTRAPOLATION_NS: u64 = 5_000_000;

    /// The tool at `now_ns`: the sample carried forward by its velocity over its age (at most
    /// [`ToolAt::MAX_EXTRAPOLATION_NS`]). A servo at 500 or 600 Hz feeds a 1 kHz physics a
    /// sample up to a servo period old, held over two ticks and then jumping; a method that
    /// steps every tool on the tick grid (and predicts the others' from their last ticks) would
    /// otherwise see a staircase instead of the hand's motion.
    pub fn at(&self, now_ns: u64) -> Vec3 {
        let age_ns = now_ns.saturating_sub(self.t_ns);
        if age_ns == 0
            || age_ns > Self::MAX_EXTRAPOLATION_NS
            || !self.vel.iter().all(|v| v.is_finite())
        {
            return self.pos;
        }
        self.pos + self.vel * ns_to_s(age_ns)
    }
}

/// Why a received report was not handed to the method.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// It names this site as its sender.
    OwnSite,
}

/// A site's method, its copy of the world, and the own user's contact, stepped the one way (see
/// the module docs).
#[derive(Debug)]
pub struct SiteDrive {
    site: usize,
    method: Box<dyn Consistency>,
    copy: WorldCopy,
    /// The copy before the step or report being taken (restored if it made the copy non-finite).
    before: WorldCopy,
    /// The world's objects (fixed at start).
    n: usize,
    /// The own user's contact on each object, from the newest tool sample.
    own: [ContactForce; MAX_OBJECTS],
    /// Whether the method steps on the session's tick grid.
    on_grid: bool,
    /// Ticks of the grid stepped so far (methods on the grid; else 0).
    ticks: u64,
    /// The last site report's and tool track's sequence numbers.
    seqs: [u64; 2],
    report_period_ns: u64,
    next_report_ns: u64,
    /// Steps or received reports that would have made the copy non-finite (the copy kept its
    /// state).
    pub nonfinite_kept: u64,
}

impl SiteDrive {
    /// Site `site`'s `method` from `copy`, reporting every `report_period_ns` from
    /// `first_report_ns` on, its site reports numbered after `report_seq` (a restarted physics
    /// process continues its sequence).
    pub fn new(
        site: usize,
        method: Box<dyn Consistency>,
        copy: WorldCopy,
        report_period_ns: u64,
        first_report_ns: u64,
        report_seq: u64,
    ) -> Self {
        Self {
            site,
            on_grid: method.grid_history_ticks().is_some(),
            method,
            n: copy.len().clamp(1, MAX_OBJECTS),
            before: copy.clone(),
            copy,
            own: [ContactForce::default(); MAX_OBJECTS],
            ticks: 0,
            seqs: [report_seq, 0],
            report_period_ns: report_period_ns.max(1),
            next_report_ns: first_report_ns,
            nonfinite_kept: 0,
        }
    }

    /// The own user's contact with each object, from the newest tool sample, as a tool sample
    /// carries it (what crosses the servo's ring is what the method sees: no slip flag, nothing
    /// past the world's objects).
    pub fn set_own(&mut self, own: &[ContactForce; MAX_OBJECTS]) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        for (k, (o, c)) in self.own.iter_mut().zip(own).enumerate() {
            *o = if k < self.n {
                ContactForce {
                    slipping: false,
                    ..*c
                }
            } else {
                ContactForce::default()
            };
        }
    }

    /// Hands a report from site `from`, received by `now_ns`, to the method. Whatever arrived,
    /// the copy never becomes NaN or infinite: such a result is undone and counted
    /// ([`SiteDrive::nonfinite_kept`]), and is no adoption.
    ///
    /// # Errors
    /// [`Refused::OwnSite`]: it names this site (nothing changed).
    pub fn receive(
        &mut self,
        world: &World,
        from: usize,
        msg: &Report,
        now_ns: u64,
    ) -> Result<Option<Adoption>, Refused> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        if from == self.site {
            return Err(Refused::OwnSite);
        }
        self.before.copy_from(&self.copy);
        let adopted = self
            .method
            .receive(world, &mut self.copy, from, msg, ns_to_s(now_ns));
        if !sane(world, &self.copy) {
            self.copy.copy_from(&self.before);
            self.nonfinite_kept += 1;
            return Ok(None);
        }
        Ok(adopted)
    }

    /// Site `from` went silent at `now_ns`: the method fades out what it still applies of it.
    pub fn peer_lost(&mut self, from: usize, now_ns: u64) {
        if from != self.site {
            self.method.peer_lost(from, ns_to_s(now_ns));
        }
    }

    /// One physics tick of `period_ns` ending at `now_ns`, with the own tool as the servo last
    /// sampled it. A step that would make the copy non-finite is undone and counted.
    pub fn tick(&mut self, world: &World, tool: &ToolAt, now_ns: u64, period_ns: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let (now_s, dt_s) = (ns_to_s(now_ns), ns_to_s(period_ns));
        self.method.own_tool(tool.at(now_ns));
        self.copy.set_time(now_s - dt_s);
        self.before.copy_from(&self.copy);
        self.method
            .physics_step(world, &mut self.copy, &self.own[..self.n], dt_s);
        if !sane(world, &self.copy) {
            self.copy.copy_from(&self.before);
            self.nonfinite_kept += 1;
        }
        self.copy.set_time(now_s);
        self.ticks += u64::from(self.on_grid);
    }

    /// The reports due at `now_ns` (one report period after the last, at the first tick at or
    /// after it), each handed to `out` as what it puts on the network, numbered. Tracks go out
    /// only once the grid has begun (before, the site has nothing of its own to say).
    pub fn report(&mut self, now_ns: u64, out: &mut dyn FnMut(Put)) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        if now_ns < self.next_report_ns {
            return;
        }
        self.next_report_ns = self
            .next_report_ns
            .max(now_ns.saturating_sub(self.report_period_ns))
            + self.report_period_ns;
        let (begun, seqs) = (self.ticks > 0, &mut self.seqs);
        let mut send = |report: Report| {
            let (track, state) = Put::split(report);
            if let Some(t) = track.filter(|_| begun) {
                seqs[1] += 1;
                out(Put::Track(ToolReport { seq: seqs[1], ..t }));
            }
            if let Some(report) = state {
                seqs[0] += 1;
                out(Put::Report {
                    seq: seqs[0],
                    report,
                });
            }
        };
        self.method
            .report(&self.copy, &self.own[..self.n], ns_to_s(now_ns), &mut send);
    }

    /// For a method on the grid: the copy is the state at the start of tick `tick` (a late or
    /// restarted physics process), from `states` (the world's objects in order; `None`: the copy
    /// as it is). Before the first tick.
    pub fn start_at_tick(&mut self, tick: u64, states: Option<&[BodyState; MAX_OBJECTS]>) {
        if let Some(states) = states {
            for (o, s) in self.copy.objects_mut().iter_mut().zip(states) {
                *o = ObjectCopy::new(*s);
            }
        }
        self.ticks = tick;
        self.method
            .start_at_tick(i64::try_from(tick).unwrap_or(i64::MAX));
    }

    /// Whether the method steps on the session's tick grid (it exchanges tool tracks).
    pub fn on_grid(&self) -> bool {
        self.on_grid
    }
    /// Ticks of the grid stepped so far (0 off the grid).
    pub fn ticks(&self) -> u64 {
        self.ticks
    }
    /// The copy this site believes.
    pub fn copy(&self) -> &WorldCopy {
        &self.copy
    }
    /// The world's objects (fixed at start).
    pub fn objects(&self) -> usize {
        self.n
    }
    /// The own user's contact with each object, as the method is given it.
    pub fn own(&self) -> &[ContactForce] {
        &self.own[..self.n]
    }
    /// The state of object `k` the own user is shown ([`Consistency::shown`]).
    pub fn shown(&self, k: usize) -> BodyState {
        self.method.shown(&self.copy, k)
    }
    /// The others' force the method applies to the copy, N ([`Consistency::remote_force`]).
    pub fn remote_force(&self) -> Vec3 {
        self.method.remote_force()
    }
    /// What the method did so far ([`Consistency::stats`]).
    pub fn stats(&self) -> Stats {
        self.method.stats()
    }
    /// The last site report's sequence number.
    pub fn report_seq(&self) -> u64 {
        self.seqs[0]
    }
}

/// A copy physics may keep: every number finite, its energy too (a finite state can still hold
/// an angular momentum whose next rotation step is NaN).
fn sane(world: &World, copy: &WorldCopy) -> bool {
    copy.objects().iter().zip(world.bodies()).all(|(o, b)| {
        o.state.is_finite()
            && o.state
                .mechanical_energy(&b.mass, world.gravity)
                .is_finite()
    })
}

/// Nanoseconds as seconds, the one conversion both callers use.
pub fn ns_to_s(ns: u64) -> f64 {
    ns as f64 * 1e-9
}
