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
//!   Contact is judged in the phase's window. So is the object's motion (`object_moves_m`,
//!   `lifted_m`) at a site whose user is among the phase's actors (its `contact` users) or that has
//!   no actors; at an *observer* site (another user acts) the motion may show as late as the
//!   earliest that site can know of it: the window's end plus the largest one-way delay, its
//!   jitter and the slowest actor's report period ([`observer_lag_s`]). No site can see a far
//!   user's push before the push's news arrives: at a constant 500 ms the paper task's push ends
//!   its window 175 ms after user 1's tool meets the disk, 325 ms before any method can tell
//!   user 2. The reference run (one world) has no observers. A phase that did not happen says
//!   why: its first failed check, what it measured against the phase's threshold, and when
//!   ([`PhaseMiss`]).
//! - **Co-contact divergence**: the divergence over only the samples at which two or more users
//!   touch the object (each site's `touching` flag: its own user on its own copy) — when the copies
//!   disagreeing is felt as two users pulling at different objects. NaN if that never happens.
//! - **Displayed-force steps**: per site, the largest change of the desired force F_h from one servo
//!   tick to the next, and how many ticks changed it by more than the just-noticeable difference
//!   ([`force_jnd_n`]), counted by the simulator at every servo tick. Contact onsets count too (the
//!   reference run shows how many the task itself has).
//! - **Display**: per site, the servo ticks at which the display's step limiter held the force
//!   back, and the most energy the display's deviation from the simulated contact ever had put
//!   into the user (the passivity observer's figure, [`crate::display`]; ≤ 0 is passive).
//! - **Correction energy**: per site, the energy its copy gained from corrections — the positive
//!   part of each adoption's (paper) or rollback's (timewarp) change of mechanical energy, summed.
//! - **Bounded corrections**: per site, the corrections the no-gain bound ([`crate::method::tank`]) scaled
//!   back because they would have given the copy energy no user put in, and the energy it took out.
//! - **Energy beyond the users' work**: the most any copy's translational energy (½ m v² plus
//!   gravity's potential, from the trace) ever exceeded its start by more than every user's positive
//!   work on every copy ([`crate::method::EnergyAccount::users_positive_j`], summed over the sites:
//!   all the energy the users can have given, at any site). Positive only if a copy gained energy no
//!   user put in; passivity's figure, checked on every sweep run.
//! - **Rollbacks**: per site, rollbacks and re-simulated ticks per simulated second; over all
//!   sites, the 99th percentile of rollback depth (from [`crate::histogram::DepthHistogram`]) and
//!   confirmed-state hash mismatches. 0 for methods that do not roll back.
//! - **Unfelt and phantom contact** (`timewarp`): per site, the confirmed time in which the own
//!   user's tool touched the object while the copy had shown no contact when it first simulated
//!   that moment (the news of a remote push that brought the object came after the user had lived
//!   through it; `timewarp` replays such a contact late to a hand still where it was, never to
//!   one that has moved on, and counts it in [`SiteMetrics::replays`]), and the confirmed
//!   time in which it did not touch while the copy had shown contact (a prediction taken back).
//!   What rolling back costs the user's feel, in ms; 0 for methods that do not roll back.

use crate::body::Vec3;
use crate::scenario::Scenario;
use crate::sim::{RunResult, SiteTrace};

mod phase;

pub use phase::{observer_lag_s, phase_happened, why_missed, Approach, MissedPhase, PhaseMiss};

#[cfg(feature = "serde")]
use serde::Serialize;

