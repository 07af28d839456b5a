//! A test double of 3D Systems' OpenHaptics HD API library (`libHD.so`, OpenHaptics 3.x): the
//! OpenHaptics backend's tests load it in place of the vendor's library. It is NOT the vendor's
//! code and contains none of it; it imitates the C API's observable behaviour (hdDefines.h
//! constants, the error stack, frames, the servo scheduler) closely enough to exercise a backend,
//! and adds control entry points ([`mock_hd_set`], [`mock_hd_get`], [`mock_hd_reset`]) through
//! which a test moves the stylus, injects faults and reads what the "device" displayed.
//!
//! Build: as a workspace crate (`cargo test -p coop-mock-hd`), or on its own, std only, with
//! `rustc --edition 2021 --crate-type cdylib -O src/lib.rs -o DIR/libHD.so`.
//!
//! The device: one Touch (handle 1) while the `"devices"` hook is at least 1. Its stylus moves as
//! `p0 + a·sin(2π·f·t)` per axis (mm), `t` the seconds since the scheduler started (0 while it is
//! stopped), and it "displays" at each `hdEndFrame` the force set in the frame, subject to force
//! output being enabled and to the nominal maximum (clamped, or a force error).
//!
//! The scheduler: one thread ("hd-servo") ticking at `hdSetSchedulerRate` Hz (default 1000) on
//! absolute deadlines (waits on a condition variable with a timeout, so a stop is prompt; never
//! spins), calling every scheduled callback once per tick, highest priority first, and removing
//! those that return anything but `HD_CALLBACK_CONTINUE`. All state lives in one mutex; callbacks
//! are called without holding it, as they call back into the `hd*` functions.
//!
//! Defaults chosen where the vendor's behaviour is not pinned down here: force output, max-force
//! clamping and force ramping start disabled after `hdInitDevice` (a backend must enable what it
//! relies on); the software force limit and the one-frame limit start enabled. Calls that need a
//! device while none is initialised push `HD_BAD_HANDLE`.
#![allow(non_snake_case, non_camel_case_types)]
#![warn(missing_docs)]

