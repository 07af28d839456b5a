//! What a receiver admits: a decoded report is taken only if it is its site's (the one its key
//! names), its time can be read (the sender's clock offset is known) and lies in a window around now
//! once corrected, it is possible in this world ([`Bounds`], derived from the scenario), and its
//! sequence number is newer than any seen from that site. Anything else is a typed [`Refusal`],
//! counted by reason, that changes nothing: no refused message moves "newest seen" for its site.
//!
//! One forged message must not silence a genuine site: a sequence number far ahead (2⁶⁴−1, or a
//! sender that restarted) would make every later genuine state look old. So a site whose states
//! keep arriving with *newer, plausible times* but sequence numbers at or below the newest seen is
//! resynchronised after [`RESYNC_STRIKES`] of them in a row (counted), while a replay (an old time)
//! stays refused.

use coop_model::method::track::QUANTUM_M;
use coop_model::scenario::Scenario;
use coop_model::world::MAX_OBJECTS;
use coop_model::MAX_SITES;
use coop_rt::msg::{SiteReport, ToolTrack, KIND_COUPLED};
use coop_rt::shm::control::Refused;

use crate::wire::{decode, decode_track, DecodeError};

/// Genuine states refused in a row as out of order, with newer plausible times, before the site's
/// sequence is resynchronised.
pub const RESYNC_STRIKES: u32 = 4;

/// Why a receiver refused a message.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Refusal {
    /// It does not decode.
    #[error(transparent)]
    Decode(#[from] DecodeError),
    /// Its site is not one of the session's, or not the one its key names.
    #[error("site {site} is not the sender its key names")]
    Foreign {
        /// The site index in the message.
        site: u64,
    },
    /// A sequence number already seen from this site, or older than the newest seen.
    #[error("sequence {seq} from site {site} is not newer than {newest}")]
    Stale {
        /// The site.
        site: usize,
        /// Its sequence number.
        seq: u64,
        /// The newest seen.
        newest: u64,
    },
    /// The sender's clock offset is not known yet, so its time cannot be read.
    #[error("site {site}'s clock offset is not known yet")]
    NoOffset {
        /// The site.
        site: usize,
    },
    /// Older than the age limit once corrected.
    #[error("state of site {site} is {age_ms:.1} ms old, beyond the {limit_ms:.1} ms age limit")]
    TooOld {
        /// The site.
        site: usize,
        /// Its age, ms.
        age_ms: f64,
        /// The limit, ms.
        limit_ms: f64,
    },
    /// Ahead of now beyond the window once corrected.
    #[error("state of site {site} is {ahead_ms:.1} ms in the future")]
    Future {
        /// The site.
        site: usize,
        /// How far ahead, ms.
        ahead_ms: f64,
    },
    /// About another object than the one its key names.
    #[error("state of site {site} is of object {object}, its key names object {key_object}")]
    OtherObject {
        /// The site.
        site: usize,
        /// The object it is about.
        object: u64,
        /// The object its key names.
        key_object: u64,
    },
    /// Finite but impossible in this world.
    #[error("state of site {site}: {what} is beyond what this world allows")]
    Implausible {
        /// The site.
        site: usize,
        /// Which quantity.
        what: &'static str,
    },
}

impl Refusal {
    /// The reason it is counted under (`ControlBlock::network.refused`).
    pub fn reason(&self) -> Refused {
        match self {
            Refusal::Decode(DecodeError::Version { .. }) => Refused::Version,
            // Not a message of this wire's framing.
            Refusal::Decode(
                DecodeError::Truncated { .. }
                | DecodeError::Trailing { .. }
                | DecodeError::Varint { .. },
            ) => Refused::Length,
            Refusal::Decode(DecodeError::Invalid) => Refused::Contents,
            // Not what its key names: counted with the foreign ones.
            Refusal::Foreign { .. } | Refusal::OtherObject { .. } => Refused::Foreign,
            Refusal::Stale { .. } => Refused::Stale,
            Refusal::NoOffset { .. } => Refused::NoOffset,
            Refusal::TooOld { .. } => Refused::TooOld,
            Refusal::Future { .. } => Refused::Future,
            Refusal::Implausible { .. } => Refused::Implausible,
        }
    }
}

/// What is possible for one object of the world.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ObjectBounds {
    /// Largest speed, m/s.
    pub speed_m_per_s: f64,
    /// Largest angular momentum, kg·m²/s.
    pub ang_mom: f64,
}

/// What is possible in one world, and how old a state may be: the receiver's plausibility bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// Largest distance from the origin an object (or a contact point) can be at, m.
    pub extent_m: f64,
    /// How many objects the world has: a state of any other is refused.
    pub object_count: usize,
    /// Per object (the world's order), its speed and angular momentum bounds.
    pub objects: [ObjectBounds; MAX_OBJECTS],
    /// Largest dead-reckoning acceleration (gravity less support), m/s².
    pub accel_m_per_s2: f64,
    /// Largest contact force a site can report, N.
    pub force_n: f64,
    /// Oldest a state may be when it is handed to physics, ns.
    pub max_age_ns: u64,
    /// How far ahead of now a corrected time may be (clock-offset error), ns.
    pub future_ns: u64,
}

