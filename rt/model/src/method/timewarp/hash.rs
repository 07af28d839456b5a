//! The confirmed state's hash every report carries, and adopting a confirmed state that differs.

use super::*;
use crate::contact::PairContactState;
use crate::world::pair_index;

impl TimeWarp {
    /// Object `k` of the kept state at the start of tick `t` (a simulated tick still kept), as
    /// a snapshot of the world whose hash there is `world_hash` ([`Self::hash_at`]).
    pub(super) fn snapshot_at(&self, t: i64, k: usize, world_hash: u64) -> Snapshot {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let i = self.idx(t);
        let w = &self.worlds[i];
        let n = w.len();
        let mut contacts = [ToolContactState::default(); MAX_SITES];
        contacts.copy_from_slice(&self.tools_at(i)[k * MAX_SITES..(k + 1) * MAX_SITES]);
        let mut pairs = [PairContactState::default(); MAX_OBJECTS - 1];
        for (p, j) in pairs.iter_mut().zip(k + 1..n) {
            *p = w.pairs()[pair_index(k, j, n)];
        }
        let o = &w.objects()[k];
        Snapshot {
            tick: t,
            object: k,
            objects: n,
            world_hash,
            state: o.state,
            env: o.env,
            contacts,
            pairs,
            still: w.still()[k],
        }
    }

    /// Takes the object of the state `r` carries from site `from` (its confirmed state at a tick
    /// this site has confirmed too); once every object of the world is in, all from that site at
    /// that tick, and they hash to the world's hash, adopts them there and re-simulates to now.
    /// `None` until then, or if what it carries is not that state. A world's first object begins
    /// a new gathering, unless a site before the sender (in the sites' order) has one under way
    /// whose tick is still kept: every earlier site that differs is asked, and the first one's
    /// state is the one taken.
    pub(super) fn resync(
        &mut self,
        world: &World,
        copy: &mut WorldCopy,
        from: usize,
        r: &ToolReport,
    ) -> Option<Adoption> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let snap = r.state?;
        let n = copy.len();
        if snap.objects != n || snap.object >= n {
            return None;
        }
        // A world of one travels whole, at the sender's frontier, under its hash.
        if n == 1 && (snap.tick != r.confirmed_tick || hash_state(&snap.state) != r.confirmed_hash)
        {
            return None;
        }
        let kept = |t: i64| t >= self.oldest_kept() && self.slots[self.idx(t)].tick == t;
        let under_way = self.incoming[..n]
            .iter()
            .flatten()
            .next()
            .copied()
            .filter(|g| kept(g.tick));
        let order = (r.started_tick, from);
        if snap.object == 0 {
            if under_way.is_some() && self.incoming_from < order {
                return None;
            }
            self.incoming[..n].fill(None);
            self.incoming_from = order;
        } else if under_way.is_none_or(|g| {
            self.incoming_from.1 != from || g.tick != snap.tick || g.world_hash != snap.world_hash
        }) {
            return None;
        }
        self.incoming[snap.object] = Some(snap);
        if self.incoming[..n].iter().any(Option::is_none) {
            return None;
        }
        let (t, i) = (snap.tick, self.idx(snap.tick));
        // A kept slot is a simulated tick (the current one is not kept yet); a tick not confirmed
        // here yet waits for the next report (the sender sends its objects again).
        if self.slots[i].tick != t || t < self.oldest_kept() {
            self.incoming[..n].fill(None);
            return None;
        }
        if t > self.confirmed_tick() {
            return None;
        }
        let mut h = FNV_OFFSET;
        for s in self.incoming[..n].iter().flatten() {
            h = fnv(h, &s.state);
        }
        let deep = self.incoming[..n].iter().flatten().any(|s| {
            super::super::tank::spring_energy(world, s.object, &s.state) > self.max_spring_j
        });
        if h != snap.world_hash || deep {
            self.incoming[..n].fill(None);
            return None;
        }
        let before = Before::of(world, copy);
        let len = self.tools_len();
        for k in 0..n {
            let Some(s) = self.incoming[k].take() else {
                continue;
            };
            let body = &world.bodies[k];
            let e = |b: &BodyState| b.mechanical_energy(&body.mass, world.gravity);
            let kept = &mut self.worlds[i];
            // The jump is energy no force of the history accounts for.
            kept.objects_mut()[k].energy.adoption_j += e(&s.state) - e(&kept.objects()[k].state);
            kept.set_object(k, (s.state, s.env), s.still, &s.pairs);
            let m = i * len + k * MAX_SITES;
            self.tools[m..m + MAX_SITES].copy_from_slice(&s.contacts);
        }
        // (Its state changed, not only inputs: every object steps again.)
        self.adopted_tick = t;
        self.rollback(world, copy, t, true);
        self.stats.adopted_states += 1;
        Some(before.adoption(world, copy, (self.now_tick - t) as f64 * self.dt))
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
