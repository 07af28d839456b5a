use super::*;
use crate::body::BodyState;
use crate::contact::EnvContactState;
use crate::scenario::Scenario;

fn paper_world() -> (Scenario, World) {
    let mut sc = Scenario::default();
    sc.objects[0].start_m = [0.0, 0.0, 0.01];
    sc.world.planes[0].normal = [0.0, 0.0, 1.0];
    sc.world.planes[0].offset_m = 0.0;
    sc.world.gravity_m_per_s2 = [0.0, 0.0, -3.27];
    let w = sc.world();
    (sc, w)
}

/// Site 0 of two 5 mm tools, 1 kHz, 600 ticks of history, the disk at rest at the origin on
/// the table: the method, its copy and the world.
fn two_tools_on_a_disk() -> (TimeWarp, WorldCopy, World) {
    let (sc, w) = paper_world();
    let copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
    let mut radii = [0.0; MAX_SITES];
    radii[..2].fill(0.005);
    (
        TimeWarp::new(0, 2, 1e-3, sc.contact, radii, 600, &copy),
        copy,
        w,
    )
}

/// [`paper_world`]'s scenario with two users resting 0.2 m either side of the disk.
fn two_users() -> Scenario {
    let (mut sc, _) = paper_world();
    for (name, x, base) in [("user1", -0.2, -0.3), ("user2", 0.2, 0.3)] {
        sc.site.push(crate::scenario::SiteSpec {
            name: name.into(),
            device_base_m: [base, -0.2, 0.0],
            script: vec![crate::scenario::KeyframeSpec {
                t_s: 0.0,
                target_m: [x, 0.0, 0.01],
            }],
            ..Default::default()
        });
    }
    sc
}

/// The history kept is `[timewarp] horizon_ms`, or by default what the network can delay a
/// position by plus 100 ms; a horizon that does not cover that is refused.
#[test]
fn the_horizon_is_configured_or_covers_the_latest_arrival() {
    let mut sc = two_users();
    sc.network.delay_min_ms = 20.0;
    sc.network.delay_max_ms = 200.0;
    sc.network.jitter_ms = 10.0;
    sc.site[0].report_rate_hz = 50.0; // 20 ms: 230 ms in all, + 100 ms
    sc.validate().expect("default horizon");
    let copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
    assert_eq!(sc.timewarp(0, &copy).history_ticks(), 331);
    // With loss, 11 reports lost in a row (0.3¹² < 10⁻⁶) and a round trip more: + 450 ms.
    sc.network.loss = 0.3;
    assert_eq!(sc.losses_in_a_row(), 11);
    assert_eq!(sc.timewarp(0, &copy).history_ticks(), 781);
    sc.network.loss = 0.0;
    sc.timewarp.horizon_ms = 2000.0;
    sc.validate().expect("a longer horizon");
    assert_eq!(sc.timewarp(0, &copy).history_ticks(), 2001);
    for bad in [229.0, -1.0, f64::NAN, 10_001.0] {
        sc.timewarp.horizon_ms = bad;
        let e = sc.validate().expect_err("refused");
        assert_eq!(e.field, "timewarp.horizon_ms", "{e}");
        assert!(e.rule.contains("230.0 ms"), "{e}");
    }
}

/// `[timewarp] local_lag_share` and `local_lag_max_ms` default to the method's constants, set
/// the site's lag, and out of range are refused with the field and the rule.
#[test]
fn the_local_lag_is_configured_and_checked() {
    let mut sc = two_users();
    sc.validate().expect("defaults");
    assert_eq!(sc.timewarp.local_lag_share, LOCAL_LAG_SHARE);
    let copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
    let tw = sc.timewarp(0, &copy);
    assert_eq!(
        (tw.lag_share, tw.lag_max),
        (LOCAL_LAG_SHARE, LOCAL_LAG_MAX_TICKS)
    );
    sc.timewarp.local_lag_share = 0.0;
    sc.timewarp.local_lag_max_ms = 150.0;
    sc.validate().expect("no lag, a larger cap");
    let tw = sc.timewarp(0, &copy);
    assert_eq!((tw.lag_share, tw.lag_max), (0.0, 150));
    for bad in [-0.1, 1.5, f64::NAN] {
        sc.timewarp.local_lag_share = bad;
        let e = sc.validate().expect_err("refused");
        assert_eq!(e.field, "timewarp.local_lag_share", "{e}");
    }
    sc.timewarp.local_lag_share = 0.5;
    for bad in [-1.0, 201.0, f64::INFINITY] {
        sc.timewarp.local_lag_max_ms = bad;
        let e = sc.validate().expect_err("refused");
        assert_eq!(e.field, "timewarp.local_lag_max_ms", "{e}");
        assert!(e.rule.contains("200"), "{e}");
    }
}

/// `[timewarp.deadband]` is off by default, turns the site's deadband on, and out of range is
/// refused with the field and the rule.
#[test]
fn the_deadband_is_configured_and_checked() {
    let mut sc = two_users();
    sc.validate().expect("defaults");
    let copy = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
    assert!(sc.timewarp(0, &copy).deadband.is_none(), "off by default");
    sc.timewarp.deadband.enabled = true;
    sc.validate().expect("on");
    assert!(sc.timewarp(0, &copy).deadband.is_some());
    type Field = fn(&mut DeadbandSpec) -> &mut f64;
    let fields: [(&str, Field, f64); 4] = [
        ("weber_fraction", |d| &mut d.weber_fraction, 0.0),
        ("floor_n", |d| &mut d.floor_n, -1.0),
        ("near_m", |d| &mut d.near_m, f64::NAN),
        ("free_space_m", |d| &mut d.free_space_m, 0.5),
    ];
    for (name, field, bad) in fields {
        let mut bad_sc = sc.clone();
        *field(&mut bad_sc.timewarp.deadband) = bad;
        let e = bad_sc.validate().expect_err("refused");
        assert_eq!(e.field, format!("timewarp.deadband.{name}"), "{e}");
    }
}

/// Both sites send their tools through the deadband while site 1's sweeps into the disk: most
/// ticks hold the last position sent, the tracks carry those held positions (runs), and every
/// site steps the same inputs: the confirmed states agree to the bit.
#[test]
fn held_positions_are_every_site_s_inputs() {
    let mut held_runs = 0;
    let sites = two_sites(
        600,
        |_, tw| {
            tw.set_deadband(DeadbandSpec {
                enabled: true,
                ..DeadbandSpec::default()
            })
        },
        3000,
        sweep_into_the_disk,
        50,
        |_, _| false,
        |_, t, _, _| {
            held_runs += t.positions[..t.count]
                .windows(2)
                .filter(|p| p[0] == p[1])
                .count();
        },
    );
    let [(a, ca), (b, cb)] = &sites;
    for (name, tw) in [("site 0", a), ("site 1", b)] {
        let st = tw.rollback_stats();
        assert!(st.hash_checks > 50, "{name}: {st:?}");
        assert_eq!(st.hash_mismatches, 0, "{name}: {st:?}");
        let (ticks, samples) = tw.deadband_samples().expect("on");
        assert_eq!(ticks, 3000);
        assert!(samples * 5 < ticks, "{name}: {samples} of {ticks} sent");
    }
    assert!(held_runs > 1000, "held positions travel: {held_runs}");
    let moved = ca.first().state.pos.x;
    assert!(moved < -1e-3, "the sweep pushed the disk: {moved}");
    let t = a.confirmed_tick().min(b.confirmed_tick());
    assert_eq!(a.hash_at(t), b.hash_at(t));
    assert_eq!(ca.first().state, cb.first().state);
}

/// [`two_tools_on_a_disk`]'s site 0, with or without a deadband, `count + 10` ticks on (its own
/// tool far left), after site 1's track of ticks `0..count` with positions `x(k)` (m, on the
/// disk's axis) arrived: the method, its copy and the world.
fn after_a_remote_track(
    deadband: bool,
    count: usize,
    x: impl Fn(usize) -> f64,
) -> (TimeWarp, WorldCopy, World) {
    let (mut tw, mut copy, w) = two_tools_on_a_disk();
    if deadband {
        tw.set_deadband(DeadbandSpec {
            enabled: true,
            ..DeadbandSpec::default()
        });
    }
    for _ in 0..count + 10 {
        tw.own_tool(Vec3::new(-0.2, 0.0, 0.01));
        tw.physics_step(&w, &mut copy, &[ContactForce::default()], 1e-3);
    }
    let mut r = ToolReport {
        first_tick: 0,
        count,
        need: [-1; MAX_SITES],
        ..ToolReport::NONE
    };
    for (k, p) in r.positions[..count].iter_mut().enumerate() {
        *p = quantize(Vec3::new(x(k), 0.0, 0.01));
    }
    tw.receive(&w, &mut copy, 1, &Report::Tools(r), 0.05);
    (tw, copy, w)
}

/// A remote tool pressing into the disk at its newest known tick is extrapolated (for a few
/// ticks) with its last step while every position is sent; through a deadband that last step is
/// a held run's (nothing, or a band's jump in one tick), and the velocity is that between its last
/// two samples instead.
#[test]
fn through_a_deadband_a_remote_tool_in_contact_goes_on_at_the_velocity_between_its_samples() {
    // Site 1's tool 0.05 mm into the disk's rim (x = 0.045 touches) and pressing on by 0.02 mm
    // every 10 ticks (too light a press to move the disk on the table): sent at ticks 0, 10, ...,
    // 40, held in between; known to tick 49.
    let x = |k: usize| 0.04495 - 0.00002 * (k / 10) as f64;
    let last = quantize(Vec3::new(x(49), 0.0, 0.01));
    let predicted = [false, true].map(|deadband| {
        let (tw, _, _) = after_a_remote_track(deadband, 50, x);
        assert!(
            TimeWarp::touches(tw.tools_at(tw.idx(49)), 1),
            "site 1's tool touches the disk at its newest tick"
        );
        [59, 99].map(|t| tw.input(1, t))
    });
    assert_eq!(
        predicted[0],
        [(last, false); 2],
        "every tick sent: on with its last step, none"
    );
    assert_eq!(
        predicted[1],
        [
            ([last[0] - 2, last[1], last[2]], false),
            ([last[0] - 4, last[1], last[2]], false)
        ],
        "through a deadband: on at 2 quanta per 10 ticks, for at most {EXTRAPOLATE_TICKS} ticks"
    );
    // A slower press, 3 quanta every 20 ticks (sent at ticks 0, 20 and 40): on by 3 quanta in 20
    // ticks, not by a velocity rounded to whole quanta per 10 ticks first (2).
    let x = |k: usize| 0.04495 - 0.00003 * (k / 20) as f64;
    let (tw, _, _) = after_a_remote_track(true, 50, x);
    let last = quantize(Vec3::new(x(49), 0.0, 0.01));
    assert_eq!(tw.input(1, 69), ([last[0] - 3, last[1], last[2]], false));
    // Every tick sent and the last step one of 5 quanta: on with it.
    let (tw, _, _) = after_a_remote_track(false, 50, |k| if k < 49 { 0.0449 } else { 0.04485 });
    let last = quantize(Vec3::new(0.04485, 0.0, 0.01));
    assert_eq!(
        tw.input(1, 55),
        ([last[0] - 6 * 5, last[1], last[2]], false)
    );
}

