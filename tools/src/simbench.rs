//! `sim bench`: what one physics step and one servo step cost, and how fast the simulator runs a
//! scenario, in one run. Each cost is the median of several timed batches (these machines are
//! shared and noisy); the speed is simulated seconds per wall-clock second over whole runs.
//!
//! Timewarp's rollback cost, for 2 users (the scenario) and 8 (the scenario's world and object with
//! eight users around it, [`eight_users`]) and the crowd: one 500-tick rollback with every tool
//! touching, after one user's late report (the rollback a late report causes: it re-simulates the
//! objects that user's tool reaches, and beside it the same with every object stepped), timed
//! whole (median and p99) and per re-simulated tick; then, from a timewarp run at a constant 150 and
//! 500 ms delay, the busiest site's re-simulated ticks per simulated second × that cost = the share
//! of one core rollbacks take, and the p99 rollback (depth × cost per tick) against the 1 ms physics
//! period.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::ContactForce;
use coop_model::method::track::{quantize, ToolReport, QUANTUM_M, WINDOW_TICKS};
use coop_model::method::{Consistency, Report, WorldCopy};
use coop_model::metrics;
use coop_model::scenario::{KeyframeSpec, MethodName, Scenario};
use coop_model::servo::{Servo, ServoInput};
use coop_model::sim::{self, Mode};

use coop_actors::scenario_file;

mod world;

pub use world::{world_step_figures, WorldStepCost};

fn median(v: Vec<f64>) -> f64 {
    quantile(v, 0.5)
}

/// The `q` quantile (nearest rank) of `v`, which is not empty.
pub(crate) fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

/// The depth of the timed rollback, ticks.
pub const ROLLBACK_TICKS: i64 = 500;

/// `base`'s world, object and contact laws with eight users around the object: device bases on a
/// 0.3 m circle about it, alternating `base`'s first two sites' rates; each user comes in from its
/// side (one after the other, 0.1 s apart), presses 3 mm into the object, all carry it 3 cm in +y
/// together and let go. No task phases.
pub fn eight_users(base: &Scenario) -> Scenario {
    let mut sc = base.clone();
    sc.name = format!("{}-eight-users", base.name);
    sc.duration_s = 6.0;
    sc.phase.clear();
    let c = Vec3::from(base.objects[0].start_m);
    let templates = [&base.site[0], &base.site[base.site.len().min(2) - 1]];
    sc.site = (0..8)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 8.0;
            let u = Vec3::new(a.cos(), a.sin(), 0.0);
            let mut s = templates[k % 2].clone();
            s.name = format!("user{}", k + 1);
            let at = |p: Vec3| [p.x, p.y, p.z];
            s.device_base_m = at(Vec3::new(c.x, c.y, 0.0) + u * 0.3);
            s.elbow = if k % 2 == 0 { 1.0 } else { -1.0 };
            let away = c + u * 0.15;
            let press = c + u * (base.objects[0].radius_m + s.tool_radius_m - 0.003);
            let carried = |p: Vec3| p + Vec3::new(0.0, 0.03, 0.0);
            let key = |t_s: f64, p: Vec3| KeyframeSpec {
                t_s,
                target_m: at(p),
            };
            let arrive = 1.0 + 0.1 * k as f64;
            s.script = vec![
                key(0.0, away),
                key(0.5, away),
                key(arrive, press),
                key(3.0, press),
                key(4.0, carried(press)),
                key(5.0, carried(press)),
                key(5.5, carried(away)),
            ];
            s
        })
        .collect();
    sc
}

