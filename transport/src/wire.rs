//! The wire format between stations: one encode and one decode per message (`docs/wire.md` is the
//! specification a foreign client can be written from).
//!
//! A site report is `version: u8 = 5`, then [`SiteReport::to_words`] (its fields in declaration
//! order, as `pod_message!` declares them) as little-endian u64/f64, nothing else: exactly
//! [`ENCODED_LEN`] bytes. There is no second field list here: the layout is the struct's, and
//! [`PINNED`] ties it to [`VERSION`] and to the table in `docs/wire.md` (a unit test fails when the
//! struct changes without a version bump and the doc). Decoding checks the version,
//! the length (no truncation, no trailing bytes) and then everything [`SiteReport::report`] checks
//! (finite numbers in every field, a unit quaternion, a known kind, and zero in the fields the
//! kind does not use). What only a receiver can check (the site, the time, plausibility, the
//! sequence) is [`crate::admit`]'s. Any failure is a typed error and changes nothing.
//!
//! The session's time 0 and clock readings are `version: u8 = 1` then one little-endian u64
//! (unchanged since version 1: [`U64_VERSION`]).
//!
//! A tool track (methods that exchange the tools: `timewarp`, `coupled`) is `version: u8 = 5` then
//! [`ToolTrack::to_words`], exactly [`TRACK_ENCODED_LEN`] bytes, on its own key (`tool/<site>`).
//! Version 2 added this message and changed nothing else; version 3 added the track's `need` (a
//! receiver asking for positions lost in a gap); version 4 the confirmed state a site whose
//! confirmed history diverged asks for and adopts; version 5 the worlds of several objects (a
//! state names its object, on its object's key; a track's carried state names its object, its
//! world, and every friction memory it holds). States and tracks both carry byte 5 and are told
//! apart by their key and length. [`TRACK_PINNED`] ties the track's layout to the doc as
//! [`PINNED`] does the state's.

use coop_rt::msg::{SiteReport, ToolTrack};

/// Current wire version.
pub const VERSION: u8 = 5;
/// The version byte of a u64 message (session time 0, clock reading): unchanged since version 1.
pub const U64_VERSION: u8 = 1;
/// The site report layout [`VERSION`] stands for: (version, FNV-1a 64 of
/// `coop_rt::msg::layout_text(SiteReport::LAYOUT)`). Changing [`SiteReport`] changes the hash, and
/// the test `the_layout_is_pinned_to_the_version_and_the_doc` fails until [`VERSION`] is bumped,
/// `docs/wire.md` describes the new layout, and this is re-pinned (the test prints the new value).
pub const PINNED: (u8, u64) = (5, 0x1cda41364d9098d7);
/// Bytes of an encoded report.
pub const ENCODED_LEN: usize = 1 + 8 * SiteReport::WORDS;
/// The version byte a tool track carries (2 added tracks, 3 added their `need`, 4 their carried
/// state, 5 a world's objects): [`VERSION`].
pub const TRACK_VERSION: u8 = VERSION;
/// The tool track layout [`TRACK_VERSION`] stands for: (version, FNV-1a 64 of
/// `coop_rt::msg::layout_text(ToolTrack::LAYOUT)`), pinned as [`PINNED`] is.
pub const TRACK_PINNED: (u8, u64) = (5, 0xfdf8d1b08f56854c);
/// Bytes of an encoded tool track.
pub const TRACK_ENCODED_LEN: usize = 1 + 8 * ToolTrack::WORDS;

/// Why a message was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Another version.
    #[error("wire version {found}, expected {VERSION}")]
    Version {
        /// Version byte found.
        found: u8,
    },
    /// Too short, too long.
    #[error("{found} bytes, expected exactly {ENCODED_LEN}")]
    Length {
        /// Length found.
        found: usize,
    },
    /// A tool track too short or too long.
    #[error("{found} bytes, expected exactly {TRACK_ENCODED_LEN} for a tool track")]
    TrackLength {
        /// Length found.
        found: usize,
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
        [U64_VERSION, ..] => Err(DecodeError::Length { found: bytes.len() }),
        [v, ..] => Err(DecodeError::Version { found: *v }),
        [] => Err(DecodeError::Length { found: 0 }),
    }
}

