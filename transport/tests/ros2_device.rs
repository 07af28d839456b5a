//! `device = "ros2"` against a driver on a real zenoh session in this process: a pose that is not
//! one is a fault, a second publisher's poses are refused, a servo that stops commanding leaves
//! the driver a zero wrench, and a silent driver makes the device stale; the servo's calls
//! allocate nothing.

#[path = "../../rt/tests/common/counting_alloc.rs"]
mod counting_alloc;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use coop_model::body::Vec3;
use coop_rt::device::{CartesianDevice, Command, DeviceFault};
use coop_rt::timer::monotonic_ns;
use coop_tests::wait_until;
use coop_transport::network::{concrete_listen, config, NetworkConfig};
use coop_transport::ros2::cdr::{Header, PoseStamped, WrenchStamped};
use coop_transport::ros2::graph::{self, Attachment};
use coop_transport::ros2_device::{Ros2Device, Ros2DeviceConfig};
use zenoh::Wait;

const LIMIT: Duration = Duration::from_secs(30);

fn pose(x: f64) -> Vec<u8> {
    PoseStamped {
        header: Header {
            frame_id: "device".into(),
            ..Header::default()
        },
        position: [x, 0.0, 0.1],
        orientation: [0.0, 0.0, 0.0, 1.0],
    }
    .encode()
}

fn attachment(gid: u8, seq: i64) -> Vec<u8> {
    Attachment {
        seq,
        source_ns: 0,
        gid: [gid; 16],
    }
    .encode()
    .to_vec()
}

#[test]
fn the_bridge_refuses_bad_and_foreign_poses_and_releases_a_driver_it_no_longer_commands() {
    let locator = concrete_listen(&["tcp/127.0.0.1:0".into()]).remove(0);
    let driver = zenoh::open(
        config(&NetworkConfig {
            listen: vec![locator.clone()],
            ..NetworkConfig::default()
        })
        .expect("config"),
    )
    .wait()
    .expect("the driver's session");
    let cfg = Ros2DeviceConfig {
        connect: vec![locator],
        // Long enough that this test's own steps, on a loaded machine, stay within it.
        stale_limit_ms: 500.0,
        first_pose_timeout_ms: 20_000,
        ..Ros2DeviceConfig::default()
    };
    let pose_key = graph::topic_key(0, &cfg.pose_topic, &graph::POSE_STAMPED);
    let wrenches: Arc<Mutex<Vec<[f64; 3]>>> = Arc::default();
    let w = wrenches.clone();
    let _sub = driver
        .declare_subscriber(graph::topic_key(
            0,
            &cfg.wrench_topic,
            &graph::WRENCH_STAMPED,
        ))
        .callback(move |s| {
            if let Ok(m) = WrenchStamped::decode(&s.payload().to_bytes()) {
                w.lock().expect("lock").push(m.force);
            }
        })
        .wait()
        .expect("subscriber");
    // The driver publishes its pose (GID 1) until the device has opened on it.
    let stop = Arc::new(coop_rt::sync::AtomicU64::new(0));
    let publisher = {
        let (d, k, stop) = (driver.clone(), pose_key.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut seq = 0;
            while stop.load(coop_rt::sync::Ordering::Relaxed) == 0 {
                seq += 1;
                let _ = d.put(&k, pose(0.01)).attachment(attachment(1, seq)).wait();
                std::thread::sleep(Duration::from_millis(1));
            }
        })
    };
    let mut dev = Ros2Device::open(&cfg).expect("the device opens on the driver's pose");
    let got = wait_until("a pose", LIMIT, || dev.sample(monotonic_ns()).ok());
    assert_eq!(got.position_m, Vec3::new(0.01, 0.0, 0.1));
    // The servo path: sample and command, while the bridge takes poses and puts wrenches.
    let mut taken = 0;
    let n = counting_alloc::allocations_during(|| {
        for k in 0..2000u32 {
            let now = monotonic_ns();
            if dev.sample(now).is_ok() {
                taken += 1;
            }
            let _ = dev.command(
                now,
                Command::Force(Vec3::new(0.0, 0.0, 1e-3 * f64::from(k % 7))),
            );
        }
    });
    assert_eq!(n, 0, "the servo's calls allocated {n} times");
    assert!(taken > 0);
    let put = |bytes: Vec<u8>, gid: u8| {
        driver
            .put(&pose_key, bytes)
            .attachment(attachment(gid, 1))
            .wait()
            .expect("put");
    };

    // A second publisher on the topic is refused and counted; the driver's poses go on. The
    // bridge's queue keeps the newest poses: one foreign pose may be pushed out by the driver's
    // stream while the bridge waits for a core, so the second publisher goes on publishing too.
    wait_until("the foreign pose refused", LIMIT, || {
        put(pose(0.5), 2);
        (dev.stats()
            .foreign_poses
            .load(coop_rt::sync::Ordering::Relaxed)
            > 0)
        .then_some(())
    });
    for _ in 0..50 {
        let s = dev.sample(monotonic_ns()).expect("fresh");
        assert!(
            s.position_m.x < 0.1,
            "a foreign pose reached the servo: {s:?}"
        );
        std::thread::sleep(Duration::from_millis(1));
    }

    // The driver's stream stops; from here the test puts each pose itself.
    stop.store(1, coop_rt::sync::Ordering::Relaxed);
    publisher.join().expect("publisher");

    // A pose that is not one is a fault until the next good one.
    put(b"not a pose".to_vec(), 1);
    wait_until("the bad pose as a fault", LIMIT, || {
        matches!(
            dev.sample(monotonic_ns()),
            Err(DeviceFault::BadValue { what: "pose" })
        )
        .then_some(())
    });
    put(pose(0.02), 1);
    wait_until("a good pose again", LIMIT, || {
        dev.sample(monotonic_ns()).ok()
    });

    // The servo commands a force, then stops commanding: the driver is left a zero wrench.
    dev.command(monotonic_ns(), Command::Force(Vec3::new(0.0, 0.0, 1.5)))
        .expect("command");
    wait_until("the force at the driver", LIMIT, || {
        wrenches
            .lock()
            .expect("lock")
            .last()
            .is_some_and(|f| f[2] == 1.5)
            .then_some(())
    });
    wait_until("the zero wrench after the servo went quiet", LIMIT, || {
        wrenches
            .lock()
            .expect("lock")
            .last()
            .is_some_and(|f| *f == [0.0; 3])
            .then_some(())
    });

    // The driver is silent: the device is stale.
    wait_until("the device stale", LIMIT, || {
        (dev.sample(monotonic_ns()) == Err(DeviceFault::Disconnected)).then_some(())
    });
    // And refuses a force on a hand it cannot see.
    assert_eq!(
        dev.command(monotonic_ns(), Command::Force(Vec3::new(1.0, 0.0, 0.0))),
        Err(DeviceFault::Disconnected)
    );
    dev.close();
    driver.close().wait().expect("close");
}
