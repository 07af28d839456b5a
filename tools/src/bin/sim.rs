//! `sim`: the deterministic multi-site simulator. See `sim --help`.

use clap::Parser;

fn main() -> std::process::ExitCode {
    coop_tools::run_main(|| coop_tools::sim::main(coop_tools::sim::Args::parse()))
}
