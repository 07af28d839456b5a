//! Two stations' physics loops running `timewarp` (and `coupled`) over real shared-memory rings, stepped with
//! injected time on the session's tick grid (no sleeping, no timing assertions): each loop's own
//! tool tracks go out through its track ring, the test carries them to the other loop's track ring
//! 30 ms later (the network's part), the loops roll back where a received position differs from the
//! prediction, both copies agree bit for bit at every confirmed frontier compared, and the
//! physics steps, rollbacks included, allocate nothing. `coupled` the same way, its states carried
//! too: its pulls allocate nothing either, and the copies stay together.

use std::collections::VecDeque;

use coop_model::body::{BodyState, Vec3};
use coop_model::method::Consistency;
use coop_model::method::WorldCopy;
use coop_model::scenario::{MethodName, Scenario, SiteSpec};
use coop_rt::msg::{ObjectSample, SiteReport, ToolSample, ToolTrack};
use coop_rt::physics::{PhysicsLoop, PhysicsRings, PhysicsTiming, MAX_CATCH_UP_TICKS};
use coop_rt::shm::{Consumer, Producer, RingSegment, SegmentName};

mod common;
use common::counting_alloc::allocations_during;

const MS: u64 = 1_000_000;
/// The session's time 0, ns (the grid's origin at both sites).
const EPOCH: u64 = 1_000 * MS;
/// The emulated one-way delay of the test's "network", ms.
const DELAY_MS: u64 = 30;

fn name(tag: &str, what: &str) -> SegmentName {
    SegmentName::new(&format!("tw{}", std::process::id()), tag, what).expect("name")
}

/// One site's loop with its rings (the segments kept alive with it).
struct Site {
    physics: PhysicsLoop,
    tool_in: Producer<ToolSample>,
    tracks_out: Consumer<ToolTrack>,
    tracks_in: Producer<ToolTrack>,
    reports: Consumer<SiteReport>,
    remote_in: Producer<SiteReport>,
    _objects: Consumer<ObjectSample>,
    _segments: Segments,
}

/// A site's rings, kept alive with it.
type Segments = (
    RingSegment<ToolSample>,
    RingSegment<ObjectSample>,
    RingSegment<SiteReport>,
    RingSegment<SiteReport>,
    RingSegment<ToolTrack>,
    RingSegment<ToolTrack>,
);

fn scenario() -> Scenario {
    let mut sc = Scenario::default();
    sc.objects[0].start_m = [0.0, 0.0, 0.01];
    sc.world.planes[0].normal = [0.0, 0.0, 1.0];
    sc.world.planes[0].offset_m = 0.0;
    sc.world.gravity_m_per_s2 = [0.0, 0.0, -3.27];
    sc.network.delay_min_ms = DELAY_MS as f64;
    sc.network.delay_max_ms = DELAY_MS as f64;
    sc.network.jitter_ms = 0.0;
    sc.site.clear();
    for n in ["user1", "user2"] {
        sc.site.push(SiteSpec {
            name: n.into(),
            physics_rate_hz: 1000.0,
            report_rate_hz: 100.0,
            tool_radius_m: 0.005,
            ..SiteSpec::default()
        });
    }
    sc
}

fn site(sc: &Scenario, i: usize, method: MethodName) -> Site {
    site_tagged(sc, i, method, "")
}

/// [`site`], its segments' names tagged with `extra` too (tests run at once in one process).
fn site_tagged(sc: &Scenario, i: usize, method: MethodName, extra: &str) -> Site {
    let tag = format!("{}{i}{extra}", &method.as_str()[..2]);
    let tool = RingSegment::<ToolSample>::create(&name(&tag, "tool"), 64).expect("tool");
    let obj = RingSegment::<ObjectSample>::create(&name(&tag, "obj"), 64).expect("obj");
    let rep = RingSegment::<SiteReport>::create(&name(&tag, "rep"), 64).expect("rep");
    let rem = RingSegment::<SiteReport>::create(&name(&tag, "rem"), 64).expect("rem");
    let tko = RingSegment::<ToolTrack>::create(&name(&tag, "tko"), 64).expect("tko");
    let tki = RingSegment::<ToolTrack>::create(&name(&tag, "tki"), 64).expect("tki");
    let copy = sc.start_copy();
    let method = sc.method(i, method);
    let mut physics = PhysicsLoop::new(
        i,
        method,
        sc.world(),
        copy,
        PhysicsRings {
            tools: tool.consumer().expect("c"),
            remote: rem.consumer().expect("c"),
            objects: obj.producer().expect("p"),
            reports: rep.producer().expect("p"),
            trace: None,
            tracks_out: Some(tko.producer().expect("p")),
            tracks_in: Some(tki.consumer().expect("c")),
        },
        PhysicsTiming {
            period_ns: MS,
            report_period_ns: 10 * MS,
            start_ns: EPOCH - 50 * MS,
            trace_period_ns: 5 * MS,
            report_seq: 0,
        },
    );
    physics.set_tick_origin(EPOCH);
    Site {
        physics,
        tool_in: tool.producer().expect("p"),
        tracks_out: tko.consumer().expect("c"),
        tracks_in: tki.producer().expect("p"),
        reports: rep.consumer().expect("c"),
        remote_in: rem.producer().expect("p"),
        _objects: obj.consumer().expect("c"),
        _segments: (tool, obj, rep, rem, tko, tki),
    }
}

