//! The interface every consistency method implements.

use crate::body::{BodyState, Vec3};
use crate::contact::ContactForce;
use crate::world::World;

use super::copy::WorldCopy;
use super::report::{Adoption, Report};
use super::stats::Stats;

/// A consistency method (see the module docs).
pub trait Consistency: std::fmt::Debug + Send {
    /// Its name, as in scenario files.
    fn name(&self) -> &'static str;
    /// Integrates `copy` by `dt` with the own user's (held) contact `own` with each object.
    fn physics_step(&mut self, world: &World, copy: &mut WorldCopy, own: &[ContactForce], dt: f64);
    /// The reports this site sends now, each handed to `out`: one for the whole world
    /// (`timewarp`), or one per object this site has something to say about (`naive`, `paper`,
    /// `coupled`: see each), in the world's order. Allocates nothing.
    fn report(&self, copy: &WorldCopy, own: &[ContactForce], now_s: f64, out: Sink<'_>);
    /// Handles a report from site `from`; `Some` when the local copy jumped to a received state.
    fn receive(
        &mut self,
        world: &World,
        copy: &mut WorldCopy,
        from: usize,
        msg: &Report,
        now_s: f64,
    ) -> Option<Adoption>;
    /// Sum of the other sites' forces this method applies to the local copy (for traces), N.
    fn remote_force(&self) -> Vec3 {
        Vec3::zeros()
    }
    /// Site `from` went silent at `now_s` (it is lost): whatever this method still applies of it
    /// must fade out rather than freeze at its last value. Hearing from it again ends that.
    fn peer_lost(&mut self, from: usize, now_s: f64) {
        let _ = (from, now_s);
    }
    /// The own tool is at `tool_pos` (world, m) at the tick about to be stepped: methods that
    /// compute every tool's contact themselves (`timewarp`) take it here.
    fn own_tool(&mut self, tool_pos: Vec3) {
        let _ = tool_pos;
    }
    /// What the method did so far (rollbacks, jitter-buffer playout), for status and recordings.
    fn stats(&self) -> Stats {
        Stats::None
    }
    /// For a method that steps on the session's tick grid (`timewarp`, `coupled`): the ticks of
    /// history it keeps. A physics process whose first step falls this many ticks or more after
    /// the session's time 0 (a restart, a late station) joins the grid where the session is
    /// ([`Consistency::start_at_tick`]) instead of re-simulating the session from its start.
    fn grid_history_ticks(&self) -> Option<u64> {
        None
    }
    /// For a method that steps on the session's tick grid (`timewarp`, `coupled`): the copy it
    /// is stepped with is the state at the start of tick `tick`, not tick 0, and nothing
    /// before it was simulated here (a restarted or late physics process joins the grid where it
    /// is now instead of re-simulating the session from its start). Called before the first step.
    fn start_at_tick(&mut self, tick: i64) {
        let _ = tick;
    }
    /// The state of object `k` the own user is shown (the servo renders against it): the
    /// copy's, unless the method replays a contact the user missed (`timewarp`: see
    /// [`crate::method::timewarp`]).
    fn shown(&self, copy: &WorldCopy, k: usize) -> BodyState {
        copy.objects()[k].state
    }
}

/// Where a method hands its reports ([`Consistency::report`]): called once per report.
pub type Sink<'a> = &'a mut dyn FnMut(Report);

/// How long a lost site's influence takes to fade to nothing, s.
pub const LOST_FADE_S: f64 = 0.1;
