//! The servo loop's body: read the device, take the newest object state from physics, run the
//! model's servo step (Eq. 5–7, 12, stale ramp, bounded adoption step), write the torques, send the
//! tool sample to physics, publish statistics. The periodic timer and scheduling around it belong to
//! the station's servo process.

use coop_model::body::BodyState;
use coop_model::method::World;
use coop_model::servo::{Servo, ServoInput, ServoOutput};

use crate::device::Device;
use crate::msg::{ObjectSample, ToolSample};
use crate::shm::control::{ControlBlock, Ring, RunState};
use crate::shm::{Consumer, Producer};

/// Everything one servo loop owns.
#[derive(Debug)]
pub struct ServoLoop<D> {
    servo: Servo,
    device: D,
    world: World,
    objects: Consumer<ObjectSample>,
    tools: Producer<ToolSample>,
    latest: Option<(BodyState, u64, u64)>,
    seq: u64,
    last_ns: u64,
    /// Tool samples dropped because physics did not keep up.
    pub dropped: u64,
    limp: bool,
    stale_state_ns: Option<u64>,
    stale_limp_recorded: bool,
    last_roundtrip_tool_ns: u64,
}

impl<D: Device> ServoLoop<D> {
    /// A servo loop over `device`, reading object states from `objects`, sending tool samples on
    /// `tools`.
    pub fn new(
        servo: Servo,
        device: D,
        world: World,
        objects: Consumer<ObjectSample>,
        tools: Producer<ToolSample>,
        start_ns: u64,
    ) -> Self {
        Self {
            servo,
            device,
            world,
            objects,
            tools,
            latest: None,
            seq: 0,
            last_ns: start_ns,
            dropped: 0,
            limp: false,
            stale_state_ns: None,
            stale_limp_recorded: false,
            last_roundtrip_tool_ns: 0,
        }
    }

    /// The device.
    pub fn device_mut(&mut self) -> &mut D {
        &mut self.device
    }

    /// One tick at `now_ns`. While the station is stopping (per `control`), the displayed force and the
    /// command ramp to zero as for a stale world; [`ServoLoop::is_limp`] says when they got there.
    pub fn step(&mut self, now_ns: u64, control: Option<&ControlBlock>) -> ServoOutput {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls but clock_nanosleep (outside).
        let mut adopted = false;
        if let Ok(n) = self.objects.pop_newest() {
            // The round trip of the tool sample this state was computed with, once per tool sample.
            if n.value.tool_t_ns > self.last_roundtrip_tool_ns && n.value.tool_t_ns <= now_ns {
                self.last_roundtrip_tool_ns = n.value.tool_t_ns;
                if let Some(c) = control {
                    let count = c.servo.roundtrip_count.load(crate::sync::Ordering::Relaxed);
                    c.servo
                        .roundtrip
                        .record(now_ns - n.value.tool_t_ns, count == 0);
                    c.servo
                        .roundtrip_count
                        .store(count + 1, crate::sync::Ordering::Relaxed);
                }
            }
            if let Some(state) = n.value.state() {
                adopted = self.latest.is_some_and(|(_, _, a)| a != n.value.adoptions);
                self.latest = Some((state, n.value.t_ns, n.value.adoptions));
            }
        }
        let reading = self.device.read(now_ns);
        let dt = (now_ns.saturating_sub(self.last_ns)).max(1) as f64 * 1e-9;
        self.last_ns = now_ns;
        // No state yet: the world is stale from the start (the display stays at zero).
        let (object, t_ns) = self.latest.map_or(
            (
                BodyState::at_rest(coop_model::body::Vec3::new(1e3, 1e3, 1e3)),
                0,
            ),
            |(s, t, _)| (s, t),
        );
        let out = self.servo.step(
            &ServoInput {
                now_s: now_ns as f64 * 1e-9,
                dt_s: dt,
                q: reading.q,
                qd: reading.qd,
                f_measured: reading.f_measured,
                object: &object,
                object_time_s: t_ns as f64 * 1e-9,
                adopted,
                stopping: control.is_some_and(|c| c.run_state() == RunState::Stopping),
            },
            &self.world.shape,
            &self.world.mass,
        );
        self.device.write(out.tau);
        self.seq += 1;
        let a = |v: coop_model::body::Vec3| [v.x, v.y, v.z];
        let sample = ToolSample {
            t_ns: now_ns,
            seq: self.seq,
            tool_pos: a(out.tool_pos),
            tool_vel: a(out.tool_vel),
            force: a(out.contact.force),
            point: a(out.contact.point),
            depth: out.contact.depth,
            touching: u64::from(out.contact.touching),
            f_desired: a(out.f_desired),
            f_measured: a(reading.f_measured),
            f_command: a(out.f_command),
        };
        if self.tools.push(sample).is_err() {
            self.dropped += 1;
            if let Some(c) = control {
                c.servo.drops.set(Ring::Tool, self.dropped);
            }
        }
        // Record stale episodes: when the newest state was, and when the command reached zero.
        let stale = now_ns.saturating_sub(t_ns) as f64 * 1e-9 > self.servo.params.stale_limit_s;
        if stale && self.stale_state_ns != Some(t_ns) {
            self.stale_state_ns = Some(t_ns);
            self.stale_limp_recorded = false;
            if let Some(c) = control {
                c.servo
                    .stale_state_ns
                    .store(t_ns, crate::sync::Ordering::Relaxed);
                c.servo
                    .stale_limp_ns
                    .store(0, crate::sync::Ordering::Relaxed);
            }
        }
        if stale && !self.stale_limp_recorded && out.f_command.norm() == 0.0 {
            self.stale_limp_recorded = true;
            if let Some(c) = control {
                c.servo
                    .stale_limp_ns
                    .store(now_ns, crate::sync::Ordering::Relaxed);
            }
        }
        if let Some(c) = control {
            ControlBlock::store_f64(&c.servo.command_n, out.f_command.norm());
            ControlBlock::store_f64(&c.servo.scale, out.scale);
        }
        self.limp = out.scale == 0.0;
        out
    }

    /// Whether the last tick displayed and commanded nothing (scale 0): safe to exit on a stop.
    pub fn is_limp(&self) -> bool {
        self.limp
    }

    /// The device.
    pub fn device(&self) -> &D {
        &self.device
    }
}
