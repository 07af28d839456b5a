//! Zenoh's own log (links opened and closed and why, routing, access control) on stderr when the
//! `RUST_LOG` environment variable asks for it, e.g. `RUST_LOG=zenoh=info,zenoh_transport=debug`.
//! Without it nothing is installed and zenoh says nothing. (Zenoh's own helper,
//! `zenoh::try_init_log_from_env`, writes to stdout, which our commands keep for their output.)

/// Installs a subscriber printing the events `RUST_LOG` selects to stderr, once per process;
/// nothing when `RUST_LOG` is unset or another subscriber came first (a router's refusal counter).
pub fn zenoh_to_stderr() {
    let Ok(filter) = tracing_subscriber::EnvFilter::try_from_default_env() else {
        return;
    };
    let subscriber = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_thread_names(true)
        .finish();
    if tracing::subscriber::set_global_default(subscriber).is_err() {
        eprintln!("RUST_LOG is set but another log subscriber was installed first: ignored");
    }
}
