//! The station's `[device]` table: which backend the servo drives, where the device sits in the
//! world, who owns its loop, and the safety contract's limits; and opening that backend in the
//! servo process. `station devices` lists what each backend finds ([`probe_all`]).
//!
//! ```toml
//! [device]
//! device = "sim"          # sim | replay | haply | dhd | openhaptics | ros2
//! loop = "station"        # station: our servo loop calls the device; vendor: its thread calls us
//!                         # (openhaptics runs only so: its HD scheduler owns the servo thread)
//!
//! [device.placement]      # world = translation_m + rotation · (workspace_scale · device)
//! translation_m = [0.0, 0.0, 0.0]
//! rotation_rpy_deg = [0.0, 0.0, 0.0]   # roll about x, pitch about y, yaw about z (fixed axes)
//! workspace_scale = 1.0   # world metres per device metre
//!
//! [device.safety]
//! ramp_in_ms = 500.0
//! max_force_n = 10.0      # the device's own maximum applies too
//! max_velocity_m_s = 2.0
//! max_force_step_n = 2.0  # per servo tick
//! watchdog_ms = 50.0
//!
//! [device.replay]         # device = "replay"
//! file = "user1.mcap"     # a station's recording (its tool positions), or a CSV t_s,x,y,z
//!
//! [device.haply]          # device = "haply": `coop_rt::device::haply::HaplyConfig`
//! url = "ws://localhost:10001"
//!
//! [device.dhd]            # device = "dhd": `coop_rt::device::dhd::DhdConfig`
//! library = "/opt/forcedimension/lib/libdhd.so"
//!
//! [device.openhaptics]    # device = "openhaptics", loop = "vendor": `coop_rt::device::openhaptics::OpenHapticsConfig`
//! library = "/usr/lib/libHD.so"
//!
//! [device.ros2]           # device = "ros2": `coop_transport::ros2_device::Ros2DeviceConfig`
//! pose_topic = "/haptic/pose"                # the driver's PoseStamped
//! wrench_topic = "/haptic/wrench_command"    # our WrenchStamped back
//! connect = ["tcp/127.0.0.1:7447"]           # the ROS 2 graph's router (rmw_zenohd)
//! ```

use std::path::{Path, PathBuf};
use std::time::Duration;

use coop_model::body::Vec3;
use coop_model::replay::Trajectory;
use coop_rt::device::cartesian::{DeviceInfo, ProbeReport};
use coop_rt::device::dhd::{DhdConfig, DhdDevice};
use coop_rt::device::haply::{HaplyConfig, HaplyDevice};
use coop_rt::device::openhaptics::{OpenHapticsConfig, OpenHapticsDevice};
use coop_rt::device::replay::Replay;
use coop_rt::device::safety::SafetyLimits;
use coop_rt::device::{Backend, Placement, SimScara, StationDevice};
use coop_transport::ros2_device::{Ros2Device, Ros2DeviceConfig};
use nalgebra::UnitQuaternion;
use serde::{Deserialize, Serialize};

use super::error::Problem;
use crate::trajectory_file::load_trajectory;

