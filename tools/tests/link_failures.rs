//! What a station, a launcher and a router say when a link cannot come up, with real processes on
//! loopback: a router (`station router run`, mutual TLS, the certificates of `session certs`) and
//! stations in client mode connecting to it with one thing wrong each. Every failure gives its own
//! message, naming the cause and the fix, and a station says it once however often its network
//! process is restarted (zenoh's own words, `Unable to connect to any of [...]`, are never shown).
//! A station holding another site's certificate, and a router whose port is taken, are refused
//! before they start. Unique session names and ports keep parallel tests apart; every wait has a
//! deadline; nothing asserts on timing.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use coop_rt::shm::control::{Child, ControlBlock};
use coop_rt::shm::{BlockSegment, SegmentName};
use coop_rt::sync::Ordering;
use coop_tests::{shm_entries, station_config, unique_session, wait_until, Reaped};
use coop_transport::network::{Mode, Tls};
use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;

const STATION: &str = env!("CARGO_BIN_EXE_station");
const SESSION_BIN: &str = env!("CARGO_BIN_EXE_session");
const LIMIT: Duration = Duration::from_secs(60);

/// A test's directory, removed when the test passes (kept to look at when it fails).
struct Dir(PathBuf);

impl Dir {
    fn new(session: &str) -> Self {
        let d = std::env::temp_dir().join(format!("coop-link-{session}"));
        std::fs::create_dir_all(&d).expect("dir");
        Self(d)
    }
}

impl Drop for Dir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// `session certs` for `session` (its CA, user1, user2, the launcher and router r1) into `out`.
fn certs(session: &str, out: &Path) -> PathBuf {
    let made = Command::new(SESSION_BIN)
        .arg("certs")
        .arg(coop_tests::scenario_path("paper.toml"))
        .args(["--session", session, "--router", "r1", "--out"])
        .arg(out)
        .output()
        .expect("session certs");
    assert!(
        made.status.success(),
        "session certs: {}",
        String::from_utf8_lossy(&made.stderr)
    );
    out.to_owned()
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .expect("bind")
        .local_addr()
        .expect("addr")
        .port()
}

/// Router r1's configuration in `dir` with the certificates in `certs`, listening on `listen`.
fn router_config(dir: &Path, certs: &Path, listen: &[String]) -> PathBuf {
    let cfg = dir.join("r1.toml");
    let list: Vec<String> = listen.iter().map(|l| format!("{l:?}")).collect();
    std::fs::write(
        &cfg,
        format!(
            "name = \"r1\"\nlisten = [{}]\nstatus_file = {status:?}\n\
             [tls]\nroot_ca_certificate = {ca:?}\nlisten_certificate = {c:?}\nlisten_private_key = {k:?}\nenable_mtls = true\n",
            list.join(", "),
            status = dir.join("r1.json"),
            ca = certs.join("ca.pem"),
            c = certs.join("r1.pem"),
            k = certs.join("r1.key"),
        ),
    )
    .expect("router config");
    cfg
}

/// Starts router r1 on `listen`; returns it once its status is written (it listens then).
fn router(dir: &Path, certs: &Path, listen: &[String]) -> Reaped {
    let cfg = router_config(dir, certs, listen);
    let r = Reaped::spawn(
        Command::new(STATION)
            .args(["router", "run", "--duration-s", "120", "--config"])
            .arg(&cfg)
            .stderr(Stdio::null()),
    );
    let resolved = coop_actors::router::RouterConfig::load(&cfg).expect("router config");
    wait_until("the router's status", LIMIT, || {
        coop_actors::router::read_status(&resolved).ok()
    });
    r
}

/// Station user1 of a new session, a client of the router at `connect`, with these TLS files
/// (`ca`: its root CA; `own`: the directory of its certificate and key).
fn client(dir: &Path, session: &str, connect: &str, ca: &Path, own: &Path) -> PathBuf {
    let (connect, ca) = (connect.to_owned(), ca.to_owned());
    let (cert, key) = (own.join("user1.pem"), own.join("user1.key"));
    station_config(dir, session, "user1", move |c| {
        c.supervisor.backoff_initial_ms = 20;
        c.supervisor.network_backoff_max_ms = 100;
        c.network.mode = Mode::Client;
        c.network.connect = vec![connect];
        c.network.tls = Some(Tls {
            root_ca_certificate: Some(ca),
            connect_certificate: Some(cert),
            connect_private_key: Some(key),
            enable_mtls: true,
            ..Tls::default()
        });
    })
}

