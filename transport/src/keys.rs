//! Key expressions. Every key a station publishes, declares or queries is built here (see
//! `docs/wire.md`).

/// The key a site publishes object `obj`'s state on: `coop/<session>/obj/<obj>/state/<site>`.
pub fn state(session: &str, obj: u32, site: &str) -> String {
    format!("coop/{session}/obj/{obj}/state/{site}")
}

/// Every site's state of object `obj` in `session`.
pub fn all_states(session: &str, obj: u32) -> String {
    format!("coop/{session}/obj/{obj}/state/*")
}

/// Every site's state of every object in `session`: `coop/<session>/obj/*/state/*`.
pub fn all_object_states(session: &str) -> String {
    format!("coop/{session}/obj/*/state/*")
}

/// Every site's current-state queryable of every object.
pub fn all_object_current(session: &str) -> String {
    format!("coop/{session}/obj/*/current/*")
}

/// Every object's state key of `site`: `coop/<session>/obj/*/state/<site>` (what its access
/// control lets it put).
pub fn states_of(session: &str, site: &str) -> String {
    format!("coop/{session}/obj/*/state/{site}")
}

/// Every object's current-state queryable of `site`.
pub fn currents_of(session: &str, site: &str) -> String {
    format!("coop/{session}/obj/*/current/{site}")
}

/// The object a state, current or tool key names (`…/obj/<obj>/…`), if it names one.
pub fn object_of(key: &str) -> Option<u64> {
    let mut chunks = key.split('/');
    chunks.find(|&c| c == "obj")?;
    let k = chunks.next()?;
    // Digits only: no sign, no leading `+`, no empty chunk.
    (!k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()))
        .then(|| k.parse().ok())
        .flatten()
}

/// The key a site's tool (its device's end effector) of object `obj`'s world goes on:
/// `coop/<session>/obj/<obj>/tool/<site>`: the site's tool track (wire version 2, methods that
/// exchange tools: `timewarp`); the access control lets only that site put it.
pub fn tool(session: &str, obj: u32, site: &str) -> String {
    format!("coop/{session}/obj/{obj}/tool/{site}")
}

/// Every site's tool key of object `obj`.
pub fn all_tools(session: &str, obj: u32) -> String {
    format!("coop/{session}/obj/{obj}/tool/*")
}

/// Every key of `session`: `coop/<session>/**`.
pub fn session_keys(session: &str) -> String {
    format!("coop/{session}/**")
}

/// The queryable a site answers with its newest state of object `obj` (for late joiners).
pub fn current(session: &str, obj: u32, site: &str) -> String {
    format!("coop/{session}/obj/{obj}/current/{site}")
}

/// Every site's current-state queryable.
pub fn all_current(session: &str, obj: u32) -> String {
    format!("coop/{session}/obj/{obj}/current/*")
}

/// A site's liveliness token: present while its network process runs.
pub fn presence(session: &str, site: &str) -> String {
    format!("coop/{session}/presence/{site}")
}

/// Every site's clock queryable.
pub fn all_clocks(session: &str) -> String {
    format!("coop/{session}/clock/*")
}

/// Every site's liveliness token.
pub fn all_presence(session: &str) -> String {
    format!("coop/{session}/presence/*")
}

/// The queryable a site answers with its clock (NTP-style offset estimation).
pub fn clock(session: &str, site: &str) -> String {
    format!("coop/{session}/clock/{site}")
}

/// The queryable a site answers with its run's figures (`network::figures`).
pub fn figures(session: &str, site: &str) -> String {
    format!("coop/{session}/figures/{site}")
}

/// Every site's figures queryable.
pub fn all_figures(session: &str) -> String {
    format!("coop/{session}/figures/*")
}

/// The session's time 0, put and answered by the launcher.
pub fn epoch(session: &str) -> String {
    format!("coop/{session}/epoch")
}

/// A study's trials, put by its runner (the launcher): each trial's scenario, and then its time 0
/// (`network::trial`).
pub fn trial(session: &str) -> String {
    format!("coop/{session}/trial")
}

/// The key a site puts its newest sample (copy and tool) on for live viewers, at most ~60 Hz.
pub fn live(session: &str, site: &str) -> String {
    format!("coop/{session}/live/{site}")
}

/// Every site's live samples.
pub fn all_live(session: &str) -> String {
    format!("coop/{session}/live/*")
}

/// The last chunk of a key: the site name of a state, current, presence or clock key.
pub fn site_of(key: &str) -> &str {
    key.rsplit('/').next().unwrap_or("")
}

#[cfg(test)]
mod tests {
    #[test]
    fn keys() {
        assert_eq!(super::state("s1", 0, "user1"), "coop/s1/obj/0/state/user1");
        assert_eq!(super::all_states("s1", 0), "coop/s1/obj/0/state/*");
        assert_eq!(super::current("s1", 0, "u"), "coop/s1/obj/0/current/u");
        assert_eq!(super::presence("s1", "u"), "coop/s1/presence/u");
        assert_eq!(super::clock("s1", "u"), "coop/s1/clock/u");
        assert_eq!(super::epoch("s1"), "coop/s1/epoch");
        assert_eq!(super::tool("s1", 0, "u"), "coop/s1/obj/0/tool/u");
        assert_eq!(super::all_tools("s1", 0), "coop/s1/obj/0/tool/*");
        assert_eq!(super::all_clocks("s1"), "coop/s1/clock/*");
        assert_eq!(super::session_keys("s1"), "coop/s1/**");
        assert_eq!(super::live("s1", "u"), "coop/s1/live/u");
        assert_eq!(super::all_live("s1"), "coop/s1/live/*");
        assert_eq!(super::site_of(&super::state("s", 0, "user2")), "user2");
        assert_eq!(super::all_object_states("s1"), "coop/s1/obj/*/state/*");
        assert_eq!(super::all_object_current("s1"), "coop/s1/obj/*/current/*");
        assert_eq!(super::object_of(&super::state("s", 12, "u")), Some(12));
        assert_eq!(super::object_of(&super::tool("s", 0, "u")), Some(0));
        for bad in [
            "coop/s/obj/+1/state/u",
            "coop/s/obj//state/u",
            "coop/s/obj/x/state/u",
        ] {
            assert_eq!(super::object_of(bad), None, "{bad}");
        }
        assert_eq!(super::object_of("coop/s/presence/u"), None);
    }
}
