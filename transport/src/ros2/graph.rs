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

/// A GID for endpoint `entity` of the zenoh session `zid` (its 16 bytes, as zenoh gives them):
/// the session's id with the entity number folded into its last bytes. Unique within a graph as
/// long as zenoh session ids are; opaque to every reader (`rmw_zenoh` hashes its token instead).
pub fn gid(zid: [u8; 16], entity: u32) -> [u8; 16] {
    let mut g = zid;
    for (b, e) in g[12..].iter_mut().zip(entity.to_le_bytes()) {
        *b ^= e;
    }
    g
}
