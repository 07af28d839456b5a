//! A station's device as the control block holds it: what it is, what the servo's safety layer saw
//! of it (samples, faults, commands, the limits that acted), what its bridge thread counted (a
//! ROS 2 driver's poses refused from a second publisher, say), the rates measured, and why it did
//! not open. Only the servo process opens the device, so only it can tell; `station status` reads
//! this group without touching the servo. Every field is a relaxed atomic (texts publish their
//! length last), the servo the one writer (`coop_rt::device::figures` publishes them).

use std::fmt;

use crate::sync::{AtomicU64, Ordering};

/// Words of the backend's name (16 bytes).
pub const BACKEND_WORDS: usize = 2;
/// Words of the model's name (64 bytes).
pub const MODEL_WORDS: usize = 8;
/// Words of the serial number (32 bytes).
pub const SERIAL_WORDS: usize = 4;
/// Words of the last fault's text (128 bytes).
pub const FAULT_WORDS: usize = 16;
/// Slots of [`DeviceShared::trips`]: one per code of the device layer's limits (`Limit::code`,
/// 1..=7; slot 0 unused), with room for limits added later without a layout change.
pub const TRIP_SLOTS: usize = 16;
/// Words of the open error's text (512 bytes: a ROS 2 driver's names its topic, domain and every
/// router locator).
pub const OPEN_ERROR_WORDS: usize = 64;

/// A text of at most `N` words, written by one process while others read: the bytes, then the
/// length last (Release). A reader after the write sees the whole text; one during a rewrite may
/// see a mix of the old and the new (read lossily) and reads it whole next time: these texts
/// name a device and its last fault for people, not for a decision.
#[derive(Debug)]
#[repr(C)]
pub struct ShmText<const N: usize> {
    len: AtomicU64,
    words: [AtomicU64; N],
}

impl<const N: usize> Default for ShmText<N> {
    fn default() -> Self {
        Self {
            len: AtomicU64::new(0),
            words: std::array::from_fn(|_| AtomicU64::new(0)),
        }
    }
}

/// Packs what is written into the words of an [`ShmText`], little-endian, cut on a character
/// boundary where it runs out of room: formatting into it allocates nothing.
struct WordWriter<'a> {
    words: &'a [AtomicU64],
    len: usize,
    word: u64,
    /// A fragment was cut: nothing after it is written (no tail without its middle).
    full: bool,
}

impl fmt::Write for WordWriter<'_> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        if self.full {
            return Ok(());
        }
        let room = self.words.len() * 8 - self.len;
        self.full = s.len() > room;
        let mut n = s.len().min(room);
        while !s.is_char_boundary(n) {
            n -= 1;
        }
        for &b in &s.as_bytes()[..n] {
            self.word |= u64::from(b) << (8 * (self.len % 8));
            self.len += 1;
            if self.len.is_multiple_of(8) {
                self.words[self.len / 8 - 1].store(self.word, Ordering::Relaxed);
                self.word = 0;
            }
        }
        Ok(())
    }
}

impl<const N: usize> ShmText<N> {
    /// Writes `args` formatted (cut to `8 N` bytes on a character boundary). No allocation: the
    /// servo writes a fault's words with it.
    pub fn store_fmt(&self, args: fmt::Arguments<'_>) {
        self.len.store(0, Ordering::Release);
        let mut w = WordWriter {
            words: &self.words,
            len: 0,
            word: 0,
            full: false,
        };
        // WordWriter never fails; a Display that does leaves what it wrote before failing.
        let _ = fmt::write(&mut w, args);
        if !w.len.is_multiple_of(8) {
            self.words[w.len / 8].store(w.word, Ordering::Relaxed);
        }
        // SYNC: Release publishes the words; pairs with the Acquire in `load`.
        self.len.store(w.len as u64, Ordering::Release);
    }

    /// Writes `text` (as [`ShmText::store_fmt`]).
    pub fn store(&self, text: &str) {
        self.store_fmt(format_args!("{text}"));
    }

    /// The text (lossy UTF-8: a read during a rewrite may mix two texts; empty: none).
    pub fn load(&self) -> String {
        // SYNC: Acquire pairs with the Release in `store_fmt`.
        let n = (self.len.load(Ordering::Acquire) as usize).min(N * 8);
        let mut bytes: Vec<u8> = self
            .words
            .iter()
            .flat_map(|w| w.load(Ordering::Relaxed).to_le_bytes())
            .collect();
        bytes.truncate(n);
        String::from_utf8_lossy(&bytes).into_owned()
    }
}