/// Encodes a report: the version, then [`SiteReport::to_words`] little-endian.
pub fn encode(r: &SiteReport) -> Vec<u8> {
    let mut out = Vec::with_capacity(ENCODED_LEN);
    out.push(VERSION);
    for w in r.to_words() {
        out.extend_from_slice(&w.to_le_bytes());
    }
    out
}

/// Decodes a report and validates it: this is where a report from the network is checked, with
/// [`SiteReport::report`], the one validation of a report (physics applies the same function as
/// its ring → model conversion, against whatever else might write the ring).
///
/// # Errors
/// [`DecodeError`]: wrong version, wrong length, or invalid contents.
pub fn decode(bytes: &[u8]) -> Result<SiteReport, DecodeError> {
    let (&version, body) = bytes
        .split_first()
        .ok_or(DecodeError::Length { found: 0 })?;
    if version != VERSION {
        return Err(DecodeError::Version { found: version });
    }
    if bytes.len() != ENCODED_LEN {
        return Err(DecodeError::Length { found: bytes.len() });
    }
    let mut words = [0u64; SiteReport::WORDS];
    for (w, c) in words.iter_mut().zip(body.chunks_exact(8)) {
        let mut b = [0u8; 8];
        b.copy_from_slice(c);
        *w = u64::from_le_bytes(b);
    }
    let r = SiteReport::from_words(&words);
    r.report().ok_or(DecodeError::Invalid)?;
    Ok(r)
}

/// Encodes a tool track: [`TRACK_VERSION`], then [`ToolTrack::to_words`] little-endian.
pub fn encode_track(t: &ToolTrack) -> Vec<u8> {
    let mut out = Vec::with_capacity(TRACK_ENCODED_LEN);
    out.push(TRACK_VERSION);
    for w in t.to_words() {
        out.extend_from_slice(&w.to_le_bytes());
    }
    out
}

