//! A rollback re-simulates only the objects a changed input can reach.
//!
//! A rollback restores the world at the first tick whose input changed and steps it again to now.
//! Most of a crowded world is not touched by that change: an object no changed tool reaches and
//! that meets no re-simulated object steps again exactly as it stepped the first time, and its
//! state at every re-simulated tick is already kept (the old history's slots). So a re-simulation
//! steps the *reached* objects only, reads the others from the old history where it needs them,
//! writes only the reached ones into the slots, and takes the others' newest state at the end.
//! An object is reached, from the tick on, when:
//!
//! - a tool whose input changed (at that tick, or at the one before: its velocity) is within
//!   reach of it, where it is now or where it was, or touches it in either history;
//! - a reached object is within reach of it (bounding spheres, plus a millimetre and twice the
//!   two objects' motion in one tick: the step evaluates contacts at the start and the end
//!   poses), or touched it at the tick's start or end in the old history (it was pushed by an
//!   object that now moves differently);
//! - or the old history lacks a tick of the rollback (then every object, the whole way).
//!
//! A reached object stays reached to the end of the rollback; it enters with the old history's
//! state at that tick (the same as a whole re-simulation's: nothing had reached it). The objects
//! not reached are never within reach of a stepped one, so the stepped ones get the same bits as
//! in a whole step ([`crate::method::integrate_some`]), and the others are the old history's
//! bits: the re-simulated world is the one a whole re-simulation gives, to the bit
//! (`timewarp.islands = false` steps every object; `tools/tests/islands.rs` runs the crowd both
//! ways and compares the bytes, and the synctest forces rollbacks through it).

use super::*;
use crate::world::pair_index;

/// What the reach tests read of a kept tick, dense: each object's position and speed, which
/// pairs of objects touch and which tools touch each object. A tick's world is 30 KB of memory a
/// tick apart from the next; read scattered, its objects cost more than stepping them.
#[derive(Debug, Clone, Copy)]
pub(super) struct Sketch {
    pos: [Vec3; MAX_OBJECTS],
    speed: [f64; MAX_OBJECTS],
    /// Bit [`pair_index`]: the pair touches.
    pairs: u128,
    /// Per object, bit `j`: site `j`'s tool touches it.
    tools: [u8; MAX_OBJECTS],
}

// The sketch's bit sets hold every pair and every site.
const _: () = assert!(MAX_OBJECTS * (MAX_OBJECTS - 1) / 2 <= 128 && MAX_SITES <= 8);

impl Sketch {
    pub(super) const EMPTY: Sketch = Sketch {
        pos: [Vec3::new(0.0, 0.0, 0.0); MAX_OBJECTS],
        speed: [0.0; MAX_OBJECTS],
        pairs: 0,
        tools: [0; MAX_OBJECTS],
    };

    /// The sketch of the objects in `which` of `copy` with the tools' memory `contacts`, over
    /// `self` (the others' entries stay, and the pairs of two others).
    pub(super) fn update(
        &mut self,
        copy: &WorldCopy,
        contacts: &[ToolContactState],
        which: &[bool; MAX_OBJECTS],
    ) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let n = copy.len();
        for k in (0..n).filter(|&k| which[k]) {
            let s = &copy.objects()[k].state;
            self.pos[k] = s.pos;
            self.speed[k] = s.vel.norm();
            let mut bits = 0u8;
            for j in 0..MAX_SITES {
                bits |= u8::from(contacts[k * MAX_SITES + j].touching()) << j;
            }
            self.tools[k] = bits;
        }
        for i in 0..n {
            for j in i + 1..n {
                if which[i] || which[j] {
                    let p = pair_index(i, j, n);
                    let bit = 1u128 << p;
                    if copy.pairs()[p].touching() {
                        self.pairs |= bit;
                    } else {
                        self.pairs &= !bit;
                    }
                }
            }
        }
    }
}

