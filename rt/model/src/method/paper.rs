//! Method `paper`: Eq. 9–11, the paper's own.

use crate::body::{BodyState, Vec3};
use crate::contact::ContactForce;
use crate::world::{pair_index, plane_depth, World, MAX_OBJECTS, MAX_SITES};
use nalgebra::UnitQuaternion;

use super::consistency::{Consistency, Sink};
use super::copy::{integrate, WorldCopy};
use super::reckon::{dead_reckon, passive_reckoned};
use super::report::{Adoption, Report};

/// One own step's impulse on one object: (the object, end of the step, middle of the step, linear
/// impulse, angular impulse, the own user's work in the step), -, s, s, N·s, N·m·s, J.
type LoggedImpulse = (usize, f64, f64, Vec3, Vec3, f64);

/// Own impulses a site remembers: 16 s of one object touched at 1 kHz, or 1 s of all
/// [`MAX_OBJECTS`] at once.
const LOG_CAP: usize = 16384;

/// Own impulses on one object an adoption replays at most: 8 s at 1 kHz.
const REPLAY_CAP: usize = 8192;

/// Eq. 9–11: each site integrates its copy with its **own** user's force only, and the newest state
/// travels between the sites; "the force of each user only updates the newest state"
/// (superposition at the acceleration level).
///
/// Every report carries, per site, the time up to which that site's user's impulses are included in
/// the state: the paper's "time of the state change", one per contributor. A site adopts a received
/// state when it includes newer contributions of the others and none older; it dead-reckons it to now
/// and **replays its own user's impulses the sender had not yet seen** (each impulse moves the object
/// by Δv·(now − t) and changes its momentum by Δp). So a site never takes back its own user's push,
/// and during a simultaneous grasp each copy carries both users' forces, each from its own site. With
/// zero delay this is the reference run's sum of forces (for free motion exactly).
///
/// When nothing new is known the sites follow the copy of the site whose user touched last (it
/// includes the newest impulse): its later snapshots are adopted, so a released object slides to
/// rest identically everywhere.
///
/// Along the normal of an environment plane the local copy rests on, the local position and velocity
/// are kept: the contact equilibrium there is local physics, and transplanting another copy's
/// micro-bounce would pump energy into every adoption. The environment's friction stick points move
/// with the adopted object.
///
/// **A world of several objects**: all of the above holds per object. Each object's state travels
/// in its own report with its own contribution times; a site adopts, dead-reckons and replays
/// object by object. What an object–object contact does at a site is that site's change: an
/// object the own user touches, and both objects of a collision here (a contact in which either
/// moved; a resting stack changes nothing), count the step as the own site's contribution. So
/// one object of a collision is never adopted from a site where the collision did not happen
/// while the other keeps what it got from it here: the energy the collision moved would count
/// twice (`billiards.toml`, 150 ms: a struck cue adopted from the catcher's site, where it had
/// not lost its energy to the target, while the local target kept it: 12 mJ beyond every user's
/// work). A site reports
/// the objects it is the newest contributor to (the author) — in a world of one object, the object
/// always — so an object nobody touches is reported by site 0 alone.
#[derive(Debug, Clone)]
pub struct Paper {
    /// Dead-reckoning order (0, 1, 2).
    pub order: u8,
    me: usize,
    /// Per object, per site: the time of its newest report taken.
    newest_from: [[f64; MAX_SITES]; MAX_OBJECTS],
    /// Own impulses, a ring (see [`LoggedImpulse`]).
    log: Box<[LoggedImpulse]>,
    log_next: usize,
    log_len: usize,
    /// The own tool as a spring, for the no-gain bound (position from [`Consistency::own_tool`]).
    tool: Option<super::tank::ToolSpring>,
    /// Per object: the own user's positive work on the local copy not yet spent by replays, J:
    /// each joule the user put in is granted to replays once ([`crate::method::tank`]).
    tank_j: [f64; MAX_OBJECTS],
}

