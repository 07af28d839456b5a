//! The compact encoding of a message's words (`docs/wire.md`, "Encoding"): a bitmap of the
//! nonzero words, then each nonzero word (an integer as a LEB128 varint, a float as its 8
//! little-endian bytes); a track's positions as zigzag varints, each coordinate after the first
//! tick as the difference from the tick before. Decoding refuses a varint that is longer than it
//! has to be, overflows 64 bits, or runs past the end; what the words then mean is checked by the
//! message's own validation.

use coop_rt::msg::Layout;

use super::DecodeError;

/// Appends `v` as LEB128 (7 bits a byte, low first, the high bit set on all but the last).
pub fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Bytes `v` takes as LEB128.
#[cfg(test)]
pub fn varint_len(v: u64) -> usize {
    (64 - v.max(1).leading_zeros() as usize).div_ceil(7)
}

/// A message's bytes being read, with the offset for errors.
pub struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    /// Reads `bytes`, the first of which is at offset `at` of the message.
    pub fn new(bytes: &'a [u8], at: usize) -> Self {
        Self { bytes, at }
    }

    /// The next `n` bytes.
    fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        if self.bytes.len() < n {
            return Err(DecodeError::Truncated { at: self.at });
        }
        let (head, rest) = self.bytes.split_at(n);
        self.bytes = rest;
        self.at += n;
        Ok(head)
    }

    /// One minimal LEB128 varint of at most 64 bits.
    pub fn varint(&mut self) -> Result<u64, DecodeError> {
        let start = self.at;
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.take(1)?[0];
            let bits = u64::from(b & 0x7f);
            // The tenth byte holds bit 63 only; a last byte of 0 after others is not minimal.
            if (shift == 63 && bits > 1) || (b == 0 && shift > 0) {
                return Err(DecodeError::Varint { at: start });
            }
            v |= bits << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(DecodeError::Varint { at: start })
    }

    /// 8 little-endian bytes.
    pub fn word(&mut self) -> Result<u64, DecodeError> {
        let mut w = [0u8; 8];
        w.copy_from_slice(self.take(8)?);
        Ok(u64::from_le_bytes(w))
    }

    /// Nothing may follow the message.
    pub fn end(&self) -> Result<(), DecodeError> {
        match self.bytes.len() {
            0 => Ok(()),
            extra => Err(DecodeError::Trailing { extra }),
        }
    }
}

/// Zigzag: 0, −1, 1, −2, … as 0, 1, 2, 3, … (a small difference of either sign is a short varint).
pub fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

/// The inverse of [`zigzag`].
pub fn unzigzag(u: u64) -> i64 {
    ((u >> 1) as i64) ^ -((u & 1) as i64)
}

/// Per word of `layout` from word `from` on: whether it is a float (one walk over the fields).
fn floats(layout: Layout, from: usize) -> impl Iterator<Item = bool> {
    layout
        .iter()
        .flat_map(|&(_, kind, n)| std::iter::repeat_n(kind == "f64", n))
        .skip(from)
}

/// The word at which field `name` of `layout` starts (its end if there is none).
pub const fn field_word(layout: Layout, name: &str) -> usize {
    const fn same(a: &str, b: &str) -> bool {
        let (a, b) = (a.as_bytes(), b.as_bytes());
        if a.len() != b.len() {
            return false;
        }
        let mut i = 0;
        while i < a.len() {
            if a[i] != b[i] {
                return false;
            }
            i += 1;
        }
        true
    }
    let (mut i, mut at) = (0, 0);
    while i < layout.len() {
        let (field, _, n) = layout[i];
        if same(field, name) {
            return at;
        }
        at += n;
        i += 1;
    }
    at
}

/// The most bytes [`put_words`] writes for `layout`'s words `from..to`.
pub const fn max_words_len(layout: Layout, from: usize, to: usize) -> usize {
    let mut len = (to - from).div_ceil(8);
    let (mut i, mut at) = (0, 0);
    while i < layout.len() {
        let (_, kind, n) = layout[i];
        let mut w = at;
        while w < at + n {
            if w >= from && w < to {
                // "f64" and "u64" differ in their first byte.
                len += if kind.as_bytes()[0] == b'f' { 8 } else { 10 };
            }
            w += 1;
        }
        at += n;
        i += 1;
    }
    len
}

/// Appends `words` (words `from..` of `layout`): the bitmap of the nonzero ones (bit `i % 8` of
/// byte `i / 8` for word `i`), then each nonzero one.
pub fn put_words(out: &mut Vec<u8>, layout: Layout, from: usize, words: &[u64]) {
    let map = out.len();
    out.resize(map + words.len().div_ceil(8), 0);
    for ((i, &w), float) in words.iter().enumerate().zip(floats(layout, from)) {
        if w == 0 {
            continue;
        }
        out[map + i / 8] |= 1 << (i % 8);
        if float {
            out.extend_from_slice(&w.to_le_bytes());
        } else {
            put_varint(out, w);
        }
    }
}

/// Reads what [`put_words`] wrote into `words` (words `from..` of `layout`). A bitmap bit past
/// the words is refused as invalid.
pub fn take_words(
    r: &mut Reader<'_>,
    layout: Layout,
    from: usize,
    words: &mut [u64],
) -> Result<(), DecodeError> {
    let map = r.take(words.len().div_ceil(8))?;
    let spare = map.len() * 8 - words.len();
    if spare > 0 && map[map.len() - 1] >> (8 - spare) != 0 {
        return Err(DecodeError::Invalid);
    }
    for ((i, w), float) in words.iter_mut().enumerate().zip(floats(layout, from)) {
        if map[i / 8] & (1 << (i % 8)) == 0 {
            *w = 0;
            continue;
        }
        *w = if float { r.word()? } else { r.varint()? };
        // A word marked nonzero is not zero (one encoding per message).
        if *w == 0 {
            return Err(DecodeError::Invalid);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varints_round_trip_and_refuse_overlong_or_truncated_ones() {
        for v in [0, 1, 127, 128, 300, u32::MAX as u64, u64::MAX - 1, u64::MAX] {
            let mut out = Vec::new();
            put_varint(&mut out, v);
            assert_eq!(out.len(), varint_len(v), "{v}");
            let mut r = Reader::new(&out, 1);
            assert_eq!(r.varint(), Ok(v));
            assert_eq!(r.end(), Ok(()));
            let mut short = Reader::new(&out[..out.len() - 1], 1);
            assert!(short.varint().is_err(), "{v} truncated");
        }
        assert_eq!(varint_len(u64::MAX), 10);
        // Not minimal: 0 as two bytes; past 64 bits: an eleventh byte, or a tenth above 1.
        assert_eq!(
            Reader::new(&[0x80, 0x00], 1).varint(),
            Err(DecodeError::Varint { at: 1 })
        );
        let mut eleven = vec![0xff; 10];
        eleven.push(0x01);
        assert!(Reader::new(&eleven, 1).varint().is_err());
        let mut tenth = vec![0xff; 9];
        tenth.push(0x02);
        assert_eq!(
            Reader::new(&tenth, 1).varint(),
            Err(DecodeError::Varint { at: 1 })
        );
        for v in [0i64, -1, 1, -2, i64::MIN, i64::MAX, -4500] {
            assert_eq!(unzigzag(zigzag(v)), v);
        }
        assert_eq!(zigzag(-1), 1);
        assert_eq!(zigzag(1), 2);
    }
}
