//! What one physics step of a world of several objects costs: a heap of boxes with tools pressing
//! into it, stepped whole (asleep where it rests, and with nothing asleep), and its contacts alone,
//! ours beside parry's geometry on the same pairs.

use std::hint::black_box;
use std::time::Instant;

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::{
    environment_wrench, pair_wrench, tool_contact, ContactForce, ContactParams, EnvContactState,
    PairContactState, PairSide, Plane, ToolContactState,
};
use coop_model::method::{integrate, WorldCopy};
use coop_model::scenario::Scenario;
use coop_model::world::{cube_heap, Body, World, MAX_OBJECTS, SLEEP_AFTER_STEPS};

use super::median;

/// What one physics step of a world of several objects costs.
#[derive(Debug, serde::Serialize)]
pub struct WorldStepCost {
    /// Objects in the world.
    pub objects: usize,
    /// Tools, each touching an object.
    pub tools: usize,
    /// One step: every tool's contact with every object, then the objects stepped together
    /// (environment, every pair, Verlet), median, ns: objects at rest and untouched sleep.
    pub step_ns: f64,
    /// ... as a share of the 1 ms physics period.
    pub period_share: f64,
    /// The same with nothing asleep, ns.
    pub step_awake_ns: f64,
    /// The step's contact geometry and laws alone, ours, nothing asleep: every tool with every
    /// object, every object with the table, every pair of objects (points, depths, normals,
    /// penalty, damping, friction memory), median, ns.
    pub contacts_ns: f64,
    /// The same pairs' contact *geometry* alone through `parry3d-f64` 0.25 (`query::contact`:
    /// the deepest point and normal of each pair, no law, no friction; the least a parry-based
    /// step would spend where our contact code is), median, ns.
    pub parry_contacts_ns: f64,
}

/// Our shapes as parry's (the bench's scene is boxes; tools are balls).
fn parry_cuboid(shape: &coop_model::shape::Shape) -> parry3d_f64::shape::Cuboid {
    match *shape {
        coop_model::shape::Shape::Box { half } => parry3d_f64::shape::Cuboid::new(half),
        _ => unreachable!("the world-step scene is a heap of boxes"),
    }
}

/// How much to time: batches (the median is taken over them) of steps each.
#[derive(Debug, Clone, Copy)]
struct Timing {
    batches: usize,
    per_batch: usize,
}

impl Timing {
    /// The median over the batches of `batch`'s time per step, ns (`batch` times `per_batch`
    /// steps itself, outside its untimed set-up).
    fn median_ns(self, mut batch: impl FnMut(usize) -> f64) -> f64 {
        median((0..self.batches).map(|_| batch(self.per_batch)).collect())
    }
}

/// The scene: boxes set down in a heap on a table and settled, tool tips pressing into them.
struct Heap {
    law: ContactParams,
    table: [Plane; 1],
    bodies: [Body; MAX_OBJECTS],
    objects: usize,
    tools: usize,
    /// The world, resting objects asleep.
    sleeping: World,
    /// The same world with nothing asleep.
    awake: World,
    /// The heap settled (a world mid-session, not one just placed).
    settled: WorldCopy,
    /// The settled objects' states.
    states: Vec<BodyState>,
    /// Each tool's tip, and the object it presses into.
    tips: Vec<(Vec3, usize)>,
}

impl Heap {
    /// `objects` boxes (4 cm, 0.1 kg) in a heap on a table, two layers, each touching its
    /// neighbours, and `tools` tool tips (5 mm) pressed 1 mm into boxes around the heap, every
    /// contact under `sc`'s environment law with rotational friction.
    fn new(sc: &Scenario, objects: usize, tools: usize) -> Self {
        let law = ContactParams {
            rotational_friction_radius_m: 0.01,
            ..sc.environment_contact
        };
        let table = [Plane {
            normal: Vec3::z(),
            offset: 0.0,
        }];
        let (bodies, states) = cube_heap(objects, 0.02, 0.1);
        let mut sleeping = World::new(&bodies[..objects], Vec3::new(0.0, 0.0, -9.81), &table, law);
        // A lone object sleeps too here: the figures compare like with like.
        sleeping.sleep_after_steps = SLEEP_AFTER_STEPS;
        let awake = World {
            sleep_after_steps: 0,
            ..sleeping
        };
        // Set down and settled (untimed): a world mid-session, not one just placed.
        let mut settled = WorldCopy::new(&states[..objects]);
        for _ in 0..1500 {
            integrate(&sleeping, &mut settled, &[], 0, 0, 1e-3, &mut []);
        }
        let states: Vec<BodyState> = settled.objects().iter().map(|o| o.state).collect();
        // Tool k presses into object k mod n from outside the heap's side.
        let tips = (0..tools)
            .map(|k| {
                let o = k % objects;
                let side = if k % 2 == 0 { -1.0 } else { 1.0 };
                (states[o].pos + Vec3::new(side * 0.024, 0.0, 0.0), o)
            })
            .collect();
        Self {
            law,
            table,
            bodies,
            objects,
            tools,
            sleeping,
            awake,
            settled,
            states,
            tips,
        }
    }

