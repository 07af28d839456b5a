//! The vendors' safety contract, for every device: [`Guarded`] sits between the servo and a backend
//! and is the only way the servo reaches it.
//!
//! - **Ramp-in** on enable (OpenHaptics `HD_FORCE_RAMPING`): the force rises from zero over
//!   `ramp_in_s` when the device is opened and again after every release a limit caused.
//! - **Force clamp** (`HD_NOMINAL_MAX_FORCE`): to the smaller of the config's and the device's
//!   maximum.
//! - **Contact stiffness and damping** against the device's maxima ([`clamp_contact`]), scaled by the
//!   workspace scale as CHAI3D does (`maxStiffness / workspaceScaleFactor`).
//! - **Software velocity limit** (`HD_SOFTWARE_VELOCITY_LIMIT`): a hand faster than the limit
//!   releases the force until it is slower again (then ramps in).
//! - **Force-impulse limit** (`HD_SOFTWARE_FORCE_IMPULSE_LIMIT`): the commanded force changes by at
//!   most `max_force_step_n` per tick (releasing is always allowed: it takes energy out).
//! - **Communication watchdog** (DHD's `dhdSetWatchdog`): a device whose sample time stops
//!   advancing for `watchdog_s`, or that reports a fault, is released.
//! - **Release on every stop**: the servo releases when the world is stale or the station stops
//!   (its display scale reached 0), [`Guarded::close`] releases and closes, and so does `Drop` (a
//!   panic unwinding through the servo).
//!
//! [`Guarded::last_trip`] says which limit acted last and when, [`Guarded::trips`] how often each
//! did, and [`Guarded::counts`] what the device did (samples, faults, commands): the servo
//! publishes them for `station status`.

use coop_model::body::Vec3;
use coop_model::contact::ContactParams;

use super::cartesian::{CartesianDevice, Command, DeviceFault, DeviceInfo, Sample};
use crate::shm::device::{DeviceCounts, FaultKind, TRIP_SLOTS};

/// The limits a station's config sets (`[device.safety]`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetyLimits {
    /// Ramp of the force from zero on enable, s (0: none).
    pub ramp_in_s: f64,
    /// Largest force, N (the device's own maximum applies too).
    pub max_force_n: f64,
    /// Hand speed above which the force is released, m/s (device frame).
    pub max_velocity_m_s: f64,
    /// Largest change of the commanded force from one tick to the next, N.
    pub max_force_step_n: f64,
    /// A sample time that stands still this long releases the device, s.
    pub watchdog_s: f64,
}

impl Default for SafetyLimits {
    fn default() -> Self {
        Self {
            ramp_in_s: 0.5,
            max_force_n: 10.0,
            max_velocity_m_s: 2.0,
            max_force_step_n: 2.0,
            watchdog_s: 0.05,
        }
    }
}

/// A limit of the contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u64)]
pub enum Limit {
    /// The force was clamped to the maximum.
    MaxForce = 1,
    /// The contact stiffness was clamped to the device's maximum (at setup).
    Stiffness = 2,
    /// The contact damping was clamped to the device's maximum (at setup).
    Damping = 3,
    /// The hand was too fast: released.
    Velocity = 4,
    /// The force changed too much in one tick: the change was clamped.
    Impulse = 5,
    /// No fresh sample within the watchdog time: released.
    Watchdog = 6,
    /// The device reported a fault: released.
    Fault = 7,
}

impl Limit {
    /// Every limit, in code order.
    pub const ALL: [Limit; 7] = [
        Limit::MaxForce,
        Limit::Stiffness,
        Limit::Damping,
        Limit::Velocity,
        Limit::Impulse,
        Limit::Watchdog,
        Limit::Fault,
    ];

    /// Its code in the control block (0 is "none").
    pub fn code(self) -> u64 {
        self as u64
    }

