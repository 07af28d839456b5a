//! coop-actors: the station as a library, and its supervisor on ractor and tokio.
//!
//! [`router`] is `station router`: a zenoh router enforcing a session's access control, for
//! sessions across machines.
//!
//! [`station`] is one site's processes: configuration, the children's entry points, `station run`
//! with its stop ladder, and `station status`. The binaries in `coop-tools` are thin mains over it.
//!
//! One [`child::ChildProcess`] actor per OS child (servo, physics, network), each owning its process,
//! started as a process-group leader and watched by a heartbeat; one [`supervisor::StationSupervisor`]
//! linking them and applying a [`policy::RestartPolicy`] written as data. Nothing here runs on a
//! real-time path: the supervisor only spawns, watches and signals processes.
//!
//! Never build this with `panic = "abort"`: ractor turns a panicking actor into a supervision event.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod child;
pub mod policy;
pub mod router;
pub mod scenario_file;
pub mod station;
pub mod supervisor;
pub mod trajectory_file;

/// What the unit tests share.
#[cfg(test)]
pub(crate) mod testing {
    /// An error as the binaries print it (anyhow's `{:#}`): its message, then each source's.
    pub(crate) fn chain(e: &dyn std::error::Error) -> String {
        let mut out = e.to_string();
        let mut next = e.source();
        while let Some(s) = next {
            out = format!("{out}: {s}");
            next = s.source();
        }
        out
    }
}
