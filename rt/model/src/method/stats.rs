//! What a method did, for status, recordings and benchmarks: one figure set per kind of method,
//! read through [`super::Consistency::stats`].

use crate::histogram::DepthHistogram;

use super::track::QUANTUM_M;

/// A method's figures.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
// NB: read by value on the physics loop, where nothing allocates: the rollback depths'
// histogram is copied, not boxed.
#[allow(clippy::large_enum_variant)]
pub enum Stats {
    /// Nothing counted beyond the copy's own (`naive`, `paper`).
    #[default]
    None,
    /// A method that rolls back (`timewarp`).
    Rollback(RollbackStats),
    /// A method that plays the other sites' tools from a jitter buffer (`coupled`): how late it
    /// plays them now, ticks, the largest over them.
    Playout {
        /// Ticks.
        ticks: f64,
    },
}

impl Stats {
    /// The rollback figures, for a method that rolls back (lent: the physics loop reads them every
    /// tick, and they hold a histogram).
    pub fn rollback(&self) -> Option<&RollbackStats> {
        match self {
            Stats::Rollback(s) => Some(s),
            _ => None,
        }
    }

    /// How late the other sites' tools are played, ticks, for a method with a jitter buffer.
    pub fn playout_ticks(&self) -> Option<f64> {
        match self {
            Stats::Playout { ticks } => Some(*ticks),
            _ => None,
        }
    }
}

/// What `timewarp` did: its rollbacks, confirmed-state checks, replays and local lag.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RollbackStats {
    /// Rollbacks (restores and re-simulations).
    pub rollbacks: u64,
    /// Ticks re-simulated in all.
    pub resimulated_ticks: u64,
    /// The deepest rollback, ticks.
    pub max_depth: u64,
    /// Received positions older than the horizon (could not be undone), and gaps of lost
    /// reports that left the horizon before their sender repaired them (never known).
    pub fallbacks: u64,
    /// Confirmed-frontier hashes compared with the sender's.
    pub hash_checks: u64,
    /// ... that differed.
    pub hash_mismatches: u64,
    /// Every rollback's depth, ticks (for percentiles).
    pub depths: DepthHistogram,
    /// Confirmed ticks in which the own tool touched the object but had not when the tick was
    /// first simulated (live): contact the user was never shown, because the news of it (a remote
    /// push that brought the object) came after the user had lived through it.
    pub unfelt_contact_ticks: u64,
    /// Confirmed ticks in which the own tool did not touch the object but had when the tick was
    /// first simulated: contact the user was shown that the confirmed history took back (a
    /// prediction's).
    pub phantom_contact_ticks: u64,
    /// Confirmed states adopted from a site before this one whose confirmed history differed
    /// (after a fallback or a restart): see the module docs.
    pub adopted_states: u64,
    /// Missed contacts replayed to the own user ([`super::Consistency::shown`]).
    pub replays: u64,
    /// The own tool's local lag now, ticks ([`super::timewarp::LOCAL_LAG_SHARE`]).
    pub local_lag_ticks: u64,
    /// ... the largest it has been ...
    pub max_local_lag_ticks: u64,
    /// ... and the ticks simulated with a lag.
    pub lagged_ticks: u64,
    /// With a perceptual deadband (`[timewarp.deadband]`): the own ticks stepped...
    pub deadband_ticks: u64,
    /// ... and the own positions sent (that left the band; the others were held).
    pub deadband_samples: u64,
    /// ... and what the held positions changed in the own tool's contact force and position
    /// (the decoded input against its source).
    pub deadband_error: CodecError,
    /// The reports each own track carries again now (`timewarp`: sized by the loss its receivers
    /// measure and the gaps they ask for, `method/window.rs`; 0 under other methods: `coupled`
    /// sizes its tracks the same way but reports its playout, not this).
    pub redundancy_reports: u64,
}