/// The default window ahead of now: offsets are estimated to within half a round trip.
pub const FUTURE_NS: u64 = 100_000_000;
/// How far a tool track's last tick may lie before the newest taken from its site: the longest
/// `timewarp` history (10 s) at the fastest physics (20 kHz). A track sent again for a receiver's
/// gap ([`coop_model::method::track::ToolReport::need`]) is older than the newest, never by more.
pub const MAX_TRACK_REWIND_TICKS: u64 = 200_000;

impl Bounds {
    /// The bounds of `sc`'s world. The age limit is `max_age_ms` if given, else the largest delay
    /// the scenario expects (its link's maximum plus jitter) plus three of its slowest report
    /// periods plus 100 ms.
    pub fn from_scenario(sc: &Scenario, max_age_ms: Option<f64>) -> Self {
        let size_of = |o: &coop_model::scenario::ObjectSpec| {
            o.radius_m
                .max(o.half_height_m)
                .max(o.half_extents_m.iter().copied().fold(0.0, f64::max))
        };
        let size = sc.objects.iter().map(size_of).fold(0.0, f64::max);
        let mut extent = sc
            .objects
            .iter()
            .map(|o| norm(o.start_m) + size_of(o))
            .fold(0.0, f64::max);
        for i in 0..sc.site.len() {
            let arm = sc.arm(i);
            extent = extent.max(norm(sc.site[i].device_base_m) + arm.link1_m + arm.link2_m);
        }
        for p in &sc.world.planes {
            extent = extent.max(p.offset_m.abs() + size);
        }
        let extent_m = extent + 1.0;
        let force_n: f64 = sc.site.iter().map(|s| s.controller.max_force_n).sum();
        let g = norm(sc.world.gravity_m_per_s2);
        let world = sc.world();
        // The fastest the users and gravity can make an object across the whole world, twice;
        // an object pushed by another is no faster than the users could make the lightest (its
        // pusher's speed bounds it): the lightest's acceleration.
        let lightest = sc
            .objects
            .iter()
            .map(|o| o.mass_kg)
            .fold(f64::INFINITY, f64::min);
        let accel = force_n / lightest + g;
        let speed_m_per_s = 2.0 * (2.0 * accel * 2.0 * extent_m).sqrt();
        let mut objects = [ObjectBounds::default(); MAX_OBJECTS];
        for ((b, o), body) in objects.iter_mut().zip(&sc.objects).zip(world.bodies()) {
            let i_max = body.mass.inertia_body.max();
            let r_min = [o.radius_m, o.half_height_m]
                .into_iter()
                .chain(o.half_extents_m)
                .filter(|&r| r > 0.0)
                .fold(f64::INFINITY, f64::min)
                .max(1e-3);
            *b = ObjectBounds {
                speed_m_per_s,
                ang_mom: i_max * speed_m_per_s / r_min,
            };
        }
        let slowest_report_s = sc
            .site
            .iter()
            .map(|s| 1.0 / s.report_rate_hz)
            .fold(0.0, f64::max);
        let expected_ms = sc.network.delay_max_ms + sc.network.jitter_ms;
        let max_age_ms = max_age_ms.unwrap_or(expected_ms + 3e3 * slowest_report_s + 100.0);
        Self {
            extent_m,
            object_count: sc.objects.len().min(MAX_OBJECTS),
            objects,
            accel_m_per_s2: g * (1.0 + 1e-6) + 1e-9,
            force_n: 2.0 * force_n.max(1.0),
            max_age_ns: (max_age_ms * 1e6) as u64,
            future_ns: FUTURE_NS,
        }
    }

    /// Bounds that admit any finite state of any age (tests of the other rules).
    pub fn unbounded() -> Self {
        Self {
            extent_m: f64::MAX,
            object_count: MAX_OBJECTS,
            objects: [ObjectBounds {
                speed_m_per_s: f64::MAX,
                ang_mom: f64::MAX,
            }; MAX_OBJECTS],
            accel_m_per_s2: f64::MAX,
            force_n: f64::MAX,
            max_age_ns: u64::MAX,
            future_ns: u64::MAX,
        }
    }

