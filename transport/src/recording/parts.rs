//! A recording's parts: when one is finished and the next begun ([`Rotation`]), their names
//! ([`part_path`]), finding them on disk, and [`Parts`], the sequence of them a recorder writes.
//!
//! A recorder writes only through a [`Slot`], and [`Parts::next`] alone gives one, after it has
//! begun the next part if the current one is full: no message can skip the rotation check.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use foxglove::Encode;
use serde::Serialize;

use super::messages::SessionMsg;
use super::part::Part;
use super::topic::{FoxgloveTopic, Topic};
use super::{io_err, RecordingError, FLUSH_EVERY, STATION_RUN};

/// How much of a part's beginning is read for its metadata (written right after its header).
const HEAD_BYTES: u64 = 64 << 10;

/// When a part of a recording is finished and the next begun, and how many parts are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rotation {
    /// A part that holds this many bytes is finished (`None`: no size bound).
    pub max_file_bytes: Option<u64>,
    /// A part written for this long is finished (`None`: no time bound).
    pub max_file_duration: Option<Duration>,
    /// Parts kept on disk, the oldest removed beyond them (0: all are kept).
    pub keep_files: usize,
}

impl Rotation {
    /// One file, however large it grows.
    pub const NONE: Rotation = Rotation {
        max_file_bytes: None,
        max_file_duration: None,
        keep_files: 0,
    };
}

/// The file of part `n` of the recording whose first part is `first`: `first` itself for 0, else
/// the number before the extension (`user1.mcap`, `user1.1.mcap`, `user1.2.mcap`, …; `rec`,
/// `rec.1`, … without one).
pub fn part_path(first: &Path, n: u32) -> PathBuf {
    if n == 0 {
        return first.to_owned();
    }
    let (stem, ext) = stem_and_ext(first);
    first.with_file_name(match ext {
        Some(e) => format!("{stem}.{n}.{e}"),
        None => format!("{stem}.{n}"),
    })
}

fn stem_and_ext(first: &Path) -> (String, Option<String>) {
    let lossy = |s: &std::ffi::OsStr| s.to_string_lossy().into_owned();
    match (first.file_stem(), first.extension()) {
        (Some(s), Some(e)) => (lossy(s), Some(lossy(e))),
        _ => (first.file_name().map(lossy).unwrap_or_default(), None),
    }
}

/// The parts of the recording whose first part is `first` that are on disk, by number.
pub(super) fn parts_on_disk(first: &Path) -> std::io::Result<Vec<(u32, PathBuf)>> {
    let (stem, ext) = stem_and_ext(first);
    let dir = match first.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut parts = Vec::new();
    if first.is_file() {
        parts.push((0, first.to_owned()));
    }
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(parts),
        Err(e) => return Err(e),
    };
    for entry in entries {
        let name = entry?.file_name();
        let Some(name) = name.to_str() else { continue };
        let number = name
            .strip_prefix(stem.as_str())
            .and_then(|r| r.strip_prefix('.'));
        let number = match &ext {
            Some(e) => number.and_then(|r| r.strip_suffix(e.as_str())?.strip_suffix('.')),
            None => number,
        };
        // Only the names `part_path` writes (no `user1.01.mcap`).
        if let Some(n) = number
            .and_then(|d| d.parse::<u32>().ok())
            .filter(|&n| n > 0 && part_path(first, n).file_name() == Some(name.as_ref()))
        {
            parts.push((n, part_path(first, n)));
        }
    }
    parts.sort();
    Ok(parts)
}

/// The first [`HEAD_BYTES`] of a file.
fn head_of(path: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut head = Vec::new();
    File::open(path)?.take(HEAD_BYTES).read_to_end(&mut head)?;
    Ok(head)
}

