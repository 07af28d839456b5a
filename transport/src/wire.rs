//! The wire format between stations: one encode and one decode per message (`docs/wire.md` is the
//! specification a foreign client can be written from).
//!
//! A site report is `version: u8 = 1`, then the [`SiteReport`] fields in declaration order as
//! little-endian u64/f64, nothing else: exactly [`ENCODED_LEN`] bytes. Decoding checks the version,
//! the length (no truncation, no trailing bytes) and then everything [`SiteReport::report`] checks
//! (finite numbers, unit quaternion, known kind). [`Inbound::check`] adds what only a receiver knows:
//! the site is one of the session's and the one its key names, and its sequence number is newer
//! than any seen from it (duplicates and reordering are refused, never applied twice). Any failure
//! is a typed error and changes nothing.
//!
//! The session's time 0 and clock readings are `version: u8 = 1` then one little-endian u64.

use coop_rt::msg::SiteReport;
use coop_rt::shm::control::Refused;

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

/// Why a receiver refused a message, by counter slot (see `ControlBlock::net_refused`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// It does not decode.
    #[error(transparent)]
    Decode(#[from] DecodeError),
    /// Its site is not one of the session's, or not the one its key names.
    #[error("site {site} is not the sender its key names")]
    Foreign {
        /// The site index in the message.
        site: u64,
    },
    /// A sequence number already seen from this site, or older than the newest seen.
    #[error("sequence {seq} from site {site} is not newer than {newest}")]
    Stale {
        /// The site.
        site: usize,
        /// Its sequence number.
        seq: u64,
        /// The newest seen.
        newest: u64,
    },
}

impl Refusal {
    /// The reason it is counted under (`ControlBlock::network.refused`).
    pub fn reason(&self) -> Refused {
        match self {
            Refusal::Decode(DecodeError::Version { .. }) => Refused::Version,
            Refusal::Decode(DecodeError::Length { .. }) => Refused::Length,
            Refusal::Decode(DecodeError::Invalid) => Refused::Contents,
            Refusal::Foreign { .. } => Refused::Foreign,
            Refusal::Stale { .. } => Refused::Stale,
        }
    }
}

/// A receiver's view of the session: which sites exist, and the newest sequence number seen from
/// each.
#[derive(Debug, Clone)]
pub struct Inbound {
    sites: Vec<String>,
    newest: Vec<Option<u64>>,
}

impl Inbound {
    /// A receiver for a session of these sites (in scenario order).
    pub fn new(sites: Vec<String>) -> Self {
        let n = sites.len();
        Self {
            sites,
            newest: vec![None; n],
        }
    }
    /// The index of a site name.
    pub fn index_of(&self, site: &str) -> Option<usize> {
        self.sites.iter().position(|s| s == site)
    }
    /// Decodes `bytes` received on a key naming `key_site`, and accepts it only if it is that
    /// site's and newer than anything seen from it.
    ///
    /// # Errors
    /// [`Refusal`]; nothing changes then.
    pub fn check(&mut self, key_site: &str, bytes: &[u8]) -> Result<(usize, SiteReport), Refusal> {
        let r = decode(bytes)?;
        let site = self
            .index_of(key_site)
            .filter(|&i| i as u64 == r.site)
            .ok_or(Refusal::Foreign { site: r.site })?;
        if let Some(newest) = self.newest[site] {
            if r.seq <= newest {
                return Err(Refusal::Stale {
                    site,
                    seq: r.seq,
                    newest,
                });
            }
        }
        self.newest[site] = Some(r.seq);
        Ok((site, r))
    }
    /// Forgets a site's sequence numbers (it left the session; a new run of it starts afresh).
    pub fn forget(&mut self, site: usize) {
        if let Some(n) = self.newest.get_mut(site) {
            *n = None;
        }
    }
}

/// Encodes a u64 message (session time 0, clock reading).
pub fn encode_u64(v: u64) -> [u8; 9] {
    let mut out = [0u8; 9];
    out[0] = VERSION;
    out[1..].copy_from_slice(&v.to_le_bytes());
    out
}

/// Decodes a u64 message.
///
/// # Errors
/// Wrong version or length.
pub fn decode_u64(bytes: &[u8]) -> Result<u64, DecodeError> {
    match bytes {
        [VERSION, rest @ ..] if rest.len() == 8 => {
            let mut w = [0u8; 8];
            w.copy_from_slice(rest);
            Ok(u64::from_le_bytes(w))
        }
        [VERSION, ..] => Err(DecodeError::Length { found: bytes.len() }),
        [v, ..] => Err(DecodeError::Version { found: *v }),
        [] => Err(DecodeError::Length { found: 0 }),
    }
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
    let mut included = [0.0; coop_model::MAX_SITES];
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
        assert_eq!(ENCODED_LEN, 289, "docs/wire.md says 289 bytes");
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
        // Flipping any single byte never panics.
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0xff;
            let _ = decode(&b);
        }
    }

    #[test]
    fn a_receiver_refuses_foreign_sites_duplicates_and_reordering() {
        let mut rx = Inbound::new(vec!["a".into(), "b".into()]);
        let mut r = sample(); // site 1 = "b", seq 9
        assert_eq!(rx.check("b", &encode(&r)).map(|x| x.0), Ok(1));
        assert_eq!(
            rx.check("b", &encode(&r)),
            Err(Refusal::Stale {
                site: 1,
                seq: 9,
                newest: 9
            }),
            "a replay"
        );
        r.seq = 8;
        assert_eq!(
            rx.check("b", &encode(&r)).map_err(|e| e.reason()),
            Err(Refused::Stale),
            "reordered"
        );
        r.seq = 10;
        assert_eq!(
            rx.check("a", &encode(&r)),
            Err(Refusal::Foreign { site: 1 }),
            "key names another site"
        );
        assert_eq!(
            rx.check("zz", &encode(&r)).map_err(|e| e.reason()),
            Err(Refused::Foreign),
            "unknown site"
        );
        r.site = 5;
        assert_eq!(
            rx.check("b", &encode(&r)).map_err(|e| e.reason()),
            Err(Refused::Foreign)
        );
        r.site = 1;
        assert_eq!(
            rx.check("b", &[1, 2, 3]).map_err(|e| e.reason()),
            Err(Refused::Length)
        );
        assert!(
            rx.check("b", &encode(&r)).is_ok(),
            "refusals changed nothing: 10 is still new"
        );
        rx.forget(1);
        r.seq = 1;
        assert!(
            rx.check("b", &encode(&r)).is_ok(),
            "a site that left starts afresh"
        );
        assert_eq!(decode_u64(&encode_u64(42)), Ok(42));
        assert_eq!(
            decode_u64(&[2, 0, 0, 0, 0, 0, 0, 0, 0]),
            Err(DecodeError::Version { found: 2 })
        );
        assert_eq!(decode_u64(&[1, 0]), Err(DecodeError::Length { found: 2 }));
    }
}
