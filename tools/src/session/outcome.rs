//! What a session produced, typed: per method the simulator's and the stations' figures, and per
//! station what its recording and its last live status said. The printer reads these by field and
//! `--json` serializes them, so a renamed field fails to build instead of printing `-`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context;
use coop_actors::station::status::StationStatus;
use coop_model::metrics::{self, Metrics};
use coop_model::scenario::{MethodName, Scenario};
use coop_model::sim::{Mode, RunResult};
use coop_rt::shm::rollback::RollbackFigures;
use coop_transport::recording::{self, Recording, StatusMsg};
use serde::Serialize;

use super::recorded::run_from_recordings;

/// Everything `session run` produced: what `--json` prints, and what the table is made from.
#[derive(Debug, Clone, Serialize)]
pub struct SessionRun {
    /// The scenario's name.
    pub scenario: String,
    /// The output directory, as given.
    pub out: String,
    /// The simulator's reference run's figures (the first method's; `None`: no method ran).
    pub reference: Option<Metrics>,
    /// Per method's name, its outcome.
    pub methods: BTreeMap<String, MethodOutcome>,
    /// The methods in the order they ran: the table's rows follow it.
    #[serde(skip)]
    pub order: Vec<MethodName>,
}

impl SessionRun {
    /// No method run yet, of `sc` into `out`.
    pub fn new(sc: &Scenario, out: &Path) -> Self {
        Self {
            scenario: sc.name.clone(),
            out: out.display().to_string(),
            reference: None,
            methods: BTreeMap::new(),
            order: Vec::new(),
        }
    }

    /// Adds `method`'s outcome (the first one's reference run is the session's).
    pub fn push(&mut self, method: MethodName, o: MethodOutcome) {
        if self.reference.is_none() {
            self.reference = Some(o.reference.clone());
        }
        self.order.push(method);
        self.methods.insert(method.as_str().to_owned(), o);
    }

    /// The table's rows: the reference, then per method in the order run, the simulator's and the
    /// stations' figures.
    pub fn rows(&self) -> Vec<Metrics> {
        let per_method = self
            .order
            .iter()
            .filter_map(|m| self.methods.get(m.as_str()))
            .flat_map(|o| [o.simulated.clone(), o.real.clone()]);
        self.reference.iter().cloned().chain(per_method).collect()
    }

    /// As JSON, its objects' keys sorted (as `--json` has always printed them).
    ///
    /// # Errors
    /// A figure does not serialize.
    pub fn to_json(&self) -> anyhow::Result<serde_json::Value> {
        Ok(serde_json::to_value(self)?)
    }
}

/// The outcome of one method's session.
#[derive(Debug, Clone, Serialize)]
pub struct MethodOutcome {
    /// The simulator's reference run's figures (in the JSON once, as the session's).
    #[serde(skip)]
    pub reference: Metrics,
    /// The simulator's figures for this method.
    pub simulated: Metrics,
    /// The stations' figures.
    pub real: Metrics,
    /// Per station (by site): what its recording says, and its live statistics.
    pub stations: BTreeMap<String, StationReport>,
    /// The session's time 0 in the launcher's clock (CLOCK_MONOTONIC ns).
    pub launcher_epoch_ns: u64,
    /// In a world of several objects, each object's figures (empty in a world of one).
    pub objects: Vec<ObjectRow>,
    /// Each station's traffic (payload kbit/s put and got, by kind).
    pub wire: Vec<WireRow>,
}

/// One station in a session: what its recording says, times in seconds from the session's time 0.
#[derive(Debug, Clone, Serialize)]
pub struct StationReport {
    /// Its recording's first part.
    pub recording: String,
    /// How many parts its recording has.
    pub recording_parts: usize,
    /// Its network process's final counters.
    #[serde(rename = "final")]
    pub final_status: Option<StatusMsg>,
    /// Its status read just before the session's end (`None`: not read, or not on this machine).
    pub live: Option<LiveStatus>,
    /// The stations table's figures: from `live`, or asked of the station through zenoh when its
    /// control block is on another machine (`session run --attach`); `None`: neither answered.
    pub figures: Option<StationRow>,
    /// The session's time 0 in this station's clock.
    pub epoch_ns: u64,
    /// When its network joined the session (its own presence seen).
    pub joined_s: Option<f64>,
    /// Its first recorded sample.
    pub first_sample_s: Option<f64>,
    /// Its last recorded sample.
    pub last_sample_s: Option<f64>,
    /// When its tool first touched the object (its script's first contact).
    pub first_contact_s: Option<f64>,
    /// Where its copy of the object was at its last sample, m.
    pub final_object_m: Option<[f64; 3]>,
    /// Its first adoption's jump, m.
    pub first_adoption_jump_m: Option<f64>,
    /// Its recording was cut short (a part lost its end).
    pub truncated: bool,
    /// Its first adoption.
    pub first_adoption_s: Option<f64>,
    /// States it took from the session's queryable at start.
    pub join_states: Option<u64>,
}

