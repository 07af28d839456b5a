//! The confirmed state's hash every report carries, and adopting a confirmed state that differs.

use super::*;
use crate::contact::PairContactState;
use crate::world::pair_index;

/// After sending its confirmed state, a site sends it again to a site that still asks a round
/// trip later and this much more, s: the time the asker takes to confirm the state's tick (the
/// other sites' inputs up to it, a report period or so) and to say in its next report that it
/// took it.
pub const STATE_RESEND_SLACK_S: f64 = 0.1;

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

    /// Takes the object of the state `r` carries from site `from` (its confirmed state at its
    /// frontier); once every object of the world is in, all from that site at that tick, checks
    /// that they hash to the world's hash and hold no more spring energy than the users could
    /// have put in, and keeps them until [`Self::adopt_gathered`] can adopt them. A world's first
    /// object begins a new gathering, unless a site before the sender (in the sites' order) has
    /// one under way whose tick is still kept (every earlier site that differs is asked, and the
    /// first one's state is the one taken), or the sender's own is whole and waits for its tick
    /// to be confirmed here (a newer one would wait longer: the sender's frontier runs ahead of
    /// what this site has confirmed by the time it arrives).
    pub(super) fn gather(&mut self, world: &World, from: usize, r: &ToolReport) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let Some(snap) = r.state else {
            return;
        };
        let n = world.bodies().len().min(self.incoming.len());
        if snap.objects != n || snap.object >= n {
            return;
        }
        // A world of one travels whole, at the sender's frontier, under its hash.
        if n == 1 && (snap.tick != r.confirmed_tick || hash_state(&snap.state) != r.confirmed_hash)
        {
            return;
        }
        let kept = |t: i64| t >= self.oldest_kept() && self.slots[self.idx(t)].tick == t;
        let under_way = self.incoming[..n]
            .iter()
            .flatten()
            .next()
            .copied()
            .filter(|g| kept(g.tick));
        let whole = self.incoming[..n].iter().all(Option::is_some);
        let order = (r.started_tick, from);
        if snap.object == 0 {
            if under_way.is_some()
                && (self.incoming_from < order || (self.incoming_from == order && whole))
            {
                return;
            }
            self.incoming[..n].fill(None);
            self.incoming_from = order;
        } else if under_way.is_none_or(|g| {
            self.incoming_from.1 != from || g.tick != snap.tick || g.world_hash != snap.world_hash
        }) {
            return;
        }
        self.incoming[snap.object] = Some(snap);
        if self.incoming[..n].iter().any(Option::is_none) {
            return;
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
        }
    }

    /// Adopts the whole state [`Self::gather`] took, at its tick, and re-simulates to now, once
    /// this site has confirmed that tick too (before, an input of an earlier tick still to come
    /// would roll back over it); `None` until then. Dropped once its tick leaves the history, is
    /// older than a state adopted since, or when its site's state no longer differs from ours (no
    /// longer asked for).
    pub(super) fn adopt_gathered(
        &mut self,
        world: &World,
        copy: &mut WorldCopy,
    ) -> Option<Adoption> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let n = copy.len().min(self.incoming.len());
        if n == 0 || self.incoming[..n].iter().any(Option::is_none) {
            return None;
        }
        let from = self.incoming_from.1;
        let t = self.incoming[0].map_or(i64::MIN, |s| s.tick);
        let i = self.idx(t);
        // A kept slot is a simulated tick (the current one is not kept yet).
        // (Nor one older than a state adopted since: it would roll back over that.)
        if !self.want_state[from]
            || self.slots[i].tick != t
            || t < self.oldest_kept()
            || t < self.adopted_tick
        {
            self.incoming[..n].fill(None);
            return None;
        }
        if t > self.confirmed_tick() {
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
        self.want_state[from] = false;
        self.rollback(world, copy, t, true);
        self.stats.adopted_states += 1;
        Some(before.adoption(world, copy, (self.now_tick - t) as f64 * self.dt))
    }

    /// How long after sending the confirmed state this site sends it again to sites that still
    /// ask, ticks: a round trip to the slowest of them ([`TimeWarp::delay_ticks`] each way: how
    /// late their newest positions arrive; where not measured, the largest measured of any site)
    /// and [`STATE_RESEND_SLACK_S`] for it to confirm the state's tick and say, in its next
    /// report, that it took it. Sooner, the same state (or a newer one, which the asker would
    /// have to confirm anew) crosses the one on its way; in every report, a world of many
    /// objects' states would take most of the upload of a site asked for it.
    pub(super) fn state_resend_ticks(&self) -> i64 {
        let slowest = |asking: bool| {
            (0..self.sites)
                .filter(|&j| j != self.me && (!asking || self.state_asked[j]))
                .map(|j| self.delay_ticks[j])
                .fold(0.0, f64::max)
        };
        let mut one_way = slowest(true);
        if one_way == 0.0 {
            one_way = slowest(false);
        }
        (2.0 * one_way + STATE_RESEND_SLACK_S / self.dt).ceil() as i64
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
