//! `study`: a user study's design as a file, its trial orders, its pilot in simulation and its
//! analysis (see `docs/study.md`).
//!
//! A study file names a task scenario and the factors whose levels make its conditions; each
//! level sets one or more fields of the scenario (any field a scenario file has), so a
//! condition is the scenario with those fields set, checked by the scenario's own rules. Groups
//! (the sites of one session: a pair, a triple) do every within-group condition in an order
//! counterbalanced across groups ([`order`]), each condition a block of its repetitions after
//! its practice trials; a between-group factor gives each group one of its levels.
//!
//! A trial is one run of the task. In simulation ([`run`]) the group's participants are drawn
//! once per group (the scenario's `people_seed`), and each trial runs with its own seed (their
//! motor noise, the network's jitter): the same people, different trials. What each trial leaves
//! is one row per site in a tidy table, written as it finishes, so a cut run resumes where it
//! stopped; [`report`] turns the table into the figures a paper needs.

pub mod board;
pub mod cli;
pub mod csv;
pub mod live;
pub mod order;
pub mod questionnaire;
pub mod report;
pub mod run;
pub mod scores;
pub mod served;
pub mod web;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use serde::{Deserialize, Serialize};

/// A study file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StudyFile {
    /// Short name (A-Z a-z 0-9 . _ -): it names the study's outputs.
    pub name: String,
    /// What it asks.
    #[serde(default)]
    pub description: String,
    /// The task scenario, relative to the study file.
    pub scenario: String,
    /// Seed of the orders (`order = "random"`), the groups' people and the trials' runs.
    #[serde(default = "one")]
    pub seed: u64,
    /// How many groups, named g01, g02, ... (or list them: `[[group]]`).
    #[serde(default)]
    pub groups: Option<usize>,
    /// The groups, each with its participants' ids (one per site of the scenario).
    #[serde(default)]
    pub group: Vec<GroupSpec>,
    /// Measured trials of each condition, one after another in its block.
    #[serde(default = "one_u32")]
    pub repetitions: u32,
    /// Practice trials at the start of each block (not analysed).
    #[serde(default)]
    pub practice: u32,
    /// How each group's conditions are ordered: `williams` (a balanced Latin square: every
    /// condition once in every position, and, for an even number of conditions, every
    /// condition once right after every other), `random` (shuffled per group with `seed`) or
    /// `fixed` (as the factors list them).
    #[serde(default)]
    pub order: OrderKind,
    /// The longest a trial may take, s (the scenario's `duration_s`; its task's timeout, if
    /// shorter, still applies).
    #[serde(default)]
    pub timeout_s: Option<f64>,
    /// The factors.
    pub factor: Vec<FactorSpec>,
    /// What each participant answers after each block (asked in a browser while `study run`
    /// serves its page).
    #[serde(default)]
    pub questionnaire: Option<questionnaire::QuestionnaireSpec>,
}

fn one() -> u64 {
    1
}

fn one_u32() -> u32 {
    1
}

/// A group: the participants of one session, one per site.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GroupSpec {
    /// Its id.
    pub id: String,
    /// Its participants' ids, in the scenario's site order.
    pub participants: Vec<String>,
}

/// How conditions are ordered per group.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum OrderKind {
    /// A balanced Latin square (Williams 1949).
    #[default]
    Williams,
    /// Shuffled per group.
    Random,
    /// As listed.
    Fixed,
}

/// A factor and its levels.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FactorSpec {
    /// Its name (a column of the trial table).
    pub name: String,
    /// The scenario fields a level sets, as dotted paths (`method`, `network.delay_min_ms`,
    /// `site.0.report_rate_hz`, `site.*.report_rate_hz` for every site).
    pub set: Vec<String>,
    /// Its levels: values those fields take.
    pub levels: Vec<toml::Value>,
    /// Each group does one level (assigned in turn), not all of them.
    #[serde(default)]
    pub between: bool,
}