/// Why the configured device did not open in the servo process.
#[derive(Debug, thiserror::Error)]
pub enum DeviceOpenError {
    /// `device = "replay"` resolved without its recorded hand (a setup not made by
    /// [`DeviceSpec::resolve`]).
    #[error("device = \"replay\" without a trajectory")]
    NoTrajectory,
    /// The Haply Inverse Service.
    #[error(transparent)]
    Haply(#[from] coop_rt::device::haply::HaplyOpenError),
    /// The DHD library or device.
    #[error(transparent)]
    Dhd(#[from] coop_rt::device::dhd::DhdError),
    /// The OpenHaptics HD library or device.
    #[error(transparent)]
    OpenHaptics(#[from] coop_rt::device::openhaptics::OpenHapticsError),
    /// The device's ROS 2 driver.
    #[error(transparent)]
    Ros2(#[from] coop_transport::ros2_device::Ros2OpenError),
}

/// `device = "…"`.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum BackendName {
    /// The simulated SCARA arm and scripted hand.
    #[default]
    Sim,
    /// A recorded hand.
    Replay,
    /// Haply Inverse3.
    Haply,
    /// Force Dimension / Novint Falcon (DHD SDK).
    Dhd,
    /// 3D Systems' Touch and Phantom devices (OpenHaptics' HD API), in the vendor's scheduler.
    Openhaptics,
    /// A device's ROS 2 driver (its pose in, a wrench out), over zenoh.
    Ros2,
}

impl BackendName {
    /// The rt backend.
    pub fn backend(self) -> Backend {
        match self {
            BackendName::Sim => Backend::Sim,
            BackendName::Replay => Backend::Replay,
            BackendName::Haply => Backend::Haply,
            BackendName::Dhd => Backend::Dhd,
            BackendName::Openhaptics => Backend::OpenHaptics,
            BackendName::Ros2 => Backend::Ros2,
        }
    }
}

/// `loop = "…"`: who runs the device's loop.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum LoopOwner {
    /// Our servo loop samples and commands the device at the scenario's servo rate.
    #[default]
    Station,
    /// The vendor's thread calls us at its own rate (`openhaptics`: the HD scheduler).
    Vendor,
}

/// `[device.placement]`: where the device sits in the world (its frame to the world's), and how far a device metre goes in it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct PlacementSpec {
    /// The device frame's origin in the world, m.
    pub translation_m: [f64; 3],
    /// The device frame's rotation: roll about x, pitch about y, yaw about z (fixed axes, applied
    /// in that order), degrees.
    pub rotation_rpy_deg: [f64; 3],
    /// World metres per device metre.
    pub workspace_scale: f64,
}

impl Default for PlacementSpec {
    fn default() -> Self {
        Self {
            translation_m: [0.0; 3],
            rotation_rpy_deg: [0.0; 3],
            workspace_scale: 1.0,
        }
    }
}

/// `[device.safety]`: the safety contract's limits (see `coop_rt::device::safety`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SafetySpec {
    /// Force ramp-in on enable, ms (0: none).
    pub ramp_in_ms: f64,
    /// Largest force, N (the device's own maximum applies too).
    pub max_force_n: f64,
    /// Hand speed above which the force is released, m/s.
    pub max_velocity_m_s: f64,
    /// Largest change of the force per servo tick, N.
    pub max_force_step_n: f64,
    /// No fresh sample for this long releases the device, ms.
    pub watchdog_ms: f64,
}

impl Default for SafetySpec {
    fn default() -> Self {
        let d = SafetyLimits::default();
        Self {
            ramp_in_ms: d.ramp_in_s * 1e3,
            max_force_n: d.max_force_n,
            max_velocity_m_s: d.max_velocity_m_s,
            max_force_step_n: d.max_force_step_n,
            watchdog_ms: d.watchdog_s * 1e3,
        }
    }
}

/// `[device.replay]`: a recorded hand played back as the device (`device = "replay"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ReplaySpec {
    /// A station's MCAP recording (its `/tool` positions, timed from its session's start) or a CSV
    /// `t_s,x,y,z` (relative to the config file's directory).
    pub file: PathBuf,
}

/// `[device]`: which device this station drives (the backend), where it sits in the world, who runs its loop, and the safety contract's limits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DeviceSpec {
    /// The backend.
    pub device: BackendName,
    /// Who runs the device's loop.
    #[serde(rename = "loop")]
    pub loop_owner: LoopOwner,
    /// Where the device sits in the world.
    pub placement: PlacementSpec,
    /// The safety contract's limits.
    pub safety: SafetySpec,
    /// The recorded hand, for `device = "replay"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub replay: Option<ReplaySpec>,
    /// The Haply backend's table (`device = "haply"`), read as
    /// [`coop_rt::device::haply::HaplyConfig`].
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<coop_rt::device::haply::HaplyConfig>")]
    pub haply: Option<toml::Table>,
    /// The DHD backend's table (`device = "dhd"`), read as [`coop_rt::device::dhd::DhdConfig`].
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<coop_rt::device::dhd::DhdConfig>")]
    pub dhd: Option<toml::Table>,
    /// The OpenHaptics backend's table (`device = "openhaptics"`), read as
    /// [`coop_rt::device::openhaptics::OpenHapticsConfig`].
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<coop_rt::device::openhaptics::OpenHapticsConfig>")]
    pub openhaptics: Option<toml::Table>,
    /// The ROS 2 backend's table (`device = "ros2"`), read as
    /// [`coop_transport::ros2_device::Ros2DeviceConfig`].
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<coop_transport::ros2_device::Ros2DeviceConfig>")]
    pub ros2: Option<toml::Table>,
}

