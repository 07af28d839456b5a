//! The reference pages of every file a user writes (a scenario, a station's configuration, a
//! router's), generated from the code so they cannot drift from it: the fields, their types and
//! defaults come from the types' JSON Schema (derived with `schemars`, the doc comments its
//! descriptions); each field's unit from its name (the project's units-in-names convention); and
//! its rule from the checks themselves: the field is set to a value no rule allows (NaN, an empty
//! name, the largest integer) in a valid file, and the rule the check names for that field is the
//! rule printed. A field without a doc comment is refused, so none is added without its line.
//!
//! `sim reference` writes the pages into `docs/reference/`; a test fails when a committed page
//! differs from what the code generates.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context};
use serde_json::{Map, Value};

use coop_actors::router::RouterConfig;
use coop_actors::scenario_file::{self, ParseError};
use coop_actors::station::config::{ConfigError, Problem, StationConfig};
use coop_model::scenario::Scenario;

/// The scenario `sim template` prints: every table a scenario may hold, commented; also the
/// valid file the scenario page's rules are probed in.
pub const TEMPLATE: &str = include_str!("../../scenarios/template.toml");

/// The router configuration the router page's rules are probed in.
const ROUTER_BASE: &str = "name = \"router1\"\nlisten = [\"tcp/127.0.0.1:7447\"]\n";

/// Where the pages live, relative to the repository's root.
pub const DIR: &str = "docs/reference";

/// One generated page.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Page {
    /// Its file name in [`DIR`].
    pub file: &'static str,
    /// Its text.
    pub text: String,
}

/// A check that names the field it refuses, and the rule.
type Check = fn(&str) -> Option<(String, String)>;

/// What a file is, for one page.
struct Kind {
    file: &'static str,
    title: &'static str,
    intro: &'static str,
    schema: Value,
    base: String,
    check: Check,
}

/// Every page, generated.
///
/// # Errors
/// A field without a doc comment, or a base file the checks refuse (a build that broke it).
pub fn pages() -> anyhow::Result<Vec<Page>> {
    let station_base = toml::to_string(&StationConfig::default())?;
    let kinds = [
        Kind {
            file: "scenario.md",
            title: "Scenario files",
            intro: "A scenario is one TOML file: the world, its objects, the sites with their \
                    rates, devices and users (scripted or simulated participants), the emulated \
                    network, the phases checked after a run and the task judged live. `sim \
                    template` prints a commented one to start from; `sim check FILE` checks one \
                    without running it. How phases and tasks are judged: [Scenarios](../scenarios.md).",
            schema: serde_json::to_value(schemars::schema_for!(Scenario))?,
            base: TEMPLATE.to_owned(),
            check: check_scenario,
        },
        Kind {
            file: "station.md",
            title: "Station configuration",
            intro: "A station's configuration is one TOML file (`station run --config FILE`); \
                    every field may be left out for its default, and `session run` writes one per \
                    site into its output directory (`user1.toml`, …), a good start. Relative paths \
                    are relative to the file's directory. How to run stations on several \
                    machines: [Many machines](../many-machines.md).",
            schema: serde_json::to_value(schemars::schema_for!(StationConfig))?,
            base: station_base,
            check: check_station,
        },
        Kind {
            file: "router.md",
            title: "Router configuration",
            intro: "A zenoh router's configuration (`station router run --config FILE`), one \
                    TOML file; `session certs` writes one per router with its certificates. \
                    Relative paths are relative to the file's directory.",
            schema: serde_json::to_value(schemars::schema_for!(RouterConfig))?,
            base: ROUTER_BASE.to_owned(),
            check: check_router,
        },
    ];
    kinds.iter().map(page).collect()
}