/// A study, checked and ready to plan or run.
#[derive(Debug, Clone)]
pub struct Study {
    /// The file as written.
    pub file: StudyFile,
    /// Where it was read from.
    pub path: PathBuf,
    /// Its text's hash (XXH3-64, hex): what the outputs name it by.
    pub hash: String,
    /// The scenario file, resolved.
    pub scenario_path: PathBuf,
    /// The scenario file's text, as a TOML table (the levels are set on it).
    scenario: toml::Table,
    /// The scenario's sites (their names, in order).
    pub sites: Vec<String>,
    /// The groups.
    pub groups: Vec<GroupSpec>,
}

/// One trial of a group's plan.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Trial {
    /// The group's index (0-based) and id.
    pub group: usize,
    /// See `group`.
    pub group_id: String,
    /// Its number within the group, from 1.
    pub trial: usize,
    /// The block (condition) it belongs to, from 1: the condition's position in the group's
    /// order.
    pub block: usize,
    /// A practice trial.
    pub practice: bool,
    /// The condition: each factor's level index, in the factors' order.
    pub levels: Vec<usize>,
    /// The run's seed.
    pub seed: u64,
}

/// A file's or a name's rule broken: one message naming the file, the field, the value and the
/// rule.
fn rule(path: &Path, field: &str, value: impl std::fmt::Debug, why: &str) -> anyhow::Error {
    anyhow::anyhow!("study file {}: {field} = {value:?}: {why}", path.display())
}

