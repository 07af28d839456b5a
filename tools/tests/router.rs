//! A session across three network namespaces: a router (`station router`) in one, a station in
//! each of the two others, over mutual TLS with the certificates and the access control that
//! `session certs` makes from the scenario. The stations reach each other only through the router
//! (each namespace has a link to the router's, none between them, and nothing forwards). An
//! impostor holding user2's certificate, and a client holding none, try their luck. The test
//! creates and removes its namespaces and links, bounds every wait, and is skipped with a message
//! where `ip netns` is not permitted.

use std::process::{Command, Stdio};
use std::time::Duration;

use coop_tests::{ip, station_config, wait_until, Namespaces, Reaped, StationConfig};
use coop_transport::network::{Mode, Tls};

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
    let session = format!("nr{pid}");
    let certs = dir.join("certs");
    let made = Command::new(SESSION_BIN)
        .args([
            "certs",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios/paper.toml"),
        ])
        .arg("--out")
        .arg(&certs)
        .args([
            "--session",
            &session,
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
    let pem = |n: &str| certs.join(format!("{n}.pem"));
    let key = |n: &str| certs.join(format!("{n}.key"));
    let acl = certs.join("acl.json5");
    let status_file = dir.join("r1.json");
    let router_cfg = dir.join("r1.toml");
    std::fs::write(
        &router_cfg,
        format!(
            "name = \"r1\"\nlisten = [\"tls/192.0.2.1:7447\", \"tls/192.0.2.5:7447\"]\n\
             access_control = {acl:?}\nstatus_file = {status_file:?}\n\
             [tls]\nroot_ca_certificate = {ca:?}\nlisten_certificate = {c:?}\nlisten_private_key = {k:?}\nenable_mtls = true\n",
            ca = certs.join("ca.pem"),
            c = pem("r1"),
            k = key("r1"),
        ),
    )
    .expect("router config");
    let mut router = Reaped::spawn(
        in_ns(&ns.names[0], STATION)
            .args(["router", "run", "--config"])
            .arg(&router_cfg)
            .stderr(Stdio::inherit()),
    );
    let resolved = coop_actors::router::RouterConfig::load(&router_cfg).expect("router config");
    wait_until("the router's status", LIMIT, || {
        coop_actors::router::read_status(&resolved).ok()
    });

    let station = |me: &'static str, router_addr: &'static str| {
        let (cert, k, ca, acl) = (pem(me), key(me), certs.join("ca.pem"), acl.clone());
        let record = dir.join(format!("{me}.mcap"));
        move |c: &mut StationConfig| {
            c.record = Some(record);
            c.network.mode = Mode::Client;
            c.network.connect = vec![format!("tls/{router_addr}:7447")];
            c.network.access_control = Some(acl);
            c.network.tls = Some(Tls {
                root_ca_certificate: Some(ca),
                connect_certificate: Some(cert),
                connect_private_key: Some(k),
                enable_mtls: true,
                ..Tls::default()
            });
        }
    };
    let a = station_config(&dir, &session, "user1", station("user1", "192.0.2.1"));
    let b = station_config(&dir, &session, "user2", station("user2", "192.0.2.5"));
    let start = |n: &str, cfg: &std::path::Path| {
        Reaped::spawn(
            in_ns(n, STATION)
                .args(["run", "--duration-s", "120", "--config"])
                .arg(cfg)
                .stderr(Stdio::inherit()),
        )
    };
    let mut sa = start(&ns.names[1], &a);
    let mut sb = start(&ns.names[2], &b);
    let sites = ["user1".to_owned(), "user2".to_owned()];
    let status = |me: &str| coop_actors::station::status::read(&session, me, &sites).ok();
    // The paper session runs through the router: each receives the other's states and adopts them.
    wait_until(
        "both stations receiving and adopting through the router",
        LIMIT,
        || {
            let (x, y) = (status("user1")?, status("user2")?);
            (x.network.received > 100
                && y.network.received > 100
                && x.physics.remote_received > 100
                && y.physics.remote_received > 100
                && x.physics.adoptions > 0
                && y.physics.adoptions > 0)
                .then_some(())
        },
    );
    let before = |s: &coop_actors::station::status::StationStatus| s.network.refused.clone();
    let (ra0, rb0) = (
        before(&status("user1").expect("a")),
        before(&status("user2").expect("b")),
    );
    assert!(
        ra0.values().chain(rb0.values()).all(|&n| n == 0),
        "a clean start through the router refuses nothing: {ra0:?} {rb0:?}"
    );

    // A client without a certificate does not get in (the TLS handshake fails).
    let nocert = in_ns(&ns.names[1], IMPOSTOR)
        .args(["tls/192.0.2.1:7447"])
        .arg(certs.join("ca.pem"))
        .args(["-", "-", &session, "user1", "user2"])
        .output()
        .expect("no-cert client");
    let said = String::from_utf8_lossy(&nocert.stdout);
    assert_eq!(nocert.status.code(), Some(3), "refused at connect: {said}");
    assert!(said.starts_with("refused:"), "{said}");

    // An impostor holding user2's certificate speaks for user1.
    let imp = in_ns(&ns.names[2], IMPOSTOR)
        .args(["tls/192.0.2.5:7447"])
        .arg(certs.join("ca.pem"))
        .arg(pem("user2"))
        .arg(key("user2"))
        .args([&session, "user2", "user1"])
        .output()
        .expect("impostor");
    let said = String::from_utf8_lossy(&imp.stdout);
    assert!(
        imp.status.success() && said.contains("connected") && said.contains("done"),
        "{said}"
    );
    // Its puts on its own key reach user1 (refused there as garbage): its link worked.
    let a_after = wait_until(
        "user1 refusing the impostor's garbage on user2's key",
        LIMIT,
        || {
            let s = status("user1")?;
            (s.network.refused.get("length").copied().unwrap_or(0) > 0).then_some(s)
        },
    );
    let rs = wait_until("the router counting its refusals", LIMIT, || {
        let s = coop_actors::router::read_status(&resolved).ok()?;
        let on = |k: String| s.recent_refusals.iter().any(|r| r.key == k);
        (on(coop_transport::keys::state(&session, 0, "user1"))).then_some(s)
    });
    assert!(rs.refused > 0 && rs.access_control, "{rs}");
    // What it said for user1 never reached user2: user2 counts the impostor's garbage on its
    // own key (200 puts, each arriving at most once) as `length` refusals, and would count the
    // 200 on user1's key there too. Nothing else is refused.
    let b_after = status("user2").expect("b");
    let b_len = b_after.network.refused.get("length").copied().unwrap_or(0);
    assert!(
        b_len <= 200
            && b_after
                .network
                .refused
                .iter()
                .all(|(r, &n)| *r == "length" || n == 0),
        "nothing the impostor said for user1 reached user2: {:?}",
        b_after.network.refused
    );
    // user2's view of user1's clock stayed true (the impostor answers an hour ahead).
    let offset = b_after.network.peers[0]
        .clock_offset_us
        .expect("user1's offset");
    assert!(
        offset.abs() < 50_000.0,
        "user2's offset of user1's clock: {offset} µs"
    );
    assert!(!a_after.network.peers[1].lost && a_after.running);
    println!("{rs}");
    assert!(rs.sessions.len() >= 2, "both stations linked: {rs}");

    for s in [&mut sa, &mut sb] {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(s.pid() as i32),
            nix::sys::signal::Signal::SIGTERM,
        );
    }
    for s in [&mut sa, &mut sb] {
        let st = s.wait_timeout(LIMIT).expect("station stopped");
        assert!(st.success(), "a station stopped cleanly: {st}");
    }
    // user1's recording: every state it handed physics came from user2's physics (none of the
    // impostor's: garbage never decodes), and its last counters agree.
    let rec = coop_transport::recording::read(&dir.join("user1.mcap")).expect("recording");
    assert!(!rec.remote.is_empty(), "user1 received states");
    assert!(
        rec.status.as_ref().is_some_and(|s| s.received > 100),
        "{:?}",
        rec.status
    );
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(router.pid() as i32),
        nix::sys::signal::Signal::SIGTERM,
    );
    let st = router.wait_timeout(LIMIT).expect("router stopped");
    assert!(st.success(), "the router stopped cleanly: {st}");
    assert!(!status_file.exists(), "the router removed its status file");
    drop(ns);
    let _ = std::fs::remove_dir_all(&dir);
}
