//! Reading a recording back: every part in order as one [`Recording`] ([`read`]), or one part
//! ([`read_part`]), also one cut short by a crash.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use foxglove::messages::Log;

use super::messages::{
    AdoptionMsg, ClockMsg, ObjectPart, ObjectSamples, PeerMsg, PresenceMsg, PublishedMsg,
    RemoteMsg, SampleMsg, SessionMsg, StatusMsg, TaskMsg, ToolPart,
};
use super::parts::{metadata_of, parts_on_disk};
use super::topic::{FoxgloveTopic, Topic};
use super::{io_err, mcap_err, Level, RecordingError, OBJECTS_KEY};

/// A recording, read back.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recording {
    /// The session message, if the session started.
    pub session: Option<SessionMsg>,
    /// Samples (object and tool joined by time): in a world of several objects, the first
    /// object's.
    pub samples: Vec<SampleMsg>,
    /// In a world of several objects, the others', in the world's order.
    pub others: Vec<ObjectSamples>,
    /// Adoptions.
    pub adoptions: Vec<AdoptionMsg>,
    /// Remote states handed to physics.
    pub remote: Vec<RemoteMsg>,
    /// Reports published.
    pub published: Vec<PublishedMsg>,
    /// Joins and leaves.
    pub presence: Vec<PresenceMsg>,
    /// Sites lost and heard again.
    pub peers: Vec<PeerMsg>,
    /// Clock estimates.
    pub clock: Vec<ClockMsg>,
    /// The task's outcome each time it changed.
    pub tasks: Vec<TaskMsg>,
    /// Final counters, if the station stopped cleanly.
    pub status: Option<StatusMsg>,
    /// The station's events, as `/log` holds them (with a scene only).
    pub logs: Vec<LogLine>,
    /// A file ended early (no footer): the station did not finish it.
    pub truncated: bool,
    /// The files read, in order (the parts on disk).
    pub files: Vec<PathBuf>,
}

/// A `/log` line, read back.
#[derive(Debug, Clone, PartialEq)]
pub struct LogLine {
    /// When, wall clock ns since the Unix epoch (the message's log time).
    pub unix_ns: u64,
    /// Foxglove's level.
    pub level: Level,
    /// What it says.
    pub text: String,
}

/// Reads the recording whose first part is `first`: every part on disk in order, as one
/// recording (the oldest parts may have been removed; the first need not exist then). A part cut
/// short by a crash is read up to the cut.
///
/// # Errors
/// No part, a part that cannot be read, is not MCAP or has a message that is not what its channel
/// says; a part of another recording (session, site or start differ, or its `part` is not its
/// number); a part missing between two that are there.
pub fn read(first: &Path) -> Result<Recording, RecordingError> {
    let parts = parts_on_disk(first).map_err(io_err(first))?;
    if parts.is_empty() {
        // The error of the missing first file.
        return read_part(first);
    }
    let mut r = Recording::default();
    let mut seen: Option<(u32, PathBuf, BTreeMap<String, String>)> = None;
    for (n, path) in parts {
        let bytes = std::fs::read(&path).map_err(io_err(&path))?;
        let meta = metadata_of(&bytes);
        let refuse = |why: String| RecordingError::NotThisRecording {
            path: path.display().to_string(),
            why,
        };
        if let Some(p) = meta.get("part").filter(|p| **p != n.to_string()) {
            return Err(refuse(format!(
                "its metadata says part {p}, its name part {n}"
            )));
        }
        if let Some((before, before_path, before_meta)) = &seen {
            if n != before + 1 {
                return Err(refuse(format!(
                    "part {n} follows part {before} ({}): the parts between are missing",
                    before_path.display()
                )));
            }
            for key in ["session", "site", "started_unix_ns"] {
                if meta.get(key) != before_meta.get(key) {
                    return Err(refuse(format!(
                        "a part of another recording than {}: {key} {:?}, not {:?}",
                        before_path.display(),
                        meta.get(key).map_or("(none)", String::as_str),
                        before_meta.get(key).map_or("(none)", String::as_str),
                    )));
                }
            }
        }
        let p = parse(&path, &bytes)?;
        r.session = r.session.or(p.session);
        r.samples.extend(p.samples);
        for o in p.others {
            match r.others.iter_mut().find(|x| x.name == o.name) {
                Some(x) => x.samples.extend(o.samples),
                None => r.others.push(o),
            }
        }
        r.adoptions.extend(p.adoptions);
        r.remote.extend(p.remote);
        r.published.extend(p.published);
        r.presence.extend(p.presence);
        r.peers.extend(p.peers);
        r.clock.extend(p.clock);
        r.tasks.extend(p.tasks);
        r.logs.extend(p.logs);
        r.status = p.status.or(r.status);
        r.truncated |= p.truncated;
        r.files.push(path.clone());
        seen = Some((n, path, meta));
    }
    Ok(r)
}

/// Reads one file written by [`Recorder`](super::Recorder) (one part of a recording), also one cut short by a crash.
///
/// # Errors
/// The file cannot be read, is not MCAP, or a message is not what its channel says.
pub fn read_part(path: &Path) -> Result<Recording, RecordingError> {
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    parse(path, &bytes)
}

