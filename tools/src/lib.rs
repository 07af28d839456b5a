//! coop-tools: the command-line programs of coop-haptics, as thin `main`s over library modules.
//!
//! - [`latency`]: the wake-up latency tool users of cyclictest already know, also attachable to a
//!   running station.
//! - [`ringbench`]: the shared-memory ring against rtrb between two cores.
//! - [`sim`]: the deterministic multi-site simulator's CLI.
//! - [`station`]: the `station` command line over [`coop_actors::station`].
//! - [`sweep`]: `sim sweep`, every method × delay × seed on one scenario; with a live task,
//!   [`sweep::completion`] summarizes success and completion time with confidence intervals
//!   ([`stats`]).
//! - [`session`]: a multi-site session of real stations, recorded and measured; [`session_cli`]
//!   its command line.
//! - [`certs`]: a session's CA, certificates and access control (`session certs`).
//! - [`study`]: a user study's design, its orders, its pilot in simulation and its analysis.
//! - [`fuzz`]: hostile input at volume (wire, scenario, station config), judged by oracles.
//!
//! The binaries set up real-time threads but contain no real-time code of their own beyond the
//! measured loops, which follow coop-rt's contract (no allocation, lock, logging or system call but
//! the timer sleep inside the loop).

// The doc comments of the clap structs are the command lines' help, where `<name>` is a
// placeholder, not an HTML tag.
#![allow(rustdoc::invalid_html_tags)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

/// Runs a tool's body and turns an error into one `error: …` line (the cause chain on it) and exit
/// status 1, whatever `RUST_BACKTRACE` says: users get the message, not a stack.
pub fn run_main(body: impl FnOnce() -> anyhow::Result<()>) -> std::process::ExitCode {
    match body() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

pub mod certs;
pub mod cli;
pub mod deadband;
pub mod devbench;
pub mod figures;
pub mod fuzz;
pub mod latency;
pub mod layout;
pub mod netbench;
pub mod people;
pub mod plots;
pub mod reference;
pub mod ringbench;
pub mod session;
pub mod session_cli;
pub mod sim;
pub mod simbench;
pub mod station;
pub mod stats;
pub mod study;
pub mod sweep;
