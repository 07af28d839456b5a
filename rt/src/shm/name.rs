//! Segment names: `coop_<session>_<station>_<what>`, so one station's segments can be found and removed.

/// Where POSIX shared memory lives on Linux.
pub const SHM_DIR: &str = "/dev/shm";
/// Every coop segment name starts with this.
pub const PREFIX: &str = "coop_";

/// A segment name component breaks the rule.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("invalid {what} {value:?}: use 1 to 48 characters from A-Z a-z 0-9 . -, starting with a letter or digit")]
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
    // The scenario's name rule (`coop_model::scenario::NAME_RULE`): no `_` (the separator), no
    // leading `.` or `-` (so neither `.`, `..` nor an option-like name).
    let ok = (1..=48).contains(&value.len())
        && value.as_bytes()[0].is_ascii_alphanumeric()
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

impl std::str::FromStr for SegmentName {
    type Err = NameError;
    /// Parses a full name, `coop_<session>_<station>_<what>`, checking each component.
    fn from_str(s: &str) -> Result<Self, NameError> {
        let bad = || NameError {
            what: "segment name",
            value: s.to_owned(),
        };
        let rest = s.strip_prefix(PREFIX).ok_or_else(bad)?;
        let mut parts = rest.split('_');
        match (parts.next(), parts.next(), parts.next(), parts.next()) {
            (Some(session), Some(station), Some(what), None) => Self::new(session, station, what),
            _ => Err(bad()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_build_and_parse() {
        let n = SegmentName::new("s1", "alice", "tool").expect("valid");
        assert_eq!(n.as_str(), "coop_s1_alice_tool");
        assert_eq!("coop_s1_alice_tool".parse::<SegmentName>(), Ok(n));
        for bad in [
            "coop_a_b",
            "coop_a_b_c_d",
            "x_a_b_c",
            "coop_a/b_c_d",
            "coop__b_c",
        ] {
            assert!(bad.parse::<SegmentName>().is_err(), "{bad}");
        }
        assert!(SegmentName::new("a_b", "c", "d").is_err());
        for bad in ["..", ".", "-x", ".hidden"] {
            assert!(SegmentName::new(bad, "c", "d").is_err(), "{bad}");
        }
        assert!(SegmentName::new(&"x".repeat(49), "c", "d").is_err());
    }
}
