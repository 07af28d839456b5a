//! The model's step functions allocate nothing (H6): the station's servo and physics loops call
//! them every tick. A counting global allocator watches thousands of servo steps, physics steps of
//! both methods, and paper adoptions with replay.

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::{ContactForce, ContactParams, Plane};
use coop_model::device::{ScaraForceLoop, ScaraParams};
use coop_model::method::{Consistency, Naive, Paper, Report, WorldCopy, MAX_SITES};
use coop_model::servo::{Servo, ServoInput, ServoParams};
use coop_model::shape::Shape;
use coop_model::world::{Body, World};

// The one counting allocator of the workspace's tests (a dev-dependency on coop-rt would break this
// crate's purity, so the file is included rather than imported).
#[path = "../../tests/common/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations_during as allocations;

fn contact() -> ContactParams {
    ContactParams {
        stiffness_n_per_m: 800.0,
        damping_n_s_per_m: 3.0,
        tangential_stiffness_n_per_m: 800.0,
        tangential_damping_n_s_per_m: 3.0,
        friction_static: 0.9,
        friction_kinetic: 0.7,
        rotational_friction_radius_m: 0.0,
    }
}

fn world() -> World {
    let shape = Shape::Cylinder {
        radius: 0.04,
        half_height: 0.01,
    };
    World::new(
        &[Body::solid(shape, 0.1)],
        Vec3::new(0.0, 0.0, -3.27),
        &[Plane {
            normal: Vec3::z(),
            offset: 0.0,
        }],
        contact(),
    )
}

#[test]
fn counting_allocator_counts() {
    assert!(allocations(|| drop(std::hint::black_box(vec![0u8; 8]))) >= 1);
}

#[test]
fn servo_with_display_blending_physics_and_adoption_steps_allocate_nothing() {
    let w = world();
    let start = BodyState::at_rest(Vec3::new(0.0, 0.0, 0.0099));
    let arm = ScaraParams::paper(Vec3::new(-0.3, -0.2, 0.0));
    let params = ServoParams {
        tool_radius_m: 0.005,
        contact: contact(),
        stale_limit_s: 0.1,
        stale_ramp_s: 0.05,
        max_ramp_in_tick_s: coop_model::servo::MAX_RAMP_IN_TICK_S,
        max_adoption_step_n: 0.5,
        display: coop_model::display::DisplayParams {
            enabled: true,
            ..Default::default()
        },
    };
    let mut servo = Servo::new(params);
    // And the servo without the display stages (the bounded adoption step).
    let mut plain = Servo::new(ServoParams {
        display: Default::default(),
        ..params
    });
    let mut force_loop = ScaraForceLoop::new(arm, Default::default());
    let q = arm
        .inverse(Vec3::new(-0.044, 0.0, 0.01), 1.0)
        .expect("reachable");
    let mut paper = Paper::new(2, 0);
    let mut naive = Naive::default();
    let (mut a, mut b) = (WorldCopy::one(start), WorldCopy::one(start));
    let mut included = [-1.0; MAX_SITES];
    let n = allocations(|| {
        for k in 0..5_000 {
            let now = k as f64 * 1e-3;
            // A correction every 97 ticks: the display blends it out (its second contact runs).
            if k % 97 == 0 {
                a.first_mut().state.pos.x += 2e-3;
            }
            let inp = ServoInput {
                now_s: now,
                dt_s: 1e-3,
                tool_pos: arm.forward(&q),
                tool_vel: arm.jacobian(&q) * Vec3::zeros(),
                objects: std::slice::from_ref(&a.first().state),
                object_time_s: if k % 1000 < 900 { now } else { now - 1.0 }, // stale ramps too
                adopted: k % 7 == 0,
                stopping: false,
            };
            plain.step(&inp, w.bodies());
            let out = servo.step(&inp, w.bodies());
            force_loop.step(out.f_desired, out.scale, Vec3::zeros(), &q, 1e-3);
            let own: &[ContactForce] = &out.contacts[..w.object_count];
            paper.physics_step(&w, &mut a, own, 1e-3);
            naive.physics_step(&w, &mut b, own, 1e-3);
            naive.receive(
                &w,
                &mut b,
                1,
                &Report::Force {
                    object: 0,
                    t_s: now,
                    force: own[0],
                    given_j: 0.01,
                },
                now,
            );
            included[1] = now;
            let msg = Report::State {
                object: 0,
                t_s: now,
                state: b.first().state,
                accel: Vec3::zeros(),
                included,
            };
            paper.receive(&w, &mut a, 1, &msg, now);
        }
    });
    assert_eq!(n, 0, "the model's step functions allocated {n} times");
    // The forced jumps went through the display's blending, not around it.
    assert!(
        servo.display_stats().corrections >= 50,
        "{:?}",
        servo.display_stats()
    );
}