/// Writes every page into `root/docs/reference` or, with `check`, fails naming each page that
/// differs from what the code generates.
///
/// # Errors
/// A page that cannot be written, or (with `check`) a stale one.
pub fn write(root: &Path, check: bool) -> anyhow::Result<()> {
    let dir = root.join(DIR);
    let mut stale = Vec::new();
    for p in pages()? {
        let path = dir.join(p.file);
        if check {
            if std::fs::read_to_string(&path).ok().as_deref() != Some(p.text.as_str()) {
                stale.push(path.display().to_string());
            }
        } else {
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            std::fs::write(&path, &p.text)
                .with_context(|| format!("writing {}", path.display()))?;
            println!("wrote {}", path.display());
        }
    }
    if !stale.is_empty() {
        bail!(
            "stale reference pages (the code's fields changed): {}; run `sim reference` and commit them",
            stale.join(", ")
        );
    }
    Ok(())
}

/// One table of a file: its fields, and the tables inside it after.
struct Section {
    header: String,
    doc: String,
    rows: Vec<Row>,
}

struct Row {
    field: String,
    ty: String,
    unit: String,
    default: String,
    rule: String,
    doc: String,
}

/// A step of a field's path: a key, or every entry of an array of tables (a rule may hold for
/// one kind of entry only: a step that waits, a box).
#[derive(Debug, Clone)]
enum Seg {
    Key(String),
    Each(String),
}

struct Walk<'a> {
    defs: &'a Map<String, Value>,
    base: toml::Table,
    check: Check,
    /// The definitions already given a section, with its header and index: another field of the
    /// same type points to it, and the rules its section lacks are probed again there (a
    /// condition's clauses are checked in a task, not in a step that does not wait).
    done: BTreeMap<String, (String, usize)>,
    /// The other places of a definition with a section, probed once every section is made.
    again: Vec<(String, Vec<Seg>)>,
    sections: Vec<Section>,
}

fn page(k: &Kind) -> anyhow::Result<Page> {
    let empty = Map::new();
    let defs = k
        .schema
        .get("$defs")
        .and_then(Value::as_object)
        .unwrap_or(&empty);
    let base: toml::Table = toml::from_str(&k.base).context("the base file of the probes")?;
    if let Some((field, rule)) = (k.check)(&k.base) {
        bail!("the base file of {} is refused: {field}: {rule}", k.file);
    }
    let mut w = Walk {
        defs,
        base,
        check: k.check,
        done: BTreeMap::new(),
        again: Vec::new(),
        sections: Vec::new(),
    };
    w.table(&k.schema, &[], "top level", describe(&k.schema), None)?;
    for (name, path) in std::mem::take(&mut w.again) {
        let section = w.done[&name].1;
        w.reprobe(section, &name, &path);
    }
    let mut text = format!(
        "<!-- Generated by `sim reference` from the code: do not edit; a test fails when it is stale. -->\n\
         # {}\n\n{}\n\n\
         Each table lists its fields: the type, the unit (from the field's name), the default \
         (used when the field is left out), the rule a value must keep (as the check states it; \
         a value that breaks it is refused with the field, the value and the rule) and what the \
         field is.\n",
        k.title, k.intro
    );
    for s in &w.sections {
        let _ = write!(text, "\n## {}\n\n{}\n\n", s.header, s.doc);
        if s.rows.is_empty() {
            continue;
        }
        text.push_str("| field | type | unit | default | rule | what it is |\n");
        text.push_str("|---|---|---|---|---|---|\n");
        for r in &s.rows {
            let _ = writeln!(
                text,
                "| `{}` | {} | {} | {} | {} | {} |",
                r.field,
                cell(&r.ty),
                cell(&r.unit),
                cell(&r.default),
                cell(&r.rule),
                cell(&r.doc)
            );
        }
    }
    Ok(Page { file: k.file, text })
}

