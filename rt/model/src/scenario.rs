//! Scenarios as data: the world, the object, each site's rates, device, controller and user script,
//! the network, and the task phases to check. Parsed from TOML by the tools (serde, behind this
//! crate's `serde` feature); validated here, with errors that name the field, the value and the rule.
//!
//! This module holds the schema: the types a scenario file is read into, with their defaults.
//! `validate` holds its rules ([`Scenario::validate`]); `build` makes the model's parts from a
//! valid one (the world, each site's method, arm, servo and script).

use crate::body::Vec3;
use crate::contact::ContactParams;
use crate::controller::ControllerParams;
use crate::device::HandParams;
pub use crate::rules::ScenarioError;
use crate::shape::Shape;
#[cfg(doc)]
use crate::world::MAX_OBJECTS;

mod build;
mod validate;

pub use validate::{valid_name, NAME_RULE};

#[cfg(feature = "serde")]
use serde::{Deserialize, Serialize};

/// A consistency method by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, Serialize, schemars::JsonSchema),
    serde(rename_all = "lowercase")
)]
pub enum MethodName {
    /// Eq. 8 across the network: sum own and latest received forces.
    Naive,
    /// Eq. 10/11: own force only, adopt newer states, dead-reckon.
    #[default]
    Paper,
    /// Exchange the tools, roll back (deterministic physics on a common tick grid).
    Timewarp,
    /// Exchange the tools, play them from a jitter buffer, pull the copies together within an
    /// energy tank (no rollback).
    Coupled,
}

impl MethodName {
    /// Every method, in table order: the simulator and real stations run each.
    pub const ALL: [MethodName; 4] = [
        MethodName::Naive,
        MethodName::Paper,
        MethodName::Timewarp,
        MethodName::Coupled,
    ];
    /// Its name.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Naive => "naive",
            Self::Paper => "paper",
            Self::Timewarp => "timewarp",
            Self::Coupled => "coupled",
        }
    }
}

/// An object shape by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(rename_all = "lowercase")
)]
pub enum ShapeName {
    /// `radius_m`.
    Sphere,
    /// `radius_m`, `half_height_m` (axis z): the paper's disk.
    #[default]
    Cylinder,
    /// `half_extents_m`.
    Box,
}

/// A complete scenario.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct Scenario {
    /// Short name.
    pub name: String,
    /// What it shows.
    pub description: String,
    /// Seed of every random choice (sensor noise, network, the participants' motor noise).
    pub seed: u64,
    /// Seed the simulated participants are drawn with (their reaction times, reach and grip
    /// parameters), instead of `seed`: a study keeps the same people through trials whose runs
    /// differ.
    pub people_seed: Option<u64>,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Method for `sim run`.
    pub method: MethodName,
    /// Dead-reckoning order for `paper`: 0, 1 or 2.
    pub dead_reckoning_order: u8,
    /// Trace rows per second.
    pub sample_rate_hz: f64,
    /// The objects (`[object]` for one, `[[object]]` for several), 1 to [`MAX_OBJECTS`].
    #[cfg_attr(
        feature = "serde",
        serde(rename = "object", deserialize_with = "one_or_many")
    )]
    pub objects: Vec<ObjectSpec>,
    /// Gravity and environment.
    pub world: WorldSpec,
    /// Tool–object contact law.
    pub contact: ContactParams,
    /// Object–environment contact law.
    pub environment_contact: ContactParams,
    /// Object–object contact law (default: `environment_contact`'s).
    pub object_contact: Option<ContactParams>,
    /// Every link between sites (emulated network).
    pub network: LinkSpec,
    /// The sites, 1 to 8.
    pub site: Vec<SiteSpec>,
    /// Task phases to check per site.
    pub phase: Vec<PhaseSpec>,
    /// Display continuity and passivity of every site's servo.
    pub display: crate::display::DisplaySpec,
    /// The `timewarp` method's settings.
    pub timewarp: TimewarpSpec,
    /// When each site's task is done or has failed, judged live on what the site shows.
    pub task: crate::task::TaskSpec,
}

