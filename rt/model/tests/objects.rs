//! Several objects that touch each other (`method::integrate`, `contact::pair_wrench`): a stack
//! rests, a box rests on a fixture, a collision conserves momentum and gains no energy, the same
//! inputs give the same bits, and one object steps exactly as the single-body step does.

use coop_model::body::{self, BodyState, Vec3, Wrench};
use coop_model::contact::{
    environment_wrench, ContactForce, ContactParams, EnvContactState, Plane,
};
use coop_model::method::{integrate, WorldCopy};
use coop_model::shape::Shape;
use coop_model::world::{pair_index, Body, World};

const DT: f64 = 1e-3;

/// Boxes on a table and on each other: stiff, well damped, wood-on-wood friction, no rotational
/// friction (the tests that need it set it).
fn law() -> ContactParams {
    ContactParams {
        stiffness_n_per_m: 3000.0,
        damping_n_s_per_m: 30.0,
        tangential_stiffness_n_per_m: 3000.0,
        tangential_damping_n_s_per_m: 15.0,
        friction_static: 0.5,
        friction_kinetic: 0.4,
        rotational_friction_radius_m: 0.0,
    }
}

/// A cylinder of `radius`, `half_height` and `mass_kg`, and the turn that stands its axis (body z)
/// along world y, the table's normal.
fn along_y(radius: f64, half_height: f64, mass_kg: f64) -> (Body, nalgebra::UnitQuaternion<f64>) {
    let shape = Shape::Cylinder {
        radius,
        half_height,
    };
    let turn =
        nalgebra::UnitQuaternion::from_axis_angle(&Vec3::x_axis(), -std::f64::consts::FRAC_PI_2);
    (Body::solid(shape, mass_kg), turn)
}

fn table() -> [Plane; 1] {
    [Plane {
        normal: Vec3::y(),
        offset: 0.0,
    }]
}

/// Every object's state in `copy`, in the world's order.
fn states(copy: &WorldCopy) -> Vec<BodyState> {
    copy.objects().iter().map(|o| o.state).collect()
}

/// A tool's contact pushing an object at `s` with `force` through its centre of mass (a wrench
/// of `force` and no torque).
fn through_centre(force: Vec3, s: &BodyState) -> ContactForce {
    ContactForce {
        force,
        point: s.pos,
        depth: 1e-3,
        touching: true,
        ..ContactForce::default()
    }
}

/// A pure torque `torque` about world y on an object at `s`, as two tools' contacts: opposite
/// forces 2 cm either side of its centre (a couple; a contact carries a force at a point, not a
/// torque).
fn twist_about_y(torque: f64, s: &BodyState) -> [ContactForce; 2] {
    let (arm, force) = (
        Vec3::new(0.02, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -torque / 0.04),
    );
    [
        ContactForce {
            point: s.pos + arm,
            ..through_centre(force, s)
        },
        ContactForce {
            point: s.pos - arm,
            ..through_centre(-force, s)
        },
    ]
}

/// Steps `copy` for `seconds` in `world`, nothing applied; the largest distance any object moved
/// from where it was after `settle_s`, m.
fn run(world: &World, copy: &mut WorldCopy, settle_s: f64, seconds: f64) -> f64 {
    let settle = (settle_s / DT).round() as usize;
    let mut rested: Vec<BodyState> = states(copy);
    let mut worst: f64 = 0.0;
    for k in 0..(seconds / DT).round() as usize {
        integrate(world, copy, &[], 0, 0, DT, &mut []);
        if k + 1 == settle {
            rested = states(copy);
        }
        if k + 1 > settle {
            for (o, r) in copy.objects().iter().zip(&rested) {
                worst = worst.max((o.state.pos - r.pos).norm());
            }
        }
    }
    worst
}

