//! A record of one site's physics ticks in a simulated run: everything its method was given and
//! everything it put, so that the same inputs can be replayed through a station's physics loop
//! and the two compared bit for bit.

use crate::contact::ContactForce;
use crate::drive::{Put, ToolAt};
use crate::method::{Report, WorldCopy};
use crate::world::MAX_OBJECTS;

/// One physics tick of the probed site.
#[derive(Debug, Clone)]
pub struct ProbedTick {
    /// When, ns of virtual time.
    pub t_ns: u64,
    /// The tick's length, ns.
    pub period_ns: u64,
    /// The own tool as last sampled by the servo.
    pub tool: ToolAt,
    /// The own contact with each object, as the method was given it.
    pub own: [ContactForce; MAX_OBJECTS],
    /// Site reports taken before the tick, in arrival order: (sender, report).
    pub states: Vec<(usize, Report)>,
    /// Tool tracks taken before the tick, after the site reports, in arrival order.
    pub tracks: Vec<(usize, Report)>,
    /// The copy after the tick.
    pub copy: WorldCopy,
    /// What the site put after the tick.
    pub puts: Vec<Put>,
}
