//! [`Recorder`]: a station writes its recording through it, message by message, in parts.

use std::collections::BTreeMap;
use std::path::Path;

use coop_rt::msg::TraceRecord;

use super::messages::{
    AdoptionMsg, ClockMsg, ObjectPart, PeerMsg, PresenceMsg, PublishedMsg, RemoteMsg, SampleMsg,
    SessionMsg, StatusMsg, TaskMsg, ToolPart,
};
use super::parts::{Parts, Rotation, Slot};
use super::topic::{FoxgloveTopic, Topic};
use super::{Level, RecordingError, Scene, OBJECTS_KEY, SCENE_EVERY};

/// Writes a recording, in parts as its [`Rotation`] says.
pub struct Recorder {
    /// Every message goes through [`Parts::next`], which rotates when the part is full.
    pub(super) parts: Parts,
    /// What the site shows, for the Foxglove channels (none: JSON channels only).
    scene: Option<Scene>,
    /// The site, in `/object` and `/tool` (the scene's, else the metadata's `site`).
    site: String,
    /// The part and the sample time the whole `/scene` was last written in.
    scene_at: Option<(u32, u64)>,
    /// The part an earlier process wrote last, when this recorder continues its recording.
    continued: Option<u32>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("path", &self.parts.path())
            .field("seq", &self.parts.seq())
            .finish()
    }
}

impl Recorder {
    /// Creates (truncates) `path`, the first part, and writes the header, metadata, schemas and
    /// channels; removes the parts an earlier recording left at the same path. Its directory must
    /// exist: none is created (a mistyped path must not make directories, least of all as root).
    ///
    /// # Errors
    /// The file cannot be created or written, or an earlier part cannot be removed.
    pub fn create(
        path: &Path,
        metadata: BTreeMap<String, String>,
        rotation: Rotation,
    ) -> Result<Self, RecordingError> {
        Self::create_with(path, metadata, rotation, None, false)
    }

    /// As [`Recorder::create`], and with Foxglove's `/tf`, `/scene` and `/log` channels showing
    /// `scene`: each sample's frames and scene, and a log line for each station event (the
    /// session's start, joins and leaves, losses and rejoins, [`Recorder::event`]s, the end).
    ///
    /// # Errors
    /// As [`Recorder::create`].
    pub fn create_with_scene(
        path: &Path,
        metadata: BTreeMap<String, String>,
        rotation: Rotation,
        scene: Scene,
    ) -> Result<Self, RecordingError> {
        Self::create_with(path, metadata, rotation, Some(scene), false)
    }

    /// As [`Recorder::create_with_scene`] (or [`Recorder::create`] without a scene), unless the
    /// recording at `path` is one an earlier process of the same station run wrote: `metadata`
    /// names a [`STATION_RUN`](super::STATION_RUN), and the newest part on disk that holds metadata names the same one
    /// (and the same session and site). Then nothing is removed: the recording goes on in the part
    /// after that one, as the same recording (its `started_unix_ns` kept), and
    /// [`Recorder::continued`] says so. A new run of the station, or a recording made without a
    /// station run, starts afresh.
    ///
    /// # Errors
    /// As [`Recorder::create`]; a part on disk that cannot be read.
    pub fn continue_or_create(
        path: &Path,
        metadata: BTreeMap<String, String>,
        rotation: Rotation,
        scene: Option<Scene>,
    ) -> Result<Self, RecordingError> {
        Self::create_with(path, metadata, rotation, scene, true)
    }

    fn create_with(
        path: &Path,
        mut metadata: BTreeMap<String, String>,
        rotation: Rotation,
        scene: Option<Scene>,
        may_continue: bool,
    ) -> Result<Self, RecordingError> {
        if let Some(sc) = scene.as_ref().filter(|s| !s.others.is_empty()) {
            // The world's objects in order: `/object` names them, and a reader orders them by it.
            let names: Vec<String> = (0..=sc.others.len()).map(|k| sc.object_name(k)).collect();
            metadata.insert(OBJECTS_KEY.into(), names.join(","));
        }
        let site = scene
            .as_ref()
            .map(|s| s.site.clone())
            .or_else(|| metadata.get("site").cloned())
            .unwrap_or_default();
        let (parts, continued) =
            Parts::open(path, metadata, rotation, scene.is_some(), may_continue)?;
        Ok(Self {
            parts,
            scene,
            site,
            scene_at: None,
            continued,
        })
    }

    /// When this recorder continues a recording an earlier process of its station run wrote
    /// ([`Recorder::continue_or_create`]): the number of the part that process wrote last.
    pub fn continued(&self) -> Option<u32> {
        self.continued
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        self.parts.path()
    }

