//! The device's figures in the control block, published by the servo (its one writer): what the
//! device is, once when it opened; then, at most every [`PUBLISH_EVERY_NS`], what the safety layer
//! counted of it, what its bridge thread counted, the limits that acted, the last fault, and the
//! rates of new samples and commands over the current window (up to [`RATE_WINDOW_NS`]). Relaxed stores and
//! atomic loads only: it runs on the servo's thread after each tick, so `station status` can tell
//! what the device does without asking the servo anything.

use super::cartesian::{CartesianDevice, DeviceFault};
use super::safety::{fault_kind, Guarded, Limit};
use super::station::{BridgeCounts, StationDevice};
use crate::shm::control::ControlBlock;
use crate::shm::device::{DeviceCounts, DeviceShared};
use crate::sync::Ordering;

/// How often the figures are published at most, ns: `station status` reads them a few times a
/// second at most, and each publication is a few dozen stores the servo need not make every tick.
pub const PUBLISH_EVERY_NS: u64 = 10_000_000;
/// The window the rates are measured over, ns: a new one starts when it is full...
pub const RATE_WINDOW_NS: u64 = 1_000_000_000;
/// ... and they are published once it spans this much (so a device that just opened has its
/// rates within a tenth of a second, not after a second of zeros).
pub const RATE_SPAN_MIN_NS: u64 = 100_000_000;

/// The servo's publisher of its device's figures.
#[derive(Debug)]
pub struct DevicePublisher {
    last_ns: u64,
    /// The rates' window: when it started, and the new samples and commands then.
    window: (u64, u64, u64),
    /// The fault whose words the block holds.
    fault: Option<DeviceFault>,
}

impl DevicePublisher {
    /// Says in `shared` what the device under `g` is (setup: once, after it opened; allocates
    /// nothing but is not meant for the tick) and starts the rates' window at `now_ns`.
    pub fn new(shared: &DeviceShared, g: &Guarded<StationDevice>, now_ns: u64) -> Self {
        let info = g.device().info();
        shared.backend.store(info.backend);
        shared.model.store(&info.model);
        shared.serial.store(info.serial.as_deref().unwrap_or(""));
        ControlBlock::store_f64(&shared.native_rate_hz, info.native_rate_hz);
        shared.bridged.store(
            u64::from(g.device().bridge_counts().is_some()),
            Ordering::Relaxed,
        );
        shared.open_error.store("");
        let mut p = Self {
            last_ns: now_ns,
            window: (now_ns, 0, 0),
            fault: None,
        };
        p.publish_now(shared, now_ns, g);
        // SYNC: Release publishes what it is; pairs with the Acquire in `DeviceShared::is_open`.
        shared.open.store(1, Ordering::Release);
        p
    }

    /// Publishes the figures of `g` at `now_ns` if [`PUBLISH_EVERY_NS`] has passed since the last
    /// time.
    pub fn publish(&mut self, shared: &DeviceShared, now_ns: u64, g: &Guarded<StationDevice>) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        if now_ns.saturating_sub(self.last_ns) >= PUBLISH_EVERY_NS {
            self.publish_now(shared, now_ns, g);
        }
    }

    /// Publishes the figures of `g` at `now_ns` (also at the end, so the last count is there).
    pub fn publish_now(&mut self, shared: &DeviceShared, now_ns: u64, g: &Guarded<StationDevice>) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls (atomics only; a new fault's
        // words are formatted into the block's words).
        self.last_ns = now_ns;
        let mut c = *g.counts();
        if let Some(b) = g.device().bridge_counts() {
            take_bridge(&mut c, b);
        }
        shared.counts.store(&c);
        let (since, samples, commands) = self.window;
        let dt = now_ns.saturating_sub(since);
        if dt >= RATE_SPAN_MIN_NS {
            let rate = |n: u64, then: u64| n.saturating_sub(then) as f64 / (dt as f64 * 1e-9);
            ControlBlock::store_f64(&shared.sample_rate_hz, rate(c.new_samples, samples));
            ControlBlock::store_f64(&shared.command_rate_hz, rate(c.commands, commands));
        }
        if dt >= RATE_WINDOW_NS {
            self.window = (now_ns, c.new_samples, c.commands);
        }
        if let Some((f, at)) = g.last_fault() {
            if self.fault != Some(f) {
                self.fault = Some(f);
                shared.last_fault.store_fmt(format_args!("{f}"));
                shared
                    .last_fault_kind
                    .store(fault_kind(&f).code(), Ordering::Relaxed);
            }
            shared.last_fault_ns.store(at, Ordering::Relaxed);
        }
        for l in Limit::ALL {
            let k = l.code() as usize;
            shared.trips[k].store(g.trips()[k], Ordering::Relaxed);
        }
        shared
            .holding
            .store(g.holding().map_or(0, Limit::code), Ordering::Relaxed);
        shared.published_ns.store(now_ns, Ordering::Relaxed);
    }
}

/// Copies `b` into `c`'s bridge fields.
fn take_bridge(c: &mut DeviceCounts, b: BridgeCounts) {
    c.received = b.received;
    c.refused = b.refused;
    c.foreign = b.foreign;
    c.sent_forces = b.sent_forces;
    c.losses = b.losses;
    c.reconnects = b.reconnects;
}
