//! Method `naive`: Eq. 8 across the network.

use crate::body::{BodyState, Vec3};
use crate::contact::ContactForce;
use crate::world::{World, MAX_OBJECTS, MAX_SITES};

use super::consistency::{Consistency, Sink, LOST_FADE_S};
use super::copy::{integrate, WorldCopy};
use super::report::{Adoption, Report};

/// Eq. 8 across the network: own force plus the latest received forces; forces are exchanged.
///
/// No gain: a received force is another user's push on *their* copy, and it may do on this one at
/// most the positive work that user has done on theirs. Each report carries that work up to its
/// time (`given_j`); this copy counts how much positive work each site's forces have done here,
/// and once it is more than the newest report's (beyond [`NAIVE_SLACK_J`] and
/// [`NAIVE_SLACK_FRACTION`] of it: the copies differ, so do the works), that site's force may do
/// no more positive work until its user gives more (what it was denied is counted in
/// [`super::copy::EnergyAccount::remote_denied_j`]). So a copy gains at most what the users gave, as far as this
/// site knows, plus the slack. Without it a user holding their copy still (a squeeze, a lift: no
/// work there) pushes a copy that has left their grasp for as long as they hold: on `lift.toml`'s
/// open table a real station's naive copy flew 613 m (481 J). Nor may a force spend ahead of what
/// its user gave while the report that would show it is on the way: with three users 120° apart
/// at 500 ms (`three-lift-balanced.toml`, seed 1) a user pressing a disk that had left the other
/// copies' grasp pushed them at 0.8 N for a delay, to 4 m/s, and the table's penalty spring then
/// threw one 44 m up. Forces that take energy (resist the motion) always apply.
#[derive(Debug, Clone)]
pub struct Naive {
    /// Per object, per site: its newest force on that object, with its time.
    remote: [[Option<(f64, ContactForce)>; MAX_SITES]; MAX_OBJECTS],
    /// Per site: when it was lost (its forces fade out over [`LOST_FADE_S`] from then).
    lost_at: [Option<f64>; MAX_SITES],
    /// Per object, per site: the positive work its forces have done on this copy, J.
    spent_j: [[f64; MAX_SITES]; MAX_OBJECTS],
    /// Per object, per site: the most positive work its forces may do here, as its newest
    /// report allows, J.
    allowed_j: [[f64; MAX_SITES]; MAX_OBJECTS],
    /// Per object: when the own user last touched it, s (negative infinity: never).
    last_touch_s: [f64; MAX_OBJECTS],
}

/// How much more work a received force may have done here than its user gave there, J...
pub const NAIVE_SLACK_J: f64 = 1e-3;
/// ...plus this fraction of what was given.
pub const NAIVE_SLACK_FRACTION: f64 = 0.1;

/// How long after its user let go of an object a site still reports its (zero) force on it, s:
/// a lost report of the release is sent again, and an object nobody has touched costs nothing.
pub const NAIVE_RELEASE_REPORTS_S: f64 = 0.5;

impl Default for Naive {
    fn default() -> Self {
        Self {
            remote: [[None; MAX_SITES]; MAX_OBJECTS],
            lost_at: [None; MAX_SITES],
            spent_j: [[0.0; MAX_SITES]; MAX_OBJECTS],
            allowed_j: [[NAIVE_SLACK_J; MAX_SITES]; MAX_OBJECTS],
            last_touch_s: [f64::NEG_INFINITY; MAX_OBJECTS],
        }
    }
}