    /// The first quantity of `r` (from `site`) beyond these bounds; `now_of` gives each site's
    /// clock now, in its own seconds, where it is known.
    fn implausible(
        &self,
        site: usize,
        r: &SiteReport,
        now_of: impl Fn(usize) -> Option<f64>,
    ) -> Option<&'static str> {
        let Some(ob) = self.object(r.object) else {
            return Some("object");
        };
        if r.kind == 1 || r.kind == KIND_COUPLED {
            if norm(r.pos) > self.extent_m {
                return Some("position");
            }
            if norm(r.vel) > ob.speed_m_per_s {
                return Some("velocity");
            }
            if norm(r.ang_mom) > ob.ang_mom {
                return Some("angular momentum");
            }
            if norm(r.accel) > self.accel_m_per_s2 {
                return Some("acceleration");
            }
            let window_s = self.future_ns as f64 * 1e-9;
            for (k, &t) in r.included.iter().enumerate() {
                // -1: that site's user has not touched it; else a time on that site's clock, which
                // cannot be later than that site's now. (`coupled`: its own user's contact times,
                // on its own clock.)
                let clock = if r.kind == KIND_COUPLED { site } else { k };
                let late = now_of(clock).is_some_and(|now| t > now + window_s);
                if !(t == -1.0 || (0.0..=1e12).contains(&t)) || late {
                    return Some("inclusion time");
                }
            }
        } else {
            if norm(r.force) > self.force_n {
                return Some("force");
            }
            if norm(r.point) > self.extent_m || !(0.0..=1.0).contains(&r.depth.abs()) {
                return Some("contact point");
            }
        }
        None
    }
}

impl Bounds {
    /// Object `k`'s bounds, or `None` if the world has no object `k`.
    pub fn object(&self, k: u64) -> Option<&ObjectBounds> {
        usize::try_from(k)
            .ok()
            .filter(|&k| k < self.object_count)
            .and_then(|k| self.objects.get(k))
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// What the receiver remembers of one site.
#[derive(Debug, Clone, Copy, Default)]
struct Seen {
    /// The newest sequence number accepted.
    seq: Option<u64>,
    /// The newest (corrected) state time accepted, ns.
    t_ns: u64,
    /// Genuine-looking states refused in a row as out of order.
    strikes: u32,
}

/// A message the receiver took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Admitted {
    /// The sender's site index.
    pub site: usize,
    /// The report, its time corrected to our clock.
    pub report: SiteReport,
    /// The sender's clock offset it was corrected by, ns.
    pub offset_ns: i64,
    /// It was taken by resynchronising the site's sequence.
    pub resync: bool,
}

/// A receiver's view of the session: which sites exist, what is plausible, and what it has taken
/// from each.
#[derive(Debug, Clone)]
pub struct Inbound {
    sites: Vec<String>,
    bounds: Bounds,
    seen: Vec<Seen>,
    /// Per site: what was taken of its tool tracks.
    seen_tracks: Vec<Seen>,
    /// Per site: the tick after the last of its newest track taken.
    track_ticks: Vec<u64>,
}

impl Inbound {
    /// A receiver for a session of these sites (in scenario order) in a world of `bounds`.
    pub fn new(sites: Vec<String>, bounds: Bounds) -> Self {
        let n = sites.len();
        Self {
            sites,
            bounds,
            seen: vec![Seen::default(); n],
            seen_tracks: vec![Seen::default(); n],
            track_ticks: vec![0; n],
        }
    }
    /// The index of a site name.
    pub fn index_of(&self, site: &str) -> Option<usize> {
        self.sites.iter().position(|s| s == site)
    }
    /// The bounds it checks against.
    pub fn bounds(&self) -> &Bounds {
        &self.bounds
    }

    /// Decodes `bytes` received on a key naming `key_site` and object `key_object` at `now_ns`
    /// (our clock) and takes it only if it passes every rule of this module; `offsets[j]` is site
    /// j's clock minus ours, ns, where known.
    ///
    /// # Errors
    /// [`Refusal`]; nothing changes then (but a resynchronisation's strike count).
    pub fn check(
        &mut self,
        key_site: &str,
        key_object: u64,
        bytes: &[u8],
        now_ns: u64,
        offsets: &[Option<i64>],
    ) -> Result<Admitted, Refusal> {
        self.check_decoded(key_site, key_object, decode(bytes)?, now_ns, offsets)
    }

    /// [`Inbound::check`] for a report already decoded (by [`crate::wire::decode`], once: a
    /// receiver that holds a report until its sender's clock offset is known holds it decoded).
    ///
    /// # Errors
    /// As [`Inbound::check`], but for the decoding.
    pub fn check_decoded(
        &mut self,
        key_site: &str,
        key_object: u64,
        mut r: SiteReport,
        now_ns: u64,
        offsets: &[Option<i64>],
    ) -> Result<Admitted, Refusal> {
        let site = self
            .index_of(key_site)
            .filter(|&i| i as u64 == r.site)
            .ok_or(Refusal::Foreign { site: r.site })?;
        if r.object != key_object {
            return Err(Refusal::OtherObject {
                site,
                object: r.object,
                key_object,
            });
        }
        let offset_ns = offsets
            .get(site)
            .copied()
            .flatten()
            .ok_or(Refusal::NoOffset { site })?;
        r.t_ns = r.t_ns.saturating_add_signed(offset_ns.saturating_neg());
        let now_of = |k: usize| -> Option<f64> {
            let off = offsets.get(k).copied().flatten()?;
            Some(now_ns.saturating_add_signed(off) as f64 * 1e-9)
        };
        let plausible = self.window(site, r.t_ns, now_ns).and_then(|()| {
            match self.bounds.implausible(site, &r, now_of) {
                Some(what) => Err(Refusal::Implausible { site, what }),
                None => Ok(()),
            }
        });
        let resync = order(&mut self.seen[site], site, r.seq, r.t_ns, plausible)?;
        if r.kind == KIND_COUPLED {
            // Its user's contact times, like its time, on our clock (−1 stays: none).
            let shift = offset_ns as f64 * 1e-9;
            for t in &mut r.included[..2] {
                if *t >= 0.0 {
                    *t = (*t - shift).max(0.0);
                }
            }
        }
        Ok(Admitted {
            site,
            report: r,
            offset_ns,
            resync,
        })
    }