impl Paper {
    /// For site `me`, with dead-reckoning `order`.
    pub fn new(order: u8, me: usize) -> Self {
        Self {
            order,
            me,
            newest_from: [[f64::NEG_INFINITY; MAX_SITES]; MAX_OBJECTS],
            log: vec![(0, 0.0, 0.0, Vec3::zeros(), Vec3::zeros(), 0.0); LOG_CAP].into_boxed_slice(),
            log_next: 0,
            log_len: 0,
            tool: None,
            tank_j: [0.0; MAX_OBJECTS],
        }
    }

    /// With the own tool's radius and contact stiffness known: the no-gain bound then counts the
    /// tool's spring ([`super::tank::ToolSpring`]) once the tool's position is given.
    pub fn with_tool(mut self, radius_m: f64, stiffness_n_per_m: f64) -> Self {
        self.tool = Some(super::tank::ToolSpring {
            pos: Vec3::repeat(f64::INFINITY),
            radius_m,
            stiffness_n_per_m,
        });
        self
    }

    /// The site whose user's impulse is the newest in `included` (ties: the lowest index).
    fn author(included: &[f64; MAX_SITES]) -> usize {
        (0..MAX_SITES).fold(0, |best, k| {
            if included[k] > included[best] {
                k
            } else {
                best
            }
        })
    }
}

/// Which objects the own site changed in the step just taken: those its user touched, and those
/// in a collision here (a contact with another object, or a fixture, in which either moved).
fn changed_by_own(
    world: &World,
    copy: &WorldCopy,
    own: &[ContactForce],
    n: usize,
) -> [bool; MAX_OBJECTS] {
    // REAL-TIME: no allocation, no lock, no logging, no syscalls.
    let bodies = world.bodies();
    let mut changed: [bool; MAX_OBJECTS] = std::array::from_fn(|k| k < n && own[k].touching);
    let moved = |k: usize| !bodies[k].fixed && copy.still()[k] == 0;
    for i in 0..n {
        for j in i + 1..n {
            if copy.pairs()[pair_index(i, j, n)].touching() && (moved(i) || moved(j)) {
                changed[i] |= !bodies[i].fixed;
                changed[j] |= !bodies[j].fixed;
            }
        }
    }
    changed
}

