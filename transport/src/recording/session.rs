//! A session file: every site of one run, and the reference copy, in one MCAP file
//! (`session.mcap`), written by `sim run --out` from the simulator's run and by `session run` from
//! the stations' recordings (resampled on the scenario's grid), so that simulated and real runs
//! open the same way in Foxglove or Lichtblick, with the same layout (`docs/foxglove-layout.json`).
//!
//! Times: `t_ns` inside messages is ns since the session's time 0; the MCAP `log_time` is
//! `epoch_unix_ns + t_ns` — the wall clock of time 0 for a real session, the fixed
//! [`SIM_EPOCH_UNIX_NS`] for the simulator (whose output must be the same bits on every run).
//!
//! | topic         | schema                    | per sample of the scenario's grid                   |
//! |---------------|---------------------------|-----------------------------------------------------|
//! | `/object`     | JSON, as in a station's recording | one per site and one for the reference (`site` tells them apart); in a world of several objects one per object of each (`object` names it) |
//! | `/tool`       | JSON, as in a station's recording | one per site                                 |
//! | `/divergence` | JSON [`DivergenceMsg`]    | the largest distance between copies, each copy's from the reference |
//! | `/tf`         | `foxglove.FrameTransform` | `world → object/<site>`, `world → tool/<site>`, `world → object/reference`; in a world of several objects also `world → object/<name>/<site>` (and `object/<name>/reference`) for each other object |
//! | `/scene`      | `foxglove.SceneUpdate`    | every [`SCENE_EVERY`]: every site's entities and the reference copy ([`REFERENCE_COLOUR`]) |
//! | `/log`        | `foxglove.Log`            | the session's start (scenario, method, sites)       |
//!
//! The frames, entities and colours are the recordings' own ([`Scene`]); one file, no parts,
//! written in (uncompressed) chunks with their indexes: it is written at once, not by a station
//! that may crash, and Rerun's MCAP loader reads chunked files only.

use std::collections::BTreeMap;
use std::path::Path;

use coop_model::scenario::Scenario;
use coop_model::sim::RunResult;
use foxglove::messages::{log::Level, Log, SceneUpdate};

use super::messages::{DivergenceMsg, ObjectPart, SampleMsg, ToolPart};
use super::part::Part;
use super::scene::{encode, REFERENCE_COLOUR};
use super::topic::{FoxgloveTopic, Topic};
use super::{io_err, RecordingError, Scene, SCENE_EVERY};

/// The simulator's time 0 on the wall clock: 1 s past the Unix epoch (a fixed value keeps its
/// file the same bits on every run; not 0, which some viewers read as "no time").
pub const SIM_EPOCH_UNIX_NS: u64 = 1_000_000_000;
/// The reference copy's site name, in its frame (`object/reference`), entity and `/object`.
pub const REFERENCE: &str = "reference";

/// Where `run` came from, for the metadata and the first log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// The simulator.
    Simulated,
    /// Real stations (their recordings resampled).
    Stations,
}

impl Source {
    fn as_str(self) -> &'static str {
        match self {
            Source::Simulated => "simulated",
            Source::Stations => "stations",
        }
    }
}

/// Site `i`'s sample `k` of `run`.
fn sample_of(run: &RunResult, i: usize, k: usize, t_ns: u64) -> SampleMsg {
    let s = &run.sites[i];
    SampleMsg {
        t_ns,
        pos: s.obj_pos[k].into(),
        rot: s.obj_rot[k],
        vel: s.obj_vel[k].into(),
        adoptions: 0,
        tool_pos: s.tool_pos[k].into(),
        f_desired: s.f_desired[k].into(),
        f_measured: s.f_measured[k].into(),
        f_object: s.f_on_object[k].into(),
        touching: s.touching[k],
    }
}

/// Site `i`'s other objects' poses (position, orientation w, x, y, z) at sample `k` of `run`.
fn other_poses(run: &RunResult, i: usize, k: usize) -> Vec<([f64; 3], [f64; 4])> {
    run.sites[i]
        .others
        .iter()
        .map(|o| (o.pos[k].into(), o.rot[k]))
        .collect()
}