/// The messages of one part.
fn parse(path: &Path, bytes: &[u8]) -> Result<Recording, RecordingError> {
    let bad = |what: String| RecordingError::Io {
        path: path.display().to_string(),
        error: std::io::Error::new(std::io::ErrorKind::InvalidData, what),
    };
    let stream =
        mcap::MessageStream::new_with_options(bytes, mcap::read::Options::IgnoreEndMagic.into())
            .map_err(mcap_err(path))?;
    let mut r = Recording {
        files: vec![path.to_owned()],
        ..Recording::default()
    };
    let mut tools: Vec<ToolPart> = Vec::new();
    let mut objects: Vec<ObjectPart> = Vec::new();
    for m in stream {
        let m = match m {
            Ok(m) => m,
            // A crash leaves a partly written last record: keep what came before it.
            Err(_) => {
                r.truncated = true;
                break;
            }
        };
        let data: &[u8] = &m.data;
        let name = m.channel.topic.as_str();
        let e = |err: serde_json::Error| bad(format!("{name}: {err}"));
        if name == FoxgloveTopic::Log.name() {
            let l = <Log as foxglove::Decode>::decode(data)
                .map_err(|err| bad(format!("{name}: {err}")))?;
            r.logs.push(LogLine {
                unix_ns: m.log_time,
                level: Level::try_from(l.level).unwrap_or(Level::Unknown),
                text: l.message,
            });
            continue;
        }
        let Some(topic) = Topic::named(name) else {
            continue;
        };
        match topic {
            Topic::Session => r.session = Some(serde_json::from_slice(data).map_err(e)?),
            Topic::Object => objects.push(serde_json::from_slice(data).map_err(e)?),
            Topic::Tool => tools.push(serde_json::from_slice(data).map_err(e)?),
            Topic::Adoption => r.adoptions.push(serde_json::from_slice(data).map_err(e)?),
            Topic::Remote => r.remote.push(serde_json::from_slice(data).map_err(e)?),
            Topic::Presence => r.presence.push(serde_json::from_slice(data).map_err(e)?),
            Topic::Peer => r.peers.push(serde_json::from_slice(data).map_err(e)?),
            Topic::Clock => r.clock.push(serde_json::from_slice(data).map_err(e)?),
            Topic::Status => r.status = Some(serde_json::from_slice(data).map_err(e)?),
            Topic::Published => r.published.push(serde_json::from_slice(data).map_err(e)?),
            Topic::Task => r.tasks.push(serde_json::from_slice(data).map_err(e)?),
            Topic::Divergence => {}
        }
    }
    r.truncated |= mcap::read::footer(bytes).is_err();
    join_samples(&mut r, &metadata_of(bytes), objects, tools);
    Ok(r)
}

