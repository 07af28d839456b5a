//! One servo tick in Cartesian space, as the station's servo loop and the simulator both run it: from
//! the tool's position and velocity in the world (the device's sample through the station's
//! placement; for the SCARA arm, Eq. 5), the contact with the newest object state (Eq. 7) and the
//! force to display at the hand (Eq. 6); and two safety rules. The device then displays that force:
//! the simulated SCARA arm through its own Eq. 12 PI loop ([`crate::device::ScaraForceLoop`]), a
//! vendor device open-loop.
//!
//!
//! - **Stale world.** If the newest object state is older than the stale limit (physics or network
//!   stopped), or the station is stopping, the displayed force ramps linearly to zero over the ramp time and stays there until
//!   fresh states return, then ramps back. The commanded force and torques ramp with it, so the
//!   device goes limp rather than holding a force against the hand.
//! - **Display continuity and passivity** ([`crate::display`]). Physics always gets the contact with
//!   the copy where it really is (so the copy's dynamics stay consistent); the *displayed* force is
//!   the contact with a displayed object that absorbs a correction (adoption, rollback, pull) and
//!   converges to the copy smoothly, stepped by at most the limiter's allowance per tick, with a
//!   passivity controller adding damping when the display's deviation from the simulated contact
//!   would inject energy into the user.

use crate::body::{BodyState, Vec3};
use crate::contact::{tool_contact, ContactForce, ContactParams, ToolContactState};
use crate::display::{
    DisplayParams, DisplayStats, DisplayedObject, PassivityObserver, StepLimiter,
};
use crate::world::{Body, MAX_OBJECTS};

/// Servo parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoParams {
    /// Radius of the virtual tool's tip, m.
    pub tool_radius_m: f64,
    /// Tool–object contact law.
    pub contact: ContactParams,
    /// Object states older than this are stale, s.
    pub stale_limit_s: f64,
    /// Time to ramp the displayed force to zero (and back), s.
    pub stale_ramp_s: f64,
    /// The longest tick the ramp back counts, s: a later tick (a stall, the first of a study's
    /// next trial) ramps in as if it were this long ([`ramp_in_tick_s`] of the servo's rate).
    pub max_ramp_in_tick_s: f64,
    /// Largest displayed-force change per tick an adoption may cause, N (with the display stages
    /// off).
    pub max_adoption_step_n: f64,
    /// Display continuity and passivity.
    pub display: DisplayParams,
}

/// What a servo tick reads.
#[derive(Debug, Clone, Copy)]
pub struct ServoInput<'a> {
    /// Now, s.
    pub now_s: f64,
    /// Tick length, s.
    pub dt_s: f64,
    /// Tool position, world, m.
    pub tool_pos: Vec3,
    /// Tool velocity, world, m/s.
    pub tool_vel: Vec3,
    /// Newest state of each object of the world, in its order.
    pub objects: &'a [BodyState],
    /// Its time, s.
    pub object_time_s: f64,
    /// Whether physics adopted a remote state since the last tick (for the bounded adoption step
    /// with the display stages off).
    pub adopted: bool,
    /// A cooperative stop was requested: ramp the display to zero as for a stale world.
    pub stopping: bool,
}

/// What a servo tick produces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoOutput {
    /// Desired force at the hand F_h (the display stages' output after the stale ramp), world, N.
    pub f_desired: Vec3,
    /// The force the copy's own contact puts on the hand after the stale ramp (what F_h would be
    /// without the display stages), world, N.
    pub f_simulated: Vec3,
    /// The tool's contact on each object (force on the object), for physics; past the world's
    /// objects, none.
    pub contacts: [ContactForce; MAX_OBJECTS],
    /// Tool position, world.
    pub tool_pos: Vec3,
    /// Tool velocity, world.
    pub tool_vel: Vec3,
    /// Display scale: 1 fresh, 0 stale (a device with its own force loop scales its output by it).
    pub scale: f64,
}

/// The longest tick the display's ramp-in counts at rates of 300 Hz and above, s: a tick later
/// than this (a stalled servo, the first of a study's next trial) ramps in as if it were this
/// long. Ramping out is never slowed.
pub const MAX_RAMP_IN_TICK_S: f64 = 0.005;

