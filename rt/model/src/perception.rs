//! What a hand can tell apart: the just-noticeable difference of a displayed force, which the
//! display's step limiter keeps under and the metrics count against.

/// Weber fraction of force: a change of the displayed force by more than this fraction of the force
/// is noticeable (about 7 % for forces at the hand; Jones, "Matching forces", 1989; Pang et al. 1991).
pub const FORCE_JND_FRACTION: f64 = 0.07;
/// Below this the fraction is meaningless (near zero force any step would count): a change smaller
/// than 0.05 N is never counted, N.
pub const FORCE_JND_FLOOR_N: f64 = 0.05;

/// The just-noticeable change of a displayed force of `force_n` N: 7 % of it, at least 0.05 N.
pub fn force_jnd_n(force_n: f64) -> f64 {
    (FORCE_JND_FRACTION * force_n.abs()).max(FORCE_JND_FLOOR_N)
}
