//! Whether a task phase happened at a site, and if not, why.
//!
//! "Did not happen" alone sends a user to the trace to find out whether the tool stopped a
//! millimetre short, pressed too softly or the copy moved too late. So the evaluation returns the
//! first check that failed with what it measured, the rule it measured against and when
//! ([`PhaseMiss`]); whether a phase happened is only whether there is no such miss.
//!
//! The checks, in the order they are judged (see `docs/scenarios.md`, "How a phase is judged"):
//! the window has samples; each `contact` user touches the object at one sample at least, and its
//! peak displayed force reaches `min_force_n`; each `no_contact` user touches it at no sample; the
//! object moves `object_moves_m` from the window's first sample to its last (plus the observer
//! lag, [`observer_lag_s`]); it stays inside `region_m` at every sample; it rises `lifted_m` above
//! its start height.

use std::fmt;

use nalgebra::{Quaternion, UnitQuaternion};

use crate::body::Vec3;
use crate::scenario::{PhaseSpec, Scenario};
use crate::sim::{RunResult, SiteTrace};

#[cfg(feature = "serde")]
use serde::Serialize;

/// Why a phase did not happen at a site: the first of its checks that failed, with the measured
/// value, the phase's threshold and when. Lengths are in m, forces in N, times in s from the
/// run's start.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(Serialize), serde(tag = "check"))]
pub enum PhaseMiss {
    /// The run has no sample inside the window (it ends before it, or the window falls between
    /// two samples).
    #[cfg_attr(feature = "serde", serde(rename = "window"))]
    EmptyWindow {
        /// Window start, s.
        from_s: f64,
        /// Window end, s.
        to_s: f64,
        /// The first and last sample's time (`None`: the run has no samples).
        samples_s: Option<[f64; 2]>,
    },
    /// A `contact` user touched the object at no sample of the window.
    #[cfg_attr(feature = "serde", serde(rename = "contact"))]
    Contact {
        /// The object's name, or `any object`.
        object: String,
        /// Window start, s.
        from_s: f64,
        /// Window end, s.
        to_s: f64,
        /// How close the tool came (`None`: the trace has no tool or object pose).
        closest: Option<Approach>,
    },
    /// A `contact` user touched it, but its displayed force never reached `min_force_n`.
    #[cfg_attr(feature = "serde", serde(rename = "min_force_n"))]
    MinForce {
        /// The largest displayed force in the window, N.
        peak_n: f64,
        /// The phase's `min_force_n`, N.
        min_force_n: f64,
        /// When the peak was displayed, s.
        at_s: f64,
    },
    /// A `no_contact` user touched the object.
    #[cfg_attr(feature = "serde", serde(rename = "no_contact"))]
    NoContact {
        /// The object's name, or `any object`.
        object: String,
        /// The first sample it touched, s.
        at_s: f64,
        /// Window start, s.
        from_s: f64,
        /// Window end, s.
        to_s: f64,
    },
    /// The object moved less than `object_moves_m`.
    #[cfg_attr(feature = "serde", serde(rename = "object_moves_m"))]
    ObjectMoves {
        /// The object's name.
        object: String,
        /// Its displacement from the first sample to the last, m.
        moved_m: f64,
        /// The phase's `object_moves_m`, m.
        object_moves_m: f64,
        /// The first sample's time (the window's first), s.
        from_s: f64,
        /// The last sample's time (at most the window's end plus `lag_s`), s.
        to_s: f64,
        /// How much later than the window this site may see the motion ([`observer_lag_s`]), s.
        lag_s: f64,
    },
    /// The object's centre was outside `region_m` at a sample of the window.
    #[cfg_attr(feature = "serde", serde(rename = "region_m"))]
    Region {
        /// The object's name.
        object: String,
        /// The first sample outside, s.
        at_s: f64,
        /// Whether that sample is the window's first (the object never was inside).
        at_start: bool,
        /// The first axis out of bounds: `x`, `y` or `z`.
        axis: char,
        /// The centre's coordinate on that axis, m.
        value_m: f64,
        /// The region's bounds on that axis (lowest, highest), m.
        bounds_m: [f64; 2],
    },
    /// The object rose less than `lifted_m` above its start height.
    #[cfg_attr(feature = "serde", serde(rename = "lifted_m"))]
    Lifted {
        /// The object's name.
        object: String,
        /// Its highest centre over its start height, m.
        rose_m: f64,
        /// The phase's `lifted_m`, m.
        lifted_m: f64,
        /// When it was highest (`None`: no height was a number), s.
        peak_at_s: Option<f64>,
    },
}

