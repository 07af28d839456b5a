//! The station's recording, from the network process: physics' trace ring drained into it, and
//! what this process saw (states received and published, presence, clocks, the session, the final
//! counters), with Foxglove's channels showing the site's [`Scene`] and its events, some watched in
//! the control block ([`Events`]: the servo's display going stale and fresh again, a child process
//! restarted, a device safety limit acting). The recorder rotates its parts as the station's
//! [`Rotation`] says; a network process restarted within the same station run continues the
//! recording its predecessor wrote ([`Recorder::continue_or_create`]). A write that fails (a full
//! disk) stops the recording, not the station.

use std::collections::BTreeMap;
use std::path::Path;

use coop_rt::device::safety::Limit;
use coop_rt::msg::TraceRecord;
use coop_rt::shm::control::{Child, ControlBlock, CHILDREN};
use coop_rt::shm::Consumer;
use coop_rt::sync::Ordering;
use foxglove::messages::log::Level;

use super::NetworkError;
use crate::recording::{Recorder, RecordingError, Rotation, Scene, StatusMsg, TaskMsg};

/// The recording being written, if any.
pub(super) struct Recording {
    recorder: Option<Recorder>,
    /// The first write error since the last [`Recording::stop_on_error`].
    err: Option<String>,
}

impl Recording {
    /// Creates the recording at `path` (none: nothing is recorded) with its `metadata`, in parts
    /// bounded by `rotation`, showing `scene` on the Foxglove channels (none: JSON channels only);
    /// continues it instead when `metadata` names the station run whose earlier network process
    /// wrote it.
    pub(super) fn create(
        path: Option<&Path>,
        metadata: BTreeMap<String, String>,
        rotation: Rotation,
        scene: Option<Scene>,
    ) -> Result<Self, NetworkError> {
        let recorder = match path {
            Some(p) => Some(Recorder::continue_or_create(p, metadata, rotation, scene)?),
            None => None,
        };
        Ok(Self {
            recorder,
            err: None,
        })
    }

    /// A recording of nothing (a study's station between trials).
    pub(super) fn none() -> Self {
        Self {
            recorder: None,
            err: None,
        }
    }

    /// Whether it continues what an earlier network process of this station run recorded.
    pub(super) fn continued(&self) -> bool {
        self.recorder
            .as_ref()
            .is_some_and(|r| r.continued().is_some())
    }

    /// Writes with `f`, remembering the first error.
    pub(super) fn write(&mut self, f: impl FnOnce(&mut Recorder) -> Result<(), RecordingError>) {
        if let Some(r) = &mut self.recorder {
            if let Err(e) = f(r) {
                self.err
                    .get_or_insert(format!("writing the recording: {e}"));
            }
        }
    }

    /// Moves physics' trace records into the recording; returns the newest sample among them,
    /// with the world's other objects' records of the same time (the first object's comes first).
    pub(super) fn drain_trace(
        &mut self,
        trace: &mut Consumer<TraceRecord>,
    ) -> Option<(TraceRecord, Vec<TraceRecord>)> {
        let mut newest: Option<(TraceRecord, Vec<TraceRecord>)> = None;
        while let Ok(t) = trace.pop() {
            self.write(|w| w.trace(&t));
            if t.kind != TraceRecord::SAMPLE {
                continue;
            }
            match &mut newest {
                Some((first, others)) if t.object != 0 && t.t_ns == first.t_ns => others.push(t),
                _ if t.object == 0 => newest = Some((t, Vec::new())),
                _ => {}
            }
        }
        newest
    }

    /// After a failed write: says so once and stops recording.
    pub(super) fn stop_on_error(&mut self, site: &str) {
        if let Some(e) = self.err.take() {
            // A full disk must not take the station down.
            eprintln!("network {site}: {e}; recording stopped");
            self.recorder = None;
        }
    }

    /// Writes the final counters and closes the file.
    pub(super) fn finish(mut self, site: &str, status: &StatusMsg) {
        if let Some(mut r) = self.recorder.take() {
            let _ = r.status(status);
            if let Err(e) = r.finish() {
                eprintln!("network {site}: finishing the recording: {e}");
            }
        }
    }
}

/// The station events the control block shows, for `/log` and the live view: what was seen at the
/// last look, so that each change is told once.
pub(super) struct Events {
    /// The servo's display was stale (none: not looked yet).
    stale: Option<bool>,
    /// Per child, the restarts already told.
    restarts: [u64; CHILDREN],
    /// Device safety episodes already told.
    safety_episodes: u64,
    /// The task's outcome last recorded: the task group's sequence when it was read.
    task_seq: u64,
}

