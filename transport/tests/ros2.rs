//! ROS 2 interop: golden bytes for every message and the attachment, the keys and tokens
//! `rmw_zenoh` (Jazzy) writes, and the type hashes of the distribution. The CDR bytes were written
//! by `rosbags` (the reader ROS users record with) from the same values, the attachment by
//! `zenoh-ros2-sdk`; the hashes are those ROS 2 Jazzy's generated type descriptions carry (and
//! `zenoh-ros2-sdk` computes from the inline definitions: `tools/tests/fixtures/ros2_client.py
//! hashes`).

use coop_transport::ros2::cdr::{
    self, CdrError, Header, Log, PoseStamped, Time, TransformStamped, WrenchStamped,
};
use coop_transport::ros2::graph::{self, Attachment, Kind, Node, Qos};

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

const STAMP: Time = Time {
    sec: 1_764_900_000,
    nanosec: 123_456_789,
};

fn world() -> Header {
    Header {
        stamp: STAMP,
        frame_id: "world".into(),
    }
}

const POSE: &str = "00010000a03c326915cd5b0706000000776f726c64000000000000009a9999999999b93f000000000000d0bf7b14ae47e17aa43f0000000000000000000000000000000064a9aea6e27dd83f468d32cf6b90ed3f";
const WRENCH: &str = "00010000a03c3269050000000b00000075736572312f746f6f6c0000000000000000f83f00000000000000c0000000000000d03f000000000000000000000000000000000000000000000000";
const TF: &str = "0001000002000000a03c326915cd5b0706000000776f726c640000000b00000075736572312f6469736b00009a9999999999b93f9a9999999999c93f333333333333d33f000000000000000000000000000000000000000000000000000000000000f03fa03c326915cd5b0706000000776f726c640000000b00000075736572312f746f6f6c000000000000000000000000e0bf0000000000000000000000000000c03f000000000000000000000000000000000000000000000000000000000000f03f";
const LOG: &str = "00010000a13c3269070000001e0000000e000000636f6f702e73312e7573657231000000240000007573657232206c6f737420616674657220302e3530302073206f662073696c656e6365000100000000000000010000000000000000000000";

fn pose() -> PoseStamped {
    PoseStamped {
        header: world(),
        position: [0.1, -0.25, 0.04],
        orientation: [0.0, 0.0, 0.382_683_432_365_089_84, 0.923_879_532_511_286_7],
    }
}

fn transforms() -> Vec<TransformStamped> {
    vec![
        TransformStamped {
            header: world(),
            child_frame_id: "user1/disk".into(),
            translation: [0.1, 0.2, 0.3],
            rotation: [0.0, 0.0, 0.0, 1.0],
        },
        TransformStamped {
            header: world(),
            child_frame_id: "user1/tool".into(),
            translation: [-0.5, 0.0, 0.125],
            rotation: [0.0, 0.0, 0.0, 1.0],
        },
    ]
}

fn log() -> Log {
    Log {
        stamp: Time {
            sec: 1_764_900_001,
            nanosec: 7,
        },
        level: Log::WARN,
        name: "coop.s1.user1".into(),
        msg: "user2 lost after 0.500 s of silence".into(),
        ..Log::default()
    }
}

#[test]
fn every_message_is_the_bytes_rosbags_writes_and_reads_back() {
    assert_eq!(pose().encode(), hex(POSE));
    assert_eq!(PoseStamped::decode(&hex(POSE)), Ok(pose()));
    let wrench = WrenchStamped {
        header: Header {
            stamp: Time {
                sec: 1_764_900_000,
                nanosec: 5,
            },
            frame_id: "user1/tool".into(),
        },
        force: [1.5, -2.0, 0.25],
        torque: [0.0; 3],
    };
    assert_eq!(wrench.encode(), hex(WRENCH));
    assert_eq!(WrenchStamped::decode(&hex(WRENCH)), Ok(wrench));
    assert_eq!(cdr::encode_tf(&transforms()), hex(TF));
    assert_eq!(cdr::decode_tf(&hex(TF)), Ok(transforms()));
    assert_eq!(log().encode(), hex(LOG));
    assert_eq!(Log::decode(&hex(LOG)), Ok(log()));
}