impl Consistency for Paper {
    fn name(&self) -> &'static str {
        "paper"
    }
    fn own_tool(&mut self, tool_pos: Vec3) {
        if let Some(t) = &mut self.tool {
            t.pos = tool_pos;
        }
    }
    fn physics_step(&mut self, world: &World, copy: &mut WorldCopy, own: &[ContactForce], dt: f64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let n = copy.len().min(own.len());
        let mut work_before = [0.0; MAX_OBJECTS];
        for (w, o) in work_before.iter_mut().zip(copy.objects()) {
            *w = o.energy.own_j;
        }
        let mut impulse = [crate::body::Wrench::default(); MAX_OBJECTS];
        integrate(world, copy, &own[..n], 1, 1, dt, &mut impulse[..n]);
        let changed = changed_by_own(world, copy, own, n);
        for k in 0..n {
            let o = &mut copy.objects_mut()[k];
            let work = o.energy.own_j - work_before[k];
            self.tank_j[k] += work.max(0.0);
            if own[k].touching {
                self.log[self.log_next] = (
                    k,
                    o.time_s,
                    o.time_s - 0.5 * dt,
                    impulse[k].force,
                    impulse[k].torque,
                    work,
                );
                self.log_next = (self.log_next + 1) % LOG_CAP;
                self.log_len = (self.log_len + 1).min(LOG_CAP);
            }
            if changed[k] {
                if let Some(mine) = o.included.get_mut(self.me) {
                    *mine = o.time_s;
                }
            }
        }
    }
    /// One report per object this site is the author of (see the type's docs).
    fn report(&self, copy: &WorldCopy, _own: &[ContactForce], now_s: f64, out: Sink<'_>) {
        let n = copy.len();
        for (k, o) in copy.objects().iter().enumerate() {
            if n > 1 && Self::author(&o.included) != self.me {
                continue;
            }
            out(Report::State {
                object: k,
                t_s: now_s,
                state: o.state,
                accel: o.passive_accel,
                included: o.included,
            });
        }
    }
    fn receive(
        &mut self,
        world: &World,
        world_copy: &mut WorldCopy,
        from: usize,
        msg: &Report,
        now_s: f64,
    ) -> Option<Adoption> {
        let Report::State {
            object: k,
            t_s,
            state,
            accel,
            included,
        } = *msg
        else {
            return None;
        };
        // (A value: the copy's other objects are read as they are to bound it, then it is put back.)
        let mut copy = *world_copy.objects().get(k)?;
        let body = world.bodies().get(k)?;
        let newest = self.newest_from[k].get_mut(from)?;
        if t_s <= *newest || !state.is_finite() || included.iter().any(|v| !v.is_finite()) {
            return None; // a replay, an older snapshot, or garbage
        }
        *newest = t_s;
        let others = (0..MAX_SITES).filter(|&j| j != self.me);
        let gains = others.clone().any(|j| included[j] > copy.included[j]);
        let loses = others.clone().any(|j| included[j] < copy.included[j]);
        let same = others.clone().all(|j| included[j] == copy.included[j]);
        let follows_author = same && from == Self::author(&copy.included) && from != self.me;
        if !((gains && !loses) || follows_author) {
            return None;
        }
        // Dead reckoning predicts a passive object: unbounded, on `three-users.toml` at 500 ms a
        // disk a user's tool had flicked up at 0.87 m/s was adopted 0.45 m up, 129 mJ beyond every
        // user's work.
        let reckoned = dead_reckon(world, k, &state, accel, now_s - t_s, self.order);
        let mut new = passive_reckoned(world, k, &state, reckoned);
        let given = new;
        // Replay our own impulses on this object the sender had not seen.
        let seen_until = included.get(self.me).copied().unwrap_or(f64::NEG_INFINITY);
        let inv_i = new.inv_inertia_world(&body.mass);
        let mut own_work_j = 0.0;
        let mut replayed = 0;
        for i in 0..self.log_len {
            let (object, t_end, t_mid, dp, dl, w) =
                self.log[(self.log_next + LOG_CAP - 1 - i) % LOG_CAP];
            if t_end <= seen_until {
                break;
            }
            if object != k {
                continue;
            }
            if replayed == REPLAY_CAP {
                break;
            }
            replayed += 1;
            own_work_j += w;
            // The impulse acted over its step: it has moved the object for (now − step middle).
            let age = (now_s - t_mid).max(0.0);
            let dv = dp / body.mass.mass_kg;
            new.vel += dv;
            new.pos += dv * age;
            new.ang_mom += dl;
            new.rot = UnitQuaternion::from_scaled_axis(inv_i * dl * age) * new.rot;
        }
        let mut base = given;
        for plane in world.planes() {
            if plane_depth(&body.shape, plane, &copy.state) > -1e-4 {
                let n = plane.normal;
                for s in [&mut new, &mut base] {
                    s.pos += n * (copy.state.pos - s.pos).dot(&n);
                    s.vel += n * (copy.state.vel - s.vel).dot(&n);
                }
            }
        }
        // Never more energy than the sender's copy or this one had, plus the replayed work.
        let (new, clipped_j, spent_j) = super::tank::bound_adoption(
            world,
            k,
            &super::tank::Adopted {
                local: copy.state,
                given,
                base,
                full: new,
                tool: self.tool.filter(|t| t.pos.iter().all(|v| v.is_finite())),
            },
            own_work_j.min(self.tank_j[k]),
        );
        self.tank_j[k] = (self.tank_j[k] - spent_j).max(0.0);
        // Nor onto the own tool, nor into another object here.
        let tool = self.tool.filter(|t| t.pos.iter().all(|v| v.is_finite()));
        // (What the own user put in and replays have not spent may load it.)
        let (new, clipped_j) = match tool.and_then(|t| {
            super::tank::bound_tool(world, k, &t, (&copy.state, &new), self.tank_j[k])
        }) {
            Some((s, c)) => (s, clipped_j + c),
            None => (new, clipped_j),
        };
        if let Some(t) = tool {
            let loaded = t.energy(world, k, &new) - t.energy(world, k, &copy.state);
            self.tank_j[k] = (self.tank_j[k] - loaded.max(0.0)).max(0.0);
        }
        let (new, clipped_j) =
            match super::tank::bound_pairs(world, world_copy, k, &copy.state, &new) {
                Some((s, c)) => (s, clipped_j + c),
                None => (new, clipped_j),
            };
        let e = |s: &BodyState| s.mechanical_energy(&body.mass, world.gravity);
        let adoption = Adoption {
            jump: copy.state.pos - new.pos,
            energy_j: e(&new) - e(&copy.state),
            work_j: 0.0,
            age_s: now_s - t_s,
            clipped_j,
        };
        copy.energy.adoption_j += adoption.energy_j;
        copy.env
            .shift(new.pos - copy.state.pos, new.rot * copy.state.rot.inverse());
        copy.state = new;
        let mine = copy.included.get(self.me).copied().unwrap_or(-1.0);
        copy.included = included;
        if let Some(m) = copy.included.get_mut(self.me) {
            *m = m.max(mine);
        }
        world_copy.objects_mut()[k] = copy;
        world_copy.corrected(k);
        Some(adoption)
    }
}

