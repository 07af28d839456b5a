//! What can stop the network process from starting (or closing) cleanly.

use coop_model::MAX_SITES;

use crate::recording::RecordingError;

/// The network process could not be set up or closed.
#[derive(Debug, thiserror::Error)]
pub enum NetworkError {
    /// This site's index is not one of the scenario's sites.
    #[error("site index {0} is not in the scenario")]
    NoSuchSite(usize),
    /// More sites than the fixed-size tables hold.
    #[error("{0} sites: at most {MAX_SITES}")]
    TooManySites(usize),
    /// Zenoh refused a configuration value.
    #[error("zenoh configuration {key}: {error}")]
    Config {
        /// The configuration key.
        key: String,
        /// Zenoh's reason.
        error: zenoh::Error,
    },
    /// The access control file cannot be read, or zenoh does not take it.
    #[error("access control {}: {reason}", path.display())]
    AccessControl {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        reason: String,
    },
    /// The recording could not be created.
    #[error("creating the recording: {0}")]
    Recording(#[from] RecordingError),
    /// The station's live view could not be started.
    #[error("the live view: {0}")]
    LiveView(#[from] crate::live_view::LiveViewError),
    /// The zenoh session could not be opened.
    #[error("opening the zenoh session: {0}")]
    Open(zenoh::Error),
    /// The zenoh session could not be opened because its links fail, each for the cause found by
    /// probing it ([`super::link`]).
    #[error("{0}")]
    Link(super::link::LinkFailures),
    /// A publisher, subscriber, queryable or liveliness token could not be declared.
    #[error("declaring the {what}: {error}")]
    Declare {
        /// What was being declared.
        what: &'static str,
        /// Zenoh's reason.
        error: zenoh::Error,
    },
    /// A put was refused.
    #[error("{what}: {error}")]
    Put {
        /// What was being put.
        what: &'static str,
        /// Zenoh's reason.
        error: zenoh::Error,
    },
    /// The zenoh session could not be closed.
    #[error("closing the zenoh session: {0}")]
    Close(zenoh::Error),
}

impl NetworkError {
    /// A failed declaration of `what`, for `map_err`.
    pub(crate) fn declare(what: &'static str) -> impl FnOnce(zenoh::Error) -> Self {
        move |error| Self::Declare { what, error }
    }
}
