//! `fuzz`: hostile input at volume for the wire, scenario and station-config parsers. See `fuzz --help`.

use clap::Parser;

fn main() -> std::process::ExitCode {
    coop_tools::run_main(|| coop_tools::fuzz::main(&coop_tools::fuzz::Args::parse()))
}
