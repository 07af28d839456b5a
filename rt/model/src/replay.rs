//! A recorded hand: a tool trajectory (time, position) played back by position, so the simulator and
//! the stations can run on human-like input instead of keyframe scripts. Positions between samples
//! are interpolated linearly, the velocity is that of the segment; before the first sample the hand
//! holds the first position, after the last the last.
//!
//! Sources: a CSV with the header `t_s,x,y,z` ([`Trajectory::parse_csv`]), or the tool positions of
//! a station's recording (the loader lives with the recording's reader).

use crate::body::Vec3;

/// Why a trajectory was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TrajectoryError {
    /// No samples.
    Empty,
    /// A CSV line that does not parse.
    Line {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// Times must increase strictly.
    NotIncreasing {
        /// 0-based sample index.
        index: usize,
        /// Its time, s (as text, so the error stays `Eq`).
        t_s: String,
        /// The previous sample's, s.
        prev_s: String,
    },
    /// A non-finite value.
    NonFinite {
        /// 0-based sample index.
        index: usize,
    },
}

impl std::fmt::Display for TrajectoryError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Empty => write!(f, "the trajectory has no samples"),
            Self::Line { line, what } => write!(f, "line {line}: {what}"),
            Self::NotIncreasing { index, t_s, prev_s } => write!(
                f,
                "sample {index}: time {t_s} s must be later than the previous sample's ({prev_s} s)"
            ),
            Self::NonFinite { index } => write!(f, "sample {index}: a non-finite value"),
        }
    }
}

impl std::error::Error for TrajectoryError {}

/// A hand's recorded trajectory.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Trajectory {
    t_s: Vec<f64>,
    pos: Vec<Vec3>,
}

impl Trajectory {
    /// From (time s, position m) samples: times increasing strictly, from 0 or later, all finite.
    ///
    /// # Errors
    /// Empty, a time that does not increase, a non-finite value.
    pub fn new(samples: impl IntoIterator<Item = (f64, Vec3)>) -> Result<Self, TrajectoryError> {
        let mut t = Self::default();
        for (index, (ts, p)) in samples.into_iter().enumerate() {
            if !ts.is_finite() || !p.iter().all(|v| v.is_finite()) {
                return Err(TrajectoryError::NonFinite { index });
            }
            if let Some(&prev) = t.t_s.last() {
                if ts <= prev {
                    return Err(TrajectoryError::NotIncreasing {
                        index,
                        t_s: ts.to_string(),
                        prev_s: prev.to_string(),
                    });
                }
            }
            t.t_s.push(ts);
            t.pos.push(p);
        }
        if t.t_s.is_empty() {
            return Err(TrajectoryError::Empty);
        }
        Ok(t)
    }

    /// From CSV text: the header `t_s,x,y,z`, then one sample a line (times in s, positions in m,
    /// world frame). Blank lines and lines starting with `#` are skipped.
    ///
    /// # Errors
    /// A missing or different header, a line without four numbers, or as [`Trajectory::new`].
    pub fn parse_csv(text: &str) -> Result<Self, TrajectoryError> {
        let mut rows = Vec::new();
        let mut header = false;
        for (k, line) in text.lines().enumerate() {
            let l = line.trim();
            if l.is_empty() || l.starts_with('#') {
                continue;
            }
            let err = |what: String| TrajectoryError::Line { line: k + 1, what };
            if !header {
                let cols: Vec<&str> = l.split(',').map(str::trim).collect();
                if cols != ["t_s", "x", "y", "z"] {
                    return Err(err(format!("header {l:?}: must be t_s,x,y,z")));
                }
                header = true;
                continue;
            }
            let v: Vec<f64> = l
                .split(',')
                .map(|c| c.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| err(format!("{l:?}: {e}")))?;
            let [t, x, y, z] = v[..] else {
                return Err(err(format!("{l:?}: must have 4 columns t_s,x,y,z")));
            };
            rows.push((t, Vec3::new(x, y, z)));
        }
        if !header {
            return Err(TrajectoryError::Line {
                line: 1,
                what: "no header: must be t_s,x,y,z".into(),
            });
        }
        Self::new(rows)
    }

    /// The trajectory as CSV (the format [`Trajectory::parse_csv`] reads).
    pub fn to_csv(&self) -> String {
        use std::fmt::Write;
        let mut out = String::from("t_s,x,y,z\n");
        for (t, p) in self.t_s.iter().zip(&self.pos) {
            let _ = writeln!(out, "{t:.9},{:.9},{:.9},{:.9}", p.x, p.y, p.z);
        }
        out
    }

    /// Samples.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// Whether there are none (never, for a constructed trajectory).
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// The first sample's time and position.
    pub fn first(&self) -> (f64, Vec3) {
        (self.t_s[0], self.pos[0])
    }

    /// The last sample's time, s.
    pub fn end_s(&self) -> f64 {
        self.t_s[self.t_s.len() - 1]
    }

    /// Position and velocity at `t` s.
    pub fn at(&self, t: f64) -> (Vec3, Vec3) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let k = self.t_s.partition_point(|&ts| ts <= t);
        if k == 0 {
            return (self.pos[0], Vec3::zeros());
        }
        if k == self.t_s.len() {
            return (self.pos[k - 1], Vec3::zeros());
        }
        let (t0, t1) = (self.t_s[k - 1], self.t_s[k]);
        let (p0, p1) = (self.pos[k - 1], self.pos[k]);
        let v = (p1 - p0) / (t1 - t0);
        (p0 + v * (t - t0), v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_holds_and_round_trips_through_csv() {
        let t = Trajectory::parse_csv("t_s,x,y,z\n0,0,0,0\n# c\n1,1,2,0\n").expect("parses");
        let (p, v) = t.at(0.5);
        assert!(
            (p - Vec3::new(0.5, 1.0, 0.0)).norm() < 1e-12
                && (v - Vec3::new(1.0, 2.0, 0.0)).norm() < 1e-12
        );
        assert_eq!(t.at(-1.0), (Vec3::zeros(), Vec3::zeros()));
        assert_eq!(t.at(5.0), (Vec3::new(1.0, 2.0, 0.0), Vec3::zeros()));
        assert_eq!(Trajectory::parse_csv(&t.to_csv()), Ok(t));
    }

    #[test]
    fn refuses_bad_input_naming_the_line() {
        assert!(matches!(
            Trajectory::parse_csv("t,x,y,z\n"),
            Err(TrajectoryError::Line { line: 1, .. })
        ));
        assert!(matches!(
            Trajectory::parse_csv("t_s,x,y,z\n0,0,0\n"),
            Err(TrajectoryError::Line { line: 2, .. })
        ));
        assert!(matches!(
            Trajectory::parse_csv("t_s,x,y,z\n1,0,0,0\n1,0,0,0\n"),
            Err(TrajectoryError::NotIncreasing { index: 1, .. })
        ));
        assert_eq!(
            Trajectory::parse_csv("t_s,x,y,z\n"),
            Err(TrajectoryError::Empty)
        );
    }
}