/// The stack the next two tests rest on a table tilted 10° (gravity tilted; static friction, 0.5,
/// holds up to 26°): a small box on a larger one, off its centre, so friction must hold both
/// along the slope and the lower box from turning under its load. Steps it 11 s, rotational
/// friction over a patch of `radius_m`; the most either moved in the last 10 s, m, and the states.
fn slope_stack(radius_m: f64) -> (f64, [BodyState; 2], WorldCopy) {
    let planes = table();
    let law = ContactParams {
        rotational_friction_radius_m: radius_m,
        ..law()
    };
    let (sin, cos) = 10f64.to_radians().sin_cos();
    let gravity = Vec3::new(9.81 * sin, -9.81 * cos, 0.0);
    let bodies = [
        Body::solid(
            Shape::Box {
                half: Vec3::new(0.05, 0.02, 0.05),
            },
            0.2,
        ),
        Body::solid(
            Shape::Box {
                half: Vec3::new(0.03, 0.02, 0.03),
            },
            0.1,
        ),
    ];
    let world = World::new(&bodies, gravity, &planes, law);
    let mut copy = WorldCopy::new(&[
        BodyState::at_rest(Vec3::new(0.0, 0.02, 0.0)),
        BodyState::at_rest(Vec3::new(0.005, 0.06, -0.004)),
    ]);
    let moved = run(&world, &mut copy, 1.0, 11.0);
    let states = [copy.objects()[0].state, copy.objects()[1].state];
    (moved, states, copy)
}

/// With rotational friction the stack rests: after a second to settle, neither box moves by more
/// than 0.1 mm over 10 s (no creep, no jitter), each sunk where its support carries its weight,
/// the top box still where it was put.
#[test]
fn a_stack_of_two_boxes_rests_on_a_slope() {
    let (moved, states, copy) = slope_stack(0.02);
    assert!(moved <= 1e-4, "moved {:.3} mm while resting", moved * 1e3);
    // The table carries the whole stack's weight with K times its deepest penetration (a corner:
    // the off-centre load tilts the lower box a little).
    let cos = 10f64.to_radians().cos();
    let mut corners = [Vec3::zeros(); 16];
    let count = Shape::Box {
        half: Vec3::new(0.05, 0.02, 0.05),
    }
    .probe_points(&mut corners);
    let deepest = corners[..count]
        .iter()
        .map(|c| -(states[0].pos + states[0].rot * c).y)
        .fold(f64::NEG_INFINITY, f64::max);
    let carried = 3000.0 * deepest / (0.3 * 9.81 * cos);
    assert!(
        (carried - 1.0).abs() < 0.01,
        "the table carries {carried} of the stack"
    );
    // The top box sits on the lower one's top face, sunk in by its weight's share at most.
    let gap = states[1].pos.y - 0.02 - (states[0].pos.y + 0.02);
    assert!(
        gap < 0.0 && gap > -2e-3,
        "the top box's bottom is {gap} m off the lower's top"
    );
    assert!(copy.pairs()[pair_index(0, 1, 2)].touching());
    assert!(
        (states[1].pos.x - 0.005).abs() < 1e-3,
        "{:?}",
        states[1].pos
    );
    assert!(states[0].rot.angle() < 1e-2 && states[1].rot.angle() < 1e-2);
}

/// Without it (the paper's law: rotational friction negligible), nothing holds the lower box from
/// turning under the off-centre load: it swings about the table's normal and the top box with it.
#[test]
fn without_rotational_friction_a_box_turns_under_an_off_centre_load() {
    let (moved, states, _) = slope_stack(0.0);
    assert!(moved > 1e-3, "moved {:.3} mm", moved * 1e3);
    assert!(
        states.iter().any(|s| s.rot.angle() > 0.01),
        "{:?}",
        states.map(|s| s.rot.angle())
    );
}

