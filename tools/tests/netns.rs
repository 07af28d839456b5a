//! Two stations in two network namespaces joined by a veth pair: real separate network stacks on one
//! machine, talking zenoh over TCP between 192.0.2.1 and 192.0.2.2 (a documentation range). The test
//! creates and removes its own namespaces and link, bounds its time, and is skipped with a message
//! where `ip netns` is not permitted (no root, no CAP_SYS_ADMIN, no iproute2).

use std::process::{Command, Stdio};
use std::time::Duration;

use coop_tests::{station_config, wait_until, Reaped, StationConfig};

/// Runs `ip` with `args`; `Err` with its message when it fails.
fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip {args:?}: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

/// The namespaces and the veth pair; removed on drop, whatever happened.
struct Netns {
    names: [String; 2],
}

impl Drop for Netns {
    fn drop(&mut self) {
        for n in &self.names {
            // Deleting a namespace deletes the veth end inside it, and with it its peer.
            let _ = ip(&["netns", "delete", n]);
        }
    }
}

fn setup(pid: u32) -> Result<Netns, String> {
    let ns = Netns {
        names: [format!("coopA{pid}"), format!("coopB{pid}")],
    };
    let (a, b) = (ns.names[0].as_str(), ns.names[1].as_str());
    ip(&["netns", "add", a])?;
    ip(&["netns", "add", b])?;
    let (va, vb) = (format!("cva{pid}"), format!("cvb{pid}"));
    ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])?;
    ip(&["link", "set", &va, "netns", a])?;
    ip(&["link", "set", &vb, "netns", b])?;
    for (n, dev, addr) in [(a, &va, "192.0.2.1/24"), (b, &vb, "192.0.2.2/24")] {
        ip(&["-n", n, "addr", "add", addr, "dev", dev])?;
        ip(&["-n", n, "link", "set", dev, "up"])?;
        ip(&["-n", n, "link", "set", "lo", "up"])?;
    }
    Ok(ns)
}

#[test]
fn two_stations_in_separate_network_namespaces_talk_over_tcp() {
    let pid = std::process::id();
    let ns = match setup(pid) {
        Ok(ns) => ns,
        Err(why) => {
            eprintln!("SKIPPED two_stations_in_separate_network_namespaces_talk_over_tcp: ip netns is not permitted here ({why})");
            return;
        }
    };
    let dir = std::env::temp_dir().join(format!("coop-netns-{pid}"));
    std::fs::create_dir_all(&dir).expect("dir");
    let session = format!("ns{pid}");
    let net = |listen: &'static str, connect: Option<&'static str>| {
        move |c: &mut StationConfig| {
            c.network.listen = vec![format!("tcp/{listen}:7447")];
            c.network.connect = connect.map(String::from).into_iter().collect();
        }
    };
    let a = station_config(&dir, &session, "user1", net("192.0.2.1", None));
    let b = station_config(
        &dir,
        &session,
        "user2",
        net("192.0.2.2", Some("tcp/192.0.2.1:7447")),
    );
    let station = env!("CARGO_BIN_EXE_station");
    let start = |n: &str, cfg: &std::path::Path| {
        Reaped::spawn(
            Command::new("ip")
                .args([
                    "netns",
                    "exec",
                    n,
                    station,
                    "run",
                    "--duration-s",
                    "60",
                    "--config",
                ])
                .arg(cfg)
                .stderr(Stdio::inherit()),
        )
    };
    let mut sa = start(&ns.names[0], &a);
    let mut sb = start(&ns.names[1], &b);
    let sites = ["user1".to_owned(), "user2".to_owned()];
    for (me, other) in [("user1", "user2"), ("user2", "user1")] {
        let v = wait_until(
            &format!("{me} receiving {other}'s states over the veth"),
            Duration::from_secs(60),
            || {
                let v = coop_actors::station::status::read(&session, me, &sites)
                    .ok()?
                    .to_json();
                let net = &v["network"];
                let peer_present = net["peers"]
                    .as_array()?
                    .iter()
                    .any(|p| p["site"] == other && p["present"] == true);
                (peer_present
                    && net["received"].as_u64()? > 100
                    && v["physics"]["remote_received"].as_u64()? > 100)
                    .then_some(v)
            },
        );
        let loc = v["network"]["locators"].as_str().unwrap_or("").to_owned();
        assert!(loc.contains("192.0.2."), "{me} listens on the veth: {loc}");
    }
    for s in [&mut sa, &mut sb] {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(s.pid() as i32),
            nix::sys::signal::Signal::SIGTERM,
        );
    }
    for s in [&mut sa, &mut sb] {
        let status = s
            .wait_timeout(Duration::from_secs(15))
            .expect("station stopped");
        assert!(status.success(), "a station stopped cleanly: {status}");
    }
    drop(ns);
    let _ = std::fs::remove_dir_all(&dir);
}