impl Study {
    /// Reads and checks a study file: its fields, its scenario, and every condition (each
    /// level set on the scenario, checked by the scenario's rules).
    ///
    /// # Errors
    /// The file cannot be read or breaks a rule; the message names the file, the field, the value
    /// and the rule.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading study file {}", path.display()))?;
        let file: StudyFile =
            toml::from_str(&text).with_context(|| format!("study file {}", path.display()))?;
        check_fields(path, &file)?;
        let base = path.parent().unwrap_or(Path::new("."));
        let scenario_path = base.join(&file.scenario);
        let scenario_text = std::fs::read_to_string(&scenario_path).with_context(|| {
            format!(
                "study file {}: scenario = {:?}: reading {}",
                path.display(),
                file.scenario,
                scenario_path.display()
            )
        })?;
        let scenario: toml::Table = toml::from_str(&scenario_text).with_context(|| {
            format!(
                "study file {}: scenario {}",
                path.display(),
                scenario_path.display()
            )
        })?;
        let sc = coop_actors::scenario_file::parse_at(&scenario_text, scenario_path.parent())
            .map_err(|e| anyhow::anyhow!("{e}"))
            .with_context(|| {
                format!(
                    "study file {}: scenario {}",
                    path.display(),
                    scenario_path.display()
                )
            })?;
        if sc.task.done.is_none() {
            return Err(rule(path, "scenario", &file.scenario, "the scenario needs a live [task] (its trials end at its goal, and are judged by it)"));
        }
        let sites: Vec<String> = sc.site.iter().map(|s| s.name.clone()).collect();
        let groups = groups_of(path, &file, &sites)?;
        let hash = format!("{:016x}", xxhash_rust::xxh3::xxh3_64(text.as_bytes()));
        let study = Self {
            file,
            path: path.to_owned(),
            hash,
            scenario_path,
            scenario,
            sites,
            groups,
        };
        // Every condition is a valid scenario before anything runs.
        for levels in study.all_level_combinations() {
            study.scenario_for(&levels, 1, 1)?;
        }
        Ok(study)
    }

    /// Every combination of every factor's levels (between ones too), in the factors' order.
    fn all_level_combinations(&self) -> Vec<Vec<usize>> {
        product(
            &self
                .file
                .factor
                .iter()
                .map(|f| f.levels.len())
                .collect::<Vec<_>>(),
        )
    }

    /// The within-group conditions: each a level index per factor (the between factors' set to
    /// 0, filled per group), the last factor's levels changing fastest.
    pub fn conditions(&self) -> Vec<Vec<usize>> {
        let sizes: Vec<usize> = self
            .file
            .factor
            .iter()
            .map(|f| if f.between { 1 } else { f.levels.len() })
            .collect();
        product(&sizes)
    }

    /// Group `g`'s levels of the between factors (each assigned in turn, the first factor's
    /// fastest): `None` for a within factor.
    pub fn between_levels(&self, g: usize) -> Vec<Option<usize>> {
        let mut rest = g;
        self.file
            .factor
            .iter()
            .map(|f| {
                f.between.then(|| {
                    let l = rest % f.levels.len();
                    rest /= f.levels.len();
                    l
                })
            })
            .collect()
    }

    /// How many between-group cells there are (1: no between factor).
    pub fn between_cells(&self) -> usize {
        self.file
            .factor
            .iter()
            .filter(|f| f.between)
            .map(|f| f.levels.len())
            .product::<usize>()
            .max(1)
    }

    /// Every group's trials, in the order each group does them.
    pub fn plan(&self) -> Vec<Trial> {
        let conditions = self.conditions();
        let mut out = Vec::new();
        for (g, group) in self.groups.iter().enumerate() {
            let order = match self.file.order {
                // The row from the group's place among the groups of its between-group cell
                // (the cells take the groups in turn): each cell's groups run through the rows.
                OrderKind::Williams => order::williams(conditions.len(), g / self.between_cells()),
                OrderKind::Random => {
                    order::shuffled(conditions.len(), mix(self.file.seed, &[1, g as u64]))
                }
                OrderKind::Fixed => (0..conditions.len()).collect(),
            };
            let between = self.between_levels(g);
            let mut trial = 0;
            for (b, &c) in order.iter().enumerate() {
                let levels: Vec<usize> = conditions[c]
                    .iter()
                    .zip(&between)
                    .map(|(&w, b)| b.unwrap_or(w))
                    .collect();
                let practice = self.file.practice as usize;
                for k in 0..practice + self.file.repetitions as usize {
                    trial += 1;
                    out.push(Trial {
                        group: g,
                        group_id: group.id.clone(),
                        trial,
                        block: b + 1,
                        practice: k < practice,
                        levels: levels.clone(),
                        seed: seed63(mix(self.file.seed, &[2, g as u64, trial as u64])),
                    });
                }
            }
        }
        out
    }

    /// The seed group `g`'s participants are drawn with.
    pub fn people_seed(&self, g: usize) -> u64 {
        seed63(mix(self.file.seed, &[3, g as u64]))
    }

    /// The scenario of a trial at `levels` (a level index per factor) with `seed` and the people
    /// of `people_seed`, checked.
    ///
    /// # Errors
    /// A level sets a field the scenario does not have, or makes it break a rule.
    pub fn scenario_for(
        &self,
        levels: &[usize],
        seed: u64,
        people_seed: u64,
    ) -> anyhow::Result<coop_model::scenario::Scenario> {
        Ok(self.scenario_text_for(levels, seed, people_seed)?.1)
    }

    /// [`Study::scenario_for`], with the scenario's TOML (what a study's stations are sent).
    ///
    /// # Errors
    /// As [`Study::scenario_for`].
    pub fn scenario_text_for(
        &self,
        levels: &[usize],
        seed: u64,
        people_seed: u64,
    ) -> anyhow::Result<(String, coop_model::scenario::Scenario)> {
        let mut doc = self.scenario.clone();
        let what = self.condition_name(levels);
        for (f, &l) in self.file.factor.iter().zip(levels) {
            for field in &f.set {
                set_path(&mut doc, field, f.levels[l].clone()).map_err(|why| {
                    anyhow::anyhow!(
                        "study file {}: factor {:?} sets {field:?}: {why}",
                        self.path.display(),
                        f.name
                    )
                })?;
            }
        }
        // (Seeds are below 2^63: a TOML integer holds them as they are.)
        let num = |v: u64| toml::Value::Integer(i64::try_from(seed63(v)).unwrap_or(0));
        doc.insert("seed".into(), num(seed));
        doc.insert("people_seed".into(), num(people_seed));
        if let Some(t) = self.file.timeout_s {
            doc.insert("duration_s".into(), toml::Value::Float(t));
        }
        let text = toml::to_string(&doc).context("writing the condition's scenario")?;
        let sc = coop_actors::scenario_file::parse_at(&text, self.scenario_path.parent())
            .map_err(|e| anyhow::anyhow!("{e}"))
            .with_context(|| {
                format!(
                    "study file {}: the condition {what} of scenario {}",
                    self.path.display(),
                    self.scenario_path.display()
                )
            })?;
        Ok((text, sc))
    }

    /// A condition as `factor=level, ...`.
    pub fn condition_name(&self, levels: &[usize]) -> String {
        self.file
            .factor
            .iter()
            .zip(levels)
            .map(|(f, &l)| format!("{}={}", f.name, level_text(&f.levels[l])))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// `study plan`: every group's trial order, one line per trial.
    pub fn plan_text(&self) -> String {
        use std::fmt::Write;
        let plan = self.plan();
        let mut out = String::new();
        let conditions = self.conditions().len();
        let _ = writeln!(
            out,
            "# study {} ({}): {} groups of {} ({}), {} conditions within groups, {} order, {} practice + {} measured trials per condition: {} trials",
            self.file.name,
            self.hash,
            self.groups.len(),
            self.sites.len(),
            self.sites.join(", "),
            conditions,
            match self.file.order {
                OrderKind::Williams => "Williams (balanced Latin square)",
                OrderKind::Random => "random",
                OrderKind::Fixed => "fixed",
            },
            self.file.practice,
            self.file.repetitions,
            plan.len()
        );
        let _ = writeln!(
            out,
            "{:<10}{:>6}{:>6}  {:<9} condition",
            "group", "trial", "block", "kind"
        );
        for t in &plan {
            let _ = writeln!(
                out,
                "{:<10}{:>6}{:>6}  {:<9} {}",
                t.group_id,
                t.trial,
                t.block,
                if t.practice { "practice" } else { "measured" },
                self.condition_name(&t.levels)
            );
        }
        out
    }
}

