//! What a site shows, as Foxglove's well-known messages (protobuf, schemas from the `foxglove`
//! crate), for the recording's `/tf`, `/scene` and `/log` channels and for the live view.
//!
//! Frames: `world` is the scenario's frame; `object/<site>` is that site's copy of the object
//! (origin at its centre of mass, axes its body axes), `tool/<site>` its tool tip (world axes). A
//! [`Scene`] turns one sample into the two [`FrameTransform`]s `world → object/<site>` and
//! `world → tool/<site>`, and into a [`SceneUpdate`] whose entities are locked to those frames:
//! the object as the primitive of its real shape and size, in the site's colour; the tool as a
//! sphere of its radius; the force the user applies to this copy as an arrow at the tool
//! ([`ARROW_M_PER_N`]); and the environment's planes (in `world`, the same for every site).
//!
//! Entity ids are unique per site (`object/<site>`, `tool/<site>`, `force/<site>`), so the
//! recordings of every site open together, and the live view shows every copy in one scene. In a
//! world of several objects the first keeps `object/<site>` and each other has its own frame and
//! entity, `object/<name>/<site>`.

use coop_model::scenario::{ObjectSpec, Scenario, ShapeName};
use foxglove::messages::{
    log::Level, ArrowPrimitive, Color, CubePrimitive, CylinderPrimitive, FrameTransform, Log, Pose,
    Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3,
};
use foxglove::Encode;

use super::SampleMsg;

/// The root frame: the scenario's world.
pub const WORLD: &str = "world";
/// Force arrows are this long per newton, m.
pub const ARROW_M_PER_N: f64 = 0.02;
/// Forces below this are drawn as no arrow, N.
pub const ARROW_MIN_N: f64 = 0.01;
/// The side of the square drawn for each plane of the environment, m.
pub const PLANE_SIDE_M: f64 = 1.0;
/// The thickness of that square (below the plane: free space stays clear), m.
pub const PLANE_THICKNESS_M: f64 = 0.002;
/// The id of the environment's entity.
pub const ENVIRONMENT: &str = "environment";

/// The object's shape and size, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Body {
    /// A sphere.
    Sphere {
        /// Radius.
        radius: f64,
    },
    /// A cylinder along the body z axis.
    Cylinder {
        /// Radius.
        radius: f64,
        /// Half its height.
        half_height: f64,
    },
    /// A box along the body axes.
    Box {
        /// Half extents.
        half: [f64; 3],
    },
}

/// What one site shows: its name and colour, the object's body, its tool, the environment.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Site name (in frame and entity ids).
    pub site: String,
    /// Its colour: red, green, blue, alpha in [0, 1].
    pub colour: [f64; 4],
    /// The object.
    pub object: Body,
    /// The tool tip's radius, m.
    pub tool_radius_m: f64,
    /// The environment's planes: normal into free space, offset along it, m.
    pub planes: Vec<([f64; 3], f64)>,
    /// The world's other objects (the second on), by name: frames `object/<name>/<site>` (the
    /// first's too in a world of several: [`Scene::object_frame`]).
    pub others: Vec<(String, Body)>,
    /// The first object's name in a world of several (empty in a world of one, whose `/object`
    /// names none).
    pub first_name: String,
}

impl Body {
    /// The shape and size of `o`.
    pub fn of(o: &ObjectSpec) -> Self {
        match o.shape {
            ShapeName::Sphere => Body::Sphere { radius: o.radius_m },
            ShapeName::Cylinder => Body::Cylinder {
                radius: o.radius_m,
                half_height: o.half_height_m,
            },
            ShapeName::Box => Body::Box {
                half: o.half_extents_m,
            },
        }
    }

    /// The primitive of this body in `entity`, centred on its frame, in colour `c`.
    fn draw(&self, entity: &mut SceneEntity, c: Option<Color>) {
        match *self {
            Body::Sphere { radius } => entity.spheres.push(SpherePrimitive {
                pose: pose([0.0; 3], IDENTITY),
                size: Some(v3([2.0 * radius; 3])),
                color: c,
            }),
            Body::Cylinder {
                radius,
                half_height,
            } => entity.cylinders.push(CylinderPrimitive {
                pose: pose([0.0; 3], IDENTITY),
                size: Some(v3([2.0 * radius, 2.0 * radius, 2.0 * half_height])),
                bottom_scale: 1.0,
                top_scale: 1.0,
                color: c,
            }),
            Body::Box { half } => entity.cubes.push(CubePrimitive {
                pose: pose([0.0; 3], IDENTITY),
                size: Some(v3([2.0 * half[0], 2.0 * half[1], 2.0 * half[2]])),
                color: c,
            }),
        }
    }
}

