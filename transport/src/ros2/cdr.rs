//! The few ROS 2 messages a station speaks, in CDR as ROS 2 writes it: a 4-byte encapsulation
//! header (`00 01 00 00`: plain CDR, little-endian), then the fields in order, each aligned to its
//! own size counted from the end of the header, strings as a `u32` length that counts the closing
//! NUL, then the bytes and the NUL, sequences as a `u32` count then the elements.
//!
//! Written by hand rather than generated: four message types (and the transform inside one), all of fixed shape but for their
//! strings and one sequence, and every byte pinned by golden tests that `rosbags` (the Python
//! reader ROS users record with) produced.

use thiserror::Error;

/// The encapsulation header: CDR, little-endian, no options.
pub const ENCAPSULATION: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Time {
    /// Seconds since the Unix epoch.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl Time {
    /// Wall time `ns` since the Unix epoch (saturated at `i32::MAX` seconds, year 2038).
    pub fn from_unix_ns(ns: u64) -> Self {
        let sec = i32::try_from(ns / 1_000_000_000).unwrap_or(i32::MAX);
        // Below 10⁹: fits.
        let nanosec = (ns % 1_000_000_000) as u32;
        Self { sec, nanosec }
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// When.
    pub stamp: Time,
    /// The frame the message's values are in.
    pub frame_id: String,
}

/// `geometry_msgs/msg/PoseStamped`: a position and an orientation (x, y, z, w) in a frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// Position, m.
    pub position: [f64; 3],
    /// Orientation as ROS orders a quaternion: x, y, z, w.
    pub orientation: [f64; 4],
}

/// `geometry_msgs/msg/WrenchStamped`: a force and a torque in a frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WrenchStamped {
    /// Stamp and frame.
    pub header: Header,
    /// Force, N.
    pub force: [f64; 3],
    /// Torque, N·m.
    pub torque: [f64; 3],
}

/// `geometry_msgs/msg/TransformStamped`: where `child_frame_id` is in `header.frame_id`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The frame this transform places.
    pub child_frame_id: String,
    /// Translation, m.
    pub translation: [f64; 3],
    /// Rotation: x, y, z, w.
    pub rotation: [f64; 4],
}

/// `rcl_interfaces/msg/Log`: one line of `/rosout`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Log {
    /// When.
    pub stamp: Time,
    /// [`Log::INFO`], [`Log::WARN`], [`Log::ERROR`].
    pub level: u8,
    /// The logger's name.
    pub name: String,
    /// The text.
    pub msg: String,
    /// Source file (empty: not ours to say).
    pub file: String,
    /// Function (empty).
    pub function: String,
    /// Line (0).
    pub line: u32,
}

impl Log {
    /// `rcl_interfaces/msg/Log` levels.
    pub const INFO: u8 = 20;
    /// A warning.
    pub const WARN: u8 = 30;
    /// An error.
    pub const ERROR: u8 = 40;
}

/// Why bytes are not the message asked for.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum CdrError {
    /// Not the little-endian CDR encapsulation.
    #[error("encapsulation {0:02x?} is not little-endian CDR (00 01 00 00)")]
    Encapsulation([u8; 4]),
    /// Fewer bytes than the fields need.
    #[error("truncated: {needed} bytes needed at offset {at}, {len} in all")]
    Truncated {
        /// Where the field starts.
        at: usize,
        /// How many it needs.
        needed: usize,
        /// The message's length.
        len: usize,
    },
    /// A string without its closing NUL, with one inside, or not UTF-8.
    #[error("string at offset {0} is not UTF-8 ending in its only NUL")]
    String(usize),
    /// More bytes than the message (beyond the 3 of padding CDR allows at the end).
    #[error("{0} bytes left over after the message")]
    Trailing(usize),
    /// A value a message of ours cannot carry (a non-finite number).
    #[error("field {0} is not finite")]
    NotFinite(&'static str),
}

/// Appends CDR fields, aligned from the end of the encapsulation header.
#[derive(Debug, Clone)]
pub struct Writer {
    buf: Vec<u8>,
}

impl Default for Writer {
    fn default() -> Self {
        Self::new()
    }
}

impl Writer {
    /// A message: the encapsulation header.
    pub fn new() -> Self {
        let mut buf = Vec::with_capacity(256);
        buf.extend_from_slice(&ENCAPSULATION);
        Self { buf }
    }