/// The study file's own rules (its name, repetitions, timeout, factors and levels).
fn check_fields(path: &Path, file: &StudyFile) -> anyhow::Result<()> {
    let name_ok = !file.name.is_empty()
        && file
            .name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "._-".contains(c));
    if !name_ok {
        return Err(rule(
            path,
            "name",
            &file.name,
            "use 1 or more of A-Z a-z 0-9 . _ -",
        ));
    }
    if file.repetitions == 0 {
        return Err(rule(
            path,
            "repetitions",
            file.repetitions,
            "at least 1 measured trial per condition",
        ));
    }
    if let Some(t) = file.timeout_s {
        if !(t.is_finite() && t > 0.0) {
            return Err(rule(path, "timeout_s", t, "a number of seconds above 0"));
        }
    }
    if let Some(q) = &file.questionnaire {
        q.check()
            .map_err(|why| anyhow::anyhow!("study file {}: {why}", path.display()))?;
    }
    if file.factor.is_empty() {
        return Err(rule(path, "factor", "[]", "at least one [[factor]]"));
    }
    let mut names = BTreeSet::new();
    for (k, f) in file.factor.iter().enumerate() {
        let field = |what: &str| format!("factor[{k}].{what}");
        let ok = !f.name.is_empty()
            && f.name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !ok {
            return Err(rule(
                path,
                &field("name"),
                &f.name,
                "use 1 or more of A-Z a-z 0-9 _",
            ));
        }
        if !names.insert(f.name.clone()) || COLUMNS.contains(&f.name.as_str()) {
            return Err(rule(
                path,
                &field("name"),
                &f.name,
                "a factor's name must be unique and not a column of the trial table",
            ));
        }
        if f.set.is_empty() {
            return Err(rule(
                path,
                &field("set"),
                "[]",
                "name at least one scenario field",
            ));
        }
        if f.levels.is_empty() {
            return Err(rule(path, &field("levels"), "[]", "at least one level"));
        }
        let mut seen = BTreeSet::new();
        for l in &f.levels {
            if !matches!(
                l,
                toml::Value::String(_)
                    | toml::Value::Integer(_)
                    | toml::Value::Float(_)
                    | toml::Value::Boolean(_)
            ) {
                return Err(rule(
                    path,
                    &field("levels"),
                    l,
                    "a level is a string, a number or a boolean",
                ));
            }
            if level_text(l).contains(['\n', '\r']) {
                return Err(rule(
                    path,
                    &field("levels"),
                    l,
                    "a level is one line (it is a cell of the tables)",
                ));
            }
            if !seen.insert(level_text(l)) {
                return Err(rule(path, &field("levels"), l, "levels must differ"));
            }
        }
    }
    Ok(())
}

