//! Scenarios as data: the world, the object, each site's rates, device, controller and user script,
//! the network, and the task phases to check. Parsed from TOML by the tools (serde, behind this
//! crate's `serde` feature); validated here, with errors that name the field, the value and the rule.

use crate::body::{BodyState, Vec3};
use crate::contact::{pair_wrench, ContactParams, PairContactState, PairSide, Plane, MAX_PLANES};
use crate::controller::ControllerParams;
use crate::device::{HandParams, ScaraParams};
use crate::method::{Consistency, Coupled, Naive, Paper, TimeWarp, WorldCopy};
pub use crate::rules::ScenarioError;
use crate::rules::{bounded, err, finite3, in_closed, in_range};
use crate::servo::ServoParams;
use crate::shape::Shape;
use crate::user::Keyframe;
use crate::world::{Body, World, MAX_OBJECTS, MAX_SITES};

#[cfg(feature = "serde")]
use serde::{Deserialize, Serialize};

/// A consistency method by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize, Serialize),
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
    derive(Deserialize),
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
    derive(Deserialize),
    serde(deny_unknown_fields, default)
)]
pub struct Scenario {
    /// Short name.
    pub name: String,
    /// What it shows.
    pub description: String,
    /// Seed of every random choice (sensor noise, network).
    pub seed: u64,
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
}

/// The `timewarp` method's settings (`[timewarp]`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(Deserialize),
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
    derive(Deserialize),
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
    derive(Deserialize),
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
#[cfg_attr(feature = "serde", derive(Deserialize), serde(deny_unknown_fields))]
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
    derive(Deserialize),
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
    derive(Deserialize),
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
}

/// A script keyframe.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "serde", derive(Deserialize), serde(deny_unknown_fields))]
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
    derive(Deserialize),
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

fn validate_contact(c: &ContactParams, at: &str) -> Result<(), ScenarioError> {
    in_range(
        &format!("{at}.stiffness_n_per_m"),
        c.stiffness_n_per_m,
        0.0,
        1e6,
    )?;
    in_closed(
        &format!("{at}.damping_n_s_per_m"),
        c.damping_n_s_per_m,
        0.0,
        1e4,
    )?;
    in_range(
        &format!("{at}.tangential_stiffness_n_per_m"),
        c.tangential_stiffness_n_per_m,
        0.0,
        1e6,
    )?;
    in_closed(
        &format!("{at}.tangential_damping_n_s_per_m"),
        c.tangential_damping_n_s_per_m,
        0.0,
        1e4,
    )?;
    in_closed(
        &format!("{at}.friction_static"),
        c.friction_static,
        0.0,
        10.0,
    )?;
    in_closed(
        &format!("{at}.friction_kinetic"),
        c.friction_kinetic,
        0.0,
        c.friction_static,
    )
    .map_err(|e| ScenarioError {
        rule: format!("{} (no more than friction_static)", e.rule),
        ..e
    })?;
    bounded(
        &format!("{at}.rotational_friction_radius_m"),
        c.rotational_friction_radius_m,
        0.0,
        0.5,
        "m",
    )
}

/// The rule for scenario and site names, which key expressions and segment names carry: 1 to 48
/// characters from A-Z a-z 0-9 . -, starting with a letter or digit (so no `.`, `..` or `-x`).
pub const NAME_RULE: &str =
    "1 to 48 characters from A-Z a-z 0-9 . -, starting with a letter or digit";

/// Whether `s` keeps [`NAME_RULE`].
pub fn valid_name(s: &str) -> bool {
    (1..=48).contains(&s.len())
        && s.as_bytes()[0].is_ascii_alphanumeric()
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'.' || b == b'-')
}