/// The tool's closest approach to an object's surface at one site in a window.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(Serialize))]
pub struct Approach {
    /// The object it came closest to.
    pub object: String,
    /// The smallest gap between the tool tip's surface and the object's, m (negative: inside).
    pub gap_m: f64,
    /// When, s.
    pub at_s: f64,
}

/// A phase that did not happen at a site, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct MissedPhase {
    /// The phase's name.
    pub phase: String,
    /// Its first failed check.
    pub miss: PhaseMiss,
}

// The reason's text goes into the JSON beside the check's figures, written from them each time
// so the two cannot disagree.
#[cfg(feature = "serde")]
impl Serialize for MissedPhase {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut st = s.serialize_struct("MissedPhase", 3)?;
        st.serialize_field("phase", &self.phase)?;
        st.serialize_field("reason", &self.miss.to_string())?;
        st.serialize_field("miss", &self.miss)?;
        st.end()
    }
}

impl fmt::Display for PhaseMiss {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mm = |m: f64| m * 1e3;
        match self {
            PhaseMiss::EmptyWindow {
                from_s,
                to_s,
                samples_s,
            } => {
                write!(f, "no sample in {from_s:.2}–{to_s:.2} s")?;
                match samples_s {
                    Some([a, b]) => write!(f, "; the run's samples span {a:.2}–{b:.2} s"),
                    None => write!(f, "; the run has no samples"),
                }
            }
            PhaseMiss::Contact {
                object,
                from_s,
                to_s,
                closest,
            } => {
                write!(f, "no contact with {object} in {from_s:.2}–{to_s:.2} s")?;
                let Some(a) = closest else {
                    return write!(
                        f,
                        " (no sample touched it; the trace holds no tool or object pose to tell how close it came)"
                    );
                };
                if a.gap_m > 0.0 {
                    write!(f, "; closest approach {} beyond contact", length(a.gap_m))?;
                } else {
                    write!(
                        f,
                        "; closest approach {} inside its surface, yet no sample touched",
                        length(-a.gap_m)
                    )?;
                }
                if a.object != *object {
                    write!(f, " ({})", a.object)?;
                }
                write!(f, " at {:.2} s", a.at_s)
            }
            PhaseMiss::MinForce {
                peak_n,
                min_force_n,
                at_s,
            } => write!(
                f,
                "peak displayed force {peak_n:.2} N of {min_force_n:.2} N at {at_s:.2} s"
            ),
            PhaseMiss::NoContact {
                object,
                at_s,
                from_s,
                to_s,
            } => write!(
                f,
                "touched {object} at {at_s:.2} s (no contact allowed in {from_s:.2}–{to_s:.2} s)"
            ),
            PhaseMiss::ObjectMoves {
                object,
                moved_m,
                object_moves_m,
                from_s,
                to_s,
                lag_s,
            } => {
                write!(
                    f,
                    "{object} moved {:.1} mm of {:.1} mm from {from_s:.2} s to {to_s:.2} s",
                    mm(*moved_m),
                    mm(*object_moves_m)
                )?;
                if *lag_s > 0.0 {
                    write!(f, " (the window's end plus {lag_s:.2} s observer lag)")?;
                }
                Ok(())
            }
            PhaseMiss::Region {
                object,
                at_s,
                at_start,
                axis,
                value_m,
                bounds_m: [lo, hi],
            } => {
                if *at_start {
                    write!(
                        f,
                        "{object} was outside the region at {at_s:.2} s, the window's start"
                    )?;
                } else {
                    write!(f, "{object} left the region at {at_s:.2} s")?;
                }
                // The margin too: a centre a few µm out reads as on the bound at mm precision.
                let at = |v: f64| if v.abs() < 5e-4 { 0.0 } else { v };
                if value_m > hi {
                    let out = length(value_m - hi);
                    write!(f, " ({axis} {:.3} m, {out} above {hi:.3} m)", at(*value_m))
                } else if value_m < lo {
                    let out = length(lo - value_m);
                    write!(f, " ({axis} {:.3} m, {out} below {lo:.3} m)", at(*value_m))
                } else {
                    write!(f, " ({axis} {value_m} m, not within {lo:.3}–{hi:.3} m)")
                }
            }
            PhaseMiss::Lifted {
                object,
                rose_m,
                lifted_m,
                peak_at_s,
            } => match peak_at_s {
                Some(t) if *rose_m > 0.0 => write!(
                    f,
                    "{object} rose {:.1} mm of {:.1} mm above its start height (peak at {t:.2} s)",
                    mm(*rose_m),
                    mm(*lifted_m)
                ),
                Some(t) => write!(
                    f,
                    "{object} never rose above its start height, of {:.1} mm (highest {:.1} mm below it, at {t:.2} s)",
                    mm(*lifted_m),
                    mm(-rose_m)
                ),
                None => write!(
                    f,
                    "{object} rose to no height that was a number, of {:.1} mm",
                    mm(*lifted_m)
                ),
            },
        }
    }
}