/// The newest part on disk of the recording at `first` that holds metadata, with its
/// `started_unix_ns`, if it is of the station run, session and site `metadata` names (none when
/// `metadata` names no [`STATION_RUN`]).
fn same_run_part(
    first: &Path,
    metadata: &BTreeMap<String, String>,
) -> Result<Option<(u32, String)>, RecordingError> {
    if metadata.get(STATION_RUN).is_none_or(String::is_empty) {
        return Ok(None);
    }
    for (n, path) in parts_on_disk(first)
        .map_err(io_err(first))?
        .into_iter()
        .rev()
    {
        let meta = metadata_of(&head_of(&path).map_err(io_err(&path))?);
        if meta.is_empty() {
            // Cut before its metadata reached the disk: look at the part before.
            continue;
        }
        let same = [STATION_RUN, "session", "site"]
            .into_iter()
            .all(|k| meta.get(k) == metadata.get(k));
        return Ok(match meta.get("started_unix_ns") {
            Some(started) if same => Some((n, started.clone())),
            _ => None,
        });
    }
    Ok(None)
}

/// The metadata record of a part (empty when it has none).
pub(super) fn metadata_of(bytes: &[u8]) -> BTreeMap<String, String> {
    let Ok(records) = mcap::read::LinearReader::new_with_options(
        bytes,
        mcap::read::Options::IgnoreEndMagic.into(),
    ) else {
        return BTreeMap::new();
    };
    for record in records {
        match record {
            Ok(mcap::records::Record::Metadata(m)) if m.name == "coop-haptics" => {
                return m.metadata
            }
            // Written before any schema, channel or message.
            Ok(mcap::records::Record::Header(_) | mcap::records::Record::Metadata(_)) => {}
            _ => break,
        }
    }
    BTreeMap::new()
}

/// The parts a recorder writes: the current one, what the next begins with, and each message's
/// sequence number and wall-clock log time.
pub(super) struct Parts {
    part: Part,
    first: PathBuf,
    /// The station's metadata and `started_unix_ns` (each part adds its `part`).
    metadata: BTreeMap<String, String>,
    rotation: Rotation,
    /// Whether every part has Foxglove's channels.
    with_foxglove: bool,
    /// The `/session` message, once written: repeated at the top of every later part.
    session: Option<SessionMsg>,
    /// Messages written in the current part besides the repeated `/session`.
    messages: u64,
    seq: u32,
    wall_minus_mono: i128,
    last_flush: Instant,
}