    /// The time rule: a corrected time `t_ns` lies within the age limit behind `now_ns` and the
    /// window ahead of it.
    fn window(&self, site: usize, t_ns: u64, now_ns: u64) -> Result<(), Refusal> {
        self.age_ok(site, t_ns, now_ns)?;
        let ahead = t_ns.saturating_sub(now_ns);
        if ahead > self.bounds.future_ns {
            return Err(Refusal::Future {
                site,
                ahead_ms: ahead as f64 * 1e-6,
            });
        }
        Ok(())
    }

    /// The age rule alone, for a state about to be handed over (after an emulated delay).
    ///
    /// # Errors
    /// [`Refusal::TooOld`].
    pub fn age_ok(&self, site: usize, t_ns: u64, now_ns: u64) -> Result<(), Refusal> {
        let age = now_ns.saturating_sub(t_ns);
        if age > self.bounds.max_age_ns {
            return Err(Refusal::TooOld {
                site,
                age_ms: age as f64 * 1e-6,
                limit_ms: self.bounds.max_age_ns as f64 * 1e-6,
            });
        }
        Ok(())
    }

    /// Forgets a site's sequence numbers (it left the session; a new run of it starts afresh).
    pub fn forget(&mut self, site: usize) {
        if let Some(s) = self.seen.get_mut(site) {
            *s = Seen::default();
        }
        if let Some(s) = self.seen_tracks.get_mut(site) {
            *s = Seen::default();
        }
        if let Some(t) = self.track_ticks.get_mut(site) {
            *t = 0;
        }
    }
}

/// The sequence rule for one site's messages of one kind (`seen` is what was taken of them):
/// newer than any taken, or a genuine sender behind a forged sequence (newer, `plausible` times,
/// [`RESYNC_STRIKES`] in a row). On success `seen` takes this message and the result says whether
/// it was a resynchronisation.
fn order(
    seen: &mut Seen,
    site: usize,
    seq: u64,
    t_ns: u64,
    plausible: Result<(), Refusal>,
) -> Result<bool, Refusal> {
    let before = *seen;
    if let Some(newest) = before.seq.filter(|&n| seq <= n) {
        // Out of order: a replay (an old time), or a genuine sender whose sequence is behind a
        // forged or stale one (newer, plausible times).
        let genuine = plausible.is_ok() && t_ns > before.t_ns;
        if !genuine {
            return Err(Refusal::Stale { site, seq, newest });
        }
        seen.strikes += 1;
        if seen.strikes < RESYNC_STRIKES {
            return Err(Refusal::Stale { site, seq, newest });
        }
    } else {
        plausible?;
    }
    *seen = Seen {
        seq: Some(seq),
        t_ns,
        strikes: 0,
    };
    Ok(before.seq.is_some_and(|n| seq <= n))
}

/// A tool track the receiver took.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdmittedTrack {
    /// The sender's site index.
    pub site: usize,
    /// The track, its time corrected to our clock (its ticks are the session's, not corrected).
    pub track: ToolTrack,
    /// The sender's clock offset it was corrected by, ns.
    pub offset_ns: i64,
    /// It was taken by resynchronising the site's track sequence.
    pub resync: bool,
}

impl Inbound {
    /// [`Inbound::check`] for a tool track (`tool/<key_site>`): decoded and validated
    /// ([`crate::wire::decode_track`]), its site the key's, its time readable and in the window,
    /// every position inside the world's extent, its sequence newer than any track taken from
    /// that site (tracks have their own sequence, apart from states'), and its last tick not more
    /// than [`MAX_TRACK_REWIND_TICKS`] before the last tick of the newest track taken (a track
    /// sent again for a receiver's gap is older than the newest, never by more than a history).
    ///
    /// # Errors
    /// [`Refusal`], counted by the same reasons as states'; nothing changes then.
    pub fn check_track(
        &mut self,
        key_site: &str,
        bytes: &[u8],
        now_ns: u64,
        offsets: &[Option<i64>],
    ) -> Result<AdmittedTrack, Refusal> {
        self.check_track_decoded(key_site, decode_track(bytes)?, now_ns, offsets)
    }

