//! [`StationStatus`] for people: a few aligned tables, a helper for each part.

use std::fmt;

use super::StationStatus;

fn opt<T: fmt::Display>(v: &Option<T>) -> String {
    v.as_ref().map_or("null".into(), ToString::to_string)
}

impl fmt::Display for StationStatus {
    /// For people: a few aligned tables.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.fmt_heading(f)?;
        self.fmt_children(f)?;
        self.fmt_loops(f)?;
        self.fmt_rings(f)?;
        self.fmt_network(f)?;
        self.fmt_physics(f)?;
        match &self.device {
            Some(d) => write!(f, "{d}")?,
            None => writeln!(f, "device: not open yet (the servo opens it as it starts)")?,
        }
        self.fmt_servo(f)?;
        if let Some(t) = &self.task {
            match (t.at_s, &t.failed_by) {
                (None, _) => write!(f, "\ntask: running")?,
                (Some(at), None) => write!(f, "\ntask: {} at {at:.2} s", t.outcome)?,
                (Some(at), Some(by)) => write!(f, "\ntask: {} at {at:.2} s by {by}", t.outcome)?,
            }
        }
        super::pipeline::fmt_hops(&self.pipeline, f)
    }
}

impl StationStatus {
    /// The station, its run state, and whether its users' scripts have started.
    fn fmt_heading(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "station {} (session {}): {}{}",
            self.station,
            self.session,
            self.run_state,
            if self.degraded {
                ", DEGRADED: the network is down; servo and physics go on locally without the other sites"
            } else {
                ""
            }
        )?;
        if self.network.epoch_ns.is_none() {
            writeln!(
                f,
                "start: waiting for the session's time 0 (the launcher's announcement, translated by its clock offset once measured: the users' scripts have not started)"
            )?;
        }
        Ok(())
    }

    /// One row per child process, and a line for each that is down.
    fn fmt_children(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{:<9}{:>8}{:>11}{:>10}  {:<9}{:<12}{:>5}  cpus",
            "child", "pid", "heartbeat", "restarts", "health", "policy", "prio"
        )?;
        for c in &self.children {
            writeln!(
                f,
                "{:<9}{:>8}{:>11}{:>10}  {:<9}{:<12}{:>5}  {}",
                c.name, c.pid, c.heartbeat, c.restarts, c.health, c.policy, c.priority, c.cpus
            )?;
        }
        for c in self.children.iter().filter(|c| c.health == "down") {
            writeln!(
                f,
                "  {} down for {} s after {} restarts; last failure: {}",
                c.name,
                c.down_s.map_or("?".into(), |d| format!("{d:.1}")),
                c.restarts,
                c.last_failure.as_deref().unwrap_or("?")
            )?;
        }
        Ok(())
    }

    /// The servo's and physics' rates, overruns and latencies.
    fn fmt_loops(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{:<9}{:>9}{:>10}{:>10}{:>10}  {:<26}{:>14}",
            "loop",
            "rate Hz",
            "period us",
            "cycles",
            "overruns",
            "wake p50/p99/p99.9/max us",
            "compute max us"
        )?;
        for (name, l) in [
            ("servo", &self.loops.servo),
            ("physics", &self.loops.physics),
        ] {
            let w = &l.wake_us;
            writeln!(
                f,
                "{:<9}{:>9.1}{:>10.1}{:>10}{:>10}  {:<26}{:>14.1}",
                name,
                l.rate_hz,
                l.period_us,
                l.cycles,
                l.overruns,
                format!("{}/{}/{}/{:.0}", w.p50, w.p99, opt(&w.p999), w.max),
                l.compute_us.max
            )?;
        }
        Ok(())
    }

    /// The rings' fill and drops.
    fn fmt_rings(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let r = &self.rings;
        let drops: Vec<String> = r.drops.iter().map(|(k, v)| format!("{k} {v}")).collect();
        writeln!(
            f,
            "rings (used/slots): tool {}, object {}, report {}, remote {}, trace {}; drops: {}",
            r.tool,
            r.object,
            r.report,
            r.remote,
            r.trace,
            drops.join(", ")
        )?;
        Ok(())
    }

    /// Zenoh, the wire, the peers and the states' latency.
    fn fmt_network(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = &self.network;
        writeln!(f, "zenoh: {}", n.locators)?;
        let refused: Vec<String> = n.refused.iter().map(|(k, v)| format!("{k} {v}")).collect();
        writeln!(
            f,
            "network: published {}, received {}, refused {} ({}); emulation: {} (lost {}); late-join states {}",
            n.published,
            n.received,
            n.rejected,
            refused.join(", "),
            n.emulation,
            n.emulated_lost,
            n.join_states
        )?;
        let t = &n.traffic;
        let kinds: Vec<String> = t
            .iter()
            .filter(|k| k.sent_msgs + k.received_msgs > 0)
            .map(|k| format!("{} {:.1}/{:.1}", k.kind, k.sent_kbit_s, k.received_kbit_s))
            .collect();
        writeln!(
            f,
            "wire (payload kbit/s sent/received, last {:.1} s): {:.1}/{:.1} ({})",
            n.traffic_window_s,
            t.iter().map(|k| k.sent_kbit_s).sum::<f64>(),
            t.iter().map(|k| k.received_kbit_s).sum::<f64>(),
            kinds.join(", ")
        )?;
        writeln!(
            f,
            "peers: {} joins, {} leaves, {} losses, {} rejoins, {} resyncs; {} states held for a clock offset",
            n.joins, n.leaves, n.losses, n.rejoins, n.resyncs, n.held_for_offset
        )?;
        for p in n.peers.iter().filter(|p| p.site != self.station) {
            writeln!(
                f,
                "  peer {:<10} {:<8} clock offset {} us, rtt {} us",
                p.site,
                match (p.present, p.lost) {
                    (_, true) => "LOST",
                    (true, false) => "present",
                    (false, false) => "absent",
                },
                opt(&p.clock_offset_us),
                opt(&p.clock_rtt_us)
            )?;
        }
        if let Some(l) = &n.latency_us {
            writeln!(
                f,
                "state latency (sender physics -> our physics ring): p50 {} us, p99 {} us, max {} us over {}",
                l.p50, l.p99, l.max, l.count
            )?;
        }
        Ok(())
    }

    /// What physics took from the other sites, per object too, and its rollbacks.
    fn fmt_physics(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "physics: took {} remote reports (rejected {}), adopted {}, kept a finite copy {} times",
            self.physics.remote_received,
            self.physics.remote_rejected,
            self.physics.adoptions,
            self.physics.nonfinite_kept
        )?;
        if !self.physics.objects.is_empty() {
            let each: Vec<String> = self
                .physics
                .objects
                .iter()
                .map(|o| format!("{} adopted {} refused {}", o.name, o.adoptions, o.refused))
                .collect();
            writeln!(f, "objects: {}", each.join("; "))?;
        }
        if let Some(r) = &self.physics.rollback {
            writeln!(f, "{r}")?;
        }
        Ok(())
    }

    /// The servo's command, the display and the device limits (the last line: no newline).
    fn fmt_servo(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "servo: commanding {:.2} N, display scale {:.2}",
            self.servo.command_n, self.servo.display_scale
        )?;
        write!(f, "\n{}", self.servo.display)?;
        match &self.servo.safety {
            None => write!(f, "\nsafety: no device limit has acted"),
            Some(s) => write!(
                f,
                "\nsafety: limit {} {} last {:.3} s ago (at {} ns; {} episodes of any limit)",
                s.limit,
                if s.releases {
                    "released the device"
                } else {
                    "clamped"
                },
                s.ago_s,
                s.at_ns,
                s.episodes
            ),
        }
    }
}