/// Makes `r`'s samples of a part's `/object` and `/tool` messages: the first object's joined
/// with the tool's of the same time, the others' by object (`metadata` names the world's objects
/// in order, in a world of several).
fn join_samples(
    r: &mut Recording,
    metadata: &BTreeMap<String, String>,
    objects: Vec<ObjectPart>,
    tools: Vec<ToolPart>,
) {
    // The first object's part comes first at every sample (a world of one names none): the
    // others are the ones named otherwise, in the order they first appear (the world's).
    // (The recording's metadata names them in order; without it, the first seen is the first.)
    let names: Vec<String> = metadata
        .get(OBJECTS_KEY)
        .map(|n| n.split(',').map(str::to_owned).collect())
        .unwrap_or_default();
    let first_name = match names.first() {
        Some(n) => n.clone(),
        None => objects
            .first()
            .map(|o| o.object.clone())
            .unwrap_or_default(),
    };
    for n in names.iter().skip(1) {
        r.others.push(ObjectSamples {
            name: n.clone(),
            samples: Vec::new(),
        });
    }
    let (objects, others): (Vec<ObjectPart>, Vec<ObjectPart>) =
        objects.into_iter().partition(|o| o.object == first_name);
    for o in others {
        let at = match r.others.iter().position(|x| x.name == o.object) {
            Some(at) => at,
            None => {
                r.others.push(ObjectSamples {
                    name: o.object.clone(),
                    samples: Vec::new(),
                });
                r.others.len() - 1
            }
        };
        r.others[at].samples.push(SampleMsg {
            t_ns: o.t_ns,
            pos: o.pos,
            rot: o.rot,
            vel: o.vel,
            adoptions: o.adoptions,
            touching: o.touching.unwrap_or(false),
            ..SampleMsg::default()
        });
    }
    // Object and tool parts of one sample are written back to back with the same time.
    let mut tools = tools.into_iter().peekable();
    for o in objects {
        while tools.next_if(|t| t.t_ns < o.t_ns).is_some() {}
        let t = tools.next_if(|t| t.t_ns == o.t_ns);
        let mut s = SampleMsg {
            t_ns: o.t_ns,
            pos: o.pos,
            rot: o.rot,
            vel: o.vel,
            adoptions: o.adoptions,
            ..SampleMsg::default()
        };
        if let Some(t) = t {
            s.tool_pos = t.tool_pos;
            s.f_desired = t.f_desired;
            s.f_measured = t.f_measured;
            s.f_object = t.f_object;
            s.touching = t.touching;
        }
        r.samples.push(s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recording::test_support::{bytes_bound, record, scratch};
    use crate::recording::{part_path, Recorder, Rotation};

    #[test]
    fn written_then_read_back_also_when_cut_short() {
        let dir = std::env::temp_dir().join(format!("coop-rec-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("a.mcap");
        let mut w = Recorder::create(
            &path,
            BTreeMap::from([("site".into(), "a".into())]),
            Rotation::NONE,
        )
        .expect("create");
        let session = SessionMsg {
            t_ns: 1,
            session: "s".into(),
            site: "a".into(),
            epoch_ns: 5,
            ..SessionMsg::default()
        };
        w.session(&session).expect("w");
        for k in 0..100u64 {
            let s = SampleMsg {
                t_ns: 10 + k,
                pos: [k as f64, 0.0, 0.0],
                rot: [1.0, 0.0, 0.0, 0.0],
                touching: k % 2 == 0,
                ..SampleMsg::default()
            };
            w.sample(&s).expect("w");
        }
        w.adoption(&AdoptionMsg {
            t_ns: 50,
            from: 1,
            jump_m: 0.01,
            age_s: 0.2,
        })
        .expect("w");
        w.status(&StatusMsg::default()).expect("w");
        w.finish().expect("finish");
        let r = read(&path).expect("read");
        assert!(!r.truncated);
        assert_eq!(r.session, Some(session));
        assert_eq!(r.samples.len(), 100);
        assert_eq!(r.samples[7].pos[0], 7.0);
        assert!(!r.samples[7].touching && r.samples[8].touching);
        assert_eq!(r.adoptions.len(), 1);
        assert!(r.status.is_some());
        // Cut the file in the middle of the data: what was before the cut is still there.
        let bytes = std::fs::read(&path).expect("bytes");
        let cut = dir.join("cut.mcap");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write");
        let r = read(&cut).expect("a cut recording still reads");
        assert!(r.truncated);
        assert!(
            r.samples.len() > 20 && r.samples.len() < 100,
            "{}",
            r.samples.len()
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn parts_of_different_recordings_or_with_a_gap_are_refused() {
        let dir = scratch("mix");
        let a = dir.join("a").join("user1.mcap");
        let b = dir.join("b").join("user1.mcap");
        // The recorder makes no directory.
        for d in ["a", "b"] {
            std::fs::create_dir_all(dir.join(d)).expect("dir");
        }
        record(&a, "s1", 200, bytes_bound(8 << 10, 0));
        record(&b, "s2", 200, bytes_bound(8 << 10, 0));
        assert!(parts_on_disk(&a).expect("parts").len() >= 3);
        let refused = |why: &str| {
            let e = read(&a).expect_err(why).to_string();
            assert!(e.contains(why), "{e}");
            assert!(e.contains("user1.1.mcap"), "names the part: {e}");
        };
        // Another session's part 1 among ours.
        std::fs::copy(part_path(&b, 1), part_path(&a, 1)).expect("copy");
        refused("a part of another recording");
        refused("session \"s2\", not \"s1\"");
        // The same session, another run of it (written later).
        record(&b, "s1", 200, bytes_bound(8 << 10, 0));
        std::fs::copy(part_path(&b, 1), part_path(&a, 1)).expect("copy");
        refused("started_unix_ns");
        // Part 2 renamed as part 1.
        std::fs::rename(part_path(&a, 2), part_path(&a, 1)).expect("rename");
        refused("its metadata says part 2, its name part 1");
        // A part missing in between.
        std::fs::remove_file(part_path(&a, 1)).expect("remove");
        let e = read(&a).expect_err("gap").to_string();
        assert!(e.contains("part 3 follows part 0"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_part_cut_short_is_read_up_to_the_cut() {
        let dir = scratch("cut-part");
        let path = dir.join("user1.mcap");
        record(&path, "s", 300, bytes_bound(8 << 10, 0));
        let whole = read(&path).expect("read");
        // A full part, as a crash mid-write leaves it.
        let part = part_path(&path, 1);
        let full = read_part(&part).expect("part 1").samples;
        let bytes = std::fs::read(&part).expect("bytes");
        std::fs::write(&part, &bytes[..bytes.len() / 2]).expect("cut");
        let alone = read_part(&part).expect("a cut part still reads alone");
        assert!(alone.truncated && alone.session.is_some());
        assert!(
            !alone.samples.is_empty() && alone.samples.len() < full.len(),
            "{} of {}",
            alone.samples.len(),
            full.len()
        );
        assert_eq!(alone.samples[..], full[..alone.samples.len()]);
        // With the others: everything but what was after the cut.
        let r = read(&path).expect("a recording with a cut part still reads");
        assert!(r.truncated);
        assert_eq!(
            r.samples.len() + full.len() - alone.samples.len(),
            whole.samples.len()
        );
        assert_eq!(r.status, whole.status, "the last part is whole");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
