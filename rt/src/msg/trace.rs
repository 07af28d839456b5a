//! The recorder's records: what a site believed and displayed, for the station's recording.

use coop_model::body::{BodyState, Vec3};

use super::{a3, state_fields, ToolSample, TraceRecord};

impl TraceRecord {
    /// A periodic sample.
    pub const SAMPLE: u64 = 1;
    /// An adoption.
    pub const ADOPTION: u64 = 2;

    /// A record of `kind` at `t_ns` of object `object`'s state `s`, with the newest tool sample
    /// `tool`.
    pub fn new(
        kind: u64,
        t_ns: u64,
        object: usize,
        s: &BodyState,
        tool: &ToolSample,
        f_object: Vec3,
    ) -> Self {
        let (pos, rot, vel, _) = state_fields(s);
        Self {
            kind,
            t_ns,
            object: object as u64,
            pos,
            rot,
            vel,
            tool_pos: tool.tool_pos,
            f_desired: tool.f_desired,
            f_measured: tool.f_measured,
            f_object: a3(f_object),
            touching: u64::from(tool.touches(object)),
            ..Self::default()
        }
    }
}