    /// [`Inbound::check_track`] for a track already decoded ([`crate::wire::decode_track`]).
    ///
    /// # Errors
    /// As [`Inbound::check_track`], but for the decoding.
    pub fn check_track_decoded(
        &mut self,
        key_site: &str,
        mut t: ToolTrack,
        now_ns: u64,
        offsets: &[Option<i64>],
    ) -> Result<AdmittedTrack, Refusal> {
        let site = self
            .index_of(key_site)
            .filter(|&i| i as u64 == t.site)
            .ok_or(Refusal::Foreign { site: t.site })?;
        let offset_ns = offsets
            .get(site)
            .copied()
            .flatten()
            .ok_or(Refusal::NoOffset { site })?;
        t.t_ns = t.t_ns.saturating_add_signed(offset_ns.saturating_neg());
        let end_tick = t.first_tick + t.count;
        let plausible = self.window(site, t.t_ns, now_ns).and_then(|()| {
            if t.max_abs_quantized() as f64 * QUANTUM_M > self.bounds.extent_m {
                return Err(Refusal::Implausible {
                    site,
                    what: "tool position",
                });
            }
            // A confirmed state sent for a site to adopt: of an object of this world, within it,
            // as a state must be (none carried: every word 0, object 0).
            let (extent, speed, ang_mom) = t.state_magnitudes();
            let ob = match self.bounds.object(t.state_object) {
                Some(ob)
                    if t.has_state == 0 || t.state_objects == self.bounds.object_count as u64 =>
                {
                    ob
                }
                _ => {
                    return Err(Refusal::Implausible {
                        site,
                        what: "state object",
                    })
                }
            };
            for (what, v, max) in [
                ("state position", extent, self.bounds.extent_m),
                ("state velocity", speed, ob.speed_m_per_s),
                ("state angular momentum", ang_mom, ob.ang_mom),
            ] {
                if v > max {
                    return Err(Refusal::Implausible { site, what });
                }
            }
            if end_tick.saturating_add(MAX_TRACK_REWIND_TICKS) < self.track_ticks[site] {
                return Err(Refusal::Implausible {
                    site,
                    what: "tool track tick",
                });
            }
            Ok(())
        });
        let resync = order(&mut self.seen_tracks[site], site, t.seq, t.t_ns, plausible)?;
        self.track_ticks[site] = self.track_ticks[site].max(end_tick);
        Ok(AdmittedTrack {
            site,
            track: t,
            offset_ns,
            resync,
        })
    }
}