impl Events {
    /// Watching `ctl` from now on. A network process that continues its predecessor's recording
    /// (`continued`) takes the servo's and physics' restarts and the safety episodes so far as
    /// told (the predecessor told them); its own restart, and everything in a new recording, is
    /// told at the first look.
    pub(super) fn new(ctl: &ControlBlock, continued: bool) -> Self {
        let mut restarts = [0; CHILDREN];
        let mut safety_episodes = 0;
        if continued {
            for c in [Child::Servo, Child::Physics] {
                restarts[c as usize] = ctl.child(c).restarts.load(Ordering::Relaxed);
            }
            safety_episodes = ctl.servo.safety_episodes.load(Ordering::Relaxed);
        }
        Self {
            stale: None,
            restarts,
            safety_episodes,
            // A continued recording has its predecessor's /task already.
            task_seq: if continued {
                ctl.task.seq.load(Ordering::Acquire)
            } else {
                0
            },
        }
    }

    /// The task's outcome when it changed since the last look (the servo judges it and writes
    /// the control block's task group), for `/task`.
    pub(super) fn task(&mut self, ctl: &ControlBlock, now_ns: u64) -> Option<TaskMsg> {
        use coop_rt::shm::control::TaskState;
        let seq = ctl.task.seq.load(Ordering::Acquire);
        if seq == self.task_seq {
            return None;
        }
        let (state, at_s, by) = ctl.task.read()?;
        self.task_seq = seq;
        if state == TaskState::None {
            return None;
        }
        let ended = matches!(state, TaskState::Done | TaskState::Failed);
        Some(TaskMsg {
            t_ns: now_ns,
            outcome: state.name().to_owned(),
            at_s: if ended { at_s } else { 0.0 },
            failed_by: match (state, by) {
                (TaskState::Failed, 0) => "timeout".to_owned(),
                (TaskState::Failed, k) => format!("fail[{}]", k - 1),
                _ => String::new(),
            },
        })
    }