/// The force `f` (N) drawn as an arrow, or `None` where it is below [`ARROW_MIN_N`]: two
/// samples with the same `arrow` draw the same.
pub fn arrow(f: [f64; 3]) -> Option<[f64; 3]> {
    ((f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt() >= ARROW_MIN_N).then_some(f)
}

/// A distinct colour per site index (eight, repeating), the object's alpha.
pub fn site_colour(index: usize) -> [f64; 4] {
    const PALETTE: [[f64; 3]; 8] = [
        [0.12, 0.47, 0.71],
        [1.00, 0.50, 0.05],
        [0.17, 0.63, 0.17],
        [0.84, 0.15, 0.16],
        [0.58, 0.40, 0.74],
        [0.55, 0.34, 0.29],
        [0.89, 0.47, 0.76],
        [0.74, 0.74, 0.13],
    ];
    let [r, g, b] = PALETTE[index % PALETTE.len()];
    [r, g, b, 0.6]
}

/// The colour of the simulator's reference copy.
pub const REFERENCE_COLOUR: [f64; 4] = [0.5, 0.5, 0.5, 0.6];

/// A wall-clock time (ns since the Unix epoch) as a protobuf timestamp (saturating past 2106).
pub fn timestamp(unix_ns: u64) -> Timestamp {
    let sec = u32::try_from(unix_ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (unix_ns % 1_000_000_000) as u32)
}

/// A message's protobuf bytes.
pub fn encode<T: Encode>(m: &T) -> Vec<u8> {
    let mut buf = Vec::with_capacity(m.encoded_len().unwrap_or(256));
    // Encoding fails only when the buffer cannot grow; a `Vec` always can.
    let _ = m.encode(&mut buf);
    buf
}

fn v3(v: [f64; 3]) -> Vector3 {
    Vector3 {
        x: v[0],
        y: v[1],
        z: v[2],
    }
}

fn colour(c: [f64; 4]) -> Color {
    Color {
        r: c[0],
        g: c[1],
        b: c[2],
        a: c[3],
    }
}

const IDENTITY: Quaternion = Quaternion {
    x: 0.0,
    y: 0.0,
    z: 0.0,
    w: 1.0,
};

/// The shortest rotation taking unit vector `from` onto the direction of `to` (identity for a
/// zero `to`; a half turn about an axis normal to `from` when they are opposite).
fn rotation_onto(from: [f64; 3], to: [f64; 3]) -> Quaternion {
    let n = (to[0] * to[0] + to[1] * to[1] + to[2] * to[2]).sqrt();
    if n < 1e-12 {
        return IDENTITY;
    }
    let d = [to[0] / n, to[1] / n, to[2] / n];
    let dot = from[0] * d[0] + from[1] * d[1] + from[2] * d[2];
    if dot < -1.0 + 1e-9 {
        // Opposite: any axis normal to `from`.
        let axis = if from[0].abs() < 0.9 {
            [0.0, -from[2], from[1]]
        } else {
            [-from[2], 0.0, from[0]]
        };
        let an = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        return Quaternion {
            x: axis[0] / an,
            y: axis[1] / an,
            z: axis[2] / an,
            w: 0.0,
        };
    }
    let c = [
        from[1] * d[2] - from[2] * d[1],
        from[2] * d[0] - from[0] * d[2],
        from[0] * d[1] - from[1] * d[0],
    ];
    let w = 1.0 + dot;
    let qn = (w * w + c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
    Quaternion {
        x: c[0] / qn,
        y: c[1] / qn,
        z: c[2] / qn,
        w: w / qn,
    }
}

fn pose(position: [f64; 3], orientation: Quaternion) -> Option<Pose> {
    Some(Pose {
        position: Some(v3(position)),
        orientation: Some(orientation),
    })
}

impl Scene {
    /// Site `index` of `scenario` (`None`: no such site), in its [`site_colour`].
    pub fn from_scenario(scenario: &Scenario, index: usize) -> Option<Self> {
        let site = scenario.site.get(index)?;
        Some(Self {
            site: site.name.clone(),
            colour: site_colour(index),
            object: Body::of(&scenario.objects[0]),
            tool_radius_m: site.tool_radius_m,
            planes: scenario
                .world
                .planes
                .iter()
                .map(|p| (p.normal, p.offset_m))
                .collect(),
            others: (1..scenario.objects.len())
                .map(|k| {
                    let name = scenario.object_name(k).to_owned();
                    (name, Body::of(&scenario.objects[k]))
                })
                .collect(),
            first_name: if scenario.objects.len() > 1 {
                scenario.object_name(0).to_owned()
            } else {
                String::new()
            },
        })
    }

    /// Object `k`'s name as `/object` gives it (the first's empty in a world of one; past the
    /// world's objects, its index).
    pub fn object_name(&self, k: usize) -> String {
        match k {
            0 => self.first_name.clone(),
            _ => self
                .others
                .get(k - 1)
                .map_or_else(|| k.to_string(), |(n, _)| n.clone()),
        }
    }

    /// `world → object/<name>/<site>` for the world's object `k` (1 or later) at `pos`, `rot`
    /// (w, x, y, z), at `unix_ns`; `None` past the world's objects.
    pub fn other_transform(
        &self,
        k: usize,
        pos: [f64; 3],
        [w, x, y, z]: [f64; 4],
        unix_ns: u64,
    ) -> Option<FrameTransform> {
        let (name, _) = self.others.get(k.checked_sub(1)?)?;
        Some(FrameTransform {
            timestamp: Some(timestamp(unix_ns)),
            parent_frame_id: WORLD.into(),
            child_frame_id: self.other_frame(name),
            translation: Some(v3(pos)),
            rotation: Some(Quaternion { x, y, z, w }),
        })
    }

    /// `object/<name>/<site>`: this site's copy of the world's other object `name`.
    pub fn other_frame(&self, name: &str) -> String {
        format!("object/{name}/{}", self.site)
    }

    /// `world → object/<name>/<site>` for each other object at its pose (position, orientation
    /// w, x, y, z) in `poses` (in [`Scene::others`]' order), at `unix_ns`.
    pub fn other_transforms(
        &self,
        poses: &[([f64; 3], [f64; 4])],
        unix_ns: u64,
    ) -> Vec<FrameTransform> {
        poses
            .iter()
            .enumerate()
            .filter_map(|(k, &(p, q))| self.other_transform(k + 1, p, q, unix_ns))
            .collect()
    }

    /// The other objects' entities, each locked to its frame, in the site's colour.
    pub fn other_entities(&self, unix_ns: u64) -> Vec<SceneEntity> {
        self.others
            .iter()
            .map(|(name, body)| {
                let mut e = SceneEntity {
                    timestamp: Some(timestamp(unix_ns)),
                    frame_id: self.other_frame(name),
                    id: self.other_frame(name),
                    frame_locked: true,
                    ..SceneEntity::default()
                };
                body.draw(&mut e, Some(colour(self.colour)));
                e
            })
            .collect()
    }

    /// The first object's frame: `object/<site>` in a world of one, `object/<name>/<site>` in a
    /// world of several, as every other object's, so that no object's frame goes unnamed.
    pub fn object_frame(&self) -> String {
        if self.first_name.is_empty() {
            format!("object/{}", self.site)
        } else {
            self.other_frame(&self.first_name)
        }
    }

    /// `tool/<site>`.
    pub fn tool_frame(&self) -> String {
        format!("tool/{}", self.site)
    }

    /// `world → object/<site>` (the copy's pose) and `world → tool/<site>` (the tool tip), at
    /// `unix_ns`.
    pub fn transforms(&self, s: &SampleMsg, unix_ns: u64) -> [FrameTransform; 2] {
        let [w, x, y, z] = s.rot;
        [
            FrameTransform {
                timestamp: Some(timestamp(unix_ns)),
                parent_frame_id: WORLD.into(),
                child_frame_id: self.object_frame(),
                translation: Some(v3(s.pos)),
                rotation: Some(Quaternion { x, y, z, w }),
            },
            FrameTransform {
                timestamp: Some(timestamp(unix_ns)),
                parent_frame_id: WORLD.into(),
                child_frame_id: self.tool_frame(),
                translation: Some(v3(s.tool_pos)),
                rotation: Some(IDENTITY),
            },
        ]
    }

    /// The site's entities for sample `s`: the object, the tool and the force arrow, each locked
    /// to its frame.
    pub fn entities(&self, s: &SampleMsg, unix_ns: u64) -> [SceneEntity; 3] {
        let ts = Some(timestamp(unix_ns));
        let entity = |frame_id: String, id: String| SceneEntity {
            timestamp: ts,
            frame_id,
            id,
            frame_locked: true,
            ..SceneEntity::default()
        };
        let mut object = entity(self.object_frame(), self.object_frame());
        self.object.draw(&mut object, Some(colour(self.colour)));
        let mut tool = entity(self.tool_frame(), self.tool_frame());
        let [r, g, b, _] = self.colour;
        tool.spheres.push(SpherePrimitive {
            pose: pose([0.0; 3], IDENTITY),
            size: Some(v3([2.0 * self.tool_radius_m; 3])),
            color: Some(colour([r, g, b, 1.0])),
        });
        [object, tool, self.force(s, unix_ns)]
    }

    /// The force the user applies to this copy in sample `s`, as an arrow at the tool (an entity
    /// without one when the force is below [`ARROW_MIN_N`]).
    pub fn force(&self, s: &SampleMsg, unix_ns: u64) -> SceneEntity {
        let mut force = SceneEntity {
            timestamp: Some(timestamp(unix_ns)),
            frame_id: self.tool_frame(),
            id: format!("force/{}", self.site),
            frame_locked: true,
            ..SceneEntity::default()
        };
        if let Some(f) = arrow(s.f_object) {
            let magnitude = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
            let [r, g, b, _] = self.colour;
            force.arrows.push(ArrowPrimitive {
                pose: pose([0.0; 3], rotation_onto([1.0, 0.0, 0.0], f)),
                shaft_length: magnitude * ARROW_M_PER_N,
                shaft_diameter: 0.003,
                head_length: 0.008,
                head_diameter: 0.008,
                color: Some(colour([r, g, b, 1.0])),
            });
        }
        force
    }

    /// The environment's planes (in `world`), each a thin square whose top face is the plane.
    pub fn environment(&self, unix_ns: u64) -> SceneEntity {
        let mut e = SceneEntity {
            timestamp: Some(timestamp(unix_ns)),
            frame_id: WORLD.into(),
            id: ENVIRONMENT.into(),
            ..SceneEntity::default()
        };
        for &(n, offset) in &self.planes {
            let depth = offset - PLANE_THICKNESS_M / 2.0;
            e.cubes.push(CubePrimitive {
                pose: pose(
                    [n[0] * depth, n[1] * depth, n[2] * depth],
                    rotation_onto([0.0, 0.0, 1.0], n),
                ),
                size: Some(v3([PLANE_SIDE_M, PLANE_SIDE_M, PLANE_THICKNESS_M])),
                color: Some(colour([0.6, 0.6, 0.6, 0.3])),
            });
        }
        e
    }

    /// The whole scene for sample `s`: the environment and the site's entities (its copy of
    /// every object, its tool and force).
    pub fn update(&self, s: &SampleMsg, unix_ns: u64) -> SceneUpdate {
        let mut entities = vec![self.environment(unix_ns)];
        entities.extend(self.entities(s, unix_ns));
        entities.extend(self.other_entities(unix_ns));
        SceneUpdate {
            deletions: Vec::new(),
            entities,
        }
    }

    /// A station event as a log line named after the site.
    pub fn log(&self, unix_ns: u64, level: Level, message: String) -> Log {
        Log {
            timestamp: Some(timestamp(unix_ns)),
            level: level as i32,
            message,
            name: self.site.clone(),
            ..Log::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use foxglove::Decode;

    fn rotate(q: &Quaternion, v: [f64; 3]) -> [f64; 3] {
        // v' = v + 2w(u × v) + 2u × (u × v)
        let u = [q.x, q.y, q.z];
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let t = cross(u, v);
        let t2 = cross(u, t);
        [
            v[0] + 2.0 * q.w * t[0] + 2.0 * t2[0],
            v[1] + 2.0 * q.w * t[1] + 2.0 * t2[1],
            v[2] + 2.0 * q.w * t[2] + 2.0 * t2[2],
        ]
    }

    #[test]
    fn rotation_onto_points_the_axis_along_the_direction() {
        for to in [
            [0.0, 0.0, 2.0],
            [-3.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.3, -0.2, -0.9],
        ] {
            for from in [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] {
                let q = rotation_onto(from, to);
                let n = (to[0] * to[0] + to[1] * to[1] + to[2] * to[2]).sqrt();
                let r = rotate(&q, from);
                for i in 0..3 {
                    assert!((r[i] - to[i] / n).abs() < 1e-9, "{from:?} → {to:?}: {r:?}");
                }
            }
        }
    }

    #[test]
    fn a_sample_becomes_frames_and_entities_of_the_site_in_its_real_size() {
        let sc = Scenario {
            site: vec![
                coop_model::scenario::SiteSpec {
                    name: "a".into(),
                    ..Default::default()
                },
                coop_model::scenario::SiteSpec {
                    name: "b".into(),
                    tool_radius_m: 0.005,
                    ..Default::default()
                },
            ],
            objects: vec![coop_model::scenario::ObjectSpec {
                shape: ShapeName::Cylinder,
                radius_m: 0.04,
                half_height_m: 0.01,
                ..Default::default()
            }],
            world: coop_model::scenario::WorldSpec {
                planes: vec![coop_model::scenario::PlaneSpec {
                    normal: [0.0, 0.0, 1.0],
                    offset_m: 0.0,
                }],
                ..Default::default()
            },
            ..Scenario::default()
        };
        assert!(Scene::from_scenario(&sc, 2).is_none());
        let scene = Scene::from_scenario(&sc, 1).expect("site b");
        let s = SampleMsg {
            pos: [0.1, 0.2, 0.3],
            rot: [1.0, 0.0, 0.0, 0.0],
            tool_pos: [0.0, 0.0, 0.05],
            f_object: [0.0, 2.0, 0.0],
            ..SampleMsg::default()
        };
        let [object, tool] = scene.transforms(&s, 1_500_000_000);
        assert_eq!(object.child_frame_id, "object/b");
        assert_eq!(tool.child_frame_id, "tool/b");
        assert_eq!(object.parent_frame_id, WORLD);
        assert_eq!(object.translation, Some(v3([0.1, 0.2, 0.3])));
        assert_eq!(object.rotation, Some(IDENTITY));
        assert_eq!(object.timestamp, Some(Timestamp::new(1, 500_000_000)));
        let update = scene.update(&s, 1_500_000_000);
        let ids: Vec<&str> = update.entities.iter().map(|e| e.id.as_str()).collect();
        assert_eq!(ids, [ENVIRONMENT, "object/b", "tool/b", "force/b"]);
        let cylinder = &update.entities[1].cylinders[0];
        assert_eq!(cylinder.size, Some(v3([0.08, 0.08, 0.02])));
        assert_eq!(cylinder.color, Some(colour(site_colour(1))));
        assert_eq!(update.entities[2].spheres[0].size, Some(v3([0.01; 3])));
        let arrow = &update.entities[3].arrows[0];
        assert!((arrow.shaft_length - 2.0 * ARROW_M_PER_N).abs() < 1e-12);
        let along = rotate(
            arrow
                .pose
                .as_ref()
                .and_then(|p| p.orientation.as_ref())
                .expect("q"),
            [1.0, 0.0, 0.0],
        );
        assert!(
            (along[1] - 1.0).abs() < 1e-9,
            "the arrow points along the force: {along:?}"
        );
        // The floor's top face is the plane.
        let floor = &update.entities[0].cubes[0];
        let z = floor.pose.as_ref().and_then(|p| p.position).expect("pos").z;
        assert!((z + PLANE_THICKNESS_M / 2.0).abs() < 1e-12);
        // No force, no arrow (the entity stays, replacing the last arrow).
        let still = scene.entities(&SampleMsg::default(), 0);
        assert!(still[2].arrows.is_empty());
        // What is written decodes as the schema says.
        let bytes = encode(&update);
        assert_eq!(
            SceneUpdate::decode(bytes.as_slice()).expect("decode"),
            update
        );
        let schema = SceneUpdate::get_schema().expect("schema");
        assert_eq!(
            (schema.name.as_str(), schema.encoding.as_str()),
            ("foxglove.SceneUpdate", "protobuf")
        );
    }
}
