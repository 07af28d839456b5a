//! The one place the ring's atomics and slot cells come from (H14).
//!
//! Normal builds re-export `core` atomics and a zero-cost cell; `RUSTFLAGS="--cfg loom"` swaps in loom's
//! model-checked ones so `loom::model` can explore every interleaving of push, pop and abandon.
//! `clippy.toml` forbids naming `core::sync::atomic` types anywhere else.

#[cfg(not(loom))]
#[allow(clippy::disallowed_types)]
pub use core::sync::atomic::{fence, AtomicU32, AtomicU64, Ordering};

#[cfg(loom)]
pub use loom::sync::atomic::{fence, AtomicU32, AtomicU64, Ordering};

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