    fn align(&mut self, n: usize) {
        while !(self.buf.len() - ENCAPSULATION.len()).is_multiple_of(n) {
            self.buf.push(0);
        }
    }

    /// A `uint8`.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `uint32` (and a sequence's count).
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `float64`.
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// `float64`s in a row (a vector or a quaternion).
    pub fn f64s(&mut self, v: &[f64]) {
        for &x in v {
            self.f64(x);
        }
    }

    /// A `string`: its length with the NUL, its bytes, the NUL. A NUL inside is cut there (ROS
    /// strings cannot carry one).
    pub fn string(&mut self, s: &str) {
        let s = s.split('\0').next().unwrap_or_default();
        // Our strings are names and log lines, far below 4 GiB.
        self.u32(u32::try_from(s.len() + 1).unwrap_or(u32::MAX));
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// A `Time`.
    pub fn time(&mut self, t: Time) {
        self.i32(t.sec);
        self.u32(t.nanosec);
    }

    /// A `Header`.
    pub fn header(&mut self, h: &Header) {
        self.time(h.stamp);
        self.string(&h.frame_id);
    }

    /// The message's bytes.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// Reads CDR fields, aligned from the end of the encapsulation header.
#[derive(Debug)]
pub struct Reader<'a> {
    buf: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    /// Checks the encapsulation header.
    ///
    /// # Errors
    /// Too short, or not little-endian CDR.
    pub fn new(buf: &'a [u8]) -> Result<Self, CdrError> {
        let head: [u8; 4] =
            buf.get(..4)
                .and_then(|h| h.try_into().ok())
                .ok_or(CdrError::Truncated {
                    at: 0,
                    needed: 4,
                    len: buf.len(),
                })?;
        // The options bytes are the writer's (padding flags); only the kind is ours to check.
        if head[..2] != ENCAPSULATION[..2] {
            return Err(CdrError::Encapsulation(head));
        }
        Ok(Self { buf, at: 4 })
    }

    fn take(&mut self, align: usize, n: usize) -> Result<&'a [u8], CdrError> {
        let pad = (align - (self.at - ENCAPSULATION.len()) % align) % align;
        let start = self.at + pad;
        let bytes = self.buf.get(start..start + n).ok_or(CdrError::Truncated {
            at: start,
            needed: n,
            len: self.buf.len(),
        })?;
        self.at = start + n;
        Ok(bytes)
    }

    /// A `uint8`.
    ///
    /// # Errors
    /// Truncated.
    pub fn u8(&mut self) -> Result<u8, CdrError> {
        Ok(self.take(1, 1)?[0])
    }

