//! Dead reckoning: where a received state has got to since it was sent.
//!
//! Order selectable: 0 adopts the state as it was; 1 extrapolates with constant velocity; 2 also
//! with gravity less what the environment supports ([`crate::world::supported_gravity`]; not the sender's user's
//! transient push, which the receiver cannot predict), and with kinetic friction slowing a slide on
//! a supporting plane until it stops. "Gravity-aware": a state in free flight falls along the
//! parabola, and a state resting on the floor, whose support cancels gravity, stays put. An
//! extrapolated state is never left inside the environment: it is moved out of any plane it
//! penetrates and its velocity into the plane removed.

use crate::body::{BodyState, Vec3};
use crate::world::{plane_depth, push_out_of_environment, World};
use nalgebra::UnitQuaternion;

/// Extrapolates `s` by `dt` seconds (see the module docs for the orders).
pub fn dead_reckon(
    world: &World,
    k: usize,
    s: &BodyState,
    accel: Vec3,
    dt: f64,
    order: u8,
) -> BodyState {
    if order == 0 || dt <= 0.0 {
        return *s;
    }
    let omega = s.omega(&world.bodies[k].mass);
    let mut out = BodyState {
        pos: s.pos + s.vel * dt,
        rot: UnitQuaternion::from_scaled_axis(omega * dt) * s.rot,
        ..*s
    };
    if order >= 2 {
        out.pos += accel * (0.5 * dt * dt);
        out.vel += accel * dt;
        slide_with_friction(world, k, s, accel, dt, &mut out);
    }
    push_out_of_environment(world, &world.bodies[k].shape, &mut out);
    out
}

/// `reckoned`, the state `s` sent of object `k` dead-reckoned ([`dead_reckon`]), as every method
/// that adopts or follows a sent state must take it for a passive object: holding no more energy
/// than the state sent, as the reckoner puts it on the environment's surface, up to
/// [`DEAD_RECKONING_SLACK_J`]. A state reported resting on a table but leaving it fast (a disk a
/// tool flicked up) is reckoned with the support's zero acceleration: unbounded, it flies on
/// unslowed by gravity (0.44 m up after 0.5 s at 0.87 m/s).
pub fn passive_reckoned(world: &World, k: usize, s: &BodyState, reckoned: BodyState) -> BodyState {
    let new = reckoned;
    let mut sent = *s;
    push_out_of_environment(world, &world.bodies[k].shape, &mut sent);
    super::tank::bound_gain(world, k, &sent, &new, DEAD_RECKONING_SLACK_J, None)
        .map_or(new, |(bounded, _)| bounded)
}

/// Order 2 on a supporting plane: the tangential velocity decays under kinetic friction
/// (μ_k times the supported part of gravity) and stops, rather than sliding on for ever.
fn slide_with_friction(
    world: &World,
    k: usize,
    s: &BodyState,
    accel: Vec3,
    dt: f64,
    out: &mut BodyState,
) {
    for plane in world.planes() {
        let n = plane.normal;
        let support = -(world.gravity.dot(&n));
        if support <= 0.0 || plane_depth(&world.bodies[k].shape, plane, s) <= -1e-4 {
            continue;
        }
        let v_t = s.vel - n * s.vel.dot(&n);
        let speed = v_t.norm();
        let decel = world.env_contact.friction_kinetic * support;
        if speed < 1e-12 || decel <= 0.0 {
            continue;
        }
        let dir = v_t / speed;
        let t = dt.min(speed / decel);
        let along = speed * t - 0.5 * decel * t * t;
        // Replace the frictionless tangential advance with the decelerating one.
        let a_t = accel - n * accel.dot(&n);
        out.pos += dir * along - v_t * dt - a_t * (0.5 * dt * dt);
        out.vel += dir * (speed - decel * t) - v_t - a_t * dt;
    }
}

/// The energy a dead-reckoned state may hold beyond the state it was reckoned from, J: rounding
/// only (a ballistic flight keeps its energy, but not to the bit).
pub const DEAD_RECKONING_SLACK_J: f64 = 1e-9;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::fixtures::{on_a_table, world};
    use crate::world::supported_gravity;

    /// Second-order dead reckoning is exact in free flight; first order misses ½ g Δ².
    #[test]
    fn gravity_aware_dead_reckoning_follows_the_parabola() {
        let w = world();
        let s = BodyState {
            vel: Vec3::new(0.2, 0.5, 0.0),
            ..BodyState::at_rest(Vec3::new(0.0, 0.2, 0.0))
        };
        let dt = 0.3;
        let exact = s.pos + s.vel * dt + w.gravity * (0.5 * dt * dt);
        assert!((dead_reckon(&w, 0, &s, w.gravity, dt, 2).pos - exact).norm() < 1e-12);
        assert!((dead_reckon(&w, 0, &s, w.gravity, dt, 1).pos - exact).norm() > 0.1);
    }

    /// A resting object (support cancels gravity) is not extrapolated through the floor.
    #[test]
    fn dead_reckoning_never_enters_the_environment() {
        let w = world();
        let s = BodyState {
            vel: Vec3::new(0.0, -0.5, 0.0),
            ..BodyState::at_rest(Vec3::new(0.0, -0.06, 0.0))
        };
        let r = dead_reckon(&w, 0, &s, w.gravity, 0.5, 2);
        assert!(r.pos.y >= -0.06 - 1e-12, "{}", r.pos.y);
        assert!(r.vel.y >= 0.0);
    }
    /// Order 2 on a table: a slide decelerates under kinetic friction and stops where physics stops it.
    #[test]
    fn dead_reckoning_slides_to_a_stop() {
        let (w, s) = on_a_table(Vec3::new(0.2, 0.0, 0.0));
        let a = supported_gravity(&w, &w.bodies[0].shape, &s);
        assert!(a.norm() < 1e-12, "a table carries all of gravity: {a:?}");
        let decel = w.env_contact.friction_kinetic * 9.81 / 3.0;
        let stop = 0.2 * 0.2 / (2.0 * decel);
        let r = dead_reckon(&w, 0, &s, a, 5.0, 2);
        assert!(
            (r.pos.x - stop).abs() < 1e-12 && r.vel.norm() < 1e-12,
            "{:?}",
            r.pos
        );
    }
}
