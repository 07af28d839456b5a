//! Figures the `sim` subcommands share (a leaf: it imports nothing of the crate, so the
//! subcommands' modules below `sim` never import one another through it).

/// Payload kbit/s of `bytes` over `duration_s`.
pub fn sent_kbit_s(bytes: u64, duration_s: f64) -> f64 {
    bytes as f64 * 8e-3 / duration_s.max(1e-9)
}

/// Whether every site of `m` saw its live task done, and when the last did, s (NaN: not done
/// at every site): a trial's outcome and completion time.
pub fn task_completion(m: &coop_model::metrics::Metrics) -> (bool, f64) {
    let done = !m.sites.is_empty()
        && m.sites
            .iter()
            .all(|s| s.task.as_ref().is_some_and(|t| t.outcome == "done"));
    let time = if done {
        m.sites
            .iter()
            .filter_map(|s| s.task.as_ref().map(|t| t.time_s))
            .fold(f64::NEG_INFINITY, f64::max)
    } else {
        f64::NAN
    };
    (done, time)
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
