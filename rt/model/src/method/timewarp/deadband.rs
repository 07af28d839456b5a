//! A perceptual deadband on the own tool's positions (opt-in: `[timewarp.deadband]`).
//!
//! The perceptual deadband coding of haptic streams (Hinterseer et al. 2008; IEEE 1918.1.1)
//! sends a sample only when it leaves a just-noticeable band around the last one sent. Here the
//! sample is the own tool's position, the input every site steps the world with. The band is
//! haptic while the tool is near an object or touches one: the position change that changes the
//! tool's contact force by a Weber fraction of it (`weber_fraction` × |F| / K, the penalty
//! contact's stiffness K), never below the change an absolute force floor makes (`floor_n` / K);
//! in free space it is coarser, `free_space_m`. Inside the band the input stays the last one
//! sent (zero-order hold). The held position *is* the tick's input, at this site as at every
//! other (the track carries it, and the wire sends a run of held ticks in a few bytes), exactly
//! as the 0.01 mm quantization is the input: every site steps the same bits, and a rollback
//! re-simulates the held positions it stepped before. A held tool's velocity in the step is its
//! last change over the time that change took ([`Moved`]), not the difference from the last
//! tick's input, which is nothing while held and a band's jump at a sample: the contact's damping
//! would vanish during a hold and spike at every sample.

use crate::body::Vec3;
use crate::contact::{ContactForce, ContactParams};
use crate::perception::force_jnd_n;
use crate::world::World;
#[cfg(feature = "serde")]
use serde::Deserialize;

use super::super::copy::WorldCopy;
use super::super::stats::CodecError;
use super::super::track::{limit_speed, position, Quantized, QUANTUM_M};
use super::predict::SAMPLE_VELOCITY_TICKS;

/// A perceptual deadband on the tool positions a `timewarp` site sends and steps with
/// (`[timewarp.deadband]`; see `method/timewarp/deadband.rs`): a position is sent when it leaves
/// a band around the last one sent, and held in between.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct DeadbandSpec {
    /// On (default off: every tick's position is sent).
    pub enabled: bool,
    /// Near or touching an object: the position change that changes the tool's contact force by
    /// this fraction of it is the band (a Weber fraction, 0 to 1; default
    /// [`JND_SHARE`] of 0.07, the force JND every figure counts in,
    /// `perception::FORCE_JND_FRACTION`)...
    pub weber_fraction: f64,
    /// ... never narrower than the change that makes this force, N (an absolute threshold, above
    /// 0; default [`FLOOR_SHARE`] of 0.05 N, `perception::FORCE_JND_FLOOR_N`).
    pub floor_n: f64,
    /// Within this of an object's bounding sphere the tool is near it, m (0 to 1; default 0.01).
    pub near_m: f64,
    /// The band's half width in free space, m (above 0, at most 0.1; default 0.002).
    pub free_space_m: f64,
}

/// The share of a just-noticeable difference each tool's band takes by default: 1/√2. An object
/// held between two tools moves with both their held positions, and two independent errors of
/// one JND each add to √2 JND; at 1/√2 each they add to one. (`sim deadband` measures what it
/// keeps: the held position's contact force against the measured one's, and run against run.)
pub const JND_SHARE: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// The share of the JND's absolute floor the band's floor is by default: 1/2. A light touch's
/// force is much of it the stuck tangential force, which a held position moves as much as the
/// normal one (the paper task's tangential stiffness is its normal one): the two directions take
/// another 1/√2.
pub const FLOOR_SHARE: f64 = 0.5;

impl Default for DeadbandSpec {
    fn default() -> Self {
        Self {
            enabled: false,
            weber_fraction: JND_SHARE * crate::perception::FORCE_JND_FRACTION,
            floor_n: FLOOR_SHARE * crate::perception::FORCE_JND_FLOOR_N,
            near_m: 0.01,
            free_space_m: 0.002,
        }
    }
}

/// A tool's last motion as its inputs show it, for its velocity through a deadband: the tick its
/// input last changed, the ticks from the change before to that one, and where it was before.
/// Every site derives it from the same inputs in tick order, so every site steps the same
/// velocity, and a rollback derives it again from the slot before.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Moved {
    at: i64,
    gap: i64,
    from: Quantized,
}

