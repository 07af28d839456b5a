//! The wire format between stations: one encode and one decode per message (`docs/wire.md` is the
//! specification a foreign client can be written from).
//!
//! A site report is `version: u8 = 6`, then [`SiteReport::to_words`] (its fields in declaration
//! order, as `pod_message!` declares them) in the compact encoding: a bitmap of the nonzero
//! words, then each of them, an integer as a LEB128 varint and a float as its 8 bytes
//! (`compact`); at most [`MAX_ENCODED_LEN`] bytes. There is no second field list here: the
//! layout is the struct's, and [`PINNED`] ties it to [`VERSION`] and to the table in
//! `docs/wire.md` (a unit test fails when the struct changes without a version bump and the doc).
//! Decoding checks the version, the framing (no truncation, no trailing bytes, minimal varints,
//! one encoding per message) and then everything [`SiteReport::report`] checks (finite numbers
//! in every field, a unit quaternion, a known kind, and zero in the fields the kind does not
//! use). What only a receiver can check (the site, the time, plausibility, the sequence) is
//! [`crate::admit`]'s. Any failure is a typed error and changes nothing.
//!
//! The session's time 0 and clock readings are `version: u8 = 1` then one little-endian u64
//! (unchanged since version 1: [`U64_VERSION`]).
//!
//! A tool track (methods that exchange the tools: `timewarp`, `coupled`) is `version: u8 = 6`
//! then [`ToolTrack::to_words`]' header, its carried state only when it has one, both compact,
//! and its positions as zigzag varints of each tick's difference from the one before; on its
//! own key (`tool/<site>`). Version 2 added this message and changed nothing else; version 3
//! added the track's `need` (a receiver asking for positions lost in a gap); version 4 the
//! confirmed state a site whose confirmed history diverged asks for and adopts; version 5 the
//! worlds of several objects (a state names its object, on its object's key; a track's carried
//! state names its object, its world, and every friction memory it holds); version 6 the compact
//! encoding (a version 5 state was 321 bytes, a track 5 817; now about 190 and 90). States and
//! tracks are told apart by their key. [`TRACK_PINNED`] ties the track's layout to the doc as
//! [`PINNED`] does the state's.

mod carry;
pub(crate) mod compact;

pub use carry::StationWire;

use compact::{
    field_word, max_words_len, put_varint, put_words, take_words, unzigzag, zigzag, Reader,
};
use coop_model::method::track::WINDOW_TICKS;
use coop_rt::msg::{SiteReport, ToolTrack, TRACK_POSITION_WORDS};

/// Current wire version.
pub const VERSION: u8 = 6;
/// The version byte of a u64 message (session time 0, clock reading): unchanged since version 1.
pub const U64_VERSION: u8 = 1;
/// The site report layout [`VERSION`] stands for: (version, FNV-1a 64 of
/// `coop_rt::msg::layout_text(SiteReport::LAYOUT)`). Changing [`SiteReport`] changes the hash, and
/// the test `the_layout_is_pinned_to_the_version_and_the_doc` fails until [`VERSION`] is bumped,
/// `docs/wire.md` describes the new layout, and this is re-pinned (the test prints the new value).
pub const PINNED: (u8, u64) = (6, 0x1cda41364d9098d7);
/// The most bytes an encoded report takes (every word nonzero, every integer 10 bytes).
pub const MAX_ENCODED_LEN: usize = 1 + max_words_len(SiteReport::LAYOUT, 0, SiteReport::WORDS);
/// The version byte a tool track carries (2 added tracks, 3 added their `need`, 4 their carried
/// state, 5 a world's objects, 6 the compact encoding): [`VERSION`].
pub const TRACK_VERSION: u8 = VERSION;
/// The tool track layout [`TRACK_VERSION`] stands for: (version, FNV-1a 64 of
/// `coop_rt::msg::layout_text(ToolTrack::LAYOUT)`), pinned as [`PINNED`] is.
pub const TRACK_PINNED: (u8, u64) = (6, 0xfcfdd4b3e41ef627);
/// The most bytes an encoded tool track takes: every header and state word nonzero and every
/// integer 10 bytes, and every coordinate 5 (a coordinate and a difference of two fit 33 bits).
/// (A bound: `count` takes 2 bytes at most, as no more than 256 is accepted.)
pub const MAX_TRACK_ENCODED_LEN: usize = 1
    + max_words_len(ToolTrack::LAYOUT, 0, TRACK_STATE_AT)
    + max_words_len(ToolTrack::LAYOUT, TRACK_STATE_AT, TRACK_POSITIONS_AT)
    + 5 * 3 * WINDOW_TICKS;