/// [`ServoParams::max_ramp_in_tick_s`] for a servo at `rate_hz`: [`MAX_RAMP_IN_TICK_S`], or one
/// and a half periods of a slower servo (whose every tick would be longer).
pub fn ramp_in_tick_s(rate_hz: f64) -> f64 {
    (1.5 / rate_hz).max(MAX_RAMP_IN_TICK_S)
}

/// A servo loop's state.
#[derive(Debug, Clone, PartialEq)]
pub struct Servo {
    /// Parameters.
    pub params: ServoParams,
    contact: [ToolContactState; MAX_OBJECTS],
    scale: f64,
    displayed: [DisplayedObject; MAX_OBJECTS],
    display_contact: [ToolContactState; MAX_OBJECTS],
    limiter: StepLimiter,
    observer: PassivityObserver,
    stats: DisplayStats,
    blend: Vec3,
    last_display: Vec3,
}

impl Servo {
    /// A servo with `params`.
    pub fn new(params: ServoParams) -> Self {
        Self {
            params,
            contact: [ToolContactState::default(); MAX_OBJECTS],
            scale: 1.0,
            displayed: [DisplayedObject::default(); MAX_OBJECTS],
            display_contact: [ToolContactState::default(); MAX_OBJECTS],
            limiter: StepLimiter::default(),
            observer: PassivityObserver::default(),
            stats: DisplayStats::default(),
            blend: Vec3::zeros(),
            last_display: Vec3::zeros(),
        }
    }

    /// The same servo with its display ramped out (scale 0): it ramps in over the ramp time once
    /// its world is fresh, as after a stale spell. What a study's next trial starts from: the
    /// hand may be anywhere in the new world when its first state comes.
    pub fn ramped_out(mut self) -> Self {
        self.scale = 0.0;
        self
    }

    /// What the display stages did so far.
    pub fn display_stats(&self) -> &DisplayStats {
        &self.stats
    }

