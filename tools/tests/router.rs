//! Sessions across three network namespaces: a router (`station router`) in one, a station in
//! each of the two others, over mutual TLS with the certificates and the access control that
//! `session certs` makes from the scenario. The stations reach each other only through the router
//! (each namespace has a link to the router's, none between them, and nothing forwards). In the
//! first test an impostor holding user2's certificate, and a client holding none, try their luck;
//! in another the router is stopped and started again under the running session; in the third
//! `session run --attach` drives the two stations, started by hand, one of them in a time
//! namespace 1000 s ahead. The tests take turns (each runs real stations in real time on a
//! two-core machine), create and remove their namespaces and links, bound every wait, and are
//! skipped with a message where `ip netns` (or a time namespace) is not permitted.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::Duration;

use coop_actors::station::config::StartMode;
use coop_actors::station::status::StationStatus;
use coop_model::scenario::MethodName;
use coop_tests::forgery::{self, FORGED_SEQ};
use coop_tests::{
    brief, ip, paper_with_scripts, shifted_clock, shm_entries, station_config,
    time_namespaces_work, wait_for, wait_until, Namespaces, Reaped, StationConfig,
};
use coop_transport::admit::{Bounds, Inbound};
use coop_transport::keys;
use coop_transport::network::{Mode, Tls};

static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

const STATION: &str = env!("CARGO_BIN_EXE_station");
const SESSION_BIN: &str = env!("CARGO_BIN_EXE_session");
const IMPOSTOR: &str = env!("CARGO_BIN_EXE_coop-impostor");
const LIMIT: Duration = Duration::from_secs(60);

/// `coopR<tag>` (192.0.2.1 towards A, 192.0.2.5 towards B), `coopA<tag>` (192.0.2.2),
/// `coopB<tag>` (192.0.2.6): two /30 links, no route between A and B.
fn setup(tag: &str) -> Result<Namespaces, String> {
    let ns = Namespaces {
        names: vec![
            format!("coopR{tag}"),
            format!("coopA{tag}"),
            format!("coopB{tag}"),
        ],
    };
    for n in &ns.names {
        ip(&["netns", "add", n])?;
        ip(&["-n", n, "link", "set", "lo", "up"])?;
    }
    let r = ns.names[0].as_str();
    for (side, n, r_addr, s_addr) in [
        ("a", ns.names[1].as_str(), "192.0.2.1/30", "192.0.2.2/30"),
        ("b", ns.names[2].as_str(), "192.0.2.5/30", "192.0.2.6/30"),
    ] {
        let (vr, vs) = (format!("cr{side}{tag}"), format!("cs{side}{tag}"));
        ip(&["link", "add", &vr, "type", "veth", "peer", "name", &vs])?;
        ip(&["link", "set", &vr, "netns", r])?;
        ip(&["link", "set", &vs, "netns", n])?;
        ip(&["-n", r, "addr", "add", r_addr, "dev", &vr])?;
        ip(&["-n", n, "addr", "add", s_addr, "dev", &vs])?;
        ip(&["-n", r, "link", "set", &vr, "up"])?;
        ip(&["-n", n, "link", "set", &vs, "up"])?;
    }
    Ok(ns)
}

fn in_ns(ns: &str, program: &str) -> Command {
    let mut c = Command::new("ip");
    c.args(["netns", "exec", ns, program]);
    c
}