/// What one 500-tick rollback with `sc`'s every tool touching an object costs at site 0, after
/// site 1's late report: each rollback's time, ns (one per batch).
fn rollback_times_ns(sc: &Scenario, batches: usize) -> anyhow::Result<Vec<f64>> {
    let world = sc.world();
    let starts = sc.start_states();
    let n = sc.site.len();
    // Every tool 1 mm into an object from its own side: the one object, or in a world of
    // several every other one (tool j's is object 2j, modulo their number).
    let touching = |j: usize| {
        let k = (2 * j) % starts.len();
        let a = std::f64::consts::TAU * j as f64 / n as f64;
        let u = -Vec3::new(a.cos(), a.sin(), 0.0);
        let reach = sc.objects[k].radius_m + sc.site[j].tool_radius_m - 0.001;
        quantize(starts[k].pos + u * reach)
    };
    let report = |first_tick: i64, count: usize, q: [i32; 3]| {
        Report::Tools(ToolReport {
            first_tick,
            count,
            positions: [q; WINDOW_TICKS],
            ..ToolReport::NONE
        })
    };
    let mut copy = sc.start_copy();
    let none = vec![ContactForce::default(); copy.len()];
    let mut tw = sc.timewarp(0, &copy);
    let dt = 1.0 / sc.site[0].physics_rate_hz;
    // Every other tool known at tick 0 only: predicted (held) there for the whole history.
    for j in 1..n {
        tw.receive(&world, &mut copy, j, &report(0, 1, touching(j)), 0.0);
    }
    let now = ROLLBACK_TICKS + 100;
    for k in 0..now {
        let q = touching(0);
        tw.own_tool(Vec3::new(f64::from(q[0]), f64::from(q[1]), f64::from(q[2])) * QUANTUM_M);
        tw.physics_step(&world, &mut copy, &none, dt);
        copy.set_time(k as f64 * dt);
    }
    let before = tw.stats().rollback().copied().unwrap_or_default();
    // Site 1's tool was 0.01 mm further in from tick now − 500 on: re-simulate 500 ticks.
    let mut moved = touching(1);
    moved[0] -= 1;
    let late = report(now - ROLLBACK_TICKS, WINDOW_TICKS, moved);
    let mut times = Vec::with_capacity(batches);
    for _ in 0..batches {
        let (mut t, mut c) = (tw.clone(), copy.clone());
        let t0 = Instant::now();
        t.receive(&world, &mut c, 1, black_box(&late), now as f64 * dt);
        let ns = t0.elapsed().as_nanos() as f64;
        let after = t.stats().rollback().copied().unwrap_or_default();
        let depth = after.resimulated_ticks - before.resimulated_ticks;
        if depth != ROLLBACK_TICKS as u64 {
            anyhow::bail!(
                "the timed rollback re-simulated {depth} ticks, not {ROLLBACK_TICKS}: the horizon of scenario {} is too short",
                sc.name
            );
        }
        black_box(&c);
        times.push(ns);
    }
    Ok(times)
}

/// Rollback cost at one site count.
#[derive(Debug, Clone, serde::Serialize)]
struct RollbackCost {
    scenario: String,
    users: usize,
    objects: usize,
    rollback_500_ticks_median_ns: f64,
    rollback_500_ticks_p99_ns: f64,
    per_resimulated_tick_ns: f64,
    /// The same rollback stepping every object (`timewarp.islands = false`): what re-simulating
    /// only the objects the late tool reaches buys.
    per_resimulated_tick_whole_ns: f64,
}

/// Rollback load of a timewarp run at one delay.
#[derive(Debug, Clone, serde::Serialize)]
struct RollbackLoad {
    scenario: String,
    users: usize,
    objects: usize,
    delay_ms: f64,
    rollbacks_per_s: f64,
    resimulated_ticks_per_s: f64,
    rollback_depth_p99_ticks: u64,
    /// Re-simulation time per second of real time, busiest site, as a share of one core.
    core_share: f64,
    /// The p99 rollback's time (depth × cost per tick) plus one tick, ns.
    p99_rollback_ns: f64,
    fits_1ms_at_p99: bool,
    hash_mismatches: u64,
}