pub use crate::perception::{force_jnd_n, FORCE_JND_FLOOR_N, FORCE_JND_FRACTION};

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
    /// Messages put: site reports and tool tracks ([`crate::sim::SiteTrace::puts`]).
    pub puts: [u64; 2],
    /// Their bytes ([`crate::sim::SiteTrace::sent_bytes`]).
    pub sent_bytes: u64,
    /// Largest displayed-force change at an adoption, N.
    pub max_adoption_force_step_n: f64,
    /// Energy this copy gained beyond its own user's and its environment's work, J.
    pub energy_from_others_j: f64,
    /// Work the other users did, each on its own site's copy, J.
    pub others_work_j: f64,
    /// (phase name, happened at this site).
    pub phases: Vec<(String, bool)>,
    /// The phases that did not happen at this site, in the scenario's order, each with its first
    /// failed check ([`PhaseMiss`]).
    pub missed_phases: Vec<MissedPhase>,
    /// The live task's outcome at this site and its participant's grip (`None`: no `[task]`
    /// and a scripted hand).
    pub task: Option<crate::task::TaskFigures>,
    /// Largest displayed-force change from one servo tick to the next, N (NaN: not measured).
    pub max_force_step_n: f64,
    /// Servo ticks whose displayed-force change exceeded the JND ([`force_jnd_n`]).
    pub force_steps_over_jnd: u64,
    /// Energy corrections gave this copy beyond what the forces of the corrected history did
    /// (positive parts summed), J (NaN: not known): what no user and no wall put in.
    pub correction_energy_j: f64,
    /// Mechanical-energy change at corrections, positive parts summed, J (NaN: not known): with
    /// a remote push learned late, the energy that push gave the object.
    pub correction_energy_gross_j: f64,
    /// Servo ticks at which the display's step limiter held the force back ([`crate::display`]).
    pub display_limited_ticks: u64,
    /// The largest displayed-force step beyond the displayed object's own contact change, N (NaN:
    /// not measured, or the display stages are off).
    pub max_correction_force_step_n: f64,
    /// The most energy the display's deviation from the simulated contact ever had injected into
    /// the user, J (0: never any; NaN: not measured, or the display stages are off).
    pub display_energy_max_j: f64,
    /// Corrections the no-gain bound scaled back.
    pub bounded_corrections: usize,
    /// Energy the no-gain bound took out of corrections, J (NaN: not known).
    pub bounded_energy_j: f64,
    /// Rollbacks this site made.
    pub rollbacks: u64,
    /// Ticks this site re-simulated.
    pub resimulated_ticks: u64,
    /// Confirmed time in which this site's user touched the object but its copy had shown no
    /// contact live, ms (0 for methods that do not roll back).
    pub unfelt_contact_ms: f64,
    /// Confirmed time in which this site's user did not touch the object but its copy had shown
    /// contact live (a prediction the confirmed history took back), ms.
    pub phantom_contact_ms: f64,
    /// Missed contacts replayed to this site's user from the confirmed history.
    pub replays: u64,
    /// The largest local lag of this site's own tool, ms (`timewarp`: see
    /// [`crate::method::timewarp::LOCAL_LAG_SHARE`]; 0 for other methods)...
    pub local_lag_max_ms: f64,
    /// ... and the time its tool was lagged, s.
    pub lagged_s: f64,
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
    /// Largest inter-site divergence while two or more users touch the object, m (NaN: never).
    pub co_contact_divergence_max_m: f64,
    /// RMS inter-site divergence while two or more users touch the object, m (NaN: never).
    pub co_contact_divergence_rms_m: f64,
    /// Samples at which two or more users touch the object.
    pub co_contact_samples: usize,
    /// Task phases that happened, summed over sites.
    pub phases_passed: usize,
    /// Task phases to check, summed over sites.
    pub phases_total: usize,
    /// The largest displayed-force step of any site, N (NaN: not measured).
    pub max_force_step_n: f64,
    /// Displayed-force steps over the JND, all sites.
    pub force_steps_over_jnd: u64,
    /// Energy corrections gave the copies beyond the forces' work, all sites, J (NaN: not known).
    pub correction_energy_j: f64,
    /// Mechanical-energy change at corrections, all sites, J (NaN: not known).
    pub correction_energy_gross_j: f64,
    /// Servo ticks at which a display's step limiter held the force back, all sites.
    pub display_limited_ticks: u64,
    /// The largest displayed-force step beyond a displayed object's own contact change, any site,
    /// N (NaN: not measured).
    pub max_correction_force_step_n: f64,
    /// The most energy any site's display deviation had injected into its user, J (NaN: not
    /// measured).
    pub display_energy_max_j: f64,
    /// Corrections the no-gain bound scaled back, all sites.
    pub bounded_corrections: usize,
    /// Energy the no-gain bound took out of corrections, all sites, J (NaN: not known).
    pub bounded_energy_j: f64,
    /// The most a copy's translational energy exceeded its start beyond all users' positive work,
    /// J (≤ 0: passive).
    pub energy_beyond_users_j: f64,
    /// The farthest any copy's centre was from the reference object's at the same time, m.
    pub farthest_from_reference_m: f64,
    /// Rollbacks per simulated second of the busiest site.
    pub rollbacks_per_s: f64,
    /// Re-simulated ticks per simulated second of the busiest site.
    pub resimulated_ticks_per_s: f64,
    /// 99th percentile of rollback depth over all sites' rollbacks, ticks (upper edge of its
    /// histogram bin, at most the deepest; 0: none).
    pub rollback_depth_p99_ticks: u64,
    /// The deepest rollback of any site, ticks.
    pub rollback_depth_max_ticks: u64,
    /// Confirmed-state hash mismatches, all sites.
    pub hash_mismatches: u64,
    /// Confirmed states adopted from a site before this one (`timewarp`) after they differed, all sites.
    pub adopted_states: u64,
    /// Contact a user was never shown live though the confirmed history has it, summed over the
    /// sites, ms ([`SiteMetrics::unfelt_contact_ms`]).
    pub unfelt_contact_ms: f64,
    /// Contact a user was shown live that the confirmed history took back, summed over the sites,
    /// ms ([`SiteMetrics::phantom_contact_ms`]).
    pub phantom_contact_ms: f64,
    /// Missed contacts replayed to the users, all sites ([`SiteMetrics::replays`]).
    pub replays: u64,
    /// The largest local lag of any site's own tool, ms ([`SiteMetrics::local_lag_max_ms`]).
    pub local_lag_max_ms: f64,
    /// Per site.
    pub sites: Vec<SiteMetrics>,
}

