//! A simulated participant's parameters: each with its unit, its default from the literature on
//! human motor control, and the spread between people, so that N seeds are N different people.
//! `docs/participants.md` lists the sources beside each value.

use crate::rng::Rng;

/// The parameters of one person (after [`ParticipantSpec::draw`]) or of the population (the
/// means a scenario may override).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct ParticipantSpec {
    /// Reaction to what the display shows: from a visual event to the first corrective change of
    /// the hand's motion, s. 150–250 ms; simple visual reaction is about 190 ms (Welford 1980),
    /// choice reaction slower.
    pub visual_reaction_s: f64,
    /// Reaction to what the hand feels (contact made or lost), s. 100–150 ms: touch shows in the
    /// finger forces about 0.1 s after contact (Jenmalm & Johansson 1997), an intended grip change
    /// to a touch about twice the slip response's 74 ms (Johansson & Westling 1987).
    pub haptic_reaction_s: f64,
    /// Latency of the grip's response to a slip, s: the automatic grip-force increase follows a
    /// slip at the fingertips within 60–80 ms (Johansson & Westling 1984).
    pub grip_reflex_s: f64,
    /// Grip force kept above the slip limit, as a fraction of that limit: 0.1–0.4, the span
    /// reported after Westling & Johansson 1984 (their safety margin; its base, the slip limit or
    /// the grip held, not verified against the paper).
    pub grip_margin: f64,
    /// Fitts' law intercept a, s (MT = a + b·log2(D/W + 1), MacKenzie 1992).
    pub fitts_a_s: f64,
    /// Fitts' law slope b, s per bit of the index of difficulty.
    pub fitts_b_s_per_bit: f64,
    /// The width a reach aims at (Fitts' W): how close to its goal a participant is content to
    /// end a reach, m.
    pub target_width_m: f64,
    /// Motor noise: the standard deviation of a reach's end point per axis, as a fraction of the
    /// reach's distance (signal-dependent noise, Harris & Wolpert 1998: a few percent).
    pub endpoint_noise: f64,
    /// Physiological tremor's frequency, Hz: 8–12 Hz (Elble & Koller 1990).
    pub tremor_hz: f64,
    /// Physiological tremor's amplitude at the hand, m (tens of micrometres).
    pub tremor_m: f64,
    /// Speed of a careful approach to a surface until contact is felt, m/s.
    pub approach_m_per_s: f64,
    /// The spread between people: each value above is drawn from a normal distribution about
    /// its mean with this relative standard deviation (0: everyone is the mean).
    pub spread: f64,
}

impl Default for ParticipantSpec {
    fn default() -> Self {
        Self {
            visual_reaction_s: 0.20,
            haptic_reaction_s: 0.125,
            grip_reflex_s: 0.07,
            grip_margin: 0.25,
            fitts_a_s: 0.10,
            fitts_b_s_per_bit: 0.12,
            target_width_m: 0.01,
            endpoint_noise: 0.02,
            tremor_hz: 10.0,
            tremor_m: 5e-5,
            approach_m_per_s: 0.06,
            spread: 0.12,
        }
    }
}

/// Where each drawn value is kept (the spread is relative, so a value stays positive; these
/// bounds keep the tails within what people do).
const LIMITS: [(f64, f64); 11] = [
    (0.12, 0.32),  // visual reaction, s
    (0.08, 0.20),  // haptic reaction, s
    (0.05, 0.10),  // grip reflex, s
    (0.10, 0.40),  // grip margin
    (0.0, 0.3),    // Fitts a, s
    (0.05, 0.3),   // Fitts b, s/bit
    (0.002, 0.03), // target width, m
    (0.0, 0.06),   // endpoint noise
    (8.0, 12.0),   // tremor, Hz
    (0.0, 2e-4),   // tremor, m
    (0.02, 0.15),  // approach, m/s
];

impl ParticipantSpec {
    /// The values' fields in [`LIMITS`]' order, for drawing and checking.
    fn values_mut(&mut self) -> [&mut f64; 11] {
        [
            &mut self.visual_reaction_s,
            &mut self.haptic_reaction_s,
            &mut self.grip_reflex_s,
            &mut self.grip_margin,
            &mut self.fitts_a_s,
            &mut self.fitts_b_s_per_bit,
            &mut self.target_width_m,
            &mut self.endpoint_noise,
            &mut self.tremor_hz,
            &mut self.tremor_m,
            &mut self.approach_m_per_s,
        ]
    }

    /// The drawn values' field names, in the order of [`ParticipantSpec::limits`].
    pub const FIELDS: [&'static str; 11] = [
        "visual_reaction_s",
        "haptic_reaction_s",
        "grip_reflex_s",
        "grip_margin",
        "fitts_a_s",
        "fitts_b_s_per_bit",
        "target_width_m",
        "endpoint_noise",
        "tremor_hz",
        "tremor_m",
        "approach_m_per_s",
    ];

    /// Each mean's allowed range (what [`ParticipantSpec::draw`] clamps a person's value to).
    pub fn limits() -> [(&'static str, f64, f64); 11] {
        let mut out = [("", 0.0, 0.0); 11];
        for (k, o) in out.iter_mut().enumerate() {
            *o = (Self::FIELDS[k], LIMITS[k].0, LIMITS[k].1);
        }
        out
    }

    /// The values a scenario gave, by field name, for validation.
    pub fn values(&self) -> [f64; 11] {
        let mut c = *self;
        c.values_mut().map(|v| *v)
    }

    /// One person: every value drawn about its mean with the relative spread, kept within what
    /// people do. The same `rng` state gives the same person.
    pub fn draw(&self, rng: &mut Rng) -> Self {
        let mut p = *self;
        let spread = self.spread;
        for (k, v) in p.values_mut().into_iter().enumerate() {
            let (lo, hi) = LIMITS[k];
            *v = (*v * (1.0 + spread * rng.normal())).clamp(lo, hi);
        }
        p.spread = 0.0;
        p
    }

    /// Fitts' movement time for a reach of `distance_m`, s.
    pub fn movement_time(&self, distance_m: f64) -> f64 {
        let id = (distance_m / self.target_width_m + 1.0).log2();
        self.fitts_a_s + self.fitts_b_s_per_bit * id
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_are_different_people_and_the_same_seed_the_same_person() {
        let mean = ParticipantSpec::default();
        let a = mean.draw(&mut Rng::new(1));
        let b = mean.draw(&mut Rng::new(2));
        assert_eq!(a, mean.draw(&mut Rng::new(1)));
        assert_ne!(a.visual_reaction_s, b.visual_reaction_s);
        for p in [a, b] {
            for (k, v) in p.values().into_iter().enumerate() {
                assert!(
                    v >= LIMITS[k].0 && v <= LIMITS[k].1,
                    "{}",
                    ParticipantSpec::FIELDS[k]
                );
            }
        }
        let none = ParticipantSpec {
            spread: 0.0,
            ..mean
        }
        .draw(&mut Rng::new(3));
        assert_eq!(
            none,
            ParticipantSpec {
                spread: 0.0,
                ..mean
            }
        );
    }

    #[test]
    fn movement_time_grows_with_the_index_of_difficulty() {
        let p = ParticipantSpec::default();
        assert!((p.movement_time(0.0) - p.fitts_a_s).abs() < 1e-12);
        // D/W + 1 = 8: three bits.
        assert!((p.movement_time(0.07) - (p.fitts_a_s + 3.0 * p.fitts_b_s_per_bit)).abs() < 1e-12);
    }
}
