//! A site's tool track (`timewarp`, `coupled`: the tools on the wire): its quantized positions,
//! its confirmed frontier and, when asked, the confirmed state with all its friction memory.

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::{EnvContactState, PairContactState, ToolContactState, MAX_PLANES};
use coop_model::method::track::{Snapshot, ToolReport, WINDOW_TICKS};
use coop_model::method::{Report, MAX_SITES};
use coop_model::world::MAX_OBJECTS;
use nalgebra::{Quaternion, UnitQuaternion};

#[cfg(doc)]
use super::SiteReport;
use super::{state_fields, ToolTrack, MAX_QUANTIZED, MAX_TRACK_TICK, TRACK_POSITION_WORDS};

impl Default for ToolTrack {
    fn default() -> Self {
        Self {
            t_ns: 0,
            seq: 0,
            site: 0,
            first_tick: 0,
            count: 0,
            confirmed_tick: 0,
            confirmed_hash: 0,
            need: [0; MAX_SITES],
            need_state: 0,
            loss: 0,
            started_tick: 0,
            has_state: 0,
            state_body: [0.0; 13],
            state_anchors: 0,
            state_env: [0.0; 3 * MAX_PLANES],
            state_tools: [0.0; 3 * MAX_SITES],
            state_object: 0,
            state_objects: 0,
            state_world_hash: 0,
            state_still: 0,
            state_memory: 0,
            state_env_twist: [0.0; 6 * MAX_PLANES],
            state_tool_twist: [0.0; 6 * MAX_SITES],
            state_pair_anchors: [0.0; 6 * (MAX_OBJECTS - 1)],
            state_pair_twist: [0.0; 6 * (MAX_OBJECTS - 1)],
            positions: [0; TRACK_POSITION_WORDS],
        }
    }
}

impl ToolTrack {
    /// Lays out `r` from `site` at `seq`, sent at `t_ns`. Negative ticks (never produced by
    /// `timewarp`, whose grid starts at 0) are laid out as 0.
    pub fn new(site: usize, seq: u64, t_ns: u64, r: &ToolReport) -> Self {
        let count = r.count.min(WINDOW_TICKS);
        let mut out = Self {
            t_ns,
            seq,
            site: site as u64,
            first_tick: r.first_tick.max(0) as u64,
            count: count as u64,
            confirmed_tick: r.confirmed_tick.max(0) as u64,
            confirmed_hash: r.confirmed_hash,
            need: r.need.map(|t| if t < 0 { 0 } else { t as u64 + 1 }),
            need_state: u64::from(r.need_state),
            loss: u64::from_le_bytes(r.loss),
            started_tick: r.started_tick,
            ..Self::default()
        };
        if let Some(snap) = r.state.filter(|s| s.tick == r.confirmed_tick) {
            out.lay_out_state(&snap);
        }
        for (c, &v) in r.positions[..count].iter().flatten().enumerate() {
            out.put_coordinate(c, v);
        }
        out
    }

    /// Lays out a carried state: the object, every friction memory it has, its world.
    fn lay_out_state(&mut self, snap: &Snapshot) {
        let (pos, rot, vel, ang_mom) = state_fields(&snap.state);
        self.has_state = 1;
        self.state_object = snap.object as u64;
        self.state_objects = snap.objects as u64;
        self.state_world_hash = snap.world_hash;
        self.state_still = u64::from(snap.still);
        for (k, v) in pos
            .iter()
            .chain(&rot)
            .chain(&vel)
            .chain(&ang_mom)
            .enumerate()
        {
            self.state_body[k] = *v;
        }
        let put =
            |w: &mut [f64], k: usize, v: Vec3| w[3 * k..3 * k + 3].copy_from_slice(v.as_slice());
        let put2 = |w: &mut [f64], k: usize, (a, b): (Vec3, Vec3)| {
            w[6 * k..6 * k + 3].copy_from_slice(a.as_slice());
            w[6 * k + 3..6 * k + 6].copy_from_slice(b.as_slice());
        };
        for (p, a) in snap.env.anchors().iter().enumerate() {
            if let Some(a) = *a {
                self.state_anchors |= 1 << p;
                put(&mut self.state_env, p, a);
            }
        }
        for (p, t) in snap.env.twists().iter().enumerate() {
            if let Some(t) = *t {
                self.state_memory |= 1 << p;
                put2(&mut self.state_env_twist, p, t);
            }
        }
        for (j, c) in snap.contacts.iter().enumerate() {
            if let Some(a) = c.anchor() {
                self.state_anchors |= 1 << (8 + j);
                put(&mut self.state_tools, j, a);
            }
            if let Some(t) = c.twist() {
                self.state_memory |= 1 << (8 + j);
                put2(&mut self.state_tool_twist, j, t);
            }
        }
        for (k, pair) in snap.pairs.iter().enumerate() {
            if let Some(a) = pair.anchors() {
                self.state_memory |= 1 << (16 + k);
                put2(&mut self.state_pair_anchors, k, a);
            }
            if let Some(t) = pair.twist() {
                self.state_memory |= 1 << (32 + k);
                put2(&mut self.state_pair_twist, k, t);
            }
        }
    }