impl Walk<'_> {
    /// A table's section (its own fields), then the sections of the tables inside it.
    fn table(
        &mut self,
        schema: &Value,
        path: &[Seg],
        header: &str,
        doc: String,
        defaults: Option<&Map<String, Value>>,
    ) -> anyhow::Result<()> {
        let empty = Map::new();
        let props = schema
            .get("properties")
            .and_then(Value::as_object)
            .unwrap_or(&empty);
        let at = self.sections.len();
        self.sections.push(Section {
            header: header.to_owned(),
            doc,
            rows: Vec::new(),
        });
        let mut inner = Vec::new();
        for (key, prop) in props {
            let doc = describe(prop);
            let shown = dotted(path, key);
            if doc.is_empty() {
                bail!("{shown} has no doc comment: every field needs one (it is the reference's line)");
            }
            let default = defaults
                .and_then(|d| d.get(key))
                .or_else(|| prop.get("default"));
            if let Some((name, array)) = self.table_def(prop) {
                let sub_header = if array {
                    format!("`[[{shown}]]`")
                } else {
                    format!("`[{shown}]`")
                };
                let what = if array { "tables" } else { "table" };
                let mut p = path.to_vec();
                p.push(if array {
                    Seg::Each(key.clone())
                } else {
                    Seg::Key(key.clone())
                });
                let ty = match self.done.get(&name) {
                    Some((first, _)) => {
                        let ty = format!("{what} as {first}");
                        self.again.push((name.clone(), p.clone()));
                        ty
                    }
                    None => format!("{what} (below)"),
                };
                let def_defaults = self.defs[&name]
                    .get("properties")
                    .and_then(Value::as_object);
                self.sections[at].rows.push(Row {
                    field: key.clone(),
                    ty,
                    unit: String::new(),
                    default: if array {
                        "none".into()
                    } else if default.is_none() {
                        required_or_none(prop)
                    } else {
                        table_default(default, def_defaults)
                    },
                    rule: String::new(),
                    doc,
                });
                if !self.done.contains_key(&name) {
                    // Its section's index is known once it is made, after this table's rows.
                    self.done
                        .insert(name.clone(), (sub_header.clone(), usize::MAX));
                    inner.push((p, name, sub_header, default.cloned(), array));
                }
                continue;
            }
            let mut p = path.to_vec();
            p.push(Seg::Key(key.clone()));
            let ty = self.type_of(prop);
            let rule = self.rule(prop, &p);
            self.sections[at].rows.push(Row {
                field: key.clone(),
                unit: unit_of(key),
                default: default.map_or_else(|| required_or_none(prop), shown_value),
                ty,
                rule,
                doc,
            });
        }
        for (p, name, header, default, array) in inner {
            self.done
                .insert(name.clone(), (header.clone(), self.sections.len()));
            let def = self.defs[&name].clone();
            let doc = describe(&def);
            let d = if array {
                None
            } else {
                default.as_ref().and_then(Value::as_object)
            };
            self.table(&def, &p, &header, doc, d)?;
        }
        Ok(())
    }
}

