//! `sim`: the deterministic multi-site simulator. See `sim --help`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    coop_tools::sim::main(coop_tools::sim::Args::parse())
}