/// Offsets for `n` sites, all known and zero (one clock).
pub fn same_clock(n: usize) -> Vec<Option<i64>> {
    vec![Some(0); n.min(MAX_SITES)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::encode;

    fn sample() -> SiteReport {
        let mut r = SiteReport {
            kind: 1,
            t_ns: 5,
            seq: 9,
            site: 1,
            rot: [1.0, 0.0, 0.0, 0.0],
            ..SiteReport::default()
        };
        r.pos = [0.1, 0.2, 0.3];
        r.included = [-1.0; MAX_SITES];
        r.included[1] = 4.5e-9;
        r
    }

    #[test]
    fn a_receiver_refuses_foreign_sites_duplicates_and_reordering() {
        let mut rx = Inbound::new(vec!["a".into(), "b".into()], Bounds::unbounded());
        let clocks = same_clock(2);
        let check = |rx: &mut Inbound, key: &str, bytes: &[u8]| rx.check(key, 0, bytes, 5, &clocks);
        let mut r = sample(); // site 1 = "b", seq 9
        assert_eq!(check(&mut rx, "b", &encode(&r)).map(|x| x.site), Ok(1));
        assert_eq!(
            check(&mut rx, "b", &encode(&r)),
            Err(Refusal::Stale {
                site: 1,
                seq: 9,
                newest: 9
            }),
            "a replay"
        );
        r.seq = 8;
        assert_eq!(
            check(&mut rx, "b", &encode(&r)).map_err(|e| e.reason()),
            Err(Refused::Stale),
            "reordered"
        );
        r.seq = 10;
        assert_eq!(
            check(&mut rx, "a", &encode(&r)),
            Err(Refusal::Foreign { site: 1 }),
            "key names another site"
        );
        assert_eq!(
            check(&mut rx, "zz", &encode(&r)).map_err(|e| e.reason()),
            Err(Refused::Foreign),
            "unknown site"
        );
        r.site = 5;
        assert_eq!(
            check(&mut rx, "b", &encode(&r)).map_err(|e| e.reason()),
            Err(Refused::Foreign)
        );
        r.site = 1;
        assert_eq!(
            check(&mut rx, "b", &[crate::wire::VERSION, 2, 3]).map_err(|e| e.reason()),
            Err(Refused::Length)
        );
        // An object other than the key's, or one the world does not have.
        r.object = 1;
        assert_eq!(
            check(&mut rx, "b", &encode(&r)).map_err(|e| e.reason()),
            Err(Refused::Foreign),
            "key names another object"
        );
        r.object = MAX_OBJECTS as u64;
        assert_eq!(
            rx.check("b", r.object, &encode(&r), 5, &clocks)
                .map_err(|e| e.reason()),
            Err(Refused::Contents),
            "an object no world has"
        );
        r.object = 0;
        assert!(
            check(&mut rx, "b", &encode(&r)).is_ok(),
            "refusals changed nothing: 10 is still new"
        );
        rx.forget(1);
        r.seq = 1;
        assert!(
            check(&mut rx, "b", &encode(&r)).is_ok(),
            "a site that left starts afresh"
        );
    }

    fn paper_bounds() -> Bounds {
        Bounds {
            extent_m: 2.0,
            object_count: 1,
            objects: [ObjectBounds {
                speed_m_per_s: 40.0,
                ang_mom: 1.0,
            }; MAX_OBJECTS],
            accel_m_per_s2: 3.27,
            force_n: 40.0,
            max_age_ns: 700_000_000,
            future_ns: FUTURE_NS,
        }
    }

    const S: u64 = 1_000_000_000;

    #[test]
    fn no_time_is_read_before_the_senders_offset_is_known() {
        let mut rx = Inbound::new(vec!["a".into(), "b".into()], paper_bounds());
        let mut r = sample();
        r.t_ns = 1000 * S + 10 * S; // their clock is 1000 s ahead of ours
        let now = 10 * S;
        assert_eq!(
            rx.check("b", 0, &encode(&r), now, &[Some(0), None]),
            Err(Refusal::NoOffset { site: 1 })
        );
        // Nothing moved: once the offset is known the same state is taken, at our time.
        let a = rx
            .check("b", 0, &encode(&r), now, &[Some(0), Some(1000 * S as i64)])
            .expect("taken");
        assert_eq!(a.report.t_ns, 10 * S);
    }

    #[test]
    fn a_coupled_states_contact_times_are_read_on_our_clock_and_checked_on_its_senders() {
        let mut rx = Inbound::new(vec!["a".into(), "b".into()], paper_bounds());
        let mut r = sample();
        r.kind = KIND_COUPLED;
        r.included = [0.0; MAX_SITES];
        r.included[0] = 1008.0; // its user's contact began 2 s before the state, its clock
        r.included[1] = -1.0; // "never" stays
        r.t_ns = 1000 * S + 10 * S; // their clock is 1000 s ahead of ours
        let offsets = [Some(0), Some(1000 * S as i64)];
        let a = rx
            .check("b", 0, &encode(&r), 10 * S, &offsets)
            .expect("taken");
        assert_eq!(a.report.t_ns, 10 * S);
        assert!((a.report.included[0] - 8.0).abs() < 1e-9, "{:?}", a.report);
        assert_eq!(a.report.included[1], -1.0);
        // A contact that begins after its sender's now is refused.
        r.seq += 1;
        r.included[0] = 1020.0;
        assert_eq!(
            rx.check("b", 0, &encode(&r), 10 * S, &offsets)
                .map_err(|e| e.reason()),
            Err(Refused::Implausible)
        );
    }

    #[test]
    fn times_outside_the_window_are_refused_and_move_nothing() {
        let mut rx = Inbound::new(vec!["a".into(), "b".into()], paper_bounds());
        let clocks = same_clock(2);
        let now = 100 * S;
        let mut r = sample();
        for (t, reason) in [
            (u64::MAX, Refused::Future),
            (now + S, Refused::Future),
            (now - 5 * S, Refused::TooOld),
            (0, Refused::TooOld),
        ] {
            r.t_ns = t;
            r.seq += 1;
            assert_eq!(
                rx.check("b", 0, &encode(&r), now, &clocks)
                    .map_err(|e| e.reason()),
                Err(reason),
                "t = {t}"
            );
        }
        // The newest seen did not move: a genuine state at now is taken.
        r.t_ns = now;
        r.seq = 10;
        assert!(rx.check("b", 0, &encode(&r), now, &clocks).is_ok());
    }

    #[test]
    fn finite_but_absurd_states_are_refused() {
        let mut rx = Inbound::new(vec!["a".into(), "b".into()], paper_bounds());
        let clocks = same_clock(2);
        let now = 100 * S;
        let base = SiteReport {
            t_ns: now,
            ..sample()
        };
        type Edit = fn(&mut SiteReport);
        let cases: [(&str, Edit); 6] = [
            ("position", |r| r.pos = [11.0, 0.0, 0.0]),
            ("velocity", |r| r.vel = [1e3, 0.0, 0.0]),
            ("angular momentum", |r| r.ang_mom = [0.0, 0.0, 1e6]),
            ("acceleration", |r| r.accel = [0.0, 0.0, -1e4]),
            ("inclusion time", |r| r.included[0] = 1e300),
            ("inclusion time", |r| r.included[1] = 1e6),
        ];
        for (k, (what, bad)) in cases.iter().enumerate() {
            let mut r = base;
            r.seq = 100 + k as u64;
            bad(&mut r);
            assert_eq!(
                rx.check("b", 0, &encode(&r), now, &clocks),
                Err(Refusal::Implausible { site: 1, what }),
                "{what}"
            );
        }
        let mut r = base;
        r.seq = 50;
        assert!(
            rx.check("b", 0, &encode(&r), now, &clocks).is_ok(),
            "refusals moved nothing"
        );
    }

    #[test]
    fn one_forged_sequence_number_cannot_silence_a_site() {
        let mut rx = Inbound::new(vec!["a".into(), "b".into()], paper_bounds());
        let clocks = same_clock(2);
        let mut now = 100 * S;
        let mut r = sample();
        r.t_ns = now;
        assert!(rx.check("b", 0, &encode(&r), now, &clocks).is_ok());
        let mut forged = r;
        forged.seq = u64::MAX;
        forged.t_ns = now + 1;
        assert!(
            rx.check("b", 0, &encode(&forged), now, &clocks).is_ok(),
            "plausible: taken once"
        );
        // The genuine sender goes on; replays of old states stay refused, but its newer states
        // resynchronise the sequence after a few.
        let mut taken = Vec::new();
        for k in 1..=10 {
            now += 10_000_000;
            r.seq += 1;
            r.t_ns = now;
            taken.push(
                rx.check("b", 0, &encode(&r), now, &clocks)
                    .map(|a| a.resync),
            );
            let mut replay = r;
            replay.t_ns = now - 20_000_000 * k;
            assert_eq!(
                rx.check("b", 0, &encode(&replay), now, &clocks)
                    .map_err(|e| e.reason()),
                Err(Refused::Stale)
            );
        }
        let first = (RESYNC_STRIKES - 1) as usize;
        assert!(taken[..first].iter().all(Result::is_err), "{taken:?}");
        assert_eq!(taken[first], Ok(true), "{taken:?}");
        assert!(
            taken[first + 1..].iter().all(|t| *t == Ok(false)),
            "{taken:?}"
        );
    }

    #[test]
    fn bounds_of_the_paper_world_admit_its_states() {
        let b = Bounds::from_scenario(&Scenario::default(), None);
        assert!(b.extent_m > 1.0 && b.extent_m < 10.0, "{b:?}");
        let speed = b.objects[0].speed_m_per_s;
        assert!(speed > 5.0 && speed < 1e3, "{b:?}");
        assert!(b.max_age_ns >= 100_000_000, "{b:?}");
    }

    /// In a world of several objects each has its own bounds (a light puck may spin faster than
    /// a heavy box), and a state of an object the world does not have is refused.
    #[test]
    fn each_object_of_a_world_has_its_bounds() {
        let mut sc = Scenario::default();
        let mut heavy = sc.objects[0].clone();
        heavy.name = "heavy".into();
        heavy.mass_kg *= 10.0;
        heavy.radius_m *= 3.0;
        heavy.start_m[0] += 0.2;
        sc.objects[0].name = "light".into();
        sc.objects.push(heavy);
        let b = Bounds::from_scenario(&sc, None);
        assert_eq!(b.object_count, 2);
        assert!(b.objects[1].ang_mom > b.objects[0].ang_mom, "{b:?}");
        let mut rx = Inbound::new(vec!["a".into(), "b".into()], b);
        let clocks = same_clock(2);
        let mut r = sample();
        r.t_ns = 1_000_000_000;
        r.ang_mom = [
            0.0,
            0.0,
            0.5 * (b.objects[0].ang_mom + b.objects[1].ang_mom),
        ];
        let now = r.t_ns;
        r.object = 1;
        assert!(
            rx.check("b", 1, &encode(&r), now, &clocks).is_ok(),
            "the heavy one"
        );
        r.seq += 1;
        r.object = 0;
        assert_eq!(
            rx.check("b", 0, &encode(&r), now, &clocks)
                .map_err(|e| e.reason()),
            Err(Refused::Implausible),
            "the light one cannot spin so"
        );
        r.object = 2;
        assert_eq!(
            rx.check("b", 2, &encode(&r), now, &clocks)
                .map_err(|e| e.reason()),
            Err(Refused::Implausible),
            "a third object"
        );
    }

    #[test]
    fn tool_tracks_are_admitted_by_the_same_rules_as_states() {
        use crate::wire::encode_track;
        use coop_model::method::track::{ToolReport, WINDOW_TICKS};
        let r = ToolReport {
            first_tick: 100,
            count: 10,
            positions: [[-4500, 0, 1000]; WINDOW_TICKS],
            confirmed_tick: 90,
            confirmed_hash: 5,
            need: [-1; coop_model::method::MAX_SITES],
            ..ToolReport::NONE
        };
        let mut r = r;
        r.positions[10..].fill([0; 3]);
        let track = |seq: u64, first: i64, r: &ToolReport| {
            let mut t = ToolTrack::new(
                1,
                seq,
                1_000_000_000,
                &ToolReport {
                    first_tick: first,
                    confirmed_tick: first - 10,
                    ..*r
                },
            );
            t.site = 1;
            encode_track(&t)
        };
        let sites = vec!["user1".to_owned(), "user2".to_owned()];
        let mut inb = Inbound::new(sites, paper_bounds());
        let now = 1_010_000_000;
        let clocks = same_clock(2);
        let a = inb
            .check_track("user2", &track(1, 100, &r), now, &clocks)
            .expect("a genuine track");
        assert_eq!((a.site, a.track.first_tick, a.track.count), (1, 100, 10));
        // Sender = key site.
        let e = inb.check_track("user1", &track(2, 110, &r), now, &clocks);
        assert_eq!(e.map_err(|e| e.reason()), Err(Refused::Foreign));
        // A replay.
        let e = inb.check_track("user2", &track(1, 100, &r), now, &clocks);
        assert_eq!(e.map_err(|e| e.reason()), Err(Refused::Stale));
        // Ticks going back, as a gap sent again does: taken (a history's worth at most).
        inb.check_track("user2", &track(3, 50, &r), now, &clocks)
            .expect("a gap's positions sent again");
        inb.check_track("user2", &track(4, 300_000, &r), now, &clocks)
            .expect("ticks on");
        let e = inb.check_track(
            "user2",
            &track(5, 300_000 - MAX_TRACK_REWIND_TICKS as i64 - 11, &r),
            now,
            &clocks,
        );
        assert_eq!(
            e.map_err(|e| e.reason()),
            Err(Refused::Implausible),
            "back past any history"
        );
        // A tool 10 km away.
        let mut far = r;
        far.positions[3] = [1_000_000_000, 0, 0];
        let e = inb.check_track("user2", &track(6, 300_010, &far), now, &clocks);
        assert_eq!(e.map_err(|e| e.reason()), Err(Refused::Implausible));
        // Malformed: a count past the window (the header's fifth word, its varint after the
        // bitmap, the time, the sequence number and the site).
        let bytes = track(7, 300_010, &r);
        let count_at = 1 + 3 + 5 + 1 + 1 + 3;
        assert_eq!(bytes[count_at], 10, "the count of {bytes:?}");
        let mut bad = bytes[..count_at].to_vec();
        crate::wire::compact::put_varint(&mut bad, WINDOW_TICKS as u64 + 1);
        bad.extend_from_slice(&bytes[count_at + 1..]);
        let e = inb.check_track("user2", &bad, now, &clocks);
        assert_eq!(e.map_err(|e| e.reason()), Err(Refused::Contents));
        // Too old.
        let e = inb.check_track(
            "user2",
            &track(8, 300_010, &r),
            now + 10_000_000_000,
            &clocks,
        );
        assert_eq!(e.map_err(|e| e.reason()), Err(Refused::TooOld));
        // No offset known.
        let e = inb.check_track("user2", &track(9, 300_010, &r), now, &[Some(0), None]);
        assert_eq!(e.map_err(|e| e.reason()), Err(Refused::NoOffset));
        // Nothing refused moved anything: the next genuine one is taken.
        let a = inb
            .check_track("user2", &track(10, 300_010, &r), now, &clocks)
            .expect("the next genuine track");
        assert_eq!(a.track.seq, 10);
        // A confirmed state carried for a site to adopt: taken where a state would be, refused
        // where a state would be (faster than anything in the world can go).
        let with_state = |vel: f64| {
            let mut w = r;
            w.state = Some(coop_model::method::track::Snapshot::one(
                300_000,
                0,
                coop_model::body::BodyState {
                    vel: coop_model::body::Vec3::new(vel, 0.0, 0.0),
                    ..coop_model::body::BodyState::at_rest(coop_model::body::Vec3::new(
                        0.0, 0.0, 0.01,
                    ))
                },
                Default::default(),
                Default::default(),
            ));
            w
        };
        let a = inb
            .check_track("user2", &track(11, 300_010, &with_state(0.5)), now, &clocks)
            .expect("a plausible state");
        assert_eq!(a.track.has_state, 1);
        let e = inb.check_track("user2", &track(12, 300_010, &with_state(1e5)), now, &clocks);
        assert_eq!(e.map_err(|e| e.reason()), Err(Refused::Implausible));
        // States and tracks keep separate sequences.
        let state = SiteReport {
            t_ns: 1_000_000_000,
            seq: 1,
            ..sample()
        };
        let a = inb.check("user2", 0, &encode(&state), now, &clocks);
        assert_eq!(
            a.map(|a| a.report.seq),
            Ok(1),
            "a state's sequence is not a track's"
        );
    }
}