impl Moved {
    /// At rest at `q` from tick `t` on.
    pub(super) fn rest(q: Quantized, t: i64) -> Self {
        Self {
            at: t,
            gap: SAMPLE_VELOCITY_TICKS,
            from: q,
        }
    }

    /// Tick `t`'s, whose input is `q`, after the last tick's input and motion (`None`: no last
    /// tick, or an unknown input).
    pub(super) fn next(was: Option<(Quantized, Moved)>, q: Quantized, t: i64) -> Self {
        match was {
            Some((p, m)) if p == q => m,
            Some((p, m)) => Self {
                at: t,
                gap: t.saturating_sub(m.at).clamp(1, SAMPLE_VELOCITY_TICKS),
                from: p,
            },
            None => Self::rest(q, t),
        }
    }

    /// The velocity at tick `t` of a tool whose input is `q` (`dt` the tick, s): its last change
    /// over the time it took, held while the input is, never faster than that change over the
    /// time since it; a held run longer than [`SAMPLE_VELOCITY_TICKS`] is a tool at rest. A held
    /// run's step difference is nothing, then a band's jump in one tick: its damping would be
    /// lost while held and a spike at every sample.
    pub(super) fn velocity(&self, q: Quantized, t: i64, dt: f64) -> Vec3 {
        let since = t.saturating_sub(self.at).saturating_add(1);
        if since > SAMPLE_VELOCITY_TICKS {
            return Vec3::zeros();
        }
        limit_speed((position(q) - position(self.from)) / (self.gap.max(since) as f64 * dt))
    }
}

/// The deadband's state: the last position sent, and what it did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deadband {
    spec: DeadbandSpec,
    held: Option<Quantized>,
    /// The last measured position (the source of the last tick).
    measured: Option<Quantized>,
    /// Own ticks stepped, and those whose position left the band (a new sample).
    pub ticks: u64,
    pub samples: u64,
    /// The decoded input against its source ([`CodecError`]).
    pub error: CodecError,
}

/// A tool's speed from its position `p` and the last tick's `prev` over `dt`, s, as the step
/// takes it: none without a last one, its speed limited ([`limit_speed`]).
fn speed(p: Quantized, prev: Option<Quantized>, dt: f64) -> Vec3 {
    prev.map_or(Vec3::zeros(), |q| {
        limit_speed((position(p) - position(q)) / dt)
    })
}

impl Deadband {
    pub fn new(spec: DeadbandSpec) -> Self {
        Self {
            spec,
            held: None,
            measured: None,
            ticks: 0,
            samples: 0,
            error: CodecError::default(),
        }
    }

    /// The band's half width, m, for the own tool at `tool` (radius `radius`) with its last
    /// tick's contacts `own` (one per object), in `world` as `copy` has it.
    pub fn width_m(
        &self,
        (world, copy): (&World, &WorldCopy),
        contact: &ContactParams,
        tool: Vec3,
        radius: f64,
        own: impl Iterator<Item = ContactForce>,
    ) -> f64 {
        let s = &self.spec;
        let mut force = 0.0;
        let mut near = false;
        for (c, (body, object)) in own.zip(world.bodies().iter().zip(copy.objects())) {
            force += c.force.norm();
            near |= c.touching
                || (tool - object.state.pos).norm() - body.shape.bounding_radius() - radius
                    < s.near_m;
        }
        if near {
            (s.weber_fraction * force).max(s.floor_n) / contact.stiffness_n_per_m
        } else {
            s.free_space_m
        }
    }

    /// The input for a tick whose measured position is `q`: `q` if it leaves the band of half
    /// width `width_m` around the last sent one (or none was sent), else the last sent.
    pub fn filter(&mut self, q: Quantized, width_m: f64) -> Quantized {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        self.ticks += 1;
        let leaves = self.held.is_none_or(|h| {
            let d = position(q) - position(h);
            // (Compared in quanta, squared: integers in f64, exact.)
            let limit = width_m / QUANTUM_M;
            d.norm_squared() / (QUANTUM_M * QUANTUM_M) > limit * limit
        });
        if leaves {
            self.held = Some(q);
            self.samples += 1;
        }
        self.held.unwrap_or(q)
    }