impl Parts {
    /// Begins the recording whose first part is `first`, with a station's JSON channels (and,
    /// `with_foxglove`, Foxglove's) in every part. Afresh, every part an earlier recording left at
    /// `first` is removed and part 0 created; `may_continue` and `metadata` naming the same
    /// [`STATION_RUN`], session and site as the newest part on disk that holds metadata, the
    /// recording goes on in the part after that one, its `started_unix_ns` kept. Also returns
    /// the number of the part continued from.
    ///
    /// # Errors
    /// A part cannot be created, written, read or removed.
    pub(super) fn open(
        first: &Path,
        mut metadata: BTreeMap<String, String>,
        rotation: Rotation,
        with_foxglove: bool,
        may_continue: bool,
    ) -> Result<(Self, Option<u32>), RecordingError> {
        let earlier = if may_continue {
            same_run_part(first, &metadata)?
        } else {
            None
        };
        let wall = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as i128);
        let mono = i128::from(coop_rt::timer::monotonic_ns());
        // Continuing: the parts after the earlier one hold no metadata (cut before any reached
        // the disk), so nothing of the recording is in them and `read` could not read past them.
        // Afresh: every part of an earlier recording goes (the first is written over).
        let continued = earlier.as_ref().map(|(n, _)| *n);
        let (number, started) = match earlier {
            Some((n, started)) => (n + 1, started),
            None => (0, wall.to_string()),
        };
        for (m, old) in parts_on_disk(first).map_err(io_err(first))? {
            if m > continued.unwrap_or(0) {
                std::fs::remove_file(&old).map_err(io_err(&old))?;
            }
        }
        metadata.insert("started_unix_ns".into(), started);
        let parts = Self {
            part: Part::create(
                part_path(first, number),
                number,
                &metadata,
                &Topic::STATION,
                with_foxglove,
                false,
            )?,
            first: first.to_owned(),
            metadata,
            rotation,
            with_foxglove,
            session: None,
            messages: 0,
            seq: 0,
            wall_minus_mono: wall - mono,
            last_flush: Instant::now(),
        };
        parts.remove_beyond_kept()?;
        Ok((parts, continued))
    }

    /// The file being written.
    pub(super) fn path(&self) -> &Path {
        self.part.path()
    }

    /// The number of the part being written.
    pub(super) fn number(&self) -> u32 {
        self.part.number()
    }

    /// The sequence number of the last message written.
    pub(super) fn seq(&self) -> u32 {
        self.seq
    }

    /// The part the next message goes in: when the current one is full, finishes it, begins the
    /// next (the `/session` message at its top) and removes the oldest part beyond the ones kept.
    /// Messages written through one slot stay together in one part.
    ///
    /// # Errors
    /// Writing, creating or removing a part failed.
    pub(super) fn next(&mut self) -> Result<Slot<'_>, RecordingError> {
        if self.full() {
            self.rotate()?;
        }
        Ok(Slot { parts: self })
    }

    /// Writes the current part's summary and footer and closes it.
    pub(super) fn finish(self) -> Result<(), RecordingError> {
        self.part.finish()
    }

    /// Whether the current part has reached a bound (a part takes at least one message).
    fn full(&self) -> bool {
        let r = &self.rotation;
        self.messages > 0
            && (r.max_file_bytes.is_some_and(|b| self.part.bytes() >= b)
                || r.max_file_duration.is_some_and(|d| self.part.age() >= d))
    }

    /// Finishes the current part and begins the next.
    fn rotate(&mut self) -> Result<(), RecordingError> {
        let number = self.part.number() + 1;
        let next = Part::create(
            part_path(&self.first, number),
            number,
            &self.metadata,
            &Topic::STATION,
            self.with_foxglove,
            false,
        )?;
        std::mem::replace(&mut self.part, next).finish()?;
        self.remove_beyond_kept()?;
        if let Some(s) = self.session.clone() {
            self.put_json(Topic::Session, s.t_ns, &s)?;
        }
        self.messages = 0;
        Ok(())
    }

    /// Removes the oldest part beyond the ones kept, counting the one being written as the newest.
    fn remove_beyond_kept(&self) -> Result<(), RecordingError> {
        let number = self.part.number();
        let keep = u32::try_from(self.rotation.keep_files).unwrap_or(u32::MAX);
        if keep > 0 && number >= keep {
            let oldest = part_path(&self.first, number - keep);
            match std::fs::remove_file(&oldest) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(io_err(&oldest)(e));
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// The wall clock (ns since the Unix epoch) of monotonic time `t_ns`.
    fn wall_ns(&self, t_ns: u64) -> u64 {
        u64::try_from(i128::from(t_ns) + self.wall_minus_mono).unwrap_or(0)
    }

    fn put_json<T: Serialize>(
        &mut self,
        topic: Topic,
        t_ns: u64,
        msg: &T,
    ) -> Result<(), RecordingError> {
        let channel_id = self.part.channel(topic)?;
        let data = serde_json::to_vec(msg).unwrap_or_default();
        self.put_bytes(channel_id, t_ns, &data)
    }

    fn put_bytes(&mut self, channel_id: u16, t_ns: u64, data: &[u8]) -> Result<(), RecordingError> {
        self.seq = self.seq.wrapping_add(1);
        let log_time = self.wall_ns(t_ns);
        self.part.write(channel_id, self.seq, log_time, data)?;
        self.messages += 1;
        if self.last_flush.elapsed() >= FLUSH_EVERY {
            self.last_flush = Instant::now();
            self.part.flush()?;
        }
        Ok(())
    }
}

/// The part a message goes in, once [`Parts::next`] has begun the next part if the last was
/// full: the only way a recorder writes.
pub(super) struct Slot<'a> {
    parts: &'a mut Parts,
}