/// A rollback's re-simulation in progress.
#[derive(Debug, Clone, Copy)]
pub(super) struct Resim {
    /// The tick the rollback re-simulates to (the old history's newest is kept apart).
    pub(super) to: i64,
    /// Whether it steps only the reached objects (every tick of it is in the old history).
    pub(super) islands: bool,
    /// The objects it steps.
    pub(super) reached: [bool; MAX_OBJECTS],
    /// Per site: its input at the last re-simulated tick differed from the old history's.
    pub(super) changed_last: [bool; MAX_SITES],
}

/// How far beyond two bounding spheres an object is taken as within reach, m (plus the motion).
const REACH_MARGIN_M: f64 = 1e-3;

impl TimeWarp {
    /// Starts a rollback's re-simulation from tick `from` to `to` (the copy and the tools are
    /// still the old history's newest: kept apart for the objects it will not reach).
    /// `whole`: every object is stepped (the state at `from` changed, not only inputs; or a
    /// test's forced rollback).
    pub(super) fn begin_resim(&mut self, copy: &WorldCopy, (from, to): (i64, i64), whole: bool) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let islands =
            !whole && self.islands && (from..to).all(|t| self.slots[self.idx(t)].tick == t);
        if islands {
            self.scratch.copy_from(copy);
            self.scratch_tools.copy_from_slice(&self.contacts);
            let all = [true; MAX_OBJECTS];
            self.scratch_sketch.update(copy, &self.contacts, &all);
        }
        self.resim = Some(Resim {
            to,
            islands,
            reached: [false; MAX_OBJECTS],
            changed_last: [false; MAX_SITES],
        });
    }

    /// Ends a rollback's re-simulation: the objects it did not reach take the old history's
    /// newest state, as they would have stepped to it again.
    pub(super) fn end_resim(&mut self, copy: &mut WorldCopy) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let Some(r) = self.resim.take() else { return };
        if !r.islands {
            return;
        }
        let n = copy.len();
        let unreached: [bool; MAX_OBJECTS] = std::array::from_fn(|k| k < n && !r.reached[k]);
        copy.copy_some_from(&self.scratch, &unreached, |i, j| {
            unreached[i] && unreached[j]
        });
        for k in (0..n).filter(|&k| unreached[k]) {
            let m = k * MAX_SITES;
            self.contacts[m..m + MAX_SITES].copy_from_slice(&self.scratch_tools[m..m + MAX_SITES]);
        }
    }

    /// Whether tick `t` is one of a re-simulation that steps only the reached objects.
    pub(super) fn in_islands(&self) -> bool {
        self.resim.is_some_and(|r| r.islands)
    }

    /// Which objects tick `t` of a re-simulation steps (see the module docs), given the old
    /// history's record of the tick and the new one's inputs and tool positions; the newly
    /// reached ones enter `copy` from the old history, and the reached ones are written into the
    /// tick's slot (the others' are the old history's, and stay).
    pub(super) fn reach_objects(
        &mut self,
        world: &World,
        copy: &mut WorldCopy,
        t: i64,
        (old, new): (&Slot, &Slot),
        tips: &[Vec3; MAX_SITES],
    ) -> [bool; MAX_OBJECTS] {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let Some(mut r) = self.resim else {
            return [true; MAX_OBJECTS];
        };
        let was = r.reached;
        let n = copy.len().min(world.bodies().len());
        let bodies = world.bodies();
        let i = self.idx(t);
        let after = t + 1;
        let now = &self.sketches[i];
        let then = if after < r.to {
            &self.sketches[self.idx(after)]
        } else {
            &self.scratch_sketch
        };
        // Where each object is at the tick's start: the new history's if reached before this
        // tick, else the old one's (the same: nothing had reached it).
        let at = |k: usize| {
            if was[k] {
                let s = &copy.objects()[k].state;
                (s.pos, s.vel.norm())
            } else {
                (now.pos[k], now.speed[k])
            }
        };
        for (j, tip) in tips.iter().enumerate().take(self.sites) {
            let changed = old.inputs[j] != new.inputs[j];
            if changed || r.changed_last[j] {
                if old.inputs[j] == UNKNOWN || new.inputs[j] == UNKNOWN {
                    r.reached = [true; MAX_OBJECTS];
                }
                let was_at = position(old.inputs[j]);
                let bit = 1u8 << j;
                for (k, body) in bodies.iter().enumerate().take(n) {
                    if r.reached[k] {
                        continue;
                    }
                    let reach = body.shape.bounding_radius() + self.radii[j] + REACH_MARGIN_M;
                    let (pos, _) = at(k);
                    r.reached[k] = (tip - pos).norm_squared() <= reach * reach
                        || (was_at - pos).norm_squared() <= reach * reach
                        || (now.tools[k] | then.tools[k]) & bit != 0;
                }
            }
            r.changed_last[j] = changed;
        }
        // What the reached objects reach, until nothing more is.
        let touching = now.pairs | then.pairs;
        loop {
            let mut grew = false;
            for a in 0..n {
                for b in 0..n {
                    if !r.reached[a] || r.reached[b] {
                        continue;
                    }
                    let ((pa, va), (pb, vb)) = (at(a), at(b));
                    let reach = bodies[a].shape.bounding_radius()
                        + bodies[b].shape.bounding_radius()
                        + REACH_MARGIN_M
                        + 2.0 * self.dt * (va + vb);
                    let p = pair_index(a.min(b), a.max(b), n);
                    if (pa - pb).norm_squared() <= reach * reach || touching & (1u128 << p) != 0 {
                        r.reached[b] = true;
                        grew = true;
                    }
                }
            }
            if !grew {
                break;
            }
        }
        let len = self.tools_len();
        let (old_now, old_tools_now) = (&self.worlds[i], &self.tools[i * len..(i + 1) * len]);
        // The newly reached enter as the old history has them at this tick (with their contacts
        // among themselves and with the objects still not reached; with the ones reached before,
        // the new history's: apart).
        let newly: [bool; MAX_OBJECTS] = std::array::from_fn(|k| k < n && r.reached[k] && !was[k]);
        copy.copy_some_from(old_now, &newly, |a, b| {
            (newly[a] || newly[b]) && !was[a] && !was[b]
        });
        for k in (0..n).filter(|&k| newly[k]) {
            let m = k * MAX_SITES;
            self.contacts[m..m + MAX_SITES].copy_from_slice(&old_tools_now[m..m + MAX_SITES]);
        }
        // The tick's record: the reached objects' start, and their contacts.
        let reached = r.reached;
        self.worlds[i].copy_some_from(copy, &reached, |a, b| reached[a] || reached[b]);
        self.sketches[i].update(copy, &self.contacts, &reached);
        for k in (0..n).filter(|&k| reached[k]) {
            let m = i * len + k * MAX_SITES;
            self.tools[m..m + MAX_SITES]
                .copy_from_slice(&self.contacts[k * MAX_SITES..(k + 1) * MAX_SITES]);
        }
        self.resim = Some(r);
        reached
    }

    /// Whether the own tool touched object `k` at tick `t` of the old history (an object a
    /// re-simulation did not step): its contact memory at the tick's end, as sketched.
    pub(super) fn touched_before(&self, k: usize, t: i64) -> bool {
        let Some(r) = self.resim else { return false };
        let then = if t + 1 < r.to {
            &self.sketches[self.idx(t + 1)]
        } else {
            &self.scratch_sketch
        };
        then.tools[k] & (1u8 << self.me) != 0
    }

    /// Re-simulates only the objects a changed input reaches (on: the default), or every object
    /// (off: to compare; the same bits either way).
    pub fn set_islands(&mut self, on: bool) {
        self.islands = on;
    }
}