use std::cmp::Reverse;
use std::ffi::{c_char, c_long, c_ulong, c_void, CStr};
use std::sync::{Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::{JoinHandle, ThreadId};
use std::time::{Duration, Instant};

// ---------------------------------------------------------------------------------------------
// Types (hdDefines.h)
// ---------------------------------------------------------------------------------------------

/// `HDuint`.
pub type HDuint = u32;
/// `HDboolean` (an `unsigned char`).
pub type HDboolean = u8;
/// `HDulong`.
pub type HDulong = c_ulong;
/// `HDlong`.
pub type HDlong = c_long;
/// `HDushort`.
pub type HDushort = u16;
/// `HDint`.
pub type HDint = i32;
/// `HDfloat`.
pub type HDfloat = f32;
/// `HDdouble`.
pub type HDdouble = f64;
/// `HDerror`.
pub type HDerror = u32;
/// `HDenum`.
pub type HDenum = u32;
/// `HDstring`: a NUL-terminated C string.
pub type HDstring = *const c_char;
/// `HHD`: a device handle.
pub type HHD = u32;
/// `HDSchedulerHandle`: a scheduled callback's handle.
pub type HDSchedulerHandle = c_ulong;
/// `HDCallbackCode`: what a scheduler callback returns.
pub type HDCallbackCode = u32;
/// `HDSchedulerCallback`: a scheduler callback, given back the `pUserData` it was scheduled with.
pub type HDSchedulerCallback = extern "C" fn(*mut c_void) -> HDCallbackCode;

/// `HDErrorInfo`, returned by value from [`hdGetError`].
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HDErrorInfo {
    /// The HD error code (`HD_SUCCESS` when the stack was empty).
    pub errorCode: HDerror,
    /// The driver's internal code (0 in this mock).
    pub internalErrorCode: i32,
    /// The device the error is about (`HD_INVALID_HANDLE` when none was initialised).
    pub hHD: HHD,
}

// ---------------------------------------------------------------------------------------------
// Constants (hdDefines.h)
// ---------------------------------------------------------------------------------------------

/// No error.
pub const HD_SUCCESS: HDerror = 0x0000;
/// An enum argument is not one this call accepts.
pub const HD_INVALID_ENUM: HDerror = 0x0100;
/// A value argument is out of range (or a NULL pointer).
pub const HD_INVALID_VALUE: HDerror = 0x0101;
/// The call is not valid in the current state.
pub const HD_INVALID_OPERATION: HDerror = 0x0102;
/// The device handle is not valid.
pub const HD_BAD_HANDLE: HDerror = 0x0104;
/// The motors are too warm.
pub const HD_WARM_MOTORS: HDerror = 0x0200;
/// A force exceeded the nominal maximum.
pub const HD_EXCEEDED_MAX_FORCE: HDerror = 0x0201;
/// A force change exceeded the impulse limit.
pub const HD_EXCEEDED_MAX_FORCE_IMPULSE: HDerror = 0x0202;
/// The stylus exceeded the velocity limit.
pub const HD_EXCEEDED_MAX_VELOCITY: HDerror = 0x0203;
/// A generic force error.
pub const HD_FORCE_ERROR: HDerror = 0x0204;
/// The device faulted.
pub const HD_DEVICE_FAULT: HDerror = 0x0300;
/// The device was already initialised.
pub const HD_DEVICE_ALREADY_INITIATED: HDerror = 0x0301;
/// Communication with the device failed.
pub const HD_COMM_ERROR: HDerror = 0x0302;
/// The device configuration is missing or wrong (no such device).
pub const HD_COMM_CONFIG_ERROR: HDerror = 0x0303;
/// The servo timer failed.
pub const HD_TIMER_ERROR: HDerror = 0x0304;
/// `hdBeginFrame` inside a frame.
pub const HD_ILLEGAL_BEGIN: HDerror = 0x0400;
/// `hdEndFrame` outside a frame.
pub const HD_ILLEGAL_END: HDerror = 0x0401;
/// A frame error.
pub const HD_FRAME_ERROR: HDerror = 0x0402;
/// A scheduler priority out of range.
pub const HD_INVALID_PRIORITY: HDerror = 0x0500;
/// Too many scheduled callbacks.
pub const HD_SCHEDULER_FULL: HDerror = 0x0501;

/// Button mask (1 integer).
pub const HD_CURRENT_BUTTONS: HDenum = 0x2000;
/// Stylus position (3 doubles, mm).
pub const HD_CURRENT_POSITION: HDenum = 0x2050;
/// Stylus velocity (3 doubles, mm/s).
pub const HD_CURRENT_VELOCITY: HDenum = 0x2051;
/// Device model (string).
pub const HD_DEVICE_MODEL_TYPE: HDenum = 0x2501;
/// Driver version (string).
pub const HD_DEVICE_DRIVER_VERSION: HDenum = 0x2502;
/// Vendor (string).
pub const HD_DEVICE_VENDOR: HDenum = 0x2503;
/// Serial number (string).
pub const HD_DEVICE_SERIAL_NUMBER: HDenum = 0x2504;
/// Mechanical workspace (6 doubles, mm: minX, minY, minZ, maxX, maxY, maxZ).
pub const HD_MAX_WORKSPACE_DIMENSIONS: HDenum = 0x2550;
/// Usable workspace (6 doubles, mm: minX, minY, minZ, maxX, maxY, maxZ).
pub const HD_USABLE_WORKSPACE_DIMENSIONS: HDenum = 0x2551;
/// Input degrees of freedom (1 integer).
pub const HD_INPUT_DOF: HDenum = 0x2553;
/// Output degrees of freedom (1 integer).
pub const HD_OUTPUT_DOF: HDenum = 0x2554;
/// Supported calibration styles (1 integer, a mask of `HD_CALIBRATION_*` styles).
pub const HD_CALIBRATION_STYLE: HDenum = 0x2555;
/// Servo rate (Hz).
pub const HD_UPDATE_RATE: HDenum = 0x2600;
/// Servo rate measured over the last tick (Hz).
pub const HD_INSTANTANEOUS_UPDATE_RATE: HDenum = 0x2601;
/// Nominal maximum stiffness (N/mm).
pub const HD_NOMINAL_MAX_STIFFNESS: HDenum = 0x2602;
/// Nominal maximum force (N).
pub const HD_NOMINAL_MAX_FORCE: HDenum = 0x2603;
/// Nominal maximum continuous force (N).
pub const HD_NOMINAL_MAX_CONTINUOUS_FORCE: HDenum = 0x2604;
/// Force ramping rate (settable; stored, not modelled).
pub const HD_FORCE_RAMPING_RATE: HDenum = 0x2608;
/// Nominal maximum damping (N·s/mm).
pub const HD_NOMINAL_MAX_DAMPING: HDenum = 0x2609;
/// The frame's force (3 doubles, N): set inside a frame, displayed at its end.
pub const HD_CURRENT_FORCE: HDenum = 0x2700;
/// The force displayed at the last end of frame (3 doubles, N).
pub const HD_LAST_FORCE: HDenum = 0x2800;

/// Capability: force output.
pub const HD_FORCE_OUTPUT: HDenum = 0x4000;
/// Capability: clamp forces to the nominal maximum instead of faulting.
pub const HD_MAX_FORCE_CLAMPING: HDenum = 0x4001;
/// Capability: ramp forces up after the scheduler starts or after an error.
pub const HD_FORCE_RAMPING: HDenum = 0x4002;
/// Capability: the software force limit.
pub const HD_SOFTWARE_FORCE_LIMIT: HDenum = 0x4003;
/// Capability: one frame per servo tick.
pub const HD_ONE_FRAME_LIMIT: HDenum = 0x4004;

/// Calibration is fine.
pub const HD_CALIBRATION_OK: HDenum = 0x5000;
/// Calibration needs `hdUpdateCalibration`.
pub const HD_CALIBRATION_NEEDS_UPDATE: HDenum = 0x5001;
/// Calibration needs the user (e.g. the stylus in its inkwell).
pub const HD_CALIBRATION_NEEDS_MANUAL_INPUT: HDenum = 0x5002;
/// Calibration style: encoder reset.
pub const HD_CALIBRATION_ENCODER_RESET: HDint = 1;
/// Calibration style: automatic.
pub const HD_CALIBRATION_AUTO: HDint = 2;
/// Calibration style: inkwell.
pub const HD_CALIBRATION_INKWELL: HDint = 4;

/// The handle `hdInitDevice` returns on failure.
pub const HD_INVALID_HANDLE: HHD = 0xFFFF_FFFF;
/// `hdInitDevice(HD_DEFAULT_DEVICE)`: the default device (a NULL name).
pub const HD_DEFAULT_DEVICE: HDstring = std::ptr::null();
/// A callback's "remove me".
pub const HD_CALLBACK_DONE: HDCallbackCode = 0;
/// A callback's "call me again next tick".
pub const HD_CALLBACK_CONTINUE: HDCallbackCode = 1;
/// The highest scheduler priority.
pub const HD_MAX_SCHEDULER_PRIORITY: HDushort = 0xffff;
/// The lowest scheduler priority.
pub const HD_MIN_SCHEDULER_PRIORITY: HDushort = 0;
/// The usual scheduler priority.
pub const HD_DEFAULT_SCHEDULER_PRIORITY: HDushort = 0x7fff;
/// `hdWaitForCompletion`: only report whether the callback is still scheduled.
pub const HD_WAIT_CHECK_STATUS: HDuint = 0;
/// `hdWaitForCompletion`: block until the callback is no longer scheduled.
pub const HD_WAIT_INFINITE: HDuint = 1;

/// The handle of the mock's one device.
const DEVICE: HHD = 1;
/// Errors kept on the stack; pushing more drops the oldest.
const MAX_ERRORS: usize = 32;
/// Callbacks scheduled at once; more is `HD_SCHEDULER_FULL`.
const MAX_SCHEDULED: usize = 32;

// ---------------------------------------------------------------------------------------------
// State
// ---------------------------------------------------------------------------------------------

/// A callback's user data, handed back to it on the scheduler thread.
#[derive(Clone, Copy)]
struct UserData(*mut c_void);

// The library never dereferences the pointer; it only passes it back to the callback it was
// registered with, possibly on the scheduler thread. That the data may be used from there is the
// caller's side of the HD scheduler contract, as with the vendor's library.
// SAFETY: sent only to be handed back, never dereferenced here (above).
unsafe impl Send for UserData {}

struct Entry {
    handle: HDSchedulerHandle,
    callback: HDSchedulerCallback,
    data: UserData,
    priority: HDushort,
}

struct State {
    /// The hooks of `COOP_MOCK_HD` have been applied (at the first `hdInitDevice`).
    env_applied: bool,
    // The device.
    initialized: bool,
    errors: Vec<HDErrorInfo>,
    force_output: bool,
    max_force_clamping: bool,
    force_ramping: bool,
    software_force_limit: bool,
    one_frame_limit: bool,
    force_ramping_rate: f64,
    in_frame: bool,
    frame_owner: Option<ThreadId>,
    frame_force: [f64; 3],
    frame_position: [f64; 3],
    frame_velocity: [f64; 3],
    displayed: [f64; 3],
    // Hooks.
    devices: f64,
    p0: [f64; 3],
    amplitude: [f64; 3],
    freq_hz: f64,
    buttons: f64,
    max_force: f64,
    calibration: HDenum,
    stall: bool,
    error_at_frame: f64,
    /// The scheduler stalls at the end of this frame (0: never).
    stall_at_frame: f64,
    error_code: HDerror,
    over_force: bool,
    rate_hz: f64,
    // Counters.
    inits: u64,
    frames: u64,
    ticks: u64,
    callbacks: u64,
    calibration_updates: u64,
    reads_outside_frame: u64,
    writes_outside_frame: u64,
    // The scheduler.
    running: bool,
    stop_requested: bool,
    /// Bumped at every start and reset: a thread of an older generation exits.
    generation: u64,
    thread: Option<JoinHandle<()>>,
    thread_id: Option<ThreadId>,
    started: Option<Instant>,
    tick_started: Option<Instant>,
    instantaneous_rate: f64,
    entries: Vec<Entry>,
    next_handle: HDSchedulerHandle,
    running_callback: Option<HDSchedulerHandle>,
}

impl State {
    const fn new(generation: u64) -> Self {
        Self {
            env_applied: false,
            initialized: false,
            errors: Vec::new(),
            force_output: false,
            max_force_clamping: false,
            force_ramping: false,
            software_force_limit: true,
            one_frame_limit: true,
            force_ramping_rate: 0.0,
            in_frame: false,
            frame_owner: None,
            frame_force: [0.0; 3],
            frame_position: [0.0; 3],
            frame_velocity: [0.0; 3],
            displayed: [0.0; 3],
            devices: 1.0,
            p0: [0.0; 3],
            amplitude: [0.0; 3],
            freq_hz: 0.0,
            buttons: 0.0,
            max_force: 3.3,
            calibration: HD_CALIBRATION_OK,
            stall: false,
            error_at_frame: 0.0,
            stall_at_frame: 0.0,
            error_code: HD_COMM_ERROR,
            over_force: false,
            rate_hz: 1000.0,
            inits: 0,
            frames: 0,
            ticks: 0,
            callbacks: 0,
            calibration_updates: 0,
            reads_outside_frame: 0,
            writes_outside_frame: 0,
            running: false,
            stop_requested: false,
            generation,
            thread: None,
            thread_id: None,
            started: None,
            tick_started: None,
            instantaneous_rate: 0.0,
            entries: Vec::new(),
            next_handle: 1,
            running_callback: None,
        }
    }

    fn push_error(&mut self, code: HDerror) {
        if self.errors.len() >= MAX_ERRORS {
            self.errors.remove(0);
        }
        let hHD = if self.initialized {
            DEVICE
        } else {
            HD_INVALID_HANDLE
        };
        self.errors.push(HDErrorInfo {
            errorCode: code,
            internalErrorCode: 0,
            hHD,
        });
    }

    /// A device is initialised; else pushes `HD_BAD_HANDLE`.
    fn need_device(&mut self) -> bool {
        if !self.initialized {
            self.push_error(HD_BAD_HANDLE);
        }
        self.initialized
    }

    /// `h` is the initialised device; else pushes `HD_BAD_HANDLE`.
    fn need_handle(&mut self, h: HHD) -> bool {
        let ok = self.initialized && h == DEVICE;
        if !ok {
            self.push_error(HD_BAD_HANDLE);
        }
        ok
    }

    fn on_scheduler_thread(&self) -> bool {
        self.thread_id == Some(std::thread::current().id())
    }

    /// The calling thread has a frame open.
    fn in_own_frame(&self) -> bool {
        self.in_frame && self.frame_owner == Some(std::thread::current().id())
    }

    fn capability(&mut self, cap: HDenum) -> Option<&mut bool> {
        match cap {
            HD_FORCE_OUTPUT => Some(&mut self.force_output),
            HD_MAX_FORCE_CLAMPING => Some(&mut self.max_force_clamping),
            HD_FORCE_RAMPING => Some(&mut self.force_ramping),
            HD_SOFTWARE_FORCE_LIMIT => Some(&mut self.software_force_limit),
            HD_ONE_FRAME_LIMIT => Some(&mut self.one_frame_limit),
            _ => None,
        }
    }

    /// The stylus's position (mm) and velocity (mm/s) at `now`.
    fn stylus(&self, now: Instant) -> ([f64; 3], [f64; 3]) {
        let t = match (self.running, self.started) {
            (true, Some(s)) => now.saturating_duration_since(s).as_secs_f64(),
            _ => 0.0,
        };
        let w = 2.0 * std::f64::consts::PI * self.freq_hz;
        let (s, c) = (w * t).sin_cos();
        let mut p = [0.0; 3];
        let mut v = [0.0; 3];
        for i in 0..3 {
            p[i] = self.p0[i] + self.amplitude[i] * s;
            v[i] = self.amplitude[i] * w * c;
        }
        (p, v)
    }

    /// A read of device state: counted when the calling thread has no frame open.
    fn note_state_read(&mut self) -> bool {
        let own = self.in_own_frame();
        if !own {
            self.reads_outside_frame += 1;
        }
        own
    }

    /// A parameter's values (up to 6) and their count; `HD_INVALID_ENUM` if unknown.
    fn read_param(&mut self, p: HDenum) -> Option<([f64; 6], usize)> {
        let three = |v: [f64; 3]| Some(([v[0], v[1], v[2], 0.0, 0.0, 0.0], 3));
        let one = |v: f64| Some(([v, 0.0, 0.0, 0.0, 0.0, 0.0], 1));
        if !self.need_device() {
            return None;
        }
        match p {
            HD_CURRENT_POSITION | HD_CURRENT_VELOCITY => {
                let (pos, vel) = if self.note_state_read() {
                    (self.frame_position, self.frame_velocity)
                } else {
                    self.stylus(Instant::now())
                };
                three(if p == HD_CURRENT_POSITION { pos } else { vel })
            }
            HD_CURRENT_BUTTONS => {
                self.note_state_read();
                one(self.buttons)
            }
            HD_CURRENT_FORCE => {
                self.note_state_read();
                three(self.frame_force)
            }
            HD_LAST_FORCE => {
                self.note_state_read();
                three(self.displayed)
            }
            HD_NOMINAL_MAX_FORCE => one(self.max_force),
            HD_NOMINAL_MAX_CONTINUOUS_FORCE => one(0.88),
            HD_NOMINAL_MAX_STIFFNESS => one(1.26),
            HD_NOMINAL_MAX_DAMPING => one(0.003),
            HD_USABLE_WORKSPACE_DIMENSIONS => Some(([-80.0, -60.0, -35.0, 80.0, 60.0, 35.0], 6)),
            HD_MAX_WORKSPACE_DIMENSIONS => Some(([-110.0, -80.0, -50.0, 110.0, 80.0, 50.0], 6)),
            HD_UPDATE_RATE => one(self.rate_hz),
            HD_INSTANTANEOUS_UPDATE_RATE => one(if self.instantaneous_rate > 0.0 {
                self.instantaneous_rate
            } else {
                self.rate_hz
            }),
            HD_INPUT_DOF => one(6.0),
            HD_OUTPUT_DOF => one(3.0),
            HD_CALIBRATION_STYLE => one(f64::from(HD_CALIBRATION_INKWELL)),
            HD_FORCE_RAMPING_RATE => one(self.force_ramping_rate),
            _ => {
                self.push_error(HD_INVALID_ENUM);
                None
            }
        }
    }

    /// How many values parameter `p` takes when set; `HD_INVALID_ENUM` if it cannot be set.
    fn settable_count(&mut self, p: HDenum) -> Option<usize> {
        match p {
            HD_CURRENT_FORCE => Some(3),
            HD_FORCE_RAMPING_RATE => Some(1),
            _ => {
                self.push_error(HD_INVALID_ENUM);
                None
            }
        }
    }

    fn write_param(&mut self, p: HDenum, v: &[f64]) {
        if v.iter().any(|x| !x.is_finite()) {
            self.push_error(HD_INVALID_VALUE);
            return;
        }
        match p {
            HD_CURRENT_FORCE => {
                if !self.in_own_frame() {
                    self.writes_outside_frame += 1;
                    self.push_error(HD_INVALID_OPERATION);
                    return;
                }
                self.frame_force = [v[0], v[1], v[2]];
            }
            HD_FORCE_RAMPING_RATE => self.force_ramping_rate = v[0],
            _ => self.push_error(HD_INVALID_ENUM),
        }
    }

    /// The end of a frame: what the device displays until the next one.
    fn commit_frame(&mut self) {
        self.frames += 1;
        let f = self.frame_force;
        let norm = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        let mut shown = [0.0; 3];
        if self.over_force {
            self.over_force = false;
            self.force_error();
        } else if self.force_output {
            if norm <= self.max_force {
                shown = f;
            } else if self.max_force_clamping {
                let k = self.max_force.max(0.0) / norm;
                shown = [f[0] * k, f[1] * k, f[2] * k];
            } else {
                self.force_error();
            }
        }
        if self.stall_at_frame >= 1.0 && self.frames as f64 == self.stall_at_frame.floor() {
            self.stall = true;
        }
        if self.error_at_frame >= 1.0 && self.frames as f64 == self.error_at_frame.floor() {
            let code = self.error_code;
            self.push_error(code);
            if faults_device(code) {
                self.force_output = false;
                shown = [0.0; 3];
            }
        }
        self.displayed = shown;
    }

    /// A force over the maximum with clamping off: the device's force error.
    fn force_error(&mut self) {
        self.push_error(HD_EXCEEDED_MAX_FORCE);
        self.force_output = false;
    }
}

/// Errors after which a real device drops its forces.
fn faults_device(code: HDerror) -> bool {
    matches!(
        code,
        HD_WARM_MOTORS
            | HD_EXCEEDED_MAX_FORCE
            | HD_EXCEEDED_MAX_FORCE_IMPULSE
            | HD_EXCEEDED_MAX_VELOCITY
            | HD_FORCE_ERROR
            | HD_DEVICE_FAULT
            | HD_COMM_ERROR
            | HD_COMM_CONFIG_ERROR
            | HD_TIMER_ERROR
    )
}

static STATE: Mutex<State> = Mutex::new(State::new(0));
/// Wakes the scheduler thread early (a stop or reset).
static WAKE: Condvar = Condvar::new();
/// Signalled whenever a callback ran, was removed, or the scheduler stopped.
static CHANGED: Condvar = Condvar::new();

fn lock() -> MutexGuard<'static, State> {
    // A panic while holding the lock leaves plain data behind: carry on with it.
    STATE.lock().unwrap_or_else(PoisonError::into_inner)
}

