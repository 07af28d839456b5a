//! The servo's samples: the tool and its contacts (servo → physics), and the object state physics
//! believes (physics → servo), converted to and from the model's types.

use coop_model::body::{BodyState, Vec3};
use coop_model::contact::ContactForce;
use coop_model::world::MAX_OBJECTS;

use super::{body_state, finite, state_fields, ObjectSample, ToolSample};

impl Default for ToolSample {
    fn default() -> Self {
        Self {
            t_ns: 0,
            seq: 0,
            tool_pos: [0.0; 3],
            tool_vel: [0.0; 3],
            f_desired: [0.0; 3],
            f_measured: [0.0; 3],
            f_command: [0.0; 3],
            objects: 0,
            touching: 0,
            force: [0.0; 3 * MAX_OBJECTS],
            point: [0.0; 3 * MAX_OBJECTS],
            depth: [0.0; MAX_OBJECTS],
            torque: [0.0; 3 * MAX_OBJECTS],
        }
    }
}

impl ToolSample {
    /// Lays out the tool's contact with each of the world's objects (`contacts`, at most
    /// [`MAX_OBJECTS`]); the rest of the sample is the caller's.
    pub fn set_contacts(&mut self, contacts: &[ContactForce]) {
        let n = contacts.len().min(MAX_OBJECTS);
        self.objects = n as u64;
        self.touching = 0;
        for (k, c) in contacts[..n].iter().enumerate() {
            self.touching |= u64::from(c.touching) << k;
            self.force[3 * k..3 * k + 3].copy_from_slice(c.force.as_slice());
            self.point[3 * k..3 * k + 3].copy_from_slice(c.point.as_slice());
            self.depth[k] = c.depth;
            self.torque[3 * k..3 * k + 3].copy_from_slice(c.torque.as_slice());
        }
    }

    /// The contact with each object (the first [`ToolSample::objects`] filled), or `None` if the
    /// count exceeds [`MAX_OBJECTS`], a touching bit names no object, or a number is not finite.
    pub fn contacts(&self) -> Option<[ContactForce; MAX_OBJECTS]> {
        let n = usize::try_from(self.objects)
            .ok()
            .filter(|&n| n <= MAX_OBJECTS)?;
        (self.touching >> n == 0).then_some(())?;
        (finite(&self.force) && finite(&self.point) && finite(&self.depth) && finite(&self.torque))
            .then_some(())?;
        let v = |w: &[f64], k: usize| Vec3::new(w[3 * k], w[3 * k + 1], w[3 * k + 2]);
        let mut out = [ContactForce::default(); MAX_OBJECTS];
        for (k, c) in out[..n].iter_mut().enumerate() {
            *c = ContactForce {
                force: v(&self.force, k),
                point: v(&self.point, k),
                depth: self.depth[k],
                touching: self.touching & (1 << k) != 0,
                slipping: false,
                torque: v(&self.torque, k),
            };
        }
        Some(out)
    }

    /// Whether the tool touches object `k`.
    pub fn touches(&self, k: usize) -> bool {
        k < 64 && self.touching & (1 << k) != 0
    }
}
impl ObjectSample {
    /// Object `object`'s state `s`, computed with the tool sample of time `tool_t_ns`.
    pub fn new(
        t_ns: u64,
        seq: u64,
        object: usize,
        s: &BodyState,
        adoptions: u64,
        tool_t_ns: u64,
    ) -> Self {
        let (pos, rot, vel, ang_mom) = state_fields(s);
        Self {
            t_ns,
            seq,
            object: object as u64,
            pos,
            rot,
            vel,
            ang_mom,
            adoptions,
            tool_t_ns,
            remote_t_ns: 0,
        }
    }
    /// The state, or `None` if not finite or not a unit quaternion.
    pub fn state(&self) -> Option<BodyState> {
        body_state(self.pos, self.rot, self.vel, self.ang_mom)
    }
    /// Which object it is, or `None` past [`MAX_OBJECTS`].
    pub fn object(&self) -> Option<usize> {
        usize::try_from(self.object)
            .ok()
            .filter(|&k| k < MAX_OBJECTS)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn object_samples_validate() {
        let s = ObjectSample::new(
            5,
            6,
            15,
            &BodyState::at_rest(Vec3::new(0.0, 0.0, 0.01)),
            2,
            4,
        );
        assert_eq!(s.state().map(|b| b.pos.z), Some(0.01));
        assert_eq!(s.object(), Some(15));
        let mut bad = s;
        bad.pos[2] = f64::INFINITY;
        assert!(bad.state().is_none());
        bad.object = 16;
        assert_eq!(bad.object(), None, "past the largest world");
    }
}