/// A device fault's kind (of `coop_rt::device::DeviceFault`), as the control block keys it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// No fresh sample within the device's stale limit: its driver or service went silent, or it
    /// was unplugged (`DeviceFault::Disconnected`).
    Disconnected = 1,
    /// A vendor call returned an error (`DeviceFault::CallFailed`).
    CallFailed = 2,
    /// A value was not finite or out of range (`DeviceFault::BadValue`).
    BadValue = 3,
}

impl FaultKind {
    /// Every kind, in code order.
    pub const ALL: [FaultKind; 3] = [
        FaultKind::Disconnected,
        FaultKind::CallFailed,
        FaultKind::BadValue,
    ];

    /// Its code in the control block (0 is "none").
    pub fn code(self) -> u64 {
        self as u64
    }

    /// The kind of `code`, if any.
    pub fn from_code(code: u64) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.code() == code)
    }

    /// Its name in `station status`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Disconnected => "disconnected",
            Self::CallFailed => "call_failed",
            Self::BadValue => "bad_value",
        }
    }
}

/// Declares each count once, with its doc: the shared block's atomic, the plain count, and the
/// load and store between them (in declaration order: the shared block's layout).
macro_rules! device_counts {
    ($($(#[$doc:meta])* $name:ident,)*) => {
        /// A device's counts as the servo publishes them: relaxed stores, the servo the one writer.
        #[derive(Debug, Default)]
        #[repr(C)]
        pub struct DeviceCountsShared {
            $($(#[$doc])* pub $name: AtomicU64,)*
        }

        /// A device's counts since the servo opened it (a restarted servo counts afresh).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
        #[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
        pub struct DeviceCounts {
            $($(#[$doc])* pub $name: u64,)*
        }

        impl DeviceCountsShared {
            /// Every count now.
            pub fn load(&self) -> DeviceCounts {
                DeviceCounts {
                    $($name: self.$name.load(Ordering::Relaxed),)*
                }
            }

            /// Counts numbered in declaration order by `f` (a test's distinct values).
            #[cfg(test)]
            fn numbered(mut f: impl FnMut() -> u64) -> DeviceCounts {
                DeviceCounts {
                    $($name: f(),)*
                }
            }

            /// Publishes every count (the servo, the one writer).
            // REAL-TIME: relaxed stores only: no allocation, no lock, no syscall.
            pub fn store(&self, c: &DeviceCounts) {
                $(self.$name.store(c.$name, Ordering::Relaxed);)*
            }
        }
    };
}

device_counts! {
    /// Servo ticks at which the device gave a sample.
    samples,
    /// ... whose time was newer than the one before: what the device itself delivered (a bridged
    /// device's driver may be slower than the servo).
    new_samples,
    /// Servo ticks at which the device reported a fault (sampling or commanding), of any kind.
    faults,
    /// ... of them [`FaultKind::Disconnected`]: its newest sample older than its stale limit.
    stale,
    /// ... [`FaultKind::CallFailed`].
    call_failed,
    /// ... [`FaultKind::BadValue`].
    bad_value,
    /// Force commands the device took (a release is not one).
    commands,
    /// Messages its bridge took from the driver or service (ROS 2 poses, Haply state frames).
    received,
    /// ... refused as not a sample (not a finite `PoseStamped`, a frame of the wrong shape).
    refused,
    /// ... refused for coming from another publisher than the driver's (ROS 2: a second driver,
    /// a bag played on the same topic).
    foreign,
    /// Force commands its bridge put to the driver or service that were not zero.
    sent_forces,
    /// Connections its bridge lost (Haply).
    losses,
    /// Reconnections after a loss (Haply).
    reconnects,
}

impl DeviceCounts {
    /// The count of faults of `kind`.
    pub fn faults_of(&self, kind: FaultKind) -> u64 {
        match kind {
            FaultKind::Disconnected => self.stale,
            FaultKind::CallFailed => self.call_failed,
            FaultKind::BadValue => self.bad_value,
        }
    }

    /// Counts a fault of `kind`.
    // REAL-TIME: additions only.
    pub fn count_fault(&mut self, kind: FaultKind) {
        self.faults += 1;
        match kind {
            FaultKind::Disconnected => self.stale += 1,
            FaultKind::CallFailed => self.call_failed += 1,
            FaultKind::BadValue => self.bad_value += 1,
        }
    }
}

/// The device group of the control block (see the module's docs). All zero until the servo opened
/// its device.
#[derive(Debug)]
#[repr(C)]
pub struct DeviceShared {
    /// 1 once the servo opened the device and said what it is (the texts below, written first).
    pub open: AtomicU64,
    /// 1 for a device behind a bridge thread (ROS 2, Haply): the bridge's counts apply.
    pub bridged: AtomicU64,
    /// The backend (`sim`, `replay`, `haply`, `dhd`, `ros2`).
    pub backend: ShmText<BACKEND_WORDS>,
    /// The model, as the device says it.
    pub model: ShmText<MODEL_WORDS>,
    /// Its serial number (empty: it tells none).
    pub serial: ShmText<SERIAL_WORDS>,
    /// The rate its own loop or firmware runs at, as it says, Hz (f64 bits).
    pub native_rate_hz: AtomicU64,
    /// When the servo last published the figures below, CLOCK_MONOTONIC ns.
    pub published_ns: AtomicU64,
    /// Its counts.
    pub counts: DeviceCountsShared,
    /// New samples per second over the current window (a tenth of a second to a second), Hz (f64
    /// bits).
    pub sample_rate_hz: AtomicU64,
    /// Force commands per second over the same window, Hz (f64 bits).
    pub command_rate_hz: AtomicU64,
    /// The last fault's [`FaultKind`] code (0: none yet).
    pub last_fault_kind: AtomicU64,
    /// ... when it was reported last, CLOCK_MONOTONIC ns.
    pub last_fault_ns: AtomicU64,
    /// ... in words.
    pub last_fault: ShmText<FAULT_WORDS>,
    /// Episodes of each safety limit acting, by its code (a limit acting on consecutive ticks
    /// counts once).
    pub trips: [AtomicU64; TRIP_SLOTS],
    /// The code of the limit holding the device released now (0: none).
    pub holding: AtomicU64,
    /// Why the device did not open (empty: it did, or the servo has not tried yet): the servo
    /// writes it before it exits, the supervisor ends the station with it.
    pub open_error: ShmText<OPEN_ERROR_WORDS>,
}

impl DeviceShared {
    /// Whether the servo has opened the device and said what it is.
    pub fn is_open(&self) -> bool {
        // SYNC: Acquire pairs with the Release in `coop_rt::device::figures::DevicePublisher::new`.
        self.open.load(Ordering::Acquire) == 1
    }

    /// The last fault: its kind, its words and when (none yet: `None`).
    pub fn last_fault(&self) -> Option<(FaultKind, String, u64)> {
        let kind = FaultKind::from_code(self.last_fault_kind.load(Ordering::Relaxed))?;
        Some((
            kind,
            self.last_fault.load(),
            self.last_fault_ns.load(Ordering::Relaxed),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every count goes through the shared block and back by its own name.
    #[test]
    fn every_count_round_trips_through_the_shared_block() {
        let shared = DeviceCountsShared::default();
        let mut k = 0;
        let c = DeviceCountsShared::numbered(|| {
            k += 1;
            k
        });
        shared.store(&c);
        assert_eq!(shared.load(), c);
        assert_eq!(
            std::mem::size_of::<DeviceCountsShared>(),
            std::mem::size_of::<DeviceCounts>()
        );
    }

    #[test]
    fn texts_round_trip_and_are_cut_on_a_character_boundary() {
        let t = ShmText::<2>::default();
        assert_eq!(t.load(), "");
        t.store("ros2");
        assert_eq!(t.load(), "ros2");
        let f = ShmText::<FAULT_WORDS>::default();
        f.store_fmt(format_args!(
            "device call {} failed with code {}",
            "dhdGetPosition", -1
        ));
        assert_eq!(f.load(), "device call dhdGetPosition failed with code -1");
        // 15 ASCII bytes, then a 2-byte character that does not fit in 16.
        t.store("abcdefghijklmnoé");
        assert_eq!(t.load(), "abcdefghijklmno");
        t.store("exactly sixteen!");
        assert_eq!(t.load(), "exactly sixteen!");
        t.store("short");
        assert_eq!(t.load(), "short");
        // A fragment cut short ends the text: a later one's tail is not appended after the cut.
        t.store_fmt(format_args!("{}{}", "abcdefghijklmnoé", "x"));
        assert_eq!(t.load(), "abcdefghijklmno");
    }

    #[test]
    fn fault_kinds_have_codes() {
        for k in FaultKind::ALL {
            assert_eq!(FaultKind::from_code(k.code()), Some(k));
        }
        assert_eq!(FaultKind::from_code(0), None);
    }
}
