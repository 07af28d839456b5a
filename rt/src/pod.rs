//! What may cross a process boundary: plain old data, checked by the compiler (H5).
#![allow(unsafe_code)] // `ShmPod` is unsafe to implement; the primitives' impls below say why each holds

/// Marks a type that may be copied through shared memory between processes.
///
/// # Safety
/// Implement only for a type that
/// - is `#[repr(C)]` (or a primitive, or an array of such), with no implicit padding: padding is an
///   explicit field, so every byte is initialised;
/// - holds no pointer, reference, file descriptor or other process-local handle;
/// - is valid for **every** bit pattern (no `bool`, `char`, enum or `NonZero*` fields): a peer process,
///   a stale segment or a hostile writer can leave any bytes in a slot, and reading them must never be
///   undefined behaviour;
/// - has a [`TYPE_NAME`](ShmPod::TYPE_NAME) that changes whenever its layout changes.
///
/// This is the spirit of iceoryx2's `ZeroCopySend`, narrowed to fixed-size values.
pub unsafe trait ShmPod: Copy + Send + 'static {
    /// The layout's stable name, hashed into every segment header. Bump a suffix (`Foo.v2`) whenever a
    /// field changes, so an old peer gets a type mismatch instead of misread bytes.
    const TYPE_NAME: &'static str;
}

/// Identity of a payload type as recorded in a segment header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TypeIdentity {
    /// The layout's name (`ShmPod::TYPE_NAME`).
    pub name: &'static str,
    /// FNV-1a 64 hash of `name`.
    pub name_hash: u64,
    /// `size_of::<T>()`.
    pub size: u64,
    /// `align_of::<T>()`.
    pub align: u64,
}

impl TypeIdentity {
    /// The identity of `T`.
    pub const fn of<T: ShmPod>() -> Self {
        Self {
            name: T::TYPE_NAME,
            name_hash: fnv1a64(T::TYPE_NAME.as_bytes()),
            size: core::mem::size_of::<T>() as u64,
            align: core::mem::align_of::<T>() as u64,
        }
    }
}

/// FNV-1a, 64 bit: stable across compilers and platforms, unlike `std::any::type_name` or `TypeId`.
pub const fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u64;
        hash = hash.wrapping_mul(0x0100_0000_01b3);
        i += 1;
    }
    hash
}

macro_rules! primitive_pod {
    ($($t:ty),*) => {$(
        // SAFETY: a primitive integer or float: no padding, no pointers, every bit pattern valid.
        unsafe impl ShmPod for $t { const TYPE_NAME: &'static str = stringify!($t); }
    )*};
}
primitive_pod!(u8, u16, u32, u64, i8, i16, i32, i64, f32, f64);

/// A 64-byte test and benchmark message: a sequence number, its check word and a payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(C)]
pub struct SeqMsg {
    /// Sequence number, counting from 0.
    pub seq: u64,
    /// `seq` mixed with a constant, so a torn or misplaced slot is caught.
    pub check: u64,
    /// Filler up to 64 bytes (the cache line the benchmarks move).
    pub payload: [u64; 6],
}
const _: () = assert!(core::mem::size_of::<SeqMsg>() == 64);

impl SeqMsg {
    /// The message with sequence number `seq`.
    #[inline]
    pub fn new(seq: u64) -> Self {
        Self {
            seq,
            check: Self::check_of(seq),
            payload: [seq; 6],
        }
    }
    /// The check word of `seq`.
    #[inline]
    pub fn check_of(seq: u64) -> u64 {
        seq.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0x5a5a_5a5a
    }
    /// Whether the check word and payload match the sequence number.
    #[inline]
    pub fn is_intact(&self) -> bool {
        self.check == Self::check_of(self.seq) && self.payload.iter().all(|&p| p == self.seq)
    }
}

// SAFETY: repr(C), eight u64 with no padding, no pointers; every bit pattern is a valid SeqMsg.
unsafe impl ShmPod for SeqMsg {
    const TYPE_NAME: &'static str = "coop.SeqMsg.v1";
}