/// A cylinder standing on a fixture (a fixed box, no table): it rests, the fixture never moves.
#[test]
fn an_object_rests_on_a_fixture() {
    let fixture = Body {
        fixed: true,
        ..Body::solid(
            Shape::Box {
                half: Vec3::new(0.1, 0.01, 0.1),
            },
            1.0,
        )
    };
    // A can standing on its end.
    let (can, upright) = along_y(0.03, 0.05, 0.15);
    let world = World::new(&[fixture, can], Vec3::new(0.0, -9.81, 0.0), &[], law());
    let fixed_at = BodyState::at_rest(Vec3::zeros());
    let mut copy = WorldCopy::new(&[
        fixed_at,
        BodyState {
            rot: upright,
            ..BodyState::at_rest(Vec3::new(0.0, 0.06, 0.0))
        },
    ]);
    let moved = run(&world, &mut copy, 1.0, 11.0);
    let states = states(&copy);
    assert!(moved <= 1e-4, "moved {:.3} mm while resting", moved * 1e3);
    assert_eq!(states[0], fixed_at, "a fixture never moves");
    assert!(
        states[1].pos.y > 0.059 && states[1].pos.y < 0.06,
        "{:?}",
        states[1].pos
    );
}

/// Two balls meeting head on in free space, off centre: momentum (linear and angular, about the
/// origin) is the same after as before to rounding, kinetic energy is never more, and they part.
#[test]
fn a_collision_conserves_momentum_and_gains_no_energy() {
    let bodies = [
        Body::solid(Shape::Sphere { radius: 0.03 }, 0.2),
        Body::solid(Shape::Sphere { radius: 0.02 }, 0.05),
    ];
    let world = World::new(&bodies, Vec3::zeros(), &[], law());
    let start = [
        BodyState {
            vel: Vec3::new(0.5, 0.0, 0.0),
            ..BodyState::at_rest(Vec3::new(-0.1, 0.0, 0.0))
        },
        BodyState {
            vel: Vec3::new(-0.8, 0.0, 0.0),
            ..BodyState::at_rest(Vec3::new(0.1, 0.02, 0.0))
        },
    ];
    let momentum = |s: &[BodyState]| -> (Vec3, Vec3) {
        s.iter()
            .zip(&bodies)
            .fold((Vec3::zeros(), Vec3::zeros()), |(p, l), (s, b)| {
                let mv = s.vel * b.mass.mass_kg;
                (p + mv, l + s.pos.cross(&mv) + s.ang_mom)
            })
    };
    let energy = |s: &[BodyState]| -> f64 {
        s.iter()
            .zip(&bodies)
            .map(|(s, b)| s.kinetic_energy(&b.mass))
            .sum()
    };
    let (p0, l0, e0) = (momentum(&start).0, momentum(&start).1, energy(&start));
    let mut copy = WorldCopy::new(&start);
    let mut touched = false;
    for _ in 0..400 {
        integrate(&world, &mut copy, &[], 0, 0, DT, &mut []);
        touched |= copy.pairs()[pair_index(0, 1, 2)].touching();
        assert!(energy(&states(&copy)) <= e0 + 1e-12, "gained energy");
    }
    let states = states(&copy);
    let (p1, l1) = momentum(&states);
    assert!(touched, "they met");
    assert!((p1 - p0).norm() < 1e-12, "{p0:?} -> {p1:?}");
    assert!((l1 - l0).norm() < 1e-12, "{l0:?} -> {l1:?}");
    assert!(!copy.pairs()[pair_index(0, 1, 2)].touching());
    let apart = (states[1].vel - states[0].vel).dot(&(states[1].pos - states[0].pos));
    assert!(apart > 0.0, "they part: {states:?}");
    assert!(energy(&states) < e0, "the contact's damping took some");
}