/// A `[device]` table checked and its files loaded.
#[derive(Debug, Clone)]
pub struct DeviceSetup {
    /// The backend.
    pub backend: Backend,
    /// Device to world.
    pub placement: Placement,
    /// The safety contract.
    pub limits: SafetyLimits,
    /// The recorded hand, for `replay`.
    pub replay: Option<Trajectory>,
    /// The Haply table (its defaults when absent).
    pub haply: HaplyConfig,
    /// The DHD table (its defaults when absent).
    pub dhd: DhdConfig,
    /// The OpenHaptics table (its defaults when absent).
    pub openhaptics: OpenHapticsConfig,
    /// The ROS 2 table (its defaults when absent).
    pub ros2: Ros2DeviceConfig,
}

/// A backend's table (`[device.<name>]`) as its config type: unknown fields and wrong types are
/// refused naming `device.<name>.<field>`.
fn backend_table<T: serde::de::DeserializeOwned + Default>(
    name: &str,
    table: Option<&toml::Table>,
) -> Result<T, Problem> {
    match table {
        None => Ok(T::default()),
        Some(t) => toml::Value::Table(t.clone())
            .try_into()
            .map_err(|e| Problem::table(format!("device.{name}"), e.to_string().trim_end())),
    }
}

/// A backend's own rule (its `validate()`), its field named as `device.<name>.<field>`.
fn backend_rule(name: &str, e: coop_rt::device::cartesian::ConfigError) -> Problem {
    Problem::Value {
        field: format!("device.{name}.{}", e.field),
        value: e.value,
        rule: e.rule,
    }
}

impl DeviceSpec {
    /// Checks every value (the messages name `device.<field>`, the value and the rule; the caller
    /// adds the file) and loads the replay file (relative to `base`).
    ///
    /// # Errors
    /// A value that breaks a rule, a backend not built in, a replay file that does not load.
    pub fn resolve(&mut self, base: Option<&Path>) -> Result<DeviceSetup, Problem> {
        let backend = self.device.backend();
        match (backend, self.loop_owner) {
            (Backend::OpenHaptics, LoopOwner::Station) => {
                return Err(Problem::value(
                    "device.loop",
                    "\"station\"",
                    "device \"openhaptics\" runs its servo inside OpenHaptics' scheduler (the HD API's device calls are valid only in its callbacks); use loop = \"vendor\"",
                ));
            }
            (Backend::OpenHaptics, LoopOwner::Vendor) | (_, LoopOwner::Station) => {}
            (_, LoopOwner::Vendor) => {
                return Err(Problem::value(
                    "device.loop",
                    "\"vendor\"",
                    format!(
                        "device {:?} cannot call the station from its own thread (only \"openhaptics\" can); use loop = \"station\"",
                        backend.name()
                    ),
                ));
            }
        }
        let placement = self.placement.checked()?;
        let limits = self.safety.checked()?;
        self.only_the_selected_table()?;
        let haply: HaplyConfig = backend_table("haply", self.haply.as_ref())?;
        haply.validate().map_err(|e| backend_rule("haply", e))?;
        let ros2: Ros2DeviceConfig = backend_table("ros2", self.ros2.as_ref())?;
        ros2.validate().map_err(|e| backend_rule("ros2", e))?;
        let mut dhd: DhdConfig = backend_table("dhd", self.dhd.as_ref())?;
        dhd.validate().map_err(|e| backend_rule("dhd", e))?;
        let mut openhaptics: OpenHapticsConfig =
            backend_table("openhaptics", self.openhaptics.as_ref())?;
        openhaptics
            .validate()
            .map_err(|e| backend_rule("openhaptics", e))?;
        for lib in [dhd.library.as_mut(), openhaptics.library.as_mut()]
            .into_iter()
            .flatten()
        {
            // A bare file name is the dynamic loader's to find, not the configuration's.
            if let Some(b) = base.filter(|_| lib.is_relative() && lib.components().count() > 1) {
                *lib = b.join(&*lib);
            }
        }
        let replay = match backend {
            Backend::Sim => {
                if !placement.is_identity() {
                    return Err(Problem::value(
                        "device.placement",
                        format!("{:?}", self.placement),
                        "must be the identity for device = \"sim\" (the simulated arm's base and its user's script are in world coordinates)",
                    ));
                }
                None
            }
            Backend::Replay => Some(self.recorded_hand(base)?),
            Backend::Haply | Backend::Dhd | Backend::OpenHaptics | Backend::Ros2 => None,
        };
        Ok(DeviceSetup {
            backend,
            placement,
            limits,
            replay,
            haply,
            dhd,
            openhaptics,
            ros2,
        })
    }