impl StationReport {
    /// What the recording `rec` (first part `record`) of `site` says, on time 0 `epoch_ns` in its
    /// station's clock, with its live status if read.
    fn of(
        site: &str,
        record: &Path,
        rec: &Recording,
        epoch_ns: u64,
        live: Option<LiveStatus>,
    ) -> Self {
        let since = |t_ns: u64| (t_ns as f64 - epoch_ns as f64) * 1e-9;
        Self {
            recording: record.display().to_string(),
            recording_parts: rec.files.len(),
            final_status: rec.status.clone(),
            figures: live.as_ref().map(StationRow::of_live),
            live,
            epoch_ns,
            joined_s: rec
                .presence
                .iter()
                .find(|p| p.site == site && p.present)
                .map(|p| since(p.t_ns)),
            first_sample_s: rec.samples.first().map(|s| since(s.t_ns)),
            last_sample_s: rec.samples.last().map(|s| since(s.t_ns)),
            first_contact_s: rec
                .samples
                .iter()
                .find(|s| s.touching)
                .map(|s| since(s.t_ns)),
            final_object_m: rec.samples.last().map(|s| s.pos),
            first_adoption_jump_m: rec.adoptions.first().map(|a| a.jump_m),
            truncated: rec.truncated,
            first_adoption_s: rec.adoptions.first().map(|a| since(a.t_ns)),
            join_states: rec.status.as_ref().map(|s| s.join_states),
        }
    }
}

/// One station's row of the stations table, wherever it came from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StationRow {
    /// Deadlines missed during the session, and whether it was overloaded.
    pub overruns: Option<SessionOverruns>,
    /// Physics' compute time per cycle, 99th percentile, µs.
    pub physics_compute_p99_us: u64,
    /// Rollback figures, for a method that rolls back.
    pub rollback: Option<RollbackFigures>,
    /// `status` (its control block, read here) or `zenoh` (asked of its network process).
    pub source: &'static str,
}

impl StationRow {
    /// From a status read here.
    pub fn of_live(l: &LiveStatus) -> Self {
        Self {
            overruns: l.overruns_during_session,
            physics_compute_p99_us: l.status.loops.physics.compute_us.p99,
            rollback: l.status.physics.rollback,
            source: "status",
        }
    }

    /// From what the station answered on its figures key, in a session of `physics_ticks` ticks
    /// at its physics rate.
    pub fn of_figures(
        f: &coop_transport::network::figures::StationFigures,
        physics_ticks: u64,
    ) -> Self {
        Self {
            overruns: Some(SessionOverruns::new(
                f.servo_overruns,
                f.physics_overruns,
                physics_ticks,
            )),
            physics_compute_p99_us: f.physics_compute_p99_us,
            rollback: f.rollback,
            source: "zenoh",
        }
    }
}

/// A station's status read just before the session's end, with its overruns during the session.
#[derive(Debug, Clone, Serialize)]
pub struct LiveStatus {
    /// What `station status` shows.
    #[serde(flatten)]
    pub status: StationStatus,
    /// Deadlines missed since the session's time 0 (startup is reported apart); absent when the
    /// counters could not be read at the end.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub overruns_during_session: Option<SessionOverruns>,
}

/// Deadlines missed during the session, per loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct SessionOverruns {
    /// The servo's.
    pub servo: u64,
    /// Physics'.
    pub physics: u64,
    /// Physics ticks the session held at the site's rate (its duration × the physics rate).
    pub physics_ticks: u64,
    /// More than `OVERLOAD_SHARE` (1 %) of those ticks overran: the station could not keep up, and
    /// its figures say more about the machine than about the method.
    pub overloaded: bool,
}

/// The share of a session's physics ticks a station may overrun before its run is marked
/// overloaded.
pub const OVERLOAD_SHARE: f64 = 0.01;

impl SessionOverruns {
    /// `servo` and `physics` overruns in a session of `physics_ticks` physics ticks.
    pub fn new(servo: u64, physics: u64, physics_ticks: u64) -> Self {
        Self {
            servo,
            physics,
            physics_ticks,
            overloaded: physics as f64 > OVERLOAD_SHARE * physics_ticks as f64,
        }
    }

    /// The share of the physics ticks that overran.
    pub fn physics_share(&self) -> f64 {
        self.physics as f64 / self.physics_ticks.max(1) as f64
    }
}