/// Where site `i`'s tool is at session time `s`: both squeeze the disk from either side, then
/// carry it along y.
fn tool_at(i: usize, s: f64) -> Vec3 {
    let side = if i == 0 { -1.0 } else { 1.0 };
    let squeeze = (s * 0.02).min(0.008);
    let carry = (s - 0.8).max(0.0) * 0.05;
    Vec3::new(side * (0.045 - squeeze), carry, 0.01)
}

/// Steps both sites from 50 ms before time 0 (the copies hold) to 1.5 s, a late period now and
/// then, carrying tool tracks and site reports between them 30 ms late: the sites, the last step's
/// time and the allocations the physics steps made.
fn run(method: MethodName) -> ([Site; 2], u64, u64) {
    let sc = scenario();
    let mut sites = [site(&sc, 0, method), site(&sc, 1, method)];
    // In flight: (delivery time, to site, track or report).
    let mut wire: VecDeque<(u64, usize, ToolTrack)> = VecDeque::with_capacity(1024);
    let mut states: VecDeque<(u64, usize, SiteReport)> = VecDeque::with_capacity(1024);
    let mut allocations = 0;
    let mut now = EPOCH - 50 * MS;
    let end = EPOCH + 1500 * MS;
    let mut k = 0u64;
    let mut last = now;
    while now < end {
        last = now;
        for (i, s) in sites.iter_mut().enumerate() {
            let t_s = now.saturating_sub(EPOCH) as f64 * 1e-9;
            let p = tool_at(i, t_s);
            let sample = ToolSample {
                t_ns: now,
                tool_pos: [p.x, p.y, p.z],
                ..ToolSample::default()
            };
            s.tool_in.push(sample).expect("tool ring has room");
            allocations += allocations_during(|| s.physics.step(now));
            while let Ok(t) = s.tracks_out.pop() {
                wire.push_back((now + DELAY_MS * MS, 1 - i, t));
            }
            while let Ok(r) = s.reports.pop() {
                states.push_back((now + DELAY_MS * MS, 1 - i, r));
            }
        }
        while wire.front().is_some_and(|&(at, _, _)| at <= now) {
            let (_, to, t) = wire.pop_front().expect("front");
            sites[to].tracks_in.push(t).expect("track ring has room");
        }
        while states.front().is_some_and(|&(at, _, _)| at <= now) {
            let (_, to, r) = states.pop_front().expect("front");
            sites[to].remote_in.push(r).expect("remote ring has room");
        }
        k += 1;
        // Every 97th period is 3 ms late: the loop catches up on the grid.
        now += if k.is_multiple_of(97) { 3 * MS } else { MS };
    }
    (sites, last, allocations)
}

/// What both methods must show: every site stepped every tick of the grid up to the last period,
/// took the other's tracks (none refused or dropped), carried the squeezed disk, and the copies
/// end within 10 mm of each other.
fn on_the_grid_carried_and_together(sites: &[Site; 2], last: u64) {
    for (i, s) in sites.iter().enumerate() {
        let tr = s.physics.tracks;
        assert_eq!(
            s.physics.ticks(),
            (last - EPOCH) / MS + 1,
            "site {i} is on the grid: every tick up to the last period's stepped ({tr:?})"
        );
        assert!(
            tr.received > 100 && tr.rejected == 0 && tr.drops == 0,
            "{tr:?}"
        );
        assert!(
            s.physics.copy().first().state.pos.y > 0.01,
            "site {i}: the squeezed disk was carried: {:?}",
            s.physics.copy().first().state.pos
        );
    }
    let (a, b) = (
        sites[0].physics.copy().first().state,
        sites[1].physics.copy().first().state,
    );
    assert!(
        (a.pos - b.pos).norm() < 0.01,
        "the copies agree within 10 mm: {:?} vs {:?}",
        a.pos,
        b.pos
    );
}

#[test]
fn timewarp_over_real_rings_rolls_back_without_allocating_and_agrees_at_confirmed_ticks() {
    let (sites, last, allocations) = run(MethodName::Timewarp);
    assert_eq!(
        allocations, 0,
        "physics steps (rollbacks included) allocated"
    );
    on_the_grid_carried_and_together(&sites, last);
    for (i, s) in sites.iter().enumerate() {
        let st = s
            .physics
            .method_stats()
            .rollback()
            .copied()
            .expect("timewarp has stats");
        let tr = s.physics.tracks;
        assert!(tr.late_periods > 0 && tr.caught_up_ticks > 0, "{tr:?}");
        assert!(st.rollbacks > 10, "site {i} rolled back: {st:?}");
        assert!(st.hash_checks > 50, "site {i} compared hashes: {st:?}");
        assert_eq!(st.hash_mismatches, 0, "site {i}: {st:?}");
        // Both tools squeeze the disk: each site's own tool was lagged (by half the 30 ms).
        assert!(
            st.lagged_ticks > 100 && st.max_local_lag_ticks >= 14,
            "site {i}: {st:?}"
        );
    }
}