    /// A table for a backend not selected is a mistake worth saying.
    fn only_the_selected_table(&self) -> Result<(), Problem> {
        for (name, present) in [
            (BackendName::Replay, self.replay.is_some()),
            (BackendName::Haply, self.haply.is_some()),
            (BackendName::Dhd, self.dhd.is_some()),
            (BackendName::Openhaptics, self.openhaptics.is_some()),
            (BackendName::Ros2, self.ros2.is_some()),
        ] {
            if present && name != self.device {
                let (name, selected) = (name.backend().name(), self.device.backend().name());
                return Err(Problem::table(
                    format!("device.{name}"),
                    format!("a table for backend {name:?}, but device = {selected:?}"),
                ));
            }
        }
        Ok(())
    }

    /// `[device.replay]`'s file, relative to `base`, loaded.
    fn recorded_hand(&mut self, base: Option<&Path>) -> Result<Trajectory, Problem> {
        let Some(spec) = &mut self.replay else {
            return Err(Problem::missing(
                "device.replay.file",
                "device = \"replay\" plays a recorded hand from a file",
            ));
        };
        if let Some(b) = base.filter(|_| spec.file.is_relative()) {
            spec.file = b.join(&spec.file);
        }
        load_trajectory(&spec.file).map_err(|error| Problem::ReplayFile {
            file: spec.file.display().to_string(),
            error: Box::new(error),
        })
    }
}

impl PlacementSpec {
    /// Checks the placement and makes it the transform from device to world.
    fn checked(&self) -> Result<Placement, Problem> {
        let p = self;
        for (k, v) in p.translation_m.iter().enumerate() {
            if !(v.is_finite() && v.abs() <= 100.0) {
                let rule = "must be finite and within ±100 m";
                return Err(Problem::value(
                    format!("device.placement.translation_m[{k}]"),
                    v,
                    rule,
                ));
            }
        }
        for (k, v) in p.rotation_rpy_deg.iter().enumerate() {
            if !(v.is_finite() && v.abs() <= 360.0) {
                let rule = "must be within ±360°";
                return Err(Problem::value(
                    format!("device.placement.rotation_rpy_deg[{k}]"),
                    v,
                    rule,
                ));
            }
        }
        if !(p.workspace_scale.is_finite() && (1e-3..=1e3).contains(&p.workspace_scale)) {
            return Err(Problem::value(
                "device.placement.workspace_scale",
                p.workspace_scale,
                "must be from 0.001 to 1000 (world metres per device metre)",
            ));
        }
        let [r, pi, y] = p.rotation_rpy_deg.map(f64::to_radians);
        Ok(Placement::new(
            Vec3::from(p.translation_m),
            UnitQuaternion::from_euler_angles(r, pi, y),
            p.workspace_scale,
        ))
    }
}