impl Walk<'_> {
    /// The definition a field's value is a table of, and whether it is an array of them.
    fn table_def(&self, prop: &Value) -> Option<(String, bool)> {
        if let Some(items) = prop.get("items") {
            return self.object_ref(items).map(|n| (n, true));
        }
        if let Some(n) = self.object_ref(prop) {
            return Some((n, false));
        }
        let any = prop.get("anyOf").and_then(Value::as_array)?;
        any.iter()
            .find_map(|v| self.object_ref(v))
            .map(|n| (n, false))
    }

    /// The definition `v` refers to, when it is a table (it has fields).
    fn object_ref(&self, v: &Value) -> Option<String> {
        let name = v.get("$ref")?.as_str()?.strip_prefix("#/$defs/")?;
        self.defs
            .get(name)
            .filter(|d| d.get("properties").is_some())
            .map(|_| name.to_owned())
    }

    /// A leaf's type in words.
    fn type_of(&self, prop: &Value) -> String {
        if let Some(name) = prop
            .get("$ref")
            .and_then(Value::as_str)
            .and_then(|r| r.strip_prefix("#/$defs/"))
        {
            return match self.defs.get(name) {
                Some(d) => self.type_of(d),
                None => name.to_owned(),
            };
        }
        if let Some(any) = prop.get("anyOf").and_then(Value::as_array) {
            let some: Vec<String> = any
                .iter()
                .filter(|v| v.get("type").and_then(Value::as_str) != Some("null"))
                .map(|v| self.type_of(v))
                .collect();
            return format!("{} or none", some.join(" or "));
        }
        if let Some(variants) = prop.get("oneOf").or_else(|| prop.get("enum")) {
            let names: Vec<String> = variants
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|v| v.get("const").unwrap_or(v).as_str())
                .map(|n| format!("`{n}`"))
                .collect();
            return format!("one of {}", names.join(", "));
        }
        let (ty, optional) = match prop.get("type") {
            Some(Value::String(t)) => (t.as_str(), false),
            Some(Value::Array(ts)) => (
                ts.iter()
                    .filter_map(Value::as_str)
                    .find(|t| *t != "null")
                    .unwrap_or("null"),
                true,
            ),
            _ => ("any", false),
        };
        let word = match ty {
            "number" => "number".to_owned(),
            "integer" => {
                if prop.get("minimum").and_then(Value::as_f64) == Some(0.0) {
                    "integer ≥ 0".to_owned()
                } else {
                    "integer".to_owned()
                }
            }
            "boolean" => "bool".to_owned(),
            "string" => "string".to_owned(),
            "array" => {
                let item = prop
                    .get("items")
                    .map_or("any".to_owned(), |i| self.type_of(i));
                match (prop.get("minItems"), prop.get("maxItems")) {
                    (Some(a), Some(b)) if a == b => format!("[{item}; {a}]"),
                    _ => format!("list of {item}"),
                }
            }
            other => other.to_owned(),
        };
        if optional {
            format!("{word} or none")
        } else {
            word
        }
    }

    /// The rule the check states for the field at `path`, found by giving it values no rule
    /// allows; empty when no such value is refused by a rule naming the field (a free choice, an
    /// enum whose values the type lists, a flag).
    fn rule(&self, prop: &Value, path: &[Seg]) -> String {
        // The first value refused is enough: the rule states the whole range.
        probes(self.defs, prop)
            .into_iter()
            .find_map(|v| {
                let shown = match &v {
                    toml::Value::String(t) => Some(format!("{t:?}")),
                    _ => None,
                };
                self.probe(path, v).map(|r| rule_only(&r, shown.as_deref()))
            })
            .unwrap_or_default()
    }

    /// The base file with the field at `path` set to `v` (in each entry of its arrays in turn),
    /// checked: the rule, when the check names this field.
    fn probe(&self, path: &[Seg], v: toml::Value) -> Option<String> {
        let want = plain(path);
        variants(&self.base, path, &v).into_iter().find_map(|doc| {
            let text = toml::to_string(&doc).ok()?;
            let (field, rule) = (self.check)(&text)?;
            (unindexed(&field) == want).then_some(rule)
        })
    }

    /// Probes again, at `path`, the rules section `section` (of definition `name`) lacks.
    fn reprobe(&mut self, section: usize, name: &str, path: &[Seg]) {
        let Some(props) = self.defs[name].get("properties").and_then(Value::as_object) else {
            return;
        };
        for k in 0..self.sections[section].rows.len() {
            let field = self.sections[section].rows[k].field.clone();
            let Some(prop) = props.get(&field) else {
                continue;
            };
            if !self.sections[section].rows[k].rule.is_empty() || self.table_def(prop).is_some() {
                continue;
            }
            let mut p = path.to_vec();
            p.push(Seg::Key(field));
            self.sections[section].rows[k].rule = self.rule(prop, &p);
        }
    }
}

/// The most documents [`variants`] makes for one probe.
const MAX_VARIANTS: usize = 64;

