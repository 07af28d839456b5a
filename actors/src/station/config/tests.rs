//! Unit tests of the configuration: its rules, messages and resolution.

use std::path::Path;

use coop_model::scenario::MethodName;
use coop_rt::sched::Policy;
use coop_transport::network::Mode;

use super::*;
use crate::scenario_file;
use crate::testing::chain;

/// Parses and resolves a configuration's text; the refusal as the binaries print it.
fn resolve_text(text: &str) -> Result<(), String> {
    let c = toml::from_str::<StationConfig>(text).map_err(|e| chain(&e))?;
    c.resolve(None).map(drop).map_err(|e| chain(&e))
}

#[test]
fn timewarp_and_coupled_need_one_physics_rate() {
    for m in [MethodName::Timewarp, MethodName::Coupled] {
        let c = StationConfig {
            method: Some(m),
            ..StationConfig::default()
        };
        let mut sc = scenario_file::parse(DEFAULT_SCENARIO).expect("paper");
        c.clone()
            .resolve_with(None, sc.clone())
            .expect("the paper's sites share a physics rate");
        sc.site[1].physics_rate_hz = 500.0;
        let err = c.resolve_with(None, sc).expect_err("two rates");
        let err = format!("{err:#}");
        assert!(
            err.contains("site[1].physics_rate_hz = 500")
                && err.contains(&format!("method {} steps", m.as_str()))
                && err.contains("must equal site[0]'s"),
            "{err}"
        );
    }
}

/// Stations run a world of several objects, with rotational friction on the table, between
/// the objects and at the fingertips, under every method: their rings and wire carry every
/// object's state, every contact's torque, and every friction memory a snapshot holds.
#[test]
fn stations_take_a_world_of_several_objects_with_every_friction() {
    for (file, text) in [
        (
            "stack.toml",
            include_str!("../../../../scenarios/stack.toml"),
        ),
        ("tray.toml", include_str!("../../../../scenarios/tray.toml")),
        (
            "billiards.toml",
            include_str!("../../../../scenarios/billiards.toml"),
        ),
    ] {
        let sc = scenario_file::parse(text).expect(file);
        assert!(sc.objects.len() > 1, "{file}");
        for m in MethodName::ALL {
            let c = StationConfig {
                method: Some(m),
                ..StationConfig::default()
            };
            let r = c
                .resolve_with(None, sc.clone())
                .unwrap_or_else(|e| panic!("{file} under {}: {e:#}", m.as_str()));
            // The rings that carry a message per object grow with the world.
            let n = sc.objects.len().next_power_of_two();
            let d = coop_rt::shm::station::RingSlots::default();
            let slots = r.config.rings_for(sc.objects.len());
            assert_eq!(slots.object_slots, d.object_slots * n, "{file}");
            assert_eq!(slots.trace_slots, d.trace_slots * n, "{file}");
            assert_eq!(slots.tool_slots, d.tool_slots, "{file}");
        }
    }
}

#[test]
fn defaults_resolve_to_the_paper_scenario_first_site() {
    let r = StationConfig::default()
        .resolve(None)
        .expect("defaults are valid");
    assert_eq!((r.name.as_str(), r.site), ("user1", 0));
    assert_eq!(r.servo_sched.policy, Policy::Fifo);
    assert_eq!(r.scenario.name, "paper");
    assert_eq!(r.network_backoff.max, std::time::Duration::from_secs(5));
}

/// The servo's start limit covers its device's own start wait (a ROS 2 driver's first pose), so
/// a device that does not open ends with its own error rather than as a hung servo; the other
/// children keep `startup_timeout_ms`.
#[test]
fn the_servo_start_limit_covers_the_device_start_wait() {
    use coop_rt::shm::control::Child;
    use std::time::Duration;
    let c: StationConfig = toml::from_str(
        "[supervisor]\nstartup_timeout_ms = 3000\n\
         [device]\ndevice = \"ros2\"\n[device.ros2]\nfirst_pose_timeout_ms = 5000\n",
    )
    .expect("TOML");
    let r = c.resolve(None).expect("resolves");
    assert_eq!(r.startup_timeout(Child::Servo), Duration::from_millis(8000));
    assert_eq!(
        r.startup_timeout(Child::Physics),
        Duration::from_millis(3000)
    );
    assert_eq!(
        r.startup_timeout(Child::Network),
        Duration::from_millis(3000)
    );
    let sim = StationConfig::default().resolve(None).expect("defaults");
    assert_eq!(
        sim.startup_timeout(Child::Servo),
        Duration::from_millis(3000)
    );
}

