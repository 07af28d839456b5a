//! What an impostor forges: a state of another site that is well formed and plausible, so that
//! only the access control can keep it from a receiver's physics. Shared by the
//! `impostor` fixture (which includes this file with `#[path]`, being built by `coop-tools` too,
//! where this crate is only a dev-dependency) and the tests that look for its traces.

use coop_rt::msg::SiteReport;
use coop_transport::wire;

/// The sequence number an impostor's forged states carry: far above anything a genuine site
/// reaches, so a receiver that took one would refuse the genuine site's next states as old (until
/// it resynchronises) and its recording would show this number.
pub const FORGED_SEQ: u64 = u64::MAX - 1;

/// A well-formed, plausible state of the object from site `index` at `t_ns` (the sender's
/// CLOCK_MONOTONIC), at rest at `pos_m`, numbered [`FORGED_SEQ`], encoded by the project's own
/// [`wire::encode`]: what an impostor speaking for that site would put. It claims
/// that site's user's impulses up to `t_ns` (so a receiver's physics would take it as news) and
/// nobody else's. Everything [`coop_transport::admit`] checks passes when `t_ns` is near the
/// receiver's now and `pos_m` inside the world: only the access control can keep it out.
///
/// # Panics
/// `index` is not below `coop_model::MAX_SITES`.
pub fn forged_state(index: usize, t_ns: u64, pos_m: [f64; 3]) -> Vec<u8> {
    let mut r = SiteReport {
        kind: 1,
        t_ns,
        seq: FORGED_SEQ,
        site: index as u64,
        pos: pos_m,
        rot: [1.0, 0.0, 0.0, 0.0],
        ..SiteReport::default()
    };
    r.included = r.included.map(|_| -1.0);
    r.included[index] = t_ns as f64 * 1e-9;
    wire::encode(&r)
}
