//! ROS 2 without ROS: a station's poses, forces, frames and events as ROS 2 topics, and a ROS 2
//! haptic driver's end effector as a device, by following `rmw_zenoh`'s conventions on our own
//! zenoh session (no ROS installation, no DDS).
//!
//! - [`cdr`]: the messages (`PoseStamped`, `WrenchStamped`, `TFMessage`, `Log`) in CDR;
//! - [`graph`]: keys, liveliness tokens, QoS strings, attachments and type hashes (Jazzy);
//! - `network::ros2_publish`: the station's publisher, in the network process (off the real-time
//!   path);
//! - [`crate::ros2_device`]: `device = "ros2"`, a bridge thread between a driver's topics and the
//!   servo.
//!
//! `docs/ros2.md` says what a ROS 2 user sees and how to use it.

pub mod cdr;
pub mod graph;

use serde::{Deserialize, Serialize};

/// A station's `[ros2]` table: whether it publishes, in which domain, how often.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2Config {
    /// Publish this site's poses, force, frames and events as ROS 2 topics.
    pub publish: bool,
    /// The ROS domain (`ROS_DOMAIN_ID`), 0–232.
    pub domain_id: u32,
    /// At most this many samples per second on each stream topic.
    pub rate_hz: f64,
}

impl Default for Ros2Config {
    fn default() -> Self {
        Self {
            publish: false,
            domain_id: 0,
            rate_hz: 100.0,
        }
    }
}

/// The highest domain id ROS 2 allows.
pub const MAX_DOMAIN_ID: u32 = 232;

impl Ros2Config {
    /// Checks every value: the field, the value and the rule on failure.
    ///
    /// # Errors
    /// A domain above [`MAX_DOMAIN_ID`], or a rate that is not a positive number up to 1 kHz.
    pub fn validate(&self) -> Result<(), String> {
        if self.domain_id > MAX_DOMAIN_ID {
            return Err(format!(
                "ros2.domain_id = {}: must be 0..={MAX_DOMAIN_ID} (ROS 2's range)",
                self.domain_id
            ));
        }
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 1000.0) {
            return Err(format!(
                "ros2.rate_hz = {}: must be a number in (0, 1000]",
                self.rate_hz
            ));
        }
        Ok(())
    }

    /// The shortest time between two samples of a stream, ns.
    pub fn period_ns(&self) -> u64 {
        // Validated: positive and at most 1 kHz.
        (1e9 / self.rate_hz) as u64
    }
}

/// The namespace a site's topics live under: `/coop/<session>/<site>`, each made a ROS name.
pub fn namespace(session: &str, site: &str) -> String {
    format!(
        "/coop/{}/{}",
        graph::ros_name(session),
        graph::ros_name(site)
    )
}

/// Wall time now minus monotonic time now, ns: what turns a station's monotonic times into
/// `header.stamp`s (read at each use, so a stepped wall clock is followed).
pub fn wall_minus_monotonic_ns() -> i128 {
    let wall = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i128);
    wall - i128::from(coop_rt::timer::monotonic_ns())
}

/// A monotonic time as a ROS stamp, given [`wall_minus_monotonic_ns`].
pub fn stamp(monotonic_ns: u64, offset_ns: i128) -> cdr::Time {
    let wall = (i128::from(monotonic_ns) + offset_ns).max(0);
    cdr::Time::from_unix_ns(u64::try_from(wall).unwrap_or(u64::MAX))
}

/// A monotonic time as wall ns since the Unix epoch (an attachment's source time), given
/// [`wall_minus_monotonic_ns`]; 0 if it does not fit.
pub fn wall_ns(monotonic_ns: u64, offset_ns: i128) -> i64 {
    i64::try_from(i128::from(monotonic_ns) + offset_ns).unwrap_or(0)
}

/// Checks that the session's sites, and the world's objects, stay distinct as ROS names
/// ([`graph::ros_name`] makes `a-b` and `a_b` one name: two sites would then share a namespace,
/// and the access control could not tell their topics apart).
///
/// # Errors
/// The two names that collide, and the name they both become.
pub fn check_names<'a>(
    sites: impl IntoIterator<Item = &'a str>,
    objects: impl IntoIterator<Item = &'a str>,
) -> Result<(), String> {
    for (what, names) in [
        ("sites", sites.into_iter().collect::<Vec<_>>()),
        ("objects", objects.into_iter().collect::<Vec<_>>()),
    ] {
        let mut seen = std::collections::BTreeMap::new();
        for n in names {
            if let Some(other) = seen.insert(graph::ros_name(n), n) {
                return Err(format!(
                    "{what} {other:?} and {n:?} are both {:?} as ROS 2 names: rename one to publish as ROS 2 topics",
                    graph::ros_name(n)
                ));
            }
        }
    }
    Ok(())
}