/// `t` with the field at `path` set to `v`: one document per choice of entry in each array on
/// the way (an absent table or array made, with one entry).
fn variants(t: &toml::Table, path: &[Seg], v: &toml::Value) -> Vec<toml::Table> {
    let with = |k: &str, x: toml::Value| {
        let mut c = t.clone();
        c.insert(k.to_owned(), x);
        c
    };
    match path {
        [] => Vec::new(),
        [Seg::Key(k)] => vec![with(k, v.clone())],
        [Seg::Each(_)] => Vec::new(),
        [Seg::Key(k), rest @ ..] => {
            let sub = t
                .get(k)
                .and_then(toml::Value::as_table)
                .cloned()
                .unwrap_or_default();
            variants(&sub, rest, v)
                .into_iter()
                .map(|s| with(k, toml::Value::Table(s)))
                .collect()
        }
        [Seg::Each(k), rest @ ..] => {
            let entries = t
                .get(k)
                .and_then(toml::Value::as_array)
                .cloned()
                .unwrap_or_else(|| vec![toml::Value::Table(toml::Table::new())]);
            let mut out = Vec::new();
            for (i, e) in entries.iter().enumerate() {
                let Some(sub) = e.as_table() else { continue };
                for s in variants(sub, rest, v) {
                    let mut a = entries.clone();
                    a[i] = toml::Value::Table(s);
                    out.push(with(k, toml::Value::Array(a)));
                    if out.len() >= MAX_VARIANTS {
                        return out;
                    }
                }
            }
            out
        }
    }
}

/// A field without a default: `none` when it may be left out (an option), else required.
fn required_or_none(prop: &Value) -> String {
    let nullable = |v: &Value| match v.get("type") {
        Some(Value::Array(ts)) => ts.iter().any(|t| t == "null"),
        Some(t) => t == "null",
        None => false,
    };
    let optional = nullable(prop)
        || prop
            .get("anyOf")
            .and_then(Value::as_array)
            .is_some_and(|a| a.iter().any(nullable));
    if optional { "none" } else { "required" }.to_owned()
}

/// A table field's default: its fields' own, or those that differ from them.
fn table_default(default: Option<&Value>, own: Option<&Map<String, Value>>) -> String {
    if default == Some(&Value::Null) {
        return "none".into();
    }
    let (Some(Value::Object(d)), Some(own)) = (default, own) else {
        return "its fields' defaults".into();
    };
    let differ: Vec<String> = d
        .iter()
        .filter(|(k, v)| own.get(*k).and_then(|p| p.get("default")) != Some(*v))
        .map(|(k, v)| format!("`{k} = {}`", shown_value(v)))
        .collect();
    if differ.is_empty() {
        "its fields' defaults".into()
    } else {
        format!("its fields' defaults but {}", differ.join(", "))
    }
}

/// The rule of a check's message, without what is the probe's own: a path's rule names the
/// probe's file and this machine's error (said as the rule), and a message that quotes the
/// probe's text before its rule (`invalid session "": use …`) keeps the rule after it.
fn rule_only(message: &str, probe: Option<&str>) -> String {
    if message.starts_with("cannot be read") {
        return "a file that can be read".to_owned();
    }
    if let Some(q) = probe {
        if let Some(i) = message.find(q) {
            if let Some(j) = message[i + q.len()..].find(": ") {
                return message[i + q.len() + j + 2..].to_owned();
            }
        }
    }
    message.to_owned()
}

/// Values no rule should allow, for a leaf of this schema.
fn probes(defs: &Map<String, Value>, prop: &Value) -> Vec<toml::Value> {
    let prop = match prop
        .get("$ref")
        .and_then(Value::as_str)
        .and_then(|r| r.strip_prefix("#/$defs/"))
        .and_then(|n| defs.get(n))
    {
        Some(d) => d,
        None => prop,
    };
    if prop.get("oneOf").is_some() || prop.get("enum").is_some() {
        return Vec::new();
    }
    let ty = match prop.get("type") {
        Some(Value::String(t)) => t.as_str(),
        Some(Value::Array(ts)) => ts
            .iter()
            .filter_map(Value::as_str)
            .find(|t| *t != "null")
            .unwrap_or("null"),
        _ => return Vec::new(),
    };
    match ty {
        "number" => vec![toml::Value::Float(f64::NAN)],
        "integer" => {
            let max = prop
                .get("maximum")
                .and_then(Value::as_f64)
                .map_or(i64::MAX, |m| {
                    if m >= i64::MAX as f64 {
                        i64::MAX
                    } else {
                        m as i64
                    }
                });
            vec![toml::Value::Integer(max), toml::Value::Integer(0)]
        }
        "string" => vec![
            toml::Value::String(String::new()),
            toml::Value::String("not a name!".into()),
        ],
        "array" => {
            let Some(items) = prop.get("items") else {
                return Vec::new();
            };
            let n = prop
                .get("minItems")
                .and_then(Value::as_u64)
                .unwrap_or(1)
                .max(1) as usize;
            probes(defs, items)
                .into_iter()
                .take(1)
                .map(|v| toml::Value::Array(vec![v; n]))
                .collect()
        }
        _ => Vec::new(),
    }
}