    /// What changed since the last look, as log lines: the servo's display going stale (its scale
    /// below 1: the newest object state is older than the stale limit) and fresh again, a child
    /// restarted by the supervisor, a device safety limit acting in a new episode.
    pub(super) fn look(&mut self, ctl: &ControlBlock) -> Vec<(Level, String)> {
        let mut told = Vec::new();
        let scale = f64::from_bits(ctl.servo.scale.load(Ordering::Relaxed));
        let stale = scale < 1.0;
        if self.stale.is_some_and(|s| s != stale) || (self.stale.is_none() && stale) {
            told.push(if stale {
                (
                    Level::Warning,
                    format!("stale: the object state is past the stale limit; the force display ramps to zero (scale {scale:.2})"),
                )
            } else {
                (Level::Info, "fresh: the force display is back".to_owned())
            });
        }
        self.stale = Some(stale);
        for c in Child::ALL {
            let slot = ctl.child(c);
            let n = slot.restarts.load(Ordering::Relaxed);
            if n > self.restarts[c as usize] {
                self.restarts[c as usize] = n;
                let failure = slot.last_failure();
                let why = if failure.is_empty() {
                    String::new()
                } else {
                    format!(" after: {failure}")
                };
                told.push((
                    Level::Warning,
                    format!(
                        "restart: the supervisor restarted the {} process (restart {n} of this station run){why}",
                        c.name()
                    ),
                ));
            }
        }
        // The servo stores the limit before the count: a new count comes with its limit.
        let episodes = ctl.servo.safety_episodes.load(Ordering::Relaxed);
        if episodes > self.safety_episodes {
            self.safety_episodes = episodes;
            let limit = Limit::from_code(ctl.servo.safety_limit.load(Ordering::Relaxed));
            let (name, did) = limit.map_or(("(unknown)", "acted"), |l| {
                (
                    l.name(),
                    if l.releases() {
                        "released the device"
                    } else {
                        "clamped"
                    },
                )
            });
            told.push((
                Level::Warning,
                format!("safety limit {name} {did} ({episodes} episodes of any limit so far)"),
            ));
        }
        told
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use coop_rt::shm::{BlockSegment, SegmentName};

    fn control(tag: &str) -> BlockSegment<ControlBlock> {
        let name =
            SegmentName::new(&format!("ut{}", std::process::id()), tag, "ctl").expect("valid name");
        BlockSegment::create(&name).expect("control block")
    }

    fn texts(told: &[(Level, String)]) -> Vec<&str> {
        told.iter().map(|t| t.1.as_str()).collect()
    }

    #[test]
    fn restarts_and_safety_limits_are_told_once_each() {
        let ctl = control("events");
        ControlBlock::store_f64(&ctl.servo.scale, 1.0);
        let mut ev = Events::new(&ctl, false);
        assert!(ev.look(&ctl).is_empty(), "nothing happened yet");
        let net = ctl.child(Child::Network);
        net.set_last_failure("network (pid 42) was killed by SIGKILL");
        net.restarts.store(1, Ordering::Relaxed);
        ctl.servo
            .safety_limit
            .store(Limit::MaxForce.code(), Ordering::Relaxed);
        ctl.servo.safety_episodes.store(1, Ordering::Relaxed);
        let told = ev.look(&ctl);
        assert_eq!(
            texts(&told),
            [
                "restart: the supervisor restarted the network process (restart 1 of this station run) after: network (pid 42) was killed by SIGKILL",
                "safety limit max_force_n clamped (1 episodes of any limit so far)",
            ]
        );
        assert!(told.iter().all(|t| t.0 == Level::Warning));
        // The clamp acting on (the same episode) is not told again.
        ctl.servo.safety_at_ns.store(99, Ordering::Relaxed);
        assert!(ev.look(&ctl).is_empty());
        ctl.child(Child::Physics)
            .restarts
            .store(1, Ordering::Relaxed);
        ctl.servo
            .safety_limit
            .store(Limit::Watchdog.code(), Ordering::Relaxed);
        ctl.servo.safety_episodes.store(3, Ordering::Relaxed);
        assert_eq!(
            texts(&ev.look(&ctl)),
            [
                "restart: the supervisor restarted the physics process (restart 1 of this station run)",
                "safety limit watchdog_ms released the device (3 episodes of any limit so far)",
            ]
        );
        // A network process that continues the recording takes the others' restarts and the
        // episodes so far as told, and tells its own restart.
        let mut next = Events::new(&ctl, true);
        assert_eq!(
            texts(&next.look(&ctl)),
            ["restart: the supervisor restarted the network process (restart 1 of this station run) after: network (pid 42) was killed by SIGKILL"]
        );
    }

    #[test]
    fn the_display_going_stale_and_fresh_is_told_but_not_a_fresh_start() {
        let ctl = control("stale");
        ControlBlock::store_f64(&ctl.servo.scale, 1.0);
        let mut ev = Events::new(&ctl, false);
        assert!(ev.look(&ctl).is_empty());
        ControlBlock::store_f64(&ctl.servo.scale, 0.5);
        let told = ev.look(&ctl);
        assert_eq!(told.len(), 1);
        assert!(told[0].1.starts_with("stale: "), "{told:?}");
        assert!(ev.look(&ctl).is_empty(), "still stale: told once");
        ControlBlock::store_f64(&ctl.servo.scale, 1.0);
        assert_eq!(texts(&ev.look(&ctl)), ["fresh: the force display is back"]);
    }

    #[test]
    fn the_tasks_outcome_is_recorded_once_per_change() {
        use coop_rt::shm::control::TaskState;
        let ctl = control("task");
        let mut ev = Events::new(&ctl, false);
        assert_eq!(ev.task(&ctl, 1), None, "no task yet");
        ctl.task.publish(TaskState::Running, 0.0, 0);
        let m = ev.task(&ctl, 2).expect("running told");
        assert_eq!((m.outcome.as_str(), m.at_s), ("running", 0.0));
        assert_eq!(ev.task(&ctl, 3), None, "told once");
        ctl.task.publish(TaskState::Failed, 5.25, 2);
        let m = ev.task(&ctl, 4).expect("failure told");
        assert_eq!(
            (m.outcome.as_str(), m.at_s, m.failed_by.as_str(), m.t_ns),
            ("failed", 5.25, "fail[1]", 4)
        );
        // Failed again, another way (a restarted servo's judge): a change, told.
        ctl.task.publish(TaskState::Failed, 9.0, 0);
        let m = ev.task(&ctl, 5).expect("the new failure told");
        assert_eq!((m.at_s, m.failed_by.as_str()), (9.0, "timeout"));
        // A network process that continues the recording does not tell it again.
        let mut next = Events::new(&ctl, true);
        assert_eq!(next.task(&ctl, 6), None, "the predecessor recorded it");
    }
}