fn object_part(site: &str, object: &str, m: &SampleMsg) -> ObjectPart {
    ObjectPart {
        t_ns: m.t_ns,
        site: site.to_owned(),
        object: object.to_owned(),
        pos: m.pos,
        rot: m.rot,
        vel: m.vel,
        adoptions: m.adoptions,
        touching: None,
    }
}

/// The `/object` messages of site `i` of `run` at sample `k` after the first object's
/// (`first`): one per other object, named (`names`: every object's, the first's first).
fn other_object_parts(
    run: &RunResult,
    (i, k): (usize, usize),
    site: &str,
    names: &[String],
    first: &SampleMsg,
) -> Vec<ObjectPart> {
    run.sites[i]
        .others
        .iter()
        .zip(names.iter().skip(1))
        .map(|(o, name)| ObjectPart {
            t_ns: first.t_ns,
            site: site.to_owned(),
            object: name.clone(),
            pos: o.pos[k].into(),
            rot: o.rot[k],
            vel: o.vel[k].into(),
            adoptions: first.adoptions,
            touching: None,
        })
        .collect()
}

fn tool_part(site: &str, m: &SampleMsg) -> ToolPart {
    ToolPart {
        t_ns: m.t_ns,
        site: site.to_owned(),
        tool_pos: m.tool_pos,
        f_desired: m.f_desired,
        f_measured: m.f_measured,
        f_object: m.f_object,
        touching: m.touching,
    }
}

/// The file being written: its part and the messages' sequence.
struct Writer {
    part: Part,
    seq: u32,
    epoch_unix_ns: u64,
}

impl Writer {
    fn put(&mut self, channel_id: u16, t_ns: u64, data: &[u8]) -> Result<(), RecordingError> {
        self.seq = self.seq.wrapping_add(1);
        self.part
            .write(channel_id, self.seq, self.epoch_unix_ns + t_ns, data)
    }
    fn json<T: serde::Serialize>(
        &mut self,
        topic: Topic,
        t_ns: u64,
        m: &T,
    ) -> Result<(), RecordingError> {
        let data = serde_json::to_vec(m).unwrap_or_default();
        self.put(self.part.channel(topic)?, t_ns, &data)
    }
    fn foxglove<T: foxglove::Encode>(
        &mut self,
        topic: FoxgloveTopic,
        t_ns: u64,
        m: &T,
    ) -> Result<(), RecordingError> {
        let id = self.part.foxglove_channel(topic).unwrap_or(0);
        self.put(id, t_ns, &encode(m))
    }
}

/// The session's start, the file's first `/log` line: where `run` of `sc` came from, its method
/// and its sites (`scenes`, `first` the first's), and whether a reference copy is shown.
fn start_line(
    (sc, run, source): (&Scenario, &RunResult, Source),
    (first, scenes): (&Scene, &[Scene]),
    with_reference: bool,
    epoch_unix_ns: u64,
) -> Log {
    let names: Vec<&str> = scenes.iter().map(|s| s.site.as_str()).collect();
    Scene {
        site: "session".into(),
        ..first.clone()
    }
    .log(
        epoch_unix_ns,
        Level::Info,
        format!(
            "session ({}): scenario {}, method {}, sites {}{}",
            source.as_str(),
            sc.name,
            run.mode.name(),
            names.join(", "),
            if with_reference {
                ", reference copy (grey) from the simulator"
            } else {
                ""
            }
        ),
    )
}

