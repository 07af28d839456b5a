//! The channels a recording or a session file declares, and each one's schema.
//!
//! Writers name a channel by its [`Topic`] or [`FoxgloveTopic`], never by a position in a list,
//! so a message cannot go on the wrong channel and a part's channels are declared in one order.

use foxglove::messages::{FrameTransform, Log, SceneUpdate};
use foxglove::Encode;

use super::messages::{
    AdoptionMsg, ClockMsg, DivergenceMsg, JsonSchema, ObjectPart, PeerMsg, PresenceMsg,
    PublishedMsg, RemoteMsg, SessionMsg, StatusMsg, TaskMsg, ToolPart,
};

/// A JSON channel (`message_encoding = "json"`, its schema a `jsonschema`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Topic {
    /// `/session`.
    Session,
    /// `/object`.
    Object,
    /// `/tool`.
    Tool,
    /// `/adoption`.
    Adoption,
    /// `/remote`.
    Remote,
    /// `/presence`.
    Presence,
    /// `/clock`.
    Clock,
    /// `/status`.
    Status,
    /// `/published`.
    Published,
    /// `/peer`.
    Peer,
    /// `/task`.
    Task,
    /// `/divergence` (a session file's only).
    Divergence,
}

impl Topic {
    /// A station's recording's channels, in the order every part declares them (their ids follow
    /// it, so a part's layout stays as readers have seen it).
    pub(super) const STATION: [Topic; 11] = [
        Topic::Session,
        Topic::Object,
        Topic::Tool,
        Topic::Adoption,
        Topic::Remote,
        Topic::Presence,
        Topic::Clock,
        Topic::Status,
        Topic::Published,
        Topic::Peer,
        Topic::Task,
    ];

    /// A session file's channels, in order.
    pub(super) const SESSION_FILE: [Topic; 3] = [Topic::Object, Topic::Tool, Topic::Divergence];

    /// The channel's topic.
    pub(super) fn name(self) -> &'static str {
        match self {
            Topic::Session => "/session",
            Topic::Object => "/object",
            Topic::Tool => "/tool",
            Topic::Adoption => "/adoption",
            Topic::Remote => "/remote",
            Topic::Presence => "/presence",
            Topic::Clock => "/clock",
            Topic::Status => "/status",
            Topic::Published => "/published",
            Topic::Peer => "/peer",
            Topic::Task => "/task",
            Topic::Divergence => "/divergence",
        }
    }

    /// The JSON channel whose topic is `name`, if there is one (a station's, or a session
    /// file's own `/divergence`).
    pub(super) fn named(name: &str) -> Option<Topic> {
        Topic::STATION
            .into_iter()
            .chain([Topic::Divergence])
            .find(|t| t.name() == name)
    }

    /// The `jsonschema` of the channel's messages.
    pub(super) fn schema(self) -> serde_json::Value {
        match self {
            Topic::Session => SessionMsg::schema(),
            Topic::Object => ObjectPart::schema(),
            Topic::Tool => ToolPart::schema(),
            Topic::Adoption => AdoptionMsg::schema(),
            Topic::Remote => RemoteMsg::schema(),
            Topic::Presence => PresenceMsg::schema(),
            Topic::Peer => PeerMsg::schema(),
            Topic::Clock => ClockMsg::schema(),
            Topic::Status => StatusMsg::schema(),
            Topic::Published => PublishedMsg::schema(),
            Topic::Task => TaskMsg::schema(),
            Topic::Divergence => DivergenceMsg::schema(),
        }
    }
}

/// One of Foxglove's well-known channels (`message_encoding = "protobuf"`), declared after the
/// JSON ones when the file shows a [`Scene`](super::Scene).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum FoxgloveTopic {
    /// `/tf`: `foxglove.FrameTransform`.
    Tf,
    /// `/scene`: `foxglove.SceneUpdate`.
    Scene,
    /// `/log`: `foxglove.Log`.
    Log,
}

impl FoxgloveTopic {
    /// Every one, in the order a file declares them.
    pub(super) const ALL: [FoxgloveTopic; 3] =
        [FoxgloveTopic::Tf, FoxgloveTopic::Scene, FoxgloveTopic::Log];

    /// The channel's topic.
    pub(super) fn name(self) -> &'static str {
        match self {
            FoxgloveTopic::Tf => "/tf",
            FoxgloveTopic::Scene => "/scene",
            FoxgloveTopic::Log => "/log",
        }
    }

    /// The schema (from the `foxglove` crate) of the channel.
    pub(super) fn schema(self) -> Option<foxglove::Schema> {
        match self {
            FoxgloveTopic::Tf => FrameTransform::get_schema(),
            FoxgloveTopic::Scene => SceneUpdate::get_schema(),
            FoxgloveTopic::Log => Log::get_schema(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The schema of the JSON channel named `topic`.
    fn schema_of(topic: &str) -> serde_json::Value {
        Topic::named(topic).expect("a JSON topic").schema()
    }

    #[test]
    fn every_schema_describes_what_is_written_and_types_its_arrays() {
        fn arrays_have_items(v: &serde_json::Value) -> bool {
            match v {
                serde_json::Value::Object(o) => {
                    (o.get("type") != Some(&"array".into()) || o.contains_key("items"))
                        && o.values().all(arrays_have_items)
                }
                serde_json::Value::Array(a) => a.iter().all(arrays_have_items),
                _ => true,
            }
        }
        fn keys(v: &serde_json::Value) -> Vec<String> {
            v.as_object()
                .map_or_else(Vec::new, |o| o.keys().cloned().collect())
        }
        let written = [
            ("/session", serde_json::to_value(SessionMsg::default())),
            (
                "/object",
                serde_json::to_value(ObjectPart {
                    t_ns: 0,
                    site: String::new(),
                    object: "cup".into(),
                    pos: [0.0; 3],
                    rot: [0.0; 4],
                    vel: [0.0; 3],
                    adoptions: 0,
                    touching: Some(true),
                }),
            ),
            (
                "/tool",
                serde_json::to_value(ToolPart {
                    t_ns: 0,
                    site: String::new(),
                    tool_pos: [0.0; 3],
                    f_desired: [0.0; 3],
                    f_measured: [0.0; 3],
                    f_object: [0.0; 3],
                    touching: false,
                }),
            ),
            ("/adoption", serde_json::to_value(AdoptionMsg::default())),
            ("/remote", serde_json::to_value(RemoteMsg::default())),
            ("/presence", serde_json::to_value(PresenceMsg::default())),
            ("/peer", serde_json::to_value(PeerMsg::default())),
            ("/clock", serde_json::to_value(ClockMsg::default())),
            ("/status", serde_json::to_value(StatusMsg::default())),
            ("/published", serde_json::to_value(PublishedMsg::default())),
            ("/task", serde_json::to_value(TaskMsg::default())),
        ];
        assert_eq!(written.len(), Topic::STATION.len());
        let session_file = [(
            "/divergence",
            serde_json::to_value(DivergenceMsg::default()),
        )];
        for (topic, value) in written.into_iter().chain(session_file) {
            let schema = schema_of(topic);
            assert!(arrays_have_items(&schema), "{topic}: {schema}");
            assert_eq!(
                keys(&schema["properties"]),
                keys(&value.expect("json")),
                "{topic}: the schema's properties are the fields written"
            );
        }
        assert_eq!(
            schema_of("/object")["properties"]["rot"],
            serde_json::json!({"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4})
        );
    }
}
