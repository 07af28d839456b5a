//! The messages on a station's rings, as plain old data (H5): servo → physics [`ToolSample`],
//! physics → servo [`ObjectSample`], physics ⇄ network [`SiteReport`] and [`ToolTrack`], physics → recorder
//! [`TraceRecord`]. Each is declared once with `pod_message!`, which derives from the one field
//! list its words (`WORDS`, `to_words`, `from_words`) and its `LAYOUT`: the wire format
//! (`coop_transport::wire`) and the control block's resume seqlock are built on those, never on a
//! second, hand-written field order. Each has a stable `TYPE_NAME` and a compile-time size check;
//! conversions to the model's types validate what they read (finite numbers, unit quaternion, known
//! site), because a ring's bytes are only as good as its writer.
#![allow(unsafe_code)] // the five `unsafe impl ShmPod` below, each with its SAFETY argument

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::{
    ContactForce, EnvContactState, PairContactState, ToolContactState, MAX_PLANES,
};
use coop_model::method::track::CoupledReport;
use coop_model::method::track::{Snapshot, ToolReport, WINDOW_TICKS};
use coop_model::method::{Report, MAX_SITES};
use coop_model::world::MAX_OBJECTS;
use nalgebra::{Quaternion, UnitQuaternion};

use crate::shm::ShmPod;

/// A field of a `pod_message!` struct: a `u64`, an `f64` or an array of one of them, as 8-byte
/// words. The words are the field's bits (`f64::to_bits`), so a round trip is exact, NaN included.
pub trait WordField: Copy {
    /// `"u64"` or `"f64"`.
    const KIND: &'static str;
    /// How many words.
    const COUNT: usize;
    /// Writes its words into `out` (exactly [`WordField::COUNT`] long).
    fn put(&self, out: &mut [u64]);
    /// Reads it back from `w` (exactly [`WordField::COUNT`] long).
    fn get(w: &[u64]) -> Self;
}
impl WordField for u64 {
    const KIND: &'static str = "u64";
    const COUNT: usize = 1;
    fn put(&self, out: &mut [u64]) {
        out[0] = *self;
    }
    fn get(w: &[u64]) -> Self {
        w[0]
    }
}
impl WordField for f64 {
    const KIND: &'static str = "f64";
    const COUNT: usize = 1;
    fn put(&self, out: &mut [u64]) {
        out[0] = self.to_bits();
    }
    fn get(w: &[u64]) -> Self {
        f64::from_bits(w[0])
    }
}
impl<const N: usize> WordField for [u64; N] {
    const KIND: &'static str = "u64";
    const COUNT: usize = N;
    fn put(&self, out: &mut [u64]) {
        out.copy_from_slice(self);
    }
    fn get(w: &[u64]) -> Self {
        core::array::from_fn(|i| w[i])
    }
}
impl<const N: usize> WordField for [f64; N] {
    const KIND: &'static str = "f64";
    const COUNT: usize = N;
    fn put(&self, out: &mut [u64]) {
        for (o, v) in out.iter_mut().zip(self) {
            *o = v.to_bits();
        }
    }
    fn get(w: &[u64]) -> Self {
        core::array::from_fn(|i| f64::from_bits(w[i]))
    }
}

/// A message's field order: (field name, `"u64"` or `"f64"`, number of words), in declaration order.
pub type Layout = &'static [(&'static str, &'static str, usize)];

/// A layout as text, one field a line: `name kind count` (what the wire pin hashes; see
/// `coop_transport::wire`).
pub fn layout_text(layout: Layout) -> String {
    layout
        .iter()
        .map(|(name, kind, count)| format!("{name} {kind} {count}\n"))
        .collect()
}