fn wait(cv: &Condvar, g: MutexGuard<'static, State>) -> MutexGuard<'static, State> {
    cv.wait(g).unwrap_or_else(PoisonError::into_inner)
}

// ---------------------------------------------------------------------------------------------
// Devices
// ---------------------------------------------------------------------------------------------

/// Initialises the device named `config` (NULL, `HD_DEFAULT_DEVICE`, for the default one; any
/// name is accepted and not read) and makes it current. Returns handle 1, or `HD_INVALID_HANDLE`
/// after pushing `HD_COMM_CONFIG_ERROR` (the `"devices"` hook is 0) or
/// `HD_DEVICE_ALREADY_INITIATED`.
#[unsafe(no_mangle)]
pub extern "C" fn hdInitDevice(config: HDstring) -> HHD {
    let _ = config;
    let mut g = lock();
    if !g.env_applied {
        g.env_applied = true;
        apply_env(&mut g);
    }
    if g.devices < 1.0 {
        g.push_error(HD_COMM_CONFIG_ERROR);
        return HD_INVALID_HANDLE;
    }
    if g.initialized {
        g.push_error(HD_DEVICE_ALREADY_INITIATED);
        return HD_INVALID_HANDLE;
    }
    g.initialized = true;
    g.inits += 1;
    g.force_output = false;
    g.max_force_clamping = false;
    g.force_ramping = false;
    g.software_force_limit = true;
    g.one_frame_limit = true;
    g.displayed = [0.0; 3];
    DEVICE
}

/// Disables device `h` (its forces drop); `HD_BAD_HANDLE` if it is not initialised.
#[unsafe(no_mangle)]
pub extern "C" fn hdDisableDevice(h: HHD) {
    let mut g = lock();
    if g.need_handle(h) {
        write_record(&g);
        g.initialized = false;
        g.in_frame = false;
        g.frame_owner = None;
        g.displayed = [0.0; 3];
    }
}

/// Makes `h` the current device; `HD_BAD_HANDLE` if it is not initialised.
#[unsafe(no_mangle)]
pub extern "C" fn hdMakeCurrentDevice(h: HHD) {
    lock().need_handle(h);
}

/// The current device: 1 while initialised, else `HD_INVALID_HANDLE`.
#[unsafe(no_mangle)]
pub extern "C" fn hdGetCurrentDevice() -> HHD {
    if lock().initialized {
        DEVICE
    } else {
        HD_INVALID_HANDLE
    }
}

/// Opens a frame on `h`: samples the stylus and clears the frame's force.
/// `HD_ILLEGAL_BEGIN` inside a frame, `HD_BAD_HANDLE` for a bad handle.
#[unsafe(no_mangle)]
pub extern "C" fn hdBeginFrame(h: HHD) {
    let mut g = lock();
    if !g.need_handle(h) {
        return;
    }
    if g.in_frame {
        g.push_error(HD_ILLEGAL_BEGIN);
        return;
    }
    let (p, v) = g.stylus(Instant::now());
    g.in_frame = true;
    g.frame_owner = Some(std::thread::current().id());
    g.frame_force = [0.0; 3];
    g.frame_position = p;
    g.frame_velocity = v;
}

/// Closes the frame on `h` and displays its force (see the crate docs). `HD_ILLEGAL_END` without
/// a frame open by this thread, `HD_BAD_HANDLE` for a bad handle.
#[unsafe(no_mangle)]
pub extern "C" fn hdEndFrame(h: HHD) {
    let mut g = lock();
    if !g.need_handle(h) {
        return;
    }
    if !g.in_own_frame() {
        g.push_error(HD_ILLEGAL_END);
        return;
    }
    g.in_frame = false;
    g.frame_owner = None;
    g.commit_frame();
}

/// Pops the most recent error; `HD_SUCCESS` when there is none.
#[unsafe(no_mangle)]
pub extern "C" fn hdGetError() -> HDErrorInfo {
    lock().errors.pop().unwrap_or(HDErrorInfo {
        errorCode: HD_SUCCESS,
        internalErrorCode: 0,
        hHD: HD_INVALID_HANDLE,
    })
}

/// A static, NUL-terminated description of error `code` (never NULL).
#[unsafe(no_mangle)]
pub extern "C" fn hdGetErrorString(code: HDerror) -> HDstring {
    let s: &'static CStr = match code {
        HD_SUCCESS => c"No error",
        HD_INVALID_ENUM => c"Invalid enumerant",
        HD_INVALID_VALUE => c"Invalid value",
        HD_INVALID_OPERATION => c"Invalid operation",
        HD_BAD_HANDLE => c"Invalid device handle",
        HD_WARM_MOTORS => c"Motors are warm",
        HD_EXCEEDED_MAX_FORCE => c"Exceeded maximum force",
        HD_EXCEEDED_MAX_FORCE_IMPULSE => c"Exceeded maximum force impulse",
        HD_EXCEEDED_MAX_VELOCITY => c"Exceeded maximum velocity",
        HD_FORCE_ERROR => c"Force error",
        HD_DEVICE_FAULT => c"Device fault",
        HD_DEVICE_ALREADY_INITIATED => c"Device already initiated",
        HD_COMM_ERROR => c"Communication error",
        HD_COMM_CONFIG_ERROR => c"Communication configuration error",
        HD_TIMER_ERROR => c"Timer error",
        HD_ILLEGAL_BEGIN => c"Illegal begin frame",
        HD_ILLEGAL_END => c"Illegal end frame",
        HD_FRAME_ERROR => c"Frame error",
        HD_INVALID_PRIORITY => c"Invalid scheduler priority",
        HD_SCHEDULER_FULL => c"Scheduler full",
        _ => c"Unknown error",
    };
    s.as_ptr()
}