impl Scenario {
    /// Checks every value; the first broken rule is the error.
    ///
    /// # Errors
    /// A [`ScenarioError`] naming the field, the value and the rule.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        if !valid_name(&self.name) {
            return Err(err("name", &self.name, NAME_RULE));
        }
        bounded("duration_s", self.duration_s, 0.01, 3600.0, "s")?;
        if self.dead_reckoning_order > 2 {
            return Err(err(
                "dead_reckoning_order",
                self.dead_reckoning_order,
                "must be 0, 1 or 2",
            ));
        }
        bounded("sample_rate_hz", self.sample_rate_hz, 1.0, 10_000.0, "Hz")?;
        self.validate_objects()?;
        finite3(
            "world.gravity_m_per_s2",
            &self.world.gravity_m_per_s2,
            100.0,
        )?;
        if self.world.planes.len() > MAX_PLANES {
            return Err(err(
                "world.planes",
                self.world.planes.len(),
                format!("at most {MAX_PLANES} planes"),
            ));
        }
        for (i, p) in self.world.planes.iter().enumerate() {
            finite3(&format!("world.planes[{i}].normal"), &p.normal, 1e3)?;
            if Vec3::from(p.normal).norm() < 1e-9 {
                return Err(err(
                    format!("world.planes[{i}].normal"),
                    p.normal,
                    "must not be zero",
                ));
            }
            in_closed(
                &format!("world.planes[{i}].offset_m"),
                p.offset_m,
                -100.0,
                100.0,
            )?;
        }
        validate_contact(&self.contact, "contact")?;
        self.display.validate()?;
        validate_contact(&self.environment_contact, "environment_contact")?;
        if let Some(c) = &self.object_contact {
            validate_contact(c, "object_contact")?;
        }
        let n = &self.network;
        in_closed("network.delay_min_ms", n.delay_min_ms, 0.0, 10_000.0)?;
        in_closed(
            "network.delay_max_ms",
            n.delay_max_ms,
            n.delay_min_ms,
            10_000.0,
        )
        .map_err(|e| ScenarioError {
            rule: format!("{} (and at least delay_min_ms)", e.rule),
            ..e
        })?;
        bounded(
            "network.delay_period_s",
            n.delay_period_s,
            0.01,
            3600.0,
            "s",
        )?;
        in_closed("network.jitter_ms", n.jitter_ms, 0.0, 10_000.0)?;
        if !(n.loss >= 0.0 && n.loss < 1.0) {
            return Err(err(
                "network.loss",
                n.loss,
                "must be a probability from 0 up to (not including) 1",
            ));
        }
        if self.site.is_empty() || self.site.len() > MAX_SITES {
            return Err(err(
                "site",
                self.site.len(),
                format!("a scenario has 1 to {MAX_SITES} sites"),
            ));
        }
        for (i, s) in self.site.iter().enumerate() {
            let at = |f: &str| format!("site[{i}].{f}");
            if !valid_name(&s.name) {
                return Err(err(at("name"), &s.name, NAME_RULE));
            }
            if self.site[..i].iter().any(|o| o.name == s.name) {
                return Err(err(at("name"), &s.name, "site names must be unique"));
            }
            bounded(&at("servo_rate_hz"), s.servo_rate_hz, 100.0, 20_000.0, "Hz")?;
            bounded(
                &at("physics_rate_hz"),
                s.physics_rate_hz,
                100.0,
                20_000.0,
                "Hz",
            )?;
            bounded(
                &at("report_rate_hz"),
                s.report_rate_hz,
                0.1,
                s.physics_rate_hz,
                "Hz",
            )
            .map_err(|e| ScenarioError {
                rule: format!("{} (physics_rate_hz)", e.rule),
                ..e
            })?;
            finite3(&at("device_base_m"), &s.device_base_m, 100.0)?;
            if s.elbow != 1.0 && s.elbow != -1.0 {
                return Err(err(at("elbow"), s.elbow, "must be 1 or -1"));
            }
            bounded(&at("tool_radius_m"), s.tool_radius_m, 1e-4, 1.0, "m")?;
            in_closed(&at("sensor_noise_n"), s.sensor_noise_n, 0.0, 100.0)?;
            bounded(&at("stale_limit_ms"), s.stale_limit_ms, 1.0, 60_000.0, "ms")?;
            bounded(&at("stale_ramp_ms"), s.stale_ramp_ms, 1.0, 60_000.0, "ms")?;
            in_range(
                &at("max_adoption_step_n"),
                s.max_adoption_step_n,
                0.0,
                1000.0,
            )?;
            let h = &s.hand;
            bounded(&at("hand.mass_kg"), h.mass_kg, 1e-3, 100.0, "kg")?;
            in_range(&at("hand.stiffness_n_per_m"), h.stiffness_n_per_m, 0.0, 1e5)?;
            in_closed(&at("hand.damping_n_s_per_m"), h.damping_n_s_per_m, 0.0, 1e4)?;
            in_range(
                &at("hand.grip_stiffness_n_per_m"),
                h.grip_stiffness_n_per_m,
                0.0,
                1e6,
            )?;
            in_closed(
                &at("hand.grip_damping_n_s_per_m"),
                h.grip_damping_n_s_per_m,
                0.0,
                1e4,
            )?;
            let c = &s.controller;
            in_closed(&at("controller.kp"), c.kp, 0.0, 100.0)?;
            in_closed(&at("controller.ki"), c.ki, 0.0, 10_000.0)?;
            in_range(&at("controller.max_force_n"), c.max_force_n, 0.0, 1000.0)?;
            in_range(
                &at("controller.max_force_rate_n_per_s"),
                c.max_force_rate_n_per_s,
                0.0,
                1e7,
            )?;
            if s.script.is_empty() {
                return Err(err(at("script"), "[]", "needs at least one keyframe"));
            }
            if let Some(file) = &s.hand_replay {
                if s.hand_trajectory.is_none() {
                    return Err(err(
                        at("hand_replay"),
                        file,
                        "was not loaded: read the scenario from its file",
                    ));
                }
            }
            let arm = self.arm(i);
            for (k, f) in s.script.iter().enumerate() {
                in_closed(&at(&format!("script[{k}].t_s")), f.t_s, 0.0, 3600.0)?;
                if k > 0 && f.t_s < s.script[k - 1].t_s {
                    return Err(err(
                        at(&format!("script[{k}].t_s")),
                        f.t_s,
                        "keyframes must be in time order",
                    ));
                }
                finite3(&at(&format!("script[{k}].target_m")), &f.target_m, 100.0)?;
                if arm.inverse(Vec3::from(f.target_m), s.elbow).is_none() {
                    return Err(err(
                        at(&format!("script[{k}].target_m")),
                        f.target_m,
                        format!(
                            "outside the device's reach ({} m around device_base_m)",
                            arm.link1_m + arm.link2_m
                        ),
                    ));
                }
            }
        }
        self.validate_stability()?;
        self.validate_start()?;
        self.validate_horizon()?;
        self.validate_local_lag()?;
        for (i, p) in self.phase.iter().enumerate() {
            let at = |f: &str| format!("phase[{i}].{f}");
            if p.name.is_empty() {
                return Err(err(at("name"), &p.name, "must not be empty"));
            }
            in_closed(&at("from_s"), p.from_s, 0.0, self.duration_s)?;
            in_closed(&at("to_s"), p.to_s, p.from_s, self.duration_s).map_err(|e| {
                ScenarioError {
                    rule: format!("{} (from_s to duration_s)", e.rule),
                    ..e
                }
            })?;
            for name in p.contact.iter().chain(&p.no_contact) {
                if !self.site.iter().any(|s| &s.name == name) {
                    return Err(err(at("contact"), name, "names no site of this scenario"));
                }
            }
            in_closed(&at("min_force_n"), p.min_force_n, 0.0, 1000.0)?;
            if !p.object.is_empty()
                && !(0..self.objects.len()).any(|k| self.object_name(k) == p.object)
            {
                return Err(err(
                    at("object"),
                    &p.object,
                    "names no object of this scenario",
                ));
            }
            if let Some([lo, hi]) = &p.region_m {
                finite3(&at("region_m[0]"), lo, 100.0)?;
                finite3(&at("region_m[1]"), hi, 100.0)?;
                if lo.iter().zip(hi).any(|(a, b)| a > b) {
                    return Err(err(
                        at("region_m"),
                        format!("{lo:?} .. {hi:?}"),
                        "the second corner must be at least the first in x, y and z",
                    ));
                }
            }
            in_closed(&at("object_moves_m"), p.object_moves_m, 0.0, 100.0)?;
            in_closed(&at("lifted_m"), p.lifted_m, 0.0, 100.0)?;
        }
        Ok(())
    }

    /// The largest delay, its jitter and the slowest report period, s: how late a tool position
    /// can arrive, the least history `timewarp` needs.
    fn latest_arrival_s(&self) -> f64 {
        (self.network.delay_max_ms + self.network.jitter_ms) * 1e-3 + self.slowest_report_period_s()
    }

    /// `timewarp.horizon_ms`: 0 (derived), or covering [`Self::latest_arrival_s`], at most
    /// [`MAX_HORIZON_MS`].
    fn validate_horizon(&self) -> Result<(), ScenarioError> {
        let h = self.timewarp.horizon_ms;
        if h == 0.0 {
            return Ok(());
        }
        let least_ms = self.latest_arrival_s() * 1e3;
        if !(h.is_finite() && h >= least_ms && h <= MAX_HORIZON_MS) {
            return Err(err(
                "timewarp.horizon_ms",
                h,
                format!(
                    "must cover the largest delay, its jitter and the slowest report period \
                     ({least_ms:.1} ms) and be at most {MAX_HORIZON_MS} ms; 0 derives it \
                     (that + 100 ms)"
                ),
            ));
        }
        Ok(())
    }

    /// `timewarp.local_lag_share` in 0..=1 and `timewarp.local_lag_max_ms` in
    /// 0..=[`MAX_LOCAL_LAG_MS`].
    fn validate_local_lag(&self) -> Result<(), ScenarioError> {
        let tw = &self.timewarp;
        if !(tw.local_lag_share.is_finite() && (0.0..=1.0).contains(&tw.local_lag_share)) {
            return Err(err(
                "timewarp.local_lag_share",
                tw.local_lag_share,
                "must be from 0 (no local lag) to 1 (the partners' whole delay)",
            ));
        }
        let most = MAX_LOCAL_LAG_MS;
        if !(tw.local_lag_max_ms.is_finite() && (0.0..=most).contains(&tw.local_lag_max_ms)) {
            return Err(err(
                "timewarp.local_lag_max_ms",
                tw.local_lag_max_ms,
                format!("must be from 0 to {most} ms"),
            ));
        }
        let d = &tw.deadband;
        let rules: [(&str, f64, bool, &str); 4] = [
            (
                "timewarp.deadband.weber_fraction",
                d.weber_fraction,
                d.weber_fraction > 0.0 && d.weber_fraction <= 1.0,
                "must be above 0 and at most 1 (a share of the contact force)",
            ),
            (
                "timewarp.deadband.floor_n",
                d.floor_n,
                d.floor_n > 0.0 && d.floor_n <= 10.0,
                "must be above 0 and at most 10 N",
            ),
            (
                "timewarp.deadband.near_m",
                d.near_m,
                (0.0..=1.0).contains(&d.near_m),
                "must be from 0 to 1 m",
            ),
            (
                "timewarp.deadband.free_space_m",
                d.free_space_m,
                d.free_space_m > 0.0 && d.free_space_m <= 0.1,
                "must be above 0 and at most 0.1 m",
            ),
        ];
        for (field, value, ok, rule) in rules {
            if !(value.is_finite() && ok) {
                return Err(err(field, value, rule));
            }
        }
        Ok(())
    }

    /// The integrator's stability rule: the object, in the stiffest contact it can be in at once
    /// along one direction (every site's tool and two planes, normal or tangential, whichever is
    /// stiffer), with the damping of those contacts, is a mass-spring-damper whose fastest mode is
    /// |λ|. Every site's physics step dt must keep |λ|·dt ≤ 1: half the limit (2) of the step's
    /// explicit force evaluation, the margin left for rotation (a lever arm over an inertia) and
    /// for penalty forces that are not quite linear. Beyond it a contact pumps energy into the
    /// object and throws it out of the world.
    fn validate_stability(&self) -> Result<(), ScenarioError> {
        let (c, e) = (&self.contact, &self.environment_contact);
        let o = self.object_law();
        let users = self.site.len() as f64;
        let planes = self.world.planes.len().min(2) as f64;
        // With several objects, one may be pressed between two others (a stack's middle box).
        let neighbours = if self.objects.len() > 1 { 2.0 } else { 0.0 };
        let k = users * c.stiffness_n_per_m.max(c.tangential_stiffness_n_per_m)
            + planes * e.stiffness_n_per_m.max(e.tangential_stiffness_n_per_m)
            + neighbours * o.stiffness_n_per_m.max(o.tangential_stiffness_n_per_m);
        let d = users * c.damping_n_s_per_m.max(c.tangential_damping_n_s_per_m)
            + planes * e.damping_n_s_per_m.max(e.tangential_damping_n_s_per_m)
            + neighbours * o.damping_n_s_per_m.max(o.tangential_damping_n_s_per_m);
        // The lightest object that moves is the fastest.
        let (lightest, m) = self
            .objects
            .iter()
            .enumerate()
            .filter(|(_, o)| !o.fixed)
            .map(|(i, o)| (i, o.mass_kg))
            .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
        if !m.is_finite() {
            return Ok(()); // nothing moves
        }
        let (omega2, gamma) = (k / m, d / m);
        // The roots of λ² + γλ + ω² = 0: complex (|λ| = ω) or real (the larger one).
        let disc = gamma * gamma / 4.0 - omega2;
        let lambda = if disc > 0.0 {
            gamma / 2.0 + disc.sqrt()
        } else {
            omega2.sqrt()
        };
        let (mass_field, laws, what) = if self.objects.len() > 1 {
            (
                format!("{}.mass_kg", self.object_field(lightest)),
                "contact, environment_contact and object_contact",
                "every tool, two planes and two other objects at once",
            )
        } else {
            (
                "object.mass_kg".to_string(),
                "contact and environment_contact",
                "every tool and two planes at once",
            )
        };
        for (i, s) in self.site.iter().enumerate() {
            let dt = 1.0 / s.physics_rate_hz;
            if lambda * dt > 1.0 || !lambda.is_finite() {
                return Err(err(
                    format!("site[{i}].physics_rate_hz"),
                    s.physics_rate_hz,
                    format!(
                        "too slow for the contacts: with {mass_field} = {m}, {laws} \
                         stiffness {k:.0} N/m and damping {d:.1} N·s/m in all \
                         ({what}), the fastest mode is {lambda:.0} 1/s, \
                         and the rule |λ|·dt ≤ 1 needs at least {:.0} Hz (or softer contacts, or \
                         a heavier object)",
                        lambda.ceil()
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The object must start outside every plane of the environment (up to 1 mm of contact sag):
    /// a start inside a wall would be ejected by the penalty force at kilometres per second.
    fn validate_start(&self) -> Result<(), ScenarioError> {
        let states = self.start_states();
        for (k, o) in self.objects.iter().enumerate() {
            let inv = states[k].rot.inverse();
            let start = Vec3::from(o.start_m);
            for (i, p) in self.world.planes.iter().enumerate() {
                let n_world = Vec3::from(p.normal).normalize();
                // How far the object reaches towards the plane, in its own axes.
                let n = inv * n_world;
                let extent = match o.shape {
                    ShapeName::Sphere => o.radius_m,
                    ShapeName::Cylinder => {
                        o.radius_m * (n.x * n.x + n.y * n.y).sqrt() + o.half_height_m * n.z.abs()
                    }
                    ShapeName::Box => Vec3::from(o.half_extents_m).dot(&n.abs()),
                };
                let depth = p.offset_m + extent - n_world.dot(&start);
                if depth > 1e-3 || !depth.is_finite() {
                    return Err(err(
                        format!("{}.start_m", self.object_field(k)),
                        o.start_m,
                        format!(
                            "starts {:.1} mm inside world.planes[{i}]: the object must start \
                             outside the environment (at most 1 mm of contact)",
                            depth * 1e3
                        ),
                    ));
                }
            }
        }
        // Nor inside another object: the pair's penalty spring would throw them apart.
        let world = self.world();
        let probe = ContactParams {
            stiffness_n_per_m: 1.0,
            damping_n_s_per_m: 0.0,
            tangential_stiffness_n_per_m: 0.0,
            tangential_damping_n_s_per_m: 0.0,
            friction_static: 0.0,
            friction_kinetic: 0.0,
            ..ContactParams::default()
        };
        let bodies = world.bodies();
        for i in 0..bodies.len() {
            for j in i + 1..bodies.len() {
                let side = |k: usize| PairSide {
                    shape: &bodies[k].shape,
                    body: &states[k],
                    mass: &bodies[k].mass,
                };
                let mut memory = PairContactState::default();
                // With a unit stiffness, the force is the deepest overlap (in m).
                let (on_i, _, _) = pair_wrench(&probe, &mut memory, side(i), side(j));
                let overlap = on_i.force.norm();
                if overlap > 1e-3 || !overlap.is_finite() {
                    return Err(err(
                        format!("{}.start_m", self.object_field(j)),
                        self.objects[j].start_m,
                        format!(
                            "starts {:.1} mm inside {} ({:?}): objects must start apart (at \
                             most 1 mm of contact)",
                            overlap * 1e3,
                            self.object_field(i),
                            self.object_name(i),
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Every object: sizes, masses, start, names, and at most [`MAX_OBJECTS`].
    fn validate_objects(&self) -> Result<(), ScenarioError> {
        if self.objects.is_empty() || self.objects.len() > MAX_OBJECTS {
            return Err(err(
                "object",
                self.objects.len(),
                format!("a scenario has 1 to {MAX_OBJECTS} objects"),
            ));
        }
        for (k, o) in self.objects.iter().enumerate() {
            let f = self.object_field(k);
            let at = |name: &str| format!("{f}.{name}");
            if self.objects.len() > 1 || !o.name.is_empty() {
                if !valid_name(&o.name) {
                    return Err(err(
                        at("name"),
                        &o.name,
                        format!("{NAME_RULE} (each of several objects needs one)"),
                    ));
                }
                if self.objects[..k].iter().any(|p| p.name == o.name) {
                    return Err(err(at("name"), &o.name, "object names must be unique"));
                }
            }
            bounded(&at("mass_kg"), o.mass_kg, 1e-3, 1000.0, "kg")?;
            match o.shape {
                ShapeName::Sphere => bounded(&at("radius_m"), o.radius_m, 1e-3, 10.0, "m")?,
                ShapeName::Cylinder => {
                    bounded(&at("radius_m"), o.radius_m, 1e-3, 10.0, "m")?;
                    bounded(&at("half_height_m"), o.half_height_m, 1e-3, 10.0, "m")?;
                }
                ShapeName::Box => {
                    for (i, h) in o.half_extents_m.iter().enumerate() {
                        bounded(&at(&format!("half_extents_m[{i}]")), *h, 1e-3, 10.0, "m")?;
                    }
                }
            }
            finite3(&at("start_m"), &o.start_m, 100.0)?;
            finite3(&at("start_rpy_deg"), &o.start_rpy_deg, 360.0)?;
            finite3(&at("velocity_m_per_s"), &o.velocity_m_per_s, 10.0)?;
            finite3(
                &at("angular_velocity_rad_per_s"),
                &o.angular_velocity_rad_per_s,
                100.0,
            )?;
            if o.fixed && o.velocity_m_per_s != [0.0; 3] {
                return Err(err(
                    at("velocity_m_per_s"),
                    o.velocity_m_per_s,
                    "must be 0 for a fixture (fixed = true)",
                ));
            }
            if o.fixed && o.angular_velocity_rad_per_s != [0.0; 3] {
                return Err(err(
                    at("angular_velocity_rad_per_s"),
                    o.angular_velocity_rad_per_s,
                    "must be 0 for a fixture (fixed = true)",
                ));
            }
        }
        Ok(())
    }

    /// How object `k` is named in errors: `object` when it is the only one, `object[k]`.
    pub fn object_field(&self, k: usize) -> String {
        if self.objects.len() > 1 {
            format!("object[{k}]")
        } else {
            "object".to_string()
        }
    }

    /// Object `k`'s name: its own, or `object` for a lone object without one.
    pub fn object_name(&self, k: usize) -> &str {
        match self.objects[k].name.as_str() {
            "" => "object",
            n => n,
        }
    }

    /// The object phase `p` is about: the one it names, else the first.
    pub fn phase_object(&self, p: &PhaseSpec) -> usize {
        (0..self.objects.len())
            .find(|&k| self.object_name(k) == p.object)
            .unwrap_or(0)
    }

    /// The object–object contact law: `object_contact`, or `environment_contact`'s.
    pub fn object_law(&self) -> ContactParams {
        self.object_contact.unwrap_or(self.environment_contact)
    }

    /// Every object's state at the start.
    pub fn start_states(&self) -> Vec<BodyState> {
        self.objects
            .iter()
            .map(|o| {
                let [roll, pitch, yaw] = o.start_rpy_deg.map(f64::to_radians);
                let rot = nalgebra::UnitQuaternion::from_euler_angles(roll, pitch, yaw);
                let shape = o.shape();
                let inertia = shape.inertia(o.mass_kg);
                let omega = Vec3::from(o.angular_velocity_rad_per_s);
                // L = R I Rᵀ ω.
                let ang_mom = rot * (inertia.component_mul(&(rot.inverse() * omega)));
                BodyState {
                    pos: Vec3::from(o.start_m),
                    rot,
                    vel: Vec3::from(o.velocity_m_per_s),
                    ang_mom,
                }
            })
            .collect()
    }

    /// The world every site shares.
    pub fn world(&self) -> World {
        let bodies: Vec<Body> = self
            .objects
            .iter()
            .map(|o| Body {
                fixed: o.fixed,
                ..Body::solid(o.shape(), o.mass_kg)
            })
            .collect();
        let planes: Vec<Plane> = self
            .world
            .planes
            .iter()
            .map(|p| {
                let n = Vec3::from(p.normal);
                Plane {
                    normal: n / n.norm(),
                    offset: p.offset_m,
                }
            })
            .collect();
        World {
            object_contact: self.object_law(),
            ..World::new(
                &bodies,
                Vec3::from(self.world.gravity_m_per_s2),
                &planes,
                self.environment_contact,
            )
        }
    }

    /// Site `i`'s arm.
    pub fn arm(&self, i: usize) -> ScaraParams {
        ScaraParams::paper(Vec3::from(self.site[i].device_base_m))
    }

    /// Site `i`'s consistency method `name`: the one place a method is built. The simulator, the
    /// station's physics process and the tests all build theirs here, so a method is the same
    /// wherever it runs (a `paper` built without its tool once counted the tool's spring in its
    /// no-gain bound in the simulator only).
    pub fn method(&self, i: usize, name: MethodName) -> Box<dyn Consistency> {
        match name {
            MethodName::Naive => Box::<Naive>::default(),
            MethodName::Paper => Box::new(
                Paper::new(self.dead_reckoning_order, i)
                    .with_tool(self.site[i].tool_radius_m, self.contact.stiffness_n_per_m),
            ),
            MethodName::Timewarp => Box::new(self.timewarp(i, &self.start_copy())),
            MethodName::Coupled => Box::new(self.coupled(i)),
        }
    }

    /// A site's copy of the world at the scenario's start, time 0.
    pub fn start_copy(&self) -> WorldCopy {
        WorldCopy::new(&self.start_states())
    }

    /// Site `i`'s `timewarp` method, starting from `copy`: the common tick is the physics step (every
    /// site's must be the same), the horizon is [`Self::timewarp_horizon_s`].
    pub fn timewarp(&self, i: usize, copy: &WorldCopy) -> TimeWarp {
        let dt = 1.0 / self.site[i].physics_rate_hz;
        let horizon_s = self.timewarp_horizon_s();
        let radii = self.tool_radii();
        let mut tw = TimeWarp::new(
            i,
            self.site.len(),
            dt,
            self.contact,
            radii,
            (horizon_s / dt).ceil() as usize,
            copy,
        );
        tw.set_local_lag(
            self.timewarp.local_lag_share,
            (self.timewarp.local_lag_max_ms * 1e-3 / dt).round() as i64,
        );
        tw.set_islands(self.timewarp.islands);
        if self.timewarp.deadband.enabled {
            tw.set_deadband(self.timewarp.deadband);
        }
        // Every user pressing the object into one plane with all the device's force, and its
        // weight: per plane at most that force's depth, ½ F² / K each.
        let press = self
            .site
            .iter()
            .map(|s| s.controller.max_force_n)
            .sum::<f64>()
            + self.objects.iter().map(|o| o.mass_kg).sum::<f64>()
                * Vec3::from(self.world.gravity_m_per_s2).norm();
        let k = self.environment_contact.stiffness_n_per_m;
        let planes = self.world.planes.len().max(1) as f64;
        tw.set_max_spring_energy(planes * 0.5 * press * press / k);
        tw
    }

    /// Every site's tool radius, m, in site order (0 past the last site).
    fn tool_radii(&self) -> [f64; MAX_SITES] {
        let mut radii = [0.0; MAX_SITES];
        for (r, s) in radii.iter_mut().zip(&self.site) {
            *r = s.tool_radius_m;
        }
        radii
    }

    /// The `timewarp` history, s: `timewarp.horizon_ms`, or when 0 the latest a tool position can
    /// arrive plus 100 ms. With `network.loss`, also one slowest report period for each of the
    /// [`Self::losses_in_a_row`] reports it can lose in a row, and a round trip more (the latest
    /// arrival again: a run of losses longer than a report's window leaves a gap, which the
    /// receiver asks for and the sender sends again, [`crate::method::track::ToolReport::need`]); at
    /// most [`MAX_HORIZON_MS`]. A position that arrives older than the history cannot be undone:
    /// the copies' confirmed states then differ for good (counted, as fallbacks and hash
    /// mismatches). At a loss of 0.3 and 150 ms, the history without loss's terms lost two or more
    /// reports in a row in 3 of 4 seeds of the paper task (97–152 mismatches each).
    pub fn timewarp_horizon_s(&self) -> f64 {
        if self.timewarp.horizon_ms > 0.0 {
            return self.timewarp.horizon_ms * 1e-3;
        }
        let k = self.losses_in_a_row();
        let lossy = if k > 0 {
            k as f64 * self.slowest_report_period_s() + self.latest_arrival_s()
        } else {
            0.0
        };
        (self.latest_arrival_s() + 0.1 + lossy).min(MAX_HORIZON_MS * 1e-3)
    }

    /// The most reports in a row the default `timewarp` history allows to be lost: the fewest `k`
    /// for which `k + 1` in a row happen with a chance of at most 10⁻⁶ at `network.loss` (0 without
    /// loss; 11 at 0.3).
    pub fn losses_in_a_row(&self) -> u32 {
        let loss = self.network.loss;
        if loss <= 0.0 {
            return 0;
        }
        // loss < 1 (validated): ln(loss) < 0.
        ((1e-6f64).ln() / loss.ln()).ceil().max(1.0) as u32 - 1
    }

    /// The slowest site's report period, s.
    fn slowest_report_period_s(&self) -> f64 {
        self.site
            .iter()
            .map(|s| 1.0 / s.report_rate_hz)
            .fold(0.0, f64::max)
    }

    /// Site `i`'s `coupled` method: remote tools are played at most the largest delay, its jitter
    /// and the slowest report period late (that late until their arrival is measured).
    pub fn coupled(&self, i: usize) -> Coupled {
        let dt = 1.0 / self.site[i].physics_rate_hz;
        let playout_s = self.latest_arrival_s();
        let radii = self.tool_radii();
        Coupled::new(
            i,
            self.site.len(),
            dt,
            self.contact,
            radii,
            (playout_s / dt).ceil() as usize,
        )
    }

    /// Site `i`'s hand.
    pub fn hand(&self, i: usize) -> HandParams {
        self.site[i].hand
    }

    /// Site `i`'s servo parameters.
    pub fn servo_params(&self, i: usize) -> ServoParams {
        let s = &self.site[i];
        ServoParams {
            tool_radius_m: s.tool_radius_m,
            contact: self.contact,
            stale_limit_s: s.stale_limit_ms / 1e3,
            stale_ramp_s: s.stale_ramp_ms / 1e3,
            max_adoption_step_n: s.max_adoption_step_n,
            display: self.display.params(),
        }
    }

    /// Site `i`'s force loop: its arm's Eq. 12 PI controller.
    pub fn force_loop(&self, i: usize) -> crate::device::ScaraForceLoop {
        crate::device::ScaraForceLoop::new(self.arm(i), self.site[i].controller)
    }

    /// Site `i`'s script.
    pub fn script(&self, i: usize) -> Vec<Keyframe> {
        self.site[i]
            .script
            .iter()
            .map(|k| Keyframe {
                t_s: k.t_s,
                target: Vec3::from(k.target_m),
            })
            .collect()
    }
}