/// Declares a ring message once: a `#[repr(C)]` struct of [`WordField`] fields, and from that one
/// field list its `WORDS` (size in 8-byte words), `to_words`/`from_words` (the fields' words in
/// declaration order) and `LAYOUT` (the order, for pinning it to `docs/wire.md`). Every other
/// representation of a message's bytes (the wire, the resume seqlock) is derived from these, so
/// changing the struct changes them all, and the wire's pin test notices.
///
/// It also checks at compile time that the words cover the struct exactly (no padding). The
/// `unsafe impl ShmPod` stays with each struct, with its own SAFETY argument.
macro_rules! pod_message {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            $( $(#[$fmeta:meta])* pub $field:ident : $t:ty ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[repr(C)]
        pub struct $name {
            $( $(#[$fmeta])* pub $field: $t, )*
        }

        impl $name {
            /// Its size in 8-byte words.
            pub const WORDS: usize = 0 $( + <$t as WordField>::COUNT )*;
            /// Its fields in declaration order: (name, `"u64"`/`"f64"`, words).
            pub const LAYOUT: Layout = &[ $( (stringify!($field), <$t as WordField>::KIND, <$t as WordField>::COUNT) ),* ];

            /// Its words: every field's, in declaration order.
            pub fn to_words(&self) -> [u64; Self::WORDS] {
                let mut out = [0u64; Self::WORDS];
                let mut at = 0;
                $(
                    let n = <$t as WordField>::COUNT;
                    WordField::put(&self.$field, &mut out[at..at + n]);
                    at += n;
                )*
                debug_assert_eq!(at, Self::WORDS);
                out
            }
            /// The inverse of `to_words`.
            pub fn from_words(w: &[u64; Self::WORDS]) -> Self {
                let mut at = 0;
                $(
                    let n = <$t as WordField>::COUNT;
                    let $field = <$t as WordField>::get(&w[at..at + n]);
                    at += n;
                )*
                debug_assert_eq!(at, Self::WORDS);
                Self { $( $field, )* }
            }
        }

        const _: () = assert!(
            core::mem::size_of::<$name>() == 8 * $name::WORDS
                && core::mem::align_of::<$name>() == 8,
            "a pod_message is its words: no padding"
        );
    };
}

fn v3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}
fn a3(v: Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}
fn finite(xs: &[f64]) -> bool {
    xs.iter().all(|x| x.is_finite())
}

pod_message! {
    /// Servo → physics, every servo tick: the tool and its contact with each object of the world.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct ToolSample {
        /// When, ns on CLOCK_MONOTONIC.
        pub t_ns: u64,
        /// Servo tick counter.
        pub seq: u64,
        /// Tool position, m.
        pub tool_pos: [f64; 3],
        /// Tool velocity, m/s.
        pub tool_vel: [f64; 3],
        /// Desired force at the hand F_h, N.
        pub f_desired: [f64; 3],
        /// Measured force F_m, N.
        pub f_measured: [f64; 3],
        /// Commanded handle force after limits, N.
        pub f_command: [f64; 3],
        /// How many objects the world has (the contacts past it are all 0).
        pub objects: u64,
        /// Bit `k`: the tool touches object `k`.
        pub touching: u64,
        /// Per object `k`, at `3k..3k+3`: the contact force on it, N.
        pub force: [f64; 3 * MAX_OBJECTS],
        /// Per object, where that force acts, m.
        pub point: [f64; 3 * MAX_OBJECTS],
        /// Per object, the penetration, m.
        pub depth: [f64; MAX_OBJECTS],
        /// Per object, a fingertip pad's torque on it besides the force's moment, N·m.
        pub torque: [f64; 3 * MAX_OBJECTS],
    }
}
const _: () = assert!(core::mem::size_of::<ToolSample>() == 1432);
// SAFETY: repr(C), only u64 and f64 fields and arrays of them (1432 bytes, no padding); every bit
// pattern is valid.
unsafe impl ShmPod for ToolSample {
    const TYPE_NAME: &'static str = "coop.ToolSample.v2";
}

impl Default for ToolSample {
    fn default() -> Self {
        Self {
            t_ns: 0,
            seq: 0,
            tool_pos: [0.0; 3],
            tool_vel: [0.0; 3],
            f_desired: [0.0; 3],
            f_measured: [0.0; 3],
            f_command: [0.0; 3],
            objects: 0,
            touching: 0,
            force: [0.0; 3 * MAX_OBJECTS],
            point: [0.0; 3 * MAX_OBJECTS],
            depth: [0.0; MAX_OBJECTS],
            torque: [0.0; 3 * MAX_OBJECTS],
        }
    }
}

impl ToolSample {
    /// Lays out the tool's contact with each of the world's objects (`contacts`, at most
    /// [`MAX_OBJECTS`]); the rest of the sample is the caller's.
    pub fn set_contacts(&mut self, contacts: &[ContactForce]) {
        let n = contacts.len().min(MAX_OBJECTS);
        self.objects = n as u64;
        self.touching = 0;
        for (k, c) in contacts[..n].iter().enumerate() {
            self.touching |= u64::from(c.touching) << k;
            self.force[3 * k..3 * k + 3].copy_from_slice(c.force.as_slice());
            self.point[3 * k..3 * k + 3].copy_from_slice(c.point.as_slice());
            self.depth[k] = c.depth;
            self.torque[3 * k..3 * k + 3].copy_from_slice(c.torque.as_slice());
        }
    }

    /// The contact with each object (the first [`ToolSample::objects`] filled), or `None` if the
    /// count exceeds [`MAX_OBJECTS`], a touching bit names no object, or a number is not finite.
    pub fn contacts(&self) -> Option<[ContactForce; MAX_OBJECTS]> {
        let n = usize::try_from(self.objects)
            .ok()
            .filter(|&n| n <= MAX_OBJECTS)?;
        (self.touching >> n == 0).then_some(())?;
        (finite(&self.force) && finite(&self.point) && finite(&self.depth) && finite(&self.torque))
            .then_some(())?;
        let v = |w: &[f64], k: usize| Vec3::new(w[3 * k], w[3 * k + 1], w[3 * k + 2]);
        let mut out = [ContactForce::default(); MAX_OBJECTS];
        for (k, c) in out[..n].iter_mut().enumerate() {
            *c = ContactForce {
                force: v(&self.force, k),
                point: v(&self.point, k),
                depth: self.depth[k],
                touching: self.touching & (1 << k) != 0,
                slipping: false,
                torque: v(&self.torque, k),
            };
        }
        Some(out)
    }

    /// Whether the tool touches object `k`.
    pub fn touches(&self, k: usize) -> bool {
        k < 64 && self.touching & (1 << k) != 0
    }
}

pod_message! {
    /// Physics → servo, every physics step: the object state this site believes.
    #[derive(Debug, Clone, Copy, PartialEq, Default)]
    pub struct ObjectSample {
        /// Time of the state, ns on CLOCK_MONOTONIC.
        pub t_ns: u64,
        /// Physics step counter.
        pub seq: u64,
        /// Which object of the world ([`coop_model::world::World::bodies`] order); physics sends
        /// every object's each step, with the same `t_ns` and `seq`.
        pub object: u64,
        /// Centre of mass, m.
        pub pos: [f64; 3],
        /// Orientation quaternion (w, x, y, z).
        pub rot: [f64; 4],
        /// Velocity, m/s.
        pub vel: [f64; 3],
        /// Angular momentum, kg·m²/s.
        pub ang_mom: [f64; 3],
        /// Adoptions so far (the servo bounds the force step when it changes).
        pub adoptions: u64,
        /// Time of the newest tool sample this state was computed with, ns (0: none yet): the servo
        /// measures the servo → physics → servo round trip from it.
        pub tool_t_ns: u64,
    }
}
const _: () = assert!(core::mem::size_of::<ObjectSample>() == 144);
// SAFETY: repr(C), only u64 and f64 fields (144 bytes, no padding); every bit pattern is valid.
unsafe impl ShmPod for ObjectSample {
    const TYPE_NAME: &'static str = "coop.ObjectSample.v3";
}

fn state_fields(s: &BodyState) -> ([f64; 3], [f64; 4], [f64; 3], [f64; 3]) {
    let q = s.rot.quaternion();
    (a3(s.pos), [q.w, q.i, q.j, q.k], a3(s.vel), a3(s.ang_mom))
}

fn body_state(pos: [f64; 3], rot: [f64; 4], vel: [f64; 3], ang_mom: [f64; 3]) -> Option<BodyState> {
    if !(finite(&pos) && finite(&rot) && finite(&vel) && finite(&ang_mom)) {
        return None;
    }
    let q = Quaternion::new(rot[0], rot[1], rot[2], rot[3]);
    // A unit quaternion up to rounding; anything else is a corrupt or hostile message.
    if (q.norm() - 1.0).abs() > 1e-6 {
        return None;
    }
    Some(BodyState {
        pos: v3(pos),
        rot: UnitQuaternion::new_normalize(q),
        vel: v3(vel),
        ang_mom: v3(ang_mom),
    })
}

impl ObjectSample {
    /// Object `object`'s state `s`, computed with the tool sample of time `tool_t_ns`.
    pub fn new(
        t_ns: u64,
        seq: u64,
        object: usize,
        s: &BodyState,
        adoptions: u64,
        tool_t_ns: u64,
    ) -> Self {
        let (pos, rot, vel, ang_mom) = state_fields(s);
        Self {
            t_ns,
            seq,
            object: object as u64,
            pos,
            rot,
            vel,
            ang_mom,
            adoptions,
            tool_t_ns,
        }
    }
    /// The state, or `None` if not finite or not a unit quaternion.
    pub fn state(&self) -> Option<BodyState> {
        body_state(self.pos, self.rot, self.vel, self.ang_mom)
    }
    /// Which object it is, or `None` past [`MAX_OBJECTS`].
    pub fn object(&self) -> Option<usize> {
        usize::try_from(self.object)
            .ok()
            .filter(|&k| k < MAX_OBJECTS)
    }
}

pod_message! {
    /// What a site reports to the others (physics → network), and what arrives from them (network →
    /// physics): the model's [`Report`] in a fixed layout, with the sender's site index.
    #[derive(Debug, Clone, Copy, PartialEq, Default)]
    pub struct SiteReport {
        /// 1 = a state (paper), 2 = a force (naive), 4 = a `coupled` state ([`KIND_COUPLED`]).
        pub kind: u64,
        /// Sender's time, ns.
        pub t_ns: u64,
        /// Sender's report counter.
        pub seq: u64,
        /// Sender's site index.
        pub site: u64,
        /// Which object of the world it is about ([`coop_model::world::World::bodies`] order).
        pub object: u64,
        /// State: centre of mass, m.
        pub pos: [f64; 3],
        /// State: orientation (w, x, y, z).
        pub rot: [f64; 4],
        /// State: velocity, m/s.
        pub vel: [f64; 3],
        /// State: angular momentum.
        pub ang_mom: [f64; 3],
        /// State: acceleration to dead-reckon with, m/s².
        pub accel: [f64; 3],
        /// State: per site, time its impulses are included up to, s (sender's clock). Force:
        /// word 0, the work the sender's user has given its copy, J.
        pub included: [f64; MAX_SITES],
        /// Force: force on the object, N.
        pub force: [f64; 3],
        /// Force: where it acts, m.
        pub point: [f64; 3],
        /// Force: penetration, m.
        pub depth: f64,
        /// Force: 1 when touching.
        pub touching: u64,
        /// Force: a fingertip pad's torque besides the force's moment, N·m.
        pub torque: [f64; 3],
    }
}
const _: () = assert!(core::mem::size_of::<SiteReport>() == 320);
// SAFETY: repr(C), only u64 and f64 fields and arrays of them (320 bytes, no padding); every bit
// pattern is valid.
unsafe impl ShmPod for SiteReport {
    const TYPE_NAME: &'static str = "coop.SiteReport.v2";
}

// ---- tool tracks (timewarp / coupled: the tools on the wire) ----

/// Words holding a [`ToolTrack`]'s positions: two quantized coordinates (i32) per word.
pub const TRACK_POSITION_WORDS: usize = WINDOW_TICKS * 3 / 2;
/// The largest tick a track may name: 2⁴⁰ ticks are 35 years at 1 kHz (a larger one is garbage).
pub const MAX_TRACK_TICK: u64 = 1 << 40;
/// The largest magnitude of a quantized coordinate ([`coop_model::method::track::quantize`]'s clamp).
pub const MAX_QUANTIZED: i64 = 2_000_000_000;

pod_message! {
    /// What a `timewarp` site reports besides (instead of) a state: its own tool's quantized
    /// positions at the last ticks of the session's tick grid, and its confirmed frontier with the
    /// hash of its state there (the model's [`ToolReport`] in a fixed layout). Physics → network
    /// (own), network → physics (remote). 5 816 bytes, copied, never boxed.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct ToolTrack {
        /// Sender's time of the report, ns (CLOCK_MONOTONIC of the sender).
        pub t_ns: u64,
        /// Sender's tool-track counter (its own sequence, apart from its states').
        pub seq: u64,
        /// Sender's site index.
        pub site: u64,
        /// The tick of the first position.
        pub first_tick: u64,
        /// How many positions are filled (≤ [`WINDOW_TICKS`]).
        pub count: u64,
        /// The sender's confirmed frontier: the first tick whose inputs it does not all know.
        pub confirmed_tick: u64,
        /// FNV-1a 64 of the sender's state at the start of `confirmed_tick` (0: none kept).
        pub confirmed_hash: u64,
        /// Per site `j`, 1 + the first tick of `j`'s positions the sender lacks though it holds
        /// later ones (reports lost for longer than the window), for `j` to send again; 0: none.
        pub need: [u64; MAX_SITES],
        /// Bit `j`: the sender's confirmed state differs from site `j`'s (`j` before the sender),
        /// and it asks `j` for its state (the `state_*` words); bits 8 and up are 0.
        pub need_state: u64,
        /// Byte `j` (little end first): the share of site `j`'s tracks the sender found lost
        /// lately, in 255ths.
        pub loss: u64,
        /// The session tick at which the sender's physics process started (0: from the session's
        /// start); sites are ordered by it, then by index, and adopt the state of one before them.
        pub started_tick: u64,
        /// 1: the `state_*` words hold the sender's state at the start of `confirmed_tick`, sent
        /// while a site asks for it; 0: they are all 0.
        pub has_state: u64,
        /// The object: centre of mass (m), orientation (w, x, y, z), velocity (m/s), angular
        /// momentum (kg·m²/s).
        pub state_body: [f64; 13],
        /// Bit `p` (`p` < 6): plane `p`'s friction stick point is in `state_env`; bit 8 + `j`:
        /// site `j`'s tool's is in `state_tools`. The points of clear bits are 0.
        pub state_anchors: u64,
        /// Per plane, its friction stick point, world, m.
        pub state_env: [f64; 3 * MAX_PLANES],
        /// Per site, its tool's friction stick point on the object, body coordinates, m.
        pub state_tools: [f64; 3 * MAX_SITES],
        /// Which object of the world the state is (a world's other objects come in tracks of
        /// their own, with no positions, at the same tick).
        pub state_object: u64,
        /// How many objects the world has (0 when no state is carried).
        pub state_objects: u64,
        /// FNV-1a 64 of the whole world's state at `confirmed_tick`.
        pub state_world_hash: u64,
        /// The steps in a row the object has been still.
        pub state_still: u64,
        /// Bit `p` (`p` < 6): plane `p`'s rotational friction references are in
        /// `state_env_twist`; bit 8 + `j`: site `j`'s pad's are in `state_tool_twist`; bit 16 +
        /// `k`: the contact with object `state_object + 1 + k` has stick points in
        /// `state_pair_anchors`; bit 32 + `k`: and rotational references in `state_pair_twist`.
        pub state_memory: u64,
        /// Per plane, its rotational friction reference in the world and on the body.
        pub state_env_twist: [f64; 6 * MAX_PLANES],
        /// Per site, its pad's reference in the world and on the body.
        pub state_tool_twist: [f64; 6 * MAX_SITES],
        /// Per later object, the stick points on this object and on it, body coordinates, m.
        pub state_pair_anchors: [f64; 6 * (MAX_OBJECTS - 1)],
        /// Per later object, the rotational references on this object and on it.
        pub state_pair_twist: [f64; 6 * (MAX_OBJECTS - 1)],
        /// Positions in quanta, tick `first_tick + k` at coordinates `3k..3k+3`; coordinate `c`
        /// is the i32 in bits `32 (c % 2) ..` of word `c / 2` (little end first); unused ones 0.
        pub positions: [u64; TRACK_POSITION_WORDS],
    }
}
const _: () = assert!(core::mem::size_of::<ToolTrack>() == 5824);
// SAFETY: repr(C), only u64 and f64 fields and arrays of them (5824 bytes, no padding); every bit
// pattern is valid.
unsafe impl ShmPod for ToolTrack {
    const TYPE_NAME: &'static str = "coop.ToolTrack.v5";
}

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