/// Decodes a tool track and validates it with [`ToolTrack::report`] (the one validation of a
/// track, which physics applies again as its ring → model conversion).
///
/// # Errors
/// [`DecodeError`]: wrong version, wrong length ([`DecodeError::TrackLength`]), invalid contents.
pub fn decode_track(bytes: &[u8]) -> Result<ToolTrack, DecodeError> {
    let (&version, body) = bytes
        .split_first()
        .ok_or(DecodeError::TrackLength { found: 0 })?;
    if version != TRACK_VERSION {
        return Err(DecodeError::Version { found: version });
    }
    if bytes.len() != TRACK_ENCODED_LEN {
        return Err(DecodeError::TrackLength { found: bytes.len() });
    }
    let mut words = [0u64; ToolTrack::WORDS];
    for (w, c) in words.iter_mut().zip(body.chunks_exact(8)) {
        let mut b = [0u8; 8];
        b.copy_from_slice(c);
        *w = u64::from_le_bytes(b);
    }
    let t = ToolTrack::from_words(&words);
    t.report().ok_or(DecodeError::Invalid)?;
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use coop_rt::msg::layout_text;
    use coop_rt::shm::pod::fnv1a64;

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
                && heading.contains(&format!("exactly {ENCODED_LEN} bytes")),
            "docs/wire.md: the heading `{heading}` should name version {VERSION} and {ENCODED_LEN} bytes"
        );
        assert!(
            section.contains(&format!("Byte 0 is the version, `{VERSION}`"))
                && section.contains(&format!("Then {} little-endian", SiteReport::WORDS)),
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
        assert_eq!(bytes.len(), ENCODED_LEN);
        assert_eq!(ENCODED_LEN, 321, "docs/wire.md says 321 bytes");
        // Where docs/wire.md puts them: kind in word 0, object in word 4, pos[0] in word 5,
        // included[1] in word 22.
        let word = |i: usize| &bytes[1 + 8 * i..9 + 8 * i];
        assert_eq!(bytes[0], 5);
        assert_eq!(word(0), 1u64.to_le_bytes());
        assert_eq!(word(2), 9u64.to_le_bytes());
        assert_eq!(word(4), 1u64.to_le_bytes());
        assert_eq!(word(5), 0.1f64.to_le_bytes());
        assert_eq!(word(22), 4.5f64.to_le_bytes());
        assert_eq!(decode(&bytes), Ok(r));
        let mut v1 = bytes.clone();
        v1[0] = 1;
        assert_eq!(decode(&v1), Err(DecodeError::Version { found: 1 }));
        assert_eq!(
            decode(&bytes[..100]),
            Err(DecodeError::Length { found: 100 })
        );
        let mut long = bytes.clone();
        long.push(0);
        assert_eq!(
            decode(&long),
            Err(DecodeError::Length {
                found: ENCODED_LEN + 1
            })
        );
        assert_eq!(decode(&[]), Err(DecodeError::Length { found: 0 }));
        let mut nan = r;
        nan.vel[0] = f64::NAN;
        assert_eq!(decode(&encode(&nan)), Err(DecodeError::Invalid));
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
        assert_eq!(decode_u64(&[1, 0]), Err(DecodeError::Length { found: 2 }));
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
                && heading.contains(&format!("exactly {TRACK_ENCODED_LEN} bytes")),
            "docs/wire.md: `{heading}` should name version {TRACK_VERSION} and {TRACK_ENCODED_LEN} bytes"
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
        assert_eq!(bytes.len(), TRACK_ENCODED_LEN);
        assert_eq!(TRACK_ENCODED_LEN, 5817, "docs/wire.md says 5817 bytes");
        assert_eq!(bytes[0], 5);
        // Where docs/wire.md puts them: site in word 2, `need` of site 0 (1 + the tick) in word 7,
        // none (0) for site 1 in word 8, no state (word 17), the first x in the low half of
        // word 343.
        assert_eq!(&bytes[1 + 16..1 + 24], 1u64.to_le_bytes());
        assert_eq!(&bytes[1 + 56..1 + 64], 471u64.to_le_bytes());
        assert_eq!(&bytes[1 + 64..1 + 72], 0u64.to_le_bytes());
        assert_eq!(&bytes[1 + 136..1 + 144], 0u64.to_le_bytes());
        assert_eq!(&bytes[1 + 2744..1 + 2748], (-4500i32).to_le_bytes());
        assert_eq!(decode_track(&bytes), Ok(t));
        assert_eq!(
            t.report().map(|(_, r2)| r2),
            Some(coop_model::method::Report::Tools(r))
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
        assert_eq!(&bs[1 + 120..1 + 128], 2u64.to_le_bytes());
        assert_eq!(&bs[1 + 128..1 + 136], 3u64.to_le_bytes());
        assert_eq!(&bs[1 + 136..1 + 144], 1u64.to_le_bytes());
        assert_eq!(
            decode_track(&bs)
                .ok()
                .and_then(|t| t.report())
                .map(|(_, r2)| r2),
            Some(coop_model::method::Report::Tools(with_state))
        );
        // A state that is not one: a stick point without its bit, or a bit without a state.
        let mut stray = ts;
        stray.state_env[0] = 1.0;
        assert_eq!(
            decode_track(&encode_track(&stray)),
            Err(DecodeError::Invalid)
        );
        let mut stray = t;
        stray.state_anchors = 1;
        assert_eq!(
            decode_track(&encode_track(&stray)),
            Err(DecodeError::Invalid)
        );
        let mut stray = ts;
        stray.state_body[3] = 2.0;
        assert_eq!(
            decode_track(&encode_track(&stray)),
            Err(DecodeError::Invalid)
        );
        // A version-4 track (one object's state) is refused by its version.
        let mut v4 = bytes.clone();
        v4[0] = 4;
        assert_eq!(decode_track(&v4), Err(DecodeError::Version { found: 4 }));
        // A state reader refuses a track by its length, a track reader a state.
        assert_eq!(
            decode(&bytes),
            Err(DecodeError::Length {
                found: TRACK_ENCODED_LEN
            })
        );
        assert_eq!(
            decode_track(&encode(&sample())),
            Err(DecodeError::TrackLength { found: ENCODED_LEN })
        );
        assert_eq!(
            decode_track(&bytes[..100]),
            Err(DecodeError::TrackLength { found: 100 })
        );
        let mut long = bytes.clone();
        long.push(0);
        assert_eq!(
            decode_track(&long),
            Err(DecodeError::TrackLength {
                found: TRACK_ENCODED_LEN + 1
            })
        );
        let mut bad = t;
        bad.count = WINDOW_TICKS as u64 + 1;
        assert_eq!(decode_track(&encode_track(&bad)), Err(DecodeError::Invalid));
        // Flipping any single byte never panics.
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0xff;
            let _ = decode_track(&b);
        }
    }
}