/// The rollback figures of `sc`, of `sc` with eight users, and of `more` (a world of several
/// objects: the crowd).
fn rollback_figures(
    sc: &Scenario,
    more: Option<&Scenario>,
    quick: bool,
) -> anyhow::Result<(Vec<RollbackCost>, Vec<RollbackLoad>)> {
    let batches = if quick { 5 } else { 41 };
    let eight = eight_users(sc);
    let mut costs = Vec::new();
    let mut loads = Vec::new();
    for many in [sc, &eight].into_iter().chain(more) {
        // The 500 ms scenario's horizon holds a 500-tick rollback.
        let deep = crate::sweep::scenario_at(many, 500.0, many.seed)?;
        let times = rollback_times_ns(&deep, batches)?;
        let per_tick = median(times.clone()) / ROLLBACK_TICKS as f64;
        let mut whole = deep.clone();
        whole.timewarp.islands = false;
        let per_tick_whole = median(rollback_times_ns(&whole, batches)?) / ROLLBACK_TICKS as f64;
        costs.push(RollbackCost {
            scenario: many.name.clone(),
            users: many.site.len(),
            objects: many.objects.len(),
            rollback_500_ticks_median_ns: median(times.clone()),
            rollback_500_ticks_p99_ns: quantile(times, 0.99),
            per_resimulated_tick_ns: per_tick,
            per_resimulated_tick_whole_ns: per_tick_whole,
        });
        for delay_ms in [150.0, 500.0] {
            let mut at = crate::sweep::scenario_at(many, delay_ms, many.seed)?;
            if quick {
                at.duration_s = at.duration_s.min(3.0);
            }
            let r = sim::run(&at, Mode::Distributed(MethodName::Timewarp), &mut |_| {});
            let reference = sim::run(&at, Mode::Reference, &mut |_| {});
            let m = metrics::compute(&at, &r, &reference);
            let p99_ns = (m.rollback_depth_p99_ticks as f64 + 1.0) * per_tick;
            loads.push(RollbackLoad {
                scenario: many.name.clone(),
                users: many.site.len(),
                objects: many.objects.len(),
                delay_ms,
                rollbacks_per_s: m.rollbacks_per_s,
                resimulated_ticks_per_s: m.resimulated_ticks_per_s,
                rollback_depth_p99_ticks: m.rollback_depth_p99_ticks,
                core_share: m.resimulated_ticks_per_s * per_tick * 1e-9,
                p99_rollback_ns: p99_ns,
                fits_1ms_at_p99: p99_ns <= 1e6,
                hash_mismatches: m.hash_mismatches,
            });
        }
    }
    Ok((costs, loads))
}

/// Runs the benchmark and prints its figures.
///
/// # Errors
/// The scenario cannot be loaded.
pub fn run(scenario: &Path, json: bool, quick: bool) -> anyhow::Result<()> {
    let sc = scenario_file::load(scenario)?;
    if sc.objects.len() > 1 {
        // Its step figures push one object and run naive and paper, which keep one.
        anyhow::bail!(
            "scenario {}: sim bench times a one-object scenario (and the crowd, crowd.toml beside it, as the world of several); this one has {} objects",
            scenario.display(),
            sc.objects.len()
        );
    }
    let (batches, per_batch) = if quick { (5, 2_000) } else { (21, 50_000) };
    let physics_ns = physics_step_ns(&sc, batches, per_batch);
    let servo_ns = servo_step_ns(&sc, batches, per_batch);
    let speeds = speeds(&sc, quick);
    // The crowd (eight users, sixteen objects) beside the scenario, if it is there.
    let crowd = match scenario.parent().map(|d| d.join("crowd.toml")) {
        Some(p) if p.exists() => Some(scenario_file::load(&p)?),
        _ => None,
    };
    let (costs, loads) = rollback_figures(&sc, crowd.as_ref(), quick)?;
    let figures = Figures {
        physics_ns,
        servo_ns,
        speeds,
        costs,
        loads,
        worlds: world_step_figures(&sc, quick),
    };
    if json {
        figures.print_json(&sc)
    } else {
        figures.print(&sc, quick, batches, per_batch);
        Ok(())
    }
}

