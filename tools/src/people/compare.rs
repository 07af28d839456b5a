//! The participants against people: each figure's published human value with its source, the
//! verdict on the participants' mean, and, said plainly, where they differ.

use serde::Serialize;

use super::lab::{self, WIDTHS_M};
use super::measure::{self, MeanSd};
use super::person::{Person, PersonCondition};

/// What people do, to hold a figure against.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Reference {
    /// A range people's values lie in.
    Range {
        /// Lower end.
        low: f64,
        /// Upper end.
        high: f64,
    },
    /// A single figure; "near" is within a factor of two of it.
    About {
        /// The figure.
        value: f64,
    },
    /// Nothing to compare with.
    None,
}

impl Reference {
    fn bounds(&self) -> Option<(f64, f64)> {
        match *self {
            Reference::Range { low, high } => Some((low, high)),
            Reference::About { value } => Some((value / 2.0, value * 2.0)),
            Reference::None => None,
        }
    }

    /// The verdict on a mean: within (near) people's figure, or below or above it; "-" with
    /// nothing to compare or nothing measured.
    fn verdict(&self, mean: f64) -> &'static str {
        let Some((lo, hi)) = self.bounds() else {
            return "-";
        };
        if mean.is_nan() {
            "-"
        } else if mean < lo {
            "below"
        } else if mean > hi {
            "above"
        } else if matches!(self, Reference::About { .. }) {
            "near"
        } else {
            "within"
        }
    }
}

/// `v` rounded to `prec` decimals: verdicts are on the figures as printed, so that a mean shown
/// on a range's end is not called outside it.
fn rounded(v: f64, prec: usize) -> f64 {
    let k = 10f64.powi(prec as i32);
    (v * k).round() / k
}

/// One line of the comparison.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figure {
    /// What is measured.
    pub name: String,
    /// The unit of the values here.
    pub unit: &'static str,
    /// Decimals printed (and verdicts taken on).
    pub decimals: usize,
    /// The participants' mean ± SD.
    pub participants: MeanSd,
    /// People's figure.
    pub people: Reference,
    /// People's figure as printed.
    pub people_shown: String,
    /// Where it comes from.
    pub source: &'static str,
    /// The participants' mean against it.
    pub verdict: &'static str,
    /// Participants whose own value is within people's range (or near their figure).
    pub in_range: Option<usize>,
    /// What in the model makes it differ, said when it does.
    pub model: &'static str,
}

/// How a figure is taken and what it is held against.
struct Spec {
    name: String,
    unit: &'static str,
    decimals: usize,
    value: fn(&Person) -> f64,
    people: Reference,
    people_shown: String,
    source: &'static str,
    model: &'static str,
}

impl Spec {
    /// The line of `ps`.
    fn figure(self, ps: &[Person]) -> Figure {
        let values: Vec<f64> = ps.iter().map(self.value).collect();
        let participants = MeanSd::of(&values);
        let shown = |v: f64| rounded(v, self.decimals);
        Figure {
            verdict: self.people.verdict(shown(participants.mean)),
            in_range: self.people.bounds().map(|(lo, hi)| {
                values
                    .iter()
                    .filter(|v| (lo..=hi).contains(&shown(**v)))
                    .count()
            }),
            name: self.name,
            unit: self.unit,
            decimals: self.decimals,
            participants,
            people: self.people,
            people_shown: self.people_shown,
            source: self.source,
            model: self.model,
        }
    }
}

/// The reaches in one condition, across participants.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ConditionRow {
    /// Distance, m.
    pub d_m: f64,
    /// Target width, m.
    pub w_m: f64,
    /// Index of difficulty, bits.
    pub id_bits: f64,
    /// Movement time, s.
    pub mt_s: MeanSd,
    /// Peak over mean speed.
    pub peak_over_mean: MeanSd,
    /// Time to peak over the movement time.
    pub time_to_peak_share: MeanSd,
    /// Effective width, mm.
    pub effective_width_mm: MeanSd,
    /// Effective width over the target's.
    pub effective_over_width: MeanSd,
    /// The verdict on the effective width over the target's, people's being about 1.
    pub verdict: &'static str,
}

/// The slopes of Fitts' law people show in pointing, s/bit: 0.096 for the mouse (Card, English &
/// Burr 1978, with Welford's ID); 0.25 is the reciprocal of the mouse's ISO throughput, 3.7–4.9
/// bit/s (Soukoreff & MacKenzie 2004), which bounds the slope from above (TP = ID_e/MT < 1/b while
/// the intercept is positive and ID_e is near ID) rather than being a fitted slope.
pub const HUMAN_FITTS_SLOPES: (f64, f64) = (0.10, 0.25);

/// The grip people keep above the slip limit, as a fraction: the 10–40 % commonly cited for
/// precision grip. Its source and its base are not verified: Westling & Johansson 1984 define the
/// margin (the grip above the least grip that prevents a slip), later work gives it as a share of
/// the grip held, here it is a share of the slip limit.
pub const HUMAN_GRIP_MARGIN: (f64, f64) = (0.10, 0.40);

