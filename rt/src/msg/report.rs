//! A site's report to the others: the model's [`Report`] laid out, and its one validation on the
//! way back.

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::ContactForce;
use coop_model::method::track::{CoupledReport, ToolReport};
use coop_model::method::{Report, MAX_SITES};
use coop_model::world::MAX_OBJECTS;

#[cfg(doc)]
use super::ToolTrack;
use super::{a3, body_state, finite, state_fields, v3, SiteReport};

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
    use nalgebra::UnitQuaternion;

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
}
