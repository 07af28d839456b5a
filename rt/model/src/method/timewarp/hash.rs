//! The confirmed state's hash every report carries, and adopting a confirmed state that differs.

use super::*;

impl TimeWarp {
    /// Adopts the state `r` carries (its sender's at its confirmed frontier, which this site has
    /// confirmed too) at that tick and re-simulates to now; `None` if it carries none, or one
    /// that is not the state its hash names.
    pub(super) fn resync(
        &mut self,
        world: &World,
        copy: &mut ObjectCopy,
        r: &ToolReport,
    ) -> Option<Adoption> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let snap = r
            .state
            .filter(|s| s.tick == r.confirmed_tick && hash_state(&s.state) == r.confirmed_hash)?;
        let i = self.idx(snap.tick);
        // A kept slot is a simulated tick (the current one is not kept yet: hash_at checked).
        if self.slots[i].tick != snap.tick
            || super::super::tank::spring_energy(world, &snap.state) > self.max_spring_j
        {
            return None;
        }
        let before = *copy;
        let e = |s: &BodyState| s.mechanical_energy(&world.mass, world.gravity);
        let slot = &mut self.slots[i];
        // The jump is energy no force of the history accounts for.
        slot.copy.energy.adoption_j += e(&snap.state) - e(&slot.copy.state);
        slot.copy.state = snap.state;
        slot.copy.env = snap.env;
        slot.contacts = snap.contacts;
        self.rollback(world, copy, snap.tick);
        self.stats.adopted_states += 1;
        // Every force's work so far, as the re-simulated account has it (as in `receive`).
        let w = |c: &ObjectCopy| c.energy.own_j + c.energy.remote_j + c.energy.env_j;
        Some(Adoption {
            jump: before.state.pos - copy.state.pos,
            energy_j: e(&copy.state) - e(&before.state),
            work_j: w(copy) - w(&before),
            age_s: (self.now_tick - snap.tick) as f64 * self.dt,
            clipped_j: 0.0,
        })
    }

    /// FNV-1a of the state at the start of tick `t`, if it is still kept.
    pub(super) fn hash_at(&self, t: i64) -> Option<u64> {
        let s = &self.slots[self.idx(t)];
        (s.tick == t).then(|| hash_state(&s.copy.state))
    }
}

/// FNV-1a 64 of a state's bits.
pub fn hash_state(s: &BodyState) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let words = s
        .pos
        .iter()
        .chain(s.vel.iter())
        .chain(s.ang_mom.iter())
        .chain(s.rot.coords.iter());
    for w in words {
        for b in w.to_bits().to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}
