//! `sim people`: the simulated participants measured the way a psychophysics lab measures people,
//! beside the published human figures the model cites, so a lab can see where a pilot run with
//! them stands in for people and where it does not.
//!
//! Each participant is the person the simulator draws from a seed; it reaches, reacts and grips
//! through the code a site's hand runs, fed scripted views (`lab`). What is measured of it
//! (`measure`) knows nothing of the model: movement times from the recorded speed, the fit of
//! Fitts' law, the profile's shape, the end points' spread, reaction and slip-response latencies,
//! the grip over the load; one value per person and figure (`person`). Each figure is then the
//! participants' mean ± SD, people's figure with its source, and a verdict (`compare`).

mod compare;
mod lab;
mod measure;
mod person;
mod plot;

use std::path::Path;

use anyhow::Context;
use serde::Serialize;

pub use compare::{ConditionRow, Figure, Reference, HUMAN_FITTS_SLOPES};
pub use lab::{Grip, DISTANCES_M, REACHES, REACTION_TRIALS, WIDTHS_M};
pub use measure::{Fit, MeanSd, Sample};
pub use person::{Person, PersonCondition};

/// `sim people`'s default number of participants.
pub const DEFAULT_PARTICIPANTS: u64 = 20;

/// What `sim people` measures and prints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// How many participants (seeds 1 to N).
    pub participants: u64,
    /// Reaches per participant and condition.
    pub reaches_per_condition: usize,
    /// Trials per participant for each reaction and the slip response.
    pub reaction_trials: usize,
    /// The held load, N.
    pub load_n: f64,
    /// The tool–object static friction of the grip paradigm.
    pub friction: f64,
    /// Fitts' law fitted to every participant's mean movement time in every condition.
    pub fitts_pooled: Fit,
    /// The comparison.
    pub figures: Vec<Figure>,
    /// The reaches per condition.
    pub conditions: Vec<ConditionRow>,
    /// Where the participants differ from people, said plainly.
    pub differences: Vec<String>,
    /// Each participant.
    pub people: Vec<Person>,
}

/// Measures participants 1 to `n`, and the first one's reach at the middle distance and width.
///
/// # Errors
/// A paradigm's plan the model refuses (a bug).
pub fn report(n: u64) -> anyhow::Result<(Report, Vec<measure::Sample>)> {
    let mut people = Vec::new();
    let mut profile = Vec::new();
    for seed in 1..=n {
        let (p, first) = person::measure(seed)?;
        if seed == 1 {
            profile = first;
        }
        people.push(p);
    }
    let points: Vec<(f64, f64)> = people
        .iter()
        .flat_map(|p| p.conditions.iter().map(|c| (c.id_bits, c.mt_s)))
        .collect();
    let (figures, conditions) = (compare::figures(&people), compare::conditions(&people));
    Ok((
        Report {
            participants: n,
            reaches_per_condition: REACHES,
            reaction_trials: REACTION_TRIALS,
            load_n: lab::LOAD_N,
            friction: lab::friction(),
            fitts_pooled: measure::fit_line(&points),
            differences: compare::differences(&figures, &conditions),
            figures,
            conditions,
            people,
        },
        profile,
    ))
}

/// The report as `sim people --json` prints it.
///
/// # Errors
/// A paradigm's plan the model refuses (a bug); serialization.
pub fn json(n: u64) -> anyhow::Result<String> {
    Ok(to_json(&report(n)?.0)?)
}

/// `r` as JSON.
fn to_json(r: &Report) -> serde_json::Result<String> {
    serde_json::to_string_pretty(r)
}

