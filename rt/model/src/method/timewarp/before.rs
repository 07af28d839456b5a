//! The copy before an adoption (a rollback that moved it, a state adopted), kept to measure the
//! adoption against: per object, without copying the world.

use crate::body::Vec3;
use crate::world::{World, MAX_OBJECTS};

use super::super::copy::WorldCopy;
use super::super::report::Adoption;

/// What an adoption (a rollback that moved the copy, a state adopted) is measured against: the
/// copy before it, per object, without copying the world.
pub(super) struct Before {
    pos: [Vec3; MAX_OBJECTS],
    energy_j: f64,
    work_j: f64,
}

impl Before {
    /// Every force's work so far, as the copy's account has it (restored with a snapshot and
    /// re-accumulated by the re-simulation), J.
    fn work(copy: &WorldCopy) -> f64 {
        copy.objects()
            .iter()
            .map(|c| c.energy.own_j + c.energy.remote_j + c.energy.env_j + c.energy.objects_j)
            .sum()
    }

    pub(super) fn of(world: &World, copy: &WorldCopy) -> Self {
        let mut pos = [Vec3::zeros(); MAX_OBJECTS];
        for (p, c) in pos.iter_mut().zip(copy.objects()) {
            *p = c.state.pos;
        }
        Self {
            pos,
            energy_j: copy.mechanical_energy(world),
            work_j: Self::work(copy),
        }
    }

    /// The adoption that made `copy` of what it was, `age_s` back: its jump is the object's that
    /// moved most (before − after).
    pub(super) fn adoption(&self, world: &World, copy: &WorldCopy, age_s: f64) -> Adoption {
        let jump = copy
            .objects()
            .iter()
            .zip(&self.pos)
            .map(|(c, p)| p - c.state.pos)
            .fold(
                Vec3::zeros(),
                |a, b| if b.norm() > a.norm() { b } else { a },
            );
        Adoption {
            jump,
            energy_j: copy.mechanical_energy(world) - self.energy_j,
            work_j: Self::work(copy) - self.work_j,
            age_s,
            clipped_j: 0.0,
        }
    }
}
