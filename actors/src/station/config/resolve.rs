//! Resolution: a configuration read (or the defaults), its scenario loaded, every rule checked and
//! its values turned into what the station runs: scheduling requests, a restart policy, a device
//! setup, paths made absolute.

use std::path::{Path, PathBuf};

use coop_model::scenario::Scenario;
use coop_rt::sched::{Policy, Request};

use super::{rules, ConfigError, LoopSpec, Problem, StationConfig, DEFAULT_SCENARIO};
use crate::policy::{Backoff, RestartPolicy};
use crate::scenario_file;
use crate::station::device::DeviceSetup;

/// A configuration with its scenario loaded and every value checked.
#[derive(Debug, Clone)]
pub struct Resolved {
    /// The file's values.
    pub config: StationConfig,
    /// The world.
    pub scenario: Scenario,
    /// This station's site index in the scenario.
    pub site: usize,
    /// This station's site name.
    pub name: String,
    /// Servo scheduling.
    pub servo_sched: Request,
    /// Physics scheduling.
    pub physics_sched: Request,
    /// CPUs for everything that is not the servo (physics, network, supervisor).
    pub housekeeping_cpus: Vec<usize>,
    /// The supervisor's restart policy (of the servo and physics).
    pub policy: RestartPolicy,
    /// The network process's retry schedule.
    pub network_backoff: Backoff,
    /// The device, checked (and a replayed hand loaded).
    pub device: DeviceSetup,
}

impl StationConfig {
    /// Reads `path` (or the defaults when `None`) and resolves it.
    ///
    /// # Errors
    /// Unreadable file, bad TOML, unknown field, or a value that breaks a rule (the message names
    /// the file, the field, the value and the rule).
    pub fn load(path: Option<&Path>) -> Result<Resolved, ConfigError> {
        let config = match path {
            None => StationConfig::default(),
            Some(p) => {
                let text = std::fs::read_to_string(p).map_err(|error| ConfigError::Read {
                    path: p.to_owned(),
                    error,
                })?;
                toml::from_str(&text)
                    .map_err(|e| ConfigError::in_file(Some(p), Problem::Toml(e)))?
            }
        };
        config
            .resolved(path.and_then(Path::parent))
            .map_err(|problem| ConfigError::in_file(path, problem))
    }

    /// Checks every value and loads the scenario (a relative scenario path is relative to `base`).
    ///
    /// # Errors
    /// As [`StationConfig::load`], without the file.
    pub fn resolve(self, base: Option<&Path>) -> Result<Resolved, ConfigError> {
        Ok(self.resolved(base)?)
    }

    /// Checks every value against `scenario`, the world this configuration names (already
    /// loaded; relative paths in the configuration are relative to `base`).
    ///
    /// # Errors
    /// As [`StationConfig::load`], without the file.
    pub fn resolve_with(
        self,
        base: Option<&Path>,
        scenario: Scenario,
    ) -> Result<Resolved, ConfigError> {
        Ok(self.resolved_with(base, scenario)?)
    }

    fn resolved(self, base: Option<&Path>) -> Result<Resolved, Problem> {
        rules::session(&self.session)?;
        let scenario = match &self.scenario {
            None => scenario_file::parse(DEFAULT_SCENARIO)
                .map_err(|e| Problem::EmbeddedScenario(Box::new(e)))?,
            Some(p) => scenario_file::load(&rebased(p, Some(base.unwrap_or(Path::new(".")))))
                .map_err(|e| Problem::Scenario(Box::new(e)))?,
        };
        self.resolved_with(base, scenario)
    }