/// A short length as text: mm to 0.1 mm, or µm below 1 mm (a tool 30 µm short is not "0.0 mm"
/// short).
fn length(m: f64) -> String {
    if m.abs() >= 1e-3 {
        format!("{:.1} mm", m * 1e3)
    } else {
        format!("{:.0} µm", m * 1e6)
    }
}

/// Whether phase `p` happened at site `i` of `run`: none of its checks failed.
pub fn phase_happened(sc: &Scenario, run: &RunResult, i: usize, p: &PhaseSpec) -> bool {
    why_missed(sc, run, i, p).is_none()
}

/// Why phase `p` did not happen at site `i` of `run` (the first failed check, in the module
/// docs' order), or `None` if it did.
pub fn why_missed(sc: &Scenario, run: &RunResult, i: usize, p: &PhaseSpec) -> Option<PhaseMiss> {
    let me = &sc.site[i].name;
    let s = &run.sites[i];
    let window: Vec<usize> = (0..run.t.len())
        .filter(|&k| run.t[k] >= p.from_s && run.t[k] <= p.to_s)
        .collect();
    let Some(&first) = window.first() else {
        return Some(PhaseMiss::EmptyWindow {
            from_s: p.from_s,
            to_s: p.to_s,
            samples_s: run.t.first().zip(run.t.last()).map(|(&a, &b)| [a, b]),
        });
    };
    // The object's motion, as late as this site can know of it.
    let lag = observer_lag_s(sc, run, i, p);
    let last = (first..run.t.len())
        .take_while(|&k| run.t[k] <= p.to_s + lag)
        .last()
        .unwrap_or(first);
    // The object the phase names (the first by default); a phase that names one is about
    // touching that object, one that names none about touching any.
    let o = sc.phase_object(p);
    let touches = |k: usize| {
        if p.object.is_empty() {
            s.touching[k]
        } else {
            s.touches(o, k)
        }
    };
    let touched_name = if p.object.is_empty() && sc.objects.len() > 1 {
        "any object".to_owned()
    } else {
        object_name(sc, o)
    };
    if p.contact.contains(me) {
        if !window.iter().any(|&k| touches(k)) {
            let candidates: Vec<usize> = if p.object.is_empty() {
                (0..s.objects()).collect()
            } else {
                vec![o]
            };
            return Some(PhaseMiss::Contact {
                object: touched_name,
                from_s: p.from_s,
                to_s: p.to_s,
                closest: closest_approach(sc, run, i, &window, &candidates),
            });
        }
        // The first sample of the largest force (a NaN force is no peak).
        let (at, peak) = window.iter().map(|&k| (k, s.f_desired[k].norm())).fold(
            (first, 0.0),
            |(ka, a), (k, x)| if x > a { (k, x) } else { (ka, a) },
        );
        if peak < p.min_force_n {
            return Some(PhaseMiss::MinForce {
                peak_n: peak,
                min_force_n: p.min_force_n,
                at_s: run.t[at],
            });
        }
    }
    if p.no_contact.contains(me) {
        if let Some(&k) = window.iter().find(|&&k| touches(k)) {
            return Some(PhaseMiss::NoContact {
                object: touched_name,
                at_s: run.t[k],
                from_s: p.from_s,
                to_s: p.to_s,
            });
        }
    }
    let object = object_name(sc, o);
    let pos = s.object_pos(o);
    let moved = (pos[last] - pos[first]).norm();
    if moved < p.object_moves_m {
        return Some(PhaseMiss::ObjectMoves {
            object,
            moved_m: moved,
            object_moves_m: p.object_moves_m,
            from_s: run.t[first],
            to_s: run.t[last],
            lag_s: lag,
        });
    }
    if let Some([lo, hi]) = p.region_m {
        // Written as "inside", so a NaN coordinate is outside.
        let within = |q: &Vec3, a: usize| q[a] >= lo[a] && q[a] <= hi[a];
        let outside = window
            .iter()
            .find_map(|&k| (0..3).find(|&a| !within(&pos[k], a)).map(|a| (k, a)));
        if let Some((k, a)) = outside {
            return Some(PhaseMiss::Region {
                object,
                at_s: run.t[k],
                at_start: k == first,
                axis: ['x', 'y', 'z'][a],
                value_m: pos[k][a],
                bounds_m: [lo[a], hi[a]],
            });
        }
    }
    if p.lifted_m > 0.0 {
        // z is up (the scenarios' convention: the table is z = 0).
        let rest = Vec3::from(sc.objects[o].start_m).z;
        let top = (first..=last)
            .map(|k| pos[k].z)
            .fold(f64::NEG_INFINITY, f64::max);
        if top < rest + p.lifted_m {
            let peak = (first..=last).find(|&k| pos[k].z == top);
            return Some(PhaseMiss::Lifted {
                object,
                rose_m: top - rest,
                lifted_m: p.lifted_m,
                peak_at_s: peak.map(|k| run.t[k]),
            });
        }
    }
    None
}