fn check_scenario(text: &str) -> Option<(String, String)> {
    match scenario_file::parse(text) {
        Err(ParseError::Rule(e)) => Some((e.field, e.rule)),
        _ => None,
    }
}

fn check_station(text: &str) -> Option<(String, String)> {
    let c: StationConfig = toml::from_str(text).ok()?;
    match c.resolve(None) {
        Err(ConfigError::Invalid(p) | ConfigError::InFile { problem: p, .. }) => named(p),
        _ => None,
    }
}

fn check_router(text: &str) -> Option<(String, String)> {
    let c: RouterConfig = toml::from_str(text).ok()?;
    c.resolve(None).err().and_then(named)
}

/// The field a problem names, and its rule.
fn named(p: Problem) -> Option<(String, String)> {
    match p {
        Problem::Value { field, rule, .. }
        | Problem::Entry { field, rule, .. }
        | Problem::Missing { field, rule } => Some((field, rule)),
        Problem::Needs { field, needs, .. } => Some((field, format!("needs {needs}"))),
        Problem::Table { table, rule } => Some((table, rule)),
        _ => None,
    }
}

/// `site[1].plan[0].for_s` → `site.plan.for_s`.
fn unindexed(field: &str) -> String {
    let mut out = String::with_capacity(field.len());
    let mut depth = 0;
    for c in field.chars() {
        match c {
            '[' => depth += 1,
            ']' => depth -= 1,
            _ if depth == 0 => out.push(c),
            _ => {}
        }
    }
    out
}

fn plain(path: &[Seg]) -> String {
    path.iter()
        .map(|s| match s {
            Seg::Key(k) | Seg::Each(k) => k.as_str(),
        })
        .collect::<Vec<_>>()
        .join(".")
}

fn dotted(path: &[Seg], key: &str) -> String {
    let p = plain(path);
    if p.is_empty() {
        key.to_owned()
    } else {
        format!("{p}.{key}")
    }
}