/// Stepping the largest world allocates nothing: sixteen objects in a heap on the table, every
/// pair and plane contact with rotational friction, and a force on each.
#[test]
fn a_world_of_the_most_objects_steps_without_allocating() {
    use coop_model::method::integrate;
    use coop_model::world::{cube_heap, MAX_OBJECTS};
    let law = ContactParams {
        rotational_friction_radius_m: 0.01,
        ..contact()
    };
    let table = [Plane {
        normal: Vec3::z(),
        offset: 0.0,
    }];
    let (bodies, states) = cube_heap(MAX_OBJECTS, 0.02, 0.1);
    let world = World::new(&bodies, Vec3::new(0.0, 0.0, -9.81), &table, law);
    // Made before the counting window: a copy allocates its tables once, stepping it never.
    let mut copy = WorldCopy::new(&states);
    // A force through each object's centre (one tool per object), as the wrench was.
    let mut users = [ContactForce::default(); MAX_OBJECTS];
    let n = allocations(|| {
        for _ in 0..500 {
            for (u, o) in users.iter_mut().zip(copy.objects()) {
                *u = ContactForce {
                    force: Vec3::new(0.01, 0.0, 0.0),
                    point: o.state.pos,
                    depth: 1e-3,
                    touching: true,
                    ..ContactForce::default()
                };
            }
            integrate(&world, &mut copy, &users, 1, 1, 1e-3, &mut []);
        }
    });
    assert_eq!(n, 0, "stepping {MAX_OBJECTS} objects allocated {n} times");
    assert!(
        copy.pairs().iter().any(|p| p.touching()),
        "the heap touches"
    );
}

/// The largest world (sixteen cubes in a heap on a table) and two sites' tool radii.
fn heap_for_two() -> (
    World,
    [BodyState; coop_model::world::MAX_OBJECTS],
    [f64; MAX_SITES],
) {
    use coop_model::world::{cube_heap, MAX_OBJECTS};
    let table = [Plane {
        normal: Vec3::z(),
        offset: 0.0,
    }];
    let (bodies, states) = cube_heap(MAX_OBJECTS, 0.02, 0.1);
    let world = World::new(&bodies, Vec3::new(0.0, 0.0, -9.81), &table, contact());
    let mut radii = [0.0; MAX_SITES];
    radii[..2].fill(0.005);
    (world, states, radii)
}

