//! The shared-memory segments of one station, by name and layout: the control block and the seven
//! rings (five, and the two tool-track rings of methods that exchange tools), created by its supervisor before any child starts and unlinked when the supervisor's handles
//! drop. Every process of the station (and `station status`, `latency attach`) finds them here.

use crate::msg::{ObjectSample, SiteReport, ToolSample, ToolTrack, TraceRecord};
use crate::shm::control::ControlBlock;
use crate::shm::{BlockSegment, CreateError, NameError, RingSegment, SegmentName};

/// Ring sizes, in slots (powers of two): the station config's `[rings]` table.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Serialize, serde::Deserialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct RingSlots {
    /// Servo → physics tool samples.
    pub tool_slots: usize,
    /// Physics → servo object states.
    pub object_slots: usize,
    /// Physics → network reports.
    pub report_slots: usize,
    /// Network → physics remote reports.
    pub remote_slots: usize,
    /// Physics → recorder trace records (the scenario's sample rate plus adoptions).
    pub trace_slots: usize,
    /// Each of the tool-track rings (physics → network, network → physics), 3 KB a slot.
    pub track_slots: usize,
}

impl Default for RingSlots {
    fn default() -> Self {
        Self {
            tool_slots: 64,
            object_slots: 64,
            report_slots: 256,
            remote_slots: 256,
            trace_slots: 4096,
            track_slots: 64,
        }
    }
}

/// Segment names of a station, by role.
#[derive(Debug, Clone)]
pub struct Names {
    /// Control block.
    pub control: SegmentName,
    /// Servo → physics.
    pub tool: SegmentName,
    /// Physics → servo.
    pub object: SegmentName,
    /// Physics → network.
    pub report: SegmentName,
    /// Network → physics.
    pub remote: SegmentName,
    /// Physics → recorder (the network process).
    pub trace: SegmentName,
    /// Physics → network: this site's tool tracks.
    pub track_out: SegmentName,
    /// Network → physics: the other sites' tool tracks.
    pub track_in: SegmentName,
}

impl Names {
    /// The names of station `station` in `session`.
    ///
    /// # Errors
    /// A name component breaks the naming rule.
    pub fn of(session: &str, station: &str) -> Result<Self, NameError> {
        let n = |w: &str| SegmentName::new(session, station, w);
        Ok(Self {
            control: n("ctl")?,
            tool: n("tool")?,
            object: n("objects")?,
            report: n("reports-out")?,
            remote: n("reports-in")?,
            trace: n("trace")?,
            track_out: n("tracks-out")?,
            track_in: n("tracks-in")?,
        })
    }
}

/// The created segments (the supervisor holds these for the station's life).
#[derive(Debug)]
pub struct StationSegments {
    /// Control block.
    pub control: BlockSegment<ControlBlock>,
    /// Servo → physics.
    pub tool: RingSegment<ToolSample>,
    /// Physics → servo.
    pub object: RingSegment<ObjectSample>,
    /// Physics → network.
    pub report: RingSegment<SiteReport>,
    /// Network → physics.
    pub remote: RingSegment<SiteReport>,
    /// Physics → recorder.
    pub trace: RingSegment<TraceRecord>,
    /// Physics → network tool tracks.
    pub track_out: RingSegment<ToolTrack>,
    /// Network → physics tool tracks.
    pub track_in: RingSegment<ToolTrack>,
}

impl StationSegments {
    /// Creates every segment of the station (exclusively: an existing one is an error naming it).
    ///
    /// # Errors
    /// A segment exists (live or stale) or the OS refuses.
    pub fn create(names: &Names, rings: &RingSlots) -> Result<Self, CreateError> {
        Ok(Self {
            control: BlockSegment::create(&names.control)?,
            tool: RingSegment::create(&names.tool, rings.tool_slots)?,
            object: RingSegment::create(&names.object, rings.object_slots)?,
            report: RingSegment::create(&names.report, rings.report_slots)?,
            remote: RingSegment::create(&names.remote, rings.remote_slots)?,
            trace: RingSegment::create(&names.trace, rings.trace_slots)?,
            track_out: RingSegment::create(&names.track_out, rings.track_slots)?,
            track_in: RingSegment::create(&names.track_in, rings.track_slots)?,
        })
    }
}