/// The comparison of `ps` with people.
pub fn figures(ps: &[Person]) -> Vec<Figure> {
    let mu = lab::friction();
    let (b_lo, b_hi) = HUMAN_FITTS_SLOPES;
    let (m_lo, m_hi) = HUMAN_GRIP_MARGIN;
    // Grip over load is friction's slip ratio 1/μ raised by the margin: people's span at this
    // friction follows from their margin, there is no friction-free figure.
    let (gl_lo, gl_hi) = ((1.0 + m_lo) / mu, (1.0 + m_hi) / mu);
    let range = |low, high| Reference::Range { low, high };
    let specs = [
        Spec {
            name: "Fitts slope b".into(),
            unit: "s/bit",
            decimals: 3,
            value: |p| p.fitts.b,
            people: range(b_lo, b_hi),
            people_shown: "0.10–0.25".into(),
            source: "mouse: 0.096 (Card, English & Burr 1978); 0.25 = 1 / throughput 4 bit/s \
                     (3.7–4.9, Soukoreff & MacKenzie 2004), an upper bound, not a fitted slope",
            model: "",
        },
        Spec {
            name: "Fitts intercept a".into(),
            unit: "s",
            decimals: 3,
            value: |p| p.fitts.a,
            people: Reference::None,
            people_shown: "apparatus".into(),
            source: "depends on the device and the end criterion (MacKenzie 1992)",
            model: "",
        },
        Spec {
            name: "Fitts fit r²".into(),
            unit: "",
            decimals: 3,
            value: |p| p.fitts.r2,
            people: range(0.81, 1.0),
            people_shown: "> 0.81".into(),
            source: "not verified: r above 0.9 in the six studies MacKenzie 1992 reviews (its \
                     table not read)",
            model: "",
        },
        Spec {
            name: "peak / mean speed".into(),
            unit: "",
            decimals: 3,
            value: |p| p.peak_over_mean,
            people: range(1.8, 2.0),
            people_shown: "1.8–2.0".into(),
            source: "minimum jerk's bell: 1.875 (Flash & Hogan 1985); the span about it not \
                     verified",
            model: "",
        },
        Spec {
            name: "time to peak / MT".into(),
            unit: "",
            decimals: 3,
            value: |p| p.time_to_peak_share,
            people: range(0.4, 0.5),
            people_shown: "0.4–0.5".into(),
            source: "about 0.5 at MT near 0.5 s, less when slower (Nagasaki 1989); earlier, the \
                     smaller the target (MacKenzie et al. 1987, not read); 0.4 not verified",
            model: "a reach is one minimum-jerk segment, symmetric whatever the target",
        },
        Spec {
            name: "end points outside W".into(),
            unit: "%",
            decimals: 1,
            value: |p| 100.0 * p.outside_share,
            people: Reference::About { value: 4.0 },
            people_shown: "about 4".into(),
            source: "the miss rate at which W_e = W (MacKenzie 1992)",
            model: "a reach is aimed again, before it ends, until its planned end point lies \
                    within half the target's width",
        },
        Spec {
            name: "visual reaction".into(),
            unit: "ms",
            decimals: 1,
            value: |p| 1e3 * p.visual_reaction_s,
            people: range(150.0, 250.0),
            people_shown: "150–250".into(),
            source: "simple reaction to a light, about 190 ms (Welford 1980, in Kosinski's \
                     review); a choice reaction is slower",
            model: "",
        },
        Spec {
            name: "haptic reaction".into(),
            unit: "ms",
            decimals: 1,
            value: |p| 1e3 * p.haptic_reaction_s,
            people: range(100.0, 150.0),
            people_shown: "100–150".into(),
            source: "touch acts on the fingers' forces 0.1 s after contact (Jenmalm & Johansson \
                     1997); an intended response, no sooner than twice the slip response's 74 ms \
                     (Johansson & Westling 1987)",
            model: "",
        },
        Spec {
            name: "grip rise after a slip".into(),
            unit: "ms",
            decimals: 1,
            value: |p| 1e3 * p.grip_latency_s,
            people: range(60.0, 80.0),
            people_shown: "60–80".into(),
            source: "Johansson & Westling 1984",
            model: "",
        },
        Spec {
            name: "grip margin over slip".into(),
            unit: "%",
            decimals: 1,
            value: |p| 100.0 * p.grip.margin,
            people: range(100.0 * m_lo, 100.0 * m_hi),
            people_shown: format!("{:.0}–{:.0}", 100.0 * m_lo, 100.0 * m_hi),
            source: "commonly cited; not verified in Westling & Johansson 1984, who define the \
                     margin (later work: a share of the grip held, not of the slip limit)",
            model: "",
        },
        Spec {
            name: format!("grip / load (μ {mu}: slips below {:.2})", 1.0 / mu),
            unit: "",
            decimals: 3,
            value: |p| p.grip.grip_over_load,
            people: range(gl_lo, gl_hi),
            people_shown: format!("{gl_lo:.3}–{gl_hi:.3}"),
            source: "(1 + margin) / μ: grip scales with the slip ratio (Johansson & Westling \
                     1984), at this μ with the margin above",
            model: "",
        },
        Spec {
            name: "slips while the load rose".into(),
            unit: "",
            decimals: 1,
            value: |p| p.grip.slips_while_loading as f64,
            people: range(0.0, 0.0),
            people_shown: "none".into(),
            source: "grip rises with the load, in parallel (Johansson & Westling 1984)",
            model: "the grip follows the load it feels, a haptic reaction late; it does not \
                    anticipate the load",
        },
    ];
    specs.into_iter().map(|f| f.figure(ps)).collect()
}