pod_message! {
    /// Physics → network (the recorder), at the scenario's sample rate and at every adoption: what this
    /// site believed and displayed, for the station's recording. Nothing on the real-time side reads it.
    #[derive(Debug, Clone, Copy, PartialEq, Default)]
    pub struct TraceRecord {
        /// [`TraceRecord::SAMPLE`] or [`TraceRecord::ADOPTION`].
        pub kind: u64,
        /// When, ns on CLOCK_MONOTONIC.
        pub t_ns: u64,
        /// Which object of the world the object fields are (a sample of a world of several is one
        /// record per object, the same tool fields in each; an adoption names the first).
        pub object: u64,
        /// Object position as this site believes it, m.
        pub pos: [f64; 3],
        /// Object orientation (w, x, y, z).
        pub rot: [f64; 4],
        /// Object velocity, m/s.
        pub vel: [f64; 3],
        /// Tool position (from the newest tool sample), m.
        pub tool_pos: [f64; 3],
        /// Desired force at the hand F_h, N.
        pub f_desired: [f64; 3],
        /// Measured force F_m, N.
        pub f_measured: [f64; 3],
        /// Users' contact force acting on this copy (own, plus the others' in naive), N.
        pub f_object: [f64; 3],
        /// 1 when the own user touches this object.
        pub touching: u64,
        /// Adoptions so far.
        pub adoptions: u64,
        /// Adoption: the sender's site index.
        pub from: u64,
        /// Adoption: position before minus after, m.
        pub jump_m: f64,
        /// Adoption: how far the received state was dead-reckoned, s.
        pub age_s: f64,
    }
}
const _: () = assert!(core::mem::size_of::<TraceRecord>() == 240);
// SAFETY: repr(C), only u64 and f64 fields (240 bytes, no padding); every bit pattern is valid.
unsafe impl ShmPod for TraceRecord {
    const TYPE_NAME: &'static str = "coop.TraceRecord.v2";
}

