//! Who may say what in a session: the zenoh access control (ACL) that follows from a scenario.
//!
//! Without it, anyone who reaches a session speaks for any site: a foreign client can put on
//! `coop/<s>/obj/<k>/state/user2` or answer `clock/user2` queries, and the receive checks
//! (`admit`) cannot tell it from user2. Zenoh's ACL decides per message and per link, by the
//! common name of the certificate the other side presented (mutual TLS), so the rules here name
//! certificates: a site's certificate has the site's name as its common name (`session certs`
//! makes them).
//!
//! What it allows, everything else being denied (`default_permission = "deny"`):
//!
//! - site X, coming in: put only its own state, tool and live-view keys; declare (and answer) only its own
//!   `current/X`, `clock/X` and `figures/X` queryables; declare only its own presence token;
//!   subscribe to the session's states, tools, epoch and trials, query its current states, clocks,
//!   figures and epoch, and watch its presence tokens;
//! - the launcher, coming in: the same watching, put, declare and answer the epoch, put a study's
//!   trials (`trial`: only a launcher runs a study on stations), and declare
//!   and answer its own clock, `clock/launcher` (nobody else may do either: stations translate the
//!   epoch, which is in the launcher's clock, with their offset to that clock);
//! - a router of the session, coming in: anything on the session's keys (routers are trusted to
//!   have applied these rules at their own edge);
//! - going out, to any of them: anything on the session's keys (what goes out was let in).
//!
//! With ROS 2 ([`Ros2Members`]: the session's stations publish as ROS 2 topics in a domain), site
//! X may also put on its own namespace (`<domain>/coop/<session>/<X>/**`) and on `/tf` and
//! `/rosout` (shared by every ROS 2 node: their contents are not ours to split), declare the
//! liveliness tokens of its own node (the namespace in the token is X's) and answer queries for
//! its `/rosout` cache; a ROS 2 viewer (RViz, `ros2 bag`, `ros2 topic`, by certificate) may
//! subscribe to and query the domain, watch and declare its graph tokens, and put nothing.
//!
//! A router enforces it on every link. A station can load it too (`network.access_control`):
//! on its links to other stations (peer to peer) it then refuses what a peer may not say; on its
//! link to a router it can only check that the other side is a router of the session.

use serde_json::{json, Value};

use crate::keys;

/// The common name of the launcher's certificate (the only one that may put the epoch).
pub const LAUNCHER: &str = "launcher";

/// Who takes part in a session, by certificate common name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Members<'a> {
    /// Session name (the first component of every key).
    pub session: &'a str,
    /// The scenario's site names, in order (each site's certificate has its name).
    pub sites: &'a [String],
    /// The launcher's common name (usually [`LAUNCHER`]).
    pub launcher: &'a str,
    /// The routers' common names.
    pub routers: &'a [String],
    /// The ROS 2 side, if the session publishes as ROS 2 topics.
    pub ros2: Option<Ros2Members<'a>>,
}

/// A session's ROS 2 side: its domain and who may look at it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Ros2Members<'a> {
    /// The ROS domain the stations publish in.
    pub domain: u32,
    /// The common names of the ROS 2 tools' certificates (RViz, `ros2 bag`, a bridge).
    pub viewers: &'a [String],
}

/// The ROS 2 keys a site puts (its namespace, `/tf`, `/rosout`), answers (its `/rosout` cache)
/// and declares tokens on.
fn ros2_site_keys(d: u32, session: &str, site: &str) -> (Vec<String>, Vec<String>, Vec<String>) {
    let ns = crate::ros2::namespace(session, site);
    let puts = vec![
        format!("{d}{ns}/**"),
        format!("{d}/tf/**"),
        format!("{d}/rosout/**"),
    ];
    let answers = vec![format!("{d}/rosout/*/*/@adv/**"), format!("{d}/rosout/**")];
    // Its node's graph tokens, and the `/rosout` cache's `@adv` token (zenoh-ext's advanced
    // publisher detection, which rmw_zenoh's transient-local subscribers watch).
    let tokens = vec![
        format!(
            "@ros2_lv/{d}/*/*/*/*/%/{}/**",
            crate::ros2::graph::mangle(&ns)
        ),
        format!("{d}/rosout/*/*/@adv/pub/**"),
    ];
    (puts, answers, tokens)
}

/// Everything of ROS 2 domain `d`: its data, the transient-local caches, its graph tokens.
fn ros2_domain_keys(d: u32) -> Vec<String> {
    vec![
        format!("{d}/**"),
        format!("{d}/**/@adv/**"),
        format!("@ros2_lv/{d}/**"),
    ]
}

/// Zenoh message kinds, as its ACL spells them.
const EVERY_MESSAGE: [&str; 9] = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
];

fn rule(id: &str, flow: &str, messages: &[&str], key_exprs: &[String]) -> Value {
    json!({
        "id": id,
        "flows": [flow],
        "permission": "allow",
        "messages": messages,
        "key_exprs": key_exprs,
    })
}