impl Consistency for Naive {
    fn remote_force(&self) -> Vec3 {
        self.remote
            .iter()
            .flatten()
            .flatten()
            .map(|(_, f)| f.force)
            .sum()
    }
    fn name(&self) -> &'static str {
        "naive"
    }
    fn physics_step(&mut self, world: &World, copy: &mut WorldCopy, own: &[ContactForce], dt: f64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls.
        let n = copy.len().min(own.len());
        // Per object: the own force, then the received ones in site order (as many slots per
        // object as the object with the most; the rest zero, which adds nothing to any sum).
        let mut users = [ContactForce::default(); MAX_SITES * MAX_OBJECTS];
        // Per object and received force: its site and its torque about the centre of mass at
        // the step's start.
        let mut sites = [[(0usize, Vec3::zeros()); MAX_SITES]; MAX_OBJECTS];
        let mut counts = [0usize; MAX_OBJECTS];
        let mut before = [BodyState::at_rest(Vec3::zeros()); MAX_OBJECTS];
        let now = copy.first().time_s;
        for k in 0..n {
            if own[k].touching {
                self.last_touch_s[k] = now + dt;
            }
            let mass = &world.bodies[k].mass;
            before[k] = copy.objects()[k].state;
            let omega = before[k].omega(mass);
            let mut count = 0;
            for (j, slot) in self.remote[k].iter_mut().enumerate() {
                let Some((_, f)) = slot else { continue };
                let mut f = *f;
                if let Some(at) = self.lost_at[j] {
                    let left = 1.0 - (now - at) / LOST_FADE_S;
                    if left <= 0.0 {
                        *slot = None;
                        continue;
                    }
                    f.force *= left.min(1.0);
                    f.torque *= left.min(1.0);
                }
                // The no-gain bound (see the type's docs): a site's force that has done here
                // what its user gave does no more positive work.
                let torque = f.wrench(before[k].pos).torque;
                let power = f.force.dot(&before[k].vel) + torque.dot(&omega);
                if self.spent_j[k][j] > self.allowed_j[k][j] && power > 0.0 {
                    copy.objects_mut()[k].energy.remote_denied_j += power * dt;
                    continue;
                }
                sites[k][count] = (j, torque);
                count += 1;
                users[k * MAX_SITES + count] = f;
            }
            users[k * MAX_SITES] = own[k];
            counts[k] = count;
        }
        // A lost site whose forces have all faded is forgotten.
        for (j, at) in self.lost_at.iter_mut().enumerate() {
            if at.is_some() && self.remote.iter().all(|o| o[j].is_none()) {
                *at = None;
            }
        }
        let per_object = 1 + counts[..n].iter().copied().max().unwrap_or(0);
        // Packed `per_object` to an object, as `integrate` takes them.
        for k in 1..n {
            for i in 0..per_object {
                users[k * per_object + i] = users[k * MAX_SITES + i];
            }
        }
        integrate(
            world,
            copy,
            &users[..n * per_object],
            per_object,
            1,
            dt,
            &mut [],
        );
        // What each received force did (the step's mean motion, as `integrate` counts work).
        for k in 0..n {
            let mass = &world.bodies[k].mass;
            let after = copy.objects()[k].state;
            let dx = after.pos - before[k].pos;
            let omega_mid = (before[k].omega(mass) + after.omega(mass)) * 0.5;
            let received = &users[k * per_object + 1..k * per_object + 1 + counts[k]];
            for (f, &(j, torque)) in received.iter().zip(&sites[k]) {
                let w = f.force.dot(&dx) + torque.dot(&omega_mid) * dt;
                self.spent_j[k][j] += w.max(0.0);
            }
        }
    }
    fn peer_lost(&mut self, from: usize, now_s: f64) {
        if let Some(at) = self.lost_at.get_mut(from) {
            if self.remote.iter().any(|o| o[from].is_some()) {
                at.get_or_insert(now_s);
            }
        }
    }
    /// One report per object the own user touches or let go of less than
    /// [`NAIVE_RELEASE_REPORTS_S`] ago; in a world of one object, that object always.
    fn report(&self, copy: &WorldCopy, own: &[ContactForce], now_s: f64, out: Sink<'_>) {
        let n = copy.len().min(own.len());
        for (k, (force, o)) in own.iter().zip(copy.objects()).enumerate() {
            if n > 1 && now_s - self.last_touch_s[k] > NAIVE_RELEASE_REPORTS_S {
                continue;
            }
            out(Report::Force {
                object: k,
                t_s: now_s,
                force: *force,
                given_j: o.energy.own_positive_j,
            });
        }
    }
    fn receive(
        &mut self,
        _w: &World,
        _c: &mut WorldCopy,
        from: usize,
        msg: &Report,
        _now: f64,
    ) -> Option<Adoption> {
        let Report::Force {
            object,
            t_s,
            force,
            given_j,
        } = msg
        else {
            return None;
        };
        let slot = self.remote.get_mut(*object)?.get_mut(from)?;
        if slot.is_none_or(|(t, _)| *t_s > t) {
            *slot = Some((*t_s, *force));
            // Heard again; a NaN gives nothing.
            self.lost_at[from] = None;
            let given = if given_j.is_finite() { *given_j } else { 0.0 };
            self.allowed_j[*object][from] = given * (1.0 + NAIVE_SLACK_FRACTION) + NAIVE_SLACK_J;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyState;
    use crate::world::fixtures::world;

    #[test]
    fn a_lost_sites_force_fades_out_instead_of_freezing() {
        let w = world();
        let mut naive = Naive::default();
        let mut copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 1.0)));
        let push = ContactForce {
            force: Vec3::new(1.0, 0.0, 0.0),
            point: Vec3::new(0.0, 0.0, 1.0),
            depth: 1e-3,
            touching: true,
            ..ContactForce::default()
        };
        let msg = Report::Force {
            object: 0,
            t_s: 0.0,
            force: push,
            given_j: 0.0,
        };
        naive.receive(&w, &mut copy, 1, &msg, 0.0);
        assert_eq!(naive.remote_force().x, 1.0);
        naive.peer_lost(1, 0.0);
        let none = ContactForce::default();
        let mut seen = Vec::new();
        for k in 1..=200 {
            copy.set_time(k as f64 * 1e-3);
            naive.physics_step(&w, &mut copy, &[none], 1e-3);
            seen.push(naive.remote_force().x);
        }
        assert_eq!(naive.remote_force(), Vec3::zeros(), "gone after the fade");
        assert!(
            naive.remote.iter().flatten().all(Option::is_none),
            "the lost site's force is dropped"
        );
        // Heard again: its new force applies in full.
        naive.receive(
            &w,
            &mut copy,
            1,
            &Report::Force {
                object: 0,
                t_s: 0.3,
                force: push,
                given_j: 0.0,
            },
            0.3,
        );
        assert_eq!(naive.remote_force().x, 1.0);
    }

    /// `naive`'s no-gain bound: a received force does on this copy at most the work its user did
    /// on their own (`given_j`, plus the slack), takes energy freely, and applies unchanged while
    /// it fits.
    #[test]
    fn a_received_force_gives_at_most_what_its_user_gave() {
        // Weightless: the push acts along the line through the centre of mass, no torque.
        let w = World {
            gravity: Vec3::zeros(),
            ..world()
        };
        let push = |x: f64| ContactForce {
            force: Vec3::new(x, 0.0, 0.0),
            point: Vec3::new(0.0, 1.0, 0.0),
            depth: 1e-3,
            touching: true,
            ..ContactForce::default()
        };
        // A free copy (1 m above the plane) pushed by a remote 1 N whose user has given
        // `given_j`, reported every `every` steps and arriving at once (`run`: every 10 ms).
        let reported = |vel: Vec3, force: f64, given_j: f64, steps: usize, every: usize| {
            let mut naive = Naive::default();
            let start = BodyState {
                vel,
                ..BodyState::at_rest(Vec3::new(0.0, 1.0, 0.0))
            };
            let mut copy = WorldCopy::one(start);
            for k in 0..steps {
                if k % every == 0 {
                    let now = copy.first().time_s;
                    let msg = Report::Force {
                        object: 0,
                        t_s: now,
                        force: push(force),
                        given_j,
                    };
                    naive.receive(&w, &mut copy, 1, &msg, now);
                }
                naive.physics_step(&w, &mut copy, &[ContactForce::default()], 1e-3);
            }
            let e = |s: &BodyState| s.mechanical_energy(&w.bodies[0].mass, w.gravity);
            (e(&copy.first().state) - e(&start), copy)
        };
        let run = |vel: Vec3, force: f64, given_j: f64, steps: usize| {
            reported(vel, force, given_j, steps, 10)
        };
        let given = 1e-2;
        let most = given * (1.0 + NAIVE_SLACK_FRACTION) + NAIVE_SLACK_J;
        let (gain, copy) = run(Vec3::zeros(), 1.0, given, 2000);
        // At most one report period (10 ms at up to 0.2 m/s) beyond it.
        assert!(gain <= most + 2e-3, "gained {gain} J, {given} J given");
        assert!(gain > given, "the given work is used: {gain} J");
        assert!(copy.first().energy.remote_denied_j > 0.0);
        // Ample: Eq. 8 unchanged, 1 N on 0.1 kg for 0.1 s.
        let (_, copy) = run(Vec3::zeros(), 1.0, 10.0, 100);
        assert!(
            (copy.first().state.vel.x - 1.0).abs() < 0.01,
            "{}",
            copy.first().state.vel.x
        );
        assert_eq!(copy.first().energy.remote_denied_j, 0.0);
        // Reported once, its next report still on the way (a 2 s delay): the force stops doing
        // work as soon as it has done here what its user gave, not when a report shows it.
        let (gain, _) = reported(Vec3::zeros(), 1.0, given, 2000, 4000);
        assert!(gain <= most + 1e-3, "gained {gain} J, {given} J given");
        // Taking energy needs nothing given: a copy at 1 m/s stopped by a 1 N brake in 0.1 s.
        let (gain, copy) = run(Vec3::new(1.0, 0.0, 0.0), -1.0, 0.0, 100);
        assert!(
            copy.first().state.vel.x.abs() < 0.01,
            "{}",
            copy.first().state.vel.x
        );
        assert!(gain < -0.04, "{gain}");
    }
}