    /// Measures the tick just filtered: `measured` went in, `held` came out, and the step takes
    /// the held tool at `held_velocity` ([`Moved::velocity`]); `render(position, velocity)` is the
    /// own tool's contact force summed over the objects and whether it touched one, from the
    /// tick's world state, leaving it as it was; `dt` the tick, s. The source's velocity is the
    /// full-rate step's: the difference from the last measured position.
    pub fn measure(
        &mut self,
        (measured, held, held_velocity): (Quantized, Quantized, Vec3),
        dt: f64,
        render: impl Fn(Vec3, Vec3) -> (Vec3, bool),
    ) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let (f_true, touch_true) = render(position(measured), speed(measured, self.measured, dt));
        let (f_held, touch_held) = render(position(held), held_velocity);
        self.measured = Some(measured);
        let e = (touch_true || touch_held)
            .then(|| (f_held - f_true).norm() / force_jnd_n(f_true.norm()));
        let d: i64 = (0..3)
            .map(|a| (i64::from(held[a]) - i64::from(measured[a])).pow(2))
            .sum();
        self.error.record(e, (d as f64).sqrt().ceil() as u64);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_position_is_sent_only_when_it_leaves_the_band() {
        let mut d = Deadband::new(DeadbandSpec {
            enabled: true,
            ..DeadbandSpec::default()
        });
        assert_eq!(
            d.filter([0, 0, 1000], 1e-3),
            [0, 0, 1000],
            "the first is sent"
        );
        // 0.5 mm away: inside a 1 mm band, held.
        assert_eq!(d.filter([50, 0, 1000], 1e-3), [0, 0, 1000]);
        assert_eq!(d.filter([0, 70, 1000], 1e-3), [0, 0, 1000]);
        // 1.2 mm: out, sent, and the band moves with it.
        assert_eq!(d.filter([120, 0, 1000], 1e-3), [120, 0, 1000]);
        assert_eq!(d.filter([100, 0, 1000], 1e-3), [120, 0, 1000]);
        // A narrower band (in contact) lets less through.
        assert_eq!(d.filter([100, 0, 1000], 1e-4), [100, 0, 1000]);
        assert_eq!((d.ticks, d.samples), (6, 3));
    }

    #[test]
    fn the_decoded_force_is_measured_against_the_source_s_from_the_same_state() {
        let mut d = Deadband::new(DeadbandSpec {
            enabled: true,
            ..DeadbandSpec::default()
        });
        // A wall at x = 0 pressed by x > 0, 1000 N/m: 1 mm is 1 N.
        let wall = |p: Vec3, _v: Vec3| {
            let depth = p.x.max(0.0);
            (Vec3::new(-1000.0 * depth, 0.0, 0.0), depth > 0.0)
        };
        let dt = 1e-3;
        // Free space: no force in either rendering, counted as a tick, not a contact tick.
        d.measure(([-500, 0, 0], [-400, 0, 0], Vec3::zeros()), dt, wall);
        assert_eq!((d.error.ticks, d.error.contact_ticks), (1, 0));
        assert_eq!(d.error.max_position_quanta, 100);
        // 3 N measured, 2.99 N held (a JND of 3 N is 0.21 N): within.
        d.measure(([300, 0, 0], [299, 0, 0], Vec3::zeros()), dt, wall);
        assert_eq!((d.error.contact_ticks, d.error.contact_within_jnd), (1, 1));
        // 3 N measured, 2.7 N held: 0.3 N, beyond one JND.
        d.measure(([300, 0, 0], [270, 0, 0], Vec3::zeros()), dt, wall);
        assert_eq!((d.error.contact_ticks, d.error.contact_within_jnd), (2, 1));
        assert_eq!(d.error.contact_within_jnd_share(), Some(0.5));
        assert_eq!(d.error.within_jnd_share(), Some(2.0 / 3.0));
        let p99 = d.error.contact_p99_jnd().expect("counted");
        assert!(
            (0.3 / 0.21..=1.125 * 0.3 / 0.21 + 0.01).contains(&p99),
            "{p99}"
        );
        // The held tool touches, the measured one does not: a contact tick beyond one JND.
        d.measure(([-10, 0, 0], [20, 0, 0], Vec3::zeros()), dt, wall);
        assert_eq!((d.error.contact_ticks, d.error.contact_within_jnd), (3, 1));
        let mut all = CodecError::default();
        all.merge(&d.error);
        all.merge(&d.error);
        assert_eq!((all.ticks, all.contact_within_jnd), (8, 2));
        assert_eq!(all.max_position_quanta, 100);
    }
}