/// Writes `run` of scenario `sc` (and its `reference` run, when given, on the same grid) to
/// `path` as a session file, with `metadata` (plus `source`, `started_unix_ns` and `part`).
///
/// # Errors
/// The file cannot be created or written; `run` has no site.
pub fn write(
    path: &Path,
    mut metadata: BTreeMap<String, String>,
    sc: &Scenario,
    run: &RunResult,
    reference: Option<&RunResult>,
    source: Source,
    epoch_unix_ns: u64,
) -> Result<(), RecordingError> {
    let scenes: Vec<Scene> = (0..run.sites.len())
        .filter_map(|i| Scene::from_scenario(sc, i))
        .collect();
    let Some(first) = scenes.first() else {
        return Err(io_err(path)(std::io::Error::other(
            "a session file needs a run with sites",
        )));
    };
    let reference = reference.filter(|r| !r.sites.is_empty());
    let reference_scene = Scene {
        site: REFERENCE.into(),
        colour: REFERENCE_COLOUR,
        ..first.clone()
    };
    metadata.insert("source".into(), source.as_str().into());
    metadata.insert("started_unix_ns".into(), epoch_unix_ns.to_string());
    let mut w = Writer {
        part: Part::create(
            path.to_owned(),
            0,
            &metadata,
            &Topic::SESSION_FILE,
            true,
            true,
        )?,
        seq: 0,
        epoch_unix_ns,
    };
    // A world of one object names none (its `/object` is a station recording's).
    let objects: Vec<String> = if sc.objects.len() > 1 {
        sc.objects.iter().map(|o| o.name.clone()).collect()
    } else {
        Vec::new()
    };
    let first_object = objects.first().map_or("", String::as_str);
    let start = start_line(
        (sc, run, source),
        (first, &scenes),
        reference.is_some(),
        epoch_unix_ns,
    );
    w.foxglove(FoxgloveTopic::Log, 0, &start)?;
    let scene_every = SCENE_EVERY.as_nanos() as u64;
    let mut scene_ns: Option<u64> = None;
    for (k, &t) in run.t.iter().enumerate() {
        let t_ns = (t * 1e9).round().max(0.0) as u64;
        let wall = epoch_unix_ns + t_ns;
        let samples: Vec<SampleMsg> = (0..scenes.len())
            .map(|i| sample_of(run, i, k, t_ns))
            .collect();
        let reference_sample = reference
            .filter(|r| k < r.t.len())
            .map(|r| sample_of(r, 0, k, t_ns));
        for (i, (scene, m)) in scenes.iter().zip(&samples).enumerate() {
            w.json(
                Topic::Object,
                t_ns,
                &object_part(&scene.site, first_object, m),
            )?;
            for part in other_object_parts(run, (i, k), &scene.site, &objects, m) {
                w.json(Topic::Object, t_ns, &part)?;
            }
            w.json(Topic::Tool, t_ns, &tool_part(&scene.site, m))?;
            for f in &scene.transforms(m, wall) {
                w.foxglove(FoxgloveTopic::Tf, t_ns, f)?;
            }
            for f in &scene.other_transforms(&other_poses(run, i, k), wall) {
                w.foxglove(FoxgloveTopic::Tf, t_ns, f)?;
            }
        }
        if let Some(m) = &reference_sample {
            w.json(
                Topic::Object,
                t_ns,
                &object_part(REFERENCE, first_object, m),
            )?;
            if let Some(r) = reference {
                for part in other_object_parts(r, (0, k), REFERENCE, &objects, m) {
                    w.json(Topic::Object, t_ns, &part)?;
                }
            }
            let [object, _tool] = reference_scene.transforms(m, wall);
            w.foxglove(FoxgloveTopic::Tf, t_ns, &object)?;
            if let Some(r) = reference {
                for f in &reference_scene.other_transforms(&other_poses(r, 0, k), wall) {
                    w.foxglove(FoxgloveTopic::Tf, t_ns, f)?;
                }
            }
        }
        let distance = |a: [f64; 3], b: [f64; 3]| {
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        };
        w.json(
            Topic::Divergence,
            t_ns,
            &DivergenceMsg {
                t_ns,
                max_m: coop_model::metrics::divergence(run, k),
                vs_reference_m: match &reference_sample {
                    Some(r) => samples.iter().map(|m| distance(m.pos, r.pos)).collect(),
                    None => Vec::new(),
                },
            },
        )?;
        if scene_ns.is_none_or(|s| t_ns.saturating_sub(s) >= scene_every) {
            let mut entities = vec![first.environment(wall)];
            for (scene, m) in scenes.iter().zip(&samples) {
                entities.extend(scene.entities(m, wall));
                entities.extend(scene.other_entities(wall));
            }
            if let Some(m) = &reference_sample {
                let [object, _tool, _force] = reference_scene.entities(m, wall);
                entities.push(object);
                entities.extend(reference_scene.other_entities(wall));
            }
            w.foxglove(
                FoxgloveTopic::Scene,
                t_ns,
                &SceneUpdate {
                    deletions: Vec::new(),
                    entities,
                },
            )?;
            scene_ns = Some(t_ns);
        }
    }
    w.part.finish()
}
