//! What a valid scenario builds: the shared world, every object's start, and each site's method,
//! arm, hand, servo, force loop and script. The one place these are made, so the simulator, the
//! station and the tests build the same.

use crate::body::{BodyState, Vec3};
use crate::contact::{ContactParams, Plane};
use crate::device::{HandParams, ScaraParams};
use crate::method::{Consistency, Coupled, Naive, Paper, TimeWarp, WorldCopy};
use crate::servo::ServoParams;
use crate::user::Keyframe;
use crate::world::{Body, World, MAX_SITES};

use super::{MethodName, PhaseSpec, Scenario, MAX_HORIZON_MS};

impl Scenario {
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

    /// Whether method `name` steps every site on the session's tick grid and exchanges tool
    /// tracks: what the method itself says ([`Consistency::grid_history_ticks`]), asked of one
    /// built here, so code that must know before it has a method (which rings to open, which
    /// rules hold) never matches a method's name.
    pub fn steps_on_grid(&self, name: MethodName) -> bool {
        !self.site.is_empty() && self.method(0, name).grid_history_ticks().is_some()
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

    /// The largest delay, its jitter and the slowest report period, s: how late a tool position
    /// can arrive, the least history `timewarp` needs.
    pub(super) fn latest_arrival_s(&self) -> f64 {
        (self.network.delay_max_ms + self.network.jitter_ms) * 1e-3 + self.slowest_report_period_s()
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
            max_ramp_in_tick_s: crate::servo::ramp_in_tick_s(s.servo_rate_hz),
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

    /// The objects' names, in the world's order.
    pub fn object_names(&self) -> Vec<&str> {
        (0..self.objects.len())
            .map(|k| self.object_name(k))
            .collect()
    }

    /// The task's live judge (`None`: the scenario has no `[task]`).
    ///
    /// # Errors
    /// A `task.` field that breaks a rule (validation reports it first).
    pub fn task_judge(
        &self,
    ) -> Result<Option<crate::task::TaskJudge>, crate::rules::ScenarioError> {
        self.task.judge(&self.object_names(), self.duration_s)
    }

    /// Site `i`'s participant, a person drawn from the site's means with the scenario's
    /// `people_seed`, else its `seed` (`None`: the site follows its script); its motor noise
    /// drawn with `seed`. Valid scenarios only.
    pub fn participant(&self, i: usize) -> Option<crate::participant::Participant> {
        let s = &self.site[i];
        if s.plan.is_empty() {
            return None;
        }
        let stream = 2000 + i as u64;
        // A person drawn apart is a mean with no spread: drawn again from the run's generator
        // it is the same person to the bit (the draw takes the same numbers from that
        // generator either way, so a scenario without `people_seed` runs as before).
        let mean = match self.people_seed {
            Some(seed) => s
                .participant
                .draw(&mut crate::rng::Rng::derive(seed, stream)),
            None => s.participant,
        };
        let names = self.object_names();
        let plan = s
            .plan
            .iter()
            .enumerate()
            .filter_map(|(k, p)| p.resolve(&format!("site[{i}].plan[{k}]"), &names).ok())
            .collect();
        let shapes: Vec<_> = self.world().bodies().iter().map(|b| b.shape).collect();
        Some(crate::participant::Participant::new(
            &mean,
            plan,
            crate::participant::Surroundings {
                shapes: &shapes,
                tool_radius_m: s.tool_radius_m,
                friction: self.contact.friction_static,
            },
            Vec3::from(s.script[0].target_m),
            crate::rng::Rng::derive(self.seed, stream),
        ))
    }
}
