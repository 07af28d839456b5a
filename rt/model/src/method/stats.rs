//! What a method did, for status, recordings and benchmarks: one figure set per kind of method,
//! read through [`super::Consistency::stats`].

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
    pub depths: crate::histogram::DepthHistogram,
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
