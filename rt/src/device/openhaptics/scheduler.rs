//! The HD scheduler as the station's servo loop: one callback per scheduler tick opens a frame,
//! runs the servo step in it and closes it; the thread that started the scheduler watches it.

use std::cell::UnsafeCell;
use std::ffi::c_void;
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::ffi::{consts::*, Api};
use super::{calibration_style, call_failed, FrameShared, OpenHapticsConfig, OpenHapticsError};
use crate::device::{VendorLoop, VendorLoopError, VendorLoopSummary};
use crate::stats::LoopStats;
use crate::sync::{AtomicU64, Ordering};
use crate::timer::monotonic_ns;

/// Runs a device's servo loop in the HD scheduler ([`HdScheduler::run`]).
#[derive(Debug)]
pub struct HdScheduler {
    api: &'static Api,
    handle: u32,
    shared: Arc<FrameShared>,
    period_ns: u64,
    stall: Duration,
}

/// What ended a run from inside the callback.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u64)]
enum Ended {
    /// `hdBeginFrame` failed: nothing of the device could be touched.
    BeginFrame = 1,
    /// The device dropped its force output for an error of its own (a force or device error).
    DeviceError = 2,
    /// The servo step panicked.
    Panic = 3,
}

/// The HD errors after which a device drops its force output (`hdDefines.h`'s force errors and
/// device faults): the run ends, the servo is restarted and ramps in again from a fresh start.
fn drops_output(code: u32) -> bool {
    matches!(code, 0x0200..=0x0204 | 0x0300 | 0x0302..=0x0304)
}

/// How long the first tick may take to come after the scheduler starts, beyond `stall_ms`.
const FIRST_TICK_GRACE: Duration = Duration::from_millis(250);

/// What the callback works with; lives on [`HdScheduler::run_hd`]'s stack while the scheduler
/// may call it. Shared between the scheduler's thread and the watching one: the watcher reads
/// only the atomics, and only the scheduler's thread reaches into `tick`.
struct Context<'a> {
    api: &'static Api,
    handle: u32,
    shared: &'a FrameShared,
    tick: UnsafeCell<&'a mut (dyn FnMut(u64) -> bool + Send)>,
    stats: Option<&'a LoopStats>,
    /// The previous tick's start, ns (0: none yet).
    last_ns: AtomicU64,
    /// 1 once the callback has returned `HD_CALLBACK_DONE`.
    done: AtomicU64,
    /// What ended the run from inside the callback (0: nothing): see [`Ended`].
    ended: AtomicU64,
    /// The HD code that ended it.
    code: AtomicU64,
    /// Callbacks running now (0 or 1): the watcher must not free the context under one.
    inside: AtomicU64,
}

impl HdScheduler {
    pub(super) fn new(
        api: &'static Api,
        handle: u32,
        shared: Arc<FrameShared>,
        config: &OpenHapticsConfig,
    ) -> Self {
        Self {
            api,
            handle,
            shared,
            period_ns: 1_000_000_000 / u64::from(config.scheduler_rate_hz.max(1)),
            stall: Duration::from_secs_f64(config.stall_ms / 1e3),
        }
    }