    /// Coordinate `c` (of `3 * count`: x, y, z of tick `first_tick + c / 3`).
    pub fn coordinate(&self, c: usize) -> i32 {
        (self.positions[c / 2] >> (32 * (c % 2))) as u32 as i32
    }

    /// Lays out coordinate `c` as `v` (its half of the word must be 0).
    pub fn put_coordinate(&mut self, c: usize, v: i32) {
        self.positions[c / 2] |= u64::from(v as u32) << (32 * (c % 2));
    }

    /// The sender and the model's report, or `None` for a site out of range, more than
    /// [`WINDOW_TICKS`] positions, a tick (or one asked for) beyond [`MAX_TRACK_TICK`], a confirmed
    /// frontier past the last tick sent, a coordinate beyond [`MAX_QUANTIZED`], a nonzero unused
    /// coordinate, or a carried state that is not one (a repair of a receiver's gap, an older
    /// window, gives its sender's frontier at the window's end: see
    /// `coop_model::method::TimeWarp`'s report). The one validation of a track:
    /// the wire's decode and physics' ring → model conversion both apply it (see
    /// [`SiteReport::report`] for why both).
    pub fn report(&self) -> Option<(usize, Report)> {
        let site = usize::try_from(self.site).ok().filter(|&s| s < MAX_SITES)?;
        let count = usize::try_from(self.count)
            .ok()
            .filter(|&c| c <= WINDOW_TICKS)?;
        let end = self.first_tick.checked_add(self.count)?;
        (end <= MAX_TRACK_TICK && self.confirmed_tick <= end).then_some(())?;
        self.need
            .iter()
            .all(|&n| n <= MAX_TRACK_TICK)
            .then_some(())?;
        let need_state = u8::try_from(self.need_state).ok()?;
        (self.started_tick <= MAX_TRACK_TICK).then_some(())?;
        let state = self.snapshot()?;
        let used = 3 * count;
        for c in 0..3 * WINDOW_TICKS {
            let v = i64::from(self.coordinate(c));
            if (c < used && v.abs() > MAX_QUANTIZED) || (c >= used && v != 0) {
                return None;
            }
        }
        let mut r = ToolReport {
            first_tick: self.first_tick as i64,
            count,
            positions: [[0; 3]; WINDOW_TICKS],
            confirmed_tick: self.confirmed_tick as i64,
            confirmed_hash: self.confirmed_hash,
            need: self.need.map(|n| n as i64 - 1),
            need_state,
            loss: self.loss.to_le_bytes(),
            seq: self.seq,
            started_tick: self.started_tick,
            state,
        };
        for (k, p) in r.positions[..count].iter_mut().enumerate() {
            *p = [
                self.coordinate(3 * k),
                self.coordinate(3 * k + 1),
                self.coordinate(3 * k + 2),
            ];
        }
        Some((site, Report::Tools(r)))
    }