#[test]
fn a_session_through_a_router_over_mutual_tls_refuses_impostors() {
    let _turn = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let pid = std::process::id();
    let tag = format!("{pid}r");
    let ns = match setup(&tag) {
        Ok(ns) => ns,
        Err(why) => {
            eprintln!("SKIPPED a_session_through_a_router_over_mutual_tls_refuses_impostors: ip netns is not permitted here ({why})");
            return;
        }
    };
    let dir = std::env::temp_dir().join(format!("coop-router-{pid}"));
    std::fs::create_dir_all(&dir).expect("dir");
    let scenario = dir.join("press.toml");
    std::fs::write(&scenario, push_catch_and_press()).expect("scenario");
    let sc = coop_actors::scenario_file::load(&scenario).expect("scenario");
    let session = format!("nr{pid}");
    let certs = certs(&dir, &session);
    let pem = |n: &str| certs.join(format!("{n}.pem"));
    let key = |n: &str| certs.join(format!("{n}.key"));
    let status_file = dir.join("r1.json");
    let (mut router, resolved) = router(&ns.names[0], &dir, &certs);

    let (a, b) = through_router(&dir, &session, &certs, &scenario, &dir, |_| {});
    let mut sa = start_station(&ns.names[1], &a);
    let mut sb = start_station(&ns.names[2], &b);
    let sites = ["user1".to_owned(), "user2".to_owned()];
    let status = |me: &str| coop_actors::station::status::read(&session, me, &sites).ok();
    // The paper session runs through the router: each receives the other's states and adopts them.
    both_receiving_and_adopting(&session, &resolved, "through the router", None);
    let before = |s: &coop_actors::station::status::StationStatus| s.network.refused.clone();
    let (ra0, rb0) = (
        before(&status("user1").expect("a")),
        before(&status("user2").expect("b")),
    );
    assert!(
        ra0.values().chain(rb0.values()).all(|&n| n == 0),
        "a clean start through the router refuses nothing: {ra0:?} {rb0:?}"
    );

    // What the impostors say a site's object is: the disk 0.10 m towards the users from where it
    // starts (inside the world, where the scripts never take it).
    let index = |site: &str| sc.site.iter().position(|s| s.name == site).expect("a site");
    let start_m = sc.objects[0].start_m;
    let forged_pos = [start_m[0], start_m[1] - 0.10, start_m[2]];
    let forged_arg = format!("{},{},{}", forged_pos[0], forged_pos[1], forged_pos[2]);

    // A client without a certificate does not get in (the TLS handshake fails).
    let nocert = in_ns(&ns.names[1], IMPOSTOR)
        .args(["tls/192.0.2.1:7447"])
        .arg(certs.join("ca.pem"))
        .args([
            "-",
            "-",
            &session,
            "user1",
            "user2",
            &index("user2").to_string(),
        ])
        .arg(&forged_arg)
        .output()
        .expect("no-cert client");
    let said = String::from_utf8_lossy(&nocert.stdout);
    assert_eq!(nocert.status.code(), Some(3), "refused at connect: {said}");
    assert!(said.starts_with("refused:"), "{said}");

    // An impostor holding user2's certificate speaks for user1: user1's clock and presence, and
    // states of user1 that user2's receive checks would take (`forgery`).
    let user1 = index("user1");
    let mut inbound = Inbound::new(sites.to_vec(), Bounds::from_scenario(&sc, None));
    let now = coop_rt::timer::monotonic_ns();
    let taken = inbound.check(
        "user1",
        0,
        &forgery::forged_state(user1, now, forged_pos),
        now,
        &[Some(0), Some(0)],
    );
    assert!(
        matches!(&taken, Ok(t) if t.report.seq == FORGED_SEQ && t.report.pos == forged_pos),
        "user2's receive checks would take the forgery (only the router keeps it out): {taken:?}"
    );
    let b_before = status("user2").expect("b");
    let impostor_from_ns = coop_rt::timer::monotonic_ns();
    let imp = in_ns(&ns.names[2], IMPOSTOR)
        .args(["tls/192.0.2.5:7447"])
        .arg(certs.join("ca.pem"))
        .arg(pem("user2"))
        .arg(key("user2"))
        .args([&session, "user2", "user1", &user1.to_string()])
        .arg(&forged_arg)
        .output()
        .expect("impostor");
    // The stations and this test share one CLOCK_MONOTONIC (no time namespace here).
    let impostor_to_ns = coop_rt::timer::monotonic_ns();
    let said = String::from_utf8_lossy(&imp.stdout);
    assert!(
        imp.status.success() && said.contains("connected") && said.contains("done"),
        "{said}"
    );
    let impostor_zid = said
        .split("connected ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .expect("the impostor's zenoh id")
        .to_owned();
    // Its puts on its own key reach user1 (refused there as garbage): its link worked.
    let a_after = wait_until(
        "user1 refusing the impostor's garbage on user2's key",
        LIMIT,
        || {
            let s = status("user1")?;
            (s.network.refused.get("length").copied().unwrap_or(0) > 0).then_some(s)
        },
    );
    // user1 was not silenced: user2 goes on receiving its states and adopting them.
    let b_mid = status("user2").expect("b");
    wait_for(
        "user2 receiving and adopting user1's states after the impostor",
        LIMIT,
        || {
            let s = status("user2").ok_or("no status")?;
            let (got, adopted) = (
                s.network.received.saturating_sub(b_mid.network.received),
                s.physics.adoptions.saturating_sub(b_mid.physics.adoptions),
            );
            if got > 10 && adopted > 0 {
                Ok(())
            } else {
                Err(format!(
                    "{got} received, {adopted} adopted since the impostor left"
                ))
            }
        },
    );
    // What it said for user1 never reached user2: user2 counts the impostor's garbage on its
    // own key (200 puts, each arriving at most once) as `length` refusals, and would count the
    // 200 on user1's key there too, and its forged states as user1's newest (no refusal, but
    // user1's next genuine ones `stale` until a resynchronisation). Nothing else is refused.
    let b_after = status("user2").expect("b");
    let b_len = b_after.network.refused.get("length").copied().unwrap_or(0);
    assert!(
        b_len <= 200
            && b_after
                .network
                .refused
                .iter()
                .all(|(r, &n)| *r == "length" || n == 0)
            && b_after.network.resyncs == 0,
        "nothing the impostor said for user1 reached user2: refused {:?}, {} resyncs",
        b_after.network.refused,
        b_after.network.resyncs
    );
    // user2's view of user1's clock stayed true (the impostor answers an hour ahead).
    // (Read once known: a station forgets a peer's clock when that peer's presence flickers and
    // measures it again within a few exchanges; what matters is that it never takes the hour.)
    let offset = wait_until("user2 knowing user1's clock offset", LIMIT, || {
        status("user2")?.network.peers[0].clock_offset_us
    });
    assert!(
        offset.abs() < 50_000.0,
        "user2's offset of user1's clock: {offset} µs"
    );
    assert!(!a_after.network.peers[1].lost && a_after.running);

    // The router refused each of the impostor's claims for user1, by kind and key, and refused
    // nothing else: every refusal it counted is one of these.
    let claims = [
        ("Put (ingress)", keys::state(&session, 0, "user1")),
        (
            "Declare Queryable (ingress)",
            keys::clock(&session, "user1"),
        ),
        (
            "Liveliness Token (ingress)",
            keys::presence(&session, "user1"),
        ),
    ];
    // A status taken once the impostor's session is gone holds all its refusals.
    let rs = wait_for("the router counting its refusals", LIMIT, || {
        let s = coop_actors::router::read_status(&resolved).map_err(|e| e.to_string())?;
        let refused = |(action, key): &(&str, String)| {
            s.recent_refusals
                .iter()
                .any(|r| r.zid == impostor_zid && r.action == *action && r.key == *key)
        };
        let gone = !s.sessions.iter().any(|l| l.zid == impostor_zid);
        if gone && claims.iter().all(refused) {
            Ok(s)
        } else {
            Err(format!("router status: {s}"))
        }
    });
    println!("{rs}");
    assert!(rs.access_control, "{rs}");
    let put = rs
        .recent_refusals
        .iter()
        .find(|r| r.action == claims[0].0 && r.key == claims[0].1)
        .expect("the puts' refusal");
    assert!(
        put.count <= 400,
        "at most the impostor's 200 forged states and 200 garbage puts on user1's key: {rs}"
    );
    assert!(
        rs.recent_refusals.len() == claims.len()
            && rs.recent_refusals.iter().all(|r| r.zid == impostor_zid)
            && rs.recent_refusals.iter().map(|r| r.count).sum::<u64>() == rs.refused,
        "the router refused the impostor's claims for user1 and nothing else: {rs}"
    );
    assert!(rs.sessions.len() >= 2, "both stations linked: {rs}");

    for s in [&sa, &sb] {
        terminate(s);
    }
    for s in [&mut sa, &mut sb] {
        let st = s.wait_timeout(LIMIT).expect("station stopped");
        assert!(st.success(), "a station stopped cleanly: {st}");
    }
    // user2's recording: no state of user1 it handed physics carried the forged sequence number
    // or the forged position; user1's genuine states went on being handed over, their sequence
    // continuing from before the impostor came, and adopted, after it left.
    let rec = coop_transport::recording::read(&dir.join("user2.mcap")).expect("recording");
    let from_user1: Vec<_> = rec.remote.iter().filter(|r| r.from == user1).collect();
    let forged: Vec<_> = from_user1
        .iter()
        .filter(|r| r.seq == FORGED_SEQ || distance(r.pos, forged_pos) < 0.05)
        .collect();
    assert!(
        forged.is_empty(),
        "user2 handed physics {} of the impostor's states for user1, first {:?}",
        forged.len(),
        forged.first()
    );
    let newest_before = from_user1
        .iter()
        .filter(|r| r.t_ns < impostor_from_ns)
        .map(|r| r.seq)
        .max()
        .expect("user2 received user1's states before the impostor came");
    let after: Vec<_> = from_user1
        .iter()
        .filter(|r| r.t_ns > impostor_to_ns)
        .collect();
    assert!(
        after.len() > 10 && after.iter().all(|r| r.seq > newest_before),
        "user1's states after the impostor: {} handed over, sequences {:?} (newest before it: {newest_before})",
        after.len(),
        after.iter().map(|r| r.seq).take(5).collect::<Vec<_>>()
    );
    assert!(
        rec.adoptions
            .iter()
            .any(|a| a.from == user1 && a.t_ns > impostor_to_ns),
        "user2 adopted none of user1's states after the impostor"
    );
    let counters = rec.status.as_ref().expect("user2's final counters");
    assert!(
        counters.received >= after.len() as u64 && counters.received > b_before.network.received,
        "{counters:?}"
    );

    terminate(&router);
    let st = router.wait_timeout(LIMIT).expect("router stopped");
    assert!(st.success(), "the router stopped cleanly: {st}");
    assert!(!status_file.exists(), "the router removed its status file");
    drop(ns);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The router goes away under a running session and comes back (stopped and started again, as an
/// operator restarting it would): both stations lose their links at once, their clients reconnect,
/// and each must find the other present again, measure its clock again, and go on receiving and
/// adopting its states. (Zenoh delivers the tokens' deletions when the links drop; should a
/// station miss their return, it would hold every state for a clock offset it never measures.)
#[test]
fn stations_find_each_other_again_after_the_router_restarts() {
    let _turn = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let pid = std::process::id();
    let ns = match setup(&format!("{pid}k")) {
        Ok(ns) => ns,
        Err(why) => {
            eprintln!("SKIPPED stations_find_each_other_again_after_the_router_restarts: ip netns is not permitted here ({why})");
            return;
        }
    };
    let dir = std::env::temp_dir().join(format!("coop-router-restart-{pid}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let scenario = dir.join("press.toml");
    std::fs::write(&scenario, push_catch_and_press()).expect("scenario");
    let session = format!("nk{pid}");
    let certs = certs(&dir, &session);
    let (mut router1, resolved) = router(&ns.names[0], &dir, &certs);
    let (a, b) = through_router(&dir, &session, &certs, &scenario, &dir, |_| {});
    let mut sa = start_station(&ns.names[1], &a);
    let mut sb = start_station(&ns.names[2], &b);
    let first = both_receiving_and_adopting(&session, &resolved, "through the router", None);

    terminate(&router1);
    let st = router1.wait_timeout(LIMIT).expect("router stopped");
    assert!(st.success(), "the router stopped cleanly: {st}");
    let sites = ["user1".to_owned(), "user2".to_owned()];
    let status = |me: &str| coop_actors::station::status::read(&session, me, &sites).ok();
    // Both see the other go (its token deleted with the link) before the router comes back.
    let gone = wait_for("both stations seeing the other leave", LIMIT, || {
        let x = status("user1").ok_or("no status of user1")?;
        let y = status("user2").ok_or("no status of user2")?;
        if !x.network.peers[1].present && !y.network.peers[0].present {
            Ok([x, y])
        } else {
            Err(format!("{}; {}", brief(&x), brief(&y)))
        }
    });
    let (mut router2, _) = router(&ns.names[0], &dir, &certs);
    let again = both_receiving_and_adopting(
        &session,
        &resolved,
        "through the restarted router",
        Some(&gone),
    );
    for (i, s) in again.iter().enumerate() {
        let other = &s.network.peers[1 - i];
        assert!(
            other.present && other.clock_offset_us.is_some(),
            "{}: the other present with its clock measured again",
            brief(s)
        );
        assert!(
            s.network.joins > first[i].network.joins,
            "{}: a join counted after the restart (before: {})",
            brief(s),
            first[i].network.joins
        );
    }
    for s in [&sa, &sb] {
        terminate(s);
    }
    for s in [&mut sa, &mut sb] {
        let st = s.wait_timeout(LIMIT).expect("station stopped");
        assert!(st.success(), "a station stopped cleanly: {st}");
    }
    terminate(&router2);
    let st = router2.wait_timeout(LIMIT).expect("router stopped");
    assert!(st.success(), "the restarted router stopped cleanly: {st}");
    drop(ns);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The two stations' configurations (in `dir`, each recording `records/<site>.mcap`, then `edit`
/// applied) for a session through router r1 over mutual TLS: user1 reaches it at 192.0.2.1,
/// user2 at 192.0.2.5.
fn through_router(
    dir: &Path,
    session: &str,
    certs: &Path,
    scenario: &Path,
    records: &Path,
    edit: impl Fn(&mut StationConfig),
) -> (PathBuf, PathBuf) {
    let station = |me: &str, router_addr: &str| {
        let (cert, key) = (
            certs.join(format!("{me}.pem")),
            certs.join(format!("{me}.key")),
        );
        let (ca, acl) = (certs.join("ca.pem"), certs.join("acl.json5"));
        let (record, scenario) = (records.join(format!("{me}.mcap")), scenario.to_owned());
        let connect = format!("tls/{router_addr}:7447");
        let edit = &edit;
        move |c: &mut StationConfig| {
            c.scenario = Some(scenario);
            c.record = Some(record);
            c.network.mode = Mode::Client;
            c.network.connect = vec![connect];
            c.network.access_control = Some(acl);
            c.network.tls = Some(Tls {
                root_ca_certificate: Some(ca),
                connect_certificate: Some(cert),
                connect_private_key: Some(key),
                enable_mtls: true,
                ..Tls::default()
            });
            edit(c);
        }
    };
    (
        station_config(dir, session, "user1", station("user1", "192.0.2.1")),
        station_config(dir, session, "user2", station("user2", "192.0.2.5")),
    )
}

/// `session run --attach` in namespace `ns` for `scenario`'s session `session` under `method`,
/// through router r1 (192.0.2.1) with the certificates in `certs`, reading the stations'
/// recordings from `records`; it waits `timeout_s` for them and writes to `out`.
fn attach_launcher(
    ns: &str,
    (scenario, session, method): (&Path, &str, MethodName),
    (certs, records): (&Path, &Path),
    timeout_s: &str,
    out: &Path,
) -> Command {
    let mut c = in_ns(ns, SESSION_BIN);
    c.arg("run")
        .arg(scenario)
        .args([
            "--attach",
            "--session",
            session,
            "--method",
            method.as_str(),
        ])
        .args(["--connect", "tls/192.0.2.1:7447", "--certs"])
        .arg(certs)
        .arg("--recordings")
        .arg(records)
        .args(["--start-timeout-s", timeout_s, "--out"])
        .arg(out);
    c
}

/// Starts a station in namespace `ns` with configuration `cfg` (120 s at most).
fn start_station(ns: &str, cfg: &Path) -> Reaped {
    Reaped::spawn(
        in_ns(ns, STATION)
            .args(["run", "--duration-s", "120", "--config"])
            .arg(cfg)
            .stderr(Stdio::inherit()),
    )
}

/// Waits until each station of `session` (user1, user2) has received more than 100 of the other's
/// states and adopted some, counted from their start; or, counted from `since` (their statuses
/// then), both received more than 100 and user2 adopted some (from 5 s on user1 presses the disk
/// alone: its copy is the newest, user2 follows it and user1 has nothing to adopt). On timeout it
/// says what both stations and the router showed.
fn both_receiving_and_adopting(
    session: &str,
    router: &coop_actors::router::ResolvedRouter,
    how: &str,
    since: Option<&[StationStatus; 2]>,
) -> [StationStatus; 2] {
    let sites = ["user1".to_owned(), "user2".to_owned()];
    let status = |me: &str| coop_actors::station::status::read(session, me, &sites).ok();
    wait_for(
        &format!("both stations receiving and adopting {how}"),
        LIMIT,
        || {
            let x = status("user1").ok_or("no status of user1")?;
            let y = status("user2").ok_or("no status of user2")?;
            let grew = |now: &StationStatus, i: usize| {
                let (received, remote, adopted) = since.map_or((0, 0, 0), |b| {
                    let b = &b[i];
                    (
                        b.network.received,
                        b.physics.remote_received,
                        b.physics.adoptions,
                    )
                });
                now.network.received > received + 100
                    && now.physics.remote_received > remote + 100
                    && (now.physics.adoptions > adopted || (since.is_some() && i == 0))
            };
            if grew(&x, 0) && grew(&y, 1) {
                return Ok([x, y]);
            }
            let router = coop_actors::router::read_status(router)
                .map_or_else(|e| format!("{e:#}"), |r| format!("{r:?}"));
            Err(format!("{}; {}; router: {router}", brief(&x), brief(&y)))
        },
    )
}

/// `session certs` for `session` into `dir/certs` (router r1 at both its addresses).
fn certs(dir: &Path, session: &str) -> PathBuf {
    let certs = dir.join("certs");
    let made = Command::new(SESSION_BIN)
        .arg("certs")
        .arg(coop_tests::scenario_path("paper.toml"))
        .arg("--out")
        .arg(&certs)
        .args([
            "--session",
            session,
            "--router",
            "r1",
            "--host",
            "r1=192.0.2.1,192.0.2.5",
        ])
        .output()
        .expect("session certs");
    assert!(
        made.status.success(),
        "session certs: {}",
        String::from_utf8_lossy(&made.stderr)
    );
    certs
}

/// Starts router r1 in `ns` listening on both its links, with the session's certificate and
/// access control; returns it and its configuration once its status is written.
fn router(ns: &str, dir: &Path, certs: &Path) -> (Reaped, coop_actors::router::ResolvedRouter) {
    let cfg = dir.join("r1.toml");
    std::fs::write(
        &cfg,
        format!(
            "name = \"r1\"\nlisten = [\"tls/192.0.2.1:7447\", \"tls/192.0.2.5:7447\"]\n\
             access_control = {acl:?}\nstatus_file = {status:?}\n\
             [tls]\nroot_ca_certificate = {ca:?}\nlisten_certificate = {c:?}\nlisten_private_key = {k:?}\nenable_mtls = true\n",
            acl = certs.join("acl.json5"),
            status = dir.join("r1.json"),
            ca = certs.join("ca.pem"),
            c = certs.join("r1.pem"),
            k = certs.join("r1.key"),
        ),
    )
    .expect("router config");
    let r = Reaped::spawn(
        in_ns(ns, STATION)
            .args(["router", "run", "--config"])
            .arg(&cfg)
            .stderr(Stdio::inherit()),
    );
    let resolved = coop_actors::router::RouterConfig::load(&cfg).expect("router config");
    wait_until("the router's status", LIMIT, || {
        coop_actors::router::read_status(&resolved).ok()
    });
    (r, resolved)
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

fn terminate(r: &Reaped) {
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(r.pid() as i32),
        nix::sys::signal::Signal::SIGTERM,
    );
}

/// The clocks differ by this much between the two stations (user2's is ahead).
const ATTACH_SKEW_S: i64 = 1000;

/// Both users reach the disk at rest from either side at the same scripted time (it is touched
/// from about 0.98 s on) and let go at 1.4 s: each site's first contact is its own script's doing,
/// so it shows when that script started. (With user2's first contact a catch of a disk user1 had
/// pushed, it also carried the network path's variance: once 57 ms off on a loaded machine.)
fn reach_together() -> String {
    paper_with_scripts(
        "attach",
        4.0,
        "[{ t_s = 0.0, target_m = [-0.20, 0.0, 0.01] }, { t_s = 0.5, target_m = [-0.20, 0.0, 0.01] }, \
          { t_s = 1.0, target_m = [-0.09, 0.0, 0.01] }, { t_s = 1.4, target_m = [-0.20, 0.0, 0.01] }]",
        "[{ t_s = 0.0, target_m = [0.20, 0.0, 0.01] }, { t_s = 0.5, target_m = [0.20, 0.0, 0.01] }, \
          { t_s = 1.0, target_m = [-0.01, 0.0, 0.01] }, { t_s = 1.4, target_m = [0.20, 0.0, 0.01] }]",
    )
}

/// The paper's push and catch; then user2 goes away and user1 reaches over the disk and presses
/// it down onto the table to the end: user1's states carry news of its user for as long as a test
/// looks, so user2 goes on adopting them whenever its impostor is done. (A held squeeze did not
/// do: under the paper's method a squeeze can push the disk out of the grasp, and then nobody's
/// states are news.)
fn push_catch_and_press() -> String {
    paper_with_scripts(
        "press",
        120.0,
        "[{ t_s = 0.0, target_m = [-0.20, 0.0, 0.01] }, { t_s = 0.5, target_m = [-0.20, 0.0, 0.01] }, \
          { t_s = 1.0, target_m = [-0.06, 0.0, 0.01] }, { t_s = 1.4, target_m = [-0.20, 0.0, 0.01] }, \
          { t_s = 3.0, target_m = [-0.20, 0.0, 0.01] }, { t_s = 3.5, target_m = [-0.20, 0.0, 0.05] }, \
          { t_s = 4.5, target_m = [0.05, 0.0, 0.05] }, { t_s = 5.0, target_m = [0.05, 0.0, 0.02] }]",
        "[{ t_s = 0.0, target_m = [0.20, 0.0, 0.01] }, { t_s = 0.5, target_m = [0.20, 0.0, 0.01] }, \
          { t_s = 1.0, target_m = [0.095, 0.0, 0.01] }, { t_s = 2.0, target_m = [0.095, 0.0, 0.01] }, \
          { t_s = 2.5, target_m = [0.20, -0.12, 0.01] }]",
    )
}

/// A recording's first contact (its tool touching the object), s after its own station's time 0
/// as the station took it, and that time 0.
fn first_contact(path: &Path) -> (f64, u64) {
    let rec = coop_transport::recording::read(path).expect("recording");
    let epoch = rec.session.as_ref().expect("the session started").epoch_ns;
    let t = rec
        .samples
        .iter()
        .find(|s| s.touching)
        .unwrap_or_else(|| panic!("{}: the tool never touched the object", path.display()))
        .t_ns;
    ((t as f64 - epoch as f64) * 1e-9, epoch)
}

/// `session run --attach` drives two stations it did not start, each in its own network namespace
/// and started by hand (user2's also in a time namespace 1000 s ahead), through the router over
/// mutual TLS with the generated access control. The launcher names who is missing when nobody
/// came; then it waits for both, announces time 0 in its own clock, each station translates it
/// with its measured offset to the launcher, the scripts start together (each site's first
/// contact, in the launcher's clock, within one of its report periods of the same scenario's
/// single-machine `session run`), the stations stop by themselves at the end, and the launcher
/// prints the table from their recordings. Nothing is left behind.
///
/// The baseline is a real single-machine run of the same scenario, not the simulator: the
/// simulator models the scenario's emulated delay, and user2's first contact (the catch) depends
/// on when user1's states arrive, so only a real run over a fast link compares like with like.
#[test]
fn session_run_attach_drives_stations_started_by_hand_whose_clocks_differ() {
    let _turn = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Err(why) = time_namespaces_work() {
        eprintln!("SKIPPED session_run_attach_drives_stations_started_by_hand_whose_clocks_differ: time namespaces are not permitted here ({why})");
        return;
    }
    let pid = std::process::id();
    let dir = std::env::temp_dir().join(format!("coop-attach-{pid}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let scenario = dir.join("attach.toml");
    std::fs::write(&scenario, reach_together()).expect("scenario");
    let sc = coop_actors::scenario_file::load(&scenario).expect("scenario");
    let period = |i: usize| 1.0 / sc.site[i].report_rate_hz;

    // The baseline: the same scenario on one machine, loopback, no emulation.
    let base_out = dir.join("baseline");
    let base = Command::new(SESSION_BIN)
        .arg("run")
        .arg(&scenario)
        .args(["--method", "paper", "--no-emulation", "--json", "--out"])
        .arg(&base_out)
        .output()
        .expect("session run");
    assert!(
        base.status.success(),
        "baseline session: {}",
        String::from_utf8_lossy(&base.stderr)
    );
    let base_json: serde_json::Value = serde_json::from_slice(&base.stdout).expect("JSON");
    let base_contact = |site: &str| {
        base_json["methods"]["paper"]["stations"][site]["first_contact_s"]
            .as_f64()
            .unwrap_or_else(|| panic!("baseline: {site} touched nothing: {base_json}"))
    };
    let baseline = [base_contact("user1"), base_contact("user2")];

    let tag = format!("{pid}a");
    let ns = match setup(&tag) {
        Ok(ns) => ns,
        Err(why) => {
            eprintln!("SKIPPED session_run_attach_drives_stations_started_by_hand_whose_clocks_differ: ip netns is not permitted here ({why})");
            return;
        }
    };
    let session = format!("na{pid}");
    let certs = certs(&dir, &session);
    let (mut router, _resolved) = router(&ns.names[0], &dir, &certs);
    let records = dir.join("records");
    std::fs::create_dir_all(&records).expect("records dir");
    let launcher = |out: &str, timeout_s: &str| {
        attach_launcher(
            &ns.names[0],
            (&scenario, &session, MethodName::Paper),
            (&certs, &records),
            timeout_s,
            &dir.join(out),
        )
    };

    // Nobody came: the launcher says who is missing, and leaves.
    let none = launcher("none", "2").output().expect("launcher");
    let said = String::from_utf8_lossy(&none.stderr);
    assert!(!none.status.success(), "{said}");
    assert!(
        said.contains("stations not present after 2s: user1, user2"),
        "{said}"
    );

    let (a, b) = through_router(&dir, &session, &certs, &scenario, &records, |c| {
        c.method = Some(MethodName::Paper);
        c.start = StartMode::Session;
    });
    // Started by hand, as on two machines: each in its namespace; user2's clock 1000 s ahead. The
    // duration only bounds them should the launcher never come: they stop at the session's end.
    let run = |cfg: &Path| {
        vec![
            STATION.to_owned(),
            "run".into(),
            "--duration-s".into(),
            "120".into(),
            "--config".into(),
            cfg.display().to_string(),
        ]
    };
    let mut sa = Reaped::spawn(
        in_ns(&ns.names[1], STATION)
            .args(&run(&a)[1..])
            .stderr(Stdio::inherit()),
    );
    let skewed = shifted_clock(ATTACH_SKEW_S);
    let mut sb = Reaped::spawn(
        in_ns(&ns.names[2], &skewed[0])
            .args(&skewed[1..])
            .args(run(&b))
            .stderr(Stdio::inherit()),
    );

    // Before time 0 the launcher checks what each station runs: another scenario, or another
    // method, is refused and starts nothing (the stations go on waiting for a time 0).
    let other = dir.join("other.toml");
    std::fs::write(
        &other,
        reach_together().replace("name = \"attach\"", "name = \"other\""),
    )
    .expect("scenario");
    for (what, scenario, method, expect) in [
        (
            "another scenario",
            other.as_path(),
            MethodName::Paper,
            "runs another scenario",
        ),
        (
            "another method",
            scenario.as_path(),
            MethodName::Naive,
            "runs method paper, the launcher was given naive",
        ),
    ] {
        let refused = attach_launcher(
            &ns.names[0],
            (scenario, &session, method),
            (&certs, &records),
            "60",
            &dir.join("refused"),
        )
        .output()
        .expect("launcher");
        let err = String::from_utf8_lossy(&refused.stderr);
        assert!(
            !refused.status.success()
                && err.contains(expect)
                && err.contains("nothing was started"),
            "{what}: {err}"
        );
        assert!(
            !err.contains("time 0 announced"),
            "{what}: nothing announced: {err}"
        );
    }

    let out = launcher("attached", "60").output().expect("launcher");
    let (said, err) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "session run --attach: {err}\n{said}");
    // Stations started by hand do not emulate the scenario's delays unless told: said, for each.
    for site in ["user1", "user2"] {
        assert!(
            err.contains(&format!(
                "warning: station {site} does not emulate the scenario's network"
            )),
            "{site}: {err}"
        );
    }
    println!("{said}");
    // The table, as a session it started prints it.
    for row in ["div max", "reference", "paper-sim", "paper-real"] {
        assert!(said.contains(row), "no {row:?} in the table:\n{said}");
    }
    let t0: u64 = said
        .split("time 0 in the launcher's clock: ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no time 0 line:\n{said}"));
    for s in [&mut sa, &mut sb] {
        let st = s
            .wait_timeout(LIMIT)
            .expect("the station stopped by itself at the session's end");
        assert!(st.success(), "a station stopped cleanly: {st}");
    }
    // Each station's time 0 is the launcher's, in its own clock (user2's 1000 s ahead); each
    // site's first contact, in the launcher's clock, is where the single-machine run has it.
    let shift = [0i128, i128::from(ATTACH_SKEW_S) * 1_000_000_000];
    for (i, site) in ["user1", "user2"].into_iter().enumerate() {
        let (contact, epoch) = first_contact(&records.join(format!("{site}.mcap")));
        let epoch_launcher = i128::from(epoch) - shift[i];
        let start_error = (epoch_launcher - i128::from(t0)) as f64 * 1e-9;
        let contact_launcher = contact + start_error;
        println!(
            "{site}: time 0 {start_error:+.6} s from the launcher's; first contact {contact_launcher:.4} s (single machine {:.4} s)",
            baseline[i]
        );
        assert!(
            (contact_launcher - baseline[i]).abs() <= period(i),
            "{site}: first contact at {contact_launcher} s of the launcher's time 0, {} s on one machine: more than a report period ({} s) apart (its time 0 is {start_error} s off the launcher's)",
            baseline[i],
            period(i)
        );
    }

    terminate(&router);
    let st = router.wait_timeout(LIMIT).expect("router stopped");
    assert!(st.success(), "the router stopped cleanly: {st}");
    for site in ["user1", "user2"] {
        let left = shm_entries(&format!("coop_{session}_{site}_"));
        assert!(left.is_empty(), "{site} left segments: {left:?}");
    }
    drop(ns);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A world of two objects through the router over mutual TLS: two users carry the tray with the
/// cup on it (`scenarios/tray.toml`, `timewarp`, fingertip pads), started by `session run
/// --attach`, and station A's link to the router goes down for 2 s during the carry (longer than
/// the method's history: the stations cannot recover each other's tools there and their confirmed
/// worlds differ). When the link is back, the later station adopts the earlier one's confirmed
/// world (both objects, their contacts and the pads' memory at once): the hash checks go on with
/// no new mismatch, and every object ends within 5 mm across the two copies.
#[test]
fn a_tray_carried_through_the_router_heals_after_a_partition_during_the_carry() {
    let _turn = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let pid = std::process::id();
    let tag = format!("{pid}t");
    let ns = match setup(&tag) {
        Ok(ns) => ns,
        Err(why) => {
            eprintln!("SKIPPED a_tray_carried_through_the_router_heals_after_a_partition_during_the_carry: ip netns is not permitted here ({why})");
            return;
        }
    };
    let dir = std::env::temp_dir().join(format!("coop-tray-{pid}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let scenario = dir.join("tray.toml");
    std::fs::copy(coop_tests::scenario_path("tray.toml"), &scenario).expect("tray.toml");
    let session = format!("nt{pid}");
    let certs = certs(&dir, &session);
    let (mut router, _resolved) = router(&ns.names[0], &dir, &certs);
    let records = dir.join("records");
    std::fs::create_dir_all(&records).expect("records dir");
    let (a, b) = through_router(&dir, &session, &certs, &scenario, &records, |c| {
        c.method = Some(MethodName::Timewarp);
        c.start = StartMode::Session;
    });
    let mut sa = start_station(&ns.names[1], &a);
    let mut sb = start_station(&ns.names[2], &b);
    let mut launcher = attach_launcher(
        &ns.names[0],
        (&scenario, &session, MethodName::Timewarp),
        (&certs, &records),
        "60",
        &dir.join("out"),
    );
    let launched = std::thread::spawn(move || launcher.output().expect("launcher"));

    let sites = ["user1".to_owned(), "user2".to_owned()];
    // The light read: the partition is timed by ticks, and a full status read (a 200 ms window
    // and more) under load reached the link's return after the carry had ended.
    let rollback = |me: &str| {
        coop_actors::station::status::rollback_figures(&session, me)
            .ok()
            .flatten()
    };
    // The carry is 7.5–11 s of the session (ticks of 1 ms): down from 8 s to 10 s.
    wait_until("the carry under way at station A", LIMIT, || {
        (rollback("user1")?.ticks >= 8_000).then_some(())
    });
    let link = format!("csa{tag}");
    ip(&["-n", &ns.names[1], "link", "set", &link, "down"]).expect("link down");
    let down_at = rollback("user1").map_or(0, |x| x.ticks);
    wait_until("2 s of partition", LIMIT, || {
        (rollback("user1")?.ticks >= down_at + 2_000).then_some(())
    });
    // The baseline is read before the link comes back (nothing is compared while it is down): an
    // adoption can follow the link's return within 100 ms, before a baseline read after it.
    let up_at = wait_until("both stations' figures", LIMIT, || {
        Some((rollback("user1")?, rollback("user2")?))
    });
    ip(&["-n", &ns.names[1], "link", "set", &link, "up"]).expect("link up");
    assert!(
        up_at.0.ticks < 11_000,
        "the link came back at tick {}, after the carry (11000)",
        up_at.0.ticks
    );
    // Once the confirmed worlds have been compared across the gap and one adopted (or they
    // never differed), 40 more comparisons at each with no new mismatch: equal confirmed worlds.
    // What the stations say while it waits, so that a heal that does not come shows why (peers
    // absent, tracks held for a clock offset, a child restarted); and a station whose session
    // ended (its status gone for a second) fails the wait at once instead of at its limit.
    let (mut last_seen, mut gone) = (String::from("nothing yet"), 0);
    let settled = wait_for("the comparisons after the partition", LIMIT, || {
        let status = |me: &str| coop_actors::station::status::read(&session, me, &sites).ok();
        let (Some(sx), Some(sy)) = (status("user1"), status("user2")) else {
            gone += 1;
            assert!(
                gone < 200,
                "a station's status is gone (its session ended) before the comparisons resumed; last seen:\n{last_seen}"
            );
            return Err(last_seen.clone());
        };
        gone = 0;
        let rb = |s: &coop_actors::station::status::StationStatus| {
            s.physics
                .rollback
                .map_or("no rollback figures".to_owned(), |r| r.to_string())
        };
        last_seen = format!(
            "user1: {} {}\nuser2: {} {}",
            brief(&sx),
            rb(&sx),
            brief(&sy),
            rb(&sy)
        );
        let (Some(x), Some(y)) = (sx.physics.rollback, sy.physics.rollback) else {
            return Err(last_seen.clone());
        };
        let healed = x.adopted_states + y.adopted_states
            > up_at.0.adopted_states + up_at.1.adopted_states
            || (x.hash_mismatches, y.hash_mismatches)
                == (up_at.0.hash_mismatches, up_at.1.hash_mismatches);
        if healed
            && x.hash_checks >= up_at.0.hash_checks + 20
            && y.hash_checks >= up_at.1.hash_checks + 20
        {
            Ok((x, y))
        } else {
            Err(last_seen.clone())
        }
    });
    eprintln!(
        "the comparisons after the partition: {} ticks after the link came back",
        settled.0.ticks.saturating_sub(up_at.0.ticks)
    );
    let after = wait_until("40 more comparisons at each", LIMIT, || {
        let (x, y) = (rollback("user1")?, rollback("user2")?);
        (x.hash_checks >= settled.0.hash_checks + 40 && y.hash_checks >= settled.1.hash_checks + 40)
            .then_some((x, y))
    });
    eprintln!("after the partition: user1 {}\nuser2 {}", after.0, after.1);
    assert_eq!(
        (after.0.hash_mismatches, after.1.hash_mismatches),
        (settled.0.hash_mismatches, settled.1.hash_mismatches),
        "the confirmed worlds agree again: {} / {}",
        after.0,
        after.1
    );

    let out = launched.join().expect("launcher thread");
    let (said, err) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "session run --attach: {err}\n{said}");
    println!("{said}");
    for row in ["timewarp-real", "# object tray", "# object cup"] {
        assert!(said.contains(row), "no {row:?} in the table:\n{said}");
    }
    // The stations' figures, asked through zenoh (their control blocks are not the launcher's to
    // read across machines): overruns, compute p99, fallbacks and mismatches, not `-`.
    let rows: Vec<&str> = said
        .lines()
        .filter(|l| l.starts_with("# stations: timewarp"))
        .collect();
    assert_eq!(rows.len(), 2, "a stations row per site:\n{said}");
    for r in rows {
        let cells: Vec<&str> = r.split_whitespace().collect();
        for (k, what) in [
            (4, "overruns"),
            (6, "compute p99"),
            (9, "fallbacks"),
            (11, "mismatches"),
        ] {
            assert!(
                cells.get(k).is_some_and(|c| c.parse::<u64>().is_ok()),
                "{what} through zenoh in {r:?}"
            );
        }
    }
    for s in [&mut sa, &mut sb] {
        let st = s
            .wait_timeout(LIMIT)
            .expect("the station stopped by itself at the session's end");
        assert!(st.success(), "a station stopped cleanly: {st}");
    }
    // Every object of the two copies at the end, within 5 mm.
    let last = |me: &str| {
        let r = coop_transport::recording::read(&records.join(format!("{me}.mcap")))
            .expect("recording");
        let mut at = vec![r.samples.last().expect("samples").pos];
        for o in &r.others {
            at.push(o.samples.last().expect("samples of each object").pos);
        }
        at
    };
    let (pa, pb) = (last("user1"), last("user2"));
    assert_eq!(pa.len(), 2, "both objects recorded: {pa:?}");
    for (k, (x, y)) in pa.iter().zip(&pb).enumerate() {
        let apart = distance(*x, *y);
        assert!(
            apart < 5e-3,
            "object {k} ended {apart} m apart across the copies: {x:?} vs {y:?}"
        );
    }
    terminate(&router);
    let st = router.wait_timeout(LIMIT).expect("router stopped");
    assert!(st.success(), "the router stopped cleanly: {st}");
    for site in ["user1", "user2"] {
        let left = shm_entries(&format!("coop_{session}_{site}_"));
        assert!(left.is_empty(), "{site} left segments: {left:?}");
    }
    drop(ns);
    let _ = std::fs::remove_dir_all(&dir);
}