#[test]
fn bad_bytes_are_refused_with_the_reason() {
    let good = hex(POSE);
    let mut big_endian = good.clone();
    big_endian[1] = 0x00;
    assert!(matches!(
        PoseStamped::decode(&big_endian),
        Err(CdrError::Encapsulation(_))
    ));
    // x of the position (at 28: encapsulation 4, stamp 8, frame id 4 + 6, padding to 8 from 4) NaN.
    let mut nan = good.clone();
    nan[28..36].copy_from_slice(&f64::NAN.to_le_bytes());
    assert_eq!(
        PoseStamped::decode(&nan),
        Err(CdrError::NotFinite("pose.position"))
    );
    let mut long = good.clone();
    long.extend_from_slice(&[0; 8]);
    assert_eq!(PoseStamped::decode(&long), Err(CdrError::Trailing(8)));
    // A frame id whose length runs past the end, and one without its NUL.
    let mut lying = good.clone();
    lying[12..16].copy_from_slice(&1_000_000u32.to_le_bytes());
    assert!(matches!(
        PoseStamped::decode(&lying),
        Err(CdrError::Truncated { .. })
    ));
    let mut no_nul = good.clone();
    no_nul[21] = b'x';
    assert_eq!(PoseStamped::decode(&no_nul), Err(CdrError::String(12)));
    // A NUL inside the frame id (a ROS string cannot hold one; found by `fuzz ros2`).
    let mut inner_nul = good.clone();
    inner_nul[18] = 0;
    assert_eq!(PoseStamped::decode(&inner_nul), Err(CdrError::String(12)));
    // A TFMessage claiming a billion transforms is refused before anything is allocated for them.
    let mut many = hex(TF);
    many[4..8].copy_from_slice(&1_000_000_000u32.to_le_bytes());
    assert!(matches!(
        cdr::decode_tf(&many),
        Err(CdrError::Truncated { .. })
    ));
    // Every prefix of a message short of its last field is an error for its own decoder, and no
    // decoder panics on any prefix of any message.
    type Check = fn(&[u8]) -> bool;
    let decoders: [(&str, Check); 4] = [
        (POSE, |b| PoseStamped::decode(b).is_err()),
        (WRENCH, |b| WrenchStamped::decode(b).is_err()),
        (TF, |b| cdr::decode_tf(b).is_err()),
        (LOG, |b| Log::decode(b).is_err()),
    ];
    for (m, refused) in decoders {
        let b = hex(m);
        for n in 0..b.len() - 3 {
            assert!(refused(&b[..n]), "a {n}-byte prefix of {m} was taken");
            for (_, other) in decoders {
                other(&b[..n]);
            }
        }
    }
}

#[test]
fn type_hashes_are_jazzy_s() {
    let hashes: Vec<(&str, &str)> = graph::TYPES.iter().map(|t| (t.name, t.hash)).collect();
    assert_eq!(
        hashes,
        [
            (
                "geometry_msgs/msg/PoseStamped",
                "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"
            ),
            (
                "geometry_msgs/msg/WrenchStamped",
                "RIHS01_8dc3deaf06b2ab281f9f9a742a8961c328ca7cec16e3fd6586d3a5c83fa78f77"
            ),
            (
                "tf2_msgs/msg/TFMessage",
                "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
            ),
            (
                "rcl_interfaces/msg/Log",
                "RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac"
            ),
        ]
    );
    for t in graph::TYPES {
        let (pkg, name) = (
            t.name.split('/').next().expect("package"),
            t.name.rsplit('/').next().expect("name"),
        );
        assert_eq!(t.dds, format!("{pkg}::msg::dds_::{name}_"));
    }
}

