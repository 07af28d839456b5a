//! One MCAP file being written: a part of a station's recording, or a whole session file.

use std::cell::Cell;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::{Duration, Instant};

use super::topic::{FoxgloveTopic, Topic};
use super::{io_err, mcap_err, RecordingError};

/// The file being written, counting the bytes that go into it.
struct Counted {
    file: BufWriter<File>,
    written: Rc<Cell<u64>>,
}

impl Write for Counted {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.file.write(buf)?;
        self.written.set(self.written.get() + n as u64);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl Seek for Counted {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.file.seek(pos)
    }
}

/// One part being written.
pub(super) struct Part {
    w: mcap::Writer<Counted>,
    path: PathBuf,
    number: u32,
    /// The JSON channels' ids, in the order they were declared.
    channels: Vec<(Topic, u16)>,
    /// The ids of [`FoxgloveTopic::ALL`], in its order, when the file has them.
    foxglove: Option<[u16; FoxgloveTopic::ALL.len()]>,
    written: Rc<Cell<u64>>,
    started: Instant,
}

impl Part {
    /// Creates (truncates) part `number` at `path` and writes its header, metadata, schemas and
    /// channels: the JSON channels `json` (each with its [`Topic::schema`]; ids in that order),
    /// then, `with_foxglove`, [`FoxgloveTopic::ALL`]. A station's parts are written `!chunked`
    /// (every message reaches the file at the next flush: crash-safe); a file written at once
    /// (a session file) in chunks, with their indexes, which some readers (Rerun) need.
    pub(super) fn create(
        path: PathBuf,
        number: u32,
        metadata: &BTreeMap<String, String>,
        json: &[Topic],
        with_foxglove: bool,
        chunked: bool,
    ) -> Result<Self, RecordingError> {
        let file = File::create(&path).map_err(io_err(&path))?;
        let written = Rc::new(Cell::new(0));
        let mut w = mcap::WriteOptions::new()
            .use_chunks(chunked)
            .profile("")
            .library(concat!("coop-haptics ", env!("CARGO_PKG_VERSION")))
            .create(Counted {
                file: BufWriter::new(file),
                written: written.clone(),
            })
            .map_err(mcap_err(&path))?;
        let mut metadata = metadata.clone();
        metadata.insert("part".into(), number.to_string());
        w.write_metadata(&mcap::records::Metadata {
            name: "coop-haptics".into(),
            metadata,
        })
        .map_err(mcap_err(&path))?;
        let mut channels = Vec::with_capacity(json.len());
        for &topic in json {
            let name = topic.name();
            let schema = w
                .add_schema(name, "jsonschema", topic.schema().to_string().as_bytes())
                .map_err(mcap_err(&path))?;
            let id = w
                .add_channel(schema, name, "json", &BTreeMap::new())
                .map_err(mcap_err(&path))?;
            channels.push((topic, id));
        }
        let foxglove = if with_foxglove {
            let mut ids = [0u16; FoxgloveTopic::ALL.len()];
            for (c, topic) in ids.iter_mut().zip(FoxgloveTopic::ALL) {
                let name = topic.name();
                let s = topic.schema().ok_or_else(|| RecordingError::Io {
                    path: path.display().to_string(),
                    error: std::io::Error::other(format!("{name}: the SDK gives no schema")),
                })?;
                let schema = w
                    .add_schema(&s.name, &s.encoding, &s.data)
                    .map_err(mcap_err(&path))?;
                *c = w
                    .add_channel(schema, name, "protobuf", &BTreeMap::new())
                    .map_err(mcap_err(&path))?;
            }
            Some(ids)
        } else {
            None
        };
        if !chunked {
            // The part's metadata reaches the disk now, not at the first flush: a process killed
            // before that must leave a part a successor recognises as its run's, not an empty file.
            w.flush().map_err(mcap_err(&path))?;
        }
        Ok(Self {
            w,
            path,
            number,
            channels,
            foxglove,
            written,
            started: Instant::now(),
        })
    }

    /// The file.
    pub(super) fn path(&self) -> &Path {
        &self.path
    }

    /// The part's number (0 for the first).
    pub(super) fn number(&self) -> u32 {
        self.number
    }

    /// The bytes written to the file so far.
    pub(super) fn bytes(&self) -> u64 {
        self.written.get()
    }

    /// How long ago the part was created.
    pub(super) fn age(&self) -> Duration {
        self.started.elapsed()
    }

    /// The id of JSON channel `topic`.
    ///
    /// # Errors
    /// The part was created without it.
    pub(super) fn channel(&self, topic: Topic) -> Result<u16, RecordingError> {
        self.channels
            .iter()
            .find(|c| c.0 == topic)
            .map(|c| c.1)
            .ok_or_else(|| {
                io_err(&self.path)(std::io::Error::other(format!(
                    "{}: no such channel in this file",
                    topic.name()
                )))
            })
    }

    /// The id of Foxglove channel `topic`, when the part has the Foxglove channels.
    pub(super) fn foxglove_channel(&self, topic: FoxgloveTopic) -> Option<u16> {
        self.foxglove.map(|ids| ids[topic as usize])
    }

    /// Writes one message on channel `channel_id` at `log_time` (also its publish time), with
    /// `sequence`.
    pub(super) fn write(
        &mut self,
        channel_id: u16,
        sequence: u32,
        log_time: u64,
        data: &[u8],
    ) -> Result<(), RecordingError> {
        self.w
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id,
                    sequence,
                    log_time,
                    publish_time: log_time,
                },
                data,
            )
            .map_err(mcap_err(&self.path))
    }

    /// Pushes what has been written to the file.
    pub(super) fn flush(&mut self) -> Result<(), RecordingError> {
        self.w.flush().map_err(mcap_err(&self.path))
    }

    /// Writes the summary and footer and closes the file.
    pub(super) fn finish(mut self) -> Result<(), RecordingError> {
        self.w.finish().map_err(mcap_err(&self.path))?;
        Ok(())
    }
}
