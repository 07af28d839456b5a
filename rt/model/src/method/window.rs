//! Which own ticks a track carries: the new ones, and the last few reports' again (`timewarp`
//! and `coupled` alike).
//!
//! A track used to carry the last [`WINDOW_TICKS`] ticks every time, so that a few lost tracks
//! lost nothing: at 1 kHz physics and 90 Hz reports that sends every tick 23 times. Now a track
//! carries the ticks since the previous report and those of the [`Redundancy::reports`] reports
//! before it (a tick goes out `reports + 1` times). A loss longer than that leaves a gap. A
//! `timewarp` receiver holds later ticks around it: it asks for it ([`ToolReport::need`]) and gets
//! it in a repair, a round trip later at best, and the confirmed frontier waits for it: a repair
//! must stay the exception. A `coupled` receiver plays the tool on from the last position it had
//! (its jitter buffer holds it). So the redundancy follows the loss the receivers measure (each
//! track says what share of each site's tracks its sender found lost, RTCP's receiver report in
//! one byte): at the worst receiver's loss `p`, as many reports as make a gap (`reports + 1`
//! tracks lost in a row) rarer than [`GAP_CHANCE`] per track, from [`MIN_REDUNDANCY`] to
//! [`MAX_REDUNDANCY`] (at `p` = 0.3, all 7). Each new gap asked for besides adds one report (a
//! loss the measurement has not caught up with), shed after [`REDUNDANCY_DECAY_REPORTS`] reports
//! without one. `timewarp`'s confirmed states do not depend on it: every tick's position arrives
//! once, however it travels.
//!
//! [`ToolReport::need`]: super::track::ToolReport::need

use std::cell::Cell;

use super::track::WINDOW_TICKS;
use crate::world::MAX_SITES;

/// The fewest reports a track sends again (a single lost track then never makes a gap).
pub const MIN_REDUNDANCY: usize = 1;
/// The most reports a track sends again.
pub const MAX_REDUNDANCY: usize = 7;
/// Reports in a row with no new gap asked for, after which the redundancy shrinks by one.
pub const REDUNDANCY_DECAY_REPORTS: u32 = 256;
/// The chance per track of a gap the redundancy is sized for at the measured loss.
pub const GAP_CHANCE: f64 = 1e-4;
/// The weight of each track in a receiver's loss measurement (about the last 32 count).
pub const LOSS_FILTER_SHARE: f64 = 1.0 / 32.0;

/// The ends of the last tracks sent (newest first) and how many of them to send again.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Redundancy {
    /// The first tick after each of the last `MAX_REDUNDANCY + 1` windows of the newest ticks
    /// sent (newest first; `i64::MIN`: none). A repair is not one of them: the next window
    /// covers what it left out.
    ends: [i64; MAX_REDUNDANCY + 1],
    /// How many reports before the newest a track sends again for the gaps asked for...
    reports: usize,
    /// ...and for the loss the receivers measure (`loss`, in 255ths).
    for_loss: usize,
    loss: u8,
    /// Reports since the last new gap was asked for.
    quiet: u32,
}

impl Redundancy {
    /// Nothing sent yet.
    pub const START: Self = Self {
        ends: [i64::MIN; MAX_REDUNDANCY + 1],
        reports: MIN_REDUNDANCY,
        for_loss: MIN_REDUNDANCY,
        loss: 0,
        quiet: 0,
    };

    /// How many reports before the newest a track sends again.
    pub fn reports(&self) -> usize {
        self.reports.max(self.for_loss)
    }

    /// The worst receiver loses `share` 255ths of this site's tracks.
    pub fn set_loss(&mut self, share: u8) {
        if share == self.loss {
            return;
        }
        self.loss = share;
        let loss = f64::from(share) / 255.0;
        // The fewest k with loss^(k + 1) ≤ GAP_CHANCE.
        self.for_loss = if loss > 0.0 {
            let k = (GAP_CHANCE.ln() / loss.min(0.99).ln()).ceil() - 1.0;
            (k.max(0.0) as usize).clamp(MIN_REDUNDANCY, MAX_REDUNDANCY)
        } else {
            MIN_REDUNDANCY
        };
    }