#[test]
fn keys_tokens_and_qos_are_rmw_zenoh_s() {
    assert_eq!(
        graph::topic_key(0, "/coop/s1/user1/tool", &graph::POSE_STAMPED),
        "0/coop/s1/user1/tool/geometry_msgs::msg::dds_::PoseStamped_/RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"
    );
    let node = Node {
        domain: 7,
        zid: "8b20917a2e7e4d5b9a2f1f4e6d5c3b2a".into(),
        id: 0,
        namespace: "/coop/s1/user1".into(),
        name: "station".into(),
    };
    assert_eq!(
        node.token(),
        "@ros2_lv/7/8b20917a2e7e4d5b9a2f1f4e6d5c3b2a/0/0/NN/%/%coop%s1%user1/station"
    );
    // rcl's own /rosout publisher writes exactly this QoS (reliable, transient local, 1000, 10 s).
    assert_eq!(
        node.endpoint_token(5, Kind::Publisher, "/rosout", &graph::LOG, Qos::ROSOUT),
        "@ros2_lv/7/8b20917a2e7e4d5b9a2f1f4e6d5c3b2a/0/5/MP/%/%coop%s1%user1/station/%rosout/rcl_interfaces::msg::dds_::Log_/RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac/:1:,1000:,:10,0:,,"
    );
    assert_eq!(Qos::STREAM.encode(), "2::,5:,:,:,,");
    let sub = node.endpoint_token(
        1,
        Kind::Subscription,
        "/coop/s1/user1/pose",
        &graph::POSE_STAMPED,
        Qos::STREAM,
    );
    assert!(
        sub.starts_with("@ros2_lv/7/8b20917a2e7e4d5b9a2f1f4e6d5c3b2a/0/1/MS/%/%coop%s1%user1/station/%coop%s1%user1%pose/"),
        "{sub}"
    );
    assert_eq!(graph::ros_name("s123-timewarp"), "s123_timewarp");
    assert_eq!(graph::ros_name("2nd"), "_2nd");
    assert_eq!(graph::mangle("/"), "%");
}

#[test]
fn the_attachment_is_sequence_time_and_gid() {
    let a = Attachment {
        seq: 1,
        source_ns: 1_764_900_000_123_456_789,
        gid: [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15],
    };
    // Written by zenoh-ros2-sdk's `Attachment(1, ts, bytes(range(16))).to_bytes()`.
    let golden = hex("0100000000000000150d7203332f7e1810000102030405060708090a0b0c0d0e0f");
    assert_eq!(a.encode().to_vec(), golden);
    assert_eq!(Attachment::decode(&golden), Some(a));
    assert_eq!(Attachment::decode(&golden[..32]), None);
    // A GID is rmw_zenoh's hash of the endpoint's token (pinned in `graph`'s own tests): two
    // endpoints of one node get two.
    let node = Node {
        domain: 0,
        zid: "8b20917a2e7e4d5b9a2f1f4e6d5c3b2a".into(),
        id: 0,
        namespace: "/coop/s1/user1".into(),
        name: "station".into(),
    };
    let token = |entity| {
        node.endpoint_token(
            entity,
            Kind::Publisher,
            "/coop/s1/user1/tool",
            &graph::POSE_STAMPED,
            Qos::STREAM,
        )
    };
    assert_ne!(graph::gid(&token(1)), graph::gid(&token(2)));
    assert_eq!(graph::gid(&token(1)), graph::gid(&token(1)));
}

#[test]
fn names_that_become_one_ros_name_are_refused() {
    use coop_transport::ros2::check_names;
    assert_eq!(check_names(["user1", "user2"], ["cup", "tray"]), Ok(()));
    let e = check_names(["a-b", "a_b"], []).expect_err("one namespace for two sites");
    assert!(e.contains("\"a-b\"") && e.contains("\"a_b\""), "{e}");
    assert!(check_names(["u"], ["big cup", "big_cup"]).is_err());
}
