//! `session`: a multi-site session of real stations on this machine. See `session --help`.

fn main() -> std::process::ExitCode {
    coop_tools::session_cli::main()
}