    /// One tick.
    pub fn step(&mut self, inp: &ServoInput<'_>, bodies: &[Body]) -> ServoOutput {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let p = &self.params;
        let (tool_pos, tool_vel) = (inp.tool_pos, inp.tool_vel);
        let n = bodies.len().min(inp.objects.len()).clamp(1, MAX_OBJECTS);
        let synced: [bool; MAX_OBJECTS] =
            std::array::from_fn(|k| k < n && self.display_contact[k] == self.contact[k]);
        let mut contacts = [ContactForce::default(); MAX_OBJECTS];
        for k in 0..n {
            contacts[k] = tool_contact(
                &p.contact,
                &mut self.contact[k],
                &bodies[k].shape,
                &inp.objects[k],
                &bodies[k].mass,
                tool_pos,
                tool_vel,
                p.tool_radius_m,
            );
        }
        // Every object's force on the tool, summed in the world's order.
        let total =
            |c: &[ContactForce; MAX_OBJECTS]| c[1..n].iter().fold(c[0].force, |a, c| a + c.force);
        // Stale world: ramp the display to zero, and back once fresh.
        let stale = inp.stopping || inp.now_s - inp.object_time_s > p.stale_limit_s;
        let ramp = p.stale_ramp_s.max(1e-9);
        self.scale = if stale {
            (self.scale - inp.dt_s / ramp).max(0.0)
        } else {
            // A late tick ramps in no further than a tick of the longest counted: the first tick
            // after a stall, or of a study's next trial, never skips the ramp.
            (self.scale + inp.dt_s.min(p.max_ramp_in_tick_s) / ramp).min(1.0)
        };
        if !p.display.enabled {
            return self.bounded_adoption_step(inp, total(&contacts), contacts);
        }
        // The displayed objects: a stale world (no state yet, or none fresh) has nothing to blend
        // from, so the first fresh state is displayed as it is.
        if stale {
            self.displayed = [DisplayedObject::default(); MAX_OBJECTS];
        }
        let d = &p.display;
        // Whether the display is the copy: the one object's, or in a world of several those the
        // tool touches (live or displayed; a correction of a puck across the table must not hold
        // back the force of the one in hand).
        let in_hand: [bool; MAX_OBJECTS] = std::array::from_fn(|k| {
            n == 1 || self.contact[k].touching() || self.display_contact[k].touching()
        });
        let all_copy = |displayed: &[DisplayedObject; MAX_OBJECTS]| {
            (0..n).all(|k| !in_hand[k] || displayed[k].is_copy())
        };
        let was_copy = all_copy(&self.displayed);
        let mut shown_contacts = [ContactForce::default(); MAX_OBJECTS];
        for k in 0..n {
            let (shown, _corrected) = self.displayed[k].update(
                d,
                &inp.objects[k],
                inp.object_time_s,
                inp.dt_s,
                &bodies[k].mass,
                &mut self.stats,
            );
            // The copy's contact serves the display while they agree (pose and friction memory);
            // the display keeps its own stick point after a blend until it slips or lets go, so
            // that switching back never steps the tangential force.
            shown_contacts[k] = if self.displayed[k].is_copy() && (synced[k] || stale) {
                self.display_contact[k] = self.contact[k];
                contacts[k]
            } else {
                tool_contact(
                    &p.contact,
                    &mut self.display_contact[k],
                    &bodies[k].shape,
                    &shown,
                    &bodies[k].mass,
                    tool_pos,
                    tool_vel,
                    p.tool_radius_m,
                )
            };
        }
        let is_copy = all_copy(&self.displayed);
        // Eq. 6 with the tool rigidly at the handle (J_h = I): the hand feels the reaction.
        // (0 − F rather than −F: no contact displays +0, not −0, as before the display stages.)
        let (f_target, f_sim) = (
            Vec3::zeros() - total(&shown_contacts),
            Vec3::zeros() - total(&contacts),
        );
        // While a correction is blended out, every step is limited; otherwise the contact's own
        // change is rendered as it is.
        let blending = !(was_copy && is_copy);
        let base = if blending {
            self.limiter.last()
        } else {
            self.limiter.base(f_target)
        };
        let (f, limited) = self.limiter.limit(d, base, f_target);
        let f = self.observer.step(
            d,
            &self.limiter,
            base,
            f,
            f_sim,
            tool_vel,
            inp.dt_s * self.scale,
            &mut self.stats,
        );
        let s = &mut self.stats;
        s.ticks_limited += u64::from(limited);
        s.max_step_n = s.max_step_n.max((f - self.limiter.last()).norm());
        s.max_correction_step_n = s.max_correction_step_n.max((f - base).norm());
        self.limiter.set(f, f_target);
        let f_desired = f * self.scale;
        ServoOutput {
            f_desired,
            f_simulated: f_sim * self.scale,
            contacts,
            tool_pos,
            tool_vel,
            scale: self.scale,
        }
    }

    /// Without the display stages: the contact with the copy, and at an adoption the display
    /// continues from its last value and closes the gap to the true force by at most
    /// `max_adoption_step_n` per tick.
    fn bounded_adoption_step(
        &mut self,
        inp: &ServoInput<'_>,
        force: Vec3,
        contacts: [ContactForce; MAX_OBJECTS],
    ) -> ServoOutput {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let p = &self.params;
        // Eq. 6 with the tool rigidly at the handle (J_h = I): the hand feels the reaction.
        let f_true = -force * self.scale;
        if inp.adopted {
            self.blend = self.last_display - f_true;
        }
        let n = self.blend.norm();
        self.blend = if n > p.max_adoption_step_n {
            self.blend * ((n - p.max_adoption_step_n) / n)
        } else {
            Vec3::zeros()
        };
        let f_desired = f_true + self.blend;
        let st = &mut self.stats;
        st.max_step_n = st.max_step_n.max((f_desired - self.last_display).norm());
        self.last_display = f_desired;
        ServoOutput {
            f_desired,
            f_simulated: f_true,
            contacts,
            tool_pos: inp.tool_pos,
            tool_vel: inp.tool_vel,
            scale: self.scale,
        }
    }
}