/// A free remote tool is predicted on as a reaching hand. Through a deadband its held runs say
/// nothing over the last few ticks (a run) or one jump of a band: its velocity is taken between
/// its last two samples instead, each run looked for from its own end (the two together may be
/// longer than that reach back), and a run longer than that is a tool at rest.
#[test]
fn through_a_deadband_a_free_remote_tool_reaches_at_the_velocity_between_its_samples() {
    let last = quantize(Vec3::new(0.098, 0.0, 0.01));
    let [(full, _), (band, reach)] = [false, true].map(|deadband| {
        // Site 1's tool far from the disk, moving left at 40 mm/s through a 2 mm band: sent at
        // ticks 0, 50 and 100, held in between; known to tick 139.
        let x = |k: usize| 0.102 - 0.002 * (k / 50) as f64;
        let (tw, _, _) = after_a_remote_track(deadband, 140, x);
        // 200 quanta in 50 ticks.
        let reach = tw.reach(
            last,
            Some((last, [last[0] + 200, last[1], last[2]], 50)),
            10,
            f64::INFINITY,
        );
        (tw.input(1, 149).0, reach)
    });
    assert_eq!(full, last, "every tick sent: a held run is a tool at rest");
    assert_eq!(band, reach, "through a deadband: on at 40 mm/s");
    assert!(band[0] < last[0] - 20, "{band:?}");
    // Sent at ticks 0 and 100 only: the run before the last is longer than the reach back.
    let (tw, _, _) = after_a_remote_track(true, 140, |k| if k < 100 { 0.1 } else { 0.098 });
    assert_eq!(tw.input(1, 149).0, last, "a tool this slow is at rest");
    // Sent every 30 ticks (known to tick 139, last sent at 120): 200 quanta in 30 ticks, one
    // division; through a position 10 ticks back, rounded to whole quanta, it was 66 in 10.
    let (tw, _, _) = after_a_remote_track(true, 140, |k| 0.102 - 0.002 * (k / 30) as f64);
    let (h, tau) = (REACH_TICKS as f64, REACH_TIME_TICKS as f64);
    let gone = |v: f64| (v * h * tau / (h + tau)).round() as i32;
    let far = tw.input(1, 139 + REACH_TICKS).0;
    let at_120 = quantize(Vec3::new(0.094, 0.0, 0.01));
    // (1538 quanta; at 6.6 a tick, 1523.)
    assert_eq!(far[0] - at_120[0], gone(-200.0 / 30.0), "{far:?}");
}

/// A free remote tool slowing at the end of a minimum-jerk reach that stops 15 mm short of the
/// disk is predicted to stop about there, not to glide on into the disk at its last velocity (a
/// phantom push the waiting partner would see and feel, taken back a delay later).
#[test]
fn a_remote_reach_slowing_short_of_the_disk_is_predicted_to_stop_short_of_it() {
    // From x = 0.20 to 0.06 in 250 ticks (the disk's rim is touched at 0.045), known to tick 199.
    let x = |k: usize| {
        let s = (k as f64 / 250.0).min(1.0);
        0.20 - 0.14 * (10.0 * s.powi(3) - 15.0 * s.powi(4) + 6.0 * s.powi(5))
    };
    let (tw, _, _) = after_a_remote_track(false, 200, x);
    let far = tw.input(1, 199 + REACH_TICKS).0;
    let end = quantize(Vec3::new(0.06, 0.0, 0.01));
    let rim = quantize(Vec3::new(0.045, 0.0, 0.01));
    assert!(
        (far[0] - end[0]).abs() <= quantize(Vec3::new(0.003, 0.0, 0.0))[0],
        "predicted to stop within 3 mm of the reach's end: {far:?} vs {end:?}"
    );
    // Gliding on at its last velocity would have carried it into the disk.
    let last = quantize(Vec3::new(x(199), 0.0, 0.01));
    let p0 = quantize(Vec3::new(x(199 - REACH_VELOCITY_TICKS as usize), 0.0, 0.01));
    let glide = tw.reach(
        last,
        Some((last, p0, REACH_VELOCITY_TICKS)),
        REACH_TICKS,
        f64::INFINITY,
    );
    assert!(glide[0] < rim[0], "{glide:?}");
}

/// Two tools squeeze the disk from both sides and carry it: the synctest (a rollback of every
/// depth up to 50 ticks, on every tick) always arrives at the same bits.
#[test]
fn a_forced_rollback_on_every_tick_gives_the_same_bits() {
    let (mut tw, mut copy, w) = two_tools_on_a_disk();
    let mut other = [0i32; 3];
    for k in 0..1500i64 {
        let s = k as f64 * 1e-3;
        let squeeze = (s * 0.02).min(0.008);
        let carry = (s - 0.8).max(0.0) * 0.05;
        tw.own_tool(Vec3::new(-0.045 + squeeze, carry, 0.01));
        // The other site's tool, received with a 30-tick delay in 10-tick batches.
        if k % 10 == 0 && k >= 30 {
            let mut r = ToolReport {
                first_tick: k - 40,
                count: 10,
                positions: [[0; 3]; WINDOW_TICKS],
                confirmed_tick: 0,
                confirmed_hash: 0,
                need: [-1; MAX_SITES],
                ..ToolReport::NONE
            };
            for j in 0..10 {
                let t = (k - 40 + j) as f64 * 1e-3;
                other = quantize(Vec3::new(
                    0.045 - (t * 0.02).min(0.008),
                    (t - 0.8).max(0.0) * 0.05,
                    0.01,
                ));
                r.positions[j as usize] = other;
            }
            if r.first_tick >= 0 {
                tw.receive(&w, &mut copy, 1, &Report::Tools(r), s);
            }
        }
        tw.physics_step(&w, &mut copy, &[ContactForce::default()], 1e-3);
        let depth = 1 + k % 50;
        assert!(tw.synctest(&w, &mut copy, depth), "tick {k}, depth {depth}");
    }
    assert!(
        tw.rollback_stats().rollbacks > 10,
        "the received tool caused rollbacks: {:?}",
        tw.rollback_stats()
    );
    assert!(
        copy.first().state.pos.y > 0.01,
        "the squeezed disk was carried: {:?}",
        copy.first().state.pos
    );
    let _ = other;
}

/// A remote tool knocks the disk into the own, resting tool. Learned a delay late, that
/// contact is over before the copy can show it: its confirmed ticks count as unfelt. Learned
/// before each tick is simulated, everything shown live is what was confirmed.
#[test]
fn a_contact_learned_too_late_to_show_counts_as_unfelt() {
    let rest = |_| Vec3::new(0.06, 0.0, 0.01);
    let prompt = knock(0, rest);
    assert!(prompt.touched, "the knocked disk reached the own tool");
    assert_eq!(
        (
            prompt.stats.unfelt_contact_ticks,
            prompt.stats.phantom_contact_ticks
        ),
        (0, 0),
        "{:?}",
        prompt.stats
    );
    let late = knock(300, rest);
    assert!(
        late.stats.unfelt_contact_ticks > 0,
        "the contact the copy learned of 0.3 s late: {:?}",
        late.stats
    );
}

/// A contact the own user missed is shown late, replayed from the confirmed history, while
/// the hand is still where the contact had it; not once it has moved on.
#[test]
fn a_missed_contact_is_replayed_to_a_hand_still_there() {
    let rest = |_| Vec3::new(0.06, 0.0, 0.01);
    let prompt = knock(0, rest);
    assert_eq!(
        prompt.stats.replays, 0,
        "nothing missed: {:?}",
        prompt.stats
    );
    assert!(prompt.shown_touching_ticks > 0 && prompt.shown_was_copy);
    let late = knock(300, rest);
    assert_eq!(late.stats.replays, 1, "{:?}", late.stats);
    assert!(
        !late.shown_was_copy,
        "the replay showed the history, not the copy"
    );
    assert!(
        late.shown_touching_ticks > 0,
        "the replayed disk met the hand: {:?}",
        late.stats
    );
    assert!(late.ends_on_copy, "the replay caught up with the copy");
    // The hand moved 5 mm away between the contact and its news: nothing is replayed.
    let moved = knock(300, |k| {
        Vec3::new(if k < 250 { 0.06 } else { 0.065 }, 0.0, 0.01)
    });
    assert!(moved.stats.unfelt_contact_ticks > 0, "{:?}", moved.stats);
    assert_eq!(moved.stats.replays, 0, "{:?}", moved.stats);
    assert!(moved.shown_was_copy && moved.ends_on_copy);
}

/// What [`knock`] saw.
struct Knock {
    stats: RollbackStats,
    /// The copy touched the own tool at some tick.
    touched: bool,
    /// Ticks at which the shown object touched the own tool.
    shown_touching_ticks: u64,
    /// The shown object was always the copy.
    shown_was_copy: bool,
    /// ... and was at the end.
    ends_on_copy: bool,
}