    /// Starts the HD scheduler and calls `tick(now_ns)` once per scheduler tick, inside a frame
    /// (the device's `sample` and `command` are valid there), until `tick` returns false; then
    /// stops the scheduler. `stats` records each tick's lateness against the scheduler's period
    /// and its compute time, as our own loop records its wake-ups. The calling thread watches:
    /// a scheduler silent for `stall_ms` has its force output turned off and ends the run.
    ///
    /// # Errors
    /// The callback could not be scheduled, or the scheduler stalled.
    pub fn run_hd(
        &self,
        stats: Option<&LoopStats>,
        tick: &mut (dyn FnMut(u64) -> bool + Send),
    ) -> Result<VendorLoopSummary, OpenHapticsError> {
        let api = self.api;
        if let Some(s) = stats {
            s.set_period_ns(self.period_ns);
        }
        let start_ticks = self.shared.ticks.load(Ordering::Acquire);
        let ctx = Context {
            api,
            handle: self.handle,
            shared: &self.shared,
            tick: UnsafeCell::new(tick),
            stats,
            last_ns: AtomicU64::new(0),
            done: AtomicU64::new(0),
            ended: AtomicU64::new(0),
            code: AtomicU64::new(0),
            inside: AtomicU64::new(0),
        };
        api.drain_errors();
        // `ctx` outlives every call of the callback: the scheduler is stopped and the callback
        // unscheduled below before this function returns (on every path); the callback takes it
        // as a shared reference, and only its thread reaches into `tick`.
        // SAFETY: `ctx` stays valid for as long as the callback may run (above).
        let h = unsafe { api.schedule(servo_callback, std::ptr::from_ref(&ctx).cast_mut().cast()) };
        if let Some(code) = api.take_error() {
            // Whatever the handle, nothing may stay scheduled with a pointer to `ctx`.
            api.unschedule(h);
            api.drain_errors();
            return Err(call_failed(api, "hdScheduleAsynchronous", code));
        }
        api.start_scheduler();
        if let Some(code) = api.take_error() {
            api.stop_scheduler();
            api.unschedule(h);
            return Err(call_failed(api, "hdStartScheduler", code));
        }
        // Watch: the servo step ends the run (a stop leaves the device limp first); a silent
        // scheduler is turned off from here.
        let mut seen = self.shared.ticks.load(Ordering::Acquire);
        let mut since = Instant::now();
        // The first tick may come late (the vendor's thread starting): more time for it.
        let mut allowed = self.stall + FIRST_TICK_GRACE;
        let poll = (self.stall / 4).clamp(Duration::from_micros(500), Duration::from_millis(5));
        let mut stalled = None;
        while ctx.done.load(Ordering::Acquire) == 0 {
            std::thread::sleep(poll);
            let now = self.shared.ticks.load(Ordering::Acquire);
            if now != seen {
                seen = now;
                since = Instant::now();
                allowed = self.stall;
            } else if since.elapsed() >= allowed {
                // Off first: the vendor's thread may be the one that hangs.
                api.disable(HD_FORCE_OUTPUT);
                stalled = Some(u64::try_from(since.elapsed().as_millis()).unwrap_or(u64::MAX));
                break;
            }
        }
        api.stop_scheduler();
        api.unschedule(h);
        if ctx.inside.load(Ordering::Acquire) != 0 {
            // The vendor's stop returned with our callback still running on its thread: `ctx`
            // (and the servo it reaches) cannot be freed under it, nor the run go on. Output off,
            // and the process ends here; the supervisor starts a new servo.
            api.disable(HD_FORCE_OUTPUT);
            std::process::abort();
        }
        self.shared.in_frame.store(0, Ordering::Release);
        api.drain_errors();
        let ticks = self.shared.ticks.load(Ordering::Acquire) - start_ticks;
        // What the callback said ended the run comes first: a panic's report may outlast
        // `stall_ms`, and the watcher then took it for a stall.
        let code = u32::try_from(ctx.code.load(Ordering::Acquire)).unwrap_or(u32::MAX);
        match ctx.ended.load(Ordering::Acquire) {
            x if x == Ended::BeginFrame as u64 => Err(call_failed(api, "hdBeginFrame", code)),
            x if x == Ended::DeviceError as u64 => Err(call_failed(api, "hdEndFrame", code)),
            x if x == Ended::Panic as u64 => Err(OpenHapticsError::ServoPanicked),
            _ => match stalled {
                Some(ms) => Err(OpenHapticsError::Stalled { ms }),
                None => Ok(VendorLoopSummary { ticks }),
            },
        }
    }
}

impl VendorLoop for HdScheduler {
    fn run(
        &self,
        stats: Option<&LoopStats>,
        tick: &mut (dyn FnMut(u64) -> bool + Send),
    ) -> Result<VendorLoopSummary, VendorLoopError> {
        self.run_hd(stats, tick)
            .map_err(|e| VendorLoopError(e.to_string()))
    }
}

