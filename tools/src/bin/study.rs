//! `study`: a user study from its file to its figures. See `study --help`.

use clap::Parser;

fn main() -> std::process::ExitCode {
    coop_tools::run_main(|| coop_tools::study::cli::main(coop_tools::study::cli::Args::parse()))
}
