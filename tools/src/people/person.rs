//! One participant as a lab measures it: each paradigm of [`super::lab`] run on the person a
//! seed draws, and reduced to one value per figure (the mean over its trials), the unit a
//! comparison across people counts.

use coop_model::participant::ParticipantSpec;
use serde::Serialize;

use super::lab::{self, DISTANCES_M, WIDTHS_M};
use super::measure::{self, Fit};

/// One participant's reaches in one condition.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PersonCondition {
    /// Distance, m.
    pub d_m: f64,
    /// Target width, m.
    pub w_m: f64,
    /// Index of difficulty log2(D/W + 1), bits.
    pub id_bits: f64,
    /// Mean movement time, s.
    pub mt_s: f64,
    /// Mean peak over mean speed.
    pub peak_over_mean: f64,
    /// Mean time to peak over the movement time.
    pub time_to_peak_share: f64,
    /// Effective width 4.133·SD of the end points along the reach, m.
    pub effective_width_m: f64,
    /// Share of end points outside the target along the reach.
    pub outside_share: f64,
}

/// One participant as measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Person {
    /// The seed it was drawn from.
    pub seed: u64,
    /// Its drawn parameters.
    pub drawn: ParticipantSpec,
    /// Fitts' law fitted to its mean movement time per condition.
    pub fitts: Fit,
    /// Its reaches, per condition.
    pub conditions: Vec<PersonCondition>,
    /// Mean over all its reaches.
    pub peak_over_mean: f64,
    /// Mean over all its reaches.
    pub time_to_peak_share: f64,
    /// Share of all its reaches' end points outside the target.
    pub outside_share: f64,
    /// Mean visual reaction, s.
    pub visual_reaction_s: f64,
    /// Mean haptic reaction, s.
    pub haptic_reaction_s: f64,
    /// Mean latency of the grip's rise after a slip, s.
    pub grip_latency_s: f64,
    /// How it held the load.
    pub grip: lab::Grip,
}

/// Measures participant `seed`; with it, its first reach at the middle distance and width.
///
/// # Errors
/// A paradigm's plan the model refuses (a bug).
pub fn measure(seed: u64) -> anyhow::Result<(Person, Vec<measure::Sample>)> {
    let mut conditions = Vec::new();
    let mut all = Vec::new();
    let mut profile = Vec::new();
    for (i, &d) in (0..).zip(&DISTANCES_M) {
        for (j, &w) in (0..).zip(&WIDTHS_M) {
            let block = i * WIDTHS_M.len() as u64 + j;
            let (reaches, first) = lab::reach_block(seed, block, d, w)?;
            if d == DISTANCES_M[1] && w == WIDTHS_M[1] {
                profile = first;
            }
            let f = |g: fn(&lab::Reach) -> f64| -> Vec<f64> { reaches.iter().map(g).collect() };
            let along = f(|r| r.along_m);
            let outside = along.iter().filter(|a| a.abs() > w / 2.0).count();
            conditions.push(PersonCondition {
                d_m: d,
                w_m: w,
                id_bits: (d / w + 1.0).log2(),
                mt_s: measure::mean_sd(&f(|r| r.figures.mt_s)).0,
                peak_over_mean: measure::mean_sd(&f(|r| r.figures.peak_over_mean)).0,
                time_to_peak_share: measure::mean_sd(&f(|r| r.figures.time_to_peak_share)).0,
                effective_width_m: 4.133 * measure::mean_sd(&along).1,
                outside_share: outside as f64 / reaches.len().max(1) as f64,
            });
            all.extend(
                reaches
                    .iter()
                    .map(|r| (r.figures, r.along_m.abs() > w / 2.0)),
            );
        }
    }
    let fitts = measure::fit_line(
        &conditions
            .iter()
            .map(|c| (c.id_bits, c.mt_s))
            .collect::<Vec<_>>(),
    );
    let mean = |xs: Vec<f64>| measure::mean_sd(&xs).0;
    let (grip, latencies) = lab::grip(seed)?;
    let person = Person {
        seed,
        drawn: lab::drawn(seed),
        fitts,
        peak_over_mean: mean(all.iter().map(|r| r.0.peak_over_mean).collect()),
        time_to_peak_share: mean(all.iter().map(|r| r.0.time_to_peak_share).collect()),
        outside_share: all.iter().filter(|r| r.1).count() as f64 / all.len().max(1) as f64,
        conditions,
        visual_reaction_s: mean(lab::visual_reactions(seed)?),
        haptic_reaction_s: mean(lab::haptic_reactions(seed)?),
        grip_latency_s: mean(latencies),
        grip,
    };
    Ok((person, profile))
}