/// The `timewarp` method's settings (`[timewarp]`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct TimewarpSpec {
    /// History kept for rollbacks, ms: a received tool position older than this cannot be undone
    /// (it is counted as a fallback). 0 (the default): the largest delay, its jitter, the slowest
    /// report period and 100 ms; with `network.loss`, more for the reports it can lose in a row (see
    /// [`Scenario::timewarp_horizon_s`]). Otherwise at least the first three, at most 10 s (one snapshot
    /// per physics tick is kept, allocated at start).
    pub horizon_ms: f64,
    /// The own tool's local lag while a partner's is near the object, as a share of that
    /// partner's measured one-way delay, 0 to 1 (0: none; see
    /// [`crate::method::timewarp::LOCAL_LAG_SHARE`], the default).
    pub local_lag_share: f64,
    /// ... at most this, ms, 0 to [`MAX_LOCAL_LAG_MS`] (default
    /// [`crate::method::timewarp::LOCAL_LAG_MAX_TICKS`] at 1 kHz).
    pub local_lag_max_ms: f64,
    /// A rollback re-simulates only the objects a changed input reaches (true, the default), or
    /// every object (false): the same bits either way, only the cost differs (see
    /// `method/timewarp/islands.rs`; `sim bench` times both).
    pub islands: bool,
    /// A perceptual deadband on the own tool's positions (`[timewarp.deadband]`; off by default).
    pub deadband: crate::method::timewarp::DeadbandSpec,
}

impl Default for TimewarpSpec {
    fn default() -> Self {
        Self {
            horizon_ms: 0.0,
            local_lag_share: crate::method::timewarp::LOCAL_LAG_SHARE,
            local_lag_max_ms: crate::method::timewarp::LOCAL_LAG_MAX_TICKS as f64,
            islands: true,
            deadband: crate::method::timewarp::DeadbandSpec::default(),
        }
    }
}

/// The largest `timewarp.local_lag_max_ms`, ms (what the own tool's measured positions kept cover
/// at the fastest physics rate, [`crate::method::timewarp::MAX_LOCAL_LAG_TICKS`]).
pub const MAX_LOCAL_LAG_MS: f64 = 200.0;

/// The longest `timewarp.horizon_ms`, ms.
pub const MAX_HORIZON_MS: f64 = 10_000.0;

/// An object.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct ObjectSpec {
    /// Its name ([`NAME_RULE`]); a lone object's defaults to `object`, each of several needs one.
    pub name: String,
    /// Shape.
    pub shape: ShapeName,
    /// Radius (sphere, cylinder), m.
    pub radius_m: f64,
    /// Half height (cylinder), m.
    pub half_height_m: f64,
    /// Half extents (box), m.
    pub half_extents_m: [f64; 3],
    /// Mass, kg.
    pub mass_kg: f64,
    /// Initial centre of mass, m.
    pub start_m: [f64; 3],
    /// Initial orientation: turns about the world's x, then y, then z axis (roll, pitch, yaw), °.
    pub start_rpy_deg: [f64; 3],
    /// Initial velocity, m/s.
    pub velocity_m_per_s: [f64; 3],
    /// Initial angular velocity, world, rad/s.
    pub angular_velocity_rad_per_s: [f64; 3],
    /// A fixture: it never moves (tools and objects still touch it).
    pub fixed: bool,
}

/// `[object]` (one object) or `[[object]]` (several).
#[cfg(feature = "serde")]
fn one_or_many<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<ObjectSpec>, D::Error> {
    use serde::de::{value, MapAccess, SeqAccess, Visitor};
    struct OneOrMany;
    impl<'de> Visitor<'de> for OneOrMany {
        type Value = Vec<ObjectSpec>;
        fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("an [object] table or [[object]] tables")
        }
        fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
            Ok(vec![ObjectSpec::deserialize(
                value::MapAccessDeserializer::new(map),
            )?])
        }
        fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
            Vec::deserialize(value::SeqAccessDeserializer::new(seq))
        }
    }
    d.deserialize_any(OneOrMany)
}