/// Site 0 of [`two_tools_on_a_disk`], its tool at `own(k)`; site 1's tool knocks the disk
/// towards it (from x = -0.1 into the disk's rim at -0.04 in 0.1 s, then back), its
/// positions arriving `delay` ticks late, 10 to a report (each one at once at 0).
fn knock(delay: i64, own: impl Fn(i64) -> Vec3) -> Knock {
    let (mut tw, mut copy, w) = two_tools_on_a_disk();
    let remote = |k: i64| {
        let s = k as f64 * 1e-3;
        let x = if s < 0.1 {
            -0.1 + 0.7 * s
        } else {
            (-0.03 - 0.7 * (s - 0.1)).max(-0.1)
        };
        quantize(Vec3::new(x, 0.0, 0.01))
    };
    let mut out = Knock {
        stats: RollbackStats::default(),
        touched: false,
        shown_touching_ticks: 0,
        shown_was_copy: true,
        ends_on_copy: false,
    };
    for k in 0..1000i64 {
        tw.own_tool(own(k));
        let first = k - delay;
        if first >= 0 && (delay == 0 || k % 10 == 0) {
            let count = if delay == 0 { 1 } else { 10 };
            let r = track((first - count + 1).max(0), first, remote);
            tw.receive(&w, &mut copy, 1, &r, k as f64 * 1e-3);
        }
        tw.physics_step(&w, &mut copy, &[ContactForce::default()], 1e-3);
        out.touched |= tw.contacts[0].touching();
        let shown = tw.shown(&copy, 0);
        out.shown_was_copy &= shown == copy.first().state;
        // The rim (0.04 m) meets the tool (0.005 m) in the plane.
        let gap = (own(k) - shown.pos).xy().norm() - 0.045;
        out.shown_touching_ticks += u64::from(gap < 0.0);
        out.ends_on_copy = shown == copy.first().state;
    }
    out.stats = tw.rollback_stats();
    out
}

/// Site 0 of [`two_tools_on_a_disk`] for `ticks` ticks, its tool measured at `own(k)`; site
/// 1's tool at `remote(k)`, its positions arriving `delay` ticks late, 10 to a report. What
/// the own tool's input was at each tick (from the reports), and the lag after each tick.
fn lagged(
    ticks: i64,
    delay: i64,
    own: impl Fn(i64) -> Vec3,
    remote: impl Fn(i64) -> Vec3,
) -> (Vec<Quantized>, Vec<u64>, TimeWarp) {
    let (mut tw, mut copy, w) = two_tools_on_a_disk();
    let (mut inputs, mut lags) = (Vec::new(), Vec::new());
    for k in 0..ticks {
        tw.own_tool(own(k));
        let first = k - delay;
        if first >= 9 && k % 10 == 0 {
            let r = track(first - 9, first, |t| quantize(remote(t)));
            tw.receive(&w, &mut copy, 1, &r, k as f64 * 1e-3);
        }
        tw.physics_step(&w, &mut copy, &[ContactForce::default()], 1e-3);
        inputs.push(tw.own_at(k));
        lags.push(tw.rollback_stats().local_lag_ticks);
    }
    (inputs, lags, tw)
}

/// Local lag: while the own tool and a partner's are within a centimetre of the object, the
/// own tool's positions enter the physics half the partner's measured delay late (grown
/// into at half speed), and exactly as measured again once either is away (caught up at
/// twice the speed); never before the partner's delay is known.
#[test]
fn a_tool_near_the_object_with_a_partner_is_lagged_by_half_its_delay() {
    // The rim is 40 mm from the disk's centre; 5 mm tools 50 mm from it are 5 mm off it.
    // The own tool slides along the rim a quantum a tick (every tick's position differs),
    // and leaves at tick 700.
    let own = |k: i64| {
        let x = if k < 700 { -0.05 } else { -0.1 };
        Vec3::new(x, k as f64 * QUANTUM_M, 0.01)
    };
    let (inputs, lags, tw) = lagged(1000, 120, own, |_| Vec3::new(0.05, 0.0, 0.01));
    // Before the first report (tick 129) no delay is known: no lag.
    assert!(lags[..129].iter().all(|&l| l == 0), "{lags:?}");
    assert!(inputs[..129]
        .iter()
        .enumerate()
        .all(|(k, &q)| q == quantize(own(k as i64))));
    // Half of 120 ticks, within the slack, reached at half speed (60 ticks in 120).
    let lag = lags[600];
    assert!((59..=60).contains(&lag), "lag {lag}");
    assert!(lags[129..260].windows(2).all(|w| w[1] <= w[0] + 1));
    for k in 400..700 {
        assert_eq!(lags[k], lag);
        assert_eq!(inputs[k], quantize(own(k as i64 - lag as i64)), "tick {k}");
    }
    // Away from the object: caught up, a tick a tick, and exactly as measured again.
    assert!(lags[700 + lag as usize + 5..].iter().all(|&l| l == 0));
    assert_eq!(inputs[999], quantize(own(999)));
    let st = tw.rollback_stats();
    assert_eq!(st.max_local_lag_ticks, lag);
    assert!(st.lagged_ticks > 500, "{st:?}");
}

/// A partner reported lost (its link down) has no known delay: the own tool's lag for it ends.
#[test]
fn a_lost_partner_ends_the_lag() {
    let (mut tw, mut copy, w) = two_tools_on_a_disk();
    for k in 0..700i64 {
        tw.own_tool(Vec3::new(-0.05, 0.0, 0.01));
        let first = k - 120;
        if (9..400).contains(&first) && k % 10 == 0 {
            let r = track(first - 9, first, |_| quantize(Vec3::new(0.05, 0.0, 0.01)));
            tw.receive(&w, &mut copy, 1, &r, k as f64 * 1e-3);
        }
        if k == 550 {
            assert!(
                tw.rollback_stats().local_lag_ticks >= 59,
                "{:?}",
                tw.rollback_stats()
            );
            tw.peer_lost(1, k as f64 * 1e-3);
        }
        tw.physics_step(&w, &mut copy, &[ContactForce::default()], 1e-3);
    }
    assert_eq!(
        tw.rollback_stats().local_lag_ticks,
        0,
        "{:?}",
        tw.rollback_stats()
    );
}

/// A lag is never caught up while the own tool touches the object: its positions would be
/// played into the object at twice the speed the hand moved.
#[test]
fn a_touching_tool_keeps_its_lag_until_it_lets_go() {
    // Pressing on the disk's top (at 20 mm; 1 mm deep: the table holds the disk) until tick
    // 700, then away; the partner leaves at tick 400 (its leaving arrives at 520).
    let own = |k: i64| {
        let x = if k < 700 { 0.0 } else { -0.1 };
        Vec3::new(x, 0.0, 0.024)
    };
    let remote = |k: i64| Vec3::new(if k < 400 { 0.05 } else { 0.2 }, 0.0, 0.01);
    let (_, lags, _) = lagged(1000, 120, own, remote);
    let lag = lags[519];
    assert!(lag >= 59, "lag {lag}");
    // Wanted no more from tick 520, held while touching: until the tool lets go in the
    // physics (its lagged positions), `lag` ticks after it did; then caught up as fast.
    let lets_go = 700 + lag as usize;
    assert!(lags[520..lets_go].iter().all(|&l| l == lag), "{lags:?}");
    assert!(lags[lets_go + lag as usize + 5..].iter().all(|&l| l == 0));
}

/// A physics process that joins the grid late (a restart, a late station) starts where the
/// session is, not at tick 0, from a copy that is not the session's: it never simulates a
/// tick before the one it joined at, sends no positions from before it, adopts the earlier
/// site's confirmed state, and the two agree from then on.
#[test]
fn a_site_joining_the_grid_late_starts_there_and_adopts() {
    let (sc, w) = paper_world();
    let start = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
    let mut radii = [0.0; MAX_SITES];
    radii[..2].fill(0.005);
    let new = |i| TimeWarp::new(i, 2, 1e-3, sc.contact, radii, 600, &start);
    // Site 1 pushes the disk (ticks 900-1300), its physics dies at 1500 and a new one joins
    // the grid at 2000 from the scenario's start.
    let (crash, join) = (1500, 2000);
    let mut sites = [(new(0), start.clone()), (new(1), start.clone())];
    let mut in_flight: Vec<(i64, usize, Report)> = Vec::new();
    let down = |i: usize, k: i64| i == 1 && (crash..join).contains(&k);
    for k in 0..4000 {
        if k == join {
            let mut b = new(1);
            b.set_started_tick(join as u64);
            b.start_at_tick(join);
            sites[1] = (b, start.clone());
        }
        for (i, (tw, copy)) in sites.iter_mut().enumerate() {
            if down(i, k) {
                continue;
            }
            for (_, from, r) in in_flight.iter().filter(|m| m.0 == k && m.1 != i) {
                tw.receive(&w, copy, *from, r, k as f64 * 1e-3);
            }
            tw.own_tool(sweep_into_the_disk(i, k));
            tw.physics_step(&w, copy, &[ContactForce::default()], 1e-3);
        }
        in_flight.retain(|m| m.0 > k);
        if k % 20 == 0 {
            for (i, (tw, _)) in sites.iter().enumerate() {
                if down(i, k) {
                    continue;
                }
                let r = tw.track_report();
                if let Report::Tools(t) = &r {
                    assert!(
                        i == 0 || k < crash || t.first_tick >= join,
                        "{}",
                        t.first_tick
                    );
                }
                in_flight.push((k + 30, i, r));
            }
        }
    }
    let [(a, ca), (b, _)] = &sites;
    assert!(ca.first().state.pos.x < -0.002, "site 1 pushed the disk");
    assert!(
        b.slots.iter().all(|s| s.tick == i64::MIN || s.tick >= join),
        "nothing simulated before the join"
    );
    let st = b.rollback_stats();
    assert!(st.hash_mismatches > 0 && st.adopted_states >= 1, "{st:?}");
    // Positions from before it joined are not counted as ones it could not undo.
    assert_eq!(st.fallbacks, 0, "{st:?}");
    let t = a.confirmed_tick().min(b.confirmed_tick()) - 1;
    assert!(t > 3500, "both confirmed to near the end: {t}");
    assert_eq!(
        a.hash_at(t),
        b.hash_at(t),
        "the same confirmed state at {t}"
    );
    assert_eq!(
        a.rollback_stats().adopted_states,
        0,
        "{:?}",
        a.rollback_stats()
    );
}

