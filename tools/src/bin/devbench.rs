//! `devbench`: servo wake-up latency with the Haply backend vs the simulated arm, and the Haply round
//! trip. See `devbench --help`.

use clap::Parser;

fn main() -> std::process::ExitCode {
    coop_tools::run_main(|| coop_tools::devbench::run(&coop_tools::devbench::Args::parse()))
}