impl TraceRecord {
    /// A periodic sample.
    pub const SAMPLE: u64 = 1;
    /// An adoption.
    pub const ADOPTION: u64 = 2;

    /// A record of `kind` at `t_ns` of object `object`'s state `s`, with the newest tool sample
    /// `tool`.
    pub fn new(
        kind: u64,
        t_ns: u64,
        object: usize,
        s: &BodyState,
        tool: &ToolSample,
        f_object: Vec3,
    ) -> Self {
        let (pos, rot, vel, _) = state_fields(s);
        Self {
            kind,
            t_ns,
            object: object as u64,
            pos,
            rot,
            vel,
            tool_pos: tool.tool_pos,
            f_desired: tool.f_desired,
            f_measured: tool.f_measured,
            f_object: a3(f_object),
            touching: u64::from(tool.touches(object)),
            ..Self::default()
        }
    }
}

const KIND_STATE: u64 = 1;
/// A `naive` site's contact force: the force fields, and `included[0]` the positive work its user
/// has done on its own copy so far, J (finite, >= 0); the state fields and the other `included` 0.
const KIND_FORCE: u64 = 2;
/// A `coupled` site's copy and its user's contact times (its tools go as a [`ToolTrack`]); the
/// state fields are a state's, `included[0]` is when its user's current contact began and
/// `included[1]` when its user last touched, s on its clock (−1: not touching, never), the other
/// `included` 0. (3 is [`SiteReport::KIND_LOST`], never on the wire.)
pub const KIND_COUPLED: u64 = 4;