/// Gravity and the environment.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct WorldSpec {
    /// Gravity, m/s².
    pub gravity_m_per_s2: [f64; 3],
    /// Planes bounding free space (floor, walls).
    pub planes: Vec<PlaneSpec>,
}

/// A plane: free space is where `normal · x ≥ offset_m`.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields)
)]
pub struct PlaneSpec {
    /// Normal into free space (normalised on load).
    pub normal: [f64; 3],
    /// Offset along the normal, m.
    pub offset_m: f64,
}

/// An emulated network link (applied to every ordered pair of sites).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct LinkSpec {
    /// Smallest one-way delay, ms.
    pub delay_min_ms: f64,
    /// Largest one-way delay, ms (the delay swings between min and max).
    pub delay_max_ms: f64,
    /// Period of the swing, s.
    pub delay_period_s: f64,
    /// Extra uniform jitter, ± ms (reorders messages when larger than the report period).
    pub jitter_ms: f64,
    /// Probability a message is lost, [0, 1).
    pub loss: f64,
}

/// One site: its user, device and rates.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct SiteSpec {
    /// Name (A-Z a-z 0-9 . -).
    pub name: String,
    /// Servo (device) rate, Hz.
    pub servo_rate_hz: f64,
    /// Physics rate, Hz.
    pub physics_rate_hz: f64,
    /// Report rate, Hz.
    pub report_rate_hz: f64,
    /// Device base (joint 1 axis), world, m.
    pub device_base_m: [f64; 3],
    /// Elbow configuration: 1 or -1.
    pub elbow: f64,
    /// Virtual tool tip radius, m.
    pub tool_radius_m: f64,
    /// Force sensor noise (standard deviation), N.
    pub sensor_noise_n: f64,
    /// Object states older than this are stale, ms.
    pub stale_limit_ms: f64,
    /// Ramp of the displayed force to zero when stale, ms.
    pub stale_ramp_ms: f64,
    /// Largest displayed-force step per servo tick an adoption may cause, N (without the
    /// `[display]` stages; with them, their step limiter bounds every correction).
    pub max_adoption_step_n: f64,
    /// The user's hand.
    pub hand: HandParams,
    /// The force controller.
    pub controller: ControllerParams,
    /// The user's script: keyframes (time, hand target).
    pub script: Vec<KeyframeSpec>,
    /// A recorded hand instead of the scripted one: a station's MCAP recording (its tool
    /// positions, timed from its session's start) or a CSV `t_s,x,y,z`, relative to the scenario
    /// file. The tool then follows the recording by position (the arm and the script only place
    /// the device at rest; it senses no force).
    pub hand_replay: Option<String>,
    /// The recorded hand, loaded from `hand_replay` by the scenario file's reader (the model does
    /// no I/O).
    #[cfg_attr(feature = "serde", serde(skip))]
    pub hand_trajectory: Option<crate::replay::Trajectory>,
    /// A simulated participant's task plan (`[[site.plan]]`): with one, the site's hand is a
    /// participant acting on what the site shows, and `script` only places it at the start.
    pub plan: Vec<crate::participant::StepSpec>,
    /// The participant's parameters (the population's means; each seed draws a person).
    pub participant: crate::participant::ParticipantSpec,
}

/// A script keyframe.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields)
)]
pub struct KeyframeSpec {
    /// Time, s.
    pub t_s: f64,
    /// Hand target, world, m.
    pub target_m: [f64; 3],
}

/// A task phase, checked per site on what that site saw.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, serde::Serialize, schemars::JsonSchema),
    serde(deny_unknown_fields, default)
)]
pub struct PhaseSpec {
    /// Name (push, catch, grasp, squeeze, release, ...).
    pub name: String,
    /// Window start, s.
    pub from_s: f64,
    /// Window end, s.
    pub to_s: f64,
    /// Sites whose user must touch the object in the window.
    pub contact: Vec<String>,
    /// Sites whose user must not touch it.
    pub no_contact: Vec<String>,
    /// Smallest peak displayed force for the `contact` sites, N.
    pub min_force_n: f64,
    /// Smallest displacement of each site's copy over the window, m.
    pub object_moves_m: f64,
    /// Each site's copy must rise this far above its start height in the window, m (0 = no check).
    pub lifted_m: f64,
    /// The object the phase is about, by name: `contact` and `no_contact` then mean touching
    /// that object, and `object_moves_m`, `lifted_m` and `region_m` are about it (empty: contact
    /// with any object, the rest about the first).
    pub object: String,
    /// Each site's copy of the object stays inside this box (lowest corner, highest corner, m)
    /// through the window: where it must rest (on another object, on a plane), or stay.
    pub region_m: Option<[[f64; 3]; 2]>,
}

