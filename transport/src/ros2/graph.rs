//! How a zenoh program appears in a ROS 2 graph under `rmw_zenoh` (ROS 2 Jazzy and later; its
//! `docs/design.md`): the data key of a topic, the liveliness tokens that declare a node and its
//! publishers and subscriptions, the QoS string inside them, and the attachment every sample
//! carries. Nothing here is ours to choose; a test pins every string and byte.

use std::fmt::Write as _;

/// A ROS 2 message type as `rmw_zenoh` names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MsgType {
    /// `package/msg/Name`, as `ros2 topic list -t` shows it.
    pub name: &'static str,
    /// The DDS name in keys and tokens: `package::msg::dds_::Name_`.
    pub dds: &'static str,
    /// The type description hash (REP 2011, `RIHS01_` + SHA-256) of ROS 2 Jazzy's definition.
    pub hash: &'static str,
}

/// `geometry_msgs/msg/PoseStamped`.
pub const POSE_STAMPED: MsgType = MsgType {
    name: "geometry_msgs/msg/PoseStamped",
    dds: "geometry_msgs::msg::dds_::PoseStamped_",
    hash: "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
};

/// `geometry_msgs/msg/WrenchStamped`.
pub const WRENCH_STAMPED: MsgType = MsgType {
    name: "geometry_msgs/msg/WrenchStamped",
    dds: "geometry_msgs::msg::dds_::WrenchStamped_",
    hash: "RIHS01_8dc3deaf06b2ab281f9f9a742a8961c328ca7cec16e3fd6586d3a5c83fa78f77",
};

/// `tf2_msgs/msg/TFMessage`.
pub const TF_MESSAGE: MsgType = MsgType {
    name: "tf2_msgs/msg/TFMessage",
    dds: "tf2_msgs::msg::dds_::TFMessage_",
    hash: "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
};

/// `rcl_interfaces/msg/Log`.
pub const LOG: MsgType = MsgType {
    name: "rcl_interfaces/msg/Log",
    dds: "rcl_interfaces::msg::dds_::Log_",
    hash: "RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac",
};

/// Every type a station speaks.
pub const TYPES: [MsgType; 4] = [POSE_STAMPED, WRENCH_STAMPED, TF_MESSAGE, LOG];

/// The key a topic's samples go on: `<domain>/<topic without its leading slash>/<dds type>/<hash>`.
pub fn topic_key(domain: u32, topic: &str, ty: &MsgType) -> String {
    format!(
        "{domain}/{}/{}/{}",
        topic.trim_start_matches('/'),
        ty.dds,
        ty.hash
    )
}

/// A name inside a liveliness token: `/` becomes `%`; the root namespace is `%`.
pub fn mangle(name: &str) -> String {
    if name.is_empty() || name == "/" {
        "%".into()
    } else {
        name.replace('/', "%")
    }
}

/// A ROS 2 name segment from one of ours: letters, digits and underscores stay, anything else
/// becomes `_`, and a leading digit gets a `_` before it (ROS names cannot start with one).
pub fn ros_name(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 1);
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        out.push('_');
    }
    out.extend(s.chars().map(|c| {
        if c.is_ascii_alphanumeric() || c == '_' {
            c
        } else {
            '_'
        }
    }));
    out
}

/// What a publisher promises, in the form `rmw_zenoh` writes into its tokens:
/// `<reliability>:<durability>:<history kind>,<depth>:<deadline>:<lifespan>:<liveliness>`, a field
/// empty where it is ROS's default (reliable, volatile, keep last, infinite durations, automatic).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Best effort rather than reliable.
    pub best_effort: bool,
    /// Transient local rather than volatile: a late subscriber gets the last `depth` samples.
    pub transient_local: bool,
    /// Keep the last this many.
    pub depth: u32,
    /// How long a sample stays worth delivering, whole seconds (`None`: for ever).
    pub lifespan_s: Option<u32>,
}

impl Qos {
    /// Streams: best effort, volatile, the last 5 (a late sample is worth less than the next).
    pub const STREAM: Qos = Qos {
        best_effort: true,
        transient_local: false,
        depth: 5,
        lifespan_s: None,
    };
    /// `/rosout`, as `rcl` declares it: reliable, transient local, the last 1000, for 10 s.
    pub const ROSOUT: Qos = Qos {
        best_effort: false,
        transient_local: true,
        depth: 1000,
        lifespan_s: Some(10),
    };

    /// The token's string.
    pub fn encode(&self) -> String {
        format!(
            "{}:{}:,{}:,:{}:,,",
            if self.best_effort { "2" } else { "" },
            if self.transient_local { "1" } else { "" },
            self.depth,
            self.lifespan_s.map_or(",".into(), |s| format!("{s},0"))
        )
    }
}

/// A node of the graph.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Node {
    /// The ROS domain.
    pub domain: u32,
    /// The zenoh session's id, as zenoh prints it.
    pub zid: String,
    /// The node's number within the zenoh session.
    pub id: u32,
    /// Its namespace, `/a/b`.
    pub namespace: String,
    /// Its name.
    pub name: String,
}

