//! A recorded hand from a file (a CSV of `t_s,x,y,z`, or a station's MCAP recording), for a
//! scenario's `hand_file` and a station's `device = "replay"` alike: a leaf both import.

use std::path::Path;

use coop_model::body::Vec3;
use coop_model::replay::Trajectory;

/// Why a recorded hand did not load (the caller names the file).
#[derive(Debug, thiserror::Error)]
pub enum TrajectoryFileError {
    /// The CSV file cannot be read.
    #[error("cannot be read")]
    Read(#[source] std::io::Error),
    /// The samples do not make a trajectory.
    #[error(transparent)]
    Trajectory(#[from] coop_model::replay::TrajectoryError),
    /// The MCAP recording cannot be read.
    #[error(transparent)]
    Recording(#[from] coop_transport::recording::RecordingError),
    /// The recording's session never started.
    #[error("the recording has no /session message: its session never started, so its samples have no time 0")]
    NoSession,
}

/// A recorded hand from `path`: a CSV `t_s,x,y,z` (by its `.csv` extension), else a station's MCAP
/// recording, whose `/tool` positions are timed from its session's start (its epoch).
///
/// # Errors
/// The file cannot be read or parsed, has no samples, or a recording without a session start.
pub fn load_trajectory(path: &Path) -> Result<Trajectory, TrajectoryFileError> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
    {
        let text = std::fs::read_to_string(path).map_err(TrajectoryFileError::Read)?;
        return Ok(Trajectory::parse_csv(&text)?);
    }
    let rec = coop_transport::recording::read(path)?;
    let Some(session) = &rec.session else {
        return Err(TrajectoryFileError::NoSession);
    };
    let epoch = session.epoch_ns;
    let mut last: Option<u64> = None;
    let samples: Vec<(f64, Vec3)> = rec
        .samples
        .iter()
        .filter(|s| {
            // One sample per time (a restarted physics may repeat the last one).
            let keep = last.is_none_or(|l| s.t_ns > l);
            if keep {
                last = Some(s.t_ns);
            }
            keep
        })
        .map(|s| {
            let t = (s.t_ns as f64 - epoch as f64) * 1e-9;
            (t, Vec3::from(s.tool_pos))
        })
        .collect();
    Ok(Trajectory::new(samples)?)
}