/// The methods that keep a copy per object (`naive`, `paper`, `coupled`) step, report and take
/// each other's reports on the largest world without allocating: two sites, every object touched
/// by the own tool, every report of one handed to the other.
#[test]
fn every_method_on_the_most_objects_steps_reports_and_receives_without_allocating() {
    use coop_model::method::Coupled;
    use coop_model::world::MAX_OBJECTS;
    let (world, states, radii) = heap_for_two();
    let pair = |make: &dyn Fn(usize) -> Box<dyn Consistency>| [make(0), make(1)];
    let mut methods = [
        pair(&|_| Box::<Naive>::default()),
        pair(&|i| Box::new(Paper::new(2, i).with_tool(0.005, 800.0))),
        pair(&|i| Box::new(Coupled::new(i, 2, 1e-3, contact(), radii, 100))),
    ];
    let mut copies: Vec<[WorldCopy; 2]> = (0..methods.len())
        .map(|_| [WorldCopy::new(&states), WorldCopy::new(&states)])
        .collect();
    // Each tool pressing on every object's centre a little, so every object is the own site's.
    let mut own = [ContactForce::default(); MAX_OBJECTS];
    let mut sent =
        [[Report::Tools(coop_model::method::track::ToolReport::NONE); MAX_OBJECTS + 1]; 2];
    let mut reports = 0usize;
    let n = allocations(|| {
        for k in 0..300 {
            let now = k as f64 * 1e-3;
            for (site_methods, site_copies) in methods.iter_mut().zip(copies.iter_mut()) {
                let mut counts = [0usize; 2];
                for i in 0..2 {
                    let (m, copy) = (&mut site_methods[i], &mut site_copies[i]);
                    for (u, o) in own.iter_mut().zip(copy.objects()) {
                        *u = ContactForce {
                            force: Vec3::new(0.01, 0.0, 0.0),
                            point: o.state.pos,
                            depth: 1e-3,
                            touching: true,
                            ..ContactForce::default()
                        };
                    }
                    m.own_tool(copy.first().state.pos);
                    m.physics_step(&world, copy, &own, 1e-3);
                    m.report(copy, &own, now, &mut |r| {
                        if counts[i] < sent[i].len() {
                            sent[i][counts[i]] = r;
                            counts[i] += 1;
                        }
                    });
                }
                for i in 0..2 {
                    let other = 1 - i;
                    for r in &sent[other][..counts[other]] {
                        site_methods[i].receive(&world, &mut site_copies[i], other, r, now);
                    }
                }
                reports += counts[0] + counts[1];
            }
        }
    });
    assert_eq!(n, 0, "the per-object methods allocated {n} times");
    // Every object was reported by some method on some tick.
    assert!(reports >= 300 * MAX_OBJECTS, "{reports} reports");
}

/// `timewarp` on the largest world rolls back without allocating: two sites whose tools move
/// through a heap of sixteen cubes, each one's track reaching the other 30 ticks late, so every
/// report rolls the other back over the objects the late tool reaches; one of them sends its
/// tool through the perceptual deadband.
#[test]
fn timewarp_rollbacks_on_the_most_objects_allocate_nothing() {
    use coop_model::method::TimeWarp;
    use coop_model::world::MAX_OBJECTS;
    let (world, states, radii) = heap_for_two();
    let start = WorldCopy::new(&states);
    let mut sites: Vec<(TimeWarp, WorldCopy)> = (0..2)
        .map(|i| {
            let mut tw = TimeWarp::new(i, 2, 1e-3, contact(), radii, 200, &start);
            // Site 1 sends its tool through the perceptual deadband (its filter is on the path).
            if i == 1 {
                tw.set_deadband(coop_model::method::timewarp::DeadbandSpec {
                    enabled: true,
                    ..Default::default()
                });
            }
            (tw, start.clone())
        })
        .collect();
    // Reports in flight: (due tick, from, to, report), a fixed ring.
    let mut flight = [(
        i64::MAX,
        0usize,
        0usize,
        Report::Tools(coop_model::method::track::ToolReport::NONE),
    ); 16];
    let none = [ContactForce::default(); MAX_OBJECTS];
    let n = allocations(|| {
        for k in 0..600i64 {
            let now = k as f64 * 1e-3;
            for f in flight.iter_mut().filter(|f| f.0 == k) {
                let (tw, copy) = &mut sites[f.2];
                tw.receive(&world, copy, f.1, &f.3, now);
                f.0 = i64::MAX;
            }
            for (i, (tw, copy)) in sites.iter_mut().enumerate() {
                // Each tool sweeps along one side of the heap and back.
                let x = -0.06 + 0.12 * ((k as f64 / 300.0).sin().abs());
                let y = if i == 0 { -0.025 } else { 0.025 };
                tw.own_tool(Vec3::new(x, y, 0.02));
                tw.physics_step(&world, copy, &none, 1e-3);
                if k % 10 == 9 {
                    tw.report(copy, &none, now, &mut |r| {
                        if let Some(slot) = flight.iter_mut().find(|f| f.0 == i64::MAX) {
                            *slot = (k + 30, i, 1 - i, r);
                        }
                    });
                }
            }
        }
    });
    assert_eq!(
        n, 0,
        "timewarp on {MAX_OBJECTS} objects allocated {n} times"
    );
    let rolled: u64 = sites
        .iter()
        .map(|(tw, _)| tw.rollback_stats().rollbacks)
        .sum();
    assert!(
        rolled > 10,
        "the late tracks rolled the sites back: {rolled}"
    );
}