    /// An `int32`.
    ///
    /// # Errors
    /// Truncated.
    pub fn i32(&mut self) -> Result<i32, CdrError> {
        let b = self.take(4, 4)?;
        Ok(i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// A `uint32`.
    ///
    /// # Errors
    /// Truncated.
    pub fn u32(&mut self) -> Result<u32, CdrError> {
        let b = self.take(4, 4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// A finite `float64`; `field` names it in the error.
    ///
    /// # Errors
    /// Truncated, or not finite.
    pub fn f64(&mut self, field: &'static str) -> Result<f64, CdrError> {
        let b = self.take(8, 8)?;
        let mut w = [0u8; 8];
        w.copy_from_slice(b);
        let v = f64::from_le_bytes(w);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(CdrError::NotFinite(field))
        }
    }

    /// `N` finite `float64`s.
    ///
    /// # Errors
    /// As [`Reader::f64`].
    pub fn f64s<const N: usize>(&mut self, field: &'static str) -> Result<[f64; N], CdrError> {
        let mut out = [0.0; N];
        for x in &mut out {
            *x = self.f64(field)?;
        }
        Ok(out)
    }

    /// A `string`.
    ///
    /// # Errors
    /// Truncated, no closing NUL, or not UTF-8.
    pub fn string(&mut self) -> Result<String, CdrError> {
        let at = self.at;
        let n = self.u32()? as usize;
        if n == 0 {
            return Err(CdrError::String(at));
        }
        let b = self.take(1, n)?;
        let (text, nul) = b.split_at(n - 1);
        // One NUL, at the end: a ROS string cannot hold one inside.
        if nul != [0] || text.contains(&0) {
            return Err(CdrError::String(at));
        }
        std::str::from_utf8(text)
            .map(str::to_owned)
            .map_err(|_| CdrError::String(at))
    }

    /// A `Time`.
    ///
    /// # Errors
    /// Truncated.
    pub fn time(&mut self) -> Result<Time, CdrError> {
        Ok(Time {
            sec: self.i32()?,
            nanosec: self.u32()?,
        })
    }

    /// A `Header`.
    ///
    /// # Errors
    /// As its fields.
    pub fn header(&mut self) -> Result<Header, CdrError> {
        Ok(Header {
            stamp: self.time()?,
            frame_id: self.string()?,
        })
    }

    /// The end: nothing but up to 3 bytes of padding may follow (writers pad to 4).
    ///
    /// # Errors
    /// More bytes than that.
    pub fn finish(self) -> Result<(), CdrError> {
        let left = self.buf.len() - self.at;
        if left > 3 {
            return Err(CdrError::Trailing(left));
        }
        Ok(())
    }
}

impl PoseStamped {
    /// Its CDR bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.header(&self.header);
        w.f64s(&self.position);
        w.f64s(&self.orientation);
        w.finish()
    }

    /// From CDR bytes.
    ///
    /// # Errors
    /// Not a `PoseStamped` of finite values.
    pub fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = Reader::new(bytes)?;
        let m = Self {
            header: r.header()?,
            position: r.f64s("pose.position")?,
            orientation: r.f64s("pose.orientation")?,
        };
        r.finish()?;
        Ok(m)
    }
}

impl WrenchStamped {
    /// Its CDR bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.header(&self.header);
        w.f64s(&self.force);
        w.f64s(&self.torque);
        w.finish()
    }

    /// From CDR bytes.
    ///
    /// # Errors
    /// Not a `WrenchStamped` of finite values.
    pub fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = Reader::new(bytes)?;
        let m = Self {
            header: r.header()?,
            force: r.f64s("wrench.force")?,
            torque: r.f64s("wrench.torque")?,
        };
        r.finish()?;
        Ok(m)
    }
}

/// A `tf2_msgs/msg/TFMessage` of `transforms`, as CDR.
pub fn encode_tf(transforms: &[TransformStamped]) -> Vec<u8> {
    let mut w = Writer::new();
    // At most one per object and one tool.
    w.u32(u32::try_from(transforms.len()).unwrap_or(u32::MAX));
    for t in transforms {
        w.header(&t.header);
        w.string(&t.child_frame_id);
        w.f64s(&t.translation);
        w.f64s(&t.rotation);
    }
    w.finish()
}

/// A `tf2_msgs/msg/TFMessage` from CDR.
///
/// # Errors
/// Not a `TFMessage` of finite values (or one claiming more transforms than its bytes hold).
pub fn decode_tf(bytes: &[u8]) -> Result<Vec<TransformStamped>, CdrError> {
    let mut r = Reader::new(bytes)?;
    let n = r.u32()? as usize;
    // A transform is at least 60 bytes: a count beyond that is a lie, not an allocation.
    if n > bytes.len() / 60 {
        return Err(CdrError::Truncated {
            at: 4,
            needed: n * 60,
            len: bytes.len(),
        });
    }
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        out.push(TransformStamped {
            header: r.header()?,
            child_frame_id: r.string()?,
            translation: r.f64s("transform.translation")?,
            rotation: r.f64s("transform.rotation")?,
        });
    }
    r.finish()?;
    Ok(out)
}

impl Log {
    /// Its CDR bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new();
        w.time(self.stamp);
        w.u8(self.level);
        w.string(&self.name);
        w.string(&self.msg);
        w.string(&self.file);
        w.string(&self.function);
        w.u32(self.line);
        w.finish()
    }

    /// From CDR bytes.
    ///
    /// # Errors
    /// Not a `Log`.
    pub fn decode(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = Reader::new(bytes)?;
        let m = Self {
            stamp: r.time()?,
            level: r.u8()?,
            name: r.string()?,
            msg: r.string()?,
            file: r.string()?,
            function: r.string()?,
            line: r.u32()?,
        };
        r.finish()?;
        Ok(m)
    }
}
