//! The messages on a station's rings, as plain old data (H5): servo → physics [`ToolSample`],
//! physics → servo [`ObjectSample`], physics ⇄ network [`SiteReport`], physics → recorder
//! [`TraceRecord`]. Each has a stable
//! `TYPE_NAME` and a compile-time size check; conversions to the model's types validate what they
//! read (finite numbers, unit quaternion, known site), because a ring's bytes are only as good as its
//! writer.
#![allow(unsafe_code)] // the four `unsafe impl ShmPod` below, each with its SAFETY argument

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::ContactForce;
use coop_model::method::{Report, MAX_SITES};
use nalgebra::{Quaternion, UnitQuaternion};

use crate::shm::ShmPod;

fn v3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}
fn a3(v: Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}
fn finite(xs: &[f64]) -> bool {
    xs.iter().all(|x| x.is_finite())
}

/// Servo → physics, every servo tick: the tool and its contact with the object.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct ToolSample {
    /// When, ns on CLOCK_MONOTONIC.
    pub t_ns: u64,
    /// Servo tick counter.
    pub seq: u64,
    /// Tool position, m.
    pub tool_pos: [f64; 3],
    /// Tool velocity, m/s.
    pub tool_vel: [f64; 3],
    /// Contact force on the object, N.
    pub force: [f64; 3],
    /// Where it acts, m.
    pub point: [f64; 3],
    /// Penetration, m.
    pub depth: f64,
    /// 1 when touching.
    pub touching: u64,
    /// Desired force at the hand F_h, N.
    pub f_desired: [f64; 3],
    /// Measured force F_m, N.
    pub f_measured: [f64; 3],
    /// Commanded handle force after limits, N.
    pub f_command: [f64; 3],
}
const _: () = assert!(core::mem::size_of::<ToolSample>() == 200);
// SAFETY: repr(C), only u64 and f64 fields (200 bytes, no padding); every bit pattern is valid.
unsafe impl ShmPod for ToolSample {
    const TYPE_NAME: &'static str = "coop.ToolSample.v1";
}

impl ToolSample {
    /// The contact it carries, or `None` if any number is not finite.
    pub fn contact(&self) -> Option<ContactForce> {
        finite(&self.force).then_some(())?;
        finite(&self.point).then_some(())?;
        self.depth.is_finite().then_some(())?;
        Some(ContactForce {
            force: v3(self.force),
            point: v3(self.point),
            depth: self.depth,
            touching: self.touching != 0,
            slipping: false,
        })
    }
}

/// Physics → servo, every physics step: the object state this site believes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct ObjectSample {
    /// Time of the state, ns on CLOCK_MONOTONIC.
    pub t_ns: u64,
    /// Physics step counter.
    pub seq: u64,
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
const _: () = assert!(core::mem::size_of::<ObjectSample>() == 136);
// SAFETY: repr(C), only u64 and f64 fields (136 bytes, no padding); every bit pattern is valid.
unsafe impl ShmPod for ObjectSample {
    const TYPE_NAME: &'static str = "coop.ObjectSample.v2";
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
    /// Its size in 8-byte words.
    pub const WORDS: usize = core::mem::size_of::<Self>() / 8;
    /// From a state computed with the tool sample of time `tool_t_ns`.
    pub fn new(t_ns: u64, seq: u64, s: &BodyState, adoptions: u64, tool_t_ns: u64) -> Self {
        let (pos, rot, vel, ang_mom) = state_fields(s);
        Self {
            t_ns,
            seq,
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
    /// Its words, in field order (for the control block's resume seqlock).
    pub fn words(&self) -> [u64; Self::WORDS] {
        let f = |v: f64| v.to_bits();
        [
            self.t_ns,
            self.seq,
            f(self.pos[0]),
            f(self.pos[1]),
            f(self.pos[2]),
            f(self.rot[0]),
            f(self.rot[1]),
            f(self.rot[2]),
            f(self.rot[3]),
            f(self.vel[0]),
            f(self.vel[1]),
            f(self.vel[2]),
            f(self.ang_mom[0]),
            f(self.ang_mom[1]),
            f(self.ang_mom[2]),
            self.adoptions,
            self.tool_t_ns,
        ]
    }
    /// The inverse of [`ObjectSample::words`].
    pub fn from_words(w: [u64; Self::WORDS]) -> Self {
        let f = f64::from_bits;
        Self {
            t_ns: w[0],
            seq: w[1],
            pos: [f(w[2]), f(w[3]), f(w[4])],
            rot: [f(w[5]), f(w[6]), f(w[7]), f(w[8])],
            vel: [f(w[9]), f(w[10]), f(w[11])],
            ang_mom: [f(w[12]), f(w[13]), f(w[14])],
            adoptions: w[15],
            tool_t_ns: w[16],
        }
    }
}

/// What a site reports to the others (physics → network), and what arrives from them (network →
/// physics): the model's [`Report`] in a fixed layout, with the sender's site index.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct SiteReport {
    /// 1 = a state (paper), 2 = a force (naive).
    pub kind: u64,
    /// Sender's time, ns.
    pub t_ns: u64,
    /// Sender's report counter.
    pub seq: u64,
    /// Sender's site index.
    pub site: u64,
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
    /// State: per site, time its impulses are included up to, s (sender's clock).
    pub included: [f64; MAX_SITES],
    /// Force: force on the object, N.
    pub force: [f64; 3],
    /// Force: where it acts, m.
    pub point: [f64; 3],
    /// Force: penetration, m.
    pub depth: f64,
    /// Force: 1 when touching.
    pub touching: u64,
}
const _: () = assert!(core::mem::size_of::<SiteReport>() == 288);
// SAFETY: repr(C), only u64 and f64 fields and arrays of them (288 bytes, no padding); every bit
// pattern is valid.
unsafe impl ShmPod for SiteReport {
    const TYPE_NAME: &'static str = "coop.SiteReport.v1";
}

/// Physics → network (the recorder), at the scenario's sample rate and at every adoption: what this
/// site believed and displayed, for the station's recording. Nothing on the real-time side reads it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct TraceRecord {
    /// [`TraceRecord::SAMPLE`] or [`TraceRecord::ADOPTION`].
    pub kind: u64,
    /// When, ns on CLOCK_MONOTONIC.
    pub t_ns: u64,
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
    /// 1 when the own user touches the object.
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
const _: () = assert!(core::mem::size_of::<TraceRecord>() == 232);
// SAFETY: repr(C), only u64 and f64 fields (232 bytes, no padding); every bit pattern is valid.
unsafe impl ShmPod for TraceRecord {
    const TYPE_NAME: &'static str = "coop.TraceRecord.v1";
}

impl TraceRecord {
    /// A periodic sample.
    pub const SAMPLE: u64 = 1;
    /// An adoption.
    pub const ADOPTION: u64 = 2;

