//! `sim bench`: what one physics step and one servo step cost, and how fast the simulator runs a
//! scenario, in one run. Each cost is the median of several timed batches (these machines are
//! shared and noisy); the speed is simulated seconds per wall-clock second over whole runs.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::ContactForce;
use coop_model::method::{Consistency, ObjectCopy, Paper};
use coop_model::scenario::MethodName;
use coop_model::servo::{Servo, ServoInput};
use coop_model::sim::{self, Mode};

use coop_actors::scenario_file;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Runs the benchmark and prints its figures.
///
/// # Errors
/// The scenario cannot be loaded.
pub fn run(scenario: &Path, json: bool, quick: bool) -> anyhow::Result<()> {
    let sc = scenario_file::load(scenario)?;
    let world = sc.world();
    let (batches, per_batch) = if quick { (5, 2_000) } else { (21, 50_000) };

    // Physics: one object resting on the table with the own user pushing it (contact + environment).
    let start = BodyState::at_rest(Vec3::from(sc.object.start_m));
    let mut method = Paper::new(sc.dead_reckoning_order, 0);
    let push = ContactForce {
        force: Vec3::new(0.3, 0.05, 0.0),
        point: start.pos - Vec3::new(sc.object.radius_m, 0.0, 0.0),
        depth: 5e-4,
        touching: true,
        slipping: false,
    };
    let dt = 1e-3;
    let physics_ns = median(
        (0..batches)
            .map(|_| {
                let mut copy = ObjectCopy::new(start);
                let t0 = Instant::now();
                for _ in 0..per_batch {
                    method.physics_step(&world, &mut copy, black_box(&push), dt);
                }
                black_box(&copy);
                t0.elapsed().as_nanos() as f64 / per_batch as f64
            })
            .collect(),
    );

    // Servo: kinematics, contact, Eq. 12 controller on site 0's device, tool touching the object.
    let arm = sc.arm(0);
    let mut servo = Servo::new(sc.servo_params(0), arm);
    let q = arm
        .inverse(
            start.pos - Vec3::new(sc.object.radius_m + 0.004, 0.0, 0.0),
            sc.site[0].elbow,
        )
        .unwrap_or_else(|| {
            arm.inverse(Vec3::from(sc.site[0].script[0].target_m), sc.site[0].elbow)
                .unwrap_or_default()
        });
    let servo_ns = median(
        (0..batches)
            .map(|_| {
                let t0 = Instant::now();
                for k in 0..per_batch {
                    let out = servo.step(
                        &ServoInput {
                            now_s: k as f64 * dt,
                            dt_s: dt,
                            q: black_box(q),
                            qd: Vec3::zeros(),
                            f_measured: Vec3::new(0.1, 0.0, 0.0),
                            object: &start,
                            object_time_s: k as f64 * dt,
                            adopted: false,
                            stopping: false,
                        },
                        &world.shape,
                        &world.mass,
                    );
                    black_box(out);
                }
                t0.elapsed().as_nanos() as f64 / per_batch as f64
            })
            .collect(),
    );

    // Whole-run speed per mode.
    let runs = if quick { 1 } else { 3 };
    let mut speeds = Vec::new();
    for mode in [
        Mode::Reference,
        Mode::Distributed(MethodName::Naive),
        Mode::Distributed(MethodName::Paper),
    ] {
        let s = median(
            (0..runs)
                .map(|_| {
                    let t0 = Instant::now();
                    black_box(sim::run(&sc, mode, &mut |_| {}));
                    sc.duration_s / t0.elapsed().as_secs_f64()
                })
                .collect(),
        );
        speeds.push((mode.name(), s));
    }
    if json {
        let v = serde_json::json!({
            "scenario": sc.name,
            "physics_step_ns": physics_ns,
            "servo_step_ns": servo_ns,
            "realtime_factor": speeds.iter().map(|(n, s)| (n.to_string(), serde_json::json!(s))).collect::<serde_json::Map<_, _>>(),
            "goal": "physics step < 1000 ns; paper scenario >= 100x real time",
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!("# sim bench: median of {batches} batches of {per_batch} steps; speed over whole {} s runs of scenario {}", sc.duration_s, sc.name);
        println!("physics step (own contact + environment, Verlet): {physics_ns:>8.0} ns   (goal < 1000 ns)");
        println!("servo step (FK, contact, Eq. 12 PI):              {servo_ns:>8.0} ns");
        for (name, s) in &speeds {
            println!("simulator speed, {name:<9}: {s:>8.0}x real time   (goal >= 100x)");
        }
    }
    Ok(())
}
