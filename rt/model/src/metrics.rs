//! Figures of a run, measured against the reference run of the same scenario.
//!
//! - **Divergence**: at each sample, the largest distance between any two sites' copies of the object.
//!   Reported as max and RMS over the run and max *after contacts end*: from the moment the last user
//!   contact has ended **and** the copy of the site whose user touched last has come to rest (slower
//!   than 1 mm/s for the rest of the run: a released object may still slide or bounce off a wall, which
//!   no dead reckoner foresees), plus the largest network delay and two periods of the slowest report
//!   rate — the earliest moment every site can have heard that final state.
//! - **Error against the reference**: per site, distance of its copy from the shared reference object.
//! - **Force tracking**: per site, RMS of |F_h − F_m| over the run (the controller's error).
//! - **Adoption step**: per site, the largest change of the displayed force at the servo tick after an
//!   adoption.
//! - **Energy from other sites** (passivity check): per site, the mechanical energy its copy gained
//!   beyond its own user's and its environment's work — what reached it from the others (as forces in
//!   naive, as states in paper) — next to the work the other users actually did, each on its own
//!   site's copy. A passive method delivers no more than the others did (less what friction takes).
//!   The reference run shows the integrator's own balance (≈ 0).
//! - **Phases**: per site, whether each task phase of the scenario happened as that site saw it.

use crate::body::Vec3;
use crate::scenario::Scenario;
use crate::sim::RunResult;

#[cfg(feature = "serde")]
use serde::Serialize;

/// Per-site figures.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(Serialize))]
pub struct SiteMetrics {
    /// Site name.
    pub name: String,
    /// RMS distance from the reference object, m.
    pub error_vs_reference_rms_m: f64,
    /// Largest distance from the reference object, m.
    pub error_vs_reference_max_m: f64,
    /// RMS of |F_h − F_m|, N.
    pub force_tracking_rms_n: f64,
    /// Adoptions this site made.
    pub adoptions: usize,
    /// Largest displayed-force change at an adoption, N.
    pub max_adoption_force_step_n: f64,
    /// Energy this copy gained beyond its own user's and its environment's work, J.
    pub energy_from_others_j: f64,
    /// Work the other users did, each on its own site's copy, J.
    pub others_work_j: f64,
    /// (phase name, happened at this site).
    pub phases: Vec<(String, bool)>,
}

/// A run's figures.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(Serialize))]
pub struct Metrics {
    /// `naive`, `paper` or `reference`.
    pub method: String,
    /// Largest inter-site divergence, m.
    pub divergence_max_m: f64,
    /// RMS inter-site divergence, m.
    pub divergence_rms_m: f64,
    /// Largest inter-site divergence after contacts end, m (NaN if they never end within the run).
    pub divergence_after_contact_m: f64,
    /// Inter-site divergence at the end of the run, m.
    pub divergence_final_m: f64,
    /// When the last contact ended, s.
    pub contacts_end_s: f64,
    /// When the last-touching site's copy came to rest, s.
    pub settled_s: f64,
    /// From when `divergence_after_contact_m` is measured, s.
    pub after_contact_from_s: f64,
    /// Messages sent, delivered, lost.
    pub messages: (u64, u64, u64),
    /// Per site.
    pub sites: Vec<SiteMetrics>,
}