/// A schema's description as one paragraph, rustdoc's links made plain code.
fn describe(v: &Value) -> String {
    let d = v.get("description").and_then(Value::as_str).unwrap_or("");
    let mut out = String::new();
    let mut rest = d;
    while let Some(i) = rest.find("[`") {
        out.push_str(&rest[..i]);
        let after = &rest[i + 2..];
        match after.find("`]") {
            Some(j) => {
                let name = &after[..j];
                let short = name.rsplit("::").next().unwrap_or(name);
                let _ = write!(out, "`{short}`");
                rest = &after[j + 2..];
            }
            None => {
                out.push_str("[`");
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The unit a field's name ends in (`stiffness_n_per_m` → N/m), or empty.
fn unit_of(key: &str) -> String {
    const UNITS: [(&str, &str); 18] = [
        ("s", "s"),
        ("ms", "ms"),
        ("us", "µs"),
        ("ns", "ns"),
        ("hz", "Hz"),
        ("m", "m"),
        ("mm", "mm"),
        ("kg", "kg"),
        ("n", "N"),
        ("rad", "rad"),
        ("deg", "°"),
        ("mib", "MiB"),
        ("kib", "KiB"),
        ("s2", "s²"),
        ("m2", "m²"),
        ("nm", "N·m"),
        ("kbit", "kbit"),
        ("bit", "bit"),
    ];
    // A speed written `_m_s` (`still_m_s`) is m/s, not m·s.
    if key.ends_with("_m_s") {
        return "m/s".into();
    }
    let unit = |t: &str| UNITS.iter().find(|(k, _)| *k == t).map(|(_, u)| *u);
    let tokens: Vec<&str> = key.split('_').collect();
    let mut start = tokens.len();
    while start > 1 && (unit(tokens[start - 1]).is_some() || tokens[start - 1] == "per") {
        start -= 1;
    }
    let tail = &tokens[start..];
    if tail.first() == Some(&"per") {
        // `per` needs a unit before it (`_per_s` alone names a rate of something else).
        return String::new();
    }
    let mut parts = tail.split(|t| *t == "per");
    let num: Vec<&str> = parts
        .next()
        .unwrap_or(&[])
        .iter()
        .filter_map(|t| unit(t))
        .collect();
    let den: Vec<&str> = parts.flatten().filter_map(|t| unit(t)).collect();
    match (num.is_empty(), den.is_empty()) {
        (true, _) => String::new(),
        (false, true) => num.join("·"),
        (false, false) => format!("{}/{}", num.join("·"), den.join("·")),
    }
}

/// A default as a TOML value is written.
fn shown_value(v: &Value) -> String {
    match v {
        Value::Null => "none".into(),
        Value::String(s) => format!("\"{s}\""),
        Value::Array(a) => format!(
            "[{}]",
            a.iter().map(shown_value).collect::<Vec<_>>().join(", ")
        ),
        Value::Object(_) => "its fields' defaults".into(),
        Value::Number(n) => match n.as_f64() {
            Some(f) if n.is_f64() && f.fract() == 0.0 && f.abs() < 1e15 => format!("{f:.1}"),
            _ => n.to_string(),
        },
        Value::Bool(b) => b.to_string(),
    }
}

/// Text fit for a table cell.
fn cell(s: &str) -> String {
    if s.is_empty() {
        "—".into()
    } else {
        s.replace('|', "\\|")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A field a test adds without its doc comment.
    #[derive(serde::Deserialize, schemars::JsonSchema)]
    #[allow(dead_code, missing_docs)]
    struct Undocumented {
        /// A documented one.
        documented_m: f64,
        bare_s: f64,
    }

    fn kind_of(schema: Value) -> Kind {
        Kind {
            file: "t.md",
            title: "t",
            intro: "t",
            schema,
            base: String::new(),
            check: |_| None,
        }
    }

    #[test]
    fn a_field_without_its_doc_comment_is_refused() {
        let k = kind_of(serde_json::to_value(schemars::schema_for!(Undocumented)).unwrap());
        let e = page(&k)
            .expect_err("an undocumented field was accepted")
            .to_string();
        assert!(e.contains("bare_s has no doc comment"), "{e}");
    }

    #[test]
    fn units_come_from_the_names() {
        for (name, unit) in [
            ("stiffness_n_per_m", "N/m"),
            ("damping_n_s_per_m", "N·s/m"),
            ("gravity_m_per_s2", "m/s²"),
            ("still_m_s", "m/s"),
            ("fitts_b_s_per_bit", "s/bit"),
            ("record_max_file_mib", "MiB"),
            ("start_rpy_deg", "°"),
            ("servo_rate_hz", "Hz"),
            ("friction_static", ""),
            ("elbow", ""),
            ("samples_per_s", ""),
        ] {
            assert_eq!(unit_of(name), unit, "{name}");
        }
    }

    #[test]
    fn a_rule_is_said_without_the_probes_own_text() {
        assert_eq!(
            rule_only("invalid session \"\": use 1 to 48 characters", Some("\"\"")),
            "use 1 to 48 characters"
        );
        assert_eq!(
            rule_only("must be a finite number from 0 to 1", None),
            "must be a finite number from 0 to 1"
        );
        assert_eq!(
            rule_only(
                "cannot be read: No such file or directory (os error 2)",
                None
            ),
            "a file that can be read"
        );
    }

    #[test]
    fn a_path_in_an_error_is_matched_without_its_indices() {
        assert_eq!(unindexed("site[1].plan[0].for_s"), "site.plan.for_s");
        assert_eq!(unindexed("duration_s"), "duration_s");
    }
}