/// Enables capability `cap` (`HD_FORCE_OUTPUT`, ...); `HD_INVALID_ENUM` if unknown.
#[unsafe(no_mangle)]
pub extern "C" fn hdEnable(cap: HDenum) {
    set_capability(cap, true);
}

/// Disables capability `cap`; `HD_INVALID_ENUM` if unknown. Disabling `HD_FORCE_OUTPUT` drops the
/// displayed force at once.
#[unsafe(no_mangle)]
pub extern "C" fn hdDisable(cap: HDenum) {
    set_capability(cap, false);
}

fn set_capability(cap: HDenum, on: bool) {
    let mut g = lock();
    if !g.need_device() {
        return;
    }
    match g.capability(cap) {
        Some(c) => *c = on,
        None => g.push_error(HD_INVALID_ENUM),
    }
    if cap == HD_FORCE_OUTPUT && !on {
        g.displayed = [0.0; 3];
    }
}

/// Whether capability `cap` is enabled (1/0); `HD_INVALID_ENUM` (and 0) if unknown.
#[unsafe(no_mangle)]
pub extern "C" fn hdIsEnabled(cap: HDenum) -> HDboolean {
    let mut g = lock();
    if !g.need_device() {
        return 0;
    }
    match g.capability(cap) {
        Some(c) => u8::from(*c),
        None => {
            g.push_error(HD_INVALID_ENUM);
            0
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Parameters
// ---------------------------------------------------------------------------------------------

/// Writes parameter `p`'s values to `out`, converted by `conv`.
///
/// # Safety
/// `out` is NULL or valid for writes of as many `T` as the parameter has (up to 6).
unsafe fn get_into<T>(p: HDenum, out: *mut T, conv: fn(f64) -> T) {
    let mut g = lock();
    if out.is_null() {
        g.push_error(HD_INVALID_VALUE);
        return;
    }
    let Some((values, n)) = g.read_param(p) else {
        return;
    };
    drop(g);
    for (i, v) in values.iter().take(n).enumerate() {
        // SAFETY: `out` is not NULL and, by this function's contract (the HD API's: the caller
        // passes an array as long as the parameter), valid for `n` writes of `T`.
        unsafe { out.add(i).write(conv(*v)) };
    }
}

/// Reads parameter `p`'s values from `v`, converted by `conv`, and sets them.
///
/// # Safety
/// `v` is NULL or valid for reads of as many `T` as the parameter takes (up to 3).
unsafe fn set_from<T: Copy>(p: HDenum, v: *const T, conv: fn(T) -> f64) {
    let mut g = lock();
    let Some(n) = g.settable_count(p) else {
        return;
    };
    if v.is_null() {
        g.push_error(HD_INVALID_VALUE);
        return;
    }
    let mut values = [0.0; 3];
    for (i, slot) in values.iter_mut().take(n).enumerate() {
        // SAFETY: `v` is not NULL and, by this function's contract (the HD API's), valid for `n`
        // reads of `T`.
        *slot = conv(unsafe { v.add(i).read() });
    }
    g.write_param(p, &values[..n]);
}

/// Gets parameter `p` as booleans (nonzero → 1).
///
/// # Safety
/// `out` is NULL or points to an array at least as long as the parameter (up to 6 values).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hdGetBooleanv(p: HDenum, out: *mut HDboolean) {
    // SAFETY: forwarded from this function's contract.
    unsafe { get_into(p, out, |v| u8::from(v != 0.0)) }
}

/// Gets parameter `p` as integers (rounded).
///
/// # Safety
/// `out` is NULL or points to an array at least as long as the parameter (up to 6 values).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hdGetIntegerv(p: HDenum, out: *mut HDint) {
    // SAFETY: forwarded from this function's contract.
    unsafe { get_into(p, out, |v| v.round() as HDint) }
}

/// Gets parameter `p` as floats.
///
/// # Safety
/// `out` is NULL or points to an array at least as long as the parameter (up to 6 values).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hdGetFloatv(p: HDenum, out: *mut HDfloat) {
    // SAFETY: forwarded from this function's contract.
    unsafe { get_into(p, out, |v| v as HDfloat) }
}

/// Gets parameter `p` as doubles.
///
/// # Safety
/// `out` is NULL or points to an array at least as long as the parameter (up to 6 values).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hdGetDoublev(p: HDenum, out: *mut HDdouble) {
    // SAFETY: forwarded from this function's contract.
    unsafe { get_into(p, out, |v| v) }
}

/// Gets parameter `p` as longs (rounded).
///
/// # Safety
/// `out` is NULL or points to an array at least as long as the parameter (up to 6 values).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hdGetLongv(p: HDenum, out: *mut HDlong) {
    // SAFETY: forwarded from this function's contract.
    unsafe { get_into(p, out, |v| v.round() as HDlong) }
}

/// A string parameter: model "Touch", vendor "3D Systems", serial "mock-0001", driver version
/// "mock". NULL and `HD_INVALID_ENUM` for any other parameter.
#[unsafe(no_mangle)]
pub extern "C" fn hdGetString(p: HDenum) -> HDstring {
    let mut g = lock();
    if !g.need_device() {
        return std::ptr::null();
    }
    let s: &'static CStr = match p {
        HD_DEVICE_MODEL_TYPE => c"Touch",
        HD_DEVICE_VENDOR => c"3D Systems",
        HD_DEVICE_SERIAL_NUMBER => c"mock-0001",
        HD_DEVICE_DRIVER_VERSION => c"mock",
        _ => {
            g.push_error(HD_INVALID_ENUM);
            return std::ptr::null();
        }
    };
    s.as_ptr()
}

/// Sets parameter `p` from doubles: `HD_CURRENT_FORCE` (3, N, inside a frame only, else
/// `HD_INVALID_OPERATION`) or `HD_FORCE_RAMPING_RATE` (1). NaN or infinite: `HD_INVALID_VALUE`.
///
/// # Safety
/// `v` is NULL or points to as many values as the parameter takes (3 or 1).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hdSetDoublev(p: HDenum, v: *const HDdouble) {
    // SAFETY: forwarded from this function's contract.
    unsafe { set_from(p, v, |x| x) }
}

/// Sets parameter `p` from floats (as [`hdSetDoublev`]).
///
/// # Safety
/// `v` is NULL or points to as many values as the parameter takes (3 or 1).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hdSetFloatv(p: HDenum, v: *const HDfloat) {
    // SAFETY: forwarded from this function's contract.
    unsafe { set_from(p, v, f64::from) }
}

/// Sets parameter `p` from integers (as [`hdSetDoublev`]).
///
/// # Safety
/// `v` is NULL or points to as many values as the parameter takes (3 or 1).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hdSetIntegerv(p: HDenum, v: *const HDint) {
    // SAFETY: forwarded from this function's contract.
    unsafe { set_from(p, v, f64::from) }
}

/// Sets parameter `p` from longs (as [`hdSetDoublev`]).
///
/// # Safety
/// `v` is NULL or points to as many values as the parameter takes (3 or 1).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn hdSetLongv(p: HDenum, v: *const HDlong) {
    // SAFETY: forwarded from this function's contract.
    unsafe { set_from(p, v, |x| x as f64) }
}