/// Where a track's words part: its header (through `has_state`), its carried state (from
/// `state_body`), its positions.
const TRACK_STATE_AT: usize = field_word(ToolTrack::LAYOUT, "state_body");
const TRACK_POSITIONS_AT: usize = field_word(ToolTrack::LAYOUT, "positions");
const _: () = assert!(TRACK_POSITIONS_AT + TRACK_POSITION_WORDS == ToolTrack::WORDS);
const _: () = assert!(field_word(ToolTrack::LAYOUT, "has_state") + 1 == TRACK_STATE_AT);

/// Why a message was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Another version.
    #[error("wire version {found}, expected {VERSION}")]
    Version {
        /// Version byte found.
        found: u8,
    },
    /// It ends inside a field.
    #[error("truncated: the message ends inside the field at byte {at}")]
    Truncated {
        /// Offset of the field.
        at: usize,
    },
    /// Bytes after its end.
    #[error("{extra} bytes after the message's end")]
    Trailing {
        /// How many.
        extra: usize,
    },
    /// A varint longer than it has to be or past 64 bits.
    #[error("the varint at byte {at} is not minimal or overflows 64 bits")]
    Varint {
        /// Its offset.
        at: usize,
    },
    /// Well-formed but not a valid report (non-finite value, bad quaternion, unknown site or kind).
    #[error("invalid report contents")]
    Invalid,
}

/// Encodes a u64 message (session time 0, clock reading).
pub fn encode_u64(v: u64) -> [u8; 9] {
    let mut out = [0u8; 9];
    out[0] = U64_VERSION;
    out[1..].copy_from_slice(&v.to_le_bytes());
    out
}

/// Decodes a u64 message.
///
/// # Errors
/// Wrong version or length.
pub fn decode_u64(bytes: &[u8]) -> Result<u64, DecodeError> {
    match bytes {
        [U64_VERSION, rest @ ..] if rest.len() == 8 => {
            let mut w = [0u8; 8];
            w.copy_from_slice(rest);
            Ok(u64::from_le_bytes(w))
        }
        [U64_VERSION, rest @ ..] if rest.len() > 8 => Err(DecodeError::Trailing {
            extra: rest.len() - 8,
        }),
        [U64_VERSION, ..] => Err(DecodeError::Truncated { at: 1 }),
        [v, ..] => Err(DecodeError::Version { found: *v }),
        [] => Err(DecodeError::Truncated { at: 0 }),
    }
}

/// The version byte, and a reader of what follows.
fn open(bytes: &[u8]) -> Result<Reader<'_>, DecodeError> {
    let (&version, body) = bytes
        .split_first()
        .ok_or(DecodeError::Truncated { at: 0 })?;
    if version != VERSION {
        return Err(DecodeError::Version { found: version });
    }
    Ok(Reader::new(body, 1))
}

/// Encodes a report: the version, then [`SiteReport::to_words`] in the compact encoding.
pub fn encode(r: &SiteReport) -> Vec<u8> {
    let mut out = Vec::with_capacity(MAX_ENCODED_LEN);
    out.push(VERSION);
    put_words(&mut out, SiteReport::LAYOUT, 0, &r.to_words());
    out
}

/// Decodes a report and validates it: this is where a report from the network is checked, with
/// [`SiteReport::report`], the one validation of a report (physics applies the same function as
/// its ring → model conversion, against whatever else might write the ring).
///
/// # Errors
/// [`DecodeError`]: wrong version, truncated, trailing bytes, a bad varint, or invalid contents.
pub fn decode(bytes: &[u8]) -> Result<SiteReport, DecodeError> {
    let mut rd = open(bytes)?;
    let mut words = [0u64; SiteReport::WORDS];
    take_words(&mut rd, SiteReport::LAYOUT, 0, &mut words)?;
    rd.end()?;
    let r = SiteReport::from_words(&words);
    r.report().ok_or(DecodeError::Invalid)?;
    Ok(r)
}