/// One object's figures in a session: the simulator's and the stations'.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObjectRow {
    /// The object's name.
    pub name: String,
    /// The simulator's run.
    pub simulated: ObjectFigures,
    /// The stations' run.
    pub real: ObjectFigures,
}

/// How one object's copies agreed with each other and with the reference, mm.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObjectFigures {
    /// Largest distance between two sites' copies of it, mm.
    pub div_max_mm: f64,
    /// RMS over the samples of that distance, mm.
    pub div_rms_mm: f64,
    /// That distance at the end, mm.
    pub div_final_mm: f64,
    /// Largest distance of any site's copy from the reference's, mm.
    pub err_ref_max_mm: f64,
}

impl ObjectFigures {
    /// Object `o`'s figures in `run` against `reference`.
    pub fn of(run: &RunResult, reference: &RunResult, o: usize) -> Self {
        let n = run.t.len();
        let div: Vec<f64> = (0..n)
            .map(|k| metrics::object_divergence(run, o, k))
            .collect();
        let rms = (div.iter().map(|d| d * d).sum::<f64>() / n.max(1) as f64).sqrt();
        let err = run
            .sites
            .iter()
            .flat_map(|s| {
                let r = reference.sites[0].object_pos(o);
                s.object_pos(o).iter().zip(r).map(|(a, b)| (a - b).norm())
            })
            .fold(0.0, f64::max);
        Self {
            div_max_mm: div.iter().copied().fold(0.0, f64::max) * 1e3,
            div_rms_mm: rms * 1e3,
            div_final_mm: div.last().copied().unwrap_or(0.0) * 1e3,
            err_ref_max_mm: err * 1e3,
        }
    }
}

/// One station's traffic over its network process's life (payload as put and got, `station
/// status`'s counts): per kind, and in all.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WireRow {
    /// The site.
    pub site: String,
    /// How long its network process ran, s.
    pub duration_s: f64,
    /// Payload put, kbit/s, all kinds.
    pub sent_kbit_s: f64,
    /// Payload received, kbit/s, all kinds.
    pub received_kbit_s: f64,
    /// Per kind (`states`, `tracks`, `clock`, `presence`, `live`): messages put per second,
    /// payload put and received, kbit/s.
    pub kinds: Vec<(String, f64, f64, f64)>,
}

impl WireRow {
    /// From a station's recording: its final counts over its network process's life (the
    /// recording's session message to its status), or `None` if it has not both.
    pub fn of(site: &str, rec: &Recording) -> Option<Self> {
        use coop_rt::shm::control::{CounterKey, WireKind};
        let status = rec.status.as_ref()?;
        let start = rec.session.as_ref()?.t_ns;
        let dt = status.t_ns.saturating_sub(start) as f64 * 1e-9;
        if dt <= 0.0 {
            return None;
        }
        let t = status.traffic;
        let kbit = |b: u64| b as f64 * 8e-3 / dt;
        Some(Self {
            site: site.to_owned(),
            duration_s: dt,
            sent_kbit_s: kbit(t.sent_bytes.iter().sum()),
            received_kbit_s: kbit(t.received_bytes.iter().sum()),
            kinds: WireKind::ALL
                .iter()
                .enumerate()
                .map(|(k, kind)| {
                    (
                        kind.name().to_owned(),
                        t.sent_msgs[k] as f64 / dt,
                        kbit(t.sent_bytes[k]),
                        kbit(t.received_bytes[k]),
                    )
                })
                .collect(),
        })
    }
}

/// What the stations recorded, and where: per site in the scenario's order, its name and
/// recording's path, the recording, and the session's time 0 in its station's clock.
pub(crate) struct Recorded<'a> {
    /// Per site: its name and its recording's first part.
    pub sites: &'a [(String, PathBuf)],
    /// The recordings, one per site.
    pub recordings: &'a [Recording],
    /// Time 0 per recording, in its station's clock.
    pub epochs: &'a [u64],
}

