//! A rolling-back method's figures on a station, declared once: the physics process publishes them
//! in the control block ([`RollbackShared`], relaxed stores, physics the one writer), `station
//! status`, the session table and the tests read them back as [`RollbackFigures`], and one
//! [`Display`](std::fmt::Display) prints them. A figure added to the list below is published, read,
//! serialized and printed with no other list to keep in step.

use crate::sync::{AtomicU64, Ordering};
use coop_model::method::RollbackStats;

/// Declares each figure once, with its doc: the shared block's atomic, the plain figure, and the
/// load and store between them (in declaration order: the shared block's layout).
macro_rules! rollback_figures {
    ($($(#[$doc:meta])* $name:ident,)*) => {
        /// What physics writes of a rolling-back method (`coop_model::method::RollbackStats`) and
        /// of the tool tracks it exchanges: relaxed stores by physics, the one writer.
        #[derive(Debug, Default)]
        #[repr(C)]
        pub struct RollbackShared {
            $($(#[$doc])* pub $name: AtomicU64,)*
        }

        /// The figures of [`RollbackShared`], read at one moment (each figure relaxed: two may be
        /// a step apart).
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
        #[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
        pub struct RollbackFigures {
            $($(#[$doc])* pub $name: u64,)*
        }

        impl RollbackShared {
            /// Every figure now.
            pub fn load(&self) -> RollbackFigures {
                RollbackFigures {
                    $($name: self.$name.load(Ordering::Relaxed),)*
                }
            }

            /// Figures numbered in declaration order by `f` (a test's distinct values).
            #[cfg(test)]
            fn numbered(mut f: impl FnMut() -> u64) -> RollbackFigures {
                RollbackFigures {
                    $($name: f(),)*
                }
            }

            /// Publishes every figure (physics, the one writer).
            // REAL-TIME: relaxed stores only: no allocation, no lock, no syscall.
            pub fn store(&self, f: &RollbackFigures) {
                $(self.$name.store(f.$name, Ordering::Relaxed);)*
            }
        }
    };
}

rollback_figures! {
    /// Rollbacks (restores and re-simulations).
    rollbacks,
    /// Ticks re-simulated in all.
    resimulated_ticks,
    /// The deepest rollback, ticks.
    max_depth,
    /// The 99th percentile of rollback depth, ticks (0: none yet).
    depth_p99,
    /// Received positions older than the horizon (could not be undone).
    fallbacks,
    /// Confirmed-frontier hashes compared with a sender's.
    hash_checks,
    /// ... that differed: the sites' confirmed states are not the same bits.
    hash_mismatches,
    /// Confirmed states adopted from a site before this one whose confirmed history differed.
    adopted_states,
    /// Remote tool tracks taken from the ring.
    tracks_received,
    /// ... that did not convert (a foreign writer of the ring), or named this site.
    tracks_rejected,
    /// Own tracks not pushed: the ring to the network was full.
    track_drops,
    /// Physics periods that stepped more than one tick to stay on the session's grid.
    late_periods,
    /// Ticks of the session's grid stepped.
    ticks,
    /// Confirmed ticks the own tool touched the object in but had not when first simulated
    /// (contact the user was never shown).
    unfelt_contact_ticks,
    /// Confirmed ticks the own tool did not touch the object in but had when first simulated
    /// (contact shown to the user that the confirmed history took back).
    phantom_contact_ticks,
    /// Missed own contacts replayed to the user from the confirmed history.
    replays,
    /// The grid tick this physics process joined at (0: with the session, at its start; later:
    /// a restarted or late one, where the session was).
    joined_tick,
    /// The own tool's local lag now, ticks (`timewarp`: its positions enter the physics this late
    /// while it and another site's are near the object).
    local_lag_ticks,
    /// Ticks stepped with the own tool lagged.
    lagged_ticks,
    /// How late the other sites' tools are played now, ticks, the largest over them (`coupled`:
    /// its adaptive jitter buffer; rounded up; 0 under other methods).
    playout_ticks,
    /// The reports each own track carries again now (`timewarp`: sized by the loss the receivers
    /// measure and the gaps they ask for; 0 under other methods).
    redundancy,
    /// With a perceptual deadband (`[timewarp.deadband]`): the own ticks stepped...
    deadband_ticks,
    /// ... and the own positions sent (the others were held).
    deadband_samples,
}

impl RollbackShared {
    /// The figures, or `None` if physics never stepped on the session's grid (a method without
    /// one, or not started yet).
    pub fn figures(&self) -> Option<RollbackFigures> {
        let f = self.load();
        (f.ticks > 0).then_some(f)
    }
}

impl RollbackFigures {
    /// Takes the method's own figures from `st` (the rest are physics' and stay as they are).
    // REAL-TIME: copies only.
    pub fn take_method(&mut self, st: &RollbackStats) {
        self.rollbacks = st.rollbacks;
        self.resimulated_ticks = st.resimulated_ticks;
        self.max_depth = st.max_depth;
        self.depth_p99 = st.depths.quantile(0.99).unwrap_or(0);
        self.fallbacks = st.fallbacks;
        self.hash_checks = st.hash_checks;
        self.hash_mismatches = st.hash_mismatches;
        self.adopted_states = st.adopted_states;
        self.unfelt_contact_ticks = st.unfelt_contact_ticks;
        self.phantom_contact_ticks = st.phantom_contact_ticks;
        self.replays = st.replays;
        self.local_lag_ticks = st.local_lag_ticks;
        self.lagged_ticks = st.lagged_ticks;
        self.redundancy = st.redundancy_reports;
        self.deadband_ticks = st.deadband_ticks;
        self.deadband_samples = st.deadband_samples;
    }
}

impl std::fmt::Display for RollbackFigures {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "rollback: {} ticks (joined at {}), {} rollbacks ({} ticks re-simulated, depth max {} p99 {}), {} fallbacks past the horizon, hash checks {} mismatches {}, {} confirmed states adopted; tool tracks: took {} (rejected {}), dropped {} own; {} late periods caught up; own contact never shown live {} ticks (replayed late {} times), shown and taken back {} ticks; own tool lagged {} ticks now, {} ticks in all",
            self.ticks,
            self.joined_tick,
            self.rollbacks,
            self.resimulated_ticks,
            self.max_depth,
            self.depth_p99,
            self.fallbacks,
            self.hash_checks,
            self.hash_mismatches,
            self.adopted_states,
            self.tracks_received,
            self.tracks_rejected,
            self.track_drops,
            self.late_periods,
            self.unfelt_contact_ticks,
            self.replays,
            self.phantom_contact_ticks,
            self.local_lag_ticks,
            self.lagged_ticks
        )?;
        if self.playout_ticks > 0 {
            write!(f, "; other tools played {} ticks late", self.playout_ticks)?;
        }
        if self.redundancy > 0 {
            write!(
                f,
                "; own tracks carry the last {} reports again",
                self.redundancy
            )?;
        }
        if self.deadband_ticks > 0 {
            write!(
                f,
                "; deadband: {} of {} own positions sent ({:.1} %)",
                self.deadband_samples,
                self.deadband_ticks,
                100.0 * self.deadband_samples as f64 / self.deadband_ticks as f64
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every figure goes through the shared block and back by its own name: a store then a load
    /// gives the same figures (a field the macro missed, or two swapped, would not).
    #[test]
    fn every_figure_round_trips_through_the_shared_block() {
        let shared = RollbackShared::default();
        assert!(shared.figures().is_none(), "no ticks yet: no figures");
        let mut k = 0;
        let f = RollbackShared::numbered(|| {
            k += 1;
            k
        });
        assert!(k > 1 && f.ticks > 0);
        shared.store(&f);
        assert_eq!(shared.load(), f);
        assert_eq!(shared.figures(), Some(f));
        assert_eq!(
            std::mem::size_of::<RollbackShared>(),
            std::mem::size_of::<RollbackFigures>()
        );
    }
}