impl Slot<'_> {
    /// The number of the part.
    pub(super) fn number(&self) -> u32 {
        self.parts.number()
    }

    /// The wall clock (ns since the Unix epoch) of monotonic time `t_ns`, the log time of a
    /// message at `t_ns`.
    pub(super) fn wall_ns(&self, t_ns: u64) -> u64 {
        self.parts.wall_ns(t_ns)
    }

    /// `/session`, kept to be repeated at the top of every later part. Returns whether it is the
    /// first.
    ///
    /// # Errors
    /// Writing failed.
    pub(super) fn session(&mut self, m: &SessionMsg) -> Result<bool, RecordingError> {
        let first = self.parts.session.is_none();
        self.parts.session = Some(m.clone());
        self.parts.put_json(Topic::Session, m.t_ns, m)?;
        Ok(first)
    }

    /// A message on JSON channel `topic` at `t_ns` (`/session` goes through [`Slot::session`]).
    ///
    /// # Errors
    /// Writing failed.
    pub(super) fn json<T: Serialize>(
        &mut self,
        topic: Topic,
        t_ns: u64,
        msg: &T,
    ) -> Result<(), RecordingError> {
        self.parts.put_json(topic, t_ns, msg)
    }

    /// A protobuf message on Foxglove channel `topic` at `t_ns`; nothing when the parts have no
    /// Foxglove channels.
    ///
    /// # Errors
    /// Writing failed.
    pub(super) fn foxglove<T: Encode>(
        &mut self,
        topic: FoxgloveTopic,
        t_ns: u64,
        msg: &T,
    ) -> Result<(), RecordingError> {
        match self.parts.part.foxglove_channel(topic) {
            Some(id) => self.parts.put_bytes(id, t_ns, &super::scene::encode(msg)),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::test_support::{bytes_bound, files_in, messages, record, scratch};
    use crate::recording::{
        read, read_part, scene, AdoptionMsg, ClockMsg, PeerMsg, PresenceMsg, PublishedMsg,
        Recorder, Recording, RemoteMsg, SampleMsg, Scene, StatusMsg,
    };

    #[test]
    fn parts_are_named_after_the_first() {
        let p = |s: &str, n| part_path(Path::new(s), n).display().to_string();
        assert_eq!(p("out/user1.mcap", 0), "out/user1.mcap");
        assert_eq!(p("out/user1.mcap", 1), "out/user1.1.mcap");
        assert_eq!(p("out/user1.mcap", 12), "out/user1.12.mcap");
        assert_eq!(p("a.b.mcap", 2), "a.b.2.mcap");
        assert_eq!(p("rec", 3), "rec.3");
    }

    #[test]
    fn a_bounded_recording_goes_on_in_parts_each_readable_alone_and_read_as_one() {
        let dir = scratch("parts");
        let (whole, parted) = (dir.join("whole.mcap"), dir.join("user1.mcap"));
        record(&whole, "s", 300, Rotation::NONE);
        let bound = 8 << 10;
        record(&parted, "s", 300, bytes_bound(bound, 0));
        let on_disk = parts_on_disk(&parted).expect("parts");
        assert!(on_disk.len() >= 4, "{:?}", files_in(&dir));
        assert_eq!(
            on_disk.iter().map(|p| p.0).collect::<Vec<_>>(),
            (0..on_disk.len() as u32).collect::<Vec<_>>()
        );
        let want = read_part(&whole).expect("whole");
        assert!(!want.truncated && want.samples.len() == 300);
        // Each part alone: a whole MCAP file with the session at its top, its number in its
        // metadata, and about the bound's size (plus its summary).
        let mut concatenated = Vec::new();
        for (n, path) in &on_disk {
            let alone = read_part(path).expect("a part reads alone");
            assert!(!alone.truncated, "{}", path.display());
            assert_eq!(alone.session, want.session, "{}", path.display());
            assert!(!alone.samples.is_empty(), "{}", path.display());
            let bytes = std::fs::read(path).expect("bytes");
            let meta = metadata_of(&bytes);
            assert_eq!(meta["part"], n.to_string());
            assert_eq!(meta["session"], "s");
            assert!(meta.contains_key("started_unix_ns"));
            assert!(
                bytes.len() < (bound as usize) + (8 << 10),
                "{}",
                bytes.len()
            );
            let m = messages(path);
            assert_eq!(m[0].0, "/session", "{}", path.display());
            concatenated.extend(m.into_iter().skip(usize::from(*n > 0)));
        }
        // Together: the same messages in the same order as the unbounded recording.
        assert_eq!(concatenated, messages(&whole));
        let got = read(&parted).expect("read the parts");
        assert_eq!(
            got.files,
            on_disk.into_iter().map(|p| p.1).collect::<Vec<_>>()
        );
        assert_eq!(
            Recording {
                files: want.files.clone(),
                ..got
            },
            want
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_part_written_for_its_time_bound_is_finished() {
        let dir = scratch("time");
        let path = dir.join("t.mcap");
        let rotation = Rotation {
            max_file_bytes: None,
            max_file_duration: Some(Duration::from_millis(20)),
            keep_files: 0,
        };
        let mut w = Recorder::create(&path, BTreeMap::new(), rotation).expect("create");
        for k in 0..3 {
            w.published(&PublishedMsg {
                t_ns: k,
                seq: k,
                state_ns: k,
            })
            .expect("w");
            assert_eq!(w.path(), part_path(&path, k as u32));
            std::thread::sleep(Duration::from_millis(25));
        }
        w.finish().expect("finish");
        assert_eq!(files_in(&dir), ["t.1.mcap", "t.2.mcap", "t.mcap"]);
        assert_eq!(read(&path).expect("read").published.len(), 3);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn beyond_the_parts_kept_the_oldest_are_removed_and_the_rest_still_read() {
        let dir = scratch("keep");
        let (whole, parted) = (dir.join("whole.mcap"), dir.join("user1.mcap"));
        record(&whole, "s", 300, Rotation::NONE);
        record(&parted, "s", 300, bytes_bound(8 << 10, 3));
        let on_disk = parts_on_disk(&parted).expect("parts");
        assert_eq!(on_disk.len(), 3, "{:?}", files_in(&dir));
        assert!(on_disk[0].0 > 0 && !parted.exists(), "the first part went");
        let want = read_part(&whole).expect("whole");
        let got = read(&parted).expect("the kept parts read without the first");
        assert_eq!(got.session, want.session, "each part repeats the session");
        assert!(got.samples.len() < 300);
        assert_eq!(got.samples[..], want.samples[300 - got.samples.len()..]);
        assert_eq!(got.status, want.status);
        // A new recording at the same path removes what the last one left.
        record(&parted, "s", 5, Rotation::NONE);
        assert_eq!(files_in(&dir), ["user1.mcap", "whole.mcap"]);
        assert_eq!(read(&parted).expect("read").samples.len(), 5);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A network process killed mid-recording and restarted in the same station run: the new
    /// recorder goes on in the next part and the recording reads as one, with what the killed one
    /// got to the disk; a new run of the station starts afresh, and a part cut before its metadata
    /// reached the disk is written over.
    #[test]
    fn the_same_station_run_continues_its_recording_and_a_new_run_starts_afresh() {
        let dir = scratch("continue");
        let path = dir.join("user1.mcap");
        let meta = |run: &str| {
            BTreeMap::from([
                ("session".into(), "s".into()),
                ("site".into(), "user1".into()),
                (STATION_RUN.into(), run.into()),
            ])
        };
        let scene = || Scene {
            site: "user1".into(),
            colour: scene::site_colour(0),
            object: scene::Body::Box {
                half: [0.02, 0.02, 0.02],
            },
            tool_radius_m: 0.005,
            planes: Vec::new(),
            others: Vec::new(),
            first_name: String::new(),
        };
        let session = SessionMsg {
            t_ns: 1,
            session: "s".into(),
            site: "user1".into(),
            ..SessionMsg::default()
        };
        let sample = |k: u64| SampleMsg {
            t_ns: 10 + 10 * k,
            pos: [k as f64, 0.0, 0.0],
            rot: [1.0, 0.0, 0.0, 0.0],
            ..SampleMsg::default()
        };
        // (The Foxglove schemas alone take some 10 KiB of every part.)
        let rotation = bytes_bound(64 << 10, 0);
        let mut first = Recorder::continue_or_create(&path, meta("run-a"), rotation, Some(scene()))
            .expect("create");
        assert_eq!(first.continued(), None, "nothing to continue yet");
        first.session(&session).expect("w");
        for k in 0..1000 {
            first.sample(&sample(k)).expect("w");
        }
        let killed_in = first.parts.number();
        assert!(
            (2..10).contains(&killed_in),
            "rotated a few times first: {killed_in}"
        );
        // Killed: nothing more is flushed, no footer written.
        std::mem::forget(first);
        let before = read(&path).expect("the killed process's parts read");
        assert!(before.samples.len() >= 500, "{}", before.samples.len());

        let mut second =
            Recorder::continue_or_create(&path, meta("run-a"), rotation, Some(scene()))
                .expect("continue");
        assert_eq!(second.continued(), Some(killed_in));
        assert_eq!(second.path(), part_path(&path, killed_in + 1));
        second.session(&session).expect("w");
        for k in 2000..2100 {
            second.sample(&sample(k)).expect("w");
        }
        second.status(&StatusMsg::default()).expect("w");
        let last = second.parts.number();
        second.finish().expect("finish");
        let r = read(&path).expect("one recording");
        assert_eq!(r.files.len() as u32, last + 1, "{:?}", files_in(&dir));
        assert!(r.truncated, "the killed process's last part has no footer");
        assert_eq!(
            r.samples[..before.samples.len()],
            before.samples[..],
            "what the killed process wrote is all there"
        );
        let after: Vec<f64> = r.samples[before.samples.len()..]
            .iter()
            .map(|s| s.pos[0])
            .collect();
        assert_eq!(after, (2000..2100).map(|k| k as f64).collect::<Vec<_>>());
        let texts: Vec<&str> = r.logs.iter().map(|l| l.text.as_str()).collect();
        let again = format!(
            "station user1 recording again in session s after its network process restarted: part {} goes on from part {killed_in}",
            killed_in + 1
        );
        assert_eq!(
            texts.first().copied(),
            Some("station user1 started in session s: scenario , method , emulation ")
        );
        assert!(texts.contains(&again.as_str()), "{texts:?}");

        // A part begun and killed before its metadata reached the disk is written over.
        let empty = part_path(&path, last + 1);
        File::create(&empty).expect("an empty part");
        let third =
            Recorder::continue_or_create(&path, meta("run-a"), rotation, None).expect("continue");
        assert_eq!(third.continued(), Some(last));
        assert_eq!(third.path(), empty);
        third.finish().expect("finish");
        assert_eq!(read(&path).expect("read").samples, r.samples);

        // A new run of the station: afresh, the earlier run's parts gone.
        let new_run =
            Recorder::continue_or_create(&path, meta("run-b"), rotation, None).expect("create");
        assert_eq!(new_run.continued(), None);
        assert_eq!(new_run.path(), path);
        new_run.finish().expect("finish");
        assert_eq!(files_in(&dir), ["user1.mcap"]);
        assert!(read(&path).expect("read").samples.is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Every kind of message checks the bound before it is written: with every part full after
    /// one message, each goes in a part of its own.
    #[test]
    fn every_message_begins_the_next_part_when_the_last_is_full() {
        let dir = scratch("each");
        let path = dir.join("e.mcap");
        let mut w = Recorder::create(&path, BTreeMap::new(), bytes_bound(1, 0)).expect("create");
        w.published(&PublishedMsg::default()).expect("w");
        w.remote(&RemoteMsg::default()).expect("w");
        w.presence(&PresenceMsg::default()).expect("w");
        w.peer(&PeerMsg::default()).expect("w");
        w.clock(&ClockMsg::default()).expect("w");
        w.adoption(&AdoptionMsg::default()).expect("w");
        w.sample(&SampleMsg::default()).expect("w");
        w.status(&StatusMsg::default()).expect("w");
        assert_eq!(w.path(), part_path(&path, 7), "{:?}", files_in(&dir));
        w.finish().expect("finish");
        let r = read(&path).expect("read");
        assert_eq!(r.files.len(), 8);
        for part in &r.files {
            let alone = read_part(part).expect("a part reads alone");
            let held = alone.published.len()
                + alone.remote.len()
                + alone.presence.len()
                + alone.peers.len()
                + alone.clock.len()
                + alone.adoptions.len()
                + alone.samples.len()
                + usize::from(alone.status.is_some());
            assert_eq!(held, 1, "{}", part.display());
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
