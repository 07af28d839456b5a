//! Local lag: the own tool's measured positions enter the physics late by a share of a near
//! partner's delay (see the module docs).

use super::*;

/// Local lag (Mauve et al. 2004's companion of timewarp): while the own tool and another site's
/// are both within this of the object's surface, the own tool's positions enter the physics late
/// by [`LOCAL_LAG_SHARE`] of that site's measured delay, m.
pub const LOCAL_LAG_NEAR_M: f64 = 0.01;

/// The share of the nearby partners' (largest) measured one-way delay the own tool is delayed by.
/// The copy then holds the own tool and the partners' newest known positions nearer the same
/// moment (the partners' are predicted as far ahead as before: the own positions are sent as they
/// are stepped): a three-user carry at 200 ms, whose users' hands each react to the disk a delay
/// late, does every phase in 23 of 24 seeds instead of 11 (the 3-D three-user lift in 18 instead
/// of 0).
pub const LOCAL_LAG_SHARE: f64 = 0.5;

/// The most the own tool is delayed by, ticks (100 ms at 1 kHz): beyond it a lag costs the
/// single-user parts of a task more than it saves (the 3-D lift at 300 ms fails with 150).
pub const LOCAL_LAG_MAX_TICKS: i64 = 100;

/// How the lag changes, in half ticks of the own tool's measured positions per tick: it grows by
/// playing them at half speed (a position between two measured ones at the odd half ticks) and
/// shrinks by playing them at twice the speed, the latter only while the own tool touches nothing
/// (a hand in contact is never fast-forwarded into the object; it may be slowed).
pub(super) const LAG_GROW_HALF_TICKS: i64 = 1;

pub(super) const LAG_SHRINK_HALF_TICKS: i64 = 4;

/// ... and within these of its target (half ticks) it stays (a measured delay jitters; none
/// above it when no lag is wanted): it settles up to a tick below its target.
pub(super) const LAG_SLACK_BELOW_HALF_TICKS: i64 = 2;

pub(super) const LAG_SLACK_ABOVE_HALF_TICKS: i64 = 20;

/// The largest local lag, ticks ([`TimeWarp::set_local_lag`]): 200 ms at the fastest physics
/// rate a scenario may have (20 kHz).
pub const MAX_LOCAL_LAG_TICKS: i64 = 4000;

/// The own tool's measured positions kept for the lag (a power of two above the largest lag and
/// its slack, in ticks).
pub(super) const MEASURED_RING: usize = 4096;

const _: () =
    assert!(MEASURED_RING as i64 > MAX_LOCAL_LAG_TICKS + LAG_SLACK_ABOVE_HALF_TICKS / 2 + 1);

/// A partner's measured one-way delay follows each report's by this share (a low-pass filter).
pub(super) const DELAY_FILTER_SHARE: f64 = 0.125;

impl TimeWarp {
    /// Lags the own tool by `share` (0 to 1; 0: never) of a near partner's delay, at most
    /// `max_ticks` (up to [`MAX_LOCAL_LAG_TICKS`]); [`LOCAL_LAG_SHARE`] and
    /// [`LOCAL_LAG_MAX_TICKS`] unless set.
    pub fn set_local_lag(&mut self, share: f64, max_ticks: i64) {
        self.lag_share = if share.is_finite() {
            share.clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.lag_max = max_ticks.clamp(0, MAX_LOCAL_LAG_TICKS);
    }

    /// The local lag wanted from the next tick on: the configured share of the largest measured
    /// delay of the sites whose tools (as last simulated) are within [`LOCAL_LAG_NEAR_M`] of the
    /// object while the own tool (as measured) is too; none otherwise.
    pub(super) fn want_lag(&mut self, world: &World, copy: &WorldCopy) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let near = |q: Quantized, radius: f64| {
            q != UNKNOWN
                && copy.objects().iter().zip(world.bodies()).any(|(o, b)| {
                    let body = &o.state;
                    b.shape
                        .signed_distance(body.rot.inverse() * (position(q) - body.pos))
                        .0
                        - radius
                        <= LOCAL_LAG_NEAR_M
                })
        };
        let measured = self.measured[(self.measured_count - 1).max(0) as usize % MEASURED_RING];
        let last = &self.slots[self.idx(self.now_tick - 1)];
        let mut delay: f64 = 0.0;
        if self.measured_count > 0
            && last.tick == self.now_tick - 1
            && near(measured, self.radii[self.me])
        {
            for j in (0..self.sites).filter(|&j| j != self.me) {
                if near(last.inputs[j], self.radii[j]) {
                    delay = delay.max(self.delay_ticks[j]);
                }
            }
        }
        self.lag_target = ((delay * self.lag_share) as i64).clamp(0, self.lag_max);
    }

    /// The own tool measured at `tool_pos` for the tick about to be stepped: the play head moves
    /// towards the lag wanted, and the own input is the measured position under it.
    pub(super) fn play_own(&mut self, tool_pos: Vec3) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let n = self.measured_count;
        self.measured[n as usize % MEASURED_RING] = quantize(tool_pos);
        self.measured_count = n + 1;
        // The lag in half ticks if the play head moves on at the measured pace, and the step of
        // the play head towards the one wanted.
        let (now, want) = (2 * n, 2 * self.lag_target);
        let lag = (now - self.play_head - 2).max(0);
        let above = if want == 0 {
            0
        } else {
            LAG_SLACK_ABOVE_HALF_TICKS
        };
        let step = if lag < want - LAG_SLACK_BELOW_HALF_TICKS {
            LAG_GROW_HALF_TICKS
        } else if lag > want + above && !Self::touches(&self.contacts, self.me) {
            LAG_SHRINK_HALF_TICKS
        } else {
            2
        };
        self.play_head = (self.play_head + step).min(now);
        let at = |k: i64| self.measured[k as usize % MEASURED_RING];
        let k = self.play_head / 2;
        self.own = if self.play_head % 2 == 0 {
            at(k)
        } else {
            // Half-way between two measured positions (k + 1 <= n: the head is below `now`).
            let (a, b) = (at(k), at(k + 1));
            std::array::from_fn(|i| ((i64::from(a[i]) + i64::from(b[i])) / 2) as i32)
        };
        // How late the input is: whole ticks, a half rounded up.
        let lag = ((now - self.play_head + 1) / 2).unsigned_abs();
        self.stats.local_lag_ticks = lag;
        self.stats.max_local_lag_ticks = self.stats.max_local_lag_ticks.max(lag);
        self.stats.lagged_ticks += u64::from(lag > 0);
    }
}
