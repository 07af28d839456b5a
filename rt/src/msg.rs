//! The messages on a station's rings, as plain old data (H5): servo → physics [`ToolSample`],
//! physics → servo [`ObjectSample`], physics ⇄ network [`SiteReport`] and [`ToolTrack`], physics → recorder
//! [`TraceRecord`]. Each is declared once with `pod_message!`, which derives from the one field
//! list its words (`WORDS`, `to_words`, `from_words`) and its `LAYOUT`: the wire format
//! (`coop_transport::wire`) and the control block's resume seqlock are built on those, never on a
//! second, hand-written field order. Each has a stable `TYPE_NAME` and a compile-time size check;
//! conversions to the model's types validate what they read (finite numbers, unit quaternion, known
//! site), because a ring's bytes are only as good as its writer.
//!
//! This module holds what crosses the boundary: [`WordField`], `pod_message!` and every message's
//! declaration with its size check and its `unsafe impl ShmPod` (the one place this crate's
//! messages use `unsafe`). What each message carries and how it converts to and from the model's
//! types lives beside it: `sample` (the servo's tool and object samples), `report` (a site's
//! report), `track` (a site's tool track), `trace` (the recorder's records).
#![allow(unsafe_code)] // the five `unsafe impl ShmPod` below, each with its SAFETY argument

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::MAX_PLANES;
#[cfg(doc)]
use coop_model::method::{track::ToolReport, Report};
use coop_model::method::{track::WINDOW_TICKS, MAX_SITES};
use coop_model::world::MAX_OBJECTS;
use nalgebra::{Quaternion, UnitQuaternion};

use crate::shm::ShmPod;

mod report;
mod sample;
mod trace;
mod track;

pub use report::KIND_COUPLED;

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
        // The sender's bits, not renormalized: a receiver takes the state as it was sent (a
        // second normalization of a unit quaternion moves its last bits, so a state relayed
        // twice, or compared with the sender's, would differ).
        rot: UnitQuaternion::new_unchecked(q),
        vel: v3(vel),
        ang_mom: v3(ang_mom),
    })
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
        /// The sender's time of the newest remote report or track physics took before computing
        /// this state, on this machine's clock (the network corrected it), ns (0: none yet): the
        /// servo measures from it how long a partner's report took to reach the displayed force.
        pub remote_t_ns: u64,
    }
}
const _: () = assert!(core::mem::size_of::<ObjectSample>() == 152);
// SAFETY: repr(C), only u64 and f64 fields (152 bytes, no padding); every bit pattern is valid.
unsafe impl ShmPod for ObjectSample {
    const TYPE_NAME: &'static str = "coop.ObjectSample.v4";
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

#[cfg(test)]
mod tests {
    use super::*;

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
        s.remote_t_ns = 7;
        let w = s.to_words();
        assert_eq!(w.len(), 19);
        assert_eq!(
            (w[0], w[1], w[2], w[16], w[17], w[18]),
            (5, 6, 3, 2, 4, 7),
            "t_ns, seq, object … adoptions, tool_t_ns, remote_t_ns"
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
}