/// Stations started apart: site 1's grid runs `skew` ticks ahead of site 0's (it started
/// first), and they hear each other only from wall tick `connect`. Reports go every 11 and 50
/// ticks (the paper's 90 and 20 Hz) and arrive a tick later. Both compare their confirmed
/// states, many times, and agree. Before, with 209 ticks of skew and a late connection, neither
/// compared once: site 0 gave up the start-up gap only at its own horizon, which site 1's
/// history had already left, so its frontier trailed a history behind for the whole session;
/// and without a late connection the site ahead compared once or not at all, the frontier
/// of the site behind being a tick it had not stepped to (no hash sent).
#[test]
fn stations_started_apart_compare_their_confirmed_states() {
    let (sc, w) = paper_world();
    for (skew, connect) in [(50_i64, 0_i64), (209, 1000), (-209, 1000), (400, 1500)] {
        let start = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
        let mut radii = [0.0; MAX_SITES];
        radii[..2].fill(0.005);
        let mut sites = [0, 1].map(|i| {
            (
                TimeWarp::new(i, 2, 1e-3, sc.contact, radii, 660, &start),
                start.clone(),
            )
        });
        let (begin, every) = ([skew.max(0), (-skew).max(0)], [11_i64, 50]);
        let mut in_flight: Vec<(i64, usize, Report)> = Vec::new();
        for k in 0..6000 {
            for i in (0..2).filter(|&i| k >= begin[i]) {
                let (tw, copy) = &mut sites[i];
                for (_, from, r) in in_flight.iter().filter(|m| m.0 == k && m.1 != i) {
                    tw.receive(&w, copy, *from, r, 0.0);
                }
                tw.own_tool(Vec3::new(if i == 0 { -0.2 } else { 0.2 }, 0.0, 0.01));
                tw.physics_step(&w, copy, &[ContactForce::default()], 1e-3);
                if (k - begin[i]) % every[i] == 0 && k >= connect {
                    let r = tw.track_report();
                    in_flight.push((k + 1, i, r));
                }
            }
            in_flight.retain(|m| m.0 > k);
        }
        for (i, (tw, _)) in sites.iter().enumerate() {
            let st = tw.rollback_stats();
            // A report of the other site's every 50 (or 11) ticks, from the connection on.
            assert!(
                st.hash_checks > 60,
                "skew {skew}, connected at {connect}: site {i} compared: {st:?}"
            );
            assert_eq!(st.hash_mismatches, 0, "skew {skew}: site {i}: {st:?}");
        }
    }
}

/// Two sites of the disk at rest, 1 kHz, `history` ticks kept, site i's method set up by
/// `configure(i, _)`, for `ticks` ticks: site i's tool at `tool(i, k)`, a report every 20
/// ticks arriving `delay` ticks later unless `lost(from, k)`; `seen(i, report, k)` sees every
/// report sent.
#[allow(clippy::too_many_arguments)]
fn two_sites(
    history: usize,
    configure: impl Fn(usize, &mut TimeWarp),
    ticks: i64,
    tool: impl Fn(usize, i64) -> Vec3,
    delay: i64,
    lost: impl Fn(usize, i64) -> bool,
    mut seen: impl FnMut(usize, &ToolReport, i64, &[(TimeWarp, WorldCopy); 2]),
) -> [(TimeWarp, WorldCopy); 2] {
    let (sc, w) = paper_world();
    let start = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
    let mut radii = [0.0; MAX_SITES];
    radii[..2].fill(0.005);
    let mut sites = [0, 1].map(|i| {
        let mut tw = TimeWarp::new(i, 2, 1e-3, sc.contact, radii, history, &start);
        configure(i, &mut tw);
        (tw, start.clone())
    });
    let mut in_flight: Vec<(i64, usize, Report)> = Vec::new();
    let mut seqs = [0u64; 2];
    for k in 0..ticks {
        for (i, (tw, copy)) in sites.iter_mut().enumerate() {
            for (_, from, r) in in_flight.iter().filter(|m| m.0 == k && m.1 != i) {
                tw.receive(&w, copy, *from, r, k as f64 * 1e-3);
            }
            tw.own_tool(tool(i, k));
            tw.physics_step(&w, copy, &[ContactForce::default()], 1e-3);
        }
        in_flight.retain(|m| m.0 > k);
        if k % 20 == 0 {
            for i in 0..2 {
                // Every track of the report (the newest window; a repair while one is asked
                // for), numbered as the wire numbers tracks; a lost report loses them all.
                let mut tracks = Vec::new();
                let (tw, copy) = &sites[i];
                tw.report(copy, &[], 0.0, &mut |r| tracks.push(r));
                for mut r in tracks {
                    if let Report::Tools(t) = &mut r {
                        seqs[i] += 1;
                        t.seq = seqs[i];
                        seen(i, t, k, &sites);
                    }
                    if !lost(i, k) {
                        in_flight.push((k + delay, i, r));
                    }
                }
            }
        }
    }
    sites
}

/// Site 1's tool sweeps from the right into the disk's rim (x = 0.04) between ticks 900 and
/// 1300, then back; site 0's rests left of the disk.
fn sweep_into_the_disk(i: usize, k: i64) -> Vec3 {
    let s = k as f64 * 1e-3;
    let x = match (i, s) {
        (0, _) => -0.06,
        (_, s) if s < 0.9 => 0.08,
        (_, s) if s < 1.3 => 0.08 - 0.1 * (s - 0.9),
        (_, s) => (0.04 + 0.1 * (s - 1.3)).min(0.08),
    };
    Vec3::new(x, 0.0, 0.01)
}

/// Two sites, 100 ticks apart, reporting every 20 ticks. Site 1's tool sweeps into the disk
/// while 400 ticks of its reports are lost (more than a report's window of 256): site 0 holds
/// later positions and not the gap's, so its frontier waits there and it asks for the gap
/// (`need`); site 1 sends the gap again and the confirmed states agree to the bit. Without the
/// request (the window alone) site 0 would confirm ticks simulated with a prediction of the
/// sweep, and every later hash would differ.
#[test]
fn a_gap_of_lost_reports_is_asked_for_and_sent_again() {
    let start_x = 0.0;
    let mut asked = false;
    let sites = two_sites(
        1000,
        |_, _| {},
        3000,
        sweep_into_the_disk,
        100,
        |from, k| from == 1 && (1150..1550).contains(&k),
        |i, t, _, _| asked |= i == 0 && t.need[1] >= 0,
    );
    let [(a, _), (b, _)] = &sites;
    assert!(asked, "site 0 asked for the gap");
    let moved = start_x - sites[1].1.first().state.pos.x;
    assert!(moved > 1e-3, "the sweep pushed the disk {moved} m");
    for (name, st) in [
        ("site 0", a.rollback_stats()),
        ("site 1", b.rollback_stats()),
    ] {
        assert!(st.hash_checks > 50, "{name} compared: {st:?}");
        assert_eq!(st.hash_mismatches, 0, "{name}: {st:?}");
        assert_eq!(st.fallbacks, 0, "{name}: {st:?}");
    }
    assert_eq!(
        a.confirmed_tick(),
        b.confirmed_tick(),
        "both confirmed to the last report"
    );
}

/// Tracks carry the ticks since the last report and the last reports' again, not a whole window:
/// with 30 % of the reports lost at random, the gaps the redundancy does not cover are asked
/// for and sent again, the redundancy grows with them, and the confirmed states still agree to
/// the bit, as with no loss, while a track carries a few reports' ticks, not 256.
#[test]
fn at_thirty_percent_loss_short_tracks_lose_nothing() {
    let mut rng = crate::rng::Rng::new(11);
    let lost: Vec<bool> = (0..6000).map(|_| rng.uniform() < 0.3).collect();
    let (mut counts, mut repairs, mut asked) = (Vec::new(), 0, 0);
    let sites = two_sites(
        1000,
        |_, _| {},
        3000,
        sweep_into_the_disk,
        30,
        |from, k| lost[2 * k as usize + from],
        |i, t, _, _| {
            asked += usize::from(t.need[1 - i] >= 0);
            // (A repair sends from the gap on, up to 256 ticks: more than the redundancy's.)
            if t.count > 20 * (MAX_REDUNDANCY + 1) {
                repairs += 1;
            }
            counts.push(t.count);
        },
    );
    let clean = two_sites(
        1000,
        |_, _| {},
        3000,
        sweep_into_the_disk,
        30,
        |_, _| false,
        |_, _, _, _| {},
    );
    let [(a, ca), (b, cb)] = &sites;
    for (name, st) in [
        ("site 0", a.rollback_stats()),
        ("site 1", b.rollback_stats()),
    ] {
        assert!(st.hash_checks > 30, "{name} compared: {st:?}");
        assert_eq!(st.hash_mismatches, 0, "{name}: {st:?}");
        assert_eq!(st.fallbacks, 0, "{name}: {st:?}");
    }
    assert!(
        asked > 0 && repairs > 0,
        "gaps asked for {asked}, repaired {repairs}"
    );
    let grown = a.tracks.reports().max(b.tracks.reports());
    assert!(
        grown > MIN_REDUNDANCY,
        "the redundancy grew with the gaps: {grown}"
    );
    // Every report is 20 ticks: a track carries as many reports' as the measured loss needs
    // (at 0.3, 8: 160 ticks), not the window.
    let reports = (0..2)
        .map(|i| sites[i].0.tracks.reports())
        .collect::<Vec<_>>();
    assert_eq!(reports, [MAX_REDUNDANCY; 2], "sized for the loss");
    counts.sort_unstable();
    let median = counts[counts.len() / 2];
    assert!(
        median <= 20 * (MAX_REDUNDANCY + 1),
        "median track {median} ticks"
    );
    // The same confirmed history as without loss.
    let t = a
        .confirmed_tick()
        .min(b.confirmed_tick())
        .min(clean[0].0.confirmed_tick());
    assert!(t > 2900, "{t}");
    assert_eq!(a.hash_at(t), clean[0].0.hash_at(t));
    assert_eq!(b.hash_at(t), clean[1].0.hash_at(t));
    assert_eq!(ca.first().state, clean[0].1.first().state);
    assert_eq!(cb.first().state, clean[1].1.first().state);
}

