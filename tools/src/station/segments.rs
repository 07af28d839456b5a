//! The shared-memory segments of one station, created by its supervisor before any child starts and
//! unlinked when the supervisor's handles drop: the control block and the five rings.

use coop_rt::msg::{ObjectSample, SiteReport, ToolSample, TraceRecord};
use coop_rt::shm::control::ControlBlock;
use coop_rt::shm::{BlockSegment, RingSegment, SegmentName};

use super::config::RingSpec;

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
}

impl Names {
    /// The names of station `station` in `session`.
    ///
    /// # Errors
    /// A name component breaks the naming rule.
    pub fn of(session: &str, station: &str) -> anyhow::Result<Self> {
        let n = |w: &str| SegmentName::new(session, station, w);
        Ok(Self {
            control: n("ctl")?,
            tool: n("tool")?,
            object: n("obj")?,
            report: n("rep")?,
            remote: n("rem")?,
            trace: n("trc")?,
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
}

impl StationSegments {
    /// Creates every segment of the station (exclusively: an existing one is an error naming it).
    ///
    /// # Errors
    /// A segment exists (live or stale) or the OS refuses.
    pub fn create(names: &Names, rings: &RingSpec) -> anyhow::Result<Self> {
        Ok(Self {
            control: BlockSegment::create(&names.control)?,
            tool: RingSegment::create(&names.tool, rings.tool_slots)?,
            object: RingSegment::create(&names.object, rings.object_slots)?,
            report: RingSegment::create(&names.report, rings.report_slots)?,
            remote: RingSegment::create(&names.remote, rings.remote_slots)?,
            trace: RingSegment::create(&names.trace, rings.trace_slots)?,
        })
    }
}