    /// The limit of `code`, if any.
    pub fn from_code(code: u64) -> Option<Self> {
        Self::ALL.into_iter().find(|l| l.code() == code)
    }

    /// Its name in `station status` and the config: `max_force_n`, …
    pub fn name(self) -> &'static str {
        match self {
            Limit::MaxForce => "max_force_n",
            Limit::Stiffness => "max_stiffness",
            Limit::Damping => "max_damping",
            Limit::Velocity => "max_velocity_m_s",
            Limit::Impulse => "max_force_step_n",
            Limit::Watchdog => "watchdog_ms",
            Limit::Fault => "device fault",
        }
    }

    /// Whether it releases the device (rather than clamping a value).
    pub fn releases(self) -> bool {
        matches!(self, Limit::Velocity | Limit::Watchdog | Limit::Fault)
    }
}

/// A limit that acted, and when (CLOCK_MONOTONIC, ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Trip {
    /// Which.
    pub limit: Limit,
    /// When it acted last.
    pub at_ns: u64,
    /// Episodes so far (of all limits): a limit acting on consecutive ticks counts once.
    pub episodes: u64,
}

/// `contact` with its stiffness and damping clamped to what the device renders (CHAI3D:
/// `maxStiffness / workspaceScaleFactor`, since a world metre is `1 / scale` device metres), and
/// which of the two limits acted.
pub fn clamp_contact(
    contact: ContactParams,
    info: &DeviceInfo,
    workspace_scale: f64,
) -> (ContactParams, [Option<Limit>; 2]) {
    let k_max = info.max_stiffness_n_per_m / workspace_scale;
    let b_max = info.max_damping_n_s_per_m / workspace_scale;
    let mut c = contact;
    let mut acted = [None, None];
    if c.stiffness_n_per_m > k_max || c.tangential_stiffness_n_per_m > k_max {
        c.stiffness_n_per_m = c.stiffness_n_per_m.min(k_max);
        c.tangential_stiffness_n_per_m = c.tangential_stiffness_n_per_m.min(k_max);
        acted[0] = Some(Limit::Stiffness);
    }
    if c.damping_n_s_per_m > b_max || c.tangential_damping_n_s_per_m > b_max {
        c.damping_n_s_per_m = c.damping_n_s_per_m.min(b_max);
        c.tangential_damping_n_s_per_m = c.tangential_damping_n_s_per_m.min(b_max);
        acted[1] = Some(Limit::Damping);
    }
    (c, acted)
}

/// A device under the safety contract.
#[derive(Debug)]
pub struct Guarded<D: CartesianDevice> {
    device: D,
    limits: SafetyLimits,
    max_force_n: f64,
    /// Ramp-in share, 0..=1.
    ramp: f64,
    last_force: Vec3,
    last_display_ns: u64,
    /// Newest sample time seen, and when it was first seen (now).
    sample_t_ns: u64,
    fresh_at_ns: u64,
    /// The limit holding the device released, if any.
    holding: Option<Limit>,
    last_trip: Option<Trip>,
    /// Limits that acted on the previous display tick, as a bit set of codes (for episode counting).
    acting: u64,
    acting_now: u64,
    /// Episodes of each limit, by code.
    trips: [u64; TRIP_SLOTS],
    /// What the device did (the samples, faults and commands fields).
    counts: DeviceCounts,
    /// The last fault the device reported, and when.
    last_fault: Option<(DeviceFault, u64)>,
    closed: bool,
}

impl<D: CartesianDevice> Guarded<D> {
    /// `device` under `limits`, enabled at `now_ns` (its force ramps in from there).
    pub fn new(device: D, limits: SafetyLimits, now_ns: u64) -> Self {
        let max_force_n = limits.max_force_n.min(device.info().max_force_n);
        Self {
            device,
            limits,
            max_force_n,
            ramp: if limits.ramp_in_s > 0.0 { 0.0 } else { 1.0 },
            last_force: Vec3::zeros(),
            last_display_ns: now_ns,
            sample_t_ns: 0,
            fresh_at_ns: now_ns,
            holding: None,
            last_trip: None,
            acting: 0,
            acting_now: 0,
            trips: [0; TRIP_SLOTS],
            counts: DeviceCounts::default(),
            last_fault: None,
            closed: false,
        }
    }