/// A link down for longer than the history: site 0 never learns part of site 1's sweep into
/// the disk (a fallback), so their confirmed states differ; site 1 asks site 0 (the lower
/// number) for its state, adopts it, and from then on they agree again. A site whose physics
/// started later (a restart) comes after one that was there: then site 0 adopts site 1's.
#[test]
fn confirmed_states_that_differ_after_a_fallback_are_resynchronized() {
    // Site 1 adopts site 0's state; with site 0's physics started at tick 1, the other way round.
    for (started_tick, adopter) in [([0, 0], 1), ([1, 0], 0)] {
        let mut asked = false;
        let mut mismatches_at = [0u64; 2];
        // The ticks the asked site sent its state at.
        let mut sent_at = Vec::new();
        // Site 1 → site 0 is down for 1.2 s, twice the history.
        let sites = two_sites(
            600,
            |i, tw| tw.set_started_tick(started_tick[i]),
            4000,
            sweep_into_the_disk,
            50,
            |from, k| from == 1 && (1000..2200).contains(&k),
            |i, t, k, sites| {
                asked |= i == adopter && t.need_state == 1 << (1 - adopter);
                if i != adopter && t.state.is_some() {
                    sent_at.push(k);
                }
                if k == 3000 {
                    mismatches_at[i] = sites[i].0.rollback_stats().hash_mismatches;
                }
            },
        );
        let [(a, ca), (b, cb)] = &sites;
        let st = [a.rollback_stats(), b.rollback_stats()];
        let why = format!("{started_tick:?}: {:?} {:?}", st[0], st[1]);
        assert!(
            st[0].fallbacks > 0,
            "site 0 lost part of site 1's sweep: {why}"
        );
        assert!(
            st[0].hash_mismatches + st[1].hash_mismatches > 0,
            "the divergence was seen: {why}"
        );
        assert!(asked, "site {adopter} asked the other for its state: {why}");
        assert!(st[adopter].adopted_states > 0, "{why}");
        assert_eq!(st[1 - adopter].adopted_states, 0, "{why}");
        // Sent while asked, but once a round trip (50 ticks each way, the asker's reports 20
        // apart) and the slack, not in every report: the adoption stops the asking in between.
        let resend = 100 + (STATE_RESEND_SLACK_S / 1e-3) as i64;
        assert!(!sent_at.is_empty(), "{why}");
        assert!(
            sent_at.windows(2).all(|w| w[1] - w[0] >= resend),
            "the state sent at ticks {sent_at:?}: {why}"
        );
        assert_eq!(
            [st[0].hash_mismatches, st[1].hash_mismatches],
            mismatches_at,
            "no mismatch in the last second: {why}"
        );
        assert!(st[1].hash_checks > mismatches_at[1] + 20, "{why}");
        let t = a.confirmed_tick().min(b.confirmed_tick());
        assert!(t > 3900, "both confirmed to the last report: {t}");
        assert_eq!(a.hash_at(t), b.hash_at(t));
        assert_eq!(
            ca.first().state,
            cb.first().state,
            "the copies are the same bits"
        );
        // Who adopted decides where the disk is: with site 0's state it was never swept.
        let swept = ca.first().state.pos.x < -1e-3;
        assert_eq!(swept, adopter == 0, "{:?}", ca.first().state.pos);
    }
}

/// Two sites whose tools rest right of the disk for 500 ticks, reporting every 20 ticks with
/// `delay` ticks of delay, nothing lost.
fn two_sites_at_rest(delay: i64) -> [(TimeWarp, WorldCopy); 2] {
    two_sites(
        600,
        |_, _| {},
        500,
        |_, _| Vec3::new(0.2, 0.0, 0.01),
        delay,
        |_, _| false,
        |_, _, _, _| {},
    )
}

/// The state asked for is lost on its way: the asked site sends it again a round trip (50 ticks
/// each way) and the slack later, while still asked, and the asker adopts that one.
#[test]
fn a_lost_state_is_sent_again_a_round_trip_later() {
    let first_state = std::cell::Cell::new(-1i64);
    let mut sent_at = Vec::new();
    // Site 1 → site 0 is down for 1.2 s, twice the history: site 0 misses part of site 1's
    // sweep, and site 1 (the later) asks site 0 for its state.
    let sites = two_sites(
        600,
        |_, _| {},
        4000,
        sweep_into_the_disk,
        50,
        |from, k| (from == 1 && (1000..2200).contains(&k)) || (from == 0 && k == first_state.get()),
        |i, t, k, _| {
            if i == 0 && t.state.is_some() {
                sent_at.push(k);
                if first_state.get() < 0 {
                    first_state.set(k);
                }
            }
        },
    );
    let [(a, ca), (b, cb)] = &sites;
    let st = [a.rollback_stats(), b.rollback_stats()];
    let resend = 100 + (STATE_RESEND_SLACK_S / 1e-3) as i64;
    assert!(sent_at.len() >= 2, "sent again: {sent_at:?} {st:?}");
    assert!(sent_at[1] - sent_at[0] >= resend, "{sent_at:?}");
    assert!(
        sent_at[1] - sent_at[0] <= resend + 40,
        "a round trip later, at the next reports: {sent_at:?}"
    );
    assert!(st[1].adopted_states > 0, "{st:?}");
    let t = a.confirmed_tick().min(b.confirmed_tick());
    assert_eq!(a.hash_at(t), b.hash_at(t));
    assert_eq!(ca.first().state, cb.first().state);
}

/// A state that would put the disk deeper into the table than every user's force could is
/// not adopted (it would be released as kinetic energy); one at rest on it is.
#[test]
fn a_state_deep_in_the_table_is_not_adopted() {
    let (_, w) = paper_world();
    let mut sites = two_sites_at_rest(10);
    let [(a, _), (b, cb)] = &mut sites;
    b.set_max_spring_energy(0.05);
    let Report::Tools(mut r) = a.track_report() else {
        panic!("a track");
    };
    assert!(r.confirmed_tick > 400, "{}", r.confirmed_tick);
    let offer = |r: &mut ToolReport, z: f64| {
        let state = BodyState::at_rest(Vec3::new(0.001, 0.0, z));
        r.confirmed_hash = hash_state(&state);
        r.state = Some(Snapshot::one(
            r.confirmed_tick,
            r.confirmed_hash,
            state,
            EnvContactState::default(),
            [ToolContactState::default(); MAX_SITES],
        ));
    };
    // 5 cm into the table: ½ · 3000 N/m · (0.05 m)² ≈ 3.75 J of spring.
    offer(&mut r, 0.01 - 0.05);
    b.receive(&w, cb, 0, &Report::Tools(r), 0.5);
    assert_eq!(
        b.rollback_stats().adopted_states,
        0,
        "{:?}",
        b.rollback_stats()
    );
    assert!(b.rollback_stats().hash_mismatches > 0);
    offer(&mut r, 0.01);
    b.receive(&w, cb, 0, &Report::Tools(r), 0.5);
    assert_eq!(
        b.rollback_stats().adopted_states,
        1,
        "{:?}",
        b.rollback_stats()
    );
    assert_eq!(b.hash_at(r.confirmed_tick), Some(r.confirmed_hash));
}

/// A state asked for that arrives before the asker has confirmed its tick (the sender's
/// frontier runs ahead of the asker's: it knew its own positions first) is kept, and adopted
/// when the inputs that confirm its tick arrive, without being sent again.
#[test]
fn a_state_ahead_of_the_askers_frontier_is_adopted_once_confirmed() {
    let (_, w) = paper_world();
    let mut sites = two_sites_at_rest(100);
    let [(a, _), (b, cb)] = &mut sites;
    // Site 0's positions to now, still on their way (100 ticks late).
    let Report::Tools(track) = a.track_report() else {
        panic!("a track");
    };
    // Site 0's state at site 1's frontier hashes differently: site 1 asks it for its state.
    let mut differs = track;
    differs.count = 0;
    differs.first_tick = b.confirmed_tick();
    differs.confirmed_tick = b.confirmed_tick();
    differs.confirmed_hash = b.hash_at(b.confirmed_tick()).unwrap() ^ 1;
    b.receive(&w, cb, 0, &Report::Tools(differs), 0.5);
    assert!(b.rollback_stats().hash_mismatches > 0);
    assert!(b.want_state[0], "site 1 asks site 0");
    // The state comes at a tick site 1 has simulated but not confirmed (site 0's positions of
    // the last ticks are still on their way): kept, not adopted.
    let t = b.confirmed_tick() + 5;
    assert!(t < b.now_tick, "{t}");
    let state = BodyState::at_rest(Vec3::new(0.001, 0.0, 0.01));
    let mut with_state = track;
    with_state.first_tick = t;
    with_state.count = 0;
    with_state.confirmed_tick = t;
    with_state.confirmed_hash = hash_state(&state);
    with_state.state = Some(Snapshot::one(
        t,
        with_state.confirmed_hash,
        state,
        EnvContactState::default(),
        [ToolContactState::default(); MAX_SITES],
    ));
    b.receive(&w, cb, 0, &Report::Tools(with_state), 0.5);
    assert_eq!(b.rollback_stats().adopted_states, 0, "not yet confirmed");
    // Site 0's positions up to now arrive (no state with them): site 1 confirms the tick and
    // adopts the state it kept.
    let mut positions = track;
    positions.confirmed_hash = 0;
    b.receive(&w, cb, 0, &Report::Tools(positions), 0.5);
    assert!(b.confirmed_tick() > t, "{}", b.confirmed_tick());
    assert_eq!(
        b.rollback_stats().adopted_states,
        1,
        "{:?}",
        b.rollback_stats()
    );
    assert_eq!(b.hash_at(t), Some(hash_state(&state)));
    assert!(!b.want_state[0], "no longer asks");
}

#[test]
fn positions_quantize_to_the_hundredth_of_a_millimetre() {
    assert_eq!(
        quantize(Vec3::new(0.012_345_6, -0.5, 0.0)),
        [1235, -50_000, 0]
    );
    let p = position([1235, -50_000, 0]);
    assert!((p - Vec3::new(0.01235, -0.5, 0.0)).norm() < 1e-15, "{p:?}");
    assert_eq!(
        quantize(p),
        [1235, -50_000, 0],
        "a quantized position quantizes to itself"
    );
}