impl std::fmt::Display for RollbackStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} rollbacks ({} ticks re-simulated, deepest {}), {} fallbacks past the horizon, {} confirmed-state hashes compared, {} mismatched, {} confirmed states adopted; confirmed contact never shown live {} ticks (replayed late {} times), shown live and taken back {} ticks; own tool lagged {} ticks, by up to {}",
            self.rollbacks,
            self.resimulated_ticks,
            self.max_depth,
            self.fallbacks,
            self.hash_checks,
            self.hash_mismatches,
            self.adopted_states,
            self.unfelt_contact_ticks,
            self.replays,
            self.phantom_contact_ticks,
            self.lagged_ticks,
            self.max_local_lag_ticks
        )
    }
}

/// What a perceptual deadband (`timewarp`'s, `[timewarp.deadband]`) changes in what every site is
/// given, tick by tick, as the codec literature
/// measures a codec: its decoded signal against its own source, inside one run. The own tool's
/// contact force on the objects is rendered twice from the same world state (the copy and the
/// tool's friction memory at the start of the tick): at the position every site decodes and
/// steps with (the held one) and at the one measured (the source). A partner holding the same
/// object feels the first through it, where the second was the hand's.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CodecError {
    /// Own ticks compared...
    pub ticks: u64,
    /// ... those in which the tool touched an object in either rendering...
    pub contact_ticks: u64,
    /// ... and of those, the ticks whose two forces were within one JND of the measured one's
    /// (`perception::force_jnd_n`; out of contact both are zero).
    pub contact_within_jnd: u64,
    /// The contact ticks' force differences, hundredths of a JND.
    pub force_centi_jnd: DepthHistogram,
    /// Every tick's distance from the measured position to the held one, quanta (0.01 mm).
    pub position_quanta: DepthHistogram,
    /// ... the largest, quanta.
    pub max_position_quanta: u64,
}

impl CodecError {
    /// Counts one tick: the force difference in JND, if the tool touched; the distance, quanta.
    pub fn record(&mut self, force_jnd: Option<f64>, distance_quanta: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        self.ticks += 1;
        if let Some(e) = force_jnd {
            self.contact_ticks += 1;
            self.contact_within_jnd += u64::from(e <= 1.0);
            // (Rounded up, so that a difference just above one JND is never counted at 100.)
            self.force_centi_jnd
                .record((e * 100.0).ceil().min(1e12) as u64);
        }
        self.position_quanta.record(distance_quanta);
        self.max_position_quanta = self.max_position_quanta.max(distance_quanta);
    }

    /// Adds another site's counts.
    pub fn merge(&mut self, other: &Self) {
        self.ticks += other.ticks;
        self.contact_ticks += other.contact_ticks;
        self.contact_within_jnd += other.contact_within_jnd;
        self.force_centi_jnd.merge(&other.force_centi_jnd);
        self.position_quanta.merge(&other.position_quanta);
        self.max_position_quanta = self.max_position_quanta.max(other.max_position_quanta);
    }

    /// The share of contact ticks within one JND (`None` before any).
    pub fn contact_within_jnd_share(&self) -> Option<f64> {
        (self.contact_ticks > 0).then(|| self.contact_within_jnd as f64 / self.contact_ticks as f64)
    }

    /// The share of all ticks within one JND, out of contact too (`None` before any).
    pub fn within_jnd_share(&self) -> Option<f64> {
        let out_of_contact = self.ticks - self.contact_ticks;
        (self.ticks > 0)
            .then(|| (out_of_contact + self.contact_within_jnd) as f64 / self.ticks as f64)
    }

    /// The contact ticks' 99th percentile difference, JND (at most 12.5 % high: the histogram's
    /// bin edge).
    pub fn contact_p99_jnd(&self) -> Option<f64> {
        self.force_centi_jnd
            .quantile(0.99)
            .map(|c| c as f64 / 100.0)
    }

    /// The 99th percentile and the largest distance from measured to held, m.
    pub fn position_p99_max_m(&self) -> Option<(f64, f64)> {
        let p99 = self.position_quanta.quantile(0.99)?;
        Some((
            p99 as f64 * QUANTUM_M,
            self.max_position_quanta as f64 * QUANTUM_M,
        ))
    }
}
