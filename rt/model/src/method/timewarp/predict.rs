//! Where a remote tool is at a tick no position of it has arrived for: extrapolated a little
//! while it touches the object, a slowing reach while it is free, then held.

use super::*;

/// A remote tool that touched the object at its last known tick is extrapolated with its last
/// velocity (through a perceptual deadband, that between its last two samples:
/// [`SAMPLE_VELOCITY_TICKS`]) for at most this many ticks, then held: the contact, not the hand's
/// motion, decides where it goes next (the hand's force balance against the object cannot be
/// predicted, and a tool predicted on into the object pushes it through the grasp: at 150 ms the
/// copies then disagree by centimetres while both users hold the disk).
pub const EXTRAPOLATE_TICKS: i64 = 20;

/// A remote tool that was free at its last known tick is predicted as a reaching hand: on with its
/// mean velocity over this many ticks (the last 10 ms: through the quantization and the sensor's
/// noise)...
pub const REACH_VELOCITY_TICKS: i64 = 10;

/// ...slowing as a reach does, so that `h` ticks on it has gone `v·h·τ/(h+τ)`, never farther than
/// `v·τ` (τ this many ticks, 0.3 s at 1 kHz; rational, not exponential: only `+ − × ÷`). Over a
/// delay a free tool crosses, this shows a push in the copy before the pushing tool's positions
/// arrive, so a far user feels the pushed object arrive when it does: the paper task at a constant
/// 300 ms passes all 12 phases with it, 10 without (seeds 1–3).
pub const REACH_TIME_TICKS: i64 = 300;

/// How long a reach is predicted before the tool is held, ticks.
pub const REACH_TICKS: i64 = 1000;

/// Through a perceptual deadband a remote tool's velocity is that between its last two samples
/// (the first ticks of its last two held runs), each run looked for at most this many ticks back
/// from its own end (a run longer than that is a tool at rest: slower than a free-space band in
/// this time, 31 mm/s at 2 mm and 1 kHz). Over the last [`REACH_VELOCITY_TICKS`] a held run says
/// 0, or one jump of a band: a free tool's reach predicted from it overshot or stopped, and at
/// 100–200 ms the copies showed a push that was not the partner's (paper task, seeds 1–4 and 7:
/// every servo tick's force within one JND of the full-rate run for 83–97 % of ticks, then
/// 92–98 %); a tool in contact extrapolated with a band's jump was pushed up to 20 bands into the
/// object, and held it lagged a partner pressing on (with every site's tool replayed from the
/// full-rate run, within one JND at 200 ms: held 88.0–91.6 %, on at this velocity 90.6–95.3 %).
pub const SAMPLE_VELOCITY_TICKS: i64 = 64;

impl TimeWarp {
    /// The received position of site `j` at tick `t`, if it is kept.
    pub(super) fn received_at(&self, j: usize, t: i64) -> Option<Quantized> {
        self.received[self.idx(t)][j]
            .filter(|(tick, _)| *tick == t)
            .map(|(_, q)| q)
    }

    /// The input of site `j` at tick `t`: received, or predicted from its last known positions.
    pub(super) fn input(&self, j: usize, t: i64) -> (Quantized, bool) {
        if let Some(q) = self.received_at(j, t) {
            return (q, true);
        }
        // In a gap, predicted on from before it (as it was live); past the newest, from that.
        let last = if t < self.newest[j] {
            self.known_until[j]
        } else {
            self.newest[j]
        };
        let Some(p) = self.received_at(j, last) else {
            // Nothing known yet (or only what left the horizon): where it was last used.
            let prev = &self.slots[self.idx(t - 1)];
            let q = if prev.tick == t - 1 {
                prev.inputs[j]
            } else {
                UNKNOWN
            };
            return (q, false);
        };
        let at = |t: i64| self.received_at(j, t);
        let at_last = &self.slots[self.idx(last)];
        let free = at_last.tick == last && !Self::touches(self.tools_at(self.idx(last)), j);
        if free {
            // Its mean velocity over the last REACH_VELOCITY_TICKS; through a deadband, that
            // between its last two samples.
            let (step, stop) = match self.deadband {
                None => (
                    at(last - REACH_VELOCITY_TICKS).map(|p0| (p, p0, REACH_VELOCITY_TICKS)),
                    self.stop_ticks(j, last, p),
                ),
                Some(_) => (self.sampled_step(j, last, p), f64::INFINITY),
            };
            return (self.reach(p, step, t - last, stop), false);
        }
        // Through a perceptual deadband (the scenario's: every site runs it) a tool's positions
        // are held runs, and the last step is a jump of a band in one tick, not a velocity:
        // extrapolated, it pushed the predicted tool up to 20 bands into the object. The
        // velocity is that between the tool's last two samples instead, as for a free tool.
        let step = match self.deadband {
            None => at(last - 1).map(|p0| (p, p0, 1)),
            Some(_) => self.sampled_step(j, last, p),
        };
        let k = (t - last).clamp(0, EXTRAPOLATE_TICKS);
        (step.map_or(p, |s| along(p, s, k)), false)
    }