/// The groups a study file gives (`groups = N` or `[[group]]`), checked against the scenario's
/// sites.
fn groups_of(path: &Path, file: &StudyFile, sites: &[String]) -> anyhow::Result<Vec<GroupSpec>> {
    let groups = match (file.groups, file.group.is_empty()) {
        (Some(_), false) => {
            return Err(rule(
                path,
                "groups",
                file.groups,
                "give a number of groups or [[group]] tables, not both",
            ))
        }
        (None, true) => {
            return Err(rule(
                path,
                "groups",
                "none",
                "give a number of groups or [[group]] tables",
            ))
        }
        (Some(0), true) => return Err(rule(path, "groups", 0, "at least one group")),
        (Some(n), true) => (1..=n)
            .map(|g| GroupSpec {
                id: format!("g{g:02}"),
                participants: sites.iter().map(|s| format!("g{g:02}-{s}")).collect(),
            })
            .collect(),
        (None, false) => file.group.clone(),
    };
    let mut ids = BTreeSet::new();
    let mut people = BTreeSet::new();
    for (k, g) in groups.iter().enumerate() {
        if g.id.is_empty()
            || !g
                .id
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "._-".contains(c))
        {
            return Err(rule(
                path,
                &format!("group[{k}].id"),
                &g.id,
                "use 1 or more of A-Z a-z 0-9 . _ -",
            ));
        }
        if !ids.insert(g.id.clone()) {
            return Err(rule(
                path,
                &format!("group[{k}].id"),
                &g.id,
                "group ids must differ",
            ));
        }
        if g.participants.len() != sites.len() {
            return Err(rule(
                path,
                &format!("group[{k}].participants"),
                &g.participants,
                &format!(
                    "one participant per site of the scenario ({}: {})",
                    sites.len(),
                    sites.join(", ")
                ),
            ));
        }
        for p in &g.participants {
            let ok = !p.is_empty()
                && p.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "._-".contains(c));
            if !ok || !people.insert(p.clone()) {
                return Err(rule(path, &format!("group[{k}].participants"), p, "participant ids use 1 or more of A-Z a-z 0-9 . _ - and are unique (a participant is in one group)"));
            }
        }
    }
    Ok(groups)
}

/// The trial table's own columns (a factor may not take one's name).
pub const COLUMNS: [&str; 25] = [
    "study",
    "group",
    "participant",
    "site",
    "block",
    "trial",
    "practice",
    "order_position",
    "seed",
    "outcome",
    "failed_by",
    "site_done",
    "trial_done",
    "site_time_s",
    "completion_s",
    "grip_mean_n",
    "grip_peak_n",
    "grip_margin",
    "slips",
    "co_divergence_max_mm",
    "phantom_ms",
    "unfelt_ms",
    "sent_bytes",
    "cut",
    "attempt",
];

/// `conditions` (each a level per factor, as the tables write them) sorted as `study` lists the
/// levels, without repeats.
pub fn in_level_order(study: &StudyFile, mut conditions: Vec<Vec<String>>) -> Vec<Vec<String>> {
    let rank = |f: usize, l: &str| {
        study.factor.get(f).map_or(usize::MAX, |factor| {
            factor
                .levels
                .iter()
                .position(|v| level_text(v) == l)
                .unwrap_or(usize::MAX)
        })
    };
    // (A level the file does not list sorts last, by its text: equal conditions end up side
    // by side whatever they hold.)
    conditions.sort_by_key(|c| {
        c.iter()
            .enumerate()
            .map(|(f, l)| (rank(f, l), l.clone()))
            .collect::<Vec<_>>()
    });
    conditions.dedup();
    conditions
}

