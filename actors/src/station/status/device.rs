//! The device section of `station status`: what the servo's device is and what it did, as the
//! servo published it in the control block's device group (`coop_rt::shm::device`): its samples
//! and their rate, stale and refused ones, faults with the last one's kind, commands, what its
//! bridge counted, and the safety limits that acted.

use std::collections::BTreeMap;
use std::fmt;

use coop_rt::device::safety::Limit;
use coop_rt::device::BridgeCounts;
use coop_rt::shm::control::ControlBlock;
use coop_rt::shm::device::{DeviceCounts, DeviceShared, FaultKind};
use coop_rt::sync::Ordering;
use serde::Serialize;

/// The device, as the servo last published it.
#[derive(Debug, Clone, Serialize)]
pub struct DeviceStatus {
    /// `sim`, `replay`, `haply`, `dhd`, `openhaptics` or `ros2`.
    pub backend: String,
    /// The model, as the device says it.
    pub model: String,
    /// Its serial number, where it tells one.
    pub serial: Option<String>,
    /// The rate its own loop or firmware runs at, as it says, Hz.
    pub native_rate_hz: f64,
    /// Servo ticks at which it gave a sample, since the servo opened it.
    pub samples: u64,
    /// ... whose time was newer than the one before (what the device delivered).
    pub new_samples: u64,
    /// New samples per second over the last second or less, Hz.
    pub sample_rate_hz: f64,
    /// Servo ticks at which its newest sample was older than its stale limit.
    pub stale: u64,
    /// Messages its bridge refused: not a sample, or from another publisher than the driver.
    pub refused: u64,
    /// Faults (sampling or commanding), by kind, and the last one.
    pub faults: FaultsStatus,
    /// Force commands it took.
    pub commands: u64,
    /// Force commands per second over the last second or less, Hz.
    pub command_rate_hz: f64,
    /// What its bridge thread counted (a device behind one: ROS 2, Haply).
    pub bridge: Option<BridgeCounts>,
    /// Episodes of each safety limit acting, by its name (only those that acted).
    pub trips: BTreeMap<&'static str, u64>,
    /// The limit holding the device released now, if any.
    pub holding: Option<&'static str>,
    /// How long ago the servo published these figures, s.
    pub age_s: f64,
}

/// A device's faults.
#[derive(Debug, Clone, Serialize)]
pub struct FaultsStatus {
    /// All kinds.
    pub total: u64,
    /// By kind: `disconnected` (stale), `call_failed`, `bad_value`.
    pub by_kind: BTreeMap<&'static str, u64>,
    /// The last one, if any.
    pub last: Option<LastFault>,
}

/// The last fault.
#[derive(Debug, Clone, Serialize)]
pub struct LastFault {
    /// Its kind.
    pub kind: &'static str,
    /// In words.
    pub text: String,
    /// How long ago, s.
    pub ago_s: f64,
}

impl DeviceStatus {
    /// The device section of `d`, or `None` before the servo opened its device.
    pub fn of(d: &DeviceShared) -> Option<Self> {
        if !d.is_open() {
            return None;
        }
        let now = coop_rt::timer::monotonic_ns();
        let ago = |ns: u64| now.saturating_sub(ns) as f64 / 1e9;
        let c: DeviceCounts = d.counts.load();
        let bridged = d.bridged.load(Ordering::Relaxed) == 1;
        let serial = d.serial.load();
        Some(Self {
            backend: d.backend.load(),
            model: d.model.load(),
            serial: (!serial.is_empty()).then_some(serial),
            native_rate_hz: ControlBlock::load_f64(&d.native_rate_hz),
            samples: c.samples,
            new_samples: c.new_samples,
            sample_rate_hz: ControlBlock::load_f64(&d.sample_rate_hz),
            stale: c.stale,
            refused: c.refused + c.foreign,
            faults: FaultsStatus {
                total: c.faults,
                by_kind: FaultKind::ALL
                    .iter()
                    .map(|&k| (k.name(), c.faults_of(k)))
                    .collect(),
                last: d.last_fault().map(|(kind, text, at)| LastFault {
                    kind: kind.name(),
                    text,
                    ago_s: ago(at),
                }),
            },
            commands: c.commands,
            command_rate_hz: ControlBlock::load_f64(&d.command_rate_hz),
            bridge: bridged.then_some(BridgeCounts {
                received: c.received,
                refused: c.refused,
                foreign: c.foreign,
                sent_forces: c.sent_forces,
                losses: c.losses,
                reconnects: c.reconnects,
            }),
            trips: Limit::ALL
                .iter()
                .map(|l| (l.name(), d.trips[l.code() as usize].load(Ordering::Relaxed)))
                .filter(|&(_, n)| n > 0)
                .collect(),
            holding: Limit::from_code(d.holding.load(Ordering::Relaxed)).map(Limit::name),
            age_s: ago(d.published_ns.load(Ordering::Relaxed)),
        })
    }
}

impl fmt::Display for DeviceStatus {
    /// A few lines, the first naming the device (each ends with a newline).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "device: {} {}{} (native {:.0} Hz): samples {} ({} new, {:.1} Hz), stale {}, refused {}; commands {} ({:.1} Hz)",
            self.backend,
            self.model,
            self.serial
                .as_ref()
                .map_or(String::new(), |s| format!(", serial {s}")),
            self.native_rate_hz,
            self.samples,
            self.new_samples,
            self.sample_rate_hz,
            self.stale,
            self.refused,
            self.commands,
            self.command_rate_hz
        )?;
        let by_kind: Vec<String> = self
            .faults
            .by_kind
            .iter()
            .filter(|&(_, &n)| n > 0)
            .map(|(k, n)| format!("{k} {n}"))
            .collect();
        match &self.faults.last {
            None => writeln!(f, "  faults: none")?,
            Some(l) => writeln!(
                f,
                "  faults: {} ({}); last: {} ({}) {:.3} s ago",
                self.faults.total,
                by_kind.join(", "),
                l.kind,
                l.text,
                l.ago_s
            )?,
        }
        if let Some(b) = &self.bridge {
            writeln!(
                f,
                "  bridge: received {}, refused {} (and {} from another publisher), forces sent {}, connections lost {}, reconnected {}",
                b.received, b.refused, b.foreign, b.sent_forces, b.losses, b.reconnects
            )?;
        }
        let trips: Vec<String> = self.trips.iter().map(|(l, n)| format!("{l} {n}")).collect();
        writeln!(
            f,
            "  safety trips (episodes): {}{}",
            if trips.is_empty() {
                "none".to_owned()
            } else {
                trips.join(", ")
            },
            self.holding.map_or(String::new(), |l| format!(
                "; {l} holds the device released now"
            ))
        )
    }
}