    /// The device.
    pub fn device(&self) -> &D {
        &self.device
    }

    /// The device, mutably (setup only: the servo path goes through [`Guarded::sample`] and
    /// [`Guarded::display`]).
    pub fn device_mut(&mut self) -> &mut D {
        &mut self.device
    }

    /// The limits in force.
    pub fn limits(&self) -> &SafetyLimits {
        &self.limits
    }

    /// The force bound in force: the smaller of the config's and the device's maximum, N.
    pub fn max_force_n(&self) -> f64 {
        self.max_force_n
    }

    /// The limit that acted last, and when.
    pub fn last_trip(&self) -> Option<Trip> {
        self.last_trip
    }

    /// The limit holding the device released now, if any.
    pub fn holding(&self) -> Option<Limit> {
        self.holding
    }

    /// Episodes of each limit so far, indexed by [`Limit::code`].
    pub fn trips(&self) -> &[u64; TRIP_SLOTS] {
        &self.trips
    }

    /// What the device did so far: its samples (and new ones), faults by kind, and force commands
    /// taken (a bridge's own counts are its backend's to tell).
    pub fn counts(&self) -> &DeviceCounts {
        &self.counts
    }

    /// The last fault the device reported, and when (CLOCK_MONOTONIC, ns).
    pub fn last_fault(&self) -> Option<(DeviceFault, u64)> {
        self.last_fault
    }

    fn fault(&mut self, f: DeviceFault, now_ns: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        self.counts.count_fault(fault_kind(&f));
        self.last_fault = Some((f, now_ns));
    }

    /// Records a limit that acted at `now_ns` outside a tick (the contact clamp at setup).
    pub fn record(&mut self, limit: Limit, now_ns: u64) {
        self.acting_now |= 1 << limit.code();
        self.trip(limit, now_ns);
    }

    fn trip(&mut self, limit: Limit, now_ns: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let bit = 1 << limit.code();
        let new_episode = self.acting & bit == 0;
        self.acting_now |= bit;
        self.trips[limit.code() as usize] += u64::from(new_episode);
        let episodes = self.last_trip.map_or(0, |t| t.episodes) + u64::from(new_episode);
        self.last_trip = Some(Trip {
            limit,
            at_ns: now_ns,
            episodes,
        });
    }

    fn end_tick(&mut self) {
        self.acting = self.acting_now;
        self.acting_now = 0;
    }

    /// The device's sample at `now_ns`, checked: a fault, a non-finite value, a sample time that
    /// stood still past the watchdog or a hand faster than the velocity limit holds the device
    /// released (from this tick's [`Guarded::display`] on) until it clears.
    ///
    /// # Errors
    /// The device's fault, or [`DeviceFault::BadValue`] for a non-finite sample.
    pub fn sample(&mut self, now_ns: u64) -> Result<Sample, DeviceFault> {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let s = match self.device.sample(now_ns) {
            Ok(s) if !finite(s.position_m) => Err(DeviceFault::BadValue { what: "position" }),
            Ok(s) if !finite(s.velocity_m_s) => Err(DeviceFault::BadValue { what: "velocity" }),
            other => other,
        };
        let s = match s {
            Ok(s) => s,
            Err(e) => {
                self.fault(e, now_ns);
                self.hold(Limit::Fault, now_ns);
                return Err(e);
            }
        };
        self.counts.samples += 1;
        if s.t_ns > self.sample_t_ns {
            self.sample_t_ns = s.t_ns;
            self.fresh_at_ns = now_ns;
            self.counts.new_samples += 1;
        }
        let watchdog_ns = (self.limits.watchdog_s * 1e9) as u64;
        if now_ns.saturating_sub(self.fresh_at_ns) > watchdog_ns {
            self.hold(Limit::Watchdog, now_ns);
        } else if s.velocity_m_s.norm() > self.limits.max_velocity_m_s {
            self.hold(Limit::Velocity, now_ns);
        } else {
            self.holding = None;
        }
        Ok(s)
    }