// ---------------------------------------------------------------------------------------------
// Calibration
// ---------------------------------------------------------------------------------------------

/// The calibration state: the `"calibration"` hook (default `HD_CALIBRATION_OK`). Without a
/// device: `HD_BAD_HANDLE` and 0.
#[unsafe(no_mangle)]
pub extern "C" fn hdCheckCalibration() -> HDenum {
    let mut g = lock();
    if !g.need_device() {
        return 0;
    }
    g.calibration
}

/// Updates the calibration with `style` (`HD_CALIBRATION_ENCODER_RESET`, `_AUTO` or `_INKWELL`,
/// else `HD_INVALID_ENUM`): counted in `"calibration_updates"`; `NEEDS_UPDATE` becomes `OK`,
/// `NEEDS_MANUAL_INPUT` stays.
#[unsafe(no_mangle)]
pub extern "C" fn hdUpdateCalibration(style: HDenum) {
    let mut g = lock();
    if !g.need_device() {
        return;
    }
    let known = [
        HD_CALIBRATION_ENCODER_RESET,
        HD_CALIBRATION_AUTO,
        HD_CALIBRATION_INKWELL,
    ];
    if !known.iter().any(|&s| s as HDenum == style) {
        g.push_error(HD_INVALID_ENUM);
        return;
    }
    g.calibration_updates += 1;
    if g.calibration == HD_CALIBRATION_NEEDS_UPDATE {
        g.calibration = HD_CALIBRATION_OK;
    }
}

// ---------------------------------------------------------------------------------------------
// Scheduler
// ---------------------------------------------------------------------------------------------

/// Adds a callback; `None` (after pushing the error) when it cannot be scheduled.
fn schedule(
    g: &mut State,
    callback: Option<HDSchedulerCallback>,
    data: *mut c_void,
    priority: HDushort,
) -> Option<(HDSchedulerHandle, HDSchedulerCallback)> {
    let Some(callback) = callback else {
        g.push_error(HD_INVALID_VALUE);
        return None;
    };
    if g.entries.len() >= MAX_SCHEDULED {
        g.push_error(HD_SCHEDULER_FULL);
        return None;
    }
    let handle = g.next_handle;
    g.next_handle += 1;
    g.entries.push(Entry {
        handle,
        callback,
        data: UserData(data),
        priority,
    });
    Some((handle, callback))
}

/// Schedules `callback(data)` to be called every servo tick until it returns
/// `HD_CALLBACK_DONE`. Returns its handle (nonzero), or 0 after pushing `HD_SCHEDULER_FULL`
/// (more than 32 scheduled) or `HD_INVALID_VALUE` (a NULL callback).
#[unsafe(no_mangle)]
pub extern "C" fn hdScheduleAsynchronous(
    callback: Option<HDSchedulerCallback>,
    data: *mut c_void,
    priority: HDushort,
) -> HDSchedulerHandle {
    schedule(&mut lock(), callback, data, priority).map_or(0, |(h, _)| h)
}

/// Runs `callback(data)` on the scheduler thread, once per tick until it returns
/// `HD_CALLBACK_DONE`, and waits for that. With the scheduler stopped (or when called from the
/// scheduler thread itself) it runs on the calling thread instead. While the `"stall"` hook is
/// set, it waits until the stall ends or the scheduler stops.
#[unsafe(no_mangle)]
pub extern "C" fn hdScheduleSynchronous(
    callback: Option<HDSchedulerCallback>,
    data: *mut c_void,
    priority: HDushort,
) {
    let mut g = lock();
    if !g.running || g.stop_requested || g.on_scheduler_thread() {
        let Some(callback) = callback else {
            g.push_error(HD_INVALID_VALUE);
            return;
        };
        drop(g);
        while callback(data) == HD_CALLBACK_CONTINUE {}
        return;
    }
    let Some((handle, _)) = schedule(&mut g, callback, data, priority) else {
        return;
    };
    while g.running && !g.stop_requested && g.entries.iter().any(|e| e.handle == handle) {
        g = wait(&CHANGED, g);
    }
    g.entries.retain(|e| e.handle != handle);
}

/// Removes callback `handle`. When the callback is running on the scheduler thread, waits for it
/// to return first (after this, its data is no longer used). A handle never issued:
/// `HD_INVALID_VALUE`; one already finished: nothing.
#[unsafe(no_mangle)]
pub extern "C" fn hdUnschedule(handle: HDSchedulerHandle) {
    let mut g = lock();
    if handle == 0 || handle >= g.next_handle {
        g.push_error(HD_INVALID_VALUE);
        return;
    }
    g.entries.retain(|e| e.handle != handle);
    if !g.on_scheduler_thread() {
        while g.running_callback == Some(handle) {
            g = wait(&CHANGED, g);
        }
    }
    CHANGED.notify_all();
}

/// Whether callback `handle` is still scheduled (1/0). `HD_WAIT_CHECK_STATUS`: at once;
/// `HD_WAIT_INFINITE`: after waiting until it is not, or the scheduler stops. Other codes:
/// `HD_INVALID_ENUM` and 0.
#[unsafe(no_mangle)]
pub extern "C" fn hdWaitForCompletion(handle: HDSchedulerHandle, code: HDuint) -> HDboolean {
    let mut g = lock();
    let scheduled = |g: &State| g.entries.iter().any(|e| e.handle == handle);
    match code {
        HD_WAIT_CHECK_STATUS => u8::from(scheduled(&g)),
        HD_WAIT_INFINITE => {
            if !g.on_scheduler_thread() {
                while g.running && !g.stop_requested && scheduled(&g) {
                    g = wait(&CHANGED, g);
                }
            }
            u8::from(scheduled(&g))
        }
        _ => {
            g.push_error(HD_INVALID_ENUM);
            0
        }
    }
}

/// Starts the scheduler thread (a no-op when it runs).
#[unsafe(no_mangle)]
pub extern "C" fn hdStartScheduler() {
    let mut g = lock();
    if g.running && !g.stop_requested {
        return;
    }
    // A thread told to stop from inside a callback: let it finish first.
    if let Some(old) = g.thread.take() {
        drop(g);
        let _ = old.join();
        g = lock();
        if g.running && !g.stop_requested {
            return;
        }
    }
    g.generation += 1;
    let generation = g.generation;
    let spawned = std::thread::Builder::new()
        .name("hd-servo".into())
        .spawn(move || servo_thread(generation));
    match spawned {
        Ok(t) => {
            let now = Instant::now();
            g.running = true;
            g.stop_requested = false;
            g.thread_id = Some(t.thread().id());
            g.thread = Some(t);
            g.started = Some(now);
            g.tick_started = None;
            g.instantaneous_rate = 0.0;
        }
        Err(_) => g.push_error(HD_TIMER_ERROR),
    }
}

/// Stops the scheduler and joins its thread (idempotent). Called from a callback, it only asks
/// the thread to stop after the current tick. The last frame's force stays displayed (the
/// `"fx"`.. readouts) until force output is disabled.
#[unsafe(no_mangle)]
pub extern "C" fn hdStopScheduler() {
    let mut g = lock();
    if g.running {
        g.stop_requested = true;
        WAKE.notify_all();
    }
    if g.on_scheduler_thread() {
        return;
    }
    // The thread clears `running` on its way out.
    let thread = g.thread.take();
    drop(g);
    if let Some(t) = thread {
        let _ = t.join();
    }
}

/// Sets the servo rate (Hz, taking effect from the next tick); 0: `HD_INVALID_VALUE`.
#[unsafe(no_mangle)]
pub extern "C" fn hdSetSchedulerRate(rate_hz: HDulong) {
    let mut g = lock();
    if rate_hz == 0 {
        g.push_error(HD_INVALID_VALUE);
        return;
    }
    g.rate_hz = rate_hz as f64;
}

/// Seconds since the current servo tick started (0 while the scheduler is stopped).
#[unsafe(no_mangle)]
pub extern "C" fn hdGetSchedulerTimeStamp() -> HDdouble {
    let g = lock();
    match (g.running, g.tick_started) {
        (true, Some(t)) => t.elapsed().as_secs_f64(),
        _ => 0.0,
    }
}

fn period(rate_hz: f64) -> Duration {
    Duration::from_secs_f64(1.0 / rate_hz.clamp(0.1, 1.0e6))
}