    /// Site `j`'s last step between deadband samples, its tool last known at `p` at tick `last`:
    /// `(to, from, ticks)`, the tool having gone from `from` to `to` in `ticks` ticks, at the
    /// velocity between its last two samples ([`SAMPLE_VELOCITY_TICKS`]; at rest, no way in one
    /// tick); `None` where no earlier sample is known.
    fn sampled_step(
        &self,
        j: usize,
        last: i64,
        p: Quantized,
    ) -> Option<(Quantized, Quantized, i64)> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls (at most
        // 2 × SAMPLE_VELOCITY_TICKS lookups).
        let at = |t: i64| self.received_at(j, t);
        // The first tick of the run of `q` that ends at `end`, if it began at most
        // SAMPLE_VELOCITY_TICKS before (else the tool is taken to rest).
        let run_start = |q: Quantized, end: i64| {
            let mut s = end;
            while at(s - 1) == Some(q) {
                if s <= end - SAMPLE_VELOCITY_TICKS {
                    return None;
                }
                s -= 1;
            }
            Some(s)
        };
        let at_rest = Some((p, p, 1));
        let Some(sample) = run_start(p, last) else {
            return at_rest;
        };
        let before = at(sample - 1)?;
        let Some(previous) = run_start(before, sample - 1) else {
            return at_rest;
        };
        Some((p, before, (sample - previous).max(1)))
    }

    /// How many ticks of its present velocity a slowing free tool, last known at `p` at tick
    /// `last`, has left before it stops: `v / 2a`, its speed over its deceleration along its
    /// way, each from its mean velocities over the last two windows of
    /// [`REACH_VELOCITY_TICKS`] (a stop at constant deceleration: for a minimum-jerk reach,
    /// within a few millimetres of its end point over the reach's last fifth, ahead of it before).
    /// Infinite for a tool that is not slowing or whose positions are not known that far back.
    ///
    /// A reach that slows to stop short of an object is predicted to stop there, not to glide on
    /// into it: gliding, the prediction pushed objects a waiting partner's real tool never
    /// touched, and the rollback took the push back a delay later (a phantom push, seen and
    /// felt).
    fn stop_ticks(&self, j: usize, last: i64, p: Quantized) -> f64 {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let w = REACH_VELOCITY_TICKS;
        let at = |t: i64| self.received_at(j, t);
        let (Some(p1), Some(p0)) = (at(last - w), at(last - 2 * w)) else {
            return f64::INFINITY;
        };
        let wf = w as f64;
        let v1: [f64; 3] = std::array::from_fn(|k| f64::from(p[k].saturating_sub(p1[k])) / wf);
        let v0: [f64; 3] = std::array::from_fn(|k| f64::from(p1[k].saturating_sub(p0[k])) / wf);
        let speed = (v1[0] * v1[0] + v1[1] * v1[1] + v1[2] * v1[2]).sqrt();
        if speed == 0.0 {
            return f64::INFINITY;
        }
        let along = (0..3).map(|k| (v1[k] - v0[k]) / wf * v1[k]).sum::<f64>() / speed;
        if along >= 0.0 {
            return f64::INFINITY;
        }
        speed / (2.0 * -along)
    }

    /// A free remote tool `h` ticks after it was last known at `p`, at the velocity of `step`,
    /// `(to, from, ticks)` (see [`along`]): see [`REACH_TIME_TICKS`]; a slowing one goes no
    /// farther than `stop` ticks of that velocity ([`Self::stop_ticks`]). Held where nothing
    /// earlier is known.
    pub(super) fn reach(
        &self,
        p: Quantized,
        step: Option<(Quantized, Quantized, i64)>,
        h: i64,
        stop: f64,
    ) -> Quantized {
        let Some((to, from, ticks)) = step else {
            return p;
        };
        let h = h.clamp(0, REACH_TICKS) as f64;
        let tau = REACH_TIME_TICKS as f64;
        // Quanta per tick: one division of the whole distance.
        let v: [f64; 3] =
            std::array::from_fn(|k| f64::from(to[k].saturating_sub(from[k])) / ticks.max(1) as f64);
        let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let max = MAX_TOOL_SPEED_M_PER_S * self.dt / QUANTUM_M;
        let scale = if speed > max { max / speed } else { 1.0 };
        let gone = (h * tau / (h + tau)).min(stop) * scale;
        let q = |k: usize| {
            let d = (v[k] * gone).round().clamp(-2e9, 2e9) as i32;
            p[k].saturating_add(d)
        };
        [q(0), q(1), q(2)]
    }
}

/// `p` moved on `k` ticks (back, for a negative `k`) at the velocity of `step`, `(to, from,
/// ticks)`: one division of the whole distance, so a slow step of a few quanta over tens of ticks
/// keeps its velocity.
fn along(p: Quantized, (to, from, ticks): (Quantized, Quantized, i64), k: i64) -> Quantized {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    std::array::from_fn(|c| {
        let d = (i64::from(to[c]) - i64::from(from[c])) * k / ticks;
        (i64::from(p[c]) + d).clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
    })
}
