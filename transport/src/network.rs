//! The station's network process loop: a zenoh peer session that publishes this site's reports (read
//! from the physics → network ring) on its key, and hands the other sites' reports (decoded, checked)
//! to physics through the network → physics ring. It bumps its heartbeat every tick and leaves when
//! the station's run state says stop.

use std::time::Duration;

use coop_rt::msg::SiteReport;
use coop_rt::shm::control::{Child, ControlBlock, RunState};
use coop_rt::shm::{Consumer, Producer};
use coop_rt::sync::Ordering;
use zenoh::qos::{CongestionControl, Priority};

use crate::{keys, wire};

/// Where the session listens and whom it connects to.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Endpoints {
    /// Zenoh locators to listen on, e.g. `tcp/127.0.0.1:7447`.
    pub listen: Vec<String>,
    /// Zenoh locators of peers or routers to connect to.
    pub connect: Vec<String>,
}

/// Counters of the network process (published in the control block too).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NetCounters {
    /// Reports published.
    pub published: u64,
    /// Valid reports from other sites handed to physics.
    pub received: u64,
    /// Messages refused (bad version, length or contents).
    pub rejected: u64,
}

/// What the loop needs.
#[derive(Debug)]
pub struct NetworkArgs<'a> {
    /// Session name.
    pub session: &'a str,
    /// This site's name.
    pub site: &'a str,
    /// This site's index (its own reports echoed back are ignored).
    pub site_index: usize,
    /// Endpoints.
    pub endpoints: Endpoints,
    /// The control block.
    pub control: &'a ControlBlock,
    /// Reports from physics.
    pub reports: Consumer<SiteReport>,
    /// Reports to physics.
    pub remote: Producer<SiteReport>,
}

/// Peer-mode zenoh configuration: explicit endpoints, no multicast scouting.
///
/// # Errors
/// An endpoint zenoh does not accept.
pub fn config(endpoints: &Endpoints) -> Result<zenoh::Config, String> {
    let json = |v: &[String]| {
        format!(
            "[{}]",
            v.iter()
                .map(|e| format!("{e:?}"))
                .collect::<Vec<_>>()
                .join(",")
        )
    };
    let mut c = zenoh::Config::default();
    c.insert_json5("mode", "\"peer\"")
        .map_err(|e| e.to_string())?;
    c.insert_json5("scouting/multicast/enabled", "false")
        .map_err(|e| e.to_string())?;
    c.insert_json5("listen/endpoints", &json(&endpoints.listen))
        .map_err(|e| format!("listen endpoints: {e}"))?;
    c.insert_json5("connect/endpoints", &json(&endpoints.connect))
        .map_err(|e| format!("connect endpoints: {e}"))?;
    Ok(c)
}

/// Runs the network loop until the run state says stop.
///
/// # Errors
/// The zenoh session or its publisher/subscriber cannot be set up.
pub async fn run(mut a: NetworkArgs<'_>) -> Result<NetCounters, String> {
    let session = zenoh::open(config(&a.endpoints)?)
        .await
        .map_err(|e| format!("opening the zenoh session: {e}"))?;
    let publisher = session
        .declare_publisher(keys::state(a.session, 0, a.site))
        .congestion_control(CongestionControl::Drop)
        .priority(Priority::RealTime)
        .express(true)
        .await
        .map_err(|e| format!("declaring the publisher: {e}"))?;
    let subscriber = session
        .declare_subscriber(keys::all_states(a.session, 0))
        .await
        .map_err(|e| format!("declaring the subscriber: {e}"))?;
    let mut n = NetCounters::default();
    let mut tick = tokio::time::interval(Duration::from_millis(1));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let slot = a.control.child(Child::Network);
    slot.pid
        .store(u64::from(std::process::id()), Ordering::Relaxed);
    loop {
        tick.tick().await;
        while let Ok(r) = a.reports.pop() {
            if publisher.put(wire::encode(&r)).await.is_ok() {
                n.published += 1;
            }
        }
        while let Ok(Some(sample)) = subscriber.try_recv() {
            match wire::decode(&sample.payload().to_bytes()) {
                Ok(r) if r.site as usize == a.site_index => {} // our own, echoed
                Ok(r) => {
                    if a.remote.push(r).is_ok() {
                        n.received += 1;
                    } else {
                        a.control.drops[3].fetch_add(1, Ordering::Relaxed);
                    }
                }
                Err(_) => n.rejected += 1,
            }
        }
        a.control
            .net_published
            .store(n.published, Ordering::Relaxed);
        a.control.net_received.store(n.received, Ordering::Relaxed);
        a.control.net_rejected.store(n.rejected, Ordering::Relaxed);
        slot.heartbeat.fetch_add(1, Ordering::Relaxed);
        if !matches!(
            a.control.run_state(),
            RunState::Starting | RunState::Running
        ) {
            break;
        }
    }
    drop(subscriber);
    drop(publisher);
    let _ = session.close().await;
    Ok(n)
}
