//! The Haply Inverse Service's JSON (format 3.1) on the simulation channel: one place that encodes
//! our force command and one that decodes the service's frames, refusing anything malformed.
//!
//! Not on the servo path: the bridge thread calls these (they allocate).
//!
//! What the service sends (docs.haply.co, "WebSocket Protocol"): a full snapshot on connect, then one
//! frame per message we send, each `{"inverse3": [{"device_id", "state": {"cursor_position",
//! "cursor_velocity", "current_cursor_force", ...}, "config"?, "status"?}], "wireless_verse_grip"?:
//! [{"state": {"orientation", "buttons"}}]}`.

use std::fmt::Write as _;

use coop_model::body::Vec3;
use nalgebra::{Quaternion, UnitQuaternion};
use serde_json::Value;

/// The largest position or velocity component we accept, m or m/s: an Inverse3's workspace is well
/// inside a metre, so anything past this is a corrupt frame, not a hand.
const MAX_ABS_COMPONENT: f64 = 10.0;

/// What one frame says of our Inverse3 (and of a VerseGrip, if one is paired).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceState {
    /// `state.cursor_position`, m.
    pub position_m: Vec3,
    /// `state.cursor_velocity`, m/s.
    pub velocity_m_s: Vec3,
    /// `state.current_cursor_force`, N: the force the service displays now (our last command).
    pub displayed_force_n: Option<Vec3>,
    /// The first VerseGrip's `state.orientation`.
    pub orientation: Option<UnitQuaternion<f64>>,
    /// The first VerseGrip's `state.buttons` a, b, c as bits 0, 1, 2.
    pub buttons: u32,
}

/// One Inverse3 in a snapshot (what `station devices` lists).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ListedDevice {
    /// `device_id`, e.g. `"049D"`.
    pub device_id: String,
    /// `config.handedness`, when the snapshot carries it.
    pub handedness: Option<String>,
    /// `config.port`, when the snapshot carries it.
    pub port: Option<String>,
}

/// Why a frame was refused. `what` is static so the servo side can carry it in a `DeviceFault`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what}: {detail}")]
pub struct FrameError {
    /// What was wrong, e.g. `"haply frame is not JSON"`.
    pub what: &'static str,
    /// The parser's words or the offending value.
    pub detail: String,
}

fn err(what: &'static str, detail: impl Into<String>) -> FrameError {
    FrameError {
        what,
        detail: detail.into(),
    }
}

/// Parses a frame as JSON with a top-level object.
///
/// # Errors
/// Not JSON (NaN and Infinity are not JSON either), or not an object.
pub fn parse(text: &str) -> Result<Value, FrameError> {
    let v: Value =
        serde_json::from_str(text).map_err(|e| err("haply frame is not JSON", e.to_string()))?;
    if !v.is_object() {
        return Err(err("haply frame is not a JSON object", clip(text)));
    }
    Ok(v)
}

/// The Inverse3 devices a snapshot lists.
///
/// # Errors
/// `inverse3` is present but not an array of objects with a string `device_id`.
pub fn list_devices(frame: &Value) -> Result<Vec<ListedDevice>, FrameError> {
    let Some(list) = frame.get("inverse3") else {
        return Ok(Vec::new());
    };
    let list = list
        .as_array()
        .ok_or_else(|| err("haply frame's inverse3 is not an array", list.to_string()))?;
    list.iter()
        .map(|d| {
            let id = d.get("device_id").and_then(Value::as_str).ok_or_else(|| {
                err(
                    "haply frame's inverse3 entry has no device_id",
                    clip(&d.to_string()),
                )
            })?;
            let cfg = d.get("config");
            let s = |k: &str| {
                cfg.and_then(|c| c.get(k))
                    .and_then(Value::as_str)
                    .map(str::to_owned)
            };
            Ok(ListedDevice {
                device_id: id.to_owned(),
                handedness: s("handedness"),
                port: s("port"),
            })
        })
        .collect()
}

/// Our device's state in a frame.
///
/// # Errors
/// The device is missing, a field is missing or not a number, or a value is out of range.
pub fn device_state(frame: &Value, device_id: &str) -> Result<DeviceState, FrameError> {
    let list = frame
        .get("inverse3")
        .and_then(Value::as_array)
        .ok_or_else(|| err("haply frame has no inverse3 list", clip(&frame.to_string())))?;
    let dev = list
        .iter()
        .find(|d| d.get("device_id").and_then(Value::as_str) == Some(device_id))
        .ok_or_else(|| {
            err(
                "haply frame does not list our Inverse3",
                device_id.to_owned(),
            )
        })?;
    let state = dev.get("state").ok_or_else(|| {
        err(
            "haply frame's Inverse3 has no state",
            clip(&dev.to_string()),
        )
    })?;
    let position_m = vec3(state, "cursor_position", "haply cursor_position is bad")?;
    let velocity_m_s = vec3(state, "cursor_velocity", "haply cursor_velocity is bad")?;
    let displayed_force_n = match state.get("current_cursor_force") {
        None => None,
        Some(_) => Some(vec3(
            state,
            "current_cursor_force",
            "haply current_cursor_force is bad",
        )?),
    };
    let bounded = |v: &Vec3| v.iter().all(|c| c.abs() <= MAX_ABS_COMPONENT);
    if !bounded(&position_m) {
        return Err(err(
            "haply cursor_position is out of range",
            format!("{position_m:?}"),
        ));
    }
    if !bounded(&velocity_m_s) {
        return Err(err(
            "haply cursor_velocity is out of range",
            format!("{velocity_m_s:?}"),
        ));
    }
    let grip = ["wireless_verse_grip", "verse_grip"]
        .iter()
        .find_map(|k| {
            frame
                .get(*k)
                .and_then(Value::as_array)
                .and_then(|a| a.first())
        })
        .and_then(|g| g.get("state"));
    let (orientation, buttons) = match grip {
        None => (None, 0),
        Some(g) => (orientation(g)?, buttons(g)),
    };
    Ok(DeviceState {
        position_m,
        velocity_m_s,
        displayed_force_n,
        orientation,
        buttons,
    })
}