    /// `steps` whole steps of `world` from the settled heap: every tool's contact with every object
    /// (held over the step), then the objects stepped together; ns per step.
    fn time_steps(&self, world: &World, steps: usize) -> f64 {
        let (objects, tools) = (self.objects, self.tools);
        let mut copy = self.settled.clone();
        let mut memory = [[ToolContactState::default(); MAX_OBJECTS]; 8];
        let mut users = [ContactForce::default(); 8 * MAX_OBJECTS];
        let t0 = Instant::now();
        for _ in 0..steps {
            for (t, (tip, _)) in self.tips.iter().enumerate() {
                for (o, c) in copy.objects().iter().enumerate() {
                    users[o * tools + t] = tool_contact(
                        &self.law,
                        &mut memory[t][o],
                        &self.bodies[o].shape,
                        &c.state,
                        &self.bodies[o].mass,
                        black_box(*tip),
                        Vec3::zeros(),
                        0.005,
                    );
                }
            }
            let users = &users[..objects * tools];
            integrate(world, &mut copy, users, tools, tools, 1e-3, &mut []);
        }
        black_box(&copy);
        t0.elapsed().as_nanos() as f64 / steps as f64
    }

    /// `steps` times our contacts alone on the settled heap, nothing asleep: every tool with every
    /// object, every object with the table, every pair; ns per step.
    fn time_our_contacts(&self, steps: usize) -> f64 {
        let (law, bodies, states) = (&self.law, &self.bodies, &self.states);
        let mut tool_memory = [[ToolContactState::default(); MAX_OBJECTS]; 8];
        let mut env = [EnvContactState::default(); MAX_OBJECTS];
        let mut pairs = [PairContactState::default(); MAX_OBJECTS * MAX_OBJECTS];
        let t0 = Instant::now();
        for _ in 0..steps {
            for (t, (tip, _)) in self.tips.iter().enumerate() {
                for (o, state) in states.iter().enumerate() {
                    black_box(tool_contact(
                        law,
                        &mut tool_memory[t][o],
                        &bodies[o].shape,
                        state,
                        &bodies[o].mass,
                        black_box(*tip),
                        Vec3::zeros(),
                        0.005,
                    ));
                }
            }
            for (o, state) in states.iter().enumerate() {
                black_box(environment_wrench(
                    law,
                    &mut env[o],
                    &self.table,
                    &bodies[o].shape,
                    state,
                    &bodies[o].mass,
                ));
            }
            for i in 0..self.objects {
                for j in i + 1..self.objects {
                    let side = |k: usize| PairSide {
                        shape: &bodies[k].shape,
                        body: &states[k],
                        mass: &bodies[k].mass,
                    };
                    black_box(pair_wrench(
                        law,
                        &mut pairs[i * MAX_OBJECTS + j],
                        side(i),
                        side(j),
                    ));
                }
            }
        }
        t0.elapsed().as_nanos() as f64 / steps as f64
    }

    /// The median of `timing`'s batches of the same pairs' contact geometry through parry, ns per
    /// step.
    fn parry_contacts_ns(&self, timing: Timing) -> f64 {
        use parry3d_f64::math::Isometry;
        use parry3d_f64::query::contact;
        use parry3d_f64::shape::{Ball, HalfSpace};
        let cuboids: Vec<_> = self.bodies[..self.objects]
            .iter()
            .map(|b| parry_cuboid(&b.shape))
            .collect();
        let poses: Vec<Isometry<f64>> = self
            .states
            .iter()
            .map(|s| Isometry::from_parts(s.pos.into(), s.rot))
            .collect();
        let ball = Ball::new(0.005);
        let tip_poses: Vec<Isometry<f64>> = self
            .tips
            .iter()
            .map(|(tip, _)| Isometry::translation(tip.x, tip.y, tip.z))
            .collect();
        let floor = HalfSpace::new(nalgebra::Vector3::z_axis());
        let origin = Isometry::identity();
        timing.median_ns(|steps| {
            let t0 = Instant::now();
            for _ in 0..steps {
                for tp in &tip_poses {
                    for (pose, c) in poses.iter().zip(&cuboids) {
                        black_box(contact(black_box(tp), &ball, pose, c, 0.0).ok());
                    }
                }
                for (pose, c) in poses.iter().zip(&cuboids) {
                    black_box(contact(&origin, &floor, pose, c, 0.0).ok());
                }
                for i in 0..self.objects {
                    for j in i + 1..self.objects {
                        black_box(
                            contact(&poses[i], &cuboids[i], &poses[j], &cuboids[j], 0.0).ok(),
                        );
                    }
                }
            }
            t0.elapsed().as_nanos() as f64 / steps as f64
        })
    }
}

/// The world-step figures: a `Heap` of 1, 4 and 16 boxes, each with 2 and 8 tools; one step
/// computes every tool's contact with every object (held over the step) and steps the objects
/// together, every contact under `sc`'s environment law with rotational friction.
pub fn world_step_figures(sc: &Scenario, quick: bool) -> Vec<WorldStepCost> {
    let timing = if quick {
        Timing {
            batches: 3,
            per_batch: 200,
        }
    } else {
        Timing {
            batches: 15,
            per_batch: 2_000,
        }
    };
    let mut out = Vec::new();
    for objects in [1usize, 4, 16] {
        for tools in [2usize, 8] {
            let heap = Heap::new(sc, objects, tools);
            let step_ns = timing.median_ns(|n| heap.time_steps(&heap.sleeping, n));
            let step_awake_ns = timing.median_ns(|n| heap.time_steps(&heap.awake, n));
            // The contacts alone, ours and parry's, on the settled heap with the tools pressing.
            let contacts_ns = timing.median_ns(|n| heap.time_our_contacts(n));
            out.push(WorldStepCost {
                objects,
                tools,
                step_ns,
                period_share: step_ns / 1e6,
                step_awake_ns,
                contacts_ns,
                parry_contacts_ns: heap.parry_contacts_ns(timing),
            });
        }
    }
    out
}