/// Encodes a tool track: [`TRACK_VERSION`], its header words, its carried state's words when it
/// has one (`has_state` not 0), each in the compact encoding, then its `count` positions: the
/// first tick's coordinates, then every later tick that moved as its difference from the tick
/// before, each coordinate a zigzag varint; x's shifted left by one, its low bit set when a
/// varint follows the tick's three with how many ticks after it hold its position (a deadband's
/// held positions, a tool at rest: one tick's bytes for a run).
pub fn encode_track(t: &ToolTrack) -> Vec<u8> {
    let words = t.to_words();
    let count = (t.count as usize).min(WINDOW_TICKS);
    let mut out = Vec::with_capacity(64 + 3 * count);
    out.push(TRACK_VERSION);
    put_words(&mut out, ToolTrack::LAYOUT, 0, &words[..TRACK_STATE_AT]);
    if t.has_state != 0 {
        put_words(
            &mut out,
            ToolTrack::LAYOUT,
            TRACK_STATE_AT,
            &words[TRACK_STATE_AT..TRACK_POSITIONS_AT],
        );
    }
    let at = |k: usize| [0, 1, 2].map(|c| i64::from(t.coordinate(3 * k + c)));
    let (mut prev, mut k) = ([0i64; 3], 0);
    while k < count {
        let p = at(k);
        let held = (k + 1..count).take_while(|&h| at(h) == p).count();
        let d = [0, 1, 2].map(|c| zigzag(p[c] - prev[c]));
        put_varint(&mut out, d[0] << 1 | u64::from(held > 0));
        put_varint(&mut out, d[1]);
        put_varint(&mut out, d[2]);
        if held > 0 {
            put_varint(&mut out, held as u64);
        }
        prev = p;
        k += 1 + held;
    }
    out
}