/// Publisher or subscription.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// `MP`.
    Publisher,
    /// `MS`.
    Subscription,
}

impl Node {
    /// Its token: `@ros2_lv/<domain>/<zid>/<id>/<id>/NN/%/<namespace>/<name>` (the `%` is the
    /// enclave: none).
    pub fn token(&self) -> String {
        format!(
            "@ros2_lv/{}/{}/{}/{}/NN/%/{}/{}",
            self.domain,
            self.zid,
            self.id,
            self.id,
            mangle(&self.namespace),
            mangle(&self.name)
        )
    }

    /// The token of its endpoint number `entity` on `topic`:
    /// `@ros2_lv/<domain>/<zid>/<node>/<entity>/MP|MS/%/<namespace>/<name>/<topic>/<dds type>/<hash>/<qos>`.
    pub fn endpoint_token(
        &self,
        entity: u32,
        kind: Kind,
        topic: &str,
        ty: &MsgType,
        qos: Qos,
    ) -> String {
        let mut s = format!(
            "@ros2_lv/{}/{}/{}/{entity}/{}/%/{}/{}/",
            self.domain,
            self.zid,
            self.id,
            match kind {
                Kind::Publisher => "MP",
                Kind::Subscription => "MS",
            },
            mangle(&self.namespace),
            mangle(&self.name)
        );
        // Writing to a String cannot fail.
        let _ = write!(
            s,
            "{}/{}/{}/{}",
            mangle(topic),
            ty.dds,
            ty.hash,
            qos.encode()
        );
        s
    }
}

/// What `rmw_zenoh` attaches to every sample: the publisher's sequence number, the time it
/// published (ns since the Unix epoch) and its 16-byte GID, as `i64`, `i64`, then the GID with
/// its length first (zenoh's serializer: a LEB128 length, one byte for 16).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    /// Counts the publisher's samples from 1.
    pub seq: i64,
    /// When, ns since the Unix epoch.
    pub source_ns: i64,
    /// The publisher's GID.
    pub gid: [u8; 16],
}

/// The attachment's length.
pub const ATTACHMENT_LEN: usize = 8 + 8 + 1 + 16;

impl Attachment {
    /// Its bytes.
    pub fn encode(&self) -> [u8; ATTACHMENT_LEN] {
        let mut b = [0u8; ATTACHMENT_LEN];
        b[..8].copy_from_slice(&self.seq.to_le_bytes());
        b[8..16].copy_from_slice(&self.source_ns.to_le_bytes());
        b[16] = 16;
        b[17..].copy_from_slice(&self.gid);
        b
    }

    /// From bytes (another publisher's: the ROS 2 device reads its driver's).
    pub fn decode(b: &[u8]) -> Option<Self> {
        if b.len() != ATTACHMENT_LEN || b[16] != 16 {
            return None;
        }
        let mut w = [0u8; 8];
        w.copy_from_slice(&b[..8]);
        let seq = i64::from_le_bytes(w);
        w.copy_from_slice(&b[8..16]);
        let source_ns = i64::from_le_bytes(w);
        let mut gid = [0u8; 16];
        gid.copy_from_slice(&b[17..]);
        Some(Self {
            seq,
            source_ns,
            gid,
        })
    }
}