/// The scheduler's callback: one servo tick in one frame.
unsafe extern "C" fn servo_callback(data: *mut c_void) -> u32 {
    // REAL-TIME: no allocation, no lock, no logging; the HD API's own calls and the servo step.
    // `data` is the `Context` `run_hd` scheduled, alive until it has stopped the scheduler and
    // unscheduled this callback (and, should the vendor's stop return while this still runs,
    // `inside` makes `run_hd` end the process rather than free it); shared with the watching
    // thread, which reads only atomics.
    // SAFETY: a live `Context`, only ever borrowed shared (above).
    let ctx = unsafe { &*data.cast::<Context<'_>>() };
    ctx.inside.fetch_add(1, Ordering::AcqRel);
    let code = tick_once(ctx);
    ctx.inside.store(0, Ordering::Release);
    code
}

/// One tick: the calibration, the frame, the servo step in it, what the frame left.
fn tick_once(ctx: &Context<'_>) -> u32 {
    // REAL-TIME: no allocation, no lock, no logging; the HD API's own calls and the servo step.
    if ctx.done.load(Ordering::Relaxed) != 0 {
        return HD_CALLBACK_DONE;
    }
    let (api, shared) = (ctx.api, ctx.shared);
    let woke = monotonic_ns();
    // The calibration as the device sees it now. Updated where it asks (in a style that needs no
    // pose of the arm); the tick of an update, and any manual need, is a fault, so the safety
    // layer holds the force released and ramps it in again from the new positions.
    let cal = api.check_calibration();
    if cal == HD_CALIBRATION_NEEDS_UPDATE {
        if let Some(style) = calibration_style(api) {
            api.update_calibration(style);
            shared.calibration_updates.fetch_add(1, Ordering::Relaxed);
        }
    }
    shared.calibration.store(u64::from(cal), Ordering::Release);
    // What the calibration calls left is not the frame's.
    api.drain_errors();
    api.begin_frame(ctx.handle);
    if let Some(code) = api.take_error() {
        // No frame: nothing of the device may be touched this tick; the run ends.
        api.disable(HD_FORCE_OUTPUT);
        return end(ctx, Ended::BeginFrame, code);
    }
    shared.in_frame.store(1, Ordering::Release);
    // SAFETY: only the scheduler's one thread runs this callback, one call at a time, so this is
    // the only reference to the tick closure while it runs (the watcher never touches it).
    let tick = unsafe { &mut *ctx.tick.get() };
    // A panic must not unwind out of the C callback (that aborts with the force on): caught, the
    // frame's force is zeroed, the output turned off, and the run ends.
    let stepped = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| tick(woke)));
    shared.in_frame.store(0, Ordering::Release);
    if stepped.is_err() {
        api.set_force(coop_model::body::Vec3::zeros());
        api.end_frame(ctx.handle);
        api.disable(HD_FORCE_OUTPUT);
        api.drain_errors();
        return end(ctx, Ended::Panic, 0);
    }
    api.end_frame(ctx.handle);
    // The first error the frame left (the rest drained): a device that dropped its output for
    // it ends the run; any other is the next sample's fault.
    if let Some(code) = api.take_error() {
        api.drain_errors();
        if drops_output(code) {
            api.disable(HD_FORCE_OUTPUT);
            return end(ctx, Ended::DeviceError, code);
        }
        shared.end_error.store(u64::from(code), Ordering::Release);
    }
    let done = monotonic_ns();
    if let Some(s) = ctx.stats {
        s.record_tick(
            woke,
            ctx.last_ns.load(Ordering::Relaxed),
            done.saturating_sub(woke),
        );
    }
    ctx.last_ns.store(woke, Ordering::Relaxed);
    shared.ticks.fetch_add(1, Ordering::Release);
    if stepped.unwrap_or(false) {
        HD_CALLBACK_CONTINUE
    } else {
        ctx.done.store(1, Ordering::Release);
        HD_CALLBACK_DONE
    }
}

/// Ends the run from inside the callback for `why`, with the HD `code`.
fn end(ctx: &Context<'_>, why: Ended, code: u32) -> u32 {
    ctx.code.store(u64::from(code), Ordering::Release);
    ctx.ended.store(why as u64, Ordering::Release);
    ctx.done.store(1, Ordering::Release);
    HD_CALLBACK_DONE
}