/// The scheduler thread of generation `generation`.
fn servo_thread(generation: u64) {
    let mut order: Vec<(Reverse<HDushort>, HDSchedulerHandle)> = Vec::with_capacity(MAX_SCHEDULED);
    let mut g = lock();
    let mut deadline = g.started.unwrap_or_else(Instant::now);
    'ticks: loop {
        // Sleep until the deadline (woken early only to stop).
        loop {
            if g.generation != generation || g.stop_requested {
                break 'ticks;
            }
            let now = Instant::now();
            if now >= deadline {
                break;
            }
            g = WAKE
                .wait_timeout(g, deadline - now)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
        let now = Instant::now();
        if let Some(prev) = g.tick_started {
            let dt = now.saturating_duration_since(prev).as_secs_f64();
            g.instantaneous_rate = if dt > 0.0 { 1.0 / dt } else { 0.0 };
        }
        g.tick_started = Some(now);
        g.ticks += 1;
        if !g.stall {
            order.clear();
            order.extend(g.entries.iter().map(|e| (Reverse(e.priority), e.handle)));
            order.sort_unstable();
            for &(_, handle) in &order {
                // Earlier callbacks may have unscheduled this one, or stopped the scheduler.
                if g.generation != generation || g.stop_requested || g.stall {
                    break;
                }
                let Some(e) = g.entries.iter().find(|e| e.handle == handle) else {
                    continue;
                };
                let (callback, data) = (e.callback, e.data);
                g.running_callback = Some(handle);
                drop(g);
                let code = callback(data.0);
                g = lock();
                g.running_callback = None;
                g.callbacks += 1;
                if code != HD_CALLBACK_CONTINUE {
                    g.entries.retain(|e| e.handle != handle);
                }
                CHANGED.notify_all();
            }
        }
        // The next absolute deadline; more than a tick late (a slow callback, a loaded machine):
        // skip the missed ticks rather than run them back to back.
        let p = period(g.rate_hz);
        deadline += p;
        let now = Instant::now();
        if now > deadline + p {
            deadline = now;
        }
    }
    if g.generation == generation {
        g.running = false;
        g.thread_id = None;
        g.tick_started = None;
    }
    CHANGED.notify_all();
}

// ---------------------------------------------------------------------------------------------
// Test control
// ---------------------------------------------------------------------------------------------

/// The key's name, if `key` is a valid UTF-8 C string.
///
/// # Safety
/// `key` is NULL or a NUL-terminated string.
unsafe fn key_name<'a>(key: *const c_char) -> Option<&'a str> {
    if key.is_null() {
        return None;
    }
    // SAFETY: not NULL, and NUL-terminated by this function's contract.
    unsafe { CStr::from_ptr(key) }.to_str().ok()
}

/// Sets hook `key` to `value` (unknown keys are ignored):
/// `"devices"` (default 1; 0: `hdInitDevice` fails), `"x0"`, `"y0"`, `"z0"` (stylus centre, mm),
/// `"ax"`, `"ay"`, `"az"` (amplitudes, mm), `"freq_hz"`, `"buttons"` (mask), `"max_force"` (N,
/// default 3.3), `"calibration"` (`hdCheckCalibration`'s answer), `"stall"` (1: the scheduler
/// keeps ticking but calls no callbacks), `"stall_at_frame"` (stall at the end of that frame),
/// `"error_at_frame"` (push `"error_code"`, default
/// `HD_COMM_ERROR`, at the end of that frame, counted from 1 since the reset; 0: never),
/// `"error_code"`, `"over_force"` (1: the next end of frame is a max-force error), `"rate_hz"`.
///
/// # Safety
/// `key` is NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn mock_hd_set(key: *const c_char, value: f64) {
    // SAFETY: forwarded from this function's contract.
    let Some(key) = (unsafe { key_name(key) }) else {
        return;
    };
    set(&mut lock(), key, value);
}

/// Hooks for a mock loaded by a process the test cannot call into (a station's servo):
/// `COOP_MOCK_HD="key=value,key=value"` with [`mock_hd_set`]'s keys, applied at the first
/// `hdInitDevice` after a load or a reset. Malformed pairs are ignored.
fn apply_env(g: &mut State) {
    let Ok(hooks) = std::env::var("COOP_MOCK_HD") else {
        return;
    };
    for pair in hooks.split(',') {
        if let Some((k, v)) = pair.split_once('=') {
            if let Ok(v) = v.trim().parse::<f64>() {
                set(g, k.trim(), v);
            }
        }
    }
}

/// What the device did, appended as one line to the file `COOP_MOCK_HD_RECORD` names (when set)
/// as the device is disabled: for a test reading a child process's use of the mock.
fn write_record(g: &State) {
    let Ok(path) = std::env::var("COOP_MOCK_HD_RECORD") else {
        return;
    };
    let line = format!(
        "frames={} force_output={} fx={} fy={} fz={} max_force_clamping={} force_ramping={} \
         reads_outside_frame={} writes_outside_frame={} calibration_updates={} inits={}\n",
        g.frames,
        u8::from(g.force_output),
        g.displayed[0],
        g.displayed[1],
        g.displayed[2],
        u8::from(g.max_force_clamping),
        u8::from(g.force_ramping),
        g.reads_outside_frame,
        g.writes_outside_frame,
        g.calibration_updates,
        g.inits,
    );
    use std::io::Write;
    if let Ok(mut f) = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
    {
        let _ = f.write_all(line.as_bytes());
    }
}

/// Sets hook `key` (see [`mock_hd_set`]).
fn set(g: &mut State, key: &str, value: f64) {
    match key {
        "devices" => g.devices = value,
        "x0" => g.p0[0] = value,
        "y0" => g.p0[1] = value,
        "z0" => g.p0[2] = value,
        "ax" => g.amplitude[0] = value,
        "ay" => g.amplitude[1] = value,
        "az" => g.amplitude[2] = value,
        "freq_hz" => g.freq_hz = value,
        "buttons" => g.buttons = value,
        "max_force" => g.max_force = value,
        "calibration" => g.calibration = value as HDenum,
        "stall" => g.stall = value != 0.0,
        "stall_at_frame" => g.stall_at_frame = value,
        "error_at_frame" => g.error_at_frame = value,
        "error_code" => g.error_code = value as HDerror,
        "over_force" => g.over_force = value != 0.0,
        "rate_hz" if value > 0.0 && value.is_finite() => g.rate_hz = value,
        _ => {}
    }
}

/// Reads hook or readout `key`; NaN if unknown. Besides the hooks of [`mock_hd_set`]:
/// `"fx"`, `"fy"`, `"fz"` (N displayed since the last end of frame; 0 with force output off),
/// `"force_output"`, `"max_force_clamping"`, `"force_ramping"`, `"software_force_limit"`,
/// `"one_frame_limit"` (1/0), `"frames"`, `"ticks"`, `"callbacks"` (calls made by the scheduler
/// thread), `"inits"`, `"initialized"`, `"scheduler_running"`, `"scheduled"` (callbacks now
/// scheduled), `"calibration_updates"`, `"reads_outside_frame"`, `"writes_outside_frame"`,
/// `"in_frame"`, `"errors"` (depth of the error stack).
///
/// # Safety
/// `key` is NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn mock_hd_get(key: *const c_char) -> f64 {
    // SAFETY: forwarded from this function's contract.
    let Some(key) = (unsafe { key_name(key) }) else {
        return f64::NAN;
    };
    let g = lock();
    let flag = |b: bool| if b { 1.0 } else { 0.0 };
    match key {
        "devices" => g.devices,
        "x0" => g.p0[0],
        "y0" => g.p0[1],
        "z0" => g.p0[2],
        "ax" => g.amplitude[0],
        "ay" => g.amplitude[1],
        "az" => g.amplitude[2],
        "freq_hz" => g.freq_hz,
        "buttons" => g.buttons,
        "max_force" => g.max_force,
        "calibration" => f64::from(g.calibration),
        "stall" => flag(g.stall),
        "stall_at_frame" => g.stall_at_frame,
        "error_at_frame" => g.error_at_frame,
        "error_code" => f64::from(g.error_code),
        "over_force" => flag(g.over_force),
        "rate_hz" => g.rate_hz,
        "fx" => g.displayed[0],
        "fy" => g.displayed[1],
        "fz" => g.displayed[2],
        "force_output" => flag(g.force_output),
        "max_force_clamping" => flag(g.max_force_clamping),
        "force_ramping" => flag(g.force_ramping),
        "software_force_limit" => flag(g.software_force_limit),
        "one_frame_limit" => flag(g.one_frame_limit),
        "frames" => g.frames as f64,
        "ticks" => g.ticks as f64,
        "callbacks" => g.callbacks as f64,
        "inits" => g.inits as f64,
        "initialized" => flag(g.initialized),
        "scheduler_running" => flag(g.running && !g.stop_requested),
        "scheduled" => g.entries.len() as f64,
        "calibration_updates" => g.calibration_updates as f64,
        "reads_outside_frame" => g.reads_outside_frame as f64,
        "writes_outside_frame" => g.writes_outside_frame as f64,
        "in_frame" => flag(g.in_frame),
        "errors" => g.errors.len() as f64,
        _ => f64::NAN,
    }
}