    fn hold(&mut self, limit: Limit, now_ns: u64) {
        self.holding = Some(limit);
        self.trip(limit, now_ns);
    }

    /// Displays `force` (device frame, N) at `now_ns` under the limits, with `world_scale` the
    /// servo's stale-world ramp (0..=1): at 0, or while a limit holds the device, it is released.
    /// Returns the force commanded (zero when released).
    pub fn display(&mut self, now_ns: u64, force: Vec3, world_scale: f64) -> Vec3 {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let dt = now_ns.saturating_sub(self.last_display_ns) as f64 * 1e-9;
        self.last_display_ns = now_ns;
        if self.closed {
            return Vec3::zeros();
        }
        if self.holding.is_some() || world_scale <= 0.0 || !finite(force) {
            if self.holding.is_some() {
                // Enabled again only through a fresh ramp-in.
                self.ramp = if self.limits.ramp_in_s > 0.0 {
                    0.0
                } else {
                    1.0
                };
            }
            self.release(now_ns);
            self.end_tick();
            return Vec3::zeros();
        }
        if self.limits.ramp_in_s > 0.0 {
            self.ramp = (self.ramp + dt / self.limits.ramp_in_s).min(1.0);
        }
        let mut f = force;
        let n = f.norm();
        if n > self.max_force_n {
            f *= self.max_force_n / n;
            self.trip(Limit::MaxForce, now_ns);
        }
        f *= self.ramp;
        let delta = f - self.last_force;
        let step = delta.norm();
        if step > self.limits.max_force_step_n {
            f = self.last_force + delta * (self.limits.max_force_step_n / step);
            self.trip(Limit::Impulse, now_ns);
        }
        self.device
            .set_output_gain(world_scale.min(1.0) * self.ramp);
        match self.device.command(now_ns, Command::Force(f)) {
            Ok(()) => {
                self.last_force = f;
                self.counts.commands += 1;
            }
            Err(e) => {
                self.fault(e, now_ns);
                self.hold(Limit::Fault, now_ns);
                self.release(now_ns);
                self.end_tick();
                return Vec3::zeros();
            }
        }
        self.end_tick();
        f
    }

    /// Releases the device now (zero force, motors off).
    pub fn release(&mut self, now_ns: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        self.last_force = Vec3::zeros();
        self.device.set_output_gain(0.0);
        // A release that fails leaves nothing more to do here: the fault shows in the next sample.
        let _ = self.device.command(now_ns, Command::Release);
    }

    /// Releases and closes the device (once; also on drop).
    pub fn close(&mut self, now_ns: u64) {
        if !self.closed {
            self.release(now_ns);
            self.device.close();
            self.closed = true;
        }
    }

    /// Whether [`Guarded::close`] ran.
    pub fn is_closed(&self) -> bool {
        self.closed
    }
}

impl<D: CartesianDevice> Drop for Guarded<D> {
    fn drop(&mut self) {
        let now = self.last_display_ns;
        self.close(now);
    }
}

/// The kind of `f`, as the control block counts it.
pub fn fault_kind(f: &DeviceFault) -> FaultKind {
    match f {
        DeviceFault::Disconnected => FaultKind::Disconnected,
        DeviceFault::CallFailed { .. } => FaultKind::CallFailed,
        DeviceFault::BadValue { .. } => FaultKind::BadValue,
    }
}

fn finite(v: Vec3) -> bool {
    v.iter().all(|x| x.is_finite())
}