/// The inter-site divergence of `r` at sample `k`: the largest distance between any two sites'
/// copies of any object, m.
pub fn divergence(r: &RunResult, k: usize) -> f64 {
    let objects = r.sites.first().map_or(1, |s| s.objects());
    (0..objects)
        .map(|o| object_divergence(r, o, k))
        .fold(0.0, f64::max)
}

/// The largest distance between any two sites' copies of object `o` at sample `k`, m.
pub fn object_divergence(r: &RunResult, o: usize, k: usize) -> f64 {
    let mut d: f64 = 0.0;
    for (i, a) in r.sites.iter().enumerate() {
        for b in &r.sites[i + 1..] {
            d = d.max((a.object_pos(o)[k] - b.object_pos(o)[k]).norm());
        }
    }
    d
}

/// `x` if positive, else 0; NaN stays NaN (not known).
fn positive_part(x: f64) -> f64 {
    if x.is_nan() || x > 0.0 {
        x
    } else {
        0.0
    }
}

/// Sums, but NaN if any term is (unknown stays unknown).
fn sum_known(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(0.0, |a, x| a + x)
}

/// The largest, but NaN if any is.
fn max_known(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(0.0, |a: f64, x| {
        if a.is_nan() || x.is_nan() {
            f64::NAN
        } else {
            a.max(x)
        }
    })
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
    let AfterContact {
        last_contact,
        settled,
        from,
        after,
    } = after_contact(scenario, run, &divs);
    let all_users_j: f64 = run.energy.iter().map(|e| e.own_j).sum();
    let sites: Vec<SiteMetrics> = run
        .sites
        .iter()
        .enumerate()
        .map(|(i, s)| site_metrics(scenario, run, reference, all_users_j, i, s))
        .collect();
    let (co, co_max, co_rms) = co_contact(run, &divs);
    let mut depths = crate::histogram::DepthHistogram::default();
    let mut depth_max = 0;
    let mut mismatches = 0;
    let mut adopted = 0;
    for st in run.rollback.iter().flatten() {
        adopted += st.adopted_states;
        depths.merge(&st.depths);
        depth_max = depth_max.max(st.max_depth);
        mismatches += st.hash_mismatches;
    }
    let per_s = |x: u64| x as f64 / scenario.duration_s;
    Metrics {
        method: run.mode.name().to_owned(),
        co_contact_divergence_max_m: co_max,
        co_contact_divergence_rms_m: co_rms,
        co_contact_samples: co.len(),
        phases_passed: sites
            .iter()
            .map(|s| s.phases.iter().filter(|(_, ok)| *ok).count())
            .sum(),
        phases_total: sites.iter().map(|s| s.phases.len()).sum(),
        max_force_step_n: max_known(sites.iter().map(|s| s.max_force_step_n)),
        force_steps_over_jnd: sites.iter().map(|s| s.force_steps_over_jnd).sum(),
        correction_energy_j: sum_known(sites.iter().map(|s| s.correction_energy_j)),
        correction_energy_gross_j: sum_known(sites.iter().map(|s| s.correction_energy_gross_j)),
        display_limited_ticks: sites.iter().map(|s| s.display_limited_ticks).sum(),
        max_correction_force_step_n: max_known(sites.iter().map(|s| s.max_correction_force_step_n)),
        display_energy_max_j: max_known(sites.iter().map(|s| s.display_energy_max_j)),
        bounded_corrections: sites.iter().map(|s| s.bounded_corrections).sum(),
        bounded_energy_j: sum_known(sites.iter().map(|s| s.bounded_energy_j)),
        energy_beyond_users_j: energy_beyond_users(scenario, run),
        farthest_from_reference_m: sites
            .iter()
            .map(|s| s.error_vs_reference_max_m)
            .fold(0.0, f64::max),
        rollbacks_per_s: sites.iter().map(|s| per_s(s.rollbacks)).fold(0.0, f64::max),
        resimulated_ticks_per_s: sites
            .iter()
            .map(|s| per_s(s.resimulated_ticks))
            .fold(0.0, f64::max),
        rollback_depth_p99_ticks: depths.quantile(0.99).map_or(0, |d| d.min(depth_max)),
        rollback_depth_max_ticks: depth_max,
        hash_mismatches: mismatches,
        adopted_states: adopted,
        unfelt_contact_ms: sites.iter().map(|s| s.unfelt_contact_ms).sum(),
        phantom_contact_ms: sites.iter().map(|s| s.phantom_contact_ms).sum(),
        replays: sites.iter().map(|s| s.replays).sum(),
        local_lag_max_ms: sites.iter().map(|s| s.local_lag_max_ms).fold(0.0, f64::max),
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

/// When contacts end and the copies can agree again, and the divergence from then on.
struct AfterContact {
    /// When the last contact ended, s.
    last_contact: f64,
    /// When the last-touching site's copy came to rest, s.
    settled: f64,
    /// From when the divergence after contact is measured, s.
    from: f64,
    /// The largest divergence from then on, m (NaN if that moment never came).
    after: f64,
}

/// The moment every site can know the final state after the last contact (the module docs'
/// divergence "after contacts end"), and the largest divergence from then on; `divs` is the
/// divergence at each sample.
fn after_contact(scenario: &Scenario, run: &RunResult, divs: &[f64]) -> AfterContact {
    let samples = run.t.len();
    let last_k = (0..samples)
        .rev()
        .find(|&k| run.sites.iter().any(|s| s.touching[k]));
    let last_contact = last_k.map_or(0.0, |k| run.t[k]);
    // The site whose user touched last holds the final change; when does its copy come to rest?
    let author = last_k
        .and_then(|k| run.sites.iter().position(|s| s.touching[k]))
        .unwrap_or(0);
    let dt = 1.0 / scenario.sample_rate_hz;
    let at = &run.sites[author];
    let settled = (1..samples)
        .rev()
        .find(|&k| {
            (0..at.objects()).any(|o| {
                let pos = at.object_pos(o);
                (pos[k] - pos[k - 1]).norm() / dt > 1e-3
            })
        })
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
    AfterContact {
        last_contact,
        settled,
        from,
        after,
    }
}

/// Site `i`'s figures (`s`, its trace in `run`); `all_users_j` is every user's work on its own
/// site's copy, summed.
fn site_metrics(
    scenario: &Scenario,
    run: &RunResult,
    reference: &RunResult,
    all_users_j: f64,
    i: usize,
    s: &SiteTrace,
) -> SiteMetrics {
    let samples = run.t.len();
    // Every object's error, the worst at each sample.
    let errs = (0..samples).map(|k| {
        let err = |o: usize| (s.object_pos(o)[k] - reference.sites[i].object_pos(o)[k]).norm();
        // (From the first object's: a NaN error stays NaN.)
        (1..s.objects()).fold(err(0), |a, o| a.max(err(o)))
    });
    let adoptions: Vec<_> = run.adoptions.iter().filter(|a| a.site == i).collect();
    let e = run.energy[i];
    let (e0, e1) = run.mech_energy[i];
    let steps = run.force_steps.get(i).copied().unwrap_or_default();
    let tw = run.rollback.get(i).copied().flatten().unwrap_or_default();
    let ms = |ticks: u64| ticks as f64 * 1e3 / scenario.site[i].physics_rate_hz;
    let misses: Vec<Option<PhaseMiss>> = scenario
        .phase
        .iter()
        .map(|p| why_missed(scenario, run, i, p))
        .collect();
    SiteMetrics {
        name: scenario.site[i].name.clone(),
        error_vs_reference_rms_m: rms(errs.clone()),
        error_vs_reference_max_m: errs.fold(0.0, f64::max),
        force_tracking_rms_n: rms((0..samples).map(|k| (s.f_desired[k] - s.f_measured[k]).norm())),
        adoptions: adoptions.len(),
        puts: s.puts,
        sent_bytes: s.sent_bytes,
        max_adoption_force_step_n: adoptions.iter().map(|a| a.force_step_n).fold(0.0, f64::max),
        energy_from_others_j: (e1 - e0) - e.own_j - e.env_j - e.objects_j,
        others_work_j: if run.mode == crate::sim::Mode::Reference {
            0.0
        } else {
            all_users_j - e.own_j
        },
        phases: scenario
            .phase
            .iter()
            .zip(&misses)
            .map(|(p, miss)| (p.name.clone(), miss.is_none()))
            .collect(),
        missed_phases: scenario
            .phase
            .iter()
            .zip(misses)
            .filter_map(|(p, miss)| {
                miss.map(|miss| MissedPhase {
                    phase: p.name.clone(),
                    miss,
                })
            })
            .collect(),
        task: run.tasks.get(i).and_then(|t| t.figures(run.task)),
        max_force_step_n: if steps.servo_ticks == 0 {
            f64::NAN
        } else {
            steps.max_step_n
        },
        force_steps_over_jnd: steps.over_jnd,
        correction_energy_j: sum_known(
            adoptions
                .iter()
                .map(|a| positive_part(a.energy_j - a.work_j)),
        ),
        correction_energy_gross_j: sum_known(adoptions.iter().map(|a| positive_part(a.energy_j))),
        display_limited_ticks: steps.display.ticks_limited,
        max_correction_force_step_n: if steps.servo_ticks == 0 || !scenario.display.enabled {
            f64::NAN
        } else {
            steps.display.max_correction_step_n
        },
        display_energy_max_j: if steps.servo_ticks == 0 || !scenario.display.enabled {
            f64::NAN
        } else {
            steps.display.max_energy_j
        },
        bounded_corrections: adoptions.iter().filter(|a| a.clipped_j > 0.0).count(),
        bounded_energy_j: sum_known(adoptions.iter().map(|a| a.clipped_j)),
        rollbacks: tw.rollbacks,
        resimulated_ticks: tw.resimulated_ticks,
        unfelt_contact_ms: ms(tw.unfelt_contact_ticks),
        phantom_contact_ms: ms(tw.phantom_contact_ticks),
        replays: tw.replays,
        local_lag_max_ms: ms(tw.max_local_lag_ticks),
        lagged_s: ms(tw.lagged_ticks) / 1e3,
    }
}

/// The samples at which two or more users touch an object (each site's flag is its own user's
/// contact), and the largest and RMS divergence over them (NaN: never).
fn co_contact(run: &RunResult, divs: &[f64]) -> (Vec<usize>, f64, f64) {
    let samples = run.t.len();
    // Co-contact: two or more users touching (each site's flag is its own user's contact).
    let co: Vec<usize> = (0..samples)
        .filter(|&k| run.sites.iter().filter(|s| s.touching[k]).count() >= 2)
        .collect();
    let (co_max, co_rms) = if co.is_empty() {
        (f64::NAN, f64::NAN)
    } else {
        (
            co.iter().map(|&k| divs[k]).fold(0.0, f64::max),
            rms(co.iter().map(|&k| divs[k])),
        )
    };
    (co, co_max, co_rms)
}

/// See the module docs ("energy beyond the users' work").
fn energy_beyond_users(scenario: &Scenario, run: &RunResult) -> f64 {
    let world = scenario.world();
    let e = |k: usize, pos: Vec3, vel: Vec3| {
        let m = world.bodies[k].mass.mass_kg;
        0.5 * m * vel.norm_squared() - m * world.gravity.dot(&pos)
    };
    let given: f64 = run.energy.iter().map(|a| a.users_positive_j).sum();
    let starts = scenario.start_states();
    let e0 = (1..starts.len()).fold(e(0, starts[0].pos, starts[0].vel), |a, k| {
        a + e(k, starts[k].pos, starts[k].vel)
    });
    // The traces hold no spin: an object started spinning may turn it into motion (a collision,
    // friction), which is energy it was given at the start, not beyond the users' work.
    let spin: f64 = starts
        .iter()
        .zip(world.bodies())
        .map(|(s, b)| s.kinetic_energy(&b.mass) - 0.5 * b.mass.mass_kg * s.vel.norm_squared())
        .filter(|&j| j > 0.0)
        .sum();
    let e0 = if spin > 0.0 { e0 + spin } else { e0 };
    run.sites
        .iter()
        .flat_map(|s| {
            (0..s.obj_pos.len()).map(move |i| {
                s.others
                    .iter()
                    .enumerate()
                    .fold(e(0, s.obj_pos[i], s.obj_vel[i]), |a, (k, o)| {
                        a + e(k + 1, o.pos[i], o.vel[i])
                    })
            })
        })
        .map(|total| total - e0 - given)
        .fold(f64::NEG_INFINITY, f64::max)
}