    /// The carried state: `Some(None)` for none (every `state_*` word 0), `Some(Some(_))` for a
    /// valid one (finite, a unit quaternion up to rounding, an object of a world of at most
    /// [`MAX_OBJECTS`], no memory named but of sites, planes and later objects that exist, kept
    /// to the bit), `None` for garbage.
    fn snapshot(&self) -> Option<Option<Snapshot>> {
        let words = || {
            self.state_body
                .iter()
                .chain(&self.state_env)
                .chain(&self.state_tools)
                .chain(&self.state_env_twist)
                .chain(&self.state_tool_twist)
                .chain(&self.state_pair_anchors)
                .chain(&self.state_pair_twist)
        };
        let valid_bits = ((1u64 << MAX_PLANES) - 1) | (((1u64 << MAX_SITES) - 1) << 8);
        match self.has_state {
            0 => (self.state_anchors == 0
                && self.state_memory == 0
                && self.state_object == 0
                && self.state_objects == 0
                && self.state_world_hash == 0
                && self.state_still == 0
                && words().all(|w| w.to_bits() == 0))
            .then_some(None),
            1 => {
                let objects = usize::try_from(self.state_objects)
                    .ok()
                    .filter(|n| (1..=MAX_OBJECTS).contains(n))?;
                let object = usize::try_from(self.state_object)
                    .ok()
                    .filter(|&k| k < objects)?;
                let later = objects - 1 - object;
                let pair_bits = ((1u64 << later) - 1) << 16 | ((1u64 << later) - 1) << 32;
                let still = u32::try_from(self.state_still).ok()?;
                if self.state_anchors & !valid_bits != 0
                    || self.state_memory & !(valid_bits | pair_bits) != 0
                    || !words().all(|w| w.is_finite())
                {
                    return None;
                }
                let b = &self.state_body;
                let q = Quaternion::new(b[3], b[4], b[5], b[6]);
                if (q.norm() - 1.0).abs() > 1e-6 {
                    return None;
                }
                let state = BodyState {
                    pos: Vec3::new(b[0], b[1], b[2]),
                    // The sender's bits: the adopting site must hash to the same.
                    rot: UnitQuaternion::new_unchecked(q),
                    vel: Vec3::new(b[7], b[8], b[9]),
                    ang_mom: Vec3::new(b[10], b[11], b[12]),
                };
                // A point of a clear bit is 0 (its bits: not even -0).
                let v = |w: &[f64], i: usize| Vec3::new(w[i], w[i + 1], w[i + 2]);
                let point = |w: &[f64], k: usize, set: bool| {
                    let p = v(w, 3 * k);
                    (set || p.iter().all(|x| x.to_bits() == 0)).then_some(set.then_some(p))
                };
                let pair = |w: &[f64], k: usize, set: bool| {
                    let (a, b) = (v(w, 6 * k), v(w, 6 * k + 3));
                    (set || a.iter().chain(b.iter()).all(|x| x.to_bits() == 0))
                        .then_some(set.then_some((a, b)))
                };
                let anchor = |k: usize| self.state_anchors & (1 << k) != 0;
                let memory = |k: usize| self.state_memory & (1 << k) != 0;
                let mut env = [None; MAX_PLANES];
                let mut env_twist = [None; MAX_PLANES];
                for p in 0..MAX_PLANES {
                    env[p] = point(&self.state_env, p, anchor(p))?;
                    env_twist[p] = pair(&self.state_env_twist, p, memory(p))?;
                }
                let mut contacts = [ToolContactState::default(); MAX_SITES];
                for (j, c) in contacts.iter_mut().enumerate() {
                    *c = ToolContactState::from_parts(
                        point(&self.state_tools, j, anchor(8 + j))?,
                        pair(&self.state_tool_twist, j, memory(8 + j))?,
                    );
                }
                let mut pairs = [PairContactState::default(); MAX_OBJECTS - 1];
                for (k, c) in pairs.iter_mut().enumerate() {
                    *c = PairContactState::from_parts(
                        pair(&self.state_pair_anchors, k, memory(16 + k))?,
                        pair(&self.state_pair_twist, k, memory(32 + k))?,
                    );
                }
                Some(Some(Snapshot {
                    tick: self.confirmed_tick as i64,
                    object,
                    objects,
                    world_hash: self.state_world_hash,
                    state,
                    env: EnvContactState::from_parts(env, env_twist),
                    contacts,
                    pairs,
                    still,
                }))
            }
            _ => None,
        }
    }

