//! `fuzz`: hostile input at volume, on stable Rust (cargo-fuzz needs a nightly toolchain, which
//! these machines cannot fetch). Each target mutates valid inputs with a seeded generator (so a
//! failure is replayed with its seed), runs every input under `catch_unwind` with a watchdog, and
//! judges what was *accepted* with an oracle of its own:
//!
//! - `wire`: the wire decoder and the receive checks ([`coop_transport::admit::Inbound::check`]),
//!   and [`coop_transport::admit::Inbound::check_track`], fed mutated station states and tool
//!   tracks (words set to NaN, ±inf, 1e300, u64::MAX or 0 before encoding; bytes flipped,
//!   inserted, removed, truncated, appended, a wrong version; wrong key, skewed or unknown
//!   clocks). Every accepted state must be finite, inside the world and the time window, and must
//!   keep a `paper` copy finite and inside the world when it is adopted and integrated; every
//!   accepted track must hold at most a window of positions inside the world; and what was
//!   accepted must be the one encoding of what was taken.
//! - `scenario`: the scenario parser and validation, fed mutated `scenarios/paper.toml` text
//!   (values replaced by hostile numbers, lines dropped or doubled, bytes flipped). Every accepted
//!   scenario must build its world, and a sample of them is simulated briefly: the object must stay
//!   finite and inside the world.
//! - `config`: the station configuration parser and validation, fed mutated station files.
//!
//! It prints inputs, time, panics and what was accepted; it fails (exit 1) on any panic, hang or
//! implausible acceptance.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::{Duration, Instant};

use anyhow::bail;
use clap::{Parser, ValueEnum};
use coop_model::contact::ContactForce;
use coop_model::method::track::{ToolReport, QUANTUM_M, WINDOW_TICKS};
use coop_model::method::Report;
use coop_model::rng::Rng;
use coop_model::scenario::{MethodName, Scenario};
use coop_model::sim::{self, Mode};
use coop_model::MAX_SITES;
use coop_rt::msg::{SiteReport, ToolTrack};
use coop_rt::sync::{AtomicU64, Ordering};
use coop_transport::admit::{Bounds, Inbound};
use coop_transport::wire;

/// Command line of `fuzz`.
#[derive(Debug, Parser)]
#[command(
    name = "fuzz",
    version,
    about = "Hostile input at volume: mutated wire messages, scenarios and station configs, each judged by an oracle. Exit 1 on any panic, hang or implausible acceptance."
)]
pub struct Args {
    /// What to fuzz.
    #[arg(value_enum)]
    pub target: Target,
    /// Inputs to try.
    #[arg(long, default_value_t = 1_000_000)]
    pub inputs: u64,
    /// Seed of the generator (the same seed gives the same inputs).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Longest any one input may take before it counts as a hang, ms.
    #[arg(long, default_value_t = 2000)]
    pub hang_ms: u64,
}

/// A fuzz target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Target {
    /// The wire decoder and the receive checks.
    Wire,
    /// The scenario parser and validation.
    Scenario,
    /// The station configuration parser and validation.
    Config,
    /// The ROS 2 decoders (what a `ros2` device takes from its driver, and the other messages).
    Ros2,
}

/// What a run found.
#[derive(Debug, Default)]
pub struct Outcome {
    /// Inputs tried.
    pub inputs: u64,
    /// Inputs accepted.
    pub accepted: u64,
    /// Inputs that panicked.
    pub panics: u64,
    /// Accepted inputs the oracle found implausible, with the first one's description.
    pub implausible: u64,
    /// The first implausible acceptance.
    pub first_implausible: Option<String>,
    /// Accepted inputs the oracle checked more deeply (adopted, or simulated).
    pub deep: u64,
}