#[cfg(test)]
mod tests {
    use super::super::reckon::{dead_reckon, DEAD_RECKONING_SLACK_J};
    use super::*;
    use crate::world::fixtures::{on_a_table, world};
    use crate::world::{push_out_of_environment, supported_gravity};

    #[test]
    fn paper_adopts_newer_contributions_and_replays_its_own() {
        let w = World {
            plane_count: 0,
            gravity: Vec3::zeros(),
            ..world()
        };
        let mut m = Paper::new(2, 0);
        let mut copy = WorldCopy::one(BodyState::at_rest(Vec3::zeros()));
        let msg = |t: f64, x: f64, mine: f64, theirs: f64| {
            let mut included = [-1.0; MAX_SITES];
            included[0] = mine;
            included[1] = theirs;
            Report::State {
                object: 0,
                t_s: t,
                state: BodyState::at_rest(Vec3::new(x, 0.0, 0.0)),
                accel: Vec3::zeros(),
                included,
            }
        };
        assert!(
            m.receive(&w, &mut copy, 1, &msg(1.0, 0.5, -1.0, 0.9), 1.0)
                .is_some(),
            "newer contribution"
        );
        assert_eq!(
            (copy.first().state.pos.x, copy.first().included[1]),
            (0.5, 0.9)
        );
        assert!(
            m.receive(&w, &mut copy, 1, &msg(0.9, 0.7, -1.0, 0.95), 1.1)
                .is_none(),
            "older snapshot"
        );
        assert!(
            m.receive(&w, &mut copy, 1, &msg(1.0, 0.7, -1.0, 0.95), 1.1)
                .is_none(),
            "replay"
        );
        // Our own user pushes: +0.1 m/s at t = 1.0 (impulse 0.01 N·s on 0.1 kg).
        let push = ContactForce {
            force: Vec3::new(1.0, 0.0, 0.0),
            point: copy.first().state.pos,
            depth: 0.001,
            touching: true,
            ..ContactForce::default()
        };
        copy.set_time(0.99);
        m.physics_step(&w, &mut copy, &[push], 0.01);
        assert!((copy.first().state.vel.x - 0.1).abs() < 1e-9);
        // A state from site 1 that has not seen our push: adopted, and our push replayed on it.
        assert!(m
            .receive(&w, &mut copy, 1, &msg(1.2, 0.6, -1.0, 1.1), 1.2)
            .is_some());
        assert!(
            (copy.first().state.vel.x - 0.1).abs() < 1e-9,
            "own impulse replayed: {:?}",
            copy.first().state.vel
        );
        // Pushed during [0.99, 1.0]: it has moved the object for 1.2 − 0.995 s.
        assert!(
            (copy.first().state.pos.x - (0.6 + 0.1 * 0.205)).abs() < 1e-9,
            "{:?}",
            copy.first().state.pos
        );
        // One that has seen it: adopted as it is.
        assert!(m
            .receive(&w, &mut copy, 1, &msg(1.3, 0.65, 1.0, 1.25), 1.3)
            .is_some());
        assert!(
            copy.first().state.vel.x.abs() < 1e-12
                && (copy.first().state.pos.x - 0.65).abs() < 1e-12
        );
    }

