//! The wire format of a site report: one encode, one decode.
//!
//! `version: u8 = 1`, then the [`SiteReport`] fields in declaration order as little-endian u64/f64,
//! nothing else: exactly [`ENCODED_LEN`] bytes. Decoding checks the version, the length (no
//! truncation, no trailing bytes) and then everything [`SiteReport::report`] checks (finite numbers,
//! unit quaternion, known site, known kind). Any failure is a typed error and changes nothing.

use coop_rt::msg::SiteReport;

/// Current wire version.
pub const VERSION: u8 = 1;
/// Bytes of an encoded report.
pub const ENCODED_LEN: usize = 1 + core::mem::size_of::<SiteReport>();

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
    /// Well-formed but not a valid report (non-finite value, bad quaternion, unknown site or kind).
    #[error("invalid report contents")]
    Invalid,
}

fn words(r: &SiteReport) -> impl Iterator<Item = u64> + '_ {
    let f = |v: &f64| v.to_bits();
    [r.kind, r.t_ns, r.seq, r.site]
        .into_iter()
        .chain(r.pos.iter().map(f))
        .chain(r.rot.iter().map(f))
        .chain(r.vel.iter().map(f))
        .chain(r.ang_mom.iter().map(f))
        .chain(r.accel.iter().map(f))
        .chain(r.included.iter().map(f))
        .chain(r.force.iter().map(f))
        .chain(r.point.iter().map(f))
        .chain([r.depth.to_bits(), r.touching])
}

/// Encodes a report.
pub fn encode(r: &SiteReport) -> Vec<u8> {
    let mut out = Vec::with_capacity(ENCODED_LEN);
    out.push(VERSION);
    for w in words(r) {
        out.extend_from_slice(&w.to_le_bytes());
    }
    out
}

/// Decodes and validates a report.
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
    let mut it = body.chunks_exact(8).map(|c| {
        let mut w = [0u8; 8];
        w.copy_from_slice(c);
        u64::from_le_bytes(w)
    });
    let mut next = || it.next().unwrap_or(0);
    let f3 = |n: &mut dyn FnMut() -> u64| {
        [
            f64::from_bits(n()),
            f64::from_bits(n()),
            f64::from_bits(n()),
        ]
    };
    let (kind, t_ns, seq, site) = (next(), next(), next(), next());
    let pos = f3(&mut next);
    let rot = [
        f64::from_bits(next()),
        f64::from_bits(next()),
        f64::from_bits(next()),
        f64::from_bits(next()),
    ];
    let vel = f3(&mut next);
    let ang_mom = f3(&mut next);
    let accel = f3(&mut next);
    let mut included = [0.0; coop_rt::msg::INCLUDED_SITES];
    for v in included.iter_mut() {
        *v = f64::from_bits(next());
    }
    let force = f3(&mut next);
    let point = f3(&mut next);
    let depth = f64::from_bits(next());
    let touching = next();
    let r = SiteReport {
        kind,
        t_ns,
        seq,
        site,
        pos,
        rot,
        vel,
        ang_mom,
        accel,
        included,
        force,
        point,
        depth,
        touching,
    };
    r.report().ok_or(DecodeError::Invalid)?;
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> SiteReport {
        let mut r = SiteReport {
            kind: 1,
            t_ns: 5,
            seq: 9,
            site: 1,
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
        assert_eq!(decode(&bytes), Ok(r));
        let mut v2 = bytes.clone();
        v2[0] = 2;
        assert_eq!(decode(&v2), Err(DecodeError::Version { found: 2 }));
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
        // Flipping any single byte never panics and never yields a different valid report silently
        // for the header fields' kind/site.
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0xff;
            let _ = decode(&b);
        }
    }
}