/// Runs the target and prints its figures.
///
/// # Errors
/// A panic, a hang or an implausible acceptance.
pub fn main(a: &Args) -> anyhow::Result<()> {
    // Panics are counted, not printed one by one.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let progress = AtomicU64::new(0);
    let done = AtomicU64::new(0);
    let started = Instant::now();
    let out = std::thread::scope(|s| {
        // The watchdog: an input that takes longer than `hang_ms` is a hang.
        let watchdog = s.spawn(|| {
            let mut last = (0, Instant::now());
            while done.load(Ordering::Relaxed) == 0 {
                std::thread::sleep(Duration::from_millis(50));
                let n = progress.load(Ordering::Relaxed);
                if n != last.0 {
                    last = (n, Instant::now());
                } else if last.1.elapsed() > Duration::from_millis(a.hang_ms) {
                    return Some(n);
                }
            }
            None
        });
        let out = match a.target {
            Target::Wire => wire_target(a, &progress),
            Target::Scenario => scenario_target(a, &progress),
            Target::Config => config_target(a, &progress),
            Target::Ros2 => ros2_target(a, &progress),
        };
        done.store(1, Ordering::Relaxed);
        (out, watchdog.join().ok().flatten())
    });
    std::panic::set_hook(default_hook);
    let (out, hang) = out;
    let secs = started.elapsed().as_secs_f64();
    println!(
        "fuzz {:?}: {} inputs in {:.1} s ({:.0}/s), seed {}: {} accepted ({} checked deeply), {} panics, {} implausible accepted",
        a.target,
        out.inputs,
        secs,
        out.inputs as f64 / secs.max(1e-9),
        a.seed,
        out.accepted,
        out.deep,
        out.panics,
        out.implausible
    );
    if let Some(n) = hang {
        bail!("input {n} ran longer than {} ms (a hang)", a.hang_ms);
    }
    if out.panics > 0 {
        bail!(
            "{} inputs panicked (replay with --seed {})",
            out.panics,
            a.seed
        );
    }
    if let Some(first) = out.first_implausible {
        bail!(
            "{} implausible inputs accepted; the first: {first}",
            out.implausible
        );
    }
    Ok(())
}

/// Runs `f` on every input index, counting panics.
fn each(a: &Args, progress: &AtomicU64, out: &mut Outcome, mut f: impl FnMut(u64, &mut Outcome)) {
    for i in 0..a.inputs {
        if catch_unwind(AssertUnwindSafe(|| f(i, out))).is_err() {
            out.panics += 1;
        }
        out.inputs += 1;
        progress.store(i + 1, Ordering::Relaxed);
    }
}

fn implausible(out: &mut Outcome, what: impl FnOnce() -> String) {
    out.implausible += 1;
    if out.first_implausible.is_none() {
        out.first_implausible = Some(what());
    }
}

fn paper() -> Scenario {
    coop_actors::scenario_file::parse(coop_actors::station::config::DEFAULT_SCENARIO)
        .unwrap_or_default()
}

const SPECIALS: [f64; 12] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    0.0,
    -0.0,
    1e300,
    -1e300,
    1e-300,
    1e6,
    -1.0,
    f64::MAX,
    f64::MIN_POSITIVE,
];

/// A world of two objects (two pucks on a table): the wire target's.
fn world_of_two() -> Scenario {
    coop_actors::scenario_file::parse(include_str!("../../scenarios/billiards.toml"))
        .unwrap_or_default()
}

