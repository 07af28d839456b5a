//! The real-time paths allocate nothing (H6): a counting global allocator watches push, pop,
//! pop_newest, the timer's wait, the live statistics and the device's figures over thousands of
//! calls.
//!
//! Counting is per thread, so tests running in parallel in this binary do not see each other's
//! allocations.

use std::time::Duration;

use coop_rt::device::DeviceFault;
use coop_rt::shm::{BlockSegment, RingSegment, SegmentName, SeqMsg};
use coop_rt::stats::LoopStats;
use coop_rt::timer::PeriodicTimer;

mod common;
use common::counting_alloc::allocations_during;

fn name(what: &str) -> SegmentName {
    SegmentName::new(&format!("alloc{}", std::process::id()), "t", what).expect("valid name")
}

#[test]
fn counting_allocator_sees_allocations() {
    // The check itself can fail: a Vec is counted.
    assert!(allocations_during(|| drop(std::hint::black_box(vec![1u8; 64]))) >= 1);
}

#[test]
fn ring_push_pop_and_pop_newest_allocate_nothing() {
    let ring = RingSegment::<SeqMsg>::create(&name("ring"), 64).expect("create");
    let mut p = ring.producer().expect("producer");
    let mut c = ring.consumer().expect("consumer");
    let n = allocations_during(|| {
        for i in 0..100_000u64 {
            p.push(SeqMsg::new(i)).expect("room");
            let m = c.pop().expect("item");
            assert_eq!(m.seq, i);
            if i % 7 == 0 {
                // Full and empty paths, too.
                for j in 0..64 {
                    let _ = p.push(SeqMsg::new(j));
                }
                assert!(p.push(SeqMsg::new(0)).is_err());
                let newest = c.pop_newest().expect("newest");
                assert_eq!(newest.skipped, 63);
                assert!(c.pop().is_err());
            }
        }
    });
    assert_eq!(n, 0, "ring hot path allocated {n} times");
}

#[test]
fn timer_wait_and_stats_record_allocate_nothing() {
    let stats = BlockSegment::<LoopStats>::create(&name("stats")).expect("create");
    let mut timer = PeriodicTimer::new(Duration::from_micros(100));
    let n = allocations_during(|| {
        for _ in 0..2_000 {
            let w = timer.wait();
            stats.record(w.latency_ns, 1_000, w.missed);
        }
    });
    assert_eq!(n, 0, "timer/stats hot path allocated {n} times");
    assert_eq!(stats.snapshot().cycles, 2_000);
}

/// A device that faults now and then, in turns of every kind, behind a bridge that counts.
#[derive(Debug)]
struct Flaky {
    info: coop_rt::device::DeviceInfo,
    calls: u64,
}

impl coop_rt::device::CartesianDevice for Flaky {
    fn info(&self) -> &coop_rt::device::DeviceInfo {
        &self.info
    }
    fn sample(&mut self, now_ns: u64) -> Result<coop_rt::device::Sample, DeviceFault> {
        use coop_model::body::Vec3;
        self.calls += 1;
        match self.calls % 10 {
            3 => Err(DeviceFault::Disconnected),
            6 => Err(DeviceFault::CallFailed {
                call: "getPosition",
                code: -(self.calls as i32 % 5),
            }),
            // A sample that repeats the last one's time every other tick: half are new.
            k => Ok(coop_rt::device::Sample {
                t_ns: now_ns - (k % 2) * 1_000_000,
                position_m: Vec3::zeros(),
                velocity_m_s: Vec3::zeros(),
                orientation: None,
                buttons: 0,
                force_sensed_n: None,
            }),
        }
    }
    fn command(&mut self, _: u64, _: coop_rt::device::Command) -> Result<(), DeviceFault> {
        Ok(())
    }
}

impl coop_rt::device::VendorDevice for Flaky {
    fn bridge_counts(&self) -> Option<coop_rt::device::BridgeCounts> {
        Some(coop_rt::device::BridgeCounts {
            received: self.calls,
            foreign: 2,
            ..Default::default()
        })
    }
}

/// The servo publishes its device's figures after every tick: that allocates nothing either, not
/// even when a new fault's words are written.
#[test]
fn publishing_the_device_figures_allocates_nothing() {
    use coop_model::body::Vec3;
    use coop_rt::device::safety::{Guarded, SafetyLimits};
    use coop_rt::device::{DevicePublisher, StationDevice};
    use coop_rt::shm::control::ControlBlock;
    use coop_rt::shm::device::FaultKind;

    let ctl = BlockSegment::<ControlBlock>::create(&name("device")).expect("create");
    let flaky = Flaky {
        info: coop_rt::device::DeviceInfo {
            backend: "fake",
            model: "flaky fake".into(),
            serial: Some("0042".into()),
            dof: 3,
            max_force_n: 3.0,
            max_stiffness_n_per_m: 1000.0,
            max_damping_n_s_per_m: 5.0,
            workspace_radius_m: 0.1,
            native_rate_hz: 1000.0,
            senses_force: false,
        },
        calls: 0,
    };
    let t0 = 1_000_000_000;
    let mut g = Guarded::new(
        StationDevice::Other(Box::new(flaky)),
        SafetyLimits::default(),
        t0,
    );
    let mut figures = DevicePublisher::new(&ctl.device, &g, t0);
    let ticks = 3_000u64;
    let n = allocations_during(|| {
        for k in 1..=ticks {
            let now = t0 + k * 1_000_000;
            let _ = g.sample(now);
            g.display(now, Vec3::new(0.0, 0.0, 1.0), 1.0);
            figures.publish(&ctl.device, now, &g);
        }
    });
    assert_eq!(n, 0, "publishing the device's figures allocated {n} times");
    figures.publish_now(&ctl.device, t0 + ticks * 1_000_000, &g);
    let d = &ctl.device;
    assert!(d.is_open());
    assert_eq!(
        (d.backend.load(), d.model.load(), d.serial.load()),
        ("fake".into(), "flaky fake".into(), "0042".into())
    );
    let c = d.counts.load();
    assert_eq!(c.samples, ticks * 8 / 10);
    assert_eq!(c.stale, ticks / 10);
    assert_eq!(c.call_failed, ticks / 10);
    assert_eq!(c.faults, c.stale + c.call_failed);
    assert_eq!((c.received, c.foreign), (ticks, 2), "the bridge's counts");
    assert!(c.new_samples > 0 && c.new_samples < c.samples, "{c:?}");
    let rate = ControlBlock::load_f64(&d.sample_rate_hz);
    assert!(rate > 0.0 && rate < 1000.0, "{rate}");
    let (kind, text, _) = d.last_fault().expect("a fault");
    assert_eq!(kind, FaultKind::CallFailed);
    assert!(
        text.starts_with("device call getPosition failed with code"),
        "{text}"
    );
    assert!(
        d.trips[coop_rt::device::safety::Limit::Fault.code() as usize]
            .load(coop_rt::sync::Ordering::Relaxed)
            > 0,
        "every fault released the device"
    );
}