    /// The rules in the order their messages have always come: the world's, the values', the
    /// files', then the scheduling's and the supervisor's.
    fn resolved_with(
        self,
        base: Option<&Path>,
        mut scenario: Scenario,
    ) -> Result<Resolved, Problem> {
        rules::session(&self.session)?;
        if let Some(m) = self.method {
            scenario.method = m;
        }
        rules::one_tick_grid(&scenario)?;
        if self.ros2.publish {
            rules::ros2_names(&scenario)?;
        }
        let name = self
            .station
            .clone()
            .unwrap_or_else(|| scenario.site[0].name.clone());
        let site = rules::site_named(&name, &scenario)?;
        self.check_values()?;
        let mut config = self;
        let device = config.rebase_and_open_files(base)?;
        if let Some(t) = &config.network.tls {
            rules::certificates_name(t, "network.tls", &name, &format!("station {name}"))?;
        }
        let (servo_sched, physics_sched) = schedules(&config)?;
        let (policy, network_backoff) = supervision(&config)?;
        Ok(Resolved {
            config,
            scenario,
            site,
            name,
            housekeeping_cpus: physics_sched.cpus.clone().unwrap_or_default(),
            servo_sched,
            physics_sched,
            policy,
            network_backoff,
            device,
        })
    }

    /// Makes the files the configuration names relative to `base` (the configuration file's
    /// directory), checks each one can be used, and loads the device's.
    fn rebase_and_open_files(&mut self, base: Option<&Path>) -> Result<DeviceSetup, Problem> {
        if let Some(r) = &mut self.record {
            *r = rebased(r, base);
            rules::record_rules(r)?;
        }
        if let Some(a) = &mut self.network.access_control {
            *a = rebased(a, base);
            rules::access_control_readable(a)?;
        }
        if let Some(t) = &mut self.network.tls {
            rules::tls_files_readable(t, base, "network.tls")?;
        }
        self.device.resolve(base)
    }
}

/// `p`, relative to `base` when it is relative and there is one.
fn rebased(p: &Path, base: Option<&Path>) -> PathBuf {
    match base {
        Some(b) if p.is_relative() => b.join(p),
        _ => p.to_owned(),
    }
}

/// The servo's and physics' scheduling: by default the servo has the last allowed CPU to itself
/// and physics shares the first with everything else.
fn schedules(config: &StationConfig) -> Result<(Request, Request), Problem> {
    let allowed = coop_rt::sched::allowed_cpus();
    let (first, last) = (
        allowed.first().copied().unwrap_or(0),
        allowed.last().copied().unwrap_or(0),
    );
    Ok((
        sched("servo", &config.servo, last, 80)?,
        sched("physics", &config.physics, first, 70)?,
    ))
}

/// One loop's scheduling request, `field` naming its table.
fn sched(
    field: &str,
    l: &LoopSpec,
    default_cpu: usize,
    default_rt_priority: i32,
) -> Result<Request, Problem> {
    let policy: Policy = l.policy.parse().map_err(|e: String| {
        Problem::value(format!("{field}.policy"), format!("{:?}", l.policy), e)
    })?;
    let req = Request {
        policy,
        priority: l.priority.unwrap_or(if policy.is_realtime() {
            default_rt_priority
        } else {
            0
        }),
        cpus: Some(vec![l.cpu.unwrap_or(default_cpu)]),
        prefault_stack_bytes: 256 * 1024,
    };
    req.validate().map_err(|e| Problem::table(field, e))?;
    Ok(req)
}

/// The supervisor's restart policy (of the servo and physics) and the network process's retry
/// schedule.
fn supervision(config: &StationConfig) -> Result<(RestartPolicy, Backoff), Problem> {
    let sup = &config.supervisor;
    let mode = sup.restart.parse().map_err(|e: String| {
        Problem::value("supervisor.restart", format!("{:?}", sup.restart), e)
    })?;
    rules::supervisor_rules(sup)?;
    let ms = std::time::Duration::from_millis;
    let policy = RestartPolicy {
        mode,
        max_restarts: sup.max_restarts,
        window: std::time::Duration::from_secs_f64(sup.restart_window_s),
        backoff_initial: ms(sup.backoff_initial_ms),
        backoff_max: ms(sup.backoff_max_ms),
    };
    let network_backoff = Backoff {
        initial: ms(sup.backoff_initial_ms),
        max: ms(sup.network_backoff_max_ms),
    };
    Ok((policy, network_backoff))
}