/// A genuine-looking state of site 1 about `object` at its clock time `t_ns`.
fn genuine(rng: &mut Rng, seq: u64, t_ns: u64, force: bool, object: u64) -> SiteReport {
    let mut r = SiteReport {
        kind: if force { 2 } else { 1 },
        t_ns,
        seq,
        site: 1,
        object,
        ..SiteReport::default()
    };
    if force {
        r.force = [rng.range(-5.0, 5.0), rng.range(-5.0, 5.0), 0.0];
        r.point = [rng.range(-0.2, 0.2), rng.range(-0.2, 0.2), 0.01];
        r.depth = rng.range(0.0, 0.005);
        r.touching = 1;
    } else {
        let (a, b) = (rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let n = (1.0 + a * a + b * b).sqrt();
        r.rot = [1.0 / n, a / n, b / n, 0.0];
        r.pos = [rng.range(-0.25, 0.25), rng.range(-0.2, 0.2), 0.01];
        r.vel = [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 0.0];
        r.ang_mom = [0.0, 0.0, rng.range(-1e-4, 1e-4)];
        r.accel = [0.0, 0.0, -3.27 * rng.uniform()];
        r.included = [-1.0; MAX_SITES];
        r.included[1] = t_ns as f64 * 1e-9 - rng.uniform();
    }
    r
}

/// One to three hostile values in a message's words, before it is encoded (what a hostile
/// sender who speaks the encoding sends).
fn mutate_words(rng: &mut Rng, words: &mut [u64]) {
    for _ in 0..1 + rng.next_u64() % 3 {
        let w = (rng.next_u64() as usize) % words.len();
        words[w] = match rng.next_u64() % 5 {
            0 | 1 => SPECIALS[(rng.next_u64() as usize) % SPECIALS.len()].to_bits(),
            // Anything (u64::MAX among them).
            2 if rng.uniform() < 0.3 => u64::MAX,
            2 => rng.next_u64(),
            // A finite but absurd float.
            3 => (rng.range(-1.0, 1.0) * 10f64.powf(rng.range(0.0, 12.0))).to_bits(),
            _ => 0,
        };
    }
}

/// One to three hostile edits of an encoded message's bytes.
fn mutate_bytes(rng: &mut Rng, bytes: &mut Vec<u8>) {
    for _ in 0..1 + rng.next_u64() % 3 {
        let at = |rng: &mut Rng, n: usize| (rng.next_u64() as usize) % n.max(1);
        match rng.next_u64() % 7 {
            0 | 1 if !bytes.is_empty() => {
                let i = at(rng, bytes.len());
                bytes[i] ^= 1 << (rng.next_u64() % 8);
            }
            2 => bytes.truncate(at(rng, bytes.len() + 1)),
            3 => bytes.extend((0..1 + rng.next_u64() % 16).map(|_| rng.next_u64() as u8)),
            4 if !bytes.is_empty() => bytes[0] = rng.next_u64() as u8,
            // A byte inserted or removed: every later field shifts.
            5 => {
                let i = at(rng, bytes.len() + 1);
                bytes.insert(i, rng.next_u64() as u8);
            }
            6 if !bytes.is_empty() => {
                let i = at(rng, bytes.len());
                bytes.remove(i);
            }
            _ => {}
        }
    }
}

/// A genuine tool track of site 1: up to a window of a tool wandering over the table at up to
/// 1 m/s (or held most ticks, as through a deadband), up to the physics tick of `t_ns` (1 kHz),
/// now and then asking for a gap or carrying no positions.
fn genuine_track(rng: &mut Rng, seq: u64, t_ns: u64) -> ToolTrack {
    let end = (t_ns / 1_000_000) as i64;
    let count = match rng.next_u64() % 8 {
        0 => 0,
        1 => WINDOW_TICKS,
        _ => 1 + (rng.next_u64() as usize) % 40,
    };
    let mut r = ToolReport {
        first_tick: end - count as i64,
        count,
        confirmed_tick: end - count as i64 - (rng.next_u64() % 100) as i64,
        confirmed_hash: rng.next_u64(),
        ..ToolReport::NONE
    };
    if rng.uniform() < 0.2 {
        r.need[0] = r.first_tick - 300;
    }
    let mut p = [
        rng.range(-20_000.0, 20_000.0) as i32,
        rng.range(-20_000.0, 20_000.0) as i32,
        1000,
    ];
    // Now and then a deadband's held positions (runs of one position).
    let hold = if rng.uniform() < 0.5 { 0.0 } else { 0.9 };
    for q in &mut r.positions[..count] {
        if rng.uniform() >= hold {
            p[0] += rng.range(-100.0, 100.0) as i32;
            p[1] += rng.range(-100.0, 100.0) as i32;
        }
        *q = p;
    }
    ToolTrack::new(1, seq, t_ns, &r)
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The oracle for an accepted state, received on a key naming `key_object`: is it what a world
/// of `b` allows at `now_ns`?
fn wire_oracle(b: &Bounds, r: &SiteReport, key_object: u64, now_ns: u64) -> Result<(), String> {
    let words_finite = r.to_words().iter().enumerate().all(|(i, &w)| {
        // Every f64 field finite (the layout's u64 fields are kind, t_ns, seq, site, object,
        // touching).
        let is_u64 = matches!(i, 0..=4) || i == SiteReport::WORDS - 4;
        is_u64 || f64::from_bits(w).is_finite()
    });
    if r.object != key_object || r.object >= b.object_count as u64 {
        return Err(format!(
            "object {} on a key of object {key_object}, in a world of {}: {r:?}",
            r.object, b.object_count
        ));
    }
    if !words_finite {
        return Err(format!("a non-finite field: {r:?}"));
    }
    if r.t_ns + b.max_age_ns < now_ns || r.t_ns > now_ns + b.future_ns {
        return Err(format!(
            "time {} outside the window at {now_ns}: {r:?}",
            r.t_ns
        ));
    }
    let state = r.kind == 1;
    if state
        && (norm(r.pos) > b.extent_m || norm(r.vel) > b.objects[r.object as usize].speed_m_per_s)
    {
        return Err(format!("outside the world or too fast: {r:?}"));
    }
    if !state && norm(r.force) > b.force_n {
        return Err(format!("a force beyond every device's: {r:?}"));
    }
    Ok(())
}

/// The oracle for an accepted track: at most a window of positions, each inside the world
/// (a tool beyond it is refused), and the bytes the one encoding of what was taken.
fn track_oracle(b: &Bounds, t: &ToolTrack, bytes: &[u8]) -> Result<(), String> {
    let Some((_, Report::Tools(r))) = t.report() else {
        return Err(format!("accepted but not a track: {t:?}"));
    };
    if r.count > WINDOW_TICKS {
        return Err(format!("{} positions", r.count));
    }
    let reach = b.extent_m / QUANTUM_M;
    if let Some(p) = r.positions[..r.count]
        .iter()
        .find(|p| p.iter().any(|&c| f64::from(c).abs() > reach))
    {
        return Err(format!("a position outside the world: {p:?}"));
    }
    // (The admitted track's time is the receiver's clock's: the decoded one is the sender's.)
    let decoded = wire::decode_track(bytes);
    if decoded.map(|d| wire::encode_track(&d)).as_deref() != Ok(bytes) {
        return Err(format!(
            "accepted {bytes:?}, which is not the encoding of {decoded:?}"
        ));
    }
    Ok(())
}

fn wire_target(a: &Args, progress: &AtomicU64) -> Outcome {
    let sc = world_of_two();
    let bounds = Bounds::from_scenario(&sc, None);
    let world = sc.world();
    let sites = vec!["user1".to_owned(), "user2".to_owned()];
    let mut rng = Rng::new(a.seed);
    let mut inbound = Inbound::new(sites.clone(), bounds);
    let mut method = sc.method(0, MethodName::Paper);
    let mut copy = sc.start_copy();
    let none = [ContactForce::default(); 2];
    let mut now: u64 = 1_000_000_000_000;
    let mut seq = 0u64;
    let mut out = Outcome::default();
    each(a, progress, &mut out, |i, out| {
        now += 1 + rng.next_u64() % 20_000_000;
        // Their clock: the same, 1000 s ahead or behind, or not known yet.
        let skew: i64 = match rng.next_u64() % 4 {
            0 => 1_000_000_000_000,
            1 => -1_000_000_000_000,
            _ => 0,
        };
        let known = rng.uniform() > 0.05;
        let offsets = [Some(0), known.then_some(skew)];
        seq += 1;
        let t_theirs = now.saturating_add_signed(skew) - rng.next_u64() % 50_000_000;
        let force = rng.uniform() < 0.2;
        // Either object of the world; now and then one it does not have.
        let object = match rng.next_u64() % 16 {
            0 => 2,
            1 => rng.next_u64() % 64,
            k => k % 2,
        };
        let key = match rng.next_u64() % 16 {
            0 => "user1",
            1 => "zz",
            _ => "user2",
        };
        // A third of the inputs are tool tracks.
        if rng.uniform() < 0.3 {
            let t = genuine_track(&mut rng, seq, t_theirs);
            let mut words = t.to_words();
            if rng.uniform() < 0.5 {
                mutate_words(&mut rng, &mut words);
            }
            let mut bytes = wire::encode_track(&ToolTrack::from_words(&words));
            if rng.uniform() < 0.5 {
                mutate_bytes(&mut rng, &mut bytes);
            }
            let Ok(admitted) = inbound.check_track(key, &bytes, now, &offsets) else {
                return;
            };
            out.accepted += 1;
            if let Err(why) = track_oracle(&bounds, &admitted.track, &bytes) {
                implausible(out, || format!("input {i}: {why}"));
            }
            return;
        }
        let r = genuine(&mut rng, seq, t_theirs, force, object);
        let mut words = r.to_words();
        if rng.uniform() < 0.5 {
            mutate_words(&mut rng, &mut words);
        }
        let mut bytes = wire::encode(&SiteReport::from_words(&words));
        if rng.uniform() < 0.8 {
            mutate_bytes(&mut rng, &mut bytes);
        }
        // The key names the message's object, or now and then another.
        let key_object = if rng.uniform() < 0.9 {
            object
        } else {
            rng.next_u64() % 3
        };
        let Ok(admitted) = inbound.check(key, key_object, &bytes, now, &offsets) else {
            return;
        };
        out.accepted += 1;
        let rep = admitted.report;
        if let Err(why) = wire_oracle(&bounds, &rep, key_object, now) {
            return implausible(out, || format!("input {i}: {why}"));
        }
        // One encoding per message: what was accepted is what it decodes to encoded again
        // (the admitted report's time is the receiver's clock's).
        let decoded = wire::decode(&bytes);
        if decoded.map(|d| wire::encode(&d)).as_deref() != Ok(&bytes[..]) {
            return implausible(out, || {
                format!("input {i}: accepted {bytes:?}, which is not the encoding of {decoded:?}")
            });
        }
        // Adopted and integrated by a paper copy, it must leave the copy finite and in the world.
        let Some((from, msg)) = rep.report() else {
            return implausible(out, || {
                format!("input {i}: accepted but not a report: {rep:?}")
            });
        };
        if !matches!(msg, Report::State { .. }) {
            return;
        }
        out.deep += 1;
        let now_s = now as f64 * 1e-9;
        copy.set_time(now_s);
        let before = copy.clone();
        method.receive(&world, &mut copy, from, &msg, now_s);
        method.physics_step(&world, &mut copy, &none, 1e-3);
        if let Some(after) = copy
            .objects()
            .iter()
            .map(|o| o.state)
            .find(|s| !s.is_finite() || s.pos.norm() > bounds.extent_m * 2.0)
        {
            copy = before;
            implausible(out, || {
                format!("input {i}: adopting {rep:?} left the copy at {after:?}")
            });
        }
    });
    out
}

/// Replaces numbers, drops or doubles lines, flips bytes of `text`.
fn mutate_text(rng: &mut Rng, text: &str) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    for _ in 0..1 + rng.next_u64() % 3 {
        let n = lines.len().max(1);
        let i = (rng.next_u64() as usize) % n;
        match rng.next_u64() % 6 {
            0..=2 => {
                // A value replaced by a hostile number.
                let Some(line) = lines.get_mut(i) else {
                    continue;
                };
                let Some(eq) = line.find('=') else { continue };
                let values = [
                    "nan",
                    "inf",
                    "-inf",
                    "0",
                    "-0.0",
                    "1e300",
                    "-1e300",
                    "1e-300",
                    "1e6",
                    "-1",
                    "1e-9",
                    "\"\"",
                    "\"..\"",
                    "[]",
                    "true",
                    "18446744073709551615",
                ];
                let v = values[(rng.next_u64() as usize) % values.len()];
                let tail = line[eq + 1..]
                    .find([',', '}'])
                    .map_or(String::new(), |k| line[eq + 1 + k..].to_owned());
                let tail = if line.trim_start().starts_with('{') || line.contains("= [") {
                    tail
                } else {
                    String::new()
                };
                *line = format!("{}= {v}{tail}", &line[..eq]);
            }
            3 if !lines.is_empty() => {
                lines.remove(i);
            }
            4 if !lines.is_empty() => {
                let l = lines[i].clone();
                lines.insert(i, l);
            }
            _ => {
                let Some(line) = lines.get_mut(i) else {
                    continue;
                };
                let mut b = std::mem::take(line).into_bytes();
                if !b.is_empty() {
                    let k = (rng.next_u64() as usize) % b.len();
                    b[k] = b[k].wrapping_add(1 + (rng.next_u64() % 255) as u8);
                }
                *line = String::from_utf8_lossy(&b).into_owned();
            }
        }
    }
    lines.join("\n")
}

fn scenario_target(a: &Args, progress: &AtomicU64) -> Outcome {
    let text = coop_actors::station::config::DEFAULT_SCENARIO;
    let mut rng = Rng::new(a.seed);
    let mut out = Outcome::default();
    each(a, progress, &mut out, |i, out| {
        let t = mutate_text(&mut rng, text);
        let Ok(sc) = coop_actors::scenario_file::parse(&t) else {
            return;
        };
        out.accepted += 1;
        let w = sc.world();
        let massive = |b: &coop_model::world::Body| {
            b.mass.mass_kg > 0.0 && b.mass.inertia_body.iter().all(|x| *x > 0.0)
        };
        if !w.bodies().iter().all(massive) {
            return implausible(out, || format!("input {i}: a world without mass: {t}"));
        }
        // A sample of the accepted scenarios, simulated briefly: nothing may blow up.
        if out.accepted % 2000 != 1 {
            return;
        }
        out.deep += 1;
        let mut short = sc.clone();
        short.duration_s = short.duration_s.min(0.5);
        let extent = Bounds::from_scenario(&sc, None).extent_m;
        for mode in [Mode::Reference, Mode::Distributed(sc.method)] {
            let r = sim::run(&short, mode, &mut |_| {});
            let bad = r
                .sites
                .iter()
                .flat_map(|s| &s.obj_pos)
                .find(|p| !(p.iter().all(|x| x.is_finite()) && p.norm() <= extent * 2.0));
            if let Some(p) = bad {
                let p = *p;
                return implausible(out, || {
                    format!("input {i}: object at {p:?} in {mode:?}: {t}")
                });
            }
        }
    });
    out
}

fn config_target(a: &Args, progress: &AtomicU64) -> Outcome {
    use coop_actors::station::config::StationConfig;
    let base = StationConfig {
        session: "fuzz".into(),
        station: Some("user2".into()),
        record: Some(std::env::temp_dir().join("coop-fuzz-unused.mcap")),
        ..StationConfig::default()
    };
    let text = base.to_toml().unwrap_or_default();
    let scenario = paper();
    let mut rng = Rng::new(a.seed);
    let mut out = Outcome::default();
    each(a, progress, &mut out, |i, out| {
        let t = mutate_text(&mut rng, &text);
        let Ok(c) = toml::from_str::<StationConfig>(&t) else {
            return;
        };
        let Ok(r) = c.resolve_with(None, scenario.clone()) else {
            return;
        };
        out.accepted += 1;
        let ok = coop_model::scenario::valid_name(&r.config.session)
            && r.site < r.scenario.site.len()
            && r.config.rings.tool_slots.is_power_of_two();
        if !ok {
            implausible(out, || format!("input {i}: accepted {t}"));
        }
    });
    out
}

/// Genuine ROS 2 messages of every type we decode, mutated byte-wise: a decoder may refuse, never
/// panic, and what it accepts must be finite and decode again to the same message once encoded
/// (padding aside, the bytes carry nothing else).
fn ros2_target(a: &Args, progress: &AtomicU64) -> Outcome {
    use coop_transport::ros2::cdr::{
        decode_tf, encode_tf, Header, Log, PoseStamped, Time, TransformStamped, WrenchStamped,
    };
    let mut rng = Rng::new(a.seed);
    let mut out = Outcome::default();
    each(a, progress, &mut out, |i, out| {
        let stamp = Time::from_unix_ns(rng.next_u64() >> 4);
        let frame: String = (0..rng.next_u64() % 12)
            .map(|_| char::from(b'a' + (rng.next_u64() % 26) as u8))
            .collect();
        let header = Header {
            stamp,
            frame_id: frame.clone(),
        };
        let v3 = |rng: &mut Rng| {
            [
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            ]
        };
        let kind = rng.next_u64() % 4;
        let mut bytes = match kind {
            0 => PoseStamped {
                header,
                position: v3(&mut rng),
                orientation: [0.0, 0.0, 0.0, 1.0],
            }
            .encode(),
            1 => WrenchStamped {
                header,
                force: v3(&mut rng),
                torque: v3(&mut rng),
            }
            .encode(),
            2 => encode_tf(
                &(0..rng.next_u64() % 4)
                    .map(|_| TransformStamped {
                        header: header.clone(),
                        child_frame_id: frame.clone(),
                        translation: v3(&mut rng),
                        rotation: [0.0, 0.0, 0.0, 1.0],
                    })
                    .collect::<Vec<_>>(),
            ),
            _ => Log {
                stamp,
                level: Log::INFO,
                name: frame.clone(),
                msg: frame.clone(),
                ..Log::default()
            }
            .encode(),
        };
        mutate_bytes(&mut rng, &mut bytes);
        let again = match kind {
            0 => PoseStamped::decode(&bytes).map(|m| {
                let finite = m
                    .position
                    .iter()
                    .chain(&m.orientation)
                    .all(|x| x.is_finite());
                (finite, PoseStamped::decode(&m.encode()) == Ok(m))
            }),
            1 => WrenchStamped::decode(&bytes).map(|m| {
                let finite = m.force.iter().chain(&m.torque).all(|x| x.is_finite());
                (finite, WrenchStamped::decode(&m.encode()) == Ok(m))
            }),
            2 => decode_tf(&bytes).map(|m| {
                let finite = m.iter().all(|t| {
                    t.translation
                        .iter()
                        .chain(&t.rotation)
                        .all(|x| x.is_finite())
                });
                (finite, decode_tf(&encode_tf(&m)) == Ok(m))
            }),
            _ => Log::decode(&bytes).map(|m| (true, Log::decode(&m.encode()) == Ok(m))),
        };
        if let Ok((finite, same)) = again {
            out.accepted += 1;
            if !(finite && same) {
                implausible(out, || {
                    format!("input {i}: accepted kind {kind}, finite {finite}, round trip {same}: {bytes:02x?}")
                });
            }
        }
    });
    out
}