/// Sixteen objects dropped on the table in a heap, twice: the same bits both times.
#[test]
fn the_same_world_steps_to_the_same_bits() {
    let shapes = [
        Shape::Sphere { radius: 0.02 },
        Shape::Box {
            half: Vec3::new(0.02, 0.015, 0.025),
        },
        Shape::Cylinder {
            radius: 0.02,
            half_height: 0.01,
        },
    ];
    let bodies: Vec<Body> = (0..16)
        .map(|k| Body::solid(shapes[k % 3], 0.05 + 0.01 * k as f64))
        .collect();
    let world = World::new(&bodies, Vec3::new(0.0, -9.81, 0.0), &table(), law());
    let start: Vec<BodyState> = (0..16)
        .map(|k| {
            let (x, z) = ((k % 4) as f64 * 0.045, (k / 4) as f64 * 0.045);
            BodyState::at_rest(Vec3::new(
                x + 0.003 * (k % 3) as f64,
                0.03 + 0.02 * (k % 2) as f64,
                z,
            ))
        })
        .collect();
    let once = || {
        let mut copy = WorldCopy::new(&start);
        run(&world, &mut copy, 0.5, 1.0);
        copy
    };
    let (a, b) = (once(), once());
    assert_eq!(a, b);
    assert!(a.pairs().iter().any(|p| p.touching()), "the heap touches");
}

/// One object on a table steps to the same bits as the single-body step with the environment.
#[test]
fn one_object_steps_as_the_single_body_step_does() {
    let (planes, law) = (table(), law());
    let g = Vec3::new(0.0, -3.27, 0.0);
    let disk = Body::solid(
        Shape::Cylinder {
            radius: 0.04,
            half_height: 0.01,
        },
        0.1,
    );
    let tilted = nalgebra::UnitQuaternion::from_axis_angle(&Vec3::x_axis(), 1.4);
    let start = BodyState {
        rot: tilted,
        vel: Vec3::new(0.3, 0.0, 0.1),
        ..BodyState::at_rest(Vec3::new(0.0, 0.045, 0.0))
    };
    let world = World::new(&[disk], g, &planes, law);
    // A tool's push, 0.2 N along x at a point 5 mm off the centre along z (0.001 N·m about y
    // where the step starts), that point following the disk from step to step.
    let push = |s: &BodyState| ContactForce {
        point: s.pos + Vec3::new(0.0, 0.0, 0.005),
        ..through_centre(Vec3::new(0.2, 0.0, 0.0), s)
    };
    let (mut single, mut env) = (start, EnvContactState::default());
    let mut copy = WorldCopy::one(start);
    for _ in 0..3000 {
        let tool = push(&single);
        single = body::step(&single, &disk.mass, g, DT, |s| {
            // The terms `integrate` sums, in its order: the own users', the remote users' (none),
            // the environment's.
            Wrench::default()
                + tool.wrench(s.pos)
                + Wrench::default()
                + environment_wrench(&law, &mut env, &planes, &disk.shape, s, &disk.mass).0
        });
        let tool = push(&copy.first().state);
        integrate(&world, &mut copy, &[tool], 1, 1, DT, &mut []);
    }
    assert_eq!(copy.first().state, single);
    assert_eq!(copy.first().env, env);
}

/// A disk lying on the table, twisted about the table's normal by a torque: below the rotational
/// friction's static limit (μ_s F_n r) it turns by the torsional spring's stretch only and stops;
/// above it, it spins up under the torque less the kinetic limit (μ_k F_n r).
#[test]
fn rotational_friction_holds_below_its_limit_and_slips_above_it() {
    let planes = table();
    let law = ContactParams {
        rotational_friction_radius_m: 0.02,
        ..law()
    };
    let g = 9.81;
    // A disk lying flat.
    let (disk, flat) = along_y(0.04, 0.01, 0.1);
    let world = World::new(&[disk], Vec3::new(0.0, -g, 0.0), &planes, law);
    let at_rest = BodyState {
        rot: flat,
        ..BodyState::at_rest(Vec3::new(0.0, 0.01 - 0.1 * g / 3000.0, 0.0))
    };
    let limit = law.friction_static * 0.1 * g * 0.02;
    let spin = |torque: f64, seconds: f64| {
        let mut copy = WorldCopy::one(at_rest);
        for _ in 0..(seconds / DT).round() as usize {
            let twist = twist_about_y(torque, &copy.first().state);
            integrate(&world, &mut copy, &twist, 2, 2, DT, &mut []);
        }
        copy.first().state.omega(&disk.mass).y
    };
    let held = spin(0.5 * limit, 2.0);
    assert!(held.abs() < 1e-6, "held: spinning at {held} rad/s");
    let slipping = spin(2.0 * limit, 0.5);
    let inertia_y = disk.mass.inertia_body.z;
    let kinetic = law.friction_kinetic * 0.1 * g * 0.02;
    let expected = (2.0 * limit - kinetic) / inertia_y * 0.5;
    assert!(
        slipping > 0.8 * expected && slipping < 1.05 * expected,
        "slipping: {slipping} rad/s, about {expected} expected"
    );
}

