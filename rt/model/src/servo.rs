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
//! - **Bounded adoption step.** When physics adopts a remote state, the object can jump, and with it
//!   the contact force. Physics always gets the contact with the object where it really is (so the
//!   copy's dynamics stay consistent); only the *displayed* force is blended: at an adoption the display
//!   continues from its last value and closes the gap to the true force by at most
//!   `max_adoption_step_n` per tick. (Rendering the object at an offset pose instead would feed
//!   physics forces computed on a pose that is not the copy's, and throw the object.)

use crate::body::{BodyState, MassProps, Vec3};
use crate::contact::{tool_contact, ContactForce, ContactParams, ToolContactState};
use crate::shape::Shape;

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
    /// Largest displayed-force change per tick an adoption may cause, N.
    pub max_adoption_step_n: f64,
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
    /// Newest object state.
    pub object: &'a BodyState,
    /// Its time, s.
    pub object_time_s: f64,
    /// Whether physics adopted a remote state since the last tick.
    pub adopted: bool,
    /// A cooperative stop was requested: ramp the display to zero as for a stale world.
    pub stopping: bool,
}

/// What a servo tick produces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoOutput {
    /// Desired force at the hand F_h (after the stale ramp and the adoption blend), world, N.
    pub f_desired: Vec3,
    /// The tool's contact on the object (force on the object), for physics.
    pub contact: ContactForce,
    /// Tool position, world.
    pub tool_pos: Vec3,
    /// Tool velocity, world.
    pub tool_vel: Vec3,
    /// Display scale: 1 fresh, 0 stale (a device with its own force loop scales its output by it).
    pub scale: f64,
}

/// A servo loop's state.
#[derive(Debug, Clone, PartialEq)]
pub struct Servo {
    /// Parameters.
    pub params: ServoParams,
    contact: ToolContactState,
    scale: f64,
    blend: Vec3,
    last_display: Vec3,
}

impl Servo {
    /// A servo with `params`.
    pub fn new(params: ServoParams) -> Self {
        Self {
            params,
            contact: ToolContactState::default(),
            scale: 1.0,
            blend: Vec3::zeros(),
            last_display: Vec3::zeros(),
        }
    }

    /// One tick.
    pub fn step(&mut self, inp: &ServoInput<'_>, shape: &Shape, mass: &MassProps) -> ServoOutput {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let p = &self.params;
        let (tool_pos, tool_vel) = (inp.tool_pos, inp.tool_vel);
        let contact = tool_contact(
            &p.contact,
            &mut self.contact,
            shape,
            inp.object,
            mass,
            tool_pos,
            tool_vel,
            p.tool_radius_m,
        );
        // Stale world: ramp the display to zero, and back once fresh.
        let stale = inp.stopping || inp.now_s - inp.object_time_s > p.stale_limit_s;
        let rate = inp.dt_s / p.stale_ramp_s.max(1e-9);
        self.scale = if stale {
            (self.scale - rate).max(0.0)
        } else {
            (self.scale + rate).min(1.0)
        };
        // Eq. 6 with the tool rigidly at the handle (J_h = I): the hand feels the reaction.
        let f_true = -contact.force * self.scale;
        // Bounded adoption step, in force space.
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
        self.last_display = f_desired;
        ServoOutput {
            f_desired,
            contact,
            tool_pos,
            tool_vel,
            scale: self.scale,
        }
    }
}