    /// A record of `kind` at `t_ns` of `state`, with the newest tool sample `tool`.
    pub fn new(kind: u64, t_ns: u64, s: &BodyState, tool: &ToolSample, f_object: Vec3) -> Self {
        let (pos, rot, vel, _) = state_fields(s);
        Self {
            kind,
            t_ns,
            pos,
            rot,
            vel,
            tool_pos: tool.tool_pos,
            f_desired: tool.f_desired,
            f_measured: tool.f_measured,
            f_object: a3(f_object),
            touching: tool.touching,
            ..Self::default()
        }
    }
}

const KIND_STATE: u64 = 1;
const KIND_FORCE: u64 = 2;

impl SiteReport {
    /// Lays out `report` from `site` at `seq`; times in seconds become ns.
    pub fn new(site: usize, seq: u64, report: &Report) -> Self {
        let ns = |s: f64| (s.max(0.0) * 1e9).round() as u64;
        match *report {
            Report::State {
                t_s,
                state,
                accel,
                included,
            } => {
                let (pos, rot, vel, ang_mom) = state_fields(&state);
                Self {
                    kind: KIND_STATE,
                    t_ns: ns(t_s),
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
            Report::Force { t_s, force } => Self {
                kind: KIND_FORCE,
                t_ns: ns(t_s),
                seq,
                site: site as u64,
                force: a3(force.force),
                point: a3(force.point),
                depth: force.depth,
                touching: u64::from(force.touching),
                ..Self::default()
            },
        }
    }

    /// The sender and the model's report, or `None` for an unknown kind, a site index out of range,
    /// a non-finite number or a non-unit quaternion.
    pub fn report(&self) -> Option<(usize, Report)> {
        let site = usize::try_from(self.site).ok().filter(|&s| s < MAX_SITES)?;
        let t_s = self.t_ns as f64 * 1e-9;
        match self.kind {
            KIND_STATE => {
                let state = body_state(self.pos, self.rot, self.vel, self.ang_mom)?;
                (finite(&self.accel) && finite(&self.included)).then_some(())?;
                Some((
                    site,
                    Report::State {
                        t_s,
                        state,
                        accel: v3(self.accel),
                        included: self.included,
                    },
                ))
            }
            KIND_FORCE => {
                (finite(&self.force) && finite(&self.point) && self.depth.is_finite())
                    .then_some(())?;
                let force = ContactForce {
                    force: v3(self.force),
                    point: v3(self.point),
                    depth: self.depth,
                    touching: self.touching != 0,
                    slipping: false,
                };
                Some((site, Report::Force { t_s, force }))
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
            Report::Force { .. } => panic!("kind changed"),
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
        let f = Report::Force {
            t_s: 1.0,
            force: ContactForce {
                force: Vec3::x(),
                point: Vec3::y(),
                depth: 1e-3,
                touching: true,
                slipping: false,
            },
        };
        assert!(matches!(
            SiteReport::new(0, 1, &f).report(),
            Some((0, Report::Force { .. }))
        ));
    }

    #[test]
    fn object_samples_validate() {
        let s = ObjectSample::new(5, 6, &BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)), 2, 4);
        assert_eq!(s.state().map(|b| b.pos.z), Some(0.01));
        let mut bad = s;
        bad.pos[2] = f64::INFINITY;
        assert!(bad.state().is_none());
    }
}