    /// The carried state's largest point (object centre, stick points) from the origin (m), its
    /// speed (m/s) and its angular momentum (kg·m²/s); zeros when none is carried. For
    /// plausibility checks.
    pub fn state_magnitudes(&self) -> (f64, f64, f64) {
        let norm3 = |w: &[f64]| (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        let extent = self
            .state_env
            .chunks(3)
            .chain(self.state_tools.chunks(3))
            .chain(self.state_pair_anchors.chunks(3))
            .map(norm3)
            .fold(norm3(&self.state_body[..3]), f64::max);
        (
            extent,
            norm3(&self.state_body[7..10]),
            norm3(&self.state_body[10..13]),
        )
    }

    /// The largest magnitude of a filled coordinate, in quanta (for plausibility checks).
    pub fn max_abs_quantized(&self) -> i64 {
        let used = 3 * (self.count as usize).min(WINDOW_TICKS);
        (0..used)
            .map(|c| i64::from(self.coordinate(c)).abs())
            .max()
            .unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use coop_model::contact::ContactForce;

    use super::*;

    /// A repair (the window from the first tick a peer lacks, sent every other report while it
    /// is asked for) passes the wire's frontier rule: the sender gives its frontier at the
    /// window's end, not past it. Before, every repair named the sender's newer frontier and was
    /// refused, so a station's gap of lost reports was never filled (paper task, 150 ms, loss
    /// 0.5, real stations: 20 fallbacks, 67 hash mismatches, copies 14.5 mm apart at the end;
    /// with repairs 0, 0 and 0).
    #[test]
    fn a_timewarp_repair_passes_the_frontier_rule() {
        use coop_model::contact::ContactForce;
        use coop_model::method::track::quantize;
        use coop_model::method::TimeWarp;
        use coop_model::method::{Consistency, WorldCopy, MAX_SITES};
        let sc = coop_model::scenario::Scenario::default();
        let world = sc.world();
        let mut copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
        let mut radii = [0.0; MAX_SITES];
        radii[..2].fill(0.005);
        let mut tw = TimeWarp::new(0, 2, 1e-3, sc.contact, radii, 600, &copy);
        let none = ContactForce::default();
        for k in 0..1000i64 {
            tw.own_tool(Vec3::new(-0.1, 0.0, 0.01));
            // Site 1 sends its positions up to now and lacks ours from tick 500 on.
            if k % 50 == 49 {
                let mut r = ToolReport {
                    first_tick: k - 49,
                    count: 50,
                    ..ToolReport::NONE
                };
                r.need[0] = 500;
                r.positions[..50].fill(quantize(Vec3::new(0.1, 0.0, 0.01)));
                tw.receive(&world, &mut copy, 1, &Report::Tools(r), k as f64 * 1e-3);
            }
            tw.physics_step(&world, &mut copy, &[none], 1e-3);
        }
        // Repairs alternate with the newest window.
        let repair = (0..2)
            .find_map(|_| {
                let mut repair = None;
                tw.report(&copy, &[none], 1.0, &mut |r| match r {
                    Report::Tools(r) if r.first_tick == 500 => repair = Some(r),
                    _ => {}
                });
                repair
            })
            .expect("a repair from tick 500");
        let end = repair.first_tick + repair.count as i64;
        assert_eq!(
            repair.confirmed_tick, end,
            "the frontier at the window's end"
        );
        assert_ne!(repair.confirmed_hash, 0, "and its hash");
        let track = ToolTrack::new(0, 1, 1, &repair);
        // (A received track's report carries its sequence number.)
        let numbered = ToolReport { seq: 1, ..repair };
        assert_eq!(track.report(), Some((0, Report::Tools(numbered))));
    }

    #[test]
    fn tool_tracks_round_trip_and_garbage_is_refused() {
        let mut r = ToolReport {
            first_tick: 1000,
            count: 3,
            positions: [[0; 3]; WINDOW_TICKS],
            confirmed_tick: 990,
            confirmed_hash: 0xdead_beef,
            need: [950, -1, -1, -1, -1, -1, -1, 7],
            ..ToolReport::NONE
        };
        r.positions[0] = [-4500, 0, 1000];
        r.positions[1] = [i32::MIN + 147_483_648, -1, 2_000_000_000];
        r.positions[2] = [7, -7, 0];
        r.loss = [3, 0, 0, 0, 0, 0, 0, 255];
        let t = ToolTrack::new(1, 5, 42, &r);
        assert_eq!(t.loss, 3 | 255 << 56, "site j's loss in byte j");
        assert_eq!(
            t.positions[0] as u32 as i32, -4500,
            "coordinate 0 in the low half"
        );
        assert_eq!((t.positions[0] >> 32) as u32 as i32, 0);
        assert_eq!(t.positions[1] as u32 as i32, 1000);
        assert_eq!(t.max_abs_quantized(), 2_000_000_000);
        assert_eq!(
            t.report(),
            Some((1, Report::Tools(ToolReport { seq: 5, ..r })))
        );
        assert_eq!(ToolTrack::from_words(&t.to_words()), t);
        let full = ToolReport {
            count: WINDOW_TICKS,
            positions: [[-3, 2, i32::MAX - 147_483_647]; WINDOW_TICKS],
            ..r
        };
        let t = ToolTrack::new(0, 1, 1, &full);
        assert_eq!(
            t.report(),
            Some((0, Report::Tools(ToolReport { seq: 1, ..full }))),
            "a full window"
        );
        let bad = |f: &dyn Fn(&mut ToolTrack)| {
            let mut b = ToolTrack::new(1, 5, 42, &r);
            f(&mut b);
            b.report()
        };
        assert!(bad(&|b| b.site = MAX_SITES as u64).is_none(), "site");
        assert!(
            bad(&|b| b.count = WINDOW_TICKS as u64 + 1).is_none(),
            "count"
        );
        assert!(bad(&|b| b.first_tick = MAX_TRACK_TICK).is_none(), "tick");
        assert!(bad(&|b| b.first_tick = u64::MAX).is_none(), "tick overflow");
        assert!(bad(&|b| b.need[3] = MAX_TRACK_TICK + 1).is_none(), "need");
        assert!(
            bad(&|b| b.confirmed_tick = 1004).is_none(),
            "frontier ahead"
        );
        assert!(
            bad(&|b| b.started_tick = MAX_TRACK_TICK + 1).is_none(),
            "start tick"
        );
        assert!(bad(&|b| b.need_state = 256).is_none(), "need_state");
        assert!(
            bad(&|b| b.positions[0] = u64::from(i32::MIN as u32)).is_none(),
            "range"
        );
        assert!(
            bad(&|b| b.positions[100] = 1).is_none(),
            "unused coordinate"
        );
        assert!(
            bad(&|b| b.count = 2).is_none(),
            "a dropped position is unused, not zero"
        );
        assert_eq!(ToolTrack::WORDS * 8, 5824);
    }

    /// What `timewarp` sends while asked for its confirmed state in a world of several objects
    /// (its track with the first object's state, and one report per other object) passes the
    /// track's own validation whole: every report lays out and reads back as it was made.
    #[test]
    fn a_world_s_confirmed_state_passes_the_track_rules_report_by_report() {
        use coop_model::method::track::quantize;
        use coop_model::method::{Consistency, TimeWarp};
        let mut sc = coop_model::scenario::Scenario::default();
        let mut second = sc.objects[0].clone();
        second.name = "second".into();
        second.start_m[0] += 0.1;
        sc.objects[0].name = "first".into();
        sc.objects.push(second);
        let world = sc.world();
        let mut copy = sc.start_copy();
        let mut radii = [0.0; MAX_SITES];
        radii[..2].fill(0.005);
        let mut tw = TimeWarp::new(0, 2, 1e-3, sc.contact, radii, 600, &copy);
        let none = [ContactForce::default(); 2];
        let mut sent = Vec::new();
        for k in 0..400i64 {
            tw.own_tool(Vec3::new(-0.2, 0.0, 0.01));
            if k % 50 == 49 {
                // Site 1 knows everything up to now and asks site 0 for its confirmed state.
                let mut r = ToolReport {
                    first_tick: k - 49,
                    count: 50,
                    need_state: 1,
                    started_tick: 5,
                    ..ToolReport::NONE
                };
                r.positions[..50].fill(quantize(Vec3::new(0.2, 0.0, 0.01)));
                tw.receive(&world, &mut copy, 1, &Report::Tools(r), k as f64 * 1e-3);
            }
            tw.physics_step(&world, &mut copy, &none, 1e-3);
            if k > 300 {
                tw.report(&copy, &none, k as f64 * 1e-3, &mut |r| sent.push(r));
            }
        }
        let states: Vec<_> = sent
            .iter()
            .filter_map(|r| match r {
                Report::Tools(t) => t.state,
                _ => None,
            })
            .collect();
        assert!(
            states.iter().any(|s| s.object == 1) && states.iter().any(|s| s.object == 0),
            "both objects' states sent: {states:?}"
        );
        for (n, r) in sent.into_iter().enumerate() {
            let Report::Tools(t) = r else {
                panic!("timewarp sends tracks only")
            };
            let laid = ToolTrack::new(0, n as u64 + 1, 1, &t);
            let t = ToolReport {
                seq: n as u64 + 1,
                ..t
            };
            assert_eq!(laid.report(), Some((0, Report::Tools(t))), "report {n}");
        }
    }

    /// A confirmed state of one object of a world of several travels with every friction memory
    /// it holds (the table's and the fingertips' stick points and rotational references, its
    /// contacts with the later objects, its sleep count) to the bit; a memory named for an
    /// object, plane or site the state cannot have is refused.
    #[test]
    fn a_world_s_object_travels_with_all_its_memory() {
        let v = |x: f64| Vec3::new(x, -2.0 * x, 0.5 * x);
        let mut env = [None; MAX_PLANES];
        let mut env_twist = [None; MAX_PLANES];
        env[0] = Some(v(0.01));
        env_twist[0] = Some((v(0.6).normalize(), v(-0.3).normalize()));
        env_twist[4] = Some((Vec3::x(), Vec3::y()));
        let mut contacts = [ToolContactState::default(); MAX_SITES];
        contacts[1] = ToolContactState::from_parts(Some(v(0.002)), Some((Vec3::z(), v(1.0))));
        contacts[7] = ToolContactState::from_parts(Some(v(-0.003)), None);
        let mut pairs = [PairContactState::default(); MAX_OBJECTS - 1];
        pairs[0] =
            PairContactState::from_parts(Some((v(0.004), v(-0.005))), Some((Vec3::x(), Vec3::z())));
        let snap = Snapshot {
            tick: 990,
            object: 1,
            objects: 3,
            world_hash: 0x1234_5678_9abc_def0,
            state: BodyState {
                rot: UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1),
                vel: v(0.7),
                ang_mom: v(1e-4),
                ..BodyState::at_rest(v(0.05))
            },
            env: EnvContactState::from_parts(env, env_twist),
            contacts,
            pairs,
            still: 17,
        };
        let r = ToolReport {
            first_tick: 1000,
            count: 0,
            confirmed_tick: 990,
            state: Some(snap),
            ..ToolReport::NONE
        };
        let t = ToolTrack::new(1, 5, 42, &r);
        assert_eq!(
            t.report(),
            Some((1, Report::Tools(ToolReport { seq: 5, ..r })))
        );
        let bad = |f: &dyn Fn(&mut ToolTrack)| {
            let mut b = t;
            f(&mut b);
            b.report()
        };
        assert!(
            bad(&|b| b.state_object = 3).is_none(),
            "an object past the world"
        );
        assert!(
            bad(&|b| b.state_objects = 17).is_none(),
            "a world past the largest"
        );
        assert!(bad(&|b| b.state_objects = 0).is_none(), "a world of none");
        // Object 1 of 3 has one later object: pair 1 is not one.
        assert!(
            bad(&|b| b.state_memory |= 1 << 17).is_none(),
            "a pair past the world"
        );
        assert!(
            bad(&|b| b.state_memory |= 1 << 6).is_none(),
            "a plane past the largest"
        );
        assert!(
            bad(&|b| b.state_pair_anchors[6] = 1.0).is_none(),
            "a point of a clear bit"
        );
        assert!(bad(&|b| b.state_tool_twist[0] = f64::NAN).is_none(), "NaN");
        assert!(
            bad(&|b| b.state_still = u64::MAX).is_none(),
            "a sleep count"
        );
        let none = ToolTrack::new(1, 5, 42, &ToolReport::NONE);
        assert!(none.report().is_some());
        let mut b = none;
        b.state_world_hash = 1;
        assert!(b.report().is_none(), "no state but a world hash");
    }
}