fn vec3(obj: &Value, key: &str, what: &'static str) -> Result<Vec3, FrameError> {
    let v = obj.get(key).ok_or_else(|| err(what, format!("no {key}")))?;
    let c = |k: &str| {
        v.get(k)
            .and_then(Value::as_f64)
            .filter(|x| x.is_finite())
            .ok_or_else(|| err(what, clip(&v.to_string())))
    };
    Ok(Vec3::new(c("x")?, c("y")?, c("z")?))
}

fn orientation(grip: &Value) -> Result<Option<UnitQuaternion<f64>>, FrameError> {
    let Some(o) = grip.get("orientation") else {
        return Ok(None);
    };
    let what = "haply VerseGrip orientation is bad";
    let c = |k: &str| {
        o.get(k)
            .and_then(Value::as_f64)
            .filter(|x| x.is_finite())
            .ok_or_else(|| err(what, clip(&o.to_string())))
    };
    let q = Quaternion::new(c("w")?, c("x")?, c("y")?, c("z")?);
    if !(q.norm() > 0.5 && q.norm() < 1.5) {
        return Err(err(what, clip(&o.to_string())));
    }
    Ok(Some(UnitQuaternion::from_quaternion(q)))
}

fn buttons(grip: &Value) -> u32 {
    let Some(b) = grip.get("buttons") else {
        return 0;
    };
    ["a", "b", "c"]
        .iter()
        .enumerate()
        .filter(|(_, k)| b.get(**k).and_then(Value::as_bool) == Some(true))
        .fold(0, |m, (i, _)| m | (1 << i))
}

fn clip(s: &str) -> String {
    const MAX: usize = 120;
    match s.char_indices().nth(MAX) {
        None => s.to_owned(),
        Some((i, _)) => format!("{}…", &s[..i]),
    }
}

/// Writes our one command, `set_cursor_force` for `device_id_json` (already a JSON string literal),
/// into `out` (cleared first; reused, so steady state does not allocate). Non-finite components are
/// written as 0: JSON has no NaN, and no force is the safe reading of one.
pub fn encode_force(out: &mut String, device_id_json: &str, f: Vec3) {
    out.clear();
    let c = |x: f64| if x.is_finite() { x } else { 0.0 };
    // Writing to a String cannot fail.
    let _ = write!(
        out,
        r#"{{"inverse3":[{{"device_id":{device_id_json},"commands":{{"set_cursor_force":{{"values":{{"x":{},"y":{},"z":{}}}}}}}}}]}}"#,
        c(f.x),
        c(f.y),
        c(f.z)
    );
}

/// The request for a full snapshot (`session.force_render_full_state`).
pub const FULL_STATE_REQUEST: &str = r#"{"session":{"force_render_full_state":{}}}"#;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encodes_a_command_the_service_parses() {
        let mut s = String::new();
        encode_force(&mut s, "\"049D\"", Vec3::new(0.5, -1.25, f64::NAN));
        let v: Value = serde_json::from_str(&s).expect("valid JSON");
        let vals = &v["inverse3"][0]["commands"]["set_cursor_force"]["values"];
        assert_eq!(v["inverse3"][0]["device_id"], "049D");
        assert_eq!(vals["x"], 0.5);
        assert_eq!(vals["y"], -1.25);
        assert_eq!(vals["z"], 0.0);
    }

    #[test]
    fn decodes_state_grip_and_refuses_garbage() {
        let f = parse(
            r#"{"inverse3":[{"device_id":"049D","state":{"cursor_position":{"x":0.1,"y":0.2,"z":0.3},
            "cursor_velocity":{"x":0,"y":0,"z":1},"current_cursor_force":{"x":1,"y":2,"z":3}}}],
            "wireless_verse_grip":[{"state":{"orientation":{"w":1,"x":0,"y":0,"z":0},
            "buttons":{"a":false,"b":true,"c":true}}}]}"#,
        )
        .expect("parses");
        let s = device_state(&f, "049D").expect("our device");
        assert_eq!(s.position_m, Vec3::new(0.1, 0.2, 0.3));
        assert_eq!(s.displayed_force_n, Some(Vec3::new(1.0, 2.0, 3.0)));
        assert_eq!(s.buttons, 0b110);
        assert!(s.orientation.is_some());
        assert_eq!(
            device_state(&f, "0001").map_err(|e| e.what),
            Err("haply frame does not list our Inverse3")
        );
        assert_eq!(
            parse("<html>").map_err(|e| e.what),
            Err("haply frame is not JSON")
        );
        let nan = r#"{"inverse3":[{"device_id":"049D","state":{"cursor_position":{"x":NaN,"y":0,"z":0}}}]}"#;
        assert_eq!(
            parse(nan).map_err(|e| e.what),
            Err("haply frame is not JSON")
        );
        let far = parse(
            r#"{"inverse3":[{"device_id":"049D","state":{"cursor_position":{"x":1e9,"y":0,"z":0},
            "cursor_velocity":{"x":0,"y":0,"z":0}}}]}"#,
        )
        .expect("parses");
        assert_eq!(
            device_state(&far, "049D").map_err(|e| e.what),
            Err("haply cursor_position is out of range")
        );
    }
}
