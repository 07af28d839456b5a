//! `station`: one site of a coop-haptics session. See `station --help`.

fn main() -> std::process::ExitCode {
    coop_tools::station::main(std::env::args().collect(), Vec::new())
}