/// Equal shapes flush face to face, 1 mm into each other (a row of equal boxes, two coins stacked
/// exactly): every corner or rim point lies on the other's side faces at depth 0, and rounding
/// leaves some a hair inside with opposite normals. The contact is found at its real depth along
/// the faces' normal, finite.
#[test]
fn flush_faces_of_equal_shapes_touch_at_their_depth() {
    use coop_model::contact::{pair_wrench, PairContactState, PairSide};
    let law = law();
    let cube = Body::solid(
        Shape::Box {
            half: Vec3::repeat(0.02),
        },
        0.1,
    );
    let coin = Body::solid(
        Shape::Cylinder {
            radius: 0.02,
            half_height: 0.003,
        },
        0.01,
    );
    for (body, apart) in [
        (cube, Vec3::new(0.039, 0.0, 0.0)),
        (cube, Vec3::new(0.0, 0.0, 0.039)),
        (coin, Vec3::new(0.0, 0.0, 0.005)),
    ] {
        let a = BodyState::at_rest(Vec3::new(0.0, 0.0, 0.0199));
        let b = BodyState::at_rest(a.pos + apart);
        let side = |s| PairSide {
            shape: &body.shape,
            body: s,
            mass: &body.mass,
        };
        let mut memory = PairContactState::default();
        let (on_a, on_b, touching) = pair_wrench(&law, &mut memory, side(&a), side(&b));
        let push = -apart.normalize() * (law.stiffness_n_per_m * 1e-3);
        assert!(touching, "{apart:?}");
        assert!(on_a.is_finite() && on_b.is_finite(), "{on_a:?}");
        assert!(
            (on_a.force - push).norm() < 1e-6 * push.norm(),
            "{:?} not {push:?}",
            on_a.force
        );
        assert_eq!(on_b.force, -on_a.force);
    }
}

/// Two bars crossed, 1 mm into each other, where no corner or face centre of either is inside
/// the other: flat bars crossing away from both their centres (the face contact clipped to the
/// crossing's square), and bars turned 45° about their lengths crossing ridge on ridge (two
/// edges). Each is found at its depth, pushing the bars apart along the vertical.
#[test]
fn crossed_bars_touch_where_they_cross() {
    use coop_model::contact::{pair_wrench, PairContactState, PairSide};
    use nalgebra::UnitQuaternion;
    let law = law();
    let (along_x, along_z) = (Vec3::new(0.1, 0.01, 0.01), Vec3::new(0.01, 0.01, 0.1));
    let bar = |half: Vec3| Body::solid(Shape::Box { half }, 0.2);
    let ridge = 0.01 * std::f64::consts::SQRT_2;
    let quarter = std::f64::consts::FRAC_PI_4;
    let cases = [
        (
            "flat",
            BodyState::at_rest(Vec3::zeros()),
            BodyState::at_rest(Vec3::new(0.05, 0.019, 0.05)),
        ),
        (
            "ridge on ridge",
            BodyState {
                rot: UnitQuaternion::from_axis_angle(&Vec3::x_axis(), quarter),
                ..BodyState::at_rest(Vec3::zeros())
            },
            BodyState {
                rot: UnitQuaternion::from_axis_angle(&Vec3::z_axis(), quarter),
                ..BodyState::at_rest(Vec3::new(0.0, 2.0 * ridge - 1e-3, 0.0))
            },
        ),
    ];
    for (name, lower, upper) in cases {
        let (a, b) = (bar(along_x), bar(along_z));
        let mut memory = PairContactState::default();
        let (on_lower, on_upper, touching) = pair_wrench(
            &law,
            &mut memory,
            PairSide {
                shape: &a.shape,
                body: &lower,
                mass: &a.mass,
            },
            PairSide {
                shape: &b.shape,
                body: &upper,
                mass: &b.mass,
            },
        );
        assert!(touching, "{name}: not found");
        let up = on_upper.force;
        assert!(
            (up.y - law.stiffness_n_per_m * 1e-3).abs() < 1e-6
                && up.x.abs() < 1e-9
                && up.z.abs() < 1e-9,
            "{name}: {up:?}"
        );
        assert_eq!(on_lower.force, -up, "{name}");
    }
}