/// Decodes a tool track and validates it with [`ToolTrack::report`] (the one validation of a
/// track, which physics applies again as its ring → model conversion).
///
/// # Errors
/// [`DecodeError`]: wrong version, truncated, trailing bytes, a bad varint, more than
/// [`WINDOW_TICKS`] positions or one beyond an i32, or invalid contents.
pub fn decode_track(bytes: &[u8]) -> Result<ToolTrack, DecodeError> {
    let mut rd = open(bytes)?;
    let mut words = [0u64; ToolTrack::WORDS];
    take_words(&mut rd, ToolTrack::LAYOUT, 0, &mut words[..TRACK_STATE_AT])?;
    let has_state = words[field_word(ToolTrack::LAYOUT, "has_state")];
    if has_state != 0 {
        take_words(
            &mut rd,
            ToolTrack::LAYOUT,
            TRACK_STATE_AT,
            &mut words[TRACK_STATE_AT..TRACK_POSITIONS_AT],
        )?;
    }
    let count = words[field_word(ToolTrack::LAYOUT, "count")];
    if count > WINDOW_TICKS as u64 {
        return Err(DecodeError::Invalid);
    }
    let mut t = ToolTrack::from_words(&words);
    let (count, mut k, mut prev) = (count as usize, 0usize, [0i64; 3]);
    while k < count {
        let x = rd.varint()?;
        let d = [
            unzigzag(x >> 1),
            unzigzag(rd.varint()?),
            unzigzag(rd.varint()?),
        ];
        let held = if x & 1 == 1 { rd.varint()? } else { 0 };
        // One encoding: a tick after the first moved (else it is held), a run is not empty and
        // ends by the count.
        let run = usize::try_from(held).ok().filter(|&h| h < count - k);
        if (k > 0 && d == [0; 3]) || (x & 1 == 1 && held == 0) || run.is_none() {
            return Err(DecodeError::Invalid);
        }
        for (p, d) in prev.iter_mut().zip(d) {
            *p = p
                .checked_add(d)
                .filter(|v| i32::try_from(*v).is_ok())
                .ok_or(DecodeError::Invalid)?;
        }
        for tick in k..=k + run.unwrap_or(0) {
            for (c, &v) in prev.iter().enumerate() {
                // (In the i32 range: checked above.)
                t.put_coordinate(3 * tick + c, v as i32);
            }
        }
        k += 1 + run.unwrap_or(0);
    }
    rd.end()?;
    t.report().ok_or(DecodeError::Invalid)?;
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use compact::{put_varint, zigzag};
    use coop_rt::msg::layout_text;
    use coop_rt::pod::fnv1a64;

    /// The site report section of `docs/wire.md`: its heading, its text, and its field table as
    /// (name, kind, words).
    fn documented_layout() -> (String, String, Vec<(String, &'static str, usize)>) {
        let doc = include_str!("../../docs/wire.md");
        let start = doc
            .find("\n## Site report")
            .expect("docs/wire.md has no \"## Site report\" section");
        let section = &doc[start + 1..];
        let section = &section[..section[1..].find("\n## ").map_or(section.len(), |e| e + 1)];
        let heading = section.lines().next().unwrap_or_default().to_string();
        let mut fields = Vec::new();
        for row in section.lines().filter(|l| l.starts_with('|')) {
            let cells: Vec<&str> = row.split('|').map(str::trim).collect();
            let (words, name) = (cells[1], cells[2]);
            if words == "words" || words.starts_with('-') {
                continue; // the header and its rule
            }
            fn bad<T>(row: &str) -> T {
                panic!("docs/wire.md: a site report row is not `| <n> u|f | `name` | … |`: {row}")
            }
            let (n, kind) = words.split_once(' ').unwrap_or_else(|| bad(row));
            let n: usize = n.parse().unwrap_or_else(|_| bad(row));
            let kind = match kind.trim() {
                "u" => "u64",
                "f" => "f64",
                _ => bad(row),
            };
            let name = name
                .strip_prefix('`')
                .and_then(|n| n.strip_suffix('`'))
                .unwrap_or_else(|| bad(row));
            fields.push((name.to_string(), kind, n));
        }
        (heading, section.to_string(), fields)
    }

    #[test]
    fn the_layout_is_pinned_to_the_version_and_the_doc() {
        let text = layout_text(SiteReport::LAYOUT);
        let hash = fnv1a64(text.as_bytes());
        assert!(
            PINNED.0 == VERSION,
            "wire::VERSION is {VERSION} but the site report layout was pinned for version {}: once \
             docs/wire.md describes version {VERSION}, re-pin `PINNED = ({VERSION}, {hash:#018x})`",
            PINNED.0
        );
        assert!(
            PINNED.1 == hash,
            "SiteReport's layout changed but wire::VERSION is still {VERSION}: another field order is \
             another wire format. Bump VERSION, update the site report table in docs/wire.md, and \
             re-pin `PINNED = (<new VERSION>, {hash:#018x})`. The layout now:\n{text}"
        );
        let (heading, section, fields) = documented_layout();
        let ours: Vec<(String, &str, usize)> = SiteReport::LAYOUT
            .iter()
            .map(|&(n, k, c)| (n.to_string(), k, c))
            .collect();
        assert_eq!(
            fields, ours,
            "docs/wire.md's site report table (left) is not SiteReport::LAYOUT (right)"
        );
        assert!(
            heading.contains(&format!("(version {VERSION})"))
                && heading.contains(&format!("at most {MAX_ENCODED_LEN} bytes")),
            "docs/wire.md: the heading `{heading}` should name version {VERSION} and {MAX_ENCODED_LEN} bytes"
        );
        assert!(
            section.contains(&format!("Byte 0 is the version, `{VERSION}`"))
                && section.contains(&format!("Then its {} words", SiteReport::WORDS)),
            "docs/wire.md: the site report text should say version `{VERSION}` and {} words",
            SiteReport::WORDS
        );
    }

    fn sample() -> SiteReport {
        let mut r = SiteReport {
            kind: 1,
            t_ns: 5,
            seq: 9,
            site: 1,
            object: 1,
            rot: [1.0, 0.0, 0.0, 0.0],
            ..SiteReport::default()
        };
        r.pos = [0.1, 0.2, 0.3];
        r.included[1] = 4.5;
        r
    }

    #[test]
    fn round_trip_and_every_corruption_is_refused() {
        let r = sample();
        let bytes = encode(&r);
        // The version; the bitmap (kind, t_ns, seq, site, object, pos[0..3], rot w, included[1]:
        // words 0-7, 8, 22); kind 1, t_ns 5, seq 9, site 1, object 1 as varints; pos and rot's w
        // and included[1] as 8 bytes each.
        let mut want = vec![VERSION, 0xff, 0x01, 0x40, 0, 0, 1, 5, 9, 1, 1];
        for v in [0.1f64, 0.2, 0.3, 1.0, 4.5] {
            want.extend_from_slice(&v.to_le_bytes());
        }
        assert_eq!(bytes, want);
        assert_eq!(bytes.len(), 51);
        assert_eq!(decode(&bytes), Ok(r));
        let mut v1 = bytes.clone();
        v1[0] = 1;
        assert_eq!(decode(&v1), Err(DecodeError::Version { found: 1 }));
        assert_eq!(decode(&bytes[..20]), Err(DecodeError::Truncated { at: 19 }));
        let mut long = bytes.clone();
        long.push(0);
        assert_eq!(decode(&long), Err(DecodeError::Trailing { extra: 1 }));
        assert_eq!(decode(&[]), Err(DecodeError::Truncated { at: 0 }));
        // A zero marked nonzero (one encoding per message), and a varint not minimal.
        let mut zero = bytes.clone();
        zero[7] = 0;
        assert_eq!(decode(&zero), Err(DecodeError::Invalid));
        let mut overlong = bytes[..6].to_vec();
        overlong.extend_from_slice(&[0x81, 0x00]);
        overlong.extend_from_slice(&bytes[7..]);
        assert_eq!(decode(&overlong), Err(DecodeError::Varint { at: 6 }));
        let mut nan = r;
        nan.vel[0] = f64::NAN;
        assert_eq!(decode(&encode(&nan)), Err(DecodeError::Invalid));
        // Every word nonzero and every integer at its longest.
        let mut full = SiteReport::from_words(&[u64::MAX; SiteReport::WORDS]);
        full.kind = u64::MAX;
        assert_eq!(encode(&full).len(), MAX_ENCODED_LEN);
        // Flipping any single byte never panics.
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0xff;
            let _ = decode(&b);
        }
    }

    #[test]
    fn u64_messages_round_trip_and_refuse_garbage() {
        assert_eq!(decode_u64(&encode_u64(42)), Ok(42));
        assert_eq!(
            decode_u64(&[2, 0, 0, 0, 0, 0, 0, 0, 0]),
            Err(DecodeError::Version { found: 2 })
        );
        assert_eq!(decode_u64(&[1, 0]), Err(DecodeError::Truncated { at: 1 }));
        assert_eq!(
            decode_u64(&[1, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
            Err(DecodeError::Trailing { extra: 1 })
        );
    }

    #[test]
    fn the_track_layout_is_pinned_to_its_version_and_the_doc() {
        let text = layout_text(ToolTrack::LAYOUT);
        let hash = fnv1a64(text.as_bytes());
        assert!(
            TRACK_PINNED == (TRACK_VERSION, hash),
            "ToolTrack's layout is pinned as {TRACK_PINNED:?} but is ({TRACK_VERSION}, {hash:#018x}): \
             another field order is another wire format. Bump TRACK_VERSION, update the tool track \
             table in docs/wire.md, and re-pin. The layout now:\n{text}"
        );
        let doc = include_str!("../../docs/wire.md");
        let start = doc
            .find("\n## Tool track")
            .expect("docs/wire.md has no \"## Tool track\" section");
        let section = &doc[start + 1..];
        let section = &section[..section[1..].find("\n## ").map_or(section.len(), |e| e + 1)];
        let mut fields = Vec::new();
        for row in section.lines().filter(|l| l.starts_with('|')) {
            let cells: Vec<&str> = row.split('|').map(str::trim).collect();
            if cells[1] == "words" || cells[1].starts_with('-') {
                continue;
            }
            let (n, _) = cells[1].split_once(' ').expect("`| <n> u | `name` | … |`");
            let name = cells[2].trim_matches('`');
            fields.push((name.to_string(), n.parse::<usize>().expect("word count")));
        }
        let ours: Vec<(String, usize)> = ToolTrack::LAYOUT
            .iter()
            .map(|&(n, _, c)| (n.to_string(), c))
            .collect();
        assert_eq!(
            fields, ours,
            "docs/wire.md's tool track table (left) is not ToolTrack::LAYOUT"
        );
        let heading = section.lines().next().unwrap_or_default();
        assert!(
            heading.contains(&format!("(version {TRACK_VERSION})"))
                && heading.contains(&format!("at most {MAX_TRACK_ENCODED_LEN} bytes")),
            "docs/wire.md: `{heading}` should name version {TRACK_VERSION} and {MAX_TRACK_ENCODED_LEN} bytes"
        );
    }

    #[test]
    fn tracks_round_trip_and_every_corruption_is_refused() {
        use coop_model::method::track::{ToolReport, WINDOW_TICKS};
        let mut r = ToolReport {
            first_tick: 500,
            count: 20,
            positions: [[0; 3]; WINDOW_TICKS],
            confirmed_tick: 480,
            confirmed_hash: 77,
            need: [-1; coop_model::method::MAX_SITES],
            ..ToolReport::NONE
        };
        for (k, p) in r.positions[..20].iter_mut().enumerate() {
            *p = [-4500 + k as i32, 3, 1000];
        }
        r.need[0] = 470;
        let t = ToolTrack::new(1, 3, 99, &r);
        let bytes = encode_track(&t);
        // The version; the header's bitmap (t_ns, seq, site, first_tick, count, confirmed_tick,
        // confirmed_hash: words 0-6; need[0]: word 7); those words as varints; then the
        // positions: the first tick's zigzagged (-4500 → 8999, shifted: 17998, no run after it;
        // 3 → 6; 1000 → 2000), and each later one's difference (x + 1 → 2, shifted: 4; y, z 0).
        let mut want = vec![TRACK_VERSION, 0xff, 0x00, 0x00, 99, 3, 1];
        for v in [500u64, 20, 480, 77, 471, 17998, 6, 2000] {
            put_varint(&mut want, v);
        }
        for _ in 1..20 {
            want.extend_from_slice(&[4, 0, 0]);
        }
        assert_eq!(bytes, want);
        assert_eq!(bytes.len(), 78);
        // Held positions (a deadband's, a tool at rest) go as a run: the 5th to the 20th tick
        // repeat the 4th (its x's low bit set, then 16).
        let mut held = r;
        for p in &mut held.positions[4..20] {
            *p = [-4497, 3, 1000];
        }
        let th = ToolTrack::new(1, 3, 99, &held);
        let hb = encode_track(&th);
        assert_eq!(hb.len(), bytes.len() - 16 * 3 + 1);
        assert_eq!(hb[hb.len() - 4..], [5, 0, 0, 16]);
        assert_eq!(decode_track(&hb), Ok(th));
        // One encoding: a run of 0, a run past the count, a tick that did not move.
        for (tail, why) in [
            (&[5u8, 0, 0, 0][..], "an empty run"),
            (&[5, 0, 0, 17], "a run past the count"),
            (&[4, 0, 0, 4, 0, 0, 0, 0, 0], "a tick that did not move"),
        ] {
            let mut b = hb[..hb.len() - 4].to_vec();
            b.extend_from_slice(tail);
            assert_eq!(decode_track(&b), Err(DecodeError::Invalid), "{why}");
        }
        assert_eq!(decode_track(&bytes), Ok(t));
        assert_eq!(
            t.report().map(|(_, r2)| r2),
            Some(coop_model::method::Report::Tools(ToolReport {
                seq: 3,
                ..r
            }))
        );
        // A confirmed state, asked for by site 1 (bit 1 of `need_state`, word 15) from a sender
        // restarted 3 times (word 16), goes to the bit: the adopting site hashes it to the
        // sender's `confirmed_hash`.
        let mut body =
            coop_model::body::BodyState::at_rest(coop_model::body::Vec3::new(0.01, -0.02, 0.01));
        body.rot = nalgebra::UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3);
        body.vel.x = -1.0 / 3.0;
        let mut anchors = [None; coop_model::contact::MAX_PLANES];
        anchors[2] = Some(coop_model::body::Vec3::new(-0.25, 0.0, 1e-3));
        let mut contacts =
            [coop_model::contact::ToolContactState::default(); coop_model::method::MAX_SITES];
        contacts[1] = coop_model::contact::ToolContactState::from_anchor(Some(
            coop_model::body::Vec3::new(0.04, 0.0, -0.0),
        ));
        let snap = coop_model::method::track::Snapshot::one(
            480,
            coop_model::method::timewarp::hash_state(&body),
            body,
            coop_model::contact::EnvContactState::from_anchors(anchors),
            contacts,
        );
        let with_state = ToolReport {
            need_state: 0b10,
            started_tick: 3,
            state: Some(snap),
            confirmed_hash: coop_model::method::timewarp::hash_state(&body),
            ..r
        };
        let ts = ToolTrack::new(1, 4, 99, &with_state);
        let bs = encode_track(&ts);
        // `need_state`, `started_tick`, `has_state` (words 15, 17, 18) in the bitmap, and the state's
        // words after the header's.
        assert_eq!(bs[1..4], [0xff, 0x80, 0x06]);
        assert!(bs.len() > bytes.len() + 13 * 8, "{}", bs.len());
        assert_eq!(
            decode_track(&bs)
                .ok()
                .and_then(|t| t.report())
                .map(|(_, r2)| r2),
            Some(coop_model::method::Report::Tools(ToolReport {
                seq: 4,
                ..with_state
            }))
        );
        // A state that is not one: a stick point without its bit, or a bit without a state.
        let mut stray = ts;
        stray.state_env[0] = 1.0;
        assert_eq!(
            decode_track(&encode_track(&stray)),
            Err(DecodeError::Invalid)
        );
        // (Without a state, no state word is on the wire: a stray one is not sent.)
        let mut stray = t;
        stray.state_anchors = 1;
        assert_eq!(decode_track(&encode_track(&stray)), Ok(t));
        let mut stray = ts;
        stray.state_body[3] = 2.0;
        assert_eq!(
            decode_track(&encode_track(&stray)),
            Err(DecodeError::Invalid)
        );
        // A version-5 track (fixed words) is refused by its version.
        let mut v5 = bytes.clone();
        v5[0] = 5;
        assert_eq!(decode_track(&v5), Err(DecodeError::Version { found: 5 }));
        // A state reader refuses a track, a track reader a state.
        assert!(decode(&bytes).is_err());
        assert!(decode_track(&encode(&sample())).is_err());
        assert_eq!(
            decode_track(&bytes[..40]),
            Err(DecodeError::Truncated { at: 40 })
        );
        let mut long = bytes.clone();
        long.push(0);
        assert_eq!(decode_track(&long), Err(DecodeError::Trailing { extra: 1 }));
        let mut bad = t;
        bad.count = WINDOW_TICKS as u64 + 1;
        assert_eq!(decode_track(&encode_track(&bad)), Err(DecodeError::Invalid));
        // A coordinate past an i32 (the difference overflows it).
        let mut far = bytes[..bytes.len() - 3].to_vec();
        put_varint(&mut far, zigzag(i64::from(i32::MAX)) << 1);
        far.extend_from_slice(&[0, 0]);
        assert_eq!(decode_track(&far), Err(DecodeError::Invalid));
        // The longest track: every header and state word nonzero and at its longest, 256
        // positions jumping across the i32 range.
        let mut longest = ToolTrack::from_words(&[u64::MAX; ToolTrack::WORDS]);
        longest.count = WINDOW_TICKS as u64;
        longest.positions = [0; TRACK_POSITION_WORDS];
        for c in 0..3 * WINDOW_TICKS {
            let v = if (c / 3) % 2 == 0 { i32::MIN } else { i32::MAX };
            longest.put_coordinate(c, v);
        }
        assert_eq!(encode_track(&longest).len() + 8, MAX_TRACK_ENCODED_LEN);
        // Flipping any single byte never panics.
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0xff;
            let _ = decode_track(&b);
        }
    }
}