/// Three sites, a world of four pucks in a row on the table, touching: each site's tool pushes
/// the row from its own side at its own time, and its positions reach the others late, one of
/// them at the edge of the history (a rollback there restores the oldest state kept). A forced
/// rollback on every tick (of every depth to 40 ticks, and to the history's edge every 50th)
/// arrives at the same bits, and once every position is known the three sites' confirmed worlds
/// are the same bits: shipped rollback engines desynchronised only with three or more peers at
/// the window's edge.
#[test]
fn three_sites_and_several_objects_in_contact_agree_to_the_bit() {
    let (sc, w, states) = pucks_in_a_row(4, -0.06);
    let start = WorldCopy::new(&states);
    const HISTORY: usize = 300;
    // Site j's positions reach site i after DELAY[j][i] ticks: one pair at the history's edge.
    const DELAY: [[i64; 3]; 3] = [[0, 20, 45], [30, 0, 290], [285, 60, 0]];
    // Run with rollbacks that re-simulate only what a changed input reaches, and with whole
    // ones: every copy at every tick is the same bits.
    let end = 2000i64;
    // Site 0 pushes the row's left end (0.1–0.5 s), site 1 its right end (0.6–1.0 s), site 2
    // pokes the second puck from behind (0.3–0.7 s); all rest far away otherwise.
    let tool = |i: usize, t: f64| -> Vec3 {
        let ramp = |from: f64, to: f64| ((t - from) / (to - from)).clamp(0.0, 1.0);
        match i {
            0 => Vec3::new(-0.12 + 0.05 * ramp(0.1, 0.5), 0.0, 0.01),
            1 => Vec3::new(0.15 - 0.04 * ramp(0.6, 1.0), 0.0, 0.01),
            _ => Vec3::new(-0.02, -0.06 + 0.035 * ramp(0.3, 0.7), 0.01),
        }
    };
    let run = |islands: bool| {
        let grid = ThreeSites {
            contact: sc.contact,
            history: HISTORY,
            delay: DELAY,
            end,
            islands,
            synctest: &[0],
        };
        grid.replay(&w, &start, tool)
    };
    let (sites, seen) = run(true);
    let (_, whole) = run(false);
    for (k, (a, b)) in seen.iter().zip(&whole).enumerate() {
        assert!(
            a == b,
            "tick {}, site {}: islands and whole rollbacks differ",
            k / 3,
            k % 3
        );
    }
    let moved: f64 = (0..4)
        .map(|o| (sites[0].1.objects()[o].state.pos - states[o].pos).norm())
        .fold(0.0, f64::max);
    assert!(moved > 0.01, "the tools moved the row: {moved} m");
    assert_confirmed_alike(&sites, end);
    for (i, (tw, _)) in sites.iter().enumerate() {
        let st = tw.rollback_stats();
        assert!(st.rollbacks > 10, "site {i} rolled back: {st:?}");
        assert!(st.hash_checks > 0, "site {i} compared hashes: {st:?}");
        assert_eq!(st.hash_mismatches, 0, "site {i}: {st:?}");
    }
    let deepest = sites
        .iter()
        .map(|(tw, _)| tw.rollback_stats().max_depth)
        .max();
    assert!(deepest >= Some(280), "rolled back to the edge: {deepest:?}");
}

/// Three sites of [`TimeWarp`] on one 1 kHz grid: each steps its own tool and reports it every
/// 10 ticks, site `j`'s reports reaching site `i` `delay[j][i]` ticks later; the sites in
/// `synctest` force a rollback every tick (of every depth to 40 ticks, and to the history's edge
/// every 50th) and must arrive at the same bits.
struct ThreeSites<'a> {
    contact: crate::contact::ContactParams,
    history: usize,
    delay: [[i64; 3]; 3],
    end: i64,
    islands: bool,
    synctest: &'a [usize],
}

impl ThreeSites<'_> {
    /// Runs the grid from `start` with site `i`'s tool at `tool(i, t)`: the sites at the end, and
    /// every site's copy at every tick.
    fn replay(
        &self,
        w: &World,
        start: &WorldCopy,
        mut tool: impl FnMut(usize, f64) -> Vec3,
    ) -> (Vec<(TimeWarp, WorldCopy)>, Vec<WorldCopy>) {
        let mut radii = [0.0; MAX_SITES];
        radii[..3].fill(0.005);
        let mut sites: Vec<(TimeWarp, WorldCopy)> = (0..3)
            .map(|i| {
                let mut tw = TimeWarp::new(i, 3, 1e-3, self.contact, radii, self.history, start);
                tw.set_islands(self.islands);
                (tw, start.clone())
            })
            .collect();
        let mut seen = Vec::new();
        let mut in_flight: Vec<(i64, usize, usize, Report)> = Vec::new();
        for k in 0..self.end {
            let t = k as f64 * 1e-3;
            let due: Vec<_> = in_flight.iter().filter(|m| m.0 <= k).cloned().collect();
            in_flight.retain(|m| m.0 > k);
            for (_, from, to, r) in due {
                let (tw, copy) = &mut sites[to];
                tw.receive(w, copy, from, &r, t);
            }
            for (i, (tw, copy)) in sites.iter_mut().enumerate() {
                tw.own_tool(tool(i, t));
                tw.physics_step(w, copy, &[ContactForce::default(); 4], 1e-3);
                if self.synctest.contains(&i) {
                    let depth = if k % 50 == 49 {
                        (self.history as i64 - 1).min(k)
                    } else {
                        1 + k % 40
                    };
                    assert!(
                        tw.synctest(w, copy, depth),
                        "site {i}, tick {k}, depth {depth}"
                    );
                }
                if k % 10 == 9 {
                    let r = tw.track_report();
                    for to in (0..3).filter(|&to| to != i) {
                        in_flight.push((k + self.delay[i][to], i, to, r));
                    }
                }
                seen.push(copy.clone());
            }
        }
        (sites, seen)
    }
}

/// Once every position is known (confirmed to within 400 ticks of `end`), the sites' confirmed
/// worlds are the same bits.
fn assert_confirmed_alike(sites: &[(TimeWarp, WorldCopy)], end: i64) {
    let confirmed = sites
        .iter()
        .map(|(tw, _)| tw.confirmed_tick())
        .min()
        .unwrap();
    assert!(confirmed > end - 400, "confirmed up to tick {confirmed}");
    let hashes: Vec<_> = sites
        .iter()
        .map(|(tw, _)| tw.hash_at(confirmed - 1))
        .collect();
    assert!(hashes[0].is_some(), "tick {confirmed} is kept");
    assert!(
        hashes.iter().all(|h| *h == hashes[0]),
        "the confirmed worlds differ: {hashes:?}"
    );
}

/// `n` pucks (radius 2 cm, 0.1 kg) in a row along x on [`paper_world`]'s table, 0.1 mm apart,
/// the first at `first_x`: its scenario (the contact laws), the world and the pucks' start.
fn pucks_in_a_row(n: usize, first_x: f64) -> (Scenario, World, Vec<BodyState>) {
    use crate::contact::Plane;
    use crate::shape::Shape;
    use crate::world::Body;
    let (sc, _) = paper_world();
    let puck = Body::solid(
        Shape::Cylinder {
            radius: 0.02,
            half_height: 0.01,
        },
        0.1,
    );
    let table = [Plane {
        normal: Vec3::z(),
        offset: 0.0,
    }];
    let w = World::new(
        &vec![puck; n],
        Vec3::new(0.0, 0.0, -3.27),
        &table,
        sc.environment_contact,
    );
    let states = (0..n)
        .map(|k| BodyState::at_rest(Vec3::new(first_x + 0.0401 * k as f64, 0.0, 0.01)))
        .collect();
    (sc, w, states)
}

/// Site `i`'s tool at tick `k` over [`pucks_in_a_row`]`(3, -0.04)`: site 1's pushes the row's
/// right end from 0.9 s to 1.3 s and draws back; the others rest far away.
fn push_the_row(i: usize, k: i64) -> Vec3 {
    let s = k as f64 * 1e-3;
    match (i, s) {
        (0, _) => Vec3::new(-0.15, 0.0, 0.01),
        (1, s) if s < 0.9 => Vec3::new(0.12, 0.0, 0.01),
        (1, s) if s < 1.3 => Vec3::new(0.12 - 0.15 * (s - 0.9), 0.0, 0.01),
        (1, s) => Vec3::new((0.06 + 0.15 * (s - 1.3)).min(0.12), 0.0, 0.01),
        _ => Vec3::new(0.0, -0.15, 0.01),
    }
}