    /// `/session` (and again at the top of every later part).
    ///
    /// # Errors
    /// Writing failed.
    pub fn session(&mut self, m: &SessionMsg) -> Result<(), RecordingError> {
        let mut slot = self.parts.next()?;
        let first = slot.session(m)?;
        let text = match self.continued {
            Some(n) if first => format!(
                "station {} recording again in session {} after its network process restarted: \
                 part {} goes on from part {n}",
                m.site,
                m.session,
                slot.number()
            ),
            _ => format!(
                "station {} started in session {}: scenario {}, method {}, emulation {}",
                m.site, m.session, m.scenario, m.method, m.emulation
            ),
        };
        log(&mut slot, self.scene.as_ref(), m.t_ns, Level::Info, text)
    }
    /// A record from physics' trace ring: `/adoption` for a [`TraceRecord::ADOPTION`], else
    /// `/object` and `/tool` (a [`TraceRecord::SAMPLE`]); the same messages as `Recorder::adoption`
    /// and `Recorder::sample` write.
    ///
    /// # Errors
    /// Writing failed.
    pub fn trace(&mut self, t: &TraceRecord) -> Result<(), RecordingError> {
        if t.kind == TraceRecord::ADOPTION {
            self.adoption(&AdoptionMsg::from(t))
        } else if t.object == 0 {
            self.sample(&SampleMsg::from(t))
        } else {
            self.other_object(t)
        }
    }
    /// The name `/object` gives object `k` (the scene's; without one, its index past the first).
    fn object_name(&self, k: usize) -> String {
        match &self.scene {
            Some(s) => s.object_name(k),
            None if k == 0 => String::new(),
            None => k.to_string(),
        }
    }
    /// Whether the world has several objects (`/object` names them and says which the tool
    /// touches).
    fn several(&self) -> bool {
        self.scene.as_ref().is_some_and(|s| !s.others.is_empty())
    }
    /// `/object` of the world's object `t.object` (1 or later), in the same part as the first's;
    /// with a scene, its `/tf` frame (its entity goes with the first's `/scene`).
    ///
    /// # Errors
    /// Writing failed.
    fn other_object(&mut self, t: &TraceRecord) -> Result<(), RecordingError> {
        let k = usize::try_from(t.object).unwrap_or(usize::MAX);
        let object = ObjectPart {
            t_ns: t.t_ns,
            site: self.site.clone(),
            object: self.object_name(k),
            pos: t.pos,
            rot: t.rot,
            vel: t.vel,
            adoptions: t.adoptions,
            touching: Some(t.touching != 0),
        };
        let mut slot = self.parts.next()?;
        slot.json(Topic::Object, t.t_ns, &object)?;
        let wall = slot.wall_ns(t.t_ns);
        if let Some(f) = self
            .scene
            .as_ref()
            .and_then(|s| s.other_transform(k, t.pos, t.rot, wall))
        {
            slot.foxglove(FoxgloveTopic::Tf, t.t_ns, &f)?;
        }
        Ok(())
    }
    /// `/object` and `/tool`, in the same part; with a scene, the sample's `/tf` frames and, every
    /// [`SCENE_EVERY`] (and first in each part), its `/scene`.
    ///
    /// # Errors
    /// Writing failed.
    pub(super) fn sample(&mut self, m: &SampleMsg) -> Result<(), RecordingError> {
        let object = ObjectPart {
            t_ns: m.t_ns,
            site: self.site.clone(),
            object: self.object_name(0),
            pos: m.pos,
            rot: m.rot,
            vel: m.vel,
            adoptions: m.adoptions,
            touching: self.several().then_some(m.touching),
        };
        let tool = ToolPart {
            t_ns: m.t_ns,
            site: self.site.clone(),
            tool_pos: m.tool_pos,
            f_desired: m.f_desired,
            f_measured: m.f_measured,
            f_object: m.f_object,
            touching: m.touching,
        };
        let mut slot = self.parts.next()?;
        slot.json(Topic::Object, m.t_ns, &object)?;
        slot.json(Topic::Tool, m.t_ns, &tool)?;
        let Some(scene) = &self.scene else {
            return Ok(());
        };
        let wall = slot.wall_ns(m.t_ns);
        let frames = scene.transforms(m, wall);
        // A part's first sample has its scene: the last one written may be in an earlier part.
        let due = match self.scene_at {
            Some((part, t)) if part == slot.number() => {
                m.t_ns.saturating_sub(t) >= SCENE_EVERY.as_nanos() as u64
            }
            _ => true,
        };
        let update = due.then(|| scene.update(m, wall));
        for f in &frames {
            slot.foxglove(FoxgloveTopic::Tf, m.t_ns, f)?;
        }
        if let Some(u) = update {
            slot.foxglove(FoxgloveTopic::Scene, m.t_ns, &u)?;
            self.scene_at = Some((slot.number(), m.t_ns));
        }
        Ok(())
    }
    /// One message on `topic`, in the current part or the next.
    fn one<T: serde::Serialize>(
        &mut self,
        topic: Topic,
        t_ns: u64,
        m: &T,
    ) -> Result<(), RecordingError> {
        self.parts.next()?.json(topic, t_ns, m)
    }
    /// `/adoption`.
    ///
    /// # Errors
    /// Writing failed.
    pub(super) fn adoption(&mut self, m: &AdoptionMsg) -> Result<(), RecordingError> {
        self.one(Topic::Adoption, m.t_ns, m)
    }
    /// `/remote`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn remote(&mut self, m: &RemoteMsg) -> Result<(), RecordingError> {
        self.one(Topic::Remote, m.t_ns, m)
    }
    /// `/presence`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn presence(&mut self, m: &PresenceMsg) -> Result<(), RecordingError> {
        let what = if m.present { "joined" } else { "left" };
        let text = format!("{} {what}", m.site);
        self.one_logged(Topic::Presence, m.t_ns, m, Level::Info, text)
    }
    /// `/peer`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn peer(&mut self, m: &PeerMsg) -> Result<(), RecordingError> {
        let (level, text) = match m.event.as_str() {
            "lost" => (
                Level::Warning,
                format!("{} lost: silent for {:.3} s", m.site, m.silent_s),
            ),
            e => (
                Level::Info,
                format!("{} {e} after {:.3} s of silence", m.site, m.silent_s),
            ),
        };
        self.one_logged(Topic::Peer, m.t_ns, m, level, text)
    }
    /// `/task` (and, with a scene, its `/log` line): the task's outcome changed.
    ///
    /// # Errors
    /// Writing failed.
    pub fn task(&mut self, m: &TaskMsg) -> Result<(), RecordingError> {
        let (level, text) = m.said();
        self.one_logged(Topic::Task, m.t_ns, m, level, text)
    }
    /// A station event for `/log` only (nothing without a scene): `level` is Foxglove's.
    ///
    /// # Errors
    /// Writing failed.
    pub fn event(&mut self, t_ns: u64, level: Level, text: String) -> Result<(), RecordingError> {
        let mut slot = self.parts.next()?;
        log(&mut slot, self.scene.as_ref(), t_ns, level, text)
    }
    /// `/clock`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn clock(&mut self, m: &ClockMsg) -> Result<(), RecordingError> {
        self.one(Topic::Clock, m.t_ns, m)
    }
    /// `/status`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn status(&mut self, m: &StatusMsg) -> Result<(), RecordingError> {
        let refused: u64 = m.refused.iter().sum();
        let text = format!(
            "station stopping: {} published, {} received, {refused} refused",
            m.published, m.received
        );
        self.one_logged(Topic::Status, m.t_ns, m, Level::Info, text)
    }
    /// `/published`.
    ///
    /// # Errors
    /// Writing failed.
    pub fn published(&mut self, m: &PublishedMsg) -> Result<(), RecordingError> {
        self.one(Topic::Published, m.t_ns, m)
    }
    /// One message on `topic` and, with a scene, its `/log` line, in the same part.
    fn one_logged<T: serde::Serialize>(
        &mut self,
        topic: Topic,
        t_ns: u64,
        m: &T,
        level: Level,
        text: String,
    ) -> Result<(), RecordingError> {
        let mut slot = self.parts.next()?;
        slot.json(topic, t_ns, m)?;
        log(&mut slot, self.scene.as_ref(), t_ns, level, text)
    }

    /// Writes the current part's summary and footer and closes it.
    ///
    /// # Errors
    /// Writing failed.
    pub fn finish(self) -> Result<(), RecordingError> {
        self.parts.finish()
    }
}