impl Default for Scenario {
    fn default() -> Self {
        Self {
            name: "default".into(),
            description: String::new(),
            seed: 1,
            people_seed: None,
            duration_s: 10.0,
            method: MethodName::Paper,
            dead_reckoning_order: 2,
            sample_rate_hz: 200.0,
            objects: vec![ObjectSpec::default()],
            world: WorldSpec::default(),
            contact: ContactParams::default(),
            environment_contact: ContactParams {
                stiffness_n_per_m: 2000.0,
                ..ContactParams::default()
            },
            object_contact: None,
            network: LinkSpec::default(),
            site: Vec::new(),
            phase: Vec::new(),
            display: crate::display::DisplaySpec::default(),
            timewarp: TimewarpSpec::default(),
            task: crate::task::TaskSpec::default(),
        }
    }
}

impl ObjectSpec {
    /// Its shape.
    pub fn shape(&self) -> Shape {
        match self.shape {
            ShapeName::Sphere => Shape::Sphere {
                radius: self.radius_m,
            },
            ShapeName::Cylinder => Shape::Cylinder {
                radius: self.radius_m,
                half_height: self.half_height_m,
            },
            ShapeName::Box => Shape::Box {
                half: Vec3::from(self.half_extents_m),
            },
        }
    }
}

impl Default for ObjectSpec {
    fn default() -> Self {
        Self {
            name: String::new(),
            shape: ShapeName::Cylinder,
            radius_m: 0.04,
            half_height_m: 0.01,
            half_extents_m: [0.04, 0.04, 0.04],
            mass_kg: 0.1,
            start_m: [0.0, 0.0, 0.0],
            start_rpy_deg: [0.0; 3],
            velocity_m_per_s: [0.0; 3],
            angular_velocity_rad_per_s: [0.0; 3],
            fixed: false,
        }
    }
}

impl Default for WorldSpec {
    fn default() -> Self {
        Self {
            gravity_m_per_s2: [0.0, -9.81 / 3.0, 0.0],
            planes: vec![PlaneSpec {
                normal: [0.0, 1.0, 0.0],
                offset_m: -0.1,
            }],
        }
    }
}

impl Default for LinkSpec {
    fn default() -> Self {
        Self {
            delay_min_ms: 0.0,
            delay_max_ms: 0.0,
            delay_period_s: 5.0,
            jitter_ms: 0.0,
            loss: 0.0,
        }
    }
}

impl Default for SiteSpec {
    fn default() -> Self {
        Self {
            name: "site".into(),
            servo_rate_hz: 1000.0,
            physics_rate_hz: 1000.0,
            report_rate_hz: 100.0,
            device_base_m: [-0.45, -0.05, 0.0],
            elbow: 1.0,
            tool_radius_m: 0.005,
            sensor_noise_n: 0.0,
            stale_limit_ms: 100.0,
            stale_ramp_ms: 50.0,
            max_adoption_step_n: 0.5,
            hand: HandParams::default(),
            controller: ControllerParams::default(),
            script: Vec::new(),
            hand_replay: None,
            hand_trajectory: None,
            plan: Vec::new(),
            participant: crate::participant::ParticipantSpec::default(),
        }
    }
}

impl Default for PhaseSpec {
    fn default() -> Self {
        Self {
            name: String::new(),
            from_s: 0.0,
            to_s: 0.0,
            contact: Vec::new(),
            no_contact: Vec::new(),
            min_force_n: 0.0,
            object_moves_m: 0.0,
            lifted_m: 0.0,
            object: String::new(),
            region_m: None,
        }
    }
}