/// The `access_control` object of a zenoh configuration (its JSON form, which is JSON5) that
/// follows from `m`: see the module's documentation.
pub fn session_acl(m: &Members<'_>) -> Value {
    let s = m.session;
    // What routers may say and anyone may be told: the session's keys, and its ROS 2 domain's.
    let mut session_keys = vec![keys::session_keys(s)];
    if let Some(r) = &m.ros2 {
        session_keys.extend(ros2_domain_keys(r.domain));
    }
    let mut rules = vec![
        rule(
            "watch-subscribe",
            "ingress",
            &["declare_subscriber"],
            &[
                keys::all_object_states(s),
                keys::all_tools(s, 0),
                keys::all_live(s),
                keys::epoch(s),
                keys::trial(s),
            ],
        ),
        rule(
            "watch-query",
            "ingress",
            &["query"],
            &[
                keys::all_object_current(s),
                keys::all_clocks(s),
                keys::all_figures(s),
                keys::epoch(s),
            ],
        ),
        rule(
            "watch-presence",
            "ingress",
            &["declare_liveliness_subscriber", "liveliness_query"],
            &[keys::all_presence(s)],
        ),
        rule(
            "launcher-epoch",
            "ingress",
            &["put", "declare_queryable", "reply"],
            &[keys::epoch(s), keys::trial(s)],
        ),
        rule(
            "launcher-clock",
            "ingress",
            &["declare_queryable", "reply"],
            &[keys::clock(s, m.launcher)],
        ),
        rule("router-anything", "ingress", &EVERY_MESSAGE, &session_keys),
        rule("out", "egress", &EVERY_MESSAGE, &session_keys),
    ];
    let watch = ["watch-subscribe", "watch-query", "watch-presence", "out"];
    let mut subjects = vec![json!({"id": "launcher", "cert_common_names": [m.launcher]})];
    let mut policies = vec![json!({
        "id": "launcher",
        "subjects": ["launcher"],
        "rules": ["watch-subscribe", "watch-query", "watch-presence", "launcher-epoch", "launcher-clock", "out"],
    })];
    if !m.routers.is_empty() {
        subjects.push(json!({"id": "routers", "cert_common_names": m.routers}));
        policies.push(json!({
            "id": "routers",
            "subjects": ["routers"],
            "rules": ["router-anything", "out"],
        }));
    }
    for site in m.sites {
        let own = |what: &str| format!("site-{site}-{what}");
        rules.push(rule(
            &own("puts"),
            "ingress",
            &["put"],
            &[
                keys::states_of(s, site),
                keys::tool(s, 0, site),
                keys::live(s, site),
            ],
        ));
        rules.push(rule(
            &own("answers"),
            "ingress",
            &["declare_queryable", "reply"],
            &[
                keys::currents_of(s, site),
                keys::clock(s, site),
                keys::figures(s, site),
            ],
        ));
        rules.push(rule(
            &own("presence"),
            "ingress",
            &["liveliness_token"],
            &[keys::presence(s, site)],
        ));
        let mut mine: Vec<String> = watch.iter().map(|r| (*r).to_owned()).collect();
        mine.extend([own("puts"), own("answers"), own("presence")]);
        if let Some(r) = &m.ros2 {
            let (puts, answers, tokens) = ros2_site_keys(r.domain, s, site);
            rules.push(rule(&own("ros2-puts"), "ingress", &["put"], &puts));
            rules.push(rule(
                &own("ros2-answers"),
                "ingress",
                &["declare_queryable", "reply"],
                &answers,
            ));
            rules.push(rule(
                &own("ros2-tokens"),
                "ingress",
                &["liveliness_token"],
                &tokens,
            ));
            mine.extend([own("ros2-puts"), own("ros2-answers"), own("ros2-tokens")]);
        }
        subjects.push(json!({"id": format!("site-{site}"), "cert_common_names": [site]}));
        policies.push(json!({
            "id": format!("site-{site}"),
            "subjects": [format!("site-{site}")],
            "rules": mine,
        }));
    }
    if let Some(r) = m.ros2.as_ref().filter(|r| !r.viewers.is_empty()) {
        let d = r.domain;
        rules.push(rule(
            "ros2-view",
            "ingress",
            &[
                "declare_subscriber",
                "query",
                "declare_liveliness_subscriber",
                "liveliness_query",
                "liveliness_token",
            ],
            &ros2_domain_keys(d),
        ));
        subjects.push(json!({"id": "ros2-viewers", "cert_common_names": r.viewers}));
        policies.push(json!({
            "id": "ros2-viewers",
            "subjects": ["ros2-viewers"],
            "rules": ["ros2-view", "out"],
        }));
    }
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rule or policy `id` of `acl`'s `what` ("rules", "policies").
    fn entry<'a>(acl: &'a Value, what: &str, id: &str) -> &'a Value {
        acl[what]
            .as_array()
            .unwrap_or_else(|| panic!("{what}"))
            .iter()
            .find(|r| r["id"] == id)
            .unwrap_or_else(|| panic!("{what}: {id}"))
    }

    fn members() -> (Vec<String>, Vec<String>) {
        (
            vec!["user1".to_owned(), "user2".to_owned()],
            vec!["r1".to_owned()],
        )
    }

    #[test]
    fn zenoh_accepts_the_acl_and_opens_a_session_enforcing_it() {
        let (sites, routers) = members();
        let acl = session_acl(&Members {
            session: "s1",
            sites: &sites,
            launcher: LAUNCHER,
            routers: &routers,
            ros2: Some(Ros2Members {
                domain: 7,
                viewers: &["rviz".to_owned()],
            }),
        });
        let mut c = zenoh::Config::default();
        c.insert_json5("access_control", &acl.to_string())
            .expect("zenoh's access_control schema");
        c.insert_json5("listen/endpoints", "[]").expect("no listen");
        c.insert_json5("scouting/multicast/enabled", "false")
            .expect("no scouting");
        // Zenoh checks the rules, subjects and policies (unique ids, known names) at open.
        use zenoh::Wait;
        let s = zenoh::open(c).wait().expect("zenoh takes the policy");
        s.close().wait().expect("close");
    }

    #[test]
    fn each_site_may_put_and_answer_only_its_own_keys() {
        let (sites, routers) = members();
        let acl = session_acl(&Members {
            session: "s1",
            sites: &sites,
            launcher: LAUNCHER,
            routers: &routers,
            ros2: None,
        });
        let rule = |id: &str| entry(&acl, "rules", id);
        assert_eq!(
            rule("site-user2-puts")["key_exprs"],
            json!([
                "coop/s1/obj/*/state/user2",
                "coop/s1/obj/0/tool/user2",
                "coop/s1/live/user2"
            ])
        );
        assert_eq!(
            rule("site-user2-answers")["key_exprs"],
            json!([
                "coop/s1/obj/*/current/user2",
                "coop/s1/clock/user2",
                "coop/s1/figures/user2"
            ])
        );
        let policy = |id: &str| entry(&acl, "policies", id).clone();
        let p2 = policy("site-user2");
        let p2_rules: Vec<&str> = p2["rules"]
            .as_array()
            .expect("rules")
            .iter()
            .filter_map(Value::as_str)
            .collect();
        assert!(p2_rules.contains(&"site-user2-puts"));
        assert!(
            !p2_rules.iter().any(|r| r.contains("user1")),
            "{p2_rules:?}"
        );
        assert!(
            !p2_rules.contains(&"launcher-epoch"),
            "only the launcher puts the epoch"
        );
        let launcher = policy("launcher");
        let launcher_rules = launcher["rules"].as_array().expect("rules");
        assert!(launcher_rules.contains(&json!("launcher-epoch")));
        assert!(launcher_rules.contains(&json!("launcher-clock")));
        assert!(
            !p2_rules.contains(&"launcher-clock"),
            "only the launcher answers its clock"
        );
        assert_eq!(
            rule("launcher-clock")["key_exprs"],
            json!(["coop/s1/clock/launcher"])
        );
        assert_eq!(acl["default_permission"], "deny");
        let subjects = acl["subjects"].as_array().expect("subjects");
        assert!(subjects
            .iter()
            .any(|s| s["id"] == "site-user1" && s["cert_common_names"] == json!(["user1"])));
        assert!(subjects
            .iter()
            .any(|s| s["id"] == "routers" && s["cert_common_names"] == json!(["r1"])));
    }

    #[test]
    fn with_ros2_a_site_puts_only_its_own_namespace_and_a_viewer_puts_nothing() {
        let (sites, routers) = members();
        let viewers = ["rviz".to_owned()];
        let acl = session_acl(&Members {
            session: "s1-timewarp",
            sites: &sites,
            launcher: LAUNCHER,
            routers: &routers,
            ros2: Some(Ros2Members {
                domain: 3,
                viewers: &viewers,
            }),
        });
        let rule = |id: &str| entry(&acl, "rules", id).clone();
        assert_eq!(
            rule("site-user2-ros2-puts")["key_exprs"],
            json!(["3/coop/s1_timewarp/user2/**", "3/tf/**", "3/rosout/**"])
        );
        assert_eq!(
            rule("site-user2-ros2-tokens")["key_exprs"],
            json!([
                "@ros2_lv/3/*/*/*/*/%/%coop%s1_timewarp%user2/**",
                "3/rosout/*/*/@adv/pub/**"
            ])
        );
        let view = rule("ros2-view");
        assert!(!view["messages"].to_string().contains("\"put\""), "{view}");
        let p2 = entry(&acl, "policies", "site-user2");
        assert!(!p2["rules"].to_string().contains("user1"), "{p2}");
        assert_eq!(
            entry(&acl, "policies", "ros2-viewers")["rules"],
            json!(["ros2-view", "out"])
        );
        // Without ROS 2, no ROS 2 key anywhere.
        let plain = session_acl(&Members {
            session: "s1",
            sites: &sites,
            launcher: LAUNCHER,
            routers: &routers,
            ros2: None,
        });
        assert!(!plain.to_string().contains("ros2"), "{plain}");
    }
}
