//! What the recordings' tests share: a scratch directory, a recording written the same way at any
//! bound, and the messages of a file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::{
    AdoptionMsg, ClockMsg, PresenceMsg, PublishedMsg, Recorder, RemoteMsg, Rotation, SampleMsg,
    SessionMsg, StatusMsg,
};

/// Every message of a recording, as (topic, JSON bytes), in order.
pub(super) fn messages(path: &Path) -> Vec<(String, Vec<u8>)> {
    let bytes = std::fs::read(path).expect("read");
    mcap::MessageStream::new(&bytes)
        .expect("mcap")
        .map(|m| {
            let m = m.expect("message");
            (m.channel.topic.clone(), m.data.to_vec())
        })
        .collect()
}

/// A fresh directory for one test.
pub(super) fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("coop-rec-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    dir
}

/// Writes the same input (the session, `n` samples with the station's other messages among
/// them, the final counters) to a recording at `path` bounded by `rotation`.
pub(super) fn record(path: &Path, session: &str, n: u64, rotation: Rotation) {
    let meta = BTreeMap::from([
        ("session".into(), session.to_owned()),
        ("site".into(), "a".into()),
    ]);
    // The recorder creates no directory: the test makes it.
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).expect("dir");
    }
    let mut w = Recorder::create(path, meta, rotation).expect("create");
    w.session(&SessionMsg {
        t_ns: 1,
        session: session.into(),
        site: "a".into(),
        epoch_ns: 5,
        ..SessionMsg::default()
    })
    .expect("w");
    for k in 0..n {
        let t_ns = 10 + 10 * k;
        w.sample(&SampleMsg {
            t_ns,
            pos: [k as f64, 0.0, 0.0],
            rot: [1.0, 0.0, 0.0, 0.0],
            touching: k % 2 == 0,
            ..SampleMsg::default()
        })
        .expect("w");
        if k % 7 == 0 {
            w.adoption(&AdoptionMsg {
                t_ns,
                from: 1,
                jump_m: 0.01,
                age_s: 0.2,
            })
            .expect("w");
            w.remote(&RemoteMsg {
                t_ns,
                seq: k,
                via: "live".into(),
                ..RemoteMsg::default()
            })
            .expect("w");
        }
        if k % 11 == 0 {
            w.published(&PublishedMsg {
                t_ns,
                seq: k,
                state_ns: t_ns,
            })
            .expect("w");
            w.clock(&ClockMsg {
                t_ns,
                site: 1,
                offset_ns: -3,
                rtt_ns: 100,
            })
            .expect("w");
        }
        if k == 3 {
            w.presence(&PresenceMsg {
                t_ns,
                site: "b".into(),
                present: true,
            })
            .expect("w");
        }
    }
    w.status(&StatusMsg {
        t_ns: 10 * n + 20,
        published: n,
        ..StatusMsg::default()
    })
    .expect("w");
    w.finish().expect("finish");
}

pub(super) fn bytes_bound(max_file_bytes: u64, keep_files: usize) -> Rotation {
    Rotation {
        max_file_bytes: Some(max_file_bytes),
        max_file_duration: None,
        keep_files,
    }
}

pub(super) fn files_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}
