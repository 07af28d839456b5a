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

/// What the callback works with; lives on [`HdScheduler::run_hd`]'s stack while the scheduler
/// may call it. Shared between the scheduler's thread and the watching one: the watcher reads
/// only the atomics, and only the scheduler's thread reaches into `tick`.
struct Context<'a> {
    api: &'static Api,
    handle: u32,
    shared: &'a FrameShared,
    tick: UnsafeCell<&'a mut (dyn FnMut(u64) -> bool + Send)>,
    stats: Option<&'a LoopStats>,
    period_ns: u64,
    /// The previous tick's start, ns (0: none yet).
    last_ns: AtomicU64,
    /// 1 once the callback has returned `HD_CALLBACK_DONE`.
    done: AtomicU64,
    /// An HD call of the callback's own failed (`hdBeginFrame`), and with what (0: none).
    failed: AtomicU64,
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
            period_ns: self.period_ns,
            last_ns: AtomicU64::new(0),
            done: AtomicU64::new(0),
            failed: AtomicU64::new(0),
        };
        api.drain_errors();
        // SAFETY: `ctx` outlives every call of the callback: the scheduler is stopped and the
        // callback unscheduled below before this function returns (on every path); the callback
        // takes it as a shared reference, and only its thread reaches into `tick`.
        let h = unsafe { api.schedule(servo_callback, std::ptr::from_ref(&ctx).cast_mut().cast()) };
        if let Some(code) = api.take_error().or((h == 0).then_some(HD_COMM_ERROR)) {
            if h != 0 {
                api.unschedule(h);
            }
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
        let poll = (self.stall / 4).clamp(Duration::from_micros(500), Duration::from_millis(5));
        let mut stalled = None;
        while ctx.done.load(Ordering::Acquire) == 0 {
            std::thread::sleep(poll);
            let now = self.shared.ticks.load(Ordering::Acquire);
            if now != seen {
                seen = now;
                since = Instant::now();
            } else if since.elapsed() >= self.stall {
                // Off first: the vendor's thread may be the one that hangs.
                api.disable(HD_FORCE_OUTPUT);
                stalled = Some(u64::try_from(since.elapsed().as_millis()).unwrap_or(u64::MAX));
                break;
            }
        }
        api.stop_scheduler();
        api.unschedule(h);
        self.shared.in_frame.store(0, Ordering::Release);
        api.drain_errors();
        let ticks = self.shared.ticks.load(Ordering::Acquire) - start_ticks;
        if let Some(ms) = stalled {
            return Err(OpenHapticsError::Stalled { ms });
        }
        let failed = ctx.failed.load(Ordering::Acquire);
        if failed != 0 {
            let code = u32::try_from(failed).unwrap_or(u32::MAX);
            return Err(call_failed(api, "hdBeginFrame", code));
        }
        Ok(VendorLoopSummary { ticks })
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
    // SAFETY: `data` is the `Context` `run_hd` scheduled, alive until it has stopped the scheduler
    // and unscheduled this callback; shared with the watching thread, which reads only atomics.
    let ctx = unsafe { &*data.cast::<Context<'_>>() };
    if ctx.done.load(Ordering::Relaxed) != 0 {
        return HD_CALLBACK_DONE;
    }
    let (api, shared) = (ctx.api, ctx.shared);
    let woke = monotonic_ns();
    // The calibration as the device sees it now; updated where it asks (a manual one it cannot
    // be: the device faults until its stylus is back in the inkwell).
    let mut cal = api.check_calibration();
    if cal == HD_CALIBRATION_NEEDS_UPDATE {
        api.update_calibration(calibration_style(api));
        shared.calibration_updates.fetch_add(1, Ordering::Relaxed);
        cal = api.check_calibration();
    }
    shared.calibration.store(u64::from(cal), Ordering::Release);
    api.begin_frame(ctx.handle);
    if let Some(code) = api.take_error() {
        // No frame: nothing of the device may be touched this tick; the run ends.
        ctx.failed.store(u64::from(code), Ordering::Release);
        api.disable(HD_FORCE_OUTPUT);
        ctx.done.store(1, Ordering::Release);
        return HD_CALLBACK_DONE;
    }
    shared.in_frame.store(1, Ordering::Release);
    // SAFETY: only the scheduler's one thread runs this callback, one call at a time, so this is
    // the only reference to the tick closure while it runs (the watcher never touches it).
    let tick = unsafe { &mut *ctx.tick.get() };
    let keep_going = tick(woke);
    shared.in_frame.store(0, Ordering::Release);
    api.end_frame(ctx.handle);
    if let Some(code) = api.take_error() {
        shared.end_error.store(u64::from(code), Ordering::Release);
    }
    let done = monotonic_ns();
    if let Some(s) = ctx.stats {
        // Lateness against the scheduler's own period, as our loop records its wake-ups against
        // its deadlines.
        let last = ctx.last_ns.load(Ordering::Relaxed);
        let late = if last == 0 {
            0
        } else {
            woke.saturating_sub(last + ctx.period_ns)
        };
        let missed = u64::from(late >= ctx.period_ns);
        s.record(late, done.saturating_sub(woke), missed);
    }
    ctx.last_ns.store(woke, Ordering::Relaxed);
    shared.ticks.fetch_add(1, Ordering::Release);
    if keep_going {
        HD_CALLBACK_CONTINUE
    } else {
        ctx.done.store(1, Ordering::Release);
        HD_CALLBACK_DONE
    }
}
