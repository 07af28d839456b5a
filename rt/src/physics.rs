//! The physics loop's body: take the newest tool sample from the servo (the own user's contact),
//! hand received reports to the consistency method (adoptions), integrate one fixed step with the own
//! user's force only (Eq. 10), publish the state to the servo every step and a report to the network at
//! the report rate. The periodic timer and scheduling around it belong to the station's physics
//! process.

use coop_model::contact::ContactForce;
use coop_model::method::{Consistency, ObjectCopy, World};

use crate::msg::{ObjectSample, SiteReport, ToolSample};
use crate::shm::{Consumer, Producer};

/// Everything one physics loop owns.
#[derive(Debug)]
pub struct PhysicsLoop {
    site: usize,
    method: Box<dyn Consistency>,
    world: World,
    copy: ObjectCopy,
    own: ContactForce,
    own_t_ns: u64,
    tools: Consumer<ToolSample>,
    remote: Consumer<SiteReport>,
    objects: Producer<ObjectSample>,
    reports: Producer<SiteReport>,
    period_ns: u64,
    report_period_ns: u64,
    next_report_ns: u64,
    seq: u64,
    report_seq: u64,
    adoptions: u64,
    /// Reports refused as malformed (non-finite, unknown site, unknown kind).
    pub rejected: u64,
    /// Remote reports taken from the ring (valid or not).
    pub received: u64,
    /// Object samples or reports dropped because a ring was full.
    pub dropped: u64,
}

/// A physics loop's clock: its fixed step, its report period, and when it starts (ns).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PhysicsTiming {
    /// Fixed step, ns.
    pub period_ns: u64,
    /// Report period, ns.
    pub report_period_ns: u64,
    /// First step's time, ns on CLOCK_MONOTONIC.
    pub start_ns: u64,
}

/// The rings a physics loop uses.
#[derive(Debug)]
pub struct PhysicsRings {
    /// Tool samples from the servo.
    pub tools: Consumer<ToolSample>,
    /// Reports received from other sites (from the network process).
    pub remote: Consumer<SiteReport>,
    /// Object states to the servo.
    pub objects: Producer<ObjectSample>,
    /// Reports to the network process.
    pub reports: Producer<SiteReport>,
}

impl PhysicsLoop {
    /// A physics loop for `site` with `method`, starting from `copy`.
    pub fn new(
        site: usize,
        method: Box<dyn Consistency>,
        world: World,
        copy: ObjectCopy,
        rings: PhysicsRings,
        timing: PhysicsTiming,
    ) -> Self {
        Self {
            site,
            method,
            world,
            copy,
            own: ContactForce::default(),
            own_t_ns: 0,
            tools: rings.tools,
            remote: rings.remote,
            objects: rings.objects,
            reports: rings.reports,
            period_ns: timing.period_ns,
            report_period_ns: timing.report_period_ns,
            next_report_ns: timing.start_ns,
            seq: 0,
            report_seq: 0,
            adoptions: 0,
            rejected: 0,
            received: 0,
            dropped: 0,
        }
    }

    /// One step at `now_ns`.
    pub fn step(&mut self, now_ns: u64) {
        // REAL-TIME: no allocation, no lock, no logging, no syscalls but clock_nanosleep (outside).
        let now_s = now_ns as f64 * 1e-9;
        if let Ok(n) = self.tools.pop_newest() {
            // A malformed sample leaves the last good contact in place.
            if let Some(c) = n.value.contact() {
                self.own = c;
                self.own_t_ns = n.value.t_ns;
            }
        }
        while let Ok(r) = self.remote.pop() {
            self.received += 1;
            match r.report() {
                Some((from, msg)) if from != self.site => {
                    if self
                        .method
                        .receive(&self.world, &mut self.copy, from, &msg, now_s)
                        .is_some()
                    {
                        self.adoptions += 1;
                    }
                }
                _ => self.rejected += 1,
            }
        }
        self.copy.time_s = now_s - self.period_ns as f64 * 1e-9;
        self.method.physics_step(
            &self.world,
            &mut self.copy,
            &self.own,
            self.period_ns as f64 * 1e-9,
        );
        self.copy.time_s = now_s;
        self.seq += 1;
        if self
            .objects
            .push(ObjectSample::new(
                now_ns,
                self.seq,
                &self.copy.state,
                self.adoptions,
                self.own_t_ns,
            ))
            .is_err()
        {
            self.dropped += 1;
        }
        if now_ns >= self.next_report_ns {
            self.next_report_ns = self
                .next_report_ns
                .max(now_ns.saturating_sub(self.report_period_ns))
                + self.report_period_ns;
            self.report_seq += 1;
            let report = self.method.report(&self.copy, &self.own, now_s);
            if self
                .reports
                .push(SiteReport::new(self.site, self.report_seq, &report))
                .is_err()
            {
                self.dropped += 1;
            }
        }
    }

    /// The copy this site believes.
    pub fn copy(&self) -> &ObjectCopy {
        &self.copy
    }
    /// Adoptions so far.
    pub fn adoptions(&self) -> u64 {
        self.adoptions
    }
}
