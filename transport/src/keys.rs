//! Key expressions. Every key a station publishes or subscribes to is built here.

/// The key a site publishes object `obj`'s state on: `coop/<session>/obj/<obj>/state/<site>`.
pub fn state(session: &str, obj: u32, site: &str) -> String {
    format!("coop/{session}/obj/{obj}/state/{site}")
}

/// Every site's state of object `obj` in `session`.
pub fn all_states(session: &str, obj: u32) -> String {
    format!("coop/{session}/obj/{obj}/state/*")
}

#[cfg(test)]
mod tests {
    #[test]
    fn keys() {
        assert_eq!(super::state("s1", 0, "user1"), "coop/s1/obj/0/state/user1");
        assert_eq!(super::all_states("s1", 0), "coop/s1/obj/0/state/*");
    }
}