/// A level as the trial table writes it.
pub fn level_text(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// Every combination of indices below `sizes`, the last changing fastest.
fn product(sizes: &[usize]) -> Vec<Vec<usize>> {
    let mut out = vec![Vec::new()];
    for &n in sizes {
        out = out
            .into_iter()
            .flat_map(|prefix| {
                (0..n).map(move |l| {
                    let mut p = prefix.clone();
                    p.push(l);
                    p
                })
            })
            .collect();
    }
    out
}

/// A seed from `seed` and a path of numbers (SplitMix64's finalizer over each): independent
/// streams for orders, people and trials.
pub fn mix(seed: u64, path: &[u64]) -> u64 {
    let step = |mut z: u64| {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    path.iter().fold(step(seed), |acc, &p| step(acc ^ step(p)))
}

/// `v` below 2^63 (a scenario's seed is a TOML integer, which is signed).
pub fn seed63(v: u64) -> u64 {
    v & (u64::MAX >> 1)
}

/// Sets the dotted `path` of `doc` to `value`: tables are made where missing; a number is an
/// array's index, `*` every element of it.
fn set_path(doc: &mut toml::Table, path: &str, value: toml::Value) -> Result<(), String> {
    let parts: Vec<&str> = path.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err("a field's path is names (and array indices) joined by dots".into());
    }
    fn go(at: &mut toml::Value, parts: &[&str], value: &toml::Value) -> Result<(), String> {
        let Some((head, rest)) = parts.split_first() else {
            *at = value.clone();
            return Ok(());
        };
        match at {
            toml::Value::Table(t) => {
                let next = t
                    .entry((*head).to_owned())
                    .or_insert_with(|| toml::Value::Table(toml::Table::new()));
                go(next, rest, value)
            }
            toml::Value::Array(a) => {
                if *head == "*" {
                    return a.iter_mut().try_for_each(|e| go(e, rest, value));
                }
                let i: usize = head
                    .parse()
                    .map_err(|_| format!("{head:?} indexes an array: use a number or *"))?;
                let len = a.len();
                let e = a
                    .get_mut(i)
                    .ok_or_else(|| format!("index {i} is past the array's {len} elements"))?;
                go(e, rest, value)
            }
            _ => Err(format!(
                "{head:?} is inside a value, not a table or an array"
            )),
        }
    }
    let mut root = toml::Value::Table(std::mem::take(doc));
    let r = go(&mut root, &parts, &value);
    if let toml::Value::Table(t) = root {
        *doc = t;
    }
    r
}

/// Checks that a directory holds a study's run: its trial table.
///
/// # Errors
/// No trial table in `dir`.
pub fn trials_file(dir: &Path) -> anyhow::Result<PathBuf> {
    let p = dir.join("trials.csv");
    if !p.is_file() {
        bail!(
            "{}: no trials.csv here: is it the --out directory of a `study run`?",
            dir.display()
        );
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_set_tables_array_elements_and_every_element() {
        let mut doc: toml::Table =
            toml::from_str("a = 1\n[[site]]\nx = 1\n[[site]]\nx = 2\n").unwrap();
        set_path(&mut doc, "net.delay", toml::Value::Integer(5)).unwrap();
        set_path(&mut doc, "site.1.x", toml::Value::Integer(7)).unwrap();
        assert_eq!(doc["net"]["delay"].as_integer(), Some(5));
        assert_eq!(doc["site"][1]["x"].as_integer(), Some(7));
        set_path(&mut doc, "site.*.x", toml::Value::Integer(9)).unwrap();
        assert_eq!(doc["site"][0]["x"].as_integer(), Some(9));
        assert!(set_path(&mut doc, "site.2.x", toml::Value::Integer(0))
            .unwrap_err()
            .contains("past the array's 2"));
        assert!(set_path(&mut doc, "a.b", toml::Value::Integer(0))
            .unwrap_err()
            .contains("inside a value"));
        assert!(set_path(&mut doc, "site.one.x", toml::Value::Integer(0)).is_err());
        assert!(set_path(&mut doc, "a..b", toml::Value::Integer(0)).is_err());
    }

    #[test]
    fn products_and_seeds() {
        assert_eq!(
            product(&[2, 3]),
            vec![
                vec![0, 0],
                vec![0, 1],
                vec![0, 2],
                vec![1, 0],
                vec![1, 1],
                vec![1, 2]
            ]
        );
        assert_eq!(mix(1, &[2, 3]), mix(1, &[2, 3]));
        assert_ne!(mix(1, &[2, 3]), mix(1, &[3, 2]));
        assert_ne!(mix(1, &[2]), mix(2, &[2]));
    }
}