/// A world of several objects resynchronises as a world of one does: site 1's tool pushes a row
/// of pucks while its reports to site 0 are lost for longer than the history (a fallback), so
/// the confirmed worlds differ; site 1 asks site 0 (the lower number) for its state, which comes
/// one object per report, all sent at once at one tick, and adopts it once all of it is in.
/// From then on the two agree to the bit, every object, its sleep and its contacts.
#[test]
fn a_world_of_several_objects_is_resynchronized_object_by_object() {
    let (sc, w, states) = pucks_in_a_row(3, -0.04);
    let start = WorldCopy::new(&states);
    let mut radii = [0.0; MAX_SITES];
    radii[..2].fill(0.005);
    let mut sites = [0, 1].map(|i| {
        (
            TimeWarp::new(i, 2, 1e-3, sc.contact, radii, 600, &start),
            start.clone(),
        )
    });
    // Site 1 → site 0 is down for 1.2 s, twice the history, while site 1 pushes the row.
    let tool = push_the_row;
    let lost = |from: usize, k: i64| from == 1 && (1000..2200).contains(&k);
    let mut in_flight: Vec<(i64, usize, Report)> = Vec::new();
    let mut carried = [false; 3];
    let mut mismatches_at = [0u64; 2];
    for k in 0..5000i64 {
        for (i, (tw, copy)) in sites.iter_mut().enumerate() {
            for (_, from, r) in in_flight.iter().filter(|m| m.0 == k && m.1 != i) {
                tw.receive(&w, copy, *from, r, k as f64 * 1e-3);
            }
            tw.own_tool(tool(i, k));
            tw.physics_step(&w, copy, &[ContactForce::default(); 3], 1e-3);
        }
        in_flight.retain(|m| m.0 > k);
        if k == 4000 {
            mismatches_at = [0, 1].map(|i| sites[i].0.rollback_stats().hash_mismatches);
        }
        if k % 20 == 0 {
            for (i, (tw, copy)) in sites.iter().enumerate() {
                let mut out = Vec::new();
                tw.report(copy, &[], k as f64 * 1e-3, &mut |r| out.push(r));
                for r in out {
                    if let Report::Tools(t) = &r {
                        if let Some(s) = t.state {
                            assert_eq!((i, s.objects), (0, 3), "only site 0 sends its state");
                            carried[s.object] = true;
                        }
                    }
                    if !lost(i, k) {
                        in_flight.push((k + 50, i, r));
                    }
                }
            }
        }
    }
    let [(a, ca), (b, cb)] = &sites;
    let st = [a.rollback_stats(), b.rollback_stats()];
    assert!(st[0].fallbacks > 0, "site 0 lost part of the push: {st:?}");
    assert!(
        st[0].hash_mismatches + st[1].hash_mismatches > 0,
        "the divergence was seen: {st:?}"
    );
    assert_eq!(carried, [true; 3], "every object went");
    assert!(st[1].adopted_states > 0, "{st:?}");
    assert_eq!(st[0].adopted_states, 0, "{st:?}");
    assert_eq!(
        [st[0].hash_mismatches, st[1].hash_mismatches],
        mismatches_at,
        "no mismatch in the last second: {st:?}"
    );
    let t = a.confirmed_tick().min(b.confirmed_tick());
    assert!(t > 4900, "both confirmed to the last report: {t}");
    assert_eq!(a.hash_at(t), b.hash_at(t));
    // (Their energy accounts differ: one adopted.)
    assert!(
        ca.pairs() == cb.pairs()
            && ca.still() == cb.still()
            && ca
                .objects()
                .iter()
                .zip(cb.objects())
                .all(|(x, y)| x.state == y.state && x.env == y.env),
        "the copies are the same bits, every object"
    );
    // With site 0's state the row was never pushed.
    let moved = (0..3)
        .map(|o| (ca.objects()[o].state.pos - states[o].pos).norm())
        .fold(0.0, f64::max);
    assert!(moved < 1e-3, "site 0's history kept: moved {moved} m");
}

/// Site 2 differs from both sites before it (site 1's push of the row never reached it: both
/// links to it were down): it asks both, and their worlds reach it only together and
/// interleaved, object by object (site 0's first, site 1's first, site 0's second, ...; a state
/// that would arrive alone waits for the other's). The gathering from site 0, the first in the sites' order, is
/// not broken off by site 1's, and site 2 adopts it; then all three agree.
#[test]
fn a_state_asked_of_two_earlier_sites_is_gathered_from_the_first() {
    let (sc, w, states) = pucks_in_a_row(3, -0.04);
    let start = WorldCopy::new(&states);
    let mut radii = [0.0; MAX_SITES];
    radii[..3].fill(0.005);
    let mut sites: Vec<(TimeWarp, WorldCopy)> = (0..3)
        .map(|i| {
            (
                TimeWarp::new(i, 3, 1e-3, sc.contact, radii, 600, &start),
                start.clone(),
            )
        })
        .collect();
    // Both links to site 2 are down for 1.2 s, twice the history, while site 1 pushes the row
    // (so both earlier sites hear it differ, and send, at the same reports).
    let tool = push_the_row;
    let lost = |_: usize, to: usize, k: i64| to == 2 && (1000..2200).contains(&k);
    // (due tick, from, to, place in its sender's burst, report)
    let mut in_flight: Vec<(i64, usize, usize, usize, Report)> = Vec::new();
    let mut waiting = Vec::new();
    let mut interleaved = 0;
    // The site each state site 2 adopted came from.
    let mut adopted_from = Vec::new();
    for k in 0..5000i64 {
        let t = k as f64 * 1e-3;
        let mut due: Vec<_> = in_flight.iter().filter(|m| m.0 == k).cloned().collect();
        in_flight.retain(|m| m.0 > k);
        // Each burst's first report, then each one's second, and so on.
        due.sort_by_key(|m| (m.3, m.1));
        // A state that would reach site 2 alone waits for the other site's: the two arrive
        // together. (Each site sends its state once a round trip while asked, and the two need
        // not send at the same reports.)
        let carries = |m: &(i64, usize, usize, usize, Report)| {
            m.2 == 2 && matches!(&m.4, Report::Tools(r) if r.state.is_some())
        };
        waiting.extend(due.iter().filter(|m| carries(m)).cloned());
        due.retain(|m| !carries(m));
        let states_from = |from: usize| waiting.iter().filter(|m| m.1 == from).count();
        if states_from(0) > 1 && states_from(1) > 1 {
            interleaved += 1;
            due.append(&mut waiting);
            due.sort_by_key(|m| (m.3, m.1));
        }
        for (_, from, to, _, r) in due {
            let (tw, copy) = &mut sites[to];
            let before = tw.rollback_stats().adopted_states;
            tw.receive(&w, copy, from, &r, t);
            if to == 2 && tw.rollback_stats().adopted_states > before {
                adopted_from.push(tw.incoming_from.1);
            }
        }
        for (i, (tw, copy)) in sites.iter_mut().enumerate() {
            tw.own_tool(tool(i, k));
            tw.physics_step(&w, copy, &[ContactForce::default(); 3], 1e-3);
        }
        if k % 20 == 0 {
            for (i, (tw, copy)) in sites.iter().enumerate() {
                let mut out = Vec::new();
                tw.report(copy, &[], t, &mut |r| out.push(r));
                for (m, r) in out.into_iter().enumerate() {
                    for to in (0..3).filter(|&to| to != i && !lost(i, to, k)) {
                        in_flight.push((k + 50, i, to, m, r));
                    }
                }
            }
        }
    }
    let st: Vec<RollbackStats> = sites.iter().map(|(tw, _)| tw.rollback_stats()).collect();
    assert!(st[2].fallbacks > 0, "site 2 lost part of the push: {st:?}");
    assert!(
        interleaved > 0,
        "both earlier sites' worlds reached site 2 interleaved"
    );
    assert!(st[2].adopted_states > 0, "{st:?}");
    assert!(
        !adopted_from.is_empty() && adopted_from.iter().all(|&i| i == 0),
        "site 2 adopted site 0's states only: from {adopted_from:?}"
    );
    assert_eq!(st[0].adopted_states + st[1].adopted_states, 0, "{st:?}");
    let t = sites
        .iter()
        .map(|(tw, _)| tw.confirmed_tick())
        .min()
        .unwrap();
    assert!(t > 4900, "all confirmed to the last report: {t}");
    let hashes: Vec<_> = sites.iter().map(|(tw, _)| tw.hash_at(t)).collect();
    assert!(
        hashes.iter().all(|h| h.is_some() && *h == hashes[0]),
        "{hashes:?}"
    );
}

/// `scenarios/tray.toml`'s world and users (two users carry a tray with a cup on it), its
/// timewarp as a station builds it; the tools where the users' scripts put them.
fn tray() -> Scenario {
    use crate::scenario::{KeyframeSpec, ObjectSpec, PlaneSpec, ShapeName, SiteSpec};
    let law = |k: f64, d: f64, kt: f64, dt: f64, mu: (f64, f64), r: f64| ContactParams {
        stiffness_n_per_m: k,
        damping_n_s_per_m: d,
        tangential_stiffness_n_per_m: kt,
        tangential_damping_n_s_per_m: dt,
        friction_static: mu.0,
        friction_kinetic: mu.1,
        rotational_friction_radius_m: r,
    };
    let mut sc = Scenario {
        objects: vec![
            ObjectSpec {
                name: "tray".into(),
                shape: ShapeName::Box,
                half_extents_m: [0.03, 0.05, 0.01],
                mass_kg: 0.25,
                start_m: [0.0, 0.0, 0.01],
                ..Default::default()
            },
            ObjectSpec {
                name: "cup".into(),
                shape: ShapeName::Cylinder,
                radius_m: 0.015,
                half_height_m: 0.01,
                mass_kg: 0.06,
                start_m: [0.0, 0.0, 0.0299],
                ..Default::default()
            },
        ],
        contact: law(800.0, 3.0, 800.0, 3.0, (0.9, 0.7), 0.005),
        environment_contact: law(3000.0, 30.0, 3000.0, 15.0, (0.35, 0.3), 0.02),
        object_contact: Some(law(1000.0, 10.0, 1000.0, 5.0, (0.5, 0.4), 0.01)),
        ..Default::default()
    };
    sc.world.gravity_m_per_s2 = [0.0, 0.0, -3.27];
    sc.world.planes = vec![PlaneSpec {
        normal: [0.0, 0.0, 1.0],
        offset_m: 0.0,
    }];
    sc.network.delay_min_ms = 20.0;
    sc.network.delay_max_ms = 200.0;
    sc.network.jitter_ms = 10.0;
    // x of the approach, the grasp and the squeeze, right of the tray (user 1's mirrored).
    let keys = |s: f64| {
        let (far, grasp, squeeze) = (0.15 * s, 0.030 * s, 0.017 * s);
        [
            (0.0, [far, 0.0, 0.010]),
            (0.5, [far, 0.0, 0.010]),
            (1.5, [grasp, 0.0, 0.010]),
            (3.0, [grasp, 0.0, 0.010]),
            (4.0, [squeeze, 0.0, 0.010]),
            (5.0, [squeeze, 0.0, 0.010]),
            (7.0, [squeeze, 0.0, 0.038]),
            (7.5, [squeeze, 0.0, 0.038]),
            (10.5, [squeeze, 0.10, 0.038]),
            (11.0, [squeeze, 0.10, 0.038]),
            (12.0, [squeeze, 0.10, 0.010]),
            (12.5, [squeeze, 0.10, 0.010]),
            (13.2, [far, 0.10, 0.010]),
        ]
    };
    for (name, x, rate) in [("user1", -1.0, 90.0), ("user2", 1.0, 20.0)] {
        sc.site.push(SiteSpec {
            name: name.into(),
            report_rate_hz: rate,
            physics_rate_hz: 1000.0,
            tool_radius_m: 0.005,
            script: keys(x)
                .iter()
                .map(|&(t_s, target_m)| KeyframeSpec { t_s, target_m })
                .collect(),
            ..Default::default()
        });
    }
    sc
}