/// Stops the scheduler (joining its thread) and puts everything back to its defaults: no
/// device, no callbacks, no errors, counters at zero, hooks at their defaults.
#[unsafe(no_mangle)]
pub extern "C" fn mock_hd_reset() {
    hdStopScheduler();
    let mut g = lock();
    let generation = g.generation + 1;
    // A thread still finishing (stopped from inside a callback) sees the new generation and exits.
    *g = State::new(generation);
    WAKE.notify_all();
    CHANGED.notify_all();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The library's state is global: one test at a time, each from a reset.
    static SERIAL: Mutex<()> = Mutex::new(());

    fn fresh() -> MutexGuard<'static, ()> {
        let guard = SERIAL.lock().unwrap_or_else(PoisonError::into_inner);
        mock_hd_reset();
        guard
    }

    fn set(key: &CStr, value: f64) {
        // SAFETY: a NUL-terminated string.
        unsafe { mock_hd_set(key.as_ptr(), value) }
    }

    fn get(key: &CStr) -> f64 {
        // SAFETY: a NUL-terminated string.
        unsafe { mock_hd_get(key.as_ptr()) }
    }

    fn doubles(p: HDenum) -> [f64; 6] {
        let mut out = [0.0; 6];
        // SAFETY: room for the longest parameter (6 values).
        unsafe { hdGetDoublev(p, out.as_mut_ptr()) };
        out
    }

    fn integer(p: HDenum) -> i32 {
        let mut out = [0; 6];
        // SAFETY: room for the longest parameter (6 values).
        unsafe { hdGetIntegerv(p, out.as_mut_ptr()) };
        out[0]
    }

    fn set_force(f: [f64; 3]) {
        // SAFETY: three doubles, as HD_CURRENT_FORCE takes.
        unsafe { hdSetDoublev(HD_CURRENT_FORCE, f.as_ptr()) }
    }

    fn frame(f: [f64; 3]) {
        hdBeginFrame(1);
        set_force(f);
        hdEndFrame(1);
    }

    fn error() -> HDerror {
        hdGetError().errorCode
    }

    /// Polls `cond` for up to 5 s.
    fn eventually(cond: impl Fn() -> bool) -> bool {
        let until = Instant::now() + Duration::from_secs(5);
        while Instant::now() < until {
            if cond() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        cond()
    }

    #[test]
    fn init_disable_and_device_strings() {
        let _g = fresh();
        assert_eq!(hdGetCurrentDevice(), HD_INVALID_HANDLE);
        assert_eq!(hdInitDevice(HD_DEFAULT_DEVICE), 1);
        assert_eq!((get(c"initialized"), get(c"inits")), (1.0, 1.0));
        assert_eq!(hdGetCurrentDevice(), 1);
        assert_eq!(hdInitDevice(c"Default Device".as_ptr()), HD_INVALID_HANDLE);
        let e = hdGetError();
        assert_eq!(
            e,
            HDErrorInfo {
                errorCode: HD_DEVICE_ALREADY_INITIATED,
                internalErrorCode: 0,
                hHD: 1
            }
        );
        assert_eq!(error(), HD_SUCCESS);
        // SAFETY: the library's strings are static and NUL-terminated.
        let s = |p| unsafe { CStr::from_ptr(hdGetString(p)) }.to_str().unwrap();
        assert_eq!(s(HD_DEVICE_MODEL_TYPE), "Touch");
        assert_eq!(s(HD_DEVICE_VENDOR), "3D Systems");
        assert_eq!(s(HD_DEVICE_SERIAL_NUMBER), "mock-0001");
        assert_eq!(s(HD_DEVICE_DRIVER_VERSION), "mock");
        assert!(hdGetString(0x1234).is_null());
        assert_eq!(error(), HD_INVALID_ENUM);
        assert_eq!((integer(HD_INPUT_DOF), integer(HD_OUTPUT_DOF)), (6, 3));
        assert_eq!(integer(HD_CALIBRATION_STYLE), HD_CALIBRATION_INKWELL);
        assert_eq!(integer(HD_UPDATE_RATE), 1000);
        assert_eq!(doubles(HD_NOMINAL_MAX_FORCE)[0], 3.3);
        assert_eq!(
            doubles(HD_USABLE_WORKSPACE_DIMENSIONS),
            [-80.0, -60.0, -35.0, 80.0, 60.0, 35.0]
        );
        let mut f = [0.0f32; 1];
        // SAFETY: one float, as the parameter has.
        unsafe { hdGetFloatv(HD_NOMINAL_MAX_CONTINUOUS_FORCE, f.as_mut_ptr()) };
        assert_eq!(f[0], 0.88);
        // SAFETY: NULL is allowed (an error).
        unsafe { hdGetDoublev(HD_CURRENT_POSITION, std::ptr::null_mut()) };
        assert_eq!(error(), HD_INVALID_VALUE);
        hdEnable(0x4999);
        assert_eq!(error(), HD_INVALID_ENUM);

        hdDisableDevice(1);
        assert_eq!(get(c"initialized"), 0.0);
        hdDisableDevice(1);
        assert_eq!(error(), HD_BAD_HANDLE);
        assert_eq!(hdInitDevice(HD_DEFAULT_DEVICE), 1);
        assert_eq!(get(c"inits"), 2.0);
        hdDisableDevice(1);

        set(c"devices", 0.0);
        assert_eq!(hdInitDevice(HD_DEFAULT_DEVICE), HD_INVALID_HANDLE);
        let e = hdGetError();
        assert_eq!(
            (e.errorCode, e.hHD),
            (HD_COMM_CONFIG_ERROR, HD_INVALID_HANDLE)
        );
        // SAFETY: the library's strings are static and NUL-terminated.
        let msg = unsafe { CStr::from_ptr(hdGetErrorString(HD_COMM_ERROR)) };
        assert_eq!(msg.to_str().unwrap(), "Communication error");
        assert!(get(c"no such key").is_nan());
        set(c"no such key", 1.0);
    }

    #[test]
    fn a_frame_sets_a_force_and_reads_it_back() {
        let _g = fresh();
        assert_eq!(hdInitDevice(HD_DEFAULT_DEVICE), 1);
        // Force output starts off: the frame's force is kept but not displayed.
        frame([1.0, 0.0, 0.0]);
        assert_eq!(get(c"fx"), 0.0);
        hdEnable(HD_FORCE_OUTPUT);
        assert_eq!(hdIsEnabled(HD_FORCE_OUTPUT), 1);
        hdBeginFrame(1);
        assert_eq!(get(c"in_frame"), 1.0);
        set_force([1.0, -2.0, 0.5]);
        assert_eq!(doubles(HD_CURRENT_FORCE)[..3], [1.0, -2.0, 0.5]);
        hdBeginFrame(1);
        assert_eq!(error(), HD_ILLEGAL_BEGIN);
        hdEndFrame(1);
        assert_eq!(
            (get(c"fx"), get(c"fy"), get(c"fz")),
            (1.0, -2.0, 0.5),
            "displayed at the end of the frame"
        );
        assert_eq!(doubles(HD_LAST_FORCE)[..3], [1.0, -2.0, 0.5]);
        assert_eq!((get(c"frames"), get(c"in_frame")), (2.0, 0.0));
        assert_eq!(get(c"reads_outside_frame"), 1.0);
        hdEndFrame(1);
        assert_eq!(error(), HD_ILLEGAL_END);
        hdBeginFrame(7);
        assert_eq!(error(), HD_BAD_HANDLE);

        set_force([1.0, 1.0, 1.0]);
        assert_eq!(error(), HD_INVALID_OPERATION);
        assert_eq!(get(c"writes_outside_frame"), 1.0);
        hdBeginFrame(1);
        set_force([f64::NAN, 0.0, 0.0]);
        assert_eq!(error(), HD_INVALID_VALUE);
        let ints = [1, 0, 0];
        // SAFETY: three integers, as HD_CURRENT_FORCE takes.
        unsafe { hdSetIntegerv(HD_CURRENT_FORCE, ints.as_ptr()) };
        hdEndFrame(1);
        assert_eq!(get(c"fx"), 1.0);
        // A frame without a force displays none.
        frame([0.0; 3]);
        hdBeginFrame(1);
        hdEndFrame(1);
        assert_eq!(get(c"fx"), 0.0);
        assert_eq!(error(), HD_SUCCESS);

        // The stylus: at rest at the origin, or where the hooks put it.
        assert_eq!(doubles(HD_CURRENT_POSITION)[..3], [0.0; 3]);
        set(c"x0", 10.0);
        set(c"buttons", 3.0);
        hdBeginFrame(1);
        assert_eq!(doubles(HD_CURRENT_POSITION)[..3], [10.0, 0.0, 0.0]);
        assert_eq!(integer(HD_CURRENT_BUTTONS), 3);
        hdEndFrame(1);
    }

    #[test]
    fn clamping_versus_the_over_force_error() {
        let _g = fresh();
        assert_eq!(hdInitDevice(HD_DEFAULT_DEVICE), 1);
        hdEnable(HD_FORCE_OUTPUT);
        hdEnable(HD_MAX_FORCE_CLAMPING);
        frame([6.0, 0.0, 0.0]);
        assert!((get(c"fx") - 3.3).abs() < 1e-12, "{}", get(c"fx"));
        assert_eq!(error(), HD_SUCCESS);

        hdDisable(HD_MAX_FORCE_CLAMPING);
        frame([6.0, 0.0, 0.0]);
        assert_eq!(error(), HD_EXCEEDED_MAX_FORCE);
        assert_eq!((get(c"fx"), get(c"force_output")), (0.0, 0.0));
        frame([1.0, 0.0, 0.0]);
        assert_eq!(get(c"fx"), 0.0, "force output stays off after the error");

        hdEnable(HD_FORCE_OUTPUT);
        set(c"over_force", 1.0);
        frame([1.0, 0.0, 0.0]);
        assert_eq!(error(), HD_EXCEEDED_MAX_FORCE);
        assert_eq!((get(c"fx"), get(c"force_output")), (0.0, 0.0));
        hdEnable(HD_FORCE_OUTPUT);
        frame([1.0, 0.0, 0.0]);
        assert_eq!(get(c"fx"), 1.0, "over_force is one frame only");

        set(c"max_force", 0.5);
        hdEnable(HD_MAX_FORCE_CLAMPING);
        hdEnable(HD_FORCE_RAMPING);
        frame([0.0, 3.0, 4.0]);
        assert!((get(c"fy") - 0.3).abs() < 1e-12 && (get(c"fz") - 0.4).abs() < 1e-12);
        assert_eq!(get(c"force_ramping"), 1.0);
    }

    #[test]
    fn an_injected_error_pops_and_faults_the_device() {
        let _g = fresh();
        assert_eq!(hdInitDevice(HD_DEFAULT_DEVICE), 1);
        hdEnable(HD_FORCE_OUTPUT);
        set(c"error_at_frame", 2.0);
        frame([1.0, 0.0, 0.0]);
        assert_eq!((error(), get(c"fx")), (HD_SUCCESS, 1.0));
        frame([1.0, 0.0, 0.0]);
        let e = hdGetError();
        assert_eq!((e.errorCode, e.hHD), (HD_COMM_ERROR, 1));
        assert_eq!((get(c"fx"), get(c"force_output")), (0.0, 0.0));
        assert_eq!(error(), HD_SUCCESS);

        // The stack keeps the newest 32.
        for _ in 0..40 {
            hdBeginFrame(9);
        }
        assert_eq!(get(c"errors"), 32.0);
        while error() != HD_SUCCESS {}

        set(c"calibration", f64::from(HD_CALIBRATION_NEEDS_UPDATE));
        assert_eq!(hdCheckCalibration(), HD_CALIBRATION_NEEDS_UPDATE);
        hdUpdateCalibration(HD_CALIBRATION_INKWELL as HDenum);
        assert_eq!(hdCheckCalibration(), HD_CALIBRATION_OK);
        set(c"calibration", f64::from(HD_CALIBRATION_NEEDS_MANUAL_INPUT));
        hdUpdateCalibration(HD_CALIBRATION_AUTO as HDenum);
        assert_eq!(hdCheckCalibration(), HD_CALIBRATION_NEEDS_MANUAL_INPUT);
        assert_eq!(get(c"calibration_updates"), 2.0);
    }

    static COUNT: Mutex<u32> = Mutex::new(0);
    static CONTINUING: Mutex<u32> = Mutex::new(0);
    static ORDER: Mutex<Vec<u32>> = Mutex::new(Vec::new());
    static SYNC_SAW: Mutex<Option<(ThreadId, [f64; 3])>> = Mutex::new(None);

    /// Counts into the `Mutex<u32>` `data` points to; done at 5.
    extern "C" fn five_times(data: *mut c_void) -> HDCallbackCode {
        // SAFETY: the tests pass a pointer to a `static Mutex<u32>`.
        let count = unsafe { &*(data as *const Mutex<u32>) };
        let mut n = count.lock().unwrap();
        *n += 1;
        if *n >= 5 {
            HD_CALLBACK_DONE
        } else {
            HD_CALLBACK_CONTINUE
        }
    }

    extern "C" fn forever(data: *mut c_void) -> HDCallbackCode {
        // SAFETY: the tests pass a pointer to a `static Mutex<u32>`.
        let count = unsafe { &*(data as *const Mutex<u32>) };
        *count.lock().unwrap() += 1;
        hdBeginFrame(hdGetCurrentDevice());
        set_force([0.5, 0.0, 0.0]);
        hdEndFrame(hdGetCurrentDevice());
        HD_CALLBACK_CONTINUE
    }

    extern "C" fn low(_: *mut c_void) -> HDCallbackCode {
        ORDER.lock().unwrap().push(1);
        HD_CALLBACK_DONE
    }

    extern "C" fn high(_: *mut c_void) -> HDCallbackCode {
        ORDER.lock().unwrap().push(100);
        HD_CALLBACK_DONE
    }

    extern "C" fn sample_once(_: *mut c_void) -> HDCallbackCode {
        hdBeginFrame(1);
        let p = doubles(HD_CURRENT_POSITION);
        hdEndFrame(1);
        *SYNC_SAW.lock().unwrap() = Some((std::thread::current().id(), [p[0], p[1], p[2]]));
        HD_CALLBACK_DONE
    }

    fn data(m: &'static Mutex<u32>) -> *mut c_void {
        m as *const Mutex<u32> as *mut c_void
    }

    #[test]
    fn the_scheduler_calls_callbacks_until_done_and_stalls_on_request() {
        let _g = fresh();
        *COUNT.lock().unwrap() = 0;
        *CONTINUING.lock().unwrap() = 0;
        ORDER.lock().unwrap().clear();
        *SYNC_SAW.lock().unwrap() = None;
        assert_eq!(hdInitDevice(HD_DEFAULT_DEVICE), 1);
        hdEnable(HD_FORCE_OUTPUT);

        // Synchronous with the scheduler stopped: on this thread.
        hdScheduleSynchronous(Some(sample_once), std::ptr::null_mut(), 5);
        let (id, _) = SYNC_SAW.lock().unwrap().take().unwrap();
        assert_eq!(id, std::thread::current().id());

        // Priority order within a tick: highest first.
        let l = hdScheduleAsynchronous(Some(low), std::ptr::null_mut(), 1);
        let h = hdScheduleAsynchronous(Some(high), std::ptr::null_mut(), 100);
        assert!(l != 0 && h != 0 && l != h);
        let five = hdScheduleAsynchronous(Some(five_times), data(&COUNT), 50);
        assert_eq!(get(c"scheduled"), 3.0);
        assert_eq!(hdWaitForCompletion(five, HD_WAIT_CHECK_STATUS), 1);
        set(c"x0", 4.0);
        set(c"ay", 2.0);
        set(c"freq_hz", 1.0);
        hdSetSchedulerRate(500);
        hdStartScheduler();
        hdStartScheduler();
        assert_eq!(get(c"scheduler_running"), 1.0);
        assert_eq!(hdWaitForCompletion(five, HD_WAIT_INFINITE), 0);
        assert!(eventually(|| get(c"scheduled") == 0.0));
        assert_eq!(*COUNT.lock().unwrap(), 5, "DONE removed it");
        assert_eq!(*ORDER.lock().unwrap(), [100, 1]);
        assert!(get(c"ticks") >= 5.0);
        assert_eq!(integer(HD_UPDATE_RATE), 500);

        // Synchronous with the scheduler running: on its thread, and waited for.
        hdScheduleSynchronous(Some(sample_once), std::ptr::null_mut(), 5);
        let (id, p) = SYNC_SAW.lock().unwrap().take().unwrap();
        assert_ne!(id, std::thread::current().id());
        assert!(p[0] == 4.0 && p[1].abs() <= 2.0 && p[2] == 0.0, "{p:?}");
        assert!(hdGetSchedulerTimeStamp() >= 0.0);

        // A servo callback that keeps going, then a stall.
        let servo = hdScheduleAsynchronous(Some(forever), data(&CONTINUING), 10);
        assert!(eventually(|| *CONTINUING.lock().unwrap() > 3));
        assert_eq!(get(c"fx"), 0.5);
        set(c"stall", 1.0);
        // A tick under way when the stall was set has finished once the next one has begun.
        let t0 = get(c"ticks");
        assert!(eventually(|| get(c"ticks") >= t0 + 2.0));
        let calls = *CONTINUING.lock().unwrap();
        assert!(
            eventually(|| get(c"ticks") >= t0 + 10.0),
            "the thread still ticks"
        );
        assert_eq!(
            *CONTINUING.lock().unwrap(),
            calls,
            "no callbacks while stalled"
        );
        set(c"stall", 0.0);
        assert!(eventually(|| *CONTINUING.lock().unwrap() > calls));

        hdUnschedule(servo);
        assert_eq!(get(c"scheduled"), 0.0);
        let after = *CONTINUING.lock().unwrap();
        std::thread::sleep(Duration::from_millis(20));
        assert_eq!(
            *CONTINUING.lock().unwrap(),
            after,
            "unscheduled: no more calls"
        );
        hdUnschedule(servo);
        assert_eq!(error(), HD_SUCCESS, "unscheduling twice is harmless");

        hdStopScheduler();
        hdStopScheduler();
        assert_eq!(get(c"scheduler_running"), 0.0);
        assert_eq!(get(c"fx"), 0.5, "the last frame's force stays displayed");
        hdDisable(HD_FORCE_OUTPUT);
        assert_eq!(get(c"fx"), 0.0, "until force output is off");

        // Full.
        for _ in 0..MAX_SCHEDULED {
            assert_ne!(
                hdScheduleAsynchronous(Some(low), std::ptr::null_mut(), 0),
                0
            );
        }
        assert_eq!(
            hdScheduleAsynchronous(Some(low), std::ptr::null_mut(), 0),
            0
        );
        assert_eq!(error(), HD_SCHEDULER_FULL);
        mock_hd_reset();
        assert_eq!((get(c"scheduled"), get(c"initialized")), (0.0, 0.0));
    }
}
