//! The confirmed state's hash every report carries, and adopting a confirmed state that differs.

use super::*;

impl TimeWarp {
    /// Adopts the state `r` carries (its sender's at its confirmed frontier, which this site has
    /// confirmed too) at that tick and re-simulates to now; `None` if it carries none, or one
    /// that is not the state its hash names.
    pub(super) fn resync(
        &mut self,
        world: &World,
        copy: &mut WorldCopy,
        r: &ToolReport,
    ) -> Option<Adoption> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        // (A snapshot carries one object: a world of several is not resynchronised.)
        if copy.len() != 1 {
            return None;
        }
        let snap = r
            .state
            .filter(|s| s.tick == r.confirmed_tick && hash_state(&s.state) == r.confirmed_hash)?;
        let i = self.idx(snap.tick);
        // A kept slot is a simulated tick (the current one is not kept yet: hash_at checked).
        if self.slots[i].tick != snap.tick
            || super::super::tank::spring_energy(world, 0, &snap.state) > self.max_spring_j
        {
            return None;
        }
        let before = Before::of(world, copy);
        let e = |s: &BodyState| s.mechanical_energy(&world.bodies[0].mass, world.gravity);
        let kept = self.worlds[i].first_mut();
        // The jump is energy no force of the history accounts for.
        kept.energy.adoption_j += e(&snap.state) - e(&kept.state);
        kept.state = snap.state;
        kept.env = snap.env;
        let n = self.tools_len();
        self.tools[i * n..i * n + MAX_SITES].copy_from_slice(&snap.contacts);
        // (Its state changed, not only inputs: every object steps again.)
        self.rollback(world, copy, snap.tick, true);
        self.stats.adopted_states += 1;
        Some(before.adoption(world, copy, (self.now_tick - snap.tick) as f64 * self.dt))
    }

    /// FNV-1a of the state at the start of tick `t`, if it is still kept.
    pub(super) fn hash_at(&self, t: i64) -> Option<u64> {
        let i = self.idx(t);
        (self.slots[i].tick == t).then(|| hash_world(&self.worlds[i]))
    }
}

/// FNV-1a 64 of every object's state's bits, in the world's order (of a world of one object:
/// [`hash_state`] of its state).
pub fn hash_world(copy: &WorldCopy) -> u64 {
    copy.objects()
        .iter()
        .fold(FNV_OFFSET, |h, o| fnv(h, &o.state))
}

const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// FNV-1a 64 of a state's bits.
pub fn hash_state(s: &BodyState) -> u64 {
    fnv(FNV_OFFSET, s)
}

/// FNV-1a 64 of a state's bits, from `h`.
fn fnv(mut h: u64, s: &BodyState) -> u64 {
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