/// The GID of the entity whose liveliness token is `token` (its 16 bytes, as the attachment carries
/// them and `ros2 topic info -v` shows them), as `rmw_zenoh` computes it (`Entity::Entity` in
/// `rmw_zenoh_cpp/src/detail/liveliness_utils.cpp`): XXH3's 128-bit hash of the whole token string
/// (`simplified_XXH3_128bits`, `rmw_zenoh_cpp/src/detail/simplified_xxhash3.cpp`: XXH3 with seed 0
/// and the default secret), its low 64 bits then its high 64, each little-endian (a `memcpy` of
/// `low64` then `high64` on a little-endian host). A reader that parses the token rebuilds the same
/// string and so the same GID.
pub fn gid(token: &str) -> [u8; 16] {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

/// The key zenoh-ext's `AdvancedPublisher` declares its liveliness token on and answers its cache's
/// queries on (its `publisher_detection` and `cache`; `rmw_zenoh` declares one for every transient
/// local publisher): `<topic key>/@adv/pub/<zid>/uhlc/_`. `uhlc` stands where a publisher that
/// numbers its samples puts its zenoh entity id (`rmw_zenoh`'s reliable transient-local publishers,
/// with zenoh-ext's sample miss detection): it tells an `AdvancedSubscriber` that this one's
/// samples are ordered by their timestamps instead. `_` is the empty metadata.
pub fn adv_key(topic_key: &str, zid: &str) -> String {
    format!("{topic_key}/@adv/pub/{zid}/uhlc/_")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `rmw_zenoh`'s GID of three tokens (a node's, 75 bytes; `/rosout`'s, 206; a long topic's,
    /// 251: XXH3's three paths for such lengths), from a Python port of `simplified_xxhash3.cpp`
    /// and, identically, xxHash's own `XXH3_128bits` (`xxhash` 3.x, `xxh3_128_intdigest`, its
    /// value's 16 little-endian bytes).
    #[test]
    fn the_gid_is_rmw_zenoh_s() {
        let zid = "8b20917a2e7e4d5b9a2f1f4e6d5c3b2a";
        let node = Node {
            domain: 7,
            zid: zid.into(),
            id: 0,
            namespace: "/coop/s1/user1".into(),
            name: "station".into(),
        };
        assert_eq!(
            gid(&node.token()),
            [
                0xea, 0x72, 0x09, 0x66, 0x4e, 0x84, 0x28, 0x94, 0xe1, 0xa0, 0xf1, 0x3f, 0x62, 0x97,
                0x74, 0x68
            ]
        );
        let rosout = node.endpoint_token(5, Kind::Publisher, "/rosout", &LOG, Qos::ROSOUT);
        assert_eq!(
            rosout,
            "@ros2_lv/7/8b20917a2e7e4d5b9a2f1f4e6d5c3b2a/0/5/MP/%/%coop%s1%user1/station/%rosout/rcl_interfaces::msg::dds_::Log_/RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac/:1:,1000:,:10,0:,,"
        );
        assert_eq!(
            gid(&rosout),
            [
                0x33, 0xa8, 0x80, 0xd2, 0xa8, 0xa9, 0x6e, 0x65, 0xf0, 0xaa, 0xf6, 0x0d, 0xe7, 0x38,
                0xec, 0xff
            ]
        );
        let long = Node {
            namespace: "/coop/s123_timewarp/user1".into(),
            ..node
        }
        .endpoint_token(
            3,
            Kind::Publisher,
            "/coop/s123_timewarp/user1/object/big_cup",
            &POSE_STAMPED,
            Qos::STREAM,
        );
        assert_eq!(long.len(), 251);
        assert_eq!(
            gid(&long),
            [
                0x74, 0x94, 0xfd, 0x7e, 0xa7, 0x79, 0x19, 0x58, 0x3f, 0xdd, 0xf6, 0x28, 0x93, 0xc2,
                0xba, 0xe1
            ]
        );
    }

    /// XXH3-128 on every one of its length paths (and their edges), against xxHash's own
    /// `XXH3_128bits` of the bytes `i % 251`.
    #[test]
    fn xxh3_128_is_xxhash_s() {
        let golden: [(usize, u128); 27] = [
            (0, 0x99aa06d3014798d86001c324468d497f),
            (1, 0xa6cd5e9392000f6ac44bdff4074eecdb),
            (3, 0xe3b55f57945a17cf5f4299fc161c9cbb),
            (4, 0xeb70bf5fc779e9e6a6111d53e80a3db5),
            (8, 0xe1e4432a62217fe4cfd50c61c8bb98c1),
            (9, 0x16c769d83e4aebce907931979dca3746),
            (16, 0x72950631827607e2842812cc870dcae2),
            (17, 0x685bc458b37d057fc06e233df7729217),
            (32, 0x25e7c9b3424ceed2457d9566b6fcd697),
            (33, 0x02175c3aabb00637e08d84951339de86),
            (64, 0x9c6e140a465545e590c1971ddb04ce74),
            (65, 0xebedf05eeadc28f11aee64a1615de88f),
            (96, 0xc57556e9ccb97efa6e53ab55b4f5558b),
            (97, 0x9b09227e063da5a25b3284a61f91e97d),
            (128, 0x14792fc3af88dc6c05321a0b64d67b41),
            (129, 0xdd5e74ac6b45f54ebc30b63382b09a3b),
            (159, 0xe34482de7831e5f6aea9455053a8845b),
            (160, 0x4e95c1cd6dc7bb85c67fcd13c31b09f4),
            (192, 0x10c987dc285c756b050f429c4f52b688),
            (240, 0x65b5be86da5540e7c92b68e16f83bbb6),
            (241, 0x1da1cb61bcb8a2a102e8cd95421c6d02),
            (256, 0x96c36c85d00e5bc544f5d90dacde463a),
            (1023, 0x4325711b0ed4d742d3d91d80ac495685),
            (1024, 0xd0ac1f7b93bf57b9e5d78bafa45b2aa5),
            (1025, 0x2882ebca04ec915ce95c42288f28186e),
            (2048, 0xa5141efedfefc1af25339063db861586),
            (3000, 0xd324b9e72fa9fb271b846747012c24aa),
        ];
        for (n, want) in golden {
            let d: Vec<u8> = (0..n).map(|i| (i % 251) as u8).collect();
            assert_eq!(xxhash_rust::xxh3::xxh3_128(&d), want, "{n} bytes");
        }
    }

    #[test]
    fn the_adv_key_is_zenoh_ext_s() {
        assert_eq!(
            adv_key(
                &topic_key(7, "/rosout", &LOG),
                "8b20917a2e7e4d5b9a2f1f4e6d5c3b2a"
            ),
            "7/rosout/rcl_interfaces::msg::dds_::Log_/RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac/@adv/pub/8b20917a2e7e4d5b9a2f1f4e6d5c3b2a/uhlc/_"
        );
    }
}