/// The tool's closest approach at site `i` to any of `objects` over the samples `window`: the
/// smallest gap between the tool tip's sphere and the object's surface. `None` if the trace holds
/// no tool position or object orientation (a hand-made trace), or no gap is a number.
fn closest_approach(
    sc: &Scenario,
    run: &RunResult,
    i: usize,
    window: &[usize],
    objects: &[usize],
) -> Option<Approach> {
    let s = &run.sites[i];
    let radius = sc.site[i].tool_radius_m;
    let mut best: Option<(f64, usize, usize)> = None;
    for &o in objects {
        let (Some(spec), true) = (sc.objects.get(o), o < s.objects()) else {
            continue;
        };
        let shape = spec.shape();
        let (pos, rot) = (s.object_pos(o), object_rot(s, o));
        for &k in window {
            let (Some(tool), Some(p), Some(q)) = (s.tool_pos.get(k), pos.get(k), rot.get(k)) else {
                continue;
            };
            let turn = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
            let gap = shape.signed_distance(turn.inverse() * (tool - p)).0 - radius;
            if gap < best.map_or(f64::INFINITY, |b| b.0) {
                best = Some((gap, o, k));
            }
        }
    }
    best.map(|(gap, o, k)| Approach {
        object: object_name(sc, o),
        gap_m: gap,
        at_s: run.t[k],
    })
}

/// Object `o`'s name in the scenario (`object` for one it does not declare, as a hand-made
/// scenario may leave out).
fn object_name(sc: &Scenario, o: usize) -> String {
    if o < sc.objects.len() {
        sc.object_name(o).to_owned()
    } else {
        "object".to_owned()
    }
}

/// Object `o`'s orientations at a site (unit quaternions w, x, y, z).
fn object_rot(s: &SiteTrace, o: usize) -> &[[f64; 4]] {
    match o {
        0 => &s.obj_rot,
        _ => s.others.get(o - 1).map_or(&[], |t| &t.rot),
    }
}

/// How much later than the phase's window site `i`'s copy may show the object's motion: 0 at an
/// actor's site (one of the phase's `contact` users), in a phase without actors, and in the
/// reference run (one world); elsewhere the largest one-way delay and its jitter, plus the slowest
/// actor's report period, s. See [`crate::metrics`]'s docs ("Phases").
pub fn observer_lag_s(sc: &Scenario, run: &RunResult, i: usize, p: &PhaseSpec) -> f64 {
    if run.mode == crate::sim::Mode::Reference
        || p.contact.is_empty()
        || p.contact.contains(&sc.site[i].name)
    {
        return 0.0;
    }
    let slowest_actor = sc
        .site
        .iter()
        .filter(|s| p.contact.contains(&s.name))
        .map(|s| 1.0 / s.report_rate_hz)
        .fold(0.0, f64::max);
    (sc.network.delay_max_ms + sc.network.jitter_ms) / 1e3 + slowest_actor
}

#[cfg(test)]
mod tests;