/// A `/log` line at `t_ns` in `slot`, when the recording has a scene.
fn log(
    slot: &mut Slot<'_>,
    scene: Option<&Scene>,
    t_ns: u64,
    level: Level,
    text: String,
) -> Result<(), RecordingError> {
    let Some(scene) = scene else {
        return Ok(());
    };
    let m = scene.log(slot.wall_ns(t_ns), level, text);
    slot.foxglove(FoxgloveTopic::Log, t_ns, &m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::test_support::{bytes_bound, messages, scratch};
    use crate::recording::{part_path, read, read_part, scene};
    use foxglove::messages::{FrameTransform, Log, SceneUpdate};

    #[test]
    fn a_trace_record_is_written_as_the_sample_and_adoption_messages_are() {
        let dir = std::env::temp_dir().join(format!("coop-rec-trace-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let mut t = TraceRecord {
            kind: TraceRecord::SAMPLE,
            t_ns: 42,
            object: 0,
            pos: [0.1, 0.2, 0.3],
            rot: [1.0, 0.0, 0.0, 0.0],
            vel: [1.5, 0.0, -2.0],
            tool_pos: [3.0, 4.0, 5.0],
            f_desired: [0.5, 0.25, 0.0],
            f_measured: [-1.0, 0.0, 1.0],
            f_object: [7.0, 8.0, 9.0],
            touching: 1,
            adoptions: 3,
            from: 1,
            jump_m: 0.01,
            age_s: 0.2,
        };
        let by_trace = dir.join("trace.mcap");
        let mut w = Recorder::create(&by_trace, BTreeMap::new(), Rotation::NONE).expect("create");
        w.trace(&t).expect("w");
        t.kind = TraceRecord::ADOPTION;
        t.t_ns = 43;
        w.trace(&t).expect("w");
        w.finish().expect("finish");
        // The same, copied field by field the way the network loop did before `trace`.
        let by_fields = dir.join("fields.mcap");
        let mut w = Recorder::create(&by_fields, BTreeMap::new(), Rotation::NONE).expect("create");
        w.sample(&SampleMsg {
            t_ns: 42,
            pos: [0.1, 0.2, 0.3],
            rot: [1.0, 0.0, 0.0, 0.0],
            vel: [1.5, 0.0, -2.0],
            adoptions: 3,
            tool_pos: [3.0, 4.0, 5.0],
            f_desired: [0.5, 0.25, 0.0],
            f_measured: [-1.0, 0.0, 1.0],
            f_object: [7.0, 8.0, 9.0],
            touching: true,
        })
        .expect("w");
        w.adoption(&AdoptionMsg {
            t_ns: 43,
            from: 1,
            jump_m: 0.01,
            age_s: 0.2,
        })
        .expect("w");
        w.finish().expect("finish");
        let (a, b) = (messages(&by_trace), messages(&by_fields));
        let topics: Vec<&str> = a.iter().map(|m| m.0.as_str()).collect();
        assert_eq!(topics, ["/object", "/tool", "/adoption"]);
        assert_eq!(a, b, "the same channels and the same JSON");
        let r = read(&by_trace).expect("read");
        assert_eq!(r.samples.len(), 1);
        assert_eq!(r.samples[0].f_object, [7.0, 8.0, 9.0]);
        assert!(r.samples[0].touching);
        assert_eq!(r.adoptions[0].from, 1);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn with_a_scene_every_part_holds_the_foxglove_channels_and_opens_alone() {
        use foxglove::Decode;
        let dir = scratch("foxglove");
        let path = dir.join("b.mcap");
        let scene = Scene {
            site: "b".into(),
            colour: scene::site_colour(1),
            object: scene::Body::Box {
                half: [0.02, 0.03, 0.04],
            },
            tool_radius_m: 0.005,
            planes: vec![([0.0, 0.0, 1.0], 0.0)],
            others: Vec::new(),
            first_name: String::new(),
        };
        let meta = BTreeMap::from([("site".into(), "b".into())]);
        let mut w = Recorder::create_with_scene(&path, meta, bytes_bound(64 << 10, 0), scene)
            .expect("create");
        let t0 = 1_000_000_000;
        w.session(&SessionMsg {
            t_ns: t0,
            site: "b".into(),
            ..SessionMsg::default()
        })
        .expect("w");
        let n = 1000u64;
        for i in 0..n {
            let t_ns = t0 + i * 5_000_000; // 200 Hz
            w.sample(&SampleMsg {
                t_ns,
                pos: [0.001 * i as f64, 0.0, 0.04],
                rot: [1.0, 0.0, 0.0, 0.0],
                tool_pos: [0.0, 0.0, 0.1],
                f_object: [1.0, 0.0, 0.0],
                ..SampleMsg::default()
            })
            .expect("w");
            if i == 500 {
                w.peer(&PeerMsg {
                    t_ns,
                    site: "a".into(),
                    event: "lost".into(),
                    silent_s: 0.5,
                })
                .expect("w");
            }
        }
        w.status(&StatusMsg::default()).expect("w");
        w.finish().expect("finish");
        let r = read(&path).expect("read");
        assert!(r.files.len() >= 3, "rotated: {:?}", r.files);
        assert_eq!(r.samples.len() as u64, n, "the JSON channels are as before");
        let (mut frames, mut logs) = (0u64, Vec::new());
        let mut last_tf = 0u64;
        for part in &r.files {
            let bytes = std::fs::read(part).expect("read");
            let summary = mcap::Summary::read(&bytes)
                .expect("summary")
                .expect("whole");
            let schemas: Vec<(String, String)> = summary
                .channels
                .values()
                .filter(|c| c.message_encoding == "protobuf")
                .map(|c| {
                    let s = c.schema.as_ref().expect("schema");
                    (c.topic.clone(), s.name.clone())
                })
                .collect();
            assert_eq!(
                schemas.len(),
                3,
                "{}: the Foxglove channels in every part: {schemas:?}",
                part.display()
            );
            let mut first_scene = None;
            let mut first_tf = None;
            for m in mcap::MessageStream::new(&bytes).expect("mcap") {
                let m = m.expect("message");
                let schema = m.channel.schema.as_ref().expect("schema");
                match m.channel.topic.as_str() {
                    "/tf" => {
                        assert_eq!(schema.name, "foxglove.FrameTransform");
                        assert_eq!(schema.encoding, "protobuf");
                        assert!(!schema.data.is_empty(), "the FileDescriptorSet");
                        let f = FrameTransform::decode(&m.data[..]).expect("decode");
                        assert_eq!(f.parent_frame_id, "world");
                        assert!(["object/b", "tool/b"].contains(&f.child_frame_id.as_str()));
                        assert!(m.log_time >= last_tf, "/tf in time order");
                        assert_eq!(
                            f.timestamp.map(|t| t.total_nanos()),
                            Some(m.log_time),
                            "the frame's time is the message's"
                        );
                        last_tf = m.log_time;
                        first_tf.get_or_insert(m.sequence);
                        frames += 1;
                    }
                    "/scene" => {
                        assert_eq!(schema.name, "foxglove.SceneUpdate");
                        let u = SceneUpdate::decode(&m.data[..]).expect("decode");
                        let ids: Vec<&str> = u.entities.iter().map(|e| e.id.as_str()).collect();
                        assert_eq!(ids, ["environment", "object/b", "tool/b", "force/b"]);
                        assert_eq!(
                            u.entities[1].cubes[0].size.map(|v| (v.x, v.y, v.z)),
                            Some((0.04, 0.06, 0.08))
                        );
                        first_scene.get_or_insert(m.sequence);
                    }
                    "/log" => {
                        assert_eq!(schema.name, "foxglove.Log");
                        logs.push(Log::decode(&m.data[..]).expect("decode"));
                    }
                    _ => {}
                }
            }
            // (The last part may hold only the final status, no sample.)
            assert!(
                first_tf.is_none()
                    || (first_scene.is_some() && first_scene < first_tf.map(|s| s + 3)),
                "{}: the part's scene comes with its first sample ({first_scene:?}, {first_tf:?})",
                part.display()
            );
        }
        assert_eq!(frames, 2 * n, "two frames per sample");
        let texts: Vec<&str> = logs.iter().map(|l| l.message.as_str()).collect();
        assert_eq!(texts.len(), 3, "{texts:?}");
        assert!(texts[0].starts_with("station b started"), "{texts:?}");
        assert!(texts[1].starts_with("a lost"), "{texts:?}");
        assert_eq!(logs[1].level, Level::Warning as i32);
        assert!(texts[2].starts_with("station stopping"), "{texts:?}");
        assert!(logs.iter().all(|l| l.name == "b"));
        // Cut short: the part still reads, our JSON and the Foxglove messages up to the cut.
        let part = part_path(&path, 1);
        let bytes = std::fs::read(&part).expect("bytes");
        std::fs::write(&part, &bytes[..bytes.len() / 2]).expect("cut");
        let alone = read_part(&part).expect("a cut part reads alone");
        assert!(alone.truncated && !alone.samples.is_empty());
        let cut = std::fs::read(&part).expect("bytes");
        let tf =
            mcap::MessageStream::new_with_options(&cut, mcap::read::Options::IgnoreEndMagic.into())
                .expect("mcap")
                .map_while(Result::ok)
                .filter(|m| m.channel.topic == "/tf")
                .count();
        assert!(tf > 0, "frames before the cut");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