fn divergence(r: &RunResult, k: usize) -> f64 {
    let mut d: f64 = 0.0;
    for (i, a) in r.sites.iter().enumerate() {
        for b in &r.sites[i + 1..] {
            d = d.max((a.obj_pos[k] - b.obj_pos[k]).norm());
        }
    }
    d
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

/// Computes the figures of `run` against `reference` (a [`crate::sim::Mode::Reference`] run of the
/// same scenario).
pub fn compute(scenario: &Scenario, run: &RunResult, reference: &RunResult) -> Metrics {
    let samples = run.t.len();
    let divs: Vec<f64> = (0..samples).map(|k| divergence(run, k)).collect();
    let last_k = (0..samples)
        .rev()
        .find(|&k| run.sites.iter().any(|s| s.touching[k]));
    let last_contact = last_k.map_or(0.0, |k| run.t[k]);
    // The site whose user touched last holds the final change; when does its copy come to rest?
    let author = last_k
        .and_then(|k| run.sites.iter().position(|s| s.touching[k]))
        .unwrap_or(0);
    let dt = 1.0 / scenario.sample_rate_hz;
    let pos = &run.sites[author].obj_pos;
    let settled = (1..samples)
        .rev()
        .find(|&k| (pos[k] - pos[k - 1]).norm() / dt > 1e-3)
        .map_or(0.0, |k| run.t[k]);
    let slowest_report = scenario
        .site
        .iter()
        .map(|s| 1.0 / s.report_rate_hz)
        .fold(0.0, f64::max);
    let settle =
        (scenario.network.delay_max_ms + scenario.network.jitter_ms) / 1e3 + 2.0 * slowest_report;
    let from = last_contact.max(settled) + settle;
    // NaN when that moment never came within the run (a user still touching at the end): there is
    // nothing to measure, and 0 would read as "together".
    let after = if run.t.last().is_some_and(|&end| from <= end) {
        (0..samples)
            .filter(|&k| run.t[k] >= from)
            .map(|k| divs[k])
            .fold(0.0, f64::max)
    } else {
        f64::NAN
    };
    let all_users_j: f64 = run.energy.iter().map(|e| e.own_j).sum();
    let sites = run
        .sites
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let errs = (0..samples).map(|k| (s.obj_pos[k] - reference.sites[i].obj_pos[k]).norm());
            let adoptions: Vec<_> = run.adoptions.iter().filter(|a| a.site == i).collect();
            let e = run.energy[i];
            let (e0, e1) = run.mech_energy[i];
            SiteMetrics {
                name: scenario.site[i].name.clone(),
                error_vs_reference_rms_m: rms(errs.clone()),
                error_vs_reference_max_m: errs.fold(0.0, f64::max),
                force_tracking_rms_n: rms(
                    (0..samples).map(|k| (s.f_desired[k] - s.f_measured[k]).norm())
                ),
                adoptions: adoptions.len(),
                max_adoption_force_step_n: adoptions
                    .iter()
                    .map(|a| a.force_step_n)
                    .fold(0.0, f64::max),
                energy_from_others_j: (e1 - e0) - e.own_j - e.env_j,
                others_work_j: if run.mode == crate::sim::Mode::Reference {
                    0.0
                } else {
                    all_users_j - e.own_j
                },
                phases: scenario
                    .phase
                    .iter()
                    .map(|p| (p.name.clone(), phase_happened(scenario, run, i, p)))
                    .collect(),
            }
        })
        .collect();
    Metrics {
        method: run.mode.name().to_owned(),
        divergence_max_m: divs.iter().copied().fold(0.0, f64::max),
        divergence_rms_m: rms(divs.iter().copied()),
        divergence_after_contact_m: after,
        divergence_final_m: divs.last().copied().unwrap_or(0.0),
        contacts_end_s: last_contact,
        settled_s: settled,
        after_contact_from_s: from,
        messages: run.messages,
        sites,
    }
}

fn phase_happened(
    sc: &Scenario,
    run: &RunResult,
    i: usize,
    p: &crate::scenario::PhaseSpec,
) -> bool {
    let me = &sc.site[i].name;
    let s = &run.sites[i];
    let window: Vec<usize> = (0..run.t.len())
        .filter(|&k| run.t[k] >= p.from_s && run.t[k] <= p.to_s)
        .collect();
    let (Some(&first), Some(&last)) = (window.first(), window.last()) else {
        return false;
    };
    if p.contact.contains(me) {
        if !window.iter().any(|&k| s.touching[k]) {
            return false;
        }
        let peak = window
            .iter()
            .map(|&k| s.f_desired[k].norm())
            .fold(0.0, f64::max);
        if peak < p.min_force_n {
            return false;
        }
    }
    if p.no_contact.contains(me) && window.iter().any(|&k| s.touching[k]) {
        return false;
    }
    if (s.obj_pos[last] - s.obj_pos[first]).norm() < p.object_moves_m {
        return false;
    }
    if p.lifted_m > 0.0 {
        let rest = Vec3::from(sc.object.start_m).y;
        let top = window
            .iter()
            .map(|&k| s.obj_pos[k].y)
            .fold(f64::NEG_INFINITY, f64::max);
        if top < rest + p.lifted_m {
            return false;
        }
    }
    true
}
