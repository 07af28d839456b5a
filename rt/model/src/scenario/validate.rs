//! A scenario's rules: every value checked with positive containment (so NaN fails), the first
//! broken rule the error, naming the field, the value and the rule (H8); and the rules across
//! fields (the integrator's stability, a start outside the environment, `timewarp`'s history).

use crate::body::Vec3;
use crate::contact::{pair_wrench, ContactParams, PairContactState, PairSide, MAX_PLANES};
use crate::rules::{bounded, err, finite3, in_closed, in_range};
use crate::world::{MAX_OBJECTS, MAX_SITES};

use super::{Scenario, ScenarioError, ShapeName, SiteSpec, MAX_HORIZON_MS, MAX_LOCAL_LAG_MS};

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
        self.validate_world()?;
        validate_contact(&self.contact, "contact")?;
        self.display.validate()?;
        validate_contact(&self.environment_contact, "environment_contact")?;
        if let Some(c) = &self.object_contact {
            validate_contact(c, "object_contact")?;
        }
        self.validate_network()?;
        self.validate_sites()?;
        self.validate_stability()?;
        self.validate_start()?;
        self.validate_horizon()?;
        self.validate_local_lag()?;
        self.validate_phases()?;
        self.task_judge().map(|_| ())
    }

    /// `world`: a finite gravity, and at most [`MAX_PLANES`] planes, each with a normal that is
    /// not zero and an offset within 100 m.
    fn validate_world(&self) -> Result<(), ScenarioError> {
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
        Ok(())
    }

    /// `network`: the delays (the largest at least the least), their period, the jitter and the
    /// loss.
    fn validate_network(&self) -> Result<(), ScenarioError> {
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
        Ok(())
    }

    /// Every site: 1 to [`MAX_SITES`] of them, each [`Self::validate_site`].
    fn validate_sites(&self) -> Result<(), ScenarioError> {
        if self.site.is_empty() || self.site.len() > MAX_SITES {
            return Err(err(
                "site",
                self.site.len(),
                format!("a scenario has 1 to {MAX_SITES} sites"),
            ));
        }
        for (i, s) in self.site.iter().enumerate() {
            self.validate_site(i, s)?;
        }
        Ok(())
    }

    /// Site `i`: its name (unique), rates, device, hand and controller, then its script.
    fn validate_site(&self, i: usize, s: &SiteSpec) -> Result<(), ScenarioError> {
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
        self.validate_script(i, s)?;
        self.validate_plan(i, s)
    }

    /// Site `i`'s participant: its means within what people do, at most
    /// [`crate::participant::MAX_STEPS`] steps, each checked; with a plan, the script only places
    /// the hand (one keyframe).
    fn validate_plan(&self, i: usize, s: &SiteSpec) -> Result<(), ScenarioError> {
        let at = |f: &str| format!("site[{i}].{f}");
        let p = &s.participant;
        for ((name, lo, hi), v) in crate::participant::ParticipantSpec::limits()
            .into_iter()
            .zip(p.values())
        {
            in_closed(&at(&format!("participant.{name}")), v, lo, hi)?;
        }
        in_closed(&at("participant.spread"), p.spread, 0.0, 0.5)?;
        if s.plan.is_empty() {
            return Ok(());
        }
        if s.plan.len() > crate::participant::MAX_STEPS {
            return Err(err(
                at("plan"),
                s.plan.len(),
                format!("at most {} steps", crate::participant::MAX_STEPS),
            ));
        }
        if s.script.len() != 1 {
            return Err(err(
                at("script"),
                s.script.len(),
                "with a plan, the script is one keyframe: where the hand starts",
            ));
        }
        if s.hand_replay.is_some() {
            return Err(err(
                at("hand_replay"),
                "given",
                "a site has a plan or a recorded hand, not both",
            ));
        }
        let names = self.object_names();
        for (k, step) in s.plan.iter().enumerate() {
            step.resolve(&at(&format!("plan[{k}]")), &names)?;
        }
        Ok(())
    }

    /// Site `i`'s script: at least one keyframe, in time order, each within the device's reach;
    /// and a hand replay named is loaded.
    fn validate_script(&self, i: usize, s: &SiteSpec) -> Result<(), ScenarioError> {
        let at = |f: &str| format!("site[{i}].{f}");
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
        Ok(())
    }

    /// Every phase: a name, a time span within the run, sites and an object of this scenario, a
    /// region whose corners are in order.
    fn validate_phases(&self) -> Result<(), ScenarioError> {
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
}