/// Runs station user1 of `session` with `cfg` until it has said why its network cannot link and
/// its network process has failed three more times; its stderr, which says the cause once.
fn station_says(cfg: &Path, session: &str, dir: &Path) -> String {
    let err_file = dir.join("user1.err");
    let station = Reaped::spawn(
        Command::new(STATION)
            .arg("run")
            .arg("--config")
            .arg(cfg)
            .stderr(std::fs::File::create(&err_file).expect("stderr file")),
    );
    let name = SegmentName::new(session, "user1", "ctl").expect("name");
    let ctl = wait_until("the control block", LIMIT, || {
        BlockSegment::<ControlBlock>::open(&name, Duration::from_secs(1)).ok()
    });
    let stderr = || std::fs::read_to_string(&err_file).unwrap_or_default();
    wait_until(
        "the station saying why its network cannot link",
        LIMIT,
        || stderr().contains("the network cannot link: ").then_some(()),
    );
    let net = ctl.child(Child::Network);
    let restarts = net.restarts.load(Ordering::Relaxed);
    wait_until("three more failures of the network", LIMIT, || {
        (net.restarts.load(Ordering::Relaxed) >= restarts + 3).then_some(())
    });
    let failure = net.last_failure();
    kill(Pid::from_raw(station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
    drop(ctl);
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
    let err = stderr();
    assert_eq!(
        err.matches("the network cannot link: ").count(),
        1,
        "said once, whatever the retries:\n{err}"
    );
    assert!(
        !err.contains("Unable to connect"),
        "zenoh's words are not shown:\n{err}"
    );
    assert!(
        failure.starts_with("network (pid ") && failure.contains(": "),
        "status shows the cause with the failure: {failure}"
    );
    err
}

/// A session's certificates (`ours`) and another session's (`other`, another CA), and router r1
/// of ours running at `connect`.
struct TwoCas {
    session: String,
    dir: Dir,
    ours: PathBuf,
    other: PathBuf,
    connect: String,
    _router: Reaped,
}

fn two_cas_and_our_router() -> TwoCas {
    let session = unique_session();
    let dir = Dir::new(&session);
    let ours = certs(&session, &dir.0.join("ours"));
    let other = certs(&format!("{session}o"), &dir.0.join("other"));
    let connect = format!("tls/127.0.0.1:{}", free_port());
    let _router = router(&dir.0, &ours, std::slice::from_ref(&connect));
    TwoCas {
        session,
        dir,
        ours,
        other,
        connect,
        _router,
    }
}

/// The station's one line about its links.
fn cause_line(err: &str) -> &str {
    err.lines()
        .find(|l| l.contains("the network cannot link: "))
        .expect("a cause line")
}

/// The router's certificate is of another CA than the station's root CA.
#[test]
fn a_router_of_another_ca_is_named_with_the_ca_file() {
    let TwoCas {
        session,
        dir,
        ours,
        other,
        connect,
        _router,
    } = two_cas_and_our_router();
    let cfg = client(&dir.0, &session, &connect, &other.join("ca.pem"), &ours);
    let err = station_says(&cfg, &session, &dir.0);
    let line = cause_line(&err);
    assert!(
        line.contains(&format!(
            "the router's certificate is not signed by the CA in network.tls.root_ca_certificate ({}): ",
            other.join("ca.pem").display()
        )),
        "{err}"
    );
}

/// The station's own certificate is of another CA: the router refuses it in the handshake.
#[test]
fn a_certificate_the_router_refuses_is_named_with_its_file() {
    let TwoCas {
        session,
        dir,
        ours,
        other,
        connect,
        _router,
    } = two_cas_and_our_router();
    let cfg = client(&dir.0, &session, &connect, &ours.join("ca.pem"), &other);
    let err = station_says(&cfg, &session, &dir.0);
    let line = cause_line(&err);
    assert!(
        line.contains(&format!(
            "the router at {connect} refused this station's certificate, network.tls.connect_certificate ({}) (it answered UnknownCA",
            other.join("user1.pem").display()
        )),
        "{err}"
    );
}

/// The station reaches the router at an address its certificate does not name.
#[test]
fn an_address_the_certificate_does_not_name_is_named() {
    let session = unique_session();
    let dir = Dir::new(&session);
    let ours = certs(&session, &dir.0.join("ours"));
    let port = free_port();
    // 127.0.0.2 is loopback too, and not among the names `session certs` gives r1.
    let connect = format!("tls/127.0.0.2:{port}");
    let _r = router(&dir.0, &ours, std::slice::from_ref(&connect));
    let cfg = client(&dir.0, &session, &connect, &ours.join("ca.pem"), &ours);
    let err = station_says(&cfg, &session, &dir.0);
    let line = cause_line(&err);
    assert!(
        line.contains("the router's certificate does not name 127.0.0.2 (it names r1, localhost, 127.0.0.1, ::1); "),
        "{err}"
    );
    assert!(line.contains("session certs --host"), "the fix: {err}");
}

/// No router listens where the station connects.
#[test]
fn a_router_that_is_down_is_said_to_be_down() {
    let session = unique_session();
    let dir = Dir::new(&session);
    let ours = certs(&session, &dir.0.join("ours"));
    let connect = format!("tls/127.0.0.1:{}", free_port());
    let cfg = client(&dir.0, &session, &connect, &ours.join("ca.pem"), &ours);
    let err = station_says(&cfg, &session, &dir.0);
    assert!(
        cause_line(&err).ends_with(&format!(
            "the network cannot link: nothing listens on {connect}: is the router running?"
        )),
        "{err}"
    );
}

/// `session run --attach` without `--certs` against a TLS router, and with the certificates of
/// another session: each its own message, once, and the launcher fails.
#[test]
fn a_launcher_without_certificates_is_told_to_give_them() {
    let TwoCas {
        session,
        dir,
        other,
        connect,
        _router,
        ..
    } = two_cas_and_our_router();
    let launch = |certs: Option<&Path>| {
        let mut c = Command::new(SESSION_BIN);
        c.arg("run")
            .arg(coop_tests::scenario_path("paper.toml"))
            .args(["--attach", "--session", &session, "--method", "paper"])
            .args(["--connect", &connect, "--recordings"])
            .arg(dir.0.join("records"))
            .arg("--out")
            .arg(dir.0.join("out"));
        if let Some(d) = certs {
            c.arg("--certs").arg(d);
        }
        let out = c.output().expect("session run");
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(!out.status.success(), "the launcher fails: {err}");
        assert!(!err.contains("Unable to connect"), "{err}");
        err
    };
    let err = launch(None);
    let said = format!("{connect} is a TLS router and this launcher has no certificates: give --certs DIR, the directory `session certs` wrote");
    assert_eq!(err.matches(&said).count(), 1, "{err}");
    let err = launch(Some(&other));
    assert!(
        err.contains(&format!(
            "the router's certificate is not signed by the CA in --certs ({}): ",
            other.join("ca.pem").display()
        )),
        "{err}"
    );
}

/// A station given another site's certificate is refused before anything starts, naming the
/// field, the file, the name the certificate holds and the station's own.
#[test]
fn a_station_holding_another_sites_certificate_is_refused() {
    let session = unique_session();
    let dir = Dir::new(&session);
    let ours = certs(&session, &dir.0.join("ours"));
    let cert = ours.join("user2.pem");
    let cfg = {
        let (ca, cert) = (ours.join("ca.pem"), cert.clone());
        let key = ours.join("user2.key");
        station_config(&dir.0, &session, "user1", move |c| {
            c.network.mode = Mode::Client;
            c.network.connect = vec!["tls/127.0.0.1:7447".into()];
            c.network.tls = Some(Tls {
                root_ca_certificate: Some(ca),
                connect_certificate: Some(cert),
                connect_private_key: Some(key),
                enable_mtls: true,
                ..Tls::default()
            });
        })
    };
    let out = Command::new(STATION)
        .arg("run")
        .arg("--config")
        .arg(&cfg)
        .output()
        .expect("station run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "accepted: {err}");
    assert!(
        err.contains(&format!(
            "network.tls.connect_certificate = {:?}: is user2's certificate (common name \"user2\"), not station user1's",
            cert.display().to_string()
        )) && err.contains(&cfg.display().to_string()),
        "{err}"
    );
    assert!(!err.contains("running servo"), "nothing started: {err}");
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
}

/// A router whose listen port is taken is refused with the checked message (the field, the
/// locator, the rule and the file), not zenoh's listener error.
#[test]
fn a_router_on_a_taken_port_is_refused_naming_listen() {
    let session = unique_session();
    let dir = Dir::new(&session);
    let ours = certs(&session, &dir.0.join("ours"));
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = taken.local_addr().expect("addr").port();
    let cfg = router_config(&dir.0, &ours, &[format!("tls/127.0.0.1:{port}")]);
    let out = Command::new(STATION)
        .args(["router", "run", "--duration-s", "10", "--config"])
        .arg(&cfg)
        .output()
        .expect("router run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "accepted: {err}");
    assert!(
        err.contains(&format!(
            "router config {}: listen contains \"tls/127.0.0.1:{port}\": cannot listen there now (",
            cfg.display()
        )) && err.contains("choose a free port, or 0 for one chosen at start"),
        "{err}"
    );
    drop(taken);
}

/// A router connecting to another router that holds a certificate of another CA says so (zenoh
/// retries that link in the background without a word).
#[test]
fn a_router_says_why_its_link_to_another_router_fails() {
    let session = unique_session();
    let dir = Dir::new(&session);
    let ours = certs(&session, &dir.0.join("ours"));
    let other = certs(&format!("{session}o"), &dir.0.join("other"));
    let port = free_port();
    let _r = router(&dir.0, &ours, &[format!("tls/127.0.0.1:{port}")]);
    let second = dir.0.join("second");
    std::fs::create_dir_all(&second).expect("dir");
    let cfg = router_config(&second, &other, &[format!("tls/127.0.0.1:{}", free_port())]);
    let mut text = std::fs::read_to_string(&cfg).expect("config");
    text = text.replacen(
        "[tls]\n",
        &format!(
            "connect = [\"tls/127.0.0.1:{port}\"]\n[tls]\nconnect_certificate = {:?}\nconnect_private_key = {:?}\n",
            other.join("r1.pem"),
            other.join("r1.key")
        ),
        1,
    );
    std::fs::write(&cfg, text).expect("config");
    let err_file = second.join("r1.err");
    let r2 = Reaped::spawn(
        Command::new(STATION)
            .args(["router", "run", "--duration-s", "60", "--config"])
            .arg(&cfg)
            .stderr(std::fs::File::create(&err_file).expect("stderr file")),
    );
    let said = wait_until("the second router saying why", LIMIT, || {
        let err = std::fs::read_to_string(&err_file).unwrap_or_default();
        err.contains("router r1: the router's certificate is not signed by the CA in tls.root_ca_certificate")
            .then_some(err)
    });
    assert!(
        said.contains(&format!("tls/127.0.0.1:{port} presented one of another CA")),
        "{said}"
    );
    kill(Pid::from_raw(r2.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = r2.finish();
    assert!(status.success(), "exit {status}");
}

/// A station in peer mode whose TLS link to another side fails opens its session anyway (zenoh
/// retries the link without a word): its network process says why.
#[test]
fn a_peer_says_why_its_tls_link_fails() {
    let session = unique_session();
    let dir = Dir::new(&session);
    let ours = certs(&session, &dir.0.join("ours"));
    let other = certs(&format!("{session}o"), &dir.0.join("other"));
    let port = free_port();
    // Any TLS listener of the session's CA will do as the other side: the router.
    let _r = router(&dir.0, &ours, &[format!("tls/127.0.0.1:{port}")]);
    let connect = format!("tls/127.0.0.1:{port}");
    let cfg = {
        let (ca, connect) = (other.join("ca.pem"), connect.clone());
        let (cert, key) = (ours.join("user1.pem"), ours.join("user1.key"));
        station_config(&dir.0, &session, "user1", move |c| {
            c.network.connect = vec![connect];
            c.network.tls = Some(Tls {
                root_ca_certificate: Some(ca),
                connect_certificate: Some(cert),
                connect_private_key: Some(key),
                enable_mtls: true,
                ..Tls::default()
            });
        })
    };
    let err_file = dir.0.join("user1.err");
    let station = Reaped::spawn(
        Command::new(STATION)
            .arg("run")
            .arg("--config")
            .arg(&cfg)
            .stderr(std::fs::File::create(&err_file).expect("stderr file")),
    );
    let said = wait_until("the network process saying why", LIMIT, || {
        let err = std::fs::read_to_string(&err_file).unwrap_or_default();
        err.contains("network user1: the station's certificate is not signed by the CA in network.tls.root_ca_certificate")
            .then_some(err)
    });
    assert!(!said.contains("DEGRADED"), "a peer's session opens: {said}");
    kill(Pid::from_raw(station.pid() as i32), Signal::SIGTERM).expect("SIGTERM");
    let (status, _) = station.finish();
    assert!(status.success(), "exit {status}");
    assert!(shm_entries(&format!("coop_{session}_")).is_empty());
}
