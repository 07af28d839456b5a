//! Segment names: `coop_<session>_<station>_<what>`, so one station's segments can be found and removed.

/// Where POSIX shared memory lives on Linux.
pub const SHM_DIR: &str = "/dev/shm";
/// Every coop segment name starts with this.
pub const PREFIX: &str = "coop_";

/// A segment name component breaks the rule.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("invalid {what} {value:?}: use 1 to 48 characters from A-Z a-z 0-9 . -")]
pub struct NameError {
    /// Which component ("session", "station", "segment").
    pub what: &'static str,
    /// The value given.
    pub value: String,
}

/// A validated segment name, `coop_<session>_<station>_<what>`.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct SegmentName(String);

impl SegmentName {
    /// Builds the name of segment `what` of `station` in `session`. Components may not contain `_`, so
    /// the prefix of one station never matches another's.
    ///
    /// # Errors
    /// [`NameError`] naming the offending component.
    pub fn new(session: &str, station: &str, what: &str) -> Result<Self, NameError> {
        Ok(Self(format!(
            "{}{}",
            Self::station_prefix(session, station)?,
            check_component("segment", what)?
        )))
    }
    /// `coop_<session>_<station>_`: the prefix of every segment of one station.
    ///
    /// # Errors
    /// [`NameError`] naming the offending component.
    pub fn station_prefix(session: &str, station: &str) -> Result<String, NameError> {
        check_component("session", session)?;
        check_component("station", station)?;
        Ok(format!("{PREFIX}{session}_{station}_"))
    }
    /// The name as given to `shm_open`.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Display for SegmentName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

fn check_component<'a>(what: &'static str, value: &'a str) -> Result<&'a str, NameError> {
    let ok = (1..=48).contains(&value.len())
        && value
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'.' || b == b'-');
    if ok {
        Ok(value)
    } else {
        Err(NameError {
            what,
            value: value.to_owned(),
        })
    }
}
