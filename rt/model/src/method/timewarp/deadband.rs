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
//! re-simulates the held positions it stepped before.

use crate::body::Vec3;
use crate::contact::{ContactForce, ContactParams};
use crate::world::World;
#[cfg(feature = "serde")]
use serde::Deserialize;

use super::super::copy::WorldCopy;
use super::super::track::{position, Quantized, QUANTUM_M};

/// A perceptual deadband on the tool positions a `timewarp` site sends and steps with
/// (`[timewarp.deadband]`; see `method/timewarp/deadband.rs`): a position is sent when it leaves
/// a band around the last one sent, and held in between.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize),
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
/// one JND each add to √2 JND; at 1/√2 each they add to one. On the paper task (seeds 1–8, every
/// site's tool replayed from the full-rate run, so only the world differs; the floor at
/// [`FLOOR_SHARE`]) the mean share of servo ticks whose displayed force is within one JND of the
/// full-rate run's at 0 / 100 / 200 / 300 ms is 99.7 / 98.5 / 95.8 / 91.7 %, against
/// 99.6 / 98.3 / 93.0 / 90.3 % with a band of one JND, with at most 9.0 % of positions sent
/// instead of 8.0 %.
pub const JND_SHARE: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// The share of the JND's absolute floor the band's floor is by default: 1/2. A light touch's
/// force is much of it the stuck tangential force, which a held position moves as much as the
/// normal one (the paper task's tangential stiffness is its normal one): the two directions take
/// another 1/√2. With the floor at 1/√2 alone, seeds 3 and 6 of the paper task at 0 ms had 98.82
/// and 97.43 % of servo ticks within one JND (hands replayed); at 1/2, 99.54 and 99.85 %.
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

/// The deadband's state: the last position sent, and what it did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deadband {
    spec: DeadbandSpec,
    held: Option<Quantized>,
    /// Own ticks stepped, and those whose position left the band (a new sample).
    pub ticks: u64,
    pub samples: u64,
}

impl Deadband {
    pub fn new(spec: DeadbandSpec) -> Self {
        Self {
            spec,
            held: None,
            ticks: 0,
            samples: 0,
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
}