/// The figures of a session that ran: the stations' recordings on the scenario's grid from each
/// one's time 0, the simulator's runs of the same scenario, the metrics, `metrics.json`,
/// `session.mcap` and the plots in `dir`, and per station what its recording says (with its live
/// statistics when read, `live`).
///
/// # Errors
/// A recording without samples; the plots, `session.mcap` or `metrics.json` cannot be written.
pub(crate) fn outcome(
    sc: &Scenario,
    session: &str,
    t0_unix_ns: u64,
    dir: &Path,
    rec: &Recorded<'_>,
    mut live: BTreeMap<String, LiveStatus>,
) -> anyhow::Result<MethodOutcome> {
    let method = sc.method;
    let real_run = run_from_recordings(sc, rec.recordings, rec.epochs)?;
    let reference_run = crate::sim::run_mode(sc, Mode::Reference);
    let sim_run = crate::sim::run_mode(sc, Mode::Distributed(method));
    let reference = metrics::compute(sc, &reference_run, &reference_run);
    let mut simulated = metrics::compute(sc, &sim_run, &reference_run);
    simulated.method = format!("{}-sim", method.as_str());
    let mut real = metrics::compute(sc, &real_run, &reference_run);
    real.method = format!("{}-real", method.as_str());
    for s in &mut real.sites {
        // Not measured on real stations (the servo's adoption step and the energy account live in
        // the simulator only).
        s.max_adoption_force_step_n = f64::NAN;
        s.energy_from_others_j = f64::NAN;
        s.others_work_j = f64::NAN;
    }
    crate::plots::figures(dir, sc, &real_run, &reference_run)?;
    write_session_file(dir, sc, session, &real_run, &reference_run, t0_unix_ns)?;
    crate::layout::write(dir, sc)?;
    std::fs::write(
        dir.join("metrics.json"),
        serde_json::to_string_pretty(&serde_json::json!({ "real": real, "simulated": simulated }))?
            + "\n",
    )?;
    let stations = rec
        .sites
        .iter()
        .zip(rec.recordings)
        .zip(rec.epochs)
        .map(|(((site, record), r), &t0)| {
            let report = StationReport::of(site, record, r, t0, live.remove(site));
            (site.clone(), report)
        })
        .collect();
    let wire = rec
        .sites
        .iter()
        .zip(rec.recordings)
        .filter_map(|((site, _), r)| WireRow::of(site, r))
        .collect();
    Ok(MethodOutcome {
        reference,
        simulated,
        real,
        stations,
        launcher_epoch_ns: 0,
        objects: object_rows(sc, &sim_run, &real_run, &reference_run),
        wire,
    })
}

/// `session.mcap` in `dir`: every site's copy, tool and forces on the grid, and the reference.
fn write_session_file(
    dir: &Path,
    sc: &Scenario,
    session: &str,
    real_run: &RunResult,
    reference_run: &RunResult,
    t0_unix_ns: u64,
) -> anyhow::Result<()> {
    let session_file = dir.join("session.mcap");
    recording::session::write(
        &session_file,
        BTreeMap::from([
            ("session".into(), session.to_owned()),
            ("scenario".into(), sc.name.clone()),
            ("method".into(), sc.method.as_str().to_owned()),
        ]),
        sc,
        real_run,
        Some(reference_run),
        recording::session::Source::Stations,
        t0_unix_ns,
    )
    .with_context(|| format!("writing {}", session_file.display()))
}

/// A world of several: each object's own figures (the table's are the worst object's); a world of
/// one: none.
fn object_rows(
    sc: &Scenario,
    sim_run: &RunResult,
    real_run: &RunResult,
    reference_run: &RunResult,
) -> Vec<ObjectRow> {
    if sc.objects.len() <= 1 {
        return Vec::new();
    }
    (0..sc.objects.len())
        .map(|o| ObjectRow {
            name: sc.object_name(o).to_owned(),
            simulated: ObjectFigures::of(sim_run, reference_run, o),
            real: ObjectFigures::of(real_run, reference_run, o),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use coop_transport::recording::SampleMsg;

    /// The keys and values the tests and bench scripts read from `--json`'s `stations`.
    #[test]
    fn a_station_report_serializes_as_the_scripts_read_it() {
        let rec = Recording {
            status: Some(StatusMsg {
                join_states: 3,
                ..StatusMsg::default()
            }),
            samples: vec![SampleMsg {
                t_ns: 3_000_000_000,
                pos: [1.0, 2.0, 3.0],
                touching: true,
                ..SampleMsg::default()
            }],
            ..Recording::default()
        };
        let r = StationReport::of(
            "user1",
            Path::new("/x/user1.mcap"),
            &rec,
            1_000_000_000,
            None,
        );
        let expected = serde_json::json!({
            "recording": "/x/user1.mcap",
            "recording_parts": 0,
            "final": rec.status,
            "live": null,
            "figures": null,
            "epoch_ns": 1_000_000_000u64,
            "joined_s": null,
            "first_sample_s": 2.0,
            "last_sample_s": 2.0,
            "first_contact_s": 2.0,
            "final_object_m": [1.0, 2.0, 3.0],
            "first_adoption_jump_m": null,
            "truncated": false,
            "first_adoption_s": null,
            "join_states": 3,
        });
        assert_eq!(serde_json::to_value(&r).expect("serializes"), expected);
    }
}