impl SafetySpec {
    /// Checks the limits and makes them the safety contract's.
    fn checked(&self) -> Result<SafetyLimits, Problem> {
        let s = self;
        // (field, value, lowest, whether the lowest itself is allowed, highest, unit)
        for (field, v, lo, lo_ok, hi, unit) in [
            ("ramp_in_ms", s.ramp_in_ms, 0.0, true, 10_000.0, "ms"),
            ("max_force_n", s.max_force_n, 0.0, false, 100.0, "N"),
            (
                "max_velocity_m_s",
                s.max_velocity_m_s,
                0.0,
                false,
                20.0,
                "m/s",
            ),
            (
                "max_force_step_n",
                s.max_force_step_n,
                0.0,
                false,
                100.0,
                "N",
            ),
            ("watchdog_ms", s.watchdog_ms, 1.0, true, 10_000.0, "ms"),
        ] {
            let above = if lo_ok { v >= lo } else { v > lo };
            if !(v.is_finite() && above && v <= hi) {
                let from = if lo_ok { "from" } else { "above" };
                let rule = format!("must be {from} {lo} and at most {hi} {unit}");
                return Err(Problem::value(format!("device.safety.{field}"), v, rule));
            }
        }
        Ok(SafetyLimits {
            ramp_in_s: s.ramp_in_ms / 1e3,
            max_force_n: s.max_force_n,
            max_velocity_m_s: s.max_velocity_m_s,
            max_force_step_n: s.max_force_step_n,
            watchdog_s: s.watchdog_ms / 1e3,
        })
    }
}

impl DeviceSetup {
    /// The longest the backend may wait for its device while it opens, beyond ordinary start-up
    /// work: a ROS 2 driver's first pose (`device.ros2.first_pose_timeout_ms`), the Haply
    /// service's connection and first frame (`device.haply.connect_timeout_ms` and
    /// `io_timeout_ms`). The others open at once.
    pub fn start_wait(&self) -> Duration {
        let ms = match self.backend {
            Backend::Ros2 => self.ros2.first_pose_timeout_ms,
            Backend::Haply => self
                .haply
                .connect_timeout_ms
                .saturating_add(self.haply.io_timeout_ms),
            Backend::Sim | Backend::Replay | Backend::Dhd | Backend::OpenHaptics => 0,
        };
        Duration::from_millis(ms)
    }
}

/// Whether a study's station makes its device again for each trial: a simulated hand (the
/// trial's participant or script) and a replayed one start over; a device the station opened (a
/// person's) stays open across the trials.
pub fn made_per_trial(setup: &DeviceSetup) -> bool {
    matches!(setup.backend, Backend::Sim | Backend::Replay)
}

/// Opens the configured backend for station site `site` at `now_ns` (the servo process).
///
/// # Errors
/// A vendor device that does not open (service unreachable, library missing, no device), naming
/// the config field to look at.
pub fn open(
    setup: &DeviceSetup,
    scenario: &coop_model::scenario::Scenario,
    site: usize,
    now_ns: u64,
) -> Result<StationDevice, DeviceOpenError> {
    match setup.backend {
        // The scenario's user is a recorded hand: it plays on this station too.
        Backend::Sim if scenario.site[site].hand_trajectory.is_some() => {
            let t = scenario.site[site]
                .hand_trajectory
                .clone()
                .unwrap_or_default();
            let what = scenario.site[site].hand_replay.clone().unwrap_or_default();
            Ok(StationDevice::Replay(Replay::new(t, &what)))
        }
        Backend::Sim => {
            let script = scenario.script(site);
            let plant = coop_model::device::Plant::at(
                scenario.arm(site),
                scenario.hand(site),
                script[0].target,
                scenario.site[site].elbow,
            );
            let arm = SimScara::waiting(plant, scenario.force_loop(site), script, now_ns);
            // A site with a plan is a simulated participant: the person the simulator draws for
            // it, acting on what this station shows.
            Ok(StationDevice::Sim(match scenario.participant(site) {
                Some(p) => arm.with_participant(p),
                None => arm,
            }))
        }
        Backend::Replay => {
            let t = setup.replay.clone().ok_or(DeviceOpenError::NoTrajectory)?;
            Ok(StationDevice::Replay(Replay::new(t, "device.replay.file")))
        }
        Backend::Haply => Ok(StationDevice::Other(Box::new(HaplyDevice::open(
            &setup.haply,
        )?))),
        Backend::Dhd => Ok(StationDevice::Other(Box::new(DhdDevice::open(&setup.dhd)?))),
        Backend::OpenHaptics => Ok(StationDevice::Other(Box::new(OpenHapticsDevice::open(
            &setup.openhaptics,
        )?))),
        Backend::Ros2 => Ok(StationDevice::Other(Box::new(Ros2Device::open(
            &setup.ros2,
        )?))),
    }
}