    /// The first tick of a window of the newest ticks ending before `end`, at or after `floor`
    /// (the first tick this site's history has): the end of the window `reports + 1` tracks back,
    /// and never more than [`WINDOW_TICKS`] before `end`.
    pub fn window_start(&self, end: i64, floor: i64) -> i64 {
        self.ends[self.reports()]
            .max(end - WINDOW_TICKS as i64)
            .max(floor)
            .min(end)
    }

    /// A window of the newest ticks up to `end` was sent.
    pub fn sent(&mut self, end: i64) {
        self.ends.copy_within(..MAX_REDUNDANCY, 1);
        self.ends[0] = end;
        self.quiet = self.quiet.saturating_add(1);
        if self.quiet >= REDUNDANCY_DECAY_REPORTS && self.reports > MIN_REDUNDANCY {
            self.reports -= 1;
            self.quiet = 0;
        }
    }

    /// A receiver asked for a gap it had not asked for before: the tracks lost in a row were
    /// more than the redundancy covered.
    pub fn gap_asked(&mut self) {
        self.reports = (self.reports + 1).min(MAX_REDUNDANCY);
        self.quiet = 0;
    }
}

/// A site's own tracks and the loss both ways, as `timewarp` and `coupled` keep them: the window
/// of the own ticks a track carries ([`Redundancy`], sized for the worst loss the receivers say),
/// each partner's tracks this site loses ([`LossMeter`]), and the share of this site's tracks
/// each partner says it loses.
#[derive(Debug, Clone)]
pub struct Tracks {
    /// (A cell: a report is made from a method's shared view, and counts its window as sent.)
    sent: Cell<Redundancy>,
    lost: [LossMeter; MAX_SITES],
    losing: [u8; MAX_SITES],
}

impl Tracks {
    /// Nothing sent or heard yet.
    pub fn new() -> Self {
        Self {
            sent: Cell::new(Redundancy::START),
            lost: [LossMeter::default(); MAX_SITES],
            losing: [0; MAX_SITES],
        }
    }

    /// A track numbered `seq` arrived from site `from`, which says it loses `share` (255ths) of
    /// this site's: that site's loss measured, and the window sized for the worst receiver.
    pub fn heard(&mut self, from: usize, seq: u64, share: u8) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let (Some(m), Some(l)) = (self.lost.get_mut(from), self.losing.get_mut(from)) else {
            return;
        };
        m.arrived(seq);
        *l = share;
        let worst = self.losing.iter().copied().max().unwrap_or(0);
        self.sent.get_mut().set_loss(worst);
    }

    /// A receiver asked for a gap it had not asked for before ([`Redundancy::gap_asked`]).
    pub fn gap_asked(&mut self) {
        self.sent.get_mut().gap_asked();
    }

    /// The first tick of the next track's window of the newest ticks, up to `end` and from
    /// `floor` on ([`Redundancy::window_start`]), counted as sent.
    pub fn next_window(&self, end: i64, floor: i64) -> i64 {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let mut sent = self.sent.get();
        let first = sent.window_start(end, floor);
        sent.sent(end);
        self.sent.set(sent);
        first
    }

    /// Per site, the share of its tracks this site loses, 255ths (a track's `loss`).
    pub fn shares(&self) -> [u8; MAX_SITES] {
        std::array::from_fn(|j| self.lost[j].share())
    }

    /// How many reports before the newest a track sends again now.
    pub fn reports(&self) -> usize {
        self.sent.get().reports()
    }

    /// Site `from` fell silent: the tracks it skipped meanwhile are not a loss rate, so its loss
    /// is measured afresh.
    pub fn peer_lost(&mut self, from: usize) {
        if let Some(m) = self.lost.get_mut(from) {
            *m = LossMeter::default();
        }
    }
}