/// The reaches per condition across `ps`.
pub fn conditions(ps: &[Person]) -> Vec<ConditionRow> {
    let about_one = Reference::About { value: 1.0 };
    (0..ps.first().map_or(0, |p| p.conditions.len()))
        .map(|k| {
            let c = ps[0].conditions[k];
            let of = |g: fn(&PersonCondition) -> f64| {
                MeanSd::of(&ps.iter().map(|p| g(&p.conditions[k])).collect::<Vec<_>>())
            };
            let ratio = of(|c| c.effective_width_m / c.w_m);
            ConditionRow {
                d_m: c.d_m,
                w_m: c.w_m,
                id_bits: c.id_bits,
                mt_s: of(|c| c.mt_s),
                peak_over_mean: of(|c| c.peak_over_mean),
                time_to_peak_share: of(|c| c.time_to_peak_share),
                effective_width_mm: of(|c| 1e3 * c.effective_width_m),
                effective_over_width: ratio,
                verdict: about_one.verdict(ratio.mean),
            }
        })
        .collect()
}

/// Where the participants differ from people: each figure outside people's range, a profile
/// whose peak does not move with the target's width, and the conditions whose end-point spread
/// is not near the target's width.
pub fn differences(figures: &[Figure], conditions: &[ConditionRow]) -> Vec<String> {
    let mut out: Vec<String> = figures
        .iter()
        .filter(|f| matches!(f.verdict, "below" | "above"))
        .map(|f| {
            let why = if f.model.is_empty() {
                String::new()
            } else {
                format!(": {}", f.model)
            };
            let unit = if f.unit.is_empty() {
                String::new()
            } else {
                format!(" {}", f.unit)
            };
            format!(
                "{}: {:.prec$}{unit}, people's {} ({}){why}",
                f.name,
                f.participants.mean,
                f.people_shown,
                f.verdict,
                prec = f.decimals
            )
        })
        .collect();
    let r2 = figures
        .iter()
        .find(|f| f.name == "Fitts fit r²")
        .map_or(f64::NAN, |f| f.participants.mean);
    // Movement times no closer to a line than people's are not worth a line of their own.
    if r2 >= 0.995 {
        out.push(format!(
            "Fitts fit r²: {r2:.3}: the movement times lie on the line; the model computes a \
             reach's duration by Fitts' law, people's times scatter about it"
        ));
    }
    let share_at = |w: f64| {
        let at: Vec<f64> = conditions
            .iter()
            .filter(|c| c.w_m == w)
            .map(|c| c.time_to_peak_share.mean)
            .collect();
        measure::mean_sd(&at).0
    };
    let (narrow, wide) = (WIDTHS_M[0], WIDTHS_M[WIDTHS_M.len() - 1]);
    let (at_narrow, at_wide) = (share_at(narrow), share_at(wide));
    // People's peak comes earlier for a narrow target; within 1 % of MT is no shift at all.
    if at_narrow > at_wide - 0.01 {
        out.push(format!(
            "time to peak / MT: {at_narrow:.3} at W {narrow} m, {at_wide:.3} at W {wide} m; \
             people's peak comes earlier, the smaller the target (MacKenzie et al. 1987): the \
             model's reach is one minimum-jerk segment, symmetric whatever the target"
        ));
    }
    let off: Vec<String> = conditions
        .iter()
        .filter(|c| c.verdict != "near")
        .map(|c| {
            format!(
                "{:.2} at D {} m, W {} m",
                c.effective_over_width.mean, c.d_m, c.w_m
            )
        })
        .collect();
    if !off.is_empty() {
        out.push(format!(
            "W_e / W not near people's 1 in {} of {} conditions ({}): the model's end-point \
             noise grows with the distance alone, and a reach is aimed again only when its \
             planned end point lies beyond half the target's width, so a wide target's width \
             goes unused",
            off.len(),
            conditions.len(),
            off.join("; ")
        ));
    }
    out
}