fn zero(xs: &[f64]) -> bool {
    xs.iter().all(|&x| x == 0.0)
}

impl SiteReport {
    /// The kind the network process hands physics, never sent on the wire: site `site` is lost
    /// (silent past the loss limit) as of `t_ns`.
    pub const KIND_LOST: u64 = 3;

    /// A notice to physics that `site` is lost as of `t_ns` (see [`SiteReport::KIND_LOST`]).
    pub fn lost(site: usize, t_ns: u64) -> Self {
        Self {
            kind: Self::KIND_LOST,
            t_ns,
            site: site as u64,
            ..Self::default()
        }
    }

    /// Lays out `report` from `site` at `seq`; times in seconds become ns.
    pub fn new(site: usize, seq: u64, report: &Report) -> Self {
        let ns = |s: f64| (s.max(0.0) * 1e9).round() as u64;
        match *report {
            Report::State {
                object,
                t_s,
                state,
                accel,
                included,
            } => Self {
                object: object as u64,
                ..Self::state(KIND_STATE, site, seq, ns(t_s), &state, accel, included)
            },
            Report::Force {
                object,
                t_s,
                force,
                given_j,
            } => {
                let mut included = [0.0; MAX_SITES];
                included[0] = given_j;
                Self {
                    kind: KIND_FORCE,
                    t_ns: ns(t_s),
                    seq,
                    site: site as u64,
                    object: object as u64,
                    force: a3(force.force),
                    point: a3(force.point),
                    depth: force.depth,
                    touching: u64::from(force.touching),
                    torque: a3(force.torque),
                    included,
                    ..Self::default()
                }
            }
            Report::Coupled(ref c) => {
                let time = |t: f64| if t.is_finite() { t.max(0.0) } else { -1.0 };
                let mut included = [0.0; MAX_SITES];
                included[0] = time(c.touch_since_s);
                included[1] = time(c.last_touch_s);
                Self {
                    object: c.object as u64,
                    ..Self::state(
                        KIND_COUPLED,
                        site,
                        seq,
                        ns(c.t_s),
                        &c.state,
                        c.accel,
                        included,
                    )
                }
            }
            // Tools go as a `ToolTrack` (their own ring and key): kind 0, which every receiver
            // refuses.
            Report::Tools(_) => Self {
                seq,
                site: site as u64,
                ..Self::default()
            },
        }
    }