impl Default for Tracks {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_covers_the_newest_reports_and_grows_with_gaps_asked_for() {
        let mut r = Redundancy::START;
        // Nothing sent yet: the whole window (from the history's start).
        assert_eq!(r.window_start(100, 0), 0);
        assert_eq!(r.window_start(1000, 0), 1000 - WINDOW_TICKS as i64);
        for end in [11, 22, 33] {
            r.sent(end);
        }
        // The newest ticks and the last report's again.
        assert_eq!(r.window_start(44, 0), 22);
        r.gap_asked();
        assert_eq!(r.reports(), 2);
        assert_eq!(r.window_start(44, 0), 11);
        for _ in 0..10 {
            r.gap_asked();
        }
        assert_eq!(r.reports(), MAX_REDUNDANCY);
        // Never more than a track holds.
        for k in 0..8 {
            r.sent(1000 + 100 * k);
        }
        assert_eq!(r.window_start(1800, 0), 1800 - WINDOW_TICKS as i64);
        // Quiet reports shrink it, one report per period, to the least.
        for _ in 0..REDUNDANCY_DECAY_REPORTS {
            r.sent(2000);
        }
        assert_eq!(r.reports(), MAX_REDUNDANCY - 1);
        for _ in 0..REDUNDANCY_DECAY_REPORTS * 20 {
            r.sent(2000);
        }
        assert_eq!(r.reports(), MIN_REDUNDANCY);
        // A measured loss sizes it by itself: 0.3 needs every report (0.3^8 < 1e-4), 0.1 four
        // (0.1^4), 1 % two (0.01^2).
        for (loss, reports) in [(0.3, 7), (0.1, 3), (0.01, 1), (0.0, 1), (1.0, 7)] {
            r.set_loss((loss * 255.0) as u8);
            assert_eq!(r.reports(), reports, "at {loss}");
        }
    }
}

/// A receiver's measure of the share of a sender's reports it loses: a sequence number is judged
/// once it is [`REORDER_DEPTH`] behind the newest (a report overtaken by a later one is late, not
/// lost), as lost if it never came, weighted [`LOSS_FILTER_SHARE`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LossMeter {
    newest: u64,
    /// Bit `i`: report `newest - i` arrived.
    seen: u64,
    loss: f64,
}

/// How far behind the newest a report may still arrive without counting as lost.
pub const REORDER_DEPTH: u64 = 8;

impl LossMeter {
    /// A report numbered `seq` (0: not numbered, not counted) arrived.
    pub fn arrived(&mut self, seq: u64) {
        if seq == 0 {
            return;
        }
        if self.newest == 0 || seq <= self.newest {
            if self.newest == 0 {
                (self.newest, self.seen) = (seq, 1);
            } else if self.newest - seq < 64 {
                self.seen |= 1 << (self.newest - seq);
            }
            return;
        }
        let d = seq - self.newest;
        // Those now REORDER_DEPTH behind for the first time: the window's...
        let (mut judged, mut lost) = (0u64, 0u64);
        for i in REORDER_DEPTH.saturating_sub(d)..REORDER_DEPTH {
            judged += 1;
            lost += u64::from(self.seen >> i & 1 == 0);
        }
        // ...and those skipped that are already that far behind.
        let skipped = d.saturating_sub(REORDER_DEPTH);
        judged += skipped;
        lost += skipped;
        self.seen = if d >= 64 { 0 } else { self.seen << d } | 1;
        self.newest = seq;
        let keep = 1.0 - LOSS_FILTER_SHARE;
        let (lost, kept) = (
            lost.min(1 << 20) as i32,
            (judged - lost).min(1 << 20) as i32,
        );
        self.loss = (1.0 - (1.0 - self.loss) * keep.powi(lost)) * keep.powi(kept);
    }

    /// The share lost, in 255ths.
    pub fn share(&self) -> u8 {
        (self.loss * 255.0).round().clamp(0.0, 255.0) as u8
    }
}

#[cfg(test)]
mod meter_tests {
    use super::*;

    #[test]
    fn a_receiver_measures_the_share_of_reports_lost() {
        let mut m = LossMeter::default();
        for s in 1..=500 {
            m.arrived(s);
        }
        assert_eq!(m.share(), 0);
        // Every third lost.
        for s in (501..5000).filter(|s| s % 3 != 0) {
            m.arrived(s);
        }
        let share = f64::from(m.share()) / 255.0;
        assert!((share - 1.0 / 3.0).abs() < 0.05, "{share}");
        // Unnumbered, duplicated, long late: not counted.
        let before = m.share();
        for s in [0, 4999, 4000] {
            m.arrived(s);
        }
        assert_eq!(m.share(), before);
        // Overtaken by one or two later ones, every report (…, 3, 1, 2, 6, 4, 5, …): none lost.
        let mut m = LossMeter::default();
        for k in 0..2000u64 {
            m.arrived(1 + 3 * (k / 3) + [2, 0, 1][(k % 3) as usize]);
        }
        assert_eq!(m.share(), 0);
    }
}