/// Prints the comparison.
pub fn print_table(r: &Report) {
    println!(
        "# the model against people: {} simulated participants, seeds 1..={} (each the person a \
         scenario with that seed draws for its first site from the default [site.participant])",
        r.participants, r.participants
    );
    println!(
        "# measured on the participant's target path (what the impedance hand follows), every {} ms; \
         {} reaches per condition and participant, {} trials per reaction and for the slip response",
        lab::TICK_S * 1e3,
        r.reaches_per_condition,
        r.reaction_trials
    );
    println!(
        "{:<34}{:>6}{:>22}{:>12}{:>9}{:>8}  source",
        "figure", "unit", "participants", "people", "verdict", "in"
    );
    println!(
        "{:<34}{:>6}{:>22}{:>12}{:>9}{:>8}",
        "", "", "mean ± SD", "", "", "range"
    );
    for f in &r.figures {
        let prec = f.decimals;
        println!(
            "{:<34}{:>6}{:>22}{:>12}{:>9}{:>8}  {}",
            f.name,
            f.unit,
            f.participants.show(prec),
            f.people_shown,
            f.verdict,
            f.in_range
                .map_or("-".to_owned(), |k| format!("{k}/{}", r.participants)),
            f.source
        );
    }
    println!(
        "# verdict: the participants' mean against people's range (within, below, above), or \
         against a single figure (near: within a factor of two); in range: participants whose \
         own value is within (near) it"
    );
    println!(
        "# reaches: MT from the speed crossing 5 % of its peak to falling below it; Fitts' law \
         fitted per participant to its mean MT per condition; peak / mean speed from rest to rest"
    );
    println!(
        "# grip: a {} N load rising over {} s, friction μ {}; grip averaged over {} s of static \
         hold; latencies from induced slips of {} ms",
        r.load_n,
        lab::LOAD_RISE_S,
        r.friction,
        lab::HOLD_TO_S - lab::HOLD_FROM_S,
        lab::SLIP_S * 1e3
    );
    println!();
    println!("# reaches per condition, mean ± SD across participants; people's W_e is about W");
    println!(
        "{:>7}{:>7}{:>8}{:>18}{:>16}{:>16}{:>16}{:>15}{:>8}",
        "D m", "W m", "ID bit", "MT s", "peak/mean", "t peak / MT", "W_e mm", "W_e / W", "verdict"
    );
    for c in &r.conditions {
        println!(
            "{:>7}{:>7}{:>8.2}{:>18}{:>16}{:>16}{:>16}{:>15}{:>8}",
            c.d_m,
            c.w_m,
            c.id_bits,
            c.mt_s.show(3),
            c.peak_over_mean.show(3),
            c.time_to_peak_share.show(3),
            c.effective_width_mm.show(1),
            c.effective_over_width.show(2),
            c.verdict
        );
    }
    let f = r.fitts_pooled;
    println!(
        "# pooled over participants and conditions: MT = {:.3} + {:.3}·ID s, r² {:.3}",
        f.a, f.b, f.r2
    );
    println!();
    if r.differences.is_empty() {
        println!("# where the participants differ from people: nowhere measured here");
    } else {
        println!("# where the participants differ from people:");
        for d in &r.differences {
            println!("#   {d}");
        }
    }
}

/// The plots' data: the Fitts points and line, and the first participant's reach normalized.
fn plots(r: &Report, profile: &[measure::Sample]) -> (plot::FittsPlot, plot::ProfilePlot) {
    let fitts = plot::FittsPlot {
        points: r
            .people
            .iter()
            .flat_map(|p| p.conditions.iter().map(|c| (c.id_bits, c.mt_s)))
            .collect(),
        fit: r.fitts_pooled,
        human_slopes: HUMAN_FITTS_SLOPES,
        participants: r.participants,
    };
    let reach = measure::measure_reach(profile)
        .map(|f| {
            profile
                .iter()
                .map(|s| ((s.t_s - f.onset_s) / f.mt_s, s.vel.norm() / f.peak_m_s))
                .filter(|q| (-0.15..=1.15).contains(&q.0))
                .collect()
        })
        .unwrap_or_default();
    // Minimum jerk on the same axes: its own 5 % crossings are t/MT = 0 and 1.
    let tail = measure::min_jerk_crossing(measure::ONSET_SHARE);
    let bell = (0..=260)
        .map(|k| {
            let x = -0.15 + k as f64 * 0.005;
            (x, measure::min_jerk_bell(tail + x * (1.0 - 2.0 * tail)))
        })
        .collect();
    let profile = plot::ProfilePlot {
        reach,
        bell,
        title: format!(
            "participant 1's first reach, D {} m, W {} m: speed profile",
            DISTANCES_M[1], WIDTHS_M[1]
        ),
    };
    (fitts, profile)
}

/// Runs `sim people`: measures participants 1 to `n`, prints the comparison (or JSON), and with
/// `out` writes the plots there.
///
/// # Errors
/// Fewer than two participants asked for; a paradigm's plan the model refuses; an unwritable
/// `out`.
pub fn main(n: u64, json: bool, out: Option<&Path>) -> anyhow::Result<()> {
    if n < 2 {
        anyhow::bail!("--participants {n}: at least 2 are needed for a spread between people");
    }
    let (r, profile) = report(n)?;
    if json {
        println!("{}", to_json(&r)?);
    } else {
        print_table(&r);
    }
    if let Some(dir) = out {
        let (fitts, profile) = plots(&r, &profile);
        plot::write(dir, &fitts, &profile)
            .with_context(|| format!("writing the plots into {}", dir.display()))?;
        eprintln!(
            "# plots: fitts.svg, profile.svg (and .png) in {}",
            dir.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use coop_model::participant::ParticipantSpec;

    /// The command's JSON is a function of N alone: the same N gives the same bytes, and another
    /// N other ones (so the comparison can fail).
    #[test]
    fn the_json_is_the_same_for_the_same_participants() {
        let a = json(2).unwrap();
        assert_eq!(a, json(2).unwrap());
        assert_ne!(a, json(3).unwrap());
    }

    /// Seed N is the person the simulator puts at a scenario's first site with seed N.
    #[test]
    fn a_seed_is_the_person_the_simulator_draws() {
        let mut sc = coop_tests::load_scenario("participants/paper.toml");
        assert_eq!(
            sc.site[0].participant,
            ParticipantSpec::default(),
            "the scenario keeps the default population"
        );
        for seed in [1, 2, 17] {
            sc.seed = seed;
            let p = sc.participant(0).expect("a participant");
            assert_eq!(p.person, lab::drawn(seed), "seed {seed}");
        }
    }
}
