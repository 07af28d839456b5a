//! `ringbench`: shared-memory ring across processes vs rtrb across threads. See `ringbench --help`.

use clap::Parser;

fn main() -> std::process::ExitCode {
    coop_tools::run_main(|| coop_tools::ringbench::run(&coop_tools::ringbench::Args::parse()))
}