/// The object resting on the table at the scenario's start.
fn resting(sc: &Scenario) -> BodyState {
    BodyState::at_rest(Vec3::from(sc.objects[0].start_m))
}

/// Physics: one object resting on the table with the own user pushing it (contact + environment),
/// median ns per step.
fn physics_step_ns(sc: &Scenario, batches: usize, per_batch: usize) -> f64 {
    let world = sc.world();
    let start = resting(sc);
    let mut method = sc.method(0, MethodName::Paper);
    let push = ContactForce {
        force: Vec3::new(0.3, 0.05, 0.0),
        point: start.pos - Vec3::new(sc.objects[0].radius_m, 0.0, 0.0),
        depth: 5e-4,
        touching: true,
        ..ContactForce::default()
    };
    let dt = 1e-3;
    median(
        (0..batches)
            .map(|_| {
                let mut copy = WorldCopy::one(start);
                let t0 = Instant::now();
                for _ in 0..per_batch {
                    method.physics_step(&world, &mut copy, black_box(&[push]), dt);
                }
                black_box(&copy);
                t0.elapsed().as_nanos() as f64 / per_batch as f64
            })
            .collect(),
    )
}

/// Servo: kinematics, contact, Eq. 12 controller on site 0's device, tool touching the object;
/// median ns per step.
fn servo_step_ns(sc: &Scenario, batches: usize, per_batch: usize) -> f64 {
    let world = sc.world();
    let start = resting(sc);
    let dt = 1e-3;
    let arm = sc.arm(0);
    let mut servo = Servo::new(sc.servo_params(0));
    let mut force_loop = sc.force_loop(0);
    let q = arm
        .inverse(
            start.pos - Vec3::new(sc.objects[0].radius_m + 0.004, 0.0, 0.0),
            sc.site[0].elbow,
        )
        .unwrap_or_else(|| {
            arm.inverse(Vec3::from(sc.site[0].script[0].target_m), sc.site[0].elbow)
                .unwrap_or_default()
        });
    median(
        (0..batches)
            .map(|_| {
                let t0 = Instant::now();
                for k in 0..per_batch {
                    let q = black_box(q);
                    let out = servo.step(
                        &ServoInput {
                            now_s: k as f64 * dt,
                            dt_s: dt,
                            tool_pos: arm.forward(&q),
                            tool_vel: arm.jacobian(&q) * Vec3::zeros(),
                            objects: std::slice::from_ref(&start),
                            object_time_s: k as f64 * dt,
                            adopted: false,
                            stopping: false,
                        },
                        world.bodies(),
                    );
                    let f_m = Vec3::new(0.1, 0.0, 0.0);
                    black_box(force_loop.step(out.f_desired, out.scale, f_m, &q, dt));
                    black_box(out);
                }
                t0.elapsed().as_nanos() as f64 / per_batch as f64
            })
            .collect(),
    )
}

/// Whole-run speed per mode: simulated seconds per wall-clock second, median of whole runs.
fn speeds(sc: &Scenario, quick: bool) -> Vec<(&'static str, f64)> {
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
                    black_box(sim::run(sc, mode, &mut |_| {}));
                    sc.duration_s / t0.elapsed().as_secs_f64()
                })
                .collect(),
        );
        speeds.push((mode.name(), s));
    }
    speeds
}