    /// A state of `kind` (1 or 4) laid out; the force fields zero.
    fn state(
        kind: u64,
        site: usize,
        seq: u64,
        t_ns: u64,
        state: &BodyState,
        accel: Vec3,
        included: [f64; MAX_SITES],
    ) -> Self {
        let (pos, rot, vel, ang_mom) = state_fields(state);
        Self {
            kind,
            t_ns,
            seq,
            site: site as u64,
            pos,
            rot,
            vel,
            ang_mom,
            accel: a3(accel),
            included,
            ..Self::default()
        }
    }

    /// The state of a state kind (1 or 4): `None` unless it is valid, its acceleration finite and
    /// the force fields, which are not a state's, zero as the sender lays them out.
    fn state_part(&self) -> Option<BodyState> {
        let state = body_state(self.pos, self.rot, self.vel, self.ang_mom)?;
        (finite(&self.accel)
            && zero(&self.force)
            && zero(&self.point)
            && zero(&self.torque)
            && self.depth == 0.0
            && self.touching == 0)
            .then_some(state)
    }

    /// The sender and the model's report, or `None` for an unknown kind, a site index out of range,
    /// a non-finite number or a non-unit quaternion.
    ///
    /// This is the one validation of a report; nothing else re-checks one. It runs at the two places
    /// a report crosses into code that trusts it:
    /// - `coop_transport::wire::decode`, where a report enters from the network: a bad one is
    ///   refused there (counted as `contents`) and never reaches the remote ring;
    /// - physics, as its ring → model conversion. Physics has to convert anyway (the ring carries
    ///   this plain-old-data layout, not the model's [`Report`]), and it converts with the checking
    ///   function rather than trusting the ring: a ring is shared memory that any process opening
    ///   the segment can write, so the network's check does not cover it (refusals there count as
    ///   `physics.rejected`). It costs a few `is_finite` and one quaternion norm per report.
    pub fn report(&self) -> Option<(usize, Report)> {
        let site = usize::try_from(self.site).ok().filter(|&s| s < MAX_SITES)?;
        let object = usize::try_from(self.object)
            .ok()
            .filter(|&k| k < MAX_OBJECTS)?;
        let t_s = self.t_ns as f64 * 1e-9;
        match self.kind {
            KIND_STATE => {
                let state = self.state_part()?;
                finite(&self.included).then_some(())?;
                Some((
                    site,
                    Report::State {
                        object,
                        t_s,
                        state,
                        accel: v3(self.accel),
                        included: self.included,
                    },
                ))
            }
            KIND_COUPLED => {
                let state = self.state_part()?;
                let time = |t: f64| (t == -1.0 || (0.0..=1e12).contains(&t)).then_some(t);
                let (since, last) = (time(self.included[0])?, time(self.included[1])?);
                zero(&self.included[2..]).then_some(())?;
                Some((
                    site,
                    Report::Coupled(CoupledReport {
                        tools: ToolReport::NONE,
                        object,
                        t_s,
                        state,
                        accel: v3(self.accel),
                        touch_since_s: if since < 0.0 { f64::INFINITY } else { since },
                        last_touch_s: if last < 0.0 { f64::NEG_INFINITY } else { last },
                    }),
                ))
            }
            KIND_FORCE => {
                (finite(&self.force)
                    && finite(&self.point)
                    && finite(&self.torque)
                    && self.depth.is_finite())
                .then_some(())?;
                // The state fields are not a force's: zero, as the sender lays them out; but
                // `included[0]`, the work the sender's user has given its copy (finite, >= 0).
                let given_j = self.included[0];
                (zero(&self.pos)
                    && zero(&self.rot)
                    && zero(&self.vel)
                    && zero(&self.ang_mom)
                    && zero(&self.accel)
                    && zero(&self.included[1..])
                    && given_j.is_finite()
                    && given_j >= 0.0
                    && self.touching <= 1)
                    .then_some(())?;
                let force = ContactForce {
                    force: v3(self.force),
                    point: v3(self.point),
                    depth: self.depth,
                    touching: self.touching != 0,
                    slipping: false,
                    torque: v3(self.torque),
                };
                Some((
                    site,
                    Report::Force {
                        object,
                        t_s,
                        force,
                        given_j,
                    },
                ))
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_round_trip_and_garbage_is_refused() {
        let mut included = [-1.0; MAX_SITES];
        included[1] = 2.5;
        let state = BodyState {
            vel: Vec3::new(0.1, 0.2, 0.3),
            rot: UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3),
            ..BodyState::at_rest(Vec3::new(1.0, 2.0, 3.0))
        };
        let r = Report::State {
            object: 0,
            t_s: 3.0,
            state,
            accel: Vec3::new(0.0, 0.0, -3.27),
            included,
        };
        let back = SiteReport::new(1, 7, &r).report().expect("valid");
        assert_eq!(back.0, 1);
        match back.1 {
            Report::State {
                t_s,
                state: s,
                included: inc,
                ..
            } => {
                assert!(
                    (t_s - 3.0).abs() < 1e-12
                        && (s.pos - state.pos).norm() < 1e-15
                        && inc == included
                );
                assert!(s.rot.angle_to(&state.rot) < 1e-12);
            }
            Report::Force { .. } | Report::Tools(_) | Report::Coupled(_) => panic!("kind changed"),
        }
        let mut bad = SiteReport::new(1, 7, &r);
        bad.vel[0] = f64::NAN;
        assert!(bad.report().is_none(), "NaN");
        let mut bad = SiteReport::new(1, 7, &r);
        bad.rot = [2.0, 0.0, 0.0, 0.0];
        assert!(bad.report().is_none(), "not a unit quaternion");
        let mut bad = SiteReport::new(1, 7, &r);
        bad.site = 99;
        assert!(bad.report().is_none(), "unknown site");
        let mut bad = SiteReport::new(1, 7, &r);
        bad.kind = 9;
        assert!(bad.report().is_none(), "unknown kind");
        let mut bad = SiteReport::new(1, 7, &r);
        bad.object = MAX_OBJECTS as u64;
        assert!(bad.report().is_none(), "an object past the largest world");
        // A `coupled` state: its user's contact times survive, "not touching" and "never" too.
        for (since, last) in [(1.25, 1.5), (f64::INFINITY, f64::NEG_INFINITY)] {
            let c = Report::Coupled(CoupledReport {
                tools: ToolReport::NONE,
                object: 3,
                t_s: 3.0,
                state,
                accel: Vec3::new(0.0, 0.0, -3.27),
                touch_since_s: since,
                last_touch_s: last,
            });
            let laid = SiteReport::new(1, 8, &c);
            assert_eq!(laid.kind, KIND_COUPLED);
            assert_eq!(laid.report(), Some((1, c)));
            let mut bad = laid;
            bad.included[0] = -2.0;
            assert!(
                bad.report().is_none(),
                "a contact time before 0 other than -1"
            );
            let mut bad = laid;
            bad.included[5] = 1.0;
            assert!(bad.report().is_none(), "an unused word not zero");
            let mut bad = laid;
            bad.force[0] = 1.0;
            assert!(bad.report().is_none(), "a force field in a state");
        }
        let f = Report::Force {
            object: 2,
            t_s: 1.0,
            force: ContactForce {
                force: Vec3::x(),
                point: Vec3::y(),
                depth: 1e-3,
                touching: true,
                torque: Vec3::new(0.0, 0.0, 1e-4),
                ..ContactForce::default()
            },
            given_j: 0.25,
        };
        let laid = SiteReport::new(0, 1, &f);
        assert_eq!(laid.report(), Some((0, f)));
        for (given, why) in [
            (-1.0, "negative"),
            (f64::NAN, "NaN"),
            (f64::INFINITY, "infinite"),
        ] {
            let mut bad = laid;
            bad.included[0] = given;
            assert!(bad.report().is_none(), "a {why} given work");
        }
        let mut bad = laid;
        bad.included[1] = 1.0;
        assert!(bad.report().is_none(), "an unused word of a force not zero");
    }

    #[test]
    fn words_follow_the_declared_layout_and_round_trip_bit_exactly() {
        let mut s = ObjectSample::new(
            5,
            6,
            3,
            &BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)),
            2,
            4,
        );
        s.vel[1] = f64::NAN;
        let w = s.to_words();
        assert_eq!(w.len(), 18);
        assert_eq!(
            (w[0], w[1], w[2], w[16], w[17]),
            (5, 6, 3, 2, 4),
            "t_ns, seq, object … adoptions, tool_t_ns"
        );
        assert_eq!(w[5], 0.01f64.to_bits(), "pos[2]");
        let back = ObjectSample::from_words(&w);
        assert_eq!(back.to_words(), w, "bit exact, NaN included");
        assert_eq!(
            ObjectSample::LAYOUT.iter().map(|f| f.2).sum::<usize>(),
            ObjectSample::WORDS
        );
        assert_eq!(ObjectSample::LAYOUT[3], ("pos", "f64", 3));
        assert_eq!(SiteReport::LAYOUT[10], ("included", "f64", MAX_SITES));
        assert_eq!(SiteReport::LAYOUT.len(), 16);
        assert_eq!(SiteReport::WORDS, 40);
        assert_eq!(TraceRecord::WORDS * 8, 240);
        assert_eq!(ToolSample::WORDS * 8, 1432);
        assert!(layout_text(ObjectSample::LAYOUT)
            .starts_with("t_ns u64 1\nseq u64 1\nobject u64 1\npos f64 3\n"));
        let mut r = SiteReport {
            kind: 1,
            site: 1,
            depth: -0.5,
            touching: 1,
            ..SiteReport::default()
        };
        r.included[7] = 3.0;
        assert_eq!(SiteReport::from_words(&r.to_words()), r);
        assert_eq!(r.to_words()[5 + 3 + 4 + 3 + 3 + 3 + 7], 3.0f64.to_bits());
    }

    #[test]
    fn object_samples_validate() {
        let s = ObjectSample::new(
            5,
            6,
            15,
            &BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)),
            2,
            4,
        );
        assert_eq!(s.state().map(|b| b.pos.z), Some(0.01));
        assert_eq!(s.object(), Some(15));
        let mut bad = s;
        bad.pos[2] = f64::INFINITY;
        assert!(bad.state().is_none());
        bad.object = 16;
        assert_eq!(bad.object(), None, "past the largest world");
    }

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
