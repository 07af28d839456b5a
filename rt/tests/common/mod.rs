//! Helpers shared by coop-rt's integration tests.
pub mod counting_alloc;