/// A heap of sixteen cubes left alone on the table falls asleep: after it settles every cube
/// sleeps and steps change no bit. A push on a top cube wakes it; the cube it slides on wakes
/// while it moves; the heap sleeps again once all rest.
#[test]
fn a_resting_heap_sleeps_and_wakes_when_pushed() {
    use coop_model::world::{cube_heap, MAX_OBJECTS, SLEEP_AFTER_STEPS};
    let table = [Plane {
        normal: Vec3::z(),
        offset: 0.0,
    }];
    let law = ContactParams {
        rotational_friction_radius_m: 0.01,
        ..law()
    };
    let (bodies, states) = cube_heap(MAX_OBJECTS, 0.02, 0.1);
    let world = World::new(&bodies, Vec3::new(0.0, 0.0, -9.81), &table, law);
    let mut copy = WorldCopy::new(&states);
    let asleep = |c: &WorldCopy| {
        c.still()
            .iter()
            .filter(|&&s| s >= SLEEP_AFTER_STEPS)
            .count()
    };
    for _ in 0..3000 {
        integrate(&world, &mut copy, &[], 0, 0, DT, &mut []);
    }
    assert_eq!(asleep(&copy), MAX_OBJECTS, "{:?}", copy.still());
    let rested = copy.clone();
    for _ in 0..500 {
        integrate(&world, &mut copy, &[], 0, 0, DT, &mut []);
    }
    // Nothing changes but the copy's time.
    let mut expected = rested.clone();
    expected.set_time(copy.first().time_s);
    assert_eq!(copy, expected, "a sleeping heap does not change");
    // Cube 11 (on cube 3, at the heap's -y side) pushed outwards along -y for 0.1 s: it slides
    // on cube 3, which wakes while it moves.
    let mut push = [ContactForce::default(); MAX_OBJECTS];
    let mut woke = false;
    for _ in 0..100 {
        push[11] = through_centre(Vec3::new(0.0, -0.7, 0.0), &copy.objects()[11].state);
        integrate(&world, &mut copy, &push, 1, 1, DT, &mut []);
        woke |= copy.still()[3] < SLEEP_AFTER_STEPS;
    }
    assert!(woke, "the cube under the moving one woke");
    let pushed = copy.objects()[11].state.pos;
    assert!(
        rested.objects()[11].state.pos.y - pushed.y > 5e-3,
        "{pushed:?}"
    );
    for _ in 0..3000 {
        integrate(&world, &mut copy, &[], 0, 0, DT, &mut []);
    }
    assert_eq!(asleep(&copy), MAX_OBJECTS, "{:?}", copy.still());
}