    /// A state reported resting on the table (within the support's band) but leaving it fast, as a
    /// disk a tool flicks up: reckoned with the support's zero acceleration it would fly on
    /// unslowed (0.44 m up after 0.5 s); `paper` adopts it with no more energy than the state sent.
    #[test]
    fn paper_never_adopts_more_energy_than_the_state_sent() {
        let (w, sent) = on_a_table(Vec3::new(0.0, 0.87, 0.0));
        let accel = supported_gravity(&w, &w.bodies[0].shape, &sent);
        assert!(accel.norm() < 1e-12, "reported as resting: {accel:?}");
        let reckoned = dead_reckon(&w, 0, &sent, accel, 0.5, 2);
        assert!(reckoned.pos.y > 0.4, "unslowed: {:?}", reckoned.pos);
        let mut m = Paper::new(2, 0);
        // This copy's disk is off the table (an earlier adoption lifted it): nothing of the
        // local state is kept along the table's normal.
        let mut copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.06, 0.0)));
        let mut included = [-1.0; MAX_SITES];
        included[1] = 1.0;
        let msg = Report::State {
            object: 0,
            t_s: 1.0,
            state: sent,
            accel,
            included,
        };
        assert!(m.receive(&w, &mut copy, 1, &msg, 1.5).is_some());
        // (The sent state as the reckoner puts it: on the table's surface.)
        let mut on_surface = sent;
        push_out_of_environment(&w, &w.bodies[0].shape, &mut on_surface);
        let e = |s: &BodyState| crate::method::tank::stored_energy(&w, 0, s);
        assert!(
            e(&copy.first().state) <= e(&on_surface) + DEAD_RECKONING_SLACK_J,
            "{} J adopted, {} J sent",
            e(&copy.first().state),
            e(&on_surface)
        );
        assert!(
            copy.first().state.pos.y < 0.1,
            "{:?}",
            copy.first().state.pos
        );
    }

    /// In a world of several, a collision at a site is that site's change to both objects, and a
    /// site reports only the objects it is the author of: a puck rolled into another at site 1
    /// (nobody touching) makes site 1 the author of both, with the collision's time; before it,
    /// site 0 (the lowest index, all contributions equal) authored both and site 1 sent nothing.
    #[test]
    fn a_collision_is_the_site_s_change_and_a_site_reports_what_it_authored() {
        use crate::shape::Shape;
        use crate::world::Body;
        let ball = Body::solid(Shape::Sphere { radius: 0.02 }, 0.1);
        let w = World::new(
            &[ball, ball],
            Vec3::zeros(),
            &[],
            crate::contact::tests::params(),
        );
        let rolling = BodyState {
            vel: Vec3::new(0.5, 0.0, 0.0),
            ..BodyState::at_rest(Vec3::zeros())
        };
        let mut copy = WorldCopy::new(&[rolling, BodyState::at_rest(Vec3::new(0.05, 0.0, 0.0))]);
        let mut paper = Paper::new(2, 1);
        let none = [ContactForce::default(); 2];
        let reported = |paper: &Paper, copy: &WorldCopy| {
            let mut objects = Vec::new();
            paper.report(copy, &none, copy.first().time_s, &mut |r| {
                if let Report::State {
                    object, included, ..
                } = r
                {
                    objects.push((object, included[1]));
                }
            });
            objects
        };
        for _ in 0..5 {
            paper.physics_step(&w, &mut copy, &none, 1e-3);
        }
        assert_eq!(
            reported(&paper, &copy),
            [],
            "site 0 authors untouched objects"
        );
        for _ in 0..100 {
            paper.physics_step(&w, &mut copy, &none, 1e-3);
        }
        assert!(copy.objects()[1].state.vel.x > 0.1, "the struck ball moves");
        let sent = reported(&paper, &copy);
        assert_eq!(sent.len(), 2, "{sent:?}");
        for (k, (object, mine)) in sent.into_iter().enumerate() {
            assert_eq!(object, k);
            assert!(
                mine > 0.01 && mine < 0.105,
                "object {k}: changed here at {mine} s"
            );
        }
    }
}