#[test]
fn coupled_over_real_rings_pulls_without_allocating_and_keeps_the_copies_together() {
    let (sites, last, allocations) = run(MethodName::Coupled);
    assert_eq!(allocations, 0, "physics steps (pulls included) allocated");
    on_the_grid_carried_and_together(&sites, last);
    assert!(
        sites.iter().any(|s| s.physics.adoptions() > 10),
        "the follower pulled its copy towards the leader's"
    );
}

/// A knock learned of 300 ms late, replayed to a hand still where the knock found it: the receive
/// that rolls back and starts the replay, the ticks that advance it and the state shown to the
/// servo allocate nothing (the method alone: the loops above carry no such knock).
#[test]
fn a_missed_contact_is_replayed_without_allocating() {
    use coop_model::contact::ContactForce;
    use coop_model::method::track::{quantize, ToolReport};
    use coop_model::method::Report;
    const LATE: i64 = 300;
    let mut sc = scenario();
    sc.network.delay_min_ms = LATE as f64;
    sc.network.delay_max_ms = LATE as f64;
    let world = sc.world();
    let mut copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
    let mut tw = sc.timewarp(0, &copy);
    // Site 1's tool sweeps into the disk's rim from the left (0.1 s), then back; site 0's rests
    // 15 mm right of the rim.
    let remote = |k: i64| {
        let s = k as f64 * 1e-3;
        let x = if s < 0.1 {
            -0.1 + 0.7 * s
        } else {
            (-0.03 - 0.7 * (s - 0.1)).max(-0.1)
        };
        quantize(Vec3::new(x, 0.0, 0.01))
    };
    let mut allocations = 0;
    let mut shown_apart = 0;
    for k in 0..1000i64 {
        let first = k - LATE;
        let report = (first >= 0 && k % 10 == 0).then(|| {
            let mut r = ToolReport {
                first_tick: (first - 9).max(0),
                ..ToolReport::NONE
            };
            for t in r.first_tick..=first {
                r.positions[r.count] = remote(t);
                r.count += 1;
            }
            Report::Tools(r)
        });
        allocations += allocations_during(|| {
            tw.own_tool(Vec3::new(0.06, 0.0, 0.01));
            if let Some(r) = &report {
                tw.receive(&world, &mut copy, 1, r, k as f64 * 1e-3);
            }
            tw.physics_step(&world, &mut copy, &[ContactForce::default()], 1e-3);
            shown_apart += u32::from(tw.shown(&copy, 0) != copy.first().state);
        });
    }
    let st = tw.rollback_stats();
    assert_eq!(st.replays, 1, "the knock was replayed: {st:?}");
    assert!(shown_apart > 0, "the replay showed the history");
    assert_eq!(allocations, 0, "the replay allocated");
}

/// A physics loop that joins the session late (a restart, a late station) steps from the tick
/// its first step falls in, not from tick 0: one tick at its first step, none of the 5 s before.
/// (One whose first step falls before the join threshold steps from tick 0, as the others: see
/// `a_loop_started_with_the_session_steps_from_tick_0`.)
#[test]
fn a_late_physics_loop_joins_the_grid_where_the_session_is() {
    let sc = scenario();
    for method in [MethodName::Timewarp, MethodName::Coupled] {
        let mut s = site_tagged(&sc, 0, method, "j");
        s.physics.join_late(1000, None);
        let now = EPOCH + 5000 * MS + MS / 2;
        let p = tool_at(0, 5.0);
        let sample = ToolSample {
            t_ns: now,
            tool_pos: [p.x, p.y, p.z],
            ..ToolSample::default()
        };
        s.tool_in.push(sample).expect("tool ring has room");
        let allocations = allocations_during(|| s.physics.step(now));
        assert_eq!(allocations, 0, "{method:?}: joining allocated");
        assert_eq!(
            s.physics.ticks(),
            5001,
            "{method:?}: tick 5000 stepped, and only it"
        );
        assert_eq!(
            s.physics.tracks.late_periods, 0,
            "{method:?}: nothing to catch up"
        );
    }
}

/// A loop that may join late but whose first step comes within the threshold (stations started
/// together) steps from tick 0 like every other site.
#[test]
fn a_loop_started_with_the_session_steps_from_tick_0() {
    let sc = scenario();
    let mut s = site_tagged(&sc, 1, MethodName::Timewarp, "z");
    s.physics.join_late(1000, None);
    let now = EPOCH + 300 * MS + MS / 2;
    s.physics.step(now);
    assert_eq!(
        s.physics.ticks(),
        1 + MAX_CATCH_UP_TICKS,
        "catching up from tick 0"
    );
}