#[test]
fn a_taken_listen_port_is_refused_before_start_and_a_free_one_passes() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = taken.local_addr().expect("addr").port();
    let mut c = StationConfig::default();
    c.network.listen = vec![format!("tcp/127.0.0.1:{port}")];
    let r = c
        .clone()
        .resolve(None)
        .expect("no look at the machine in resolve");
    let err = r.check_listen_ports_free().expect_err("taken");
    assert!(
        format!("{err:#}").contains(&format!(
            "network.listen contains \"tcp/127.0.0.1:{port}\": cannot listen there now"
        )),
        "{err:#}"
    );
    drop(taken);
    r.check_listen_ports_free().expect("free now");
    c.network.mode = Mode::Client;
    c.network.connect = vec!["tcp/127.0.0.1:7447".into()];
    let taken = std::net::TcpListener::bind(("127.0.0.1", port)).expect("bind again");
    c.resolve(None)
        .expect("valid")
        .check_listen_ports_free()
        .expect("a client does not listen");
    drop(taken);
}

#[test]
fn a_taken_live_view_port_is_refused_before_start_and_port_0_passes() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
    let port = taken.local_addr().expect("addr").port();
    let live = |addr: String| StationConfig {
        live: Some(addr),
        ..StationConfig::default()
    };
    let r = live(format!("127.0.0.1:{port}"))
        .resolve(None)
        .expect("no look at the machine in resolve");
    let err = r.check_listen_ports_free().expect_err("taken");
    assert!(
        format!("{err:#}").contains(&format!(
            "live = \"127.0.0.1:{port}\": cannot listen there now"
        )),
        "{err:#}"
    );
    live("127.0.0.1:0".into())
        .resolve(None)
        .expect("valid")
        .check_listen_ports_free()
        .expect("port 0 is chosen at start");
    drop(taken);
}