/// Under a heavy load the rotational friction's kinetic limit (μ_k F_n r) is more than its
/// spring's stiffness (K_t r², the most a spring measured by the sine of its twist could hold): a
/// torque between the two is still held (the spring stretches as far as it must), and one above
/// the static limit slips.
#[test]
fn rotational_friction_holds_a_heavy_load_up_to_its_limit() {
    let planes = table();
    let law = ContactParams {
        tangential_stiffness_n_per_m: 200.0,
        rotational_friction_radius_m: 0.02,
        ..law()
    };
    let g = 9.81;
    let (disk, flat) = along_y(0.04, 0.01, 2.0);
    let world = World::new(&[disk], Vec3::new(0.0, -g, 0.0), &planes, law);
    let stiffness = law.tangential_stiffness_n_per_m * 0.02 * 0.02;
    let limit = law.friction_static * 2.0 * g * 0.02;
    let kinetic = law.friction_kinetic * 2.0 * g * 0.02;
    let torque = 0.85 * kinetic;
    assert!(
        torque > 1.5 * stiffness,
        "the case: {torque} N·m, {stiffness} N·m/rad"
    );
    let spin = |torque: f64| {
        let mut copy = WorldCopy::one(BodyState {
            rot: flat,
            ..BodyState::at_rest(Vec3::new(0.0, 0.01 - 2.0 * g / 3000.0, 0.0))
        });
        // Ramped in over 2 s (quasi-static: no overshoot past the static limit), then held 2 s.
        for k in 0..4000 {
            let ramped = torque * (k as f64 / 2000.0).min(1.0);
            let twist = twist_about_y(ramped, &copy.first().state);
            integrate(&world, &mut copy, &twist, 2, 2, DT, &mut []);
        }
        let s = copy.first().state;
        let turned = (s.rot * flat.inverse()).angle();
        (s.omega(&disk.mass).y, turned)
    };
    // Held where the spring balances it: 2 K_t r² tan(θ/2) = torque.
    let (held, turned) = spin(torque);
    let balance = 2.0 * (torque / (2.0 * stiffness)).atan();
    assert!(
        held.abs() < 0.05 && (turned - balance).abs() < 0.1,
        "held: spinning at {held} rad/s, turned {turned} rad, balanced at {balance}"
    );
    assert!(spin(1.5 * limit).0 > 1.0, "slips above the limit");
}

/// Three cubes in a row, asleep; the first pushed into the second, the second into the third:
/// each awake cube wakes the one it touches, and the whole row moves.
#[test]
fn a_push_down_a_row_wakes_every_sleeper_in_it() {
    use coop_model::world::SLEEP_AFTER_STEPS;
    let table = [Plane {
        normal: Vec3::z(),
        offset: 0.0,
    }];
    let cube = Body::solid(
        Shape::Box {
            half: Vec3::repeat(0.02),
        },
        0.1,
    );
    let world = World::new(&[cube; 3], Vec3::new(0.0, 0.0, -9.81), &table, law());
    let start: [BodyState; 3] =
        std::array::from_fn(|k| BodyState::at_rest(Vec3::new(k as f64 * 0.0405, 0.0, 0.0199)));
    let mut copy = WorldCopy::new(&start);
    for _ in 0..1000 {
        integrate(&world, &mut copy, &[], 0, 0, DT, &mut []);
    }
    assert!(
        copy.still().iter().all(|&s| s >= SLEEP_AFTER_STEPS),
        "{:?}",
        copy.still()
    );
    let rested = states(&copy);
    // Three times the row's friction (0.5 × 3 × 0.98 N) on the first cube, along +x, for 0.3 s.
    let mut push = [ContactForce::default(); 3];
    for _ in 0..300 {
        push[0] = through_centre(Vec3::new(4.5, 0.0, 0.0), &copy.objects()[0].state);
        integrate(&world, &mut copy, &push, 1, 1, DT, &mut []);
    }
    let moved = copy.objects()[2].state.pos.x - rested[2].pos.x;
    assert!(moved > 1e-2, "the last cube moved {moved} m");
}
