//! The one place the ring's atomics and slot cells come from (H14).
//!
//! Normal builds re-export `core` atomics and a zero-cost cell; `RUSTFLAGS="--cfg loom"` swaps in loom's
//! model-checked ones so `loom::model` can explore every interleaving of push, pop and abandon.
//! `clippy.toml` forbids naming `core::sync::atomic` types anywhere else.

pub use core::sync::atomic::Ordering;

#[cfg(not(loom))]
#[allow(clippy::disallowed_types)]
type Inner64 = core::sync::atomic::AtomicU64;
#[cfg(loom)]
type Inner64 = loom::sync::atomic::AtomicU64;

/// A 64-bit atomic: `core`'s, or loom's under `--cfg loom`. `#[repr(transparent)]`, so in shared memory
/// it is exactly a `u64`, and any bit pattern is a valid value.
#[derive(Debug, Default)]
#[repr(transparent)]
pub struct AtomicU64(Inner64);

impl AtomicU64 {
    /// A new atomic holding `v`.
    #[cfg(not(loom))]
    pub const fn new(v: u64) -> Self {
        Self(Inner64::new(v))
    }
    /// A new atomic holding `v`.
    #[cfg(loom)]
    pub fn new(v: u64) -> Self {
        Self(Inner64::new(v))
    }
    /// Loads the value.
    #[inline(always)]
    pub fn load(&self, order: Ordering) -> u64 {
        self.0.load(order)
    }
    /// Stores `v`.
    #[inline(always)]
    pub fn store(&self, v: u64, order: Ordering) {
        self.0.store(v, order)
    }
    /// Stores `new` if the value is `current`; returns the previous value either way.
    ///
    /// # Errors
    /// The value found, when it was not `current`.
    #[inline(always)]
    pub fn compare_exchange(
        &self,
        current: u64,
        new: u64,
        success: Ordering,
        failure: Ordering,
    ) -> Result<u64, u64> {
        self.0.compare_exchange(current, new, success, failure)
    }
    /// Adds `v` (wrapping), returning the previous value.
    #[inline(always)]
    pub fn fetch_add(&self, v: u64, order: Ordering) -> u64 {
        self.0.fetch_add(v, order)
    }
}

/// A cell whose contents are handed across threads or processes by the ring protocol.
///
/// Same API as `loom::cell::UnsafeCell` (`with` / `with_mut`), so loom can check that every slot write
/// happens-before the matching read. `#[repr(transparent)]`: in shared memory it is exactly a `T`.
#[cfg(not(loom))]
#[derive(Debug)]
#[repr(transparent)]
pub struct SlotCell<T>(core::cell::UnsafeCell<T>);

#[cfg(not(loom))]
impl<T> SlotCell<T> {
    /// Wraps a value.
    pub const fn new(v: T) -> Self {
        Self(core::cell::UnsafeCell::new(v))
    }
    /// Calls `f` with a const pointer to the contents.
    #[inline(always)]
    pub fn with<R>(&self, f: impl FnOnce(*const T) -> R) -> R {
        f(self.0.get())
    }
    /// Calls `f` with a mut pointer to the contents.
    #[inline(always)]
    pub fn with_mut<R>(&self, f: impl FnOnce(*mut T) -> R) -> R {
        f(self.0.get())
    }
}

#[cfg(loom)]
pub use loom::cell::UnsafeCell as SlotCell;

/// Pads and aligns a value to 128 bytes so the producer's and consumer's indices never share a cache
/// line (two lines on x86_64, whose adjacent-line prefetcher pairs them; crossbeam does the same).
#[derive(Debug, Default)]
#[repr(C, align(128))]
pub struct CachePadded<T>(pub T);

impl<T> core::ops::Deref for CachePadded<T> {
    type Target = T;
    #[inline(always)]
    fn deref(&self) -> &T {
        &self.0
    }
}
