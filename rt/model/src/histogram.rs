//! A fixed-size, allocation-free histogram of tick counts (rollback depths), for percentiles.
//!
//! Depths 0 to [`EXACT`] − 1 have a bin each; above, every power-of-two octave is split into
//! [`SUB_BINS`] equal bins, so a depth is known to within 1/[`SUB_BINS`] (12.5 %) of itself. Depths
//! from 2^[`TOP_OCTAVE`] up share the last bin. Recording is a few integer operations: it may run
//! inside the physics tick.

/// Depths below this have a bin each.
pub const EXACT: u64 = 16;
/// Bins per octave above [`EXACT`].
pub const SUB_BINS: u64 = 8;
/// Octaves 2^4 … 2^(TOP_OCTAVE−1) are binned; depths ≥ 2^TOP_OCTAVE (over a million ticks) go
/// into the last bin.
pub const TOP_OCTAVE: u32 = 20;
/// Bins in all.
pub const BINS: usize = EXACT as usize + ((TOP_OCTAVE - 4) as usize) * SUB_BINS as usize + 1;

/// Counts of depths, ticks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DepthHistogram {
    bins: [u64; BINS],
}

impl Default for DepthHistogram {
    fn default() -> Self {
        Self { bins: [0; BINS] }
    }
}

/// The bin of `depth`.
fn bin(depth: u64) -> usize {
    if depth < EXACT {
        return depth as usize;
    }
    let octave = 63 - depth.leading_zeros(); // ≥ 4
    if octave >= TOP_OCTAVE {
        return BINS - 1;
    }
    let sub = (depth >> (octave - 3)) & (SUB_BINS - 1); // the 3 bits below the leading one
    EXACT as usize + (octave - 4) as usize * SUB_BINS as usize + sub as usize
}

/// The largest depth bin `b` holds.
fn upper(b: usize) -> u64 {
    if b < EXACT as usize {
        return b as u64;
    }
    if b == BINS - 1 {
        return u64::MAX;
    }
    let k = (b - EXACT as usize) as u64;
    let octave = 4 + k / SUB_BINS;
    let sub = k % SUB_BINS;
    let width = 1u64 << (octave - 3);
    (1u64 << octave) + (sub + 1) * width - 1
}

impl DepthHistogram {
    /// Counts one depth.
    pub fn record(&mut self, depth: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let b = bin(depth);
        self.bins[b] = self.bins[b].saturating_add(1);
    }

    /// How many depths were counted.
    pub fn count(&self) -> u64 {
        self.bins.iter().sum()
    }

    /// Adds another histogram's counts (e.g. every site's).
    pub fn merge(&mut self, other: &Self) {
        for (a, b) in self.bins.iter_mut().zip(&other.bins) {
            *a = a.saturating_add(*b);
        }
    }

    /// The depth at or below which fraction `q` (0 to 1) of the counted depths lie: the upper edge
    /// of the bin holding that rank (exact below [`EXACT`], at most 12.5 % high above). `None` if
    /// nothing was counted.
    pub fn quantile(&self, q: f64) -> Option<u64> {
        let n = self.count();
        if n == 0 {
            return None;
        }
        // The rank of the q-quantile, 1-based: at least the first, at most the last.
        let rank = ((q.clamp(0.0, 1.0) * n as f64).ceil() as u64).clamp(1, n);
        let mut seen = 0u64;
        for (b, &c) in self.bins.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Some(upper(b));
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_depth_falls_in_a_bin_whose_upper_edge_bounds_it_within_an_eighth() {
        for d in (0..5000u64).chain([65_535, 65_536, 1 << 19, (1 << 20) - 1]) {
            let b = bin(d);
            assert!(b < BINS - 1, "{d}");
            let up = upper(b);
            assert!(up >= d, "depth {d}: bin {b} ends at {up}");
            assert!(up - d <= d / 8, "depth {d}: bin {b} ends at {up}");
            if b > 0 {
                assert!(upper(b - 1) < d, "depth {d} also fits bin {}", b - 1);
            }
        }
        assert_eq!(bin(1 << 20), BINS - 1);
    }

    #[test]
    fn quantiles_follow_the_counts() {
        let mut h = DepthHistogram::default();
        assert_eq!(h.quantile(0.99), None);
        for _ in 0..99 {
            h.record(3);
        }
        h.record(500);
        assert_eq!(h.count(), 100);
        assert_eq!(h.quantile(0.5), Some(3));
        assert_eq!(h.quantile(0.99), Some(3));
        let top = h.quantile(1.0).expect("counted");
        assert!((500..=500 + 500 / 8).contains(&top), "{top}");
        let mut g = DepthHistogram::default();
        g.record(500);
        g.record(500);
        h.merge(&g);
        assert!(h.quantile(0.99).expect("counted") >= 500);
    }
}
