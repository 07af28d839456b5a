//! Figures the `sim` subcommands share (a leaf: it imports nothing of the crate, so the
//! subcommands' modules below `sim` never import one another through it).

/// Payload kbit/s of `bytes` over `duration_s`.
pub fn sent_kbit_s(bytes: u64, duration_s: f64) -> f64 {
    bytes as f64 * 8e-3 / duration_s.max(1e-9)
}

/// The payload the busiest site of `m` puts, kbit/s over `duration_s`.
pub fn busiest_sent_kbit_s(m: &coop_model::metrics::Metrics, duration_s: f64) -> f64 {
    m.sites
        .iter()
        .map(|s| sent_kbit_s(s.sent_bytes, duration_s))
        .fold(0.0, f64::max)
}

/// `v` with `prec` decimals, or `-` when it is NaN (a figure that was not measured).
pub fn or_dash(v: f64, prec: usize) -> String {
    if v.is_nan() {
        "-".to_owned()
    } else {
        format!("{v:.prec$}")
    }
}
