//! A contact the own user missed, replayed to them late while their hand is still there (see
//! the module docs).

use super::*;

/// A contact the own user missed (see the module docs) is replayed at this many times
/// its speed (the contact itself at its own) until the display catches up with the copy: a
/// replay of `d` ticks of history ends about `d / (REPLAY_SPEED - 1)` ticks later (250 ms after
/// a 500 ms delay's news).
pub const REPLAY_SPEED: i64 = 3;

/// A replay slows to the history's own pace this many ticks before a contact in it, so the
/// object meets the hand as fast as it did (no harder).
pub const REPLAY_SLOW_TICKS: i64 = 10;

/// A replay starts this many ticks before the missed contact, so the user sees the object come.
pub const REPLAY_LEAD_TICKS: i64 = 40;

/// A replay starts only while the own tool is within this of where the missed contact had it,
/// and ends when it moves farther: the history replayed is one in which the hand was there, m.
pub const REPLAY_REACH_M: f64 = 0.002;

/// ... and only for a missed contact of at least this many ticks.
pub const REPLAY_MIN_TICKS: u64 = 3;

impl TimeWarp {
    /// After a rollback from `from`: when the re-simulated history has the own tool touching the
    /// object where the live simulation had not (a contact the user missed: the news of a remote
    /// push came after the object had reached the hand), no tool touches the object now, and the
    /// own tool is still where it was then, the user is shown that history from a little before the contact
    /// on, sped up ([`REPLAY_SPEED`]), until it catches up with the copy.
    pub(super) fn replay_missed_contact(&mut self, from: i64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        // Only a free object's knock: in a grasp (another tool on the object) the history
        // replayed would be felt against hands that are all moving on.
        let touched_now = self.contacts.iter().any(|c| c.touching());
        if self.replay.is_some() || touched_now {
            return;
        }
        let start = from.max(self.replayed_until).max(self.oldest_kept());
        let mut first = None;
        let mut missed = 0;
        for t in start..self.now_tick {
            let s = &self.slots[self.idx(t)];
            if s.tick == t && s.touched && !s.felt {
                first = first.or(Some(t));
                missed += 1;
            }
        }
        let Some(first) = first.filter(|_| missed >= REPLAY_MIN_TICKS) else {
            return;
        };
        let then = self.slots[self.idx(first)].inputs[self.me];
        self.replayed_until = self.now_tick;
        if (position(self.own) - position(then)).norm() > REPLAY_REACH_M {
            return;
        }
        self.replay = Some(((first - REPLAY_LEAD_TICKS).max(start), then));
        self.stats.replays += 1;
    }

    /// One live tick on: a replay advances [`REPLAY_SPEED`] ticks, and ends once it reaches the
    /// copy, when the own tool touches the copy (the user feels what is now), or when the tool
    /// has moved away from where the replayed history had it.
    pub(super) fn advance_replay(&mut self) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let Some((mut t, then)) = self.replay else {
            return;
        };
        // Fast up to the contact, at its own pace into and through it (the user feels the
        // contact as the history had it, not harder).
        t += self.replay_speed(t);
        let kept = self.slots[self.idx(t)].tick == t;
        let away = (position(self.own) - position(then)).norm() > REPLAY_REACH_M;
        self.replay =
            (t < self.now_tick && kept && !away && !Self::touches(&self.contacts, self.me))
                .then_some((t, then));
    }

    /// How many ticks of history a live tick replays from tick `t` on: one while the own tool
    /// touches the object in it or is about to ([`REPLAY_SLOW_TICKS`]), [`REPLAY_SPEED`]
    /// otherwise.
    pub(super) fn replay_speed(&self, t: i64) -> i64 {
        let near = (t..=t + REPLAY_SLOW_TICKS).any(|u| {
            let s = &self.slots[self.idx(u)];
            s.tick == u && s.touched
        });
        if near {
            1
        } else {
            REPLAY_SPEED
        }
    }
}