/// Everything `sim bench` measured.
struct Figures {
    physics_ns: f64,
    servo_ns: f64,
    /// Per mode's name, simulated seconds per wall-clock second.
    speeds: Vec<(&'static str, f64)>,
    costs: Vec<RollbackCost>,
    loads: Vec<RollbackLoad>,
    worlds: Vec<WorldStepCost>,
}

impl Figures {
    /// As JSON, with the goals they are held to.
    fn print_json(&self, sc: &Scenario) -> anyhow::Result<()> {
        let v = serde_json::json!({
            "scenario": sc.name,
            "physics_step_ns": self.physics_ns,
            "servo_step_ns": self.servo_ns,
            "realtime_factor": self.speeds.iter().map(|(n, s)| (n.to_string(), serde_json::json!(s))).collect::<serde_json::Map<_, _>>(),
            "rollback_cost": self.costs,
            "rollback_load": self.loads,
            "world_step": self.worlds,
            "goal": "physics step < 1000 ns; paper scenario >= 100x real time; 8 users at 150 ms (and 8 users with 16 objects, the crowd): p99 rollback inside the 1 ms physics period",
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        Ok(())
    }

    /// For people, each figure beside its goal.
    fn print(&self, sc: &Scenario, quick: bool, batches: usize, per_batch: usize) {
        let (physics_ns, servo_ns) = (self.physics_ns, self.servo_ns);
        println!("# sim bench: median of {batches} batches of {per_batch} steps; speed over whole {} s runs of scenario {}", sc.duration_s, sc.name);
        println!("physics step (own contact + environment, Verlet): {physics_ns:>8.0} ns   (goal < 1000 ns)");
        println!("servo step (FK, contact, Eq. 12 PI):              {servo_ns:>8.0} ns");
        for (name, s) in &self.speeds {
            println!("simulator speed, {name:<9}: {s:>8.0}x real time   (goal >= 100x)");
        }
        println!(
            "# timewarp rollback, every tool touching (site 0; median / p99 of {} rollbacks)",
            if quick { 5 } else { 41 }
        );
        for c in &self.costs {
            println!(
                "{:<20} {} users, {:>2} objects: one {ROLLBACK_TICKS}-tick rollback {:>9.0} / {:>9.0} ns, {:>6.0} ns per re-simulated tick (every object stepped: {:>6.0} ns)",
                c.scenario, c.users, c.objects, c.rollback_500_ticks_median_ns, c.rollback_500_ticks_p99_ns, c.per_resimulated_tick_ns, c.per_resimulated_tick_whole_ns
            );
        }
        println!("# a world of several objects (cubes set down in a heap, tools pressing some): one physics step, every tool's contact with every object, then the objects stepped together (median); resting untouched objects sleep, and with nothing asleep");
        for w in &self.worlds {
            println!(
                "{:>2} objects, {} tools: {:>8.0} ns per step, {:>5.1} % of the 1 ms period; nothing asleep {:>8.0} ns; its contacts {:>8.0} ns (ours: points, laws, friction) vs {:>8.0} ns (parry3d-f64 geometry alone, {:.2}x ours)",
                w.objects,
                w.tools,
                w.step_ns,
                w.period_share * 100.0,
                w.step_awake_ns,
                w.contacts_ns,
                w.parry_contacts_ns,
                w.parry_contacts_ns / w.contacts_ns
            );
        }
        println!("# timewarp run at a constant delay (busiest site): re-simulation as a share of one core; p99 rollback = (p99 depth + 1) ticks x cost per tick (goal: 8 users at 150 ms <= 1 ms)");
        for l in &self.loads {
            println!(
                "{:<20} {} users, {:>2} objects, {:>3.0} ms: {:>6.1} rollbacks/s, {:>8.0} re-simulated ticks/s, depth p99 {:>4} ticks, {:>5.1} % of a core, p99 rollback {:>7.0} ns {}, {} hash mismatches",
                l.scenario,
                l.users,
                l.objects,
                l.delay_ms,
                l.rollbacks_per_s,
                l.resimulated_ticks_per_s,
                l.rollback_depth_p99_ticks,
                l.core_share * 100.0,
                l.p99_rollback_ns,
                if l.fits_1ms_at_p99 { "(fits 1 ms)" } else { "(over 1 ms)" },
                l.hash_mismatches
            );
        }
    }
}