/// Two [`tray`] sites linked as stations through a router: site 0 reports at 90 Hz, site 1 at
/// 20 Hz, each track arriving 1 to 3 ticks later (in order), and a site silent for longer than a
/// station's limit is lost (`peer_lost`) until heard again.
#[derive(Clone)]
struct TrayLink {
    world: World,
    scripts: [Vec<crate::user::Keyframe>; 2],
    sites: [(TimeWarp, WorldCopy); 2],
    /// (due tick, from, report)
    in_flight: Vec<(i64, usize, Report)>,
    heard: [i64; 2],
    lost: [bool; 2],
    seqs: [u64; 2],
    next_report: [f64; 2],
    /// Per sender: the newest due tick (tracks arrive in order, as TCP has them).
    last_due: [i64; 2],
    rng: crate::rng::Rng,
    k: i64,
}

impl TrayLink {
    fn new(seed: u64) -> Self {
        let sc = tray();
        let start = sc.start_copy();
        let scripts = [0, 1].map(|i| {
            sc.site[i]
                .script
                .iter()
                .map(|k| crate::user::Keyframe {
                    t_s: k.t_s,
                    target: Vec3::from(k.target_m),
                })
                .collect()
        });
        Self {
            world: sc.world(),
            scripts,
            sites: [0, 1].map(|i| (sc.timewarp(i, &start), start.clone())),
            in_flight: Vec::new(),
            heard: [0; 2],
            lost: [false; 2],
            seqs: [0; 2],
            next_report: [0.0; 2],
            last_due: [0; 2],
            rng: crate::rng::Rng::new(seed),
            k: 0,
        }
    }

    /// Steps both sites to tick `to`; the link is down from `down.0` to `down.1`, when what
    /// TCP held arrives at once: of the tracks sent while it was down, those at most 460 ms old
    /// then (a station's age limit), each with the chance `kept` (the rest dropped by zenoh's
    /// full queue).
    fn run(&mut self, to: i64, down: (i64, i64), kept: f64) {
        const SILENCE: [i64; 2] = [250, 500];
        const PERIOD: [f64; 2] = [1000.0 / 90.0, 50.0];
        while self.k < to {
            let k = self.k;
            for i in 0..2 {
                let (tw, copy) = &mut self.sites[i];
                let mut any = false;
                for (_, from, r) in self.in_flight.iter().filter(|m| m.0 <= k && m.1 != i) {
                    tw.receive(&self.world, copy, *from, r, k as f64 * 1e-3);
                    any = true;
                }
                self.in_flight.retain(|m| m.0 > k || m.1 == i);
                if any {
                    (self.heard[i], self.lost[i]) = (k, false);
                } else if !self.lost[i] && k - self.heard[i] > SILENCE[1 - i] {
                    tw.peer_lost(1 - i, k as f64 * 1e-3);
                    self.lost[i] = true;
                }
                let (p, _) = crate::user::target_at(&self.scripts[i], k as f64 * 1e-3);
                tw.own_tool(p);
                tw.physics_step(&self.world, copy, &[ContactForce::default(); 2], 1e-3);
                if (k as f64) < self.next_report[i] {
                    continue;
                }
                self.next_report[i] = self.next_report[i].max(k as f64 - PERIOD[i]) + PERIOD[i];
                let mut out = Vec::new();
                tw.report(copy, &[], k as f64 * 1e-3, &mut |r| out.push(r));
                for mut r in out {
                    if let Report::Tools(t) = &mut r {
                        self.seqs[i] += 1;
                        t.seq = self.seqs[i];
                    }
                    let late = 1 + (self.rng.uniform() * 3.0) as i64;
                    let at = if !(down.0..down.1).contains(&k) {
                        k + late
                    } else if down.1 - k <= 460 && self.rng.uniform() < kept {
                        down.1
                    } else {
                        continue;
                    };
                    self.last_due[i] = at.max(self.last_due[i]);
                    self.in_flight.push((self.last_due[i], i, r));
                }
            }
            self.k += 1;
        }
    }

    fn stats(&self) -> [RollbackStats; 2] {
        [0, 1].map(|i| self.sites[i].0.rollback_stats())
    }
}

/// `scenarios/tray.toml` through a router, station A's link down for 2.29 s during the carry
/// (longer than the history: the confirmed worlds differ) and the tracks TCP held delivered when
/// it is back, some of them. Site 1 adopts site 0's world soon after, while its gaps are still
/// being repaired: site 0's repairs then named a frontier (the repair window's end) older than
/// the adopted tick, and site 1 compared it with the history the adoption replaced: mismatches
/// after the heal (and the state asked for again), which `tools/tests/router.rs` counted as a
/// world that had not healed when its baseline was read after that adoption. From an adoption on
/// no mismatch is counted, and the comparisons go on at both sites.
#[test]
fn after_a_partition_the_adopted_world_has_no_mismatch_since() {
    let mut base = TrayLink::new(1);
    base.run(8000, (0, 0), 1.0);
    for m in 0..12 {
        let down = 8000 + 23 * m;
        let up = down + 2290 + 50;
        let mut net = base.clone();
        net.rng = crate::rng::Rng::derive(1, m as u64);
        net.run(up, (down, up), 0.5);
        let mut adopted = None;
        while net.k < 14_000 {
            net.run(net.k + 1, (0, 0), 1.0);
            let st = net.stats();
            if adopted.is_none() && st[1].adopted_states > 0 {
                adopted = Some(st);
            }
        }
        let st = net.stats();
        let why = format!("down from {down}: {:?} {:?}", st[0], st[1]);
        let Some(at) = adopted else {
            panic!("site 1 adopted site 0's world: {why}");
        };
        assert!(st[0].fallbacks > 0, "{why}");
        assert_eq!(st[0].adopted_states, 0, "{why}");
        assert_eq!(
            [st[0].hash_mismatches, st[1].hash_mismatches],
            [at[0].hash_mismatches, at[1].hash_mismatches],
            "no mismatch since the adoption: {why}"
        );
        for i in 0..2 {
            assert!(st[i].hash_checks > at[i].hash_checks + 20, "{why}");
        }
    }
}

/// Three simulated participants, each acting on what its own site shows under 40–120 ms: one
/// pushes the disk from the left, one from below, one waits and stops it on the right. Their
/// tools' paths, as the simulator ran them, drive three sites' rollbacks on a common grid with
/// late reports and a forced rollback of every depth on every tick at every site (the synctest):
/// each arrives at the same bits, and the three confirmed worlds agree once every position is
/// known. People's paths (reaction, motor noise, tremor, replanning) exercise the rollback where
/// scripts did not.
#[test]
fn three_participants_pass_the_synctest_and_agree_to_the_bit() {
    use crate::participant::{Action, StepSpec};
    use crate::scenario::{KeyframeSpec, MethodName, SiteSpec};
    use crate::sim::{Direct, Mode};
    let (mut sc, w) = paper_world();
    sc.duration_s = 4.0;
    sc.network.delay_min_ms = 40.0;
    sc.network.delay_max_ms = 120.0;
    sc.network.jitter_ms = 5.0;
    let face = |action, side: [f64; 3], f: fn(StepSpec) -> StepSpec| {
        f(StepSpec {
            action,
            object: Some("object".into()),
            side: Some(side),
            ..StepSpec::default()
        })
    };
    let pusher = |side: [f64; 3]| {
        vec![
            StepSpec {
                action: Action::Wait,
                for_s: 0.3,
                ..StepSpec::default()
            },
            face(Action::Reach, side, |s| StepSpec { gap_m: 0.02, ..s }),
            face(Action::Push, side, |s| StepSpec { depth_m: 0.02, ..s }),
            face(Action::Release, side, |s| StepSpec {
                object: None,
                away_m: 0.04,
                ..s
            }),
        ]
    };
    let catcher = vec![face(Action::Reach, [1.0, 0.0, 0.0], |s| StepSpec {
        gap_m: 0.015,
        ..s
    })];
    for (name, base, start, plan) in [
        (
            "user1",
            [-0.3, -0.2, 0.0],
            [-0.15, 0.0, 0.01],
            pusher([-1.0, 0.0, 0.0]),
        ),
        ("user2", [0.3, -0.2, 0.0], [0.15, 0.0, 0.01], catcher),
        (
            "user3",
            [0.0, -0.45, 0.0],
            [0.0, -0.15, 0.01],
            pusher([0.0, -1.0, 0.0]),
        ),
    ] {
        sc.site.push(SiteSpec {
            name: name.into(),
            device_base_m: base,
            report_rate_hz: 100.0,
            script: vec![KeyframeSpec {
                t_s: 0.0,
                target_m: start,
            }],
            plan,
            ..SiteSpec::default()
        });
    }
    sc.validate().expect("valid scenario");
    let ran = crate::sim::run_keeping_servo_ticks(
        &sc,
        Mode::Distributed(MethodName::Timewarp),
        &mut |_| {},
        &Direct,
    );
    for (i, t) in ran.tasks.iter().enumerate() {
        let (step, of) = t.steps.expect("a participant");
        assert!(
            step >= of.min(2),
            "site {i} reached the disk: step {step} of {of}"
        );
    }
    // Each site's tool at grid tick k: its newest servo tick at or before it.
    let ticks = &ran.servo_ticks;
    let mut next = [0usize; 3];
    let mut tool = |i: usize, t: f64| {
        while next[i] + 1 < ticks[i].len() && ticks[i][next[i] + 1].t_s <= t {
            next[i] += 1;
        }
        ticks[i][next[i]].tool_pos
    };
    let start = WorldCopy::one(BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)));
    let end = (sc.duration_s * 1e3) as i64;
    let grid = ThreeSites {
        contact: sc.contact,
        history: 300,
        delay: [[0, 45, 110], [60, 0, 290], [285, 80, 0]],
        end,
        islands: true,
        synctest: &[0, 1, 2],
    };
    let (sites, _) = grid.replay(&w, &start, &mut tool);
    let moved = (sites[0].1.objects()[0].state.pos - start.objects()[0].state.pos).norm();
    assert!(moved > 0.01, "the participants moved the disk: {moved} m");
    assert_confirmed_alike(&sites, end);
    for (i, (tw, _)) in sites.iter().enumerate() {
        let st = tw.rollback_stats();
        assert_eq!(st.hash_mismatches, 0, "site {i}: {st:?}");
    }
}
