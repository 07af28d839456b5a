//! The Foxglove layout of a scenario's session file (`layout.json`, written next to every
//! `session.mcap`): the shipped world layout (`docs/foxglove-layout-world.json`) with its series
//! made for the scenario's own sites and objects, so a world the layout was not written for opens
//! with every object of every site plotted, and a series names only what the file holds.

use std::path::Path;

use anyhow::Context;
use coop_model::scenario::Scenario;
use serde_json::{json, Value};

/// The shipped world layout: its panels, their arrangement and the look of a series.
const WORLD: &str = include_str!("../../docs/foxglove-layout-world.json");

/// One colour per site, in site order (matplotlib's), then again; the reference is grey.
const SITE_COLOURS: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22",
];
const REFERENCE_COLOUR: &str = "#7f7f7f";

/// The layout for `sc`'s session file: each object's x, y and z as each site and the reference
/// believe it, and each site's divergence from the reference.
///
/// # Panics
/// Never for the shipped layout (a test reads it).
pub fn for_scenario(sc: &Scenario) -> Value {
    let mut v: Value = serde_json::from_str(WORLD).expect("the shipped world layout is JSON");
    let sites: Vec<(&str, &str)> = sc
        .site
        .iter()
        .enumerate()
        .map(|(i, s)| (s.name.as_str(), SITE_COLOURS[i % SITE_COLOURS.len()]))
        .chain([("reference", REFERENCE_COLOUR)])
        .collect();
    let configs = &mut v["configById"];
    for (panel, axis) in [("Plot!objx", 0), ("Plot!objy", 1), ("Plot!objz", 2)] {
        let several = sc.objects.len() > 1;
        let paths: Vec<Value> = (0..sc.objects.len())
            .flat_map(|k| {
                let name = sc.object_name(k);
                sites.iter().map(move |(site, colour)| {
                    // A world of one writes its object's messages without the object's name.
                    let object = if several {
                        format!("{{object==\"{name}\"}}")
                    } else {
                        String::new()
                    };
                    json!({
                        "value": format!("/object{{site==\"{site}\"}}{object}.pos[{axis}]"),
                        "enabled": true,
                        "timestampMethod": "receiveTime",
                        "label": format!("{name} {site}"),
                        "color": colour,
                        "lineSize": 1.5,
                    })
                })
            })
            .collect();
        configs[panel]["paths"] = Value::Array(paths);
    }
    let divergence = &mut configs["Plot!divergence"]["paths"];
    let between = divergence[0].clone();
    let mut paths = vec![between];
    paths.extend(
        sites
            .iter()
            .take(sc.site.len())
            .enumerate()
            .map(|(i, (site, colour))| {
                json!({
                    "value": format!("/divergence.vs_reference_m[{i}]"),
                    "enabled": true,
                    "timestampMethod": "receiveTime",
                    "label": format!("{site} vs reference"),
                    "color": colour,
                })
            }),
    );
    *divergence = Value::Array(paths);
    v
}

/// Writes `layout.json` for `sc` into `dir`.
///
/// # Errors
/// The file cannot be written.
pub fn write(dir: &Path, sc: &Scenario) -> anyhow::Result<()> {
    let path = dir.join("layout.json");
    let text = serde_json::to_string_pretty(&for_scenario(sc))? + "\n";
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
}