#[test]
fn a_recording_path_is_a_file_in_a_writable_directory_never_made() {
    let dir = std::env::temp_dir().join(format!("coop-rec-rules-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let with = |p: &Path| StationConfig {
        record: Some(p.to_owned()),
        ..StationConfig::default()
    };
    with(&dir.join("a.mcap")).resolve(None).expect("a new file");
    let err = with(&dir).resolve(None).expect_err("a directory");
    assert!(
        format!("{err:#}").contains("must be a regular file (it is a directory)"),
        "{err:#}"
    );
    let missing = dir.join("not-made/a.mcap");
    assert!(with(&missing).resolve(None).is_err());
    assert!(
        !dir.join("not-made").exists(),
        "validation made a directory"
    );
    // Relative to the config file's directory.
    std::fs::create_dir_all(dir.join("rec")).expect("dir");
    let r = with(Path::new("rec/a.mcap"))
        .resolve(Some(&dir))
        .expect("relative");
    assert_eq!(r.config.record, Some(dir.join("rec/a.mcap")));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_station_given_tls_presents_its_own_certificate() {
    for (text, needle) in [
        (
            "[network]\nmode = \"client\"\nconnect = [\"tls/192.0.2.1:7447\"]\n[network.tls]\nroot_ca_certificate = \"/dev/null\"",
            "network.tls.connect_certificate is missing: a station that connects over TLS presents its own certificate",
        ),
        (
            "[network]\nconnect = [\"tcp/127.0.0.1:7447\"]\naccess_control = \"/dev/null\"",
            "network.access_control = \"/dev/null\": needs [network.tls] with enable_mtls = true",
        ),
    ] {
        let err = resolve_text(text).expect_err(text);
        assert!(format!("{err:#}").contains(needle), "{text}: {err:#}");
    }
}

#[test]
fn each_rule_names_field_value_and_rule() {
    let cases: [(&str, &str); 33] = [
        (
            "trials = true",
            "start = \"now\": a study's station (trials = true) starts each trial at the time 0 the study runner announces",
        ),
        (
            "trials = true\nstart = \"session\"\n[device]\ndevice = \"openhaptics\"\nloop = \"vendor\"",
            "device.loop = \"vendor\": a study's station (trials = true) runs the servo loop itself",
        ),
        (
            "[device]\ndevice = \"haply\"\n[device.haply]\nurl = \"http://localhost:10001\"",
            "device.haply.url = \"http://localhost:10001\": must be a ws://host:port URL",
        ),
        (
            "[device]\ndevice = \"haply\"\n[device.haply]\nrate = 5",
            "device.haply: unknown field `rate`",
        ),
        (
            "[device.haply]\nurl = \"ws://localhost:10001\"",
            "device.haply: a table for backend \"haply\", but device = \"sim\"",
        ),
        (
            "[device]\ndevice = \"phantom\"",
            "unknown variant `phantom`, expected one of `sim`, `replay`, `haply`, `dhd`, `openhaptics`",
        ),
        (
            "[device]\nloop = \"vendor\"",
            "device.loop = \"vendor\": device \"sim\" cannot call the station from its own thread",
        ),
        (
            "[device]\ndevice = \"openhaptics\"",
            "device.loop = \"station\": device \"openhaptics\" runs its servo inside OpenHaptics' scheduler",
        ),
        (
            "[device]\ndevice = \"openhaptics\"\nloop = \"vendor\"\n[device.openhaptics]\nscheduler_rate_hz = 600",
            "device.openhaptics.scheduler_rate_hz = 600: must be 500, 1000 or 2000",
        ),
        (
            "[device.safety]\nmax_force_n = 0",
            "device.safety.max_force_n = 0: must be above 0 and at most 100 N",
        ),
        (
            "[device.safety]\nwatchdog_ms = 0.5",
            "device.safety.watchdog_ms = 0.5: must be from 1 and at most 10000 ms",
        ),
        (
            "[device.safety]\nmax_velocity_m_s = nan",
            "device.safety.max_velocity_m_s = NaN: must be above 0",
        ),
        (
            "[device.placement]\nworkspace_scale = 0",
            "device.placement.workspace_scale = 0: must be from 0.001 to 1000",
        ),
        (
            "[device.placement]\ntranslation_m = [0.1, 0, 0]",
            "must be the identity for device = \"sim\"",
        ),
        (
            "[device]\ndevice = \"replay\"",
            "device.replay.file is missing",
        ),
        (
            "[device]\ndevice = \"replay\"\n[device.replay]\nfile = \"/nonexistent-coop/hand.csv\"",
            "device.replay.file = \"/nonexistent-coop/hand.csv\": cannot be read",
        ),
        (
            "[device]\ndevice = \"dhd\"\n[device.dhd]\nwatchdog_ms = 40",
            "device.dhd.watchdog_ms = 40: must be 0 (off) or in 0.125..=31.875 ms",
        ),
        (
            "[supervisor]\nrestart = \"sometimes\"",
            "supervisor.restart = \"sometimes\"",
        ),
        (
            "[supervisor]\nheartbeat_timeout_ms = 0",
            "supervisor.heartbeat_timeout_ms = 0: must be from 10",
        ),
        ("session = \"a_b\"", "session = \"a_b\""),
        (
            "station = \"nobody\"",
            "station = \"nobody\": names no site",
        ),
        (
            "[servo]\npriority = 120",
            "servo: priority 120 is out of range",
        ),
        (
            "[physics]\npolicy = \"deadline\"",
            "physics.policy = \"deadline\"",
        ),
        (
            "[rings]\ntool_slots = 100",
            "rings.tool_slots = 100: must be a power of two",
        ),
        ("sesion = \"x\"", "unknown field `sesion`"),
        (
            "[network]\nlisten = [\"udp/127.0.0.1:0\"]",
            "network.listen contains \"udp/127.0.0.1:0\": transport \"udp\" is not in this build",
        ),
        (
            "[network]\nconnect = [\"tcp/127.0.0.1\"]",
            "network.connect contains \"tcp/127.0.0.1\": a zenoh locator looks like",
        ),
        (
            "[network]\nlisten = [\"tcp/0.0.0.0:7447\", \"tls/127.0.0.1:7447\"]",
            "the same port twice",
        ),
        (
            "[network]\nlisten = [\"tls/127.0.0.1:0\"]",
            "a tls/ locator needs a [network.tls] table with listen_certificate and listen_private_key",
        ),
        (
            "[network]\nconnect = [\"tls/127.0.0.1:7447\"]\n[network.tls]\nenable_mtls = true",
            "needs [network.tls] root_ca_certificate and connect_certificate (enable_mtls) and",
        ),
        (
            "record = \"/dev/full\"",
            "record = \"/dev/full\": must be a regular file (it is a device)",
        ),
        (
            "record = \"/nonexistent-coop-dir/a.mcap\"",
            "its directory \"/nonexistent-coop-dir\" cannot be used",
        ),
        (
            "[supervisor]\nbackoff_initial_ms = 100\nnetwork_backoff_max_ms = 50",
            "supervisor.network_backoff_max_ms = 50: must be from 100",
        ),
    ];
    for (text, needle) in cases {
        let err = resolve_text(text).expect_err(text);
        assert!(format!("{err:#}").contains(needle), "{text}: {err:#}");
    }
}