/// What each backend built in finds, in [`Backend::ALL`] order.
pub fn probe_all(
    setup: &DeviceSetup,
    scenario: &coop_model::scenario::Scenario,
    site: usize,
) -> Vec<ProbeReport> {
    Backend::ALL
        .into_iter()
        .map(|b| match b {
            Backend::Sim => {
                let d = SimScara::waiting(
                    coop_model::device::Plant::at(
                        scenario.arm(site),
                        scenario.hand(site),
                        scenario.script(site)[0].target,
                        scenario.site[site].elbow,
                    ),
                    scenario.force_loop(site),
                    scenario.script(site),
                    0,
                );
                ProbeReport {
                    backend: b.name(),
                    built_in: true,
                    status: format!(
                        "always available: the simulated arm of site {:?}",
                        scenario.site[site].name
                    ),
                    devices: vec![coop_rt::device::CartesianDevice::info(&d).clone()],
                }
            }
            Backend::Replay => {
                // The configuration's recorded hand, or the scenario's for this site.
                let hand = setup.replay.as_ref().map(|t| ("device.replay.file", t)).or(
                    scenario.site[site]
                        .hand_trajectory
                        .as_ref()
                        .map(|t| ("the scenario's hand_replay", t)),
                );
                ProbeReport {
                    backend: b.name(),
                    built_in: true,
                    status: match hand {
                        Some((what, t)) => format!(
                            "{what}: {} samples from {:.3} s to {:.3} s",
                            t.len(),
                            t.first().0,
                            t.end_s()
                        ),
                        None => "always available: plays [device.replay] file (a station's MCAP recording or a CSV t_s,x,y,z)".into(),
                    },
                    devices: hand
                        .map(|(what, t)| {
                            coop_rt::device::CartesianDevice::info(&Replay::new(t.clone(), what))
                                .clone()
                        })
                        .into_iter()
                        .collect(),
                }
            }
            Backend::Haply => coop_rt::device::haply::probe(&setup.haply),
            Backend::Dhd => coop_rt::device::dhd::probe(&setup.dhd),
            Backend::OpenHaptics => coop_rt::device::openhaptics::probe(&setup.openhaptics),
            Backend::Ros2 => coop_transport::ros2_device::probe(&setup.ros2),
        })
        .collect()
}

/// A device's info as one line.
pub fn info_line(i: &DeviceInfo) -> String {
    format!(
        "{} ({} DOF{}), max {:.1} N, {:.0} N/m, {:.1} N·s/m, workspace radius {:.3} m, {:.0} Hz{}",
        i.model,
        i.dof,
        i.serial
            .as_ref()
            .map_or(String::new(), |s| format!(", serial {s}")),
        i.max_force_n,
        i.max_stiffness_n_per_m,
        i.max_damping_n_s_per_m,
        i.workspace_radius_m,
        i.native_rate_hz,
        if i.senses_force { ", senses force" } else { "" }
    )
}
