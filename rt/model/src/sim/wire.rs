//! What carries a site's puts to the others in the simulator: the stations' codec, or nothing.
//!
//! The model cannot see the stations' wire (it lives in a crate above this one), so the
//! simulator takes it as a [`Wire`]: `coop_transport` implements it with the very encode and
//! decode a station's network process runs, so a simulated run takes what a station's would
//! (quantization, the compact encoding, the checks) and counts the bytes it really put. Tests of
//! the model alone use [`Direct`], which hands each put over as the station's rings would, with
//! no encoding and no bytes.

use crate::drive::Put;
use crate::method::Report;

/// A put as it arrives, and what it cost.
#[derive(Debug, Clone, Copy, PartialEq)]
// NB: moved by value, as `Report` is.
#[allow(clippy::large_enum_variant)]
pub enum Carried {
    /// What the receivers decode (a tool track as [`Report::Tools`]), and the bytes put.
    Taken {
        /// The decoded report.
        report: Report,
        /// Bytes the sender put for it.
        bytes: u64,
    },
    /// A receiver's decoding refused it (it is counted as put, and lost on every link).
    Refused {
        /// Bytes the sender put for it.
        bytes: u64,
    },
}

/// Carries one put from a site to the others.
pub trait Wire {
    /// `put` from `site` at `t_ns` (the sender's clock), as the receivers take it.
    fn carry(&self, site: usize, t_ns: u64, put: &Put) -> Carried;
}

/// The puts handed over as they are, no bytes counted: the model's own tests.
#[derive(Debug, Clone, Copy, Default)]
pub struct Direct;

impl Wire for Direct {
    fn carry(&self, _site: usize, _t_ns: u64, put: &Put) -> Carried {
        let report = match put {
            Put::Report { report, .. } => *report,
            Put::Track(t) => Report::Tools(*t),
        };
        Carried::Taken { report, bytes: 0 }
    }
}
