//! The reference pages are what the code generates (so a field added without regenerating them
//! fails here), a stale page is named, and the template a user starts from is a valid scenario
//! holding every table the reference lists; `sim template` and `sim check` as a user runs them.

use std::process::Command;

use coop_tests::{repo, TempDir};
use coop_tools::reference;

const SIM: &str = env!("CARGO_BIN_EXE_sim");

#[test]
fn the_committed_reference_pages_are_what_the_code_generates() {
    if let Err(e) = reference::write(&repo(), true) {
        panic!("{e:#}");
    }
}

#[test]
fn a_page_edited_or_missing_is_named_stale() {
    let root = TempDir::new("reference");
    reference::write(root.path(), false).expect("write the pages");
    reference::write(root.path(), true).expect("just written: not stale");
    let dir = root.path().join(reference::DIR);
    let station = dir.join("station.md");
    let text = std::fs::read_to_string(&station).expect("station.md");
    std::fs::write(&station, text.replace("| `mlockall` |", "| `mlock_all` |")).expect("edit");
    std::fs::remove_file(dir.join("router.md")).expect("remove");
    let e = format!(
        "{:#}",
        reference::write(root.path(), true).expect_err("stale pages passed")
    );
    assert!(e.contains("station.md") && e.contains("router.md"), "{e}");
    assert!(!e.contains("scenario.md"), "an unchanged page named: {e}");
}

/// Every table of the scenario reference (`## \`[site.hand]\``, `## \`[[phase]]\``) is in the
/// template, in some entry of each array on its way.
#[test]
fn the_template_is_valid_and_holds_every_table_of_the_reference() {
    coop_actors::scenario_file::parse(reference::TEMPLATE).expect("the template is valid");
    let doc: toml::Table = toml::from_str(reference::TEMPLATE).expect("toml");
    let page = reference::pages()
        .expect("pages")
        .into_iter()
        .find(|p| p.file == "scenario.md")
        .expect("scenario.md");
    let tables: Vec<String> = page
        .text
        .lines()
        .filter_map(|l| l.strip_prefix("## `"))
        .map(|h| h.trim_end_matches('`').trim_matches(['[', ']']).to_owned())
        .collect();
    assert!(tables.len() >= 15, "the page lists its tables: {tables:?}");
    for t in &tables {
        let keys: Vec<&str> = t.split('.').collect();
        assert!(
            holds(&toml::Value::Table(doc.clone()), &keys),
            "the template lacks [{t}]"
        );
    }
}

fn holds(v: &toml::Value, keys: &[&str]) -> bool {
    match (v, keys) {
        (_, []) => true,
        (toml::Value::Array(a), _) => a.iter().any(|e| holds(e, keys)),
        (toml::Value::Table(t), [k, rest @ ..]) => t.get(*k).is_some_and(|x| holds(x, rest)),
        _ => false,
    }
}

#[test]
fn sim_template_prints_a_scenario_sim_check_accepts_and_check_names_what_it_refuses() {
    let dir = TempDir::new("sim-template");
    let o = Command::new(SIM)
        .arg("template")
        .output()
        .expect("sim template");
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).expect("utf-8");
    assert_eq!(text, reference::TEMPLATE);
    let good = dir.join("mine.toml");
    std::fs::write(&good, &text).expect("write");
    let o = Command::new(SIM)
        .arg("check")
        .arg(&good)
        .output()
        .expect("sim check");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        out.contains("valid") && out.contains("user1: a participant"),
        "{out}"
    );

    let bad = dir.join("bad.toml");
    std::fs::write(&bad, text.replace("mass_kg = 0.1", "mass_kg = -1.0")).expect("write");
    let before: Vec<_> = std::fs::read_dir(dir.path()).expect("dir").collect();
    let o = Command::new(SIM)
        .arg("check")
        .arg(&bad)
        .output()
        .expect("sim check");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "a negative mass passed");
    assert!(
        err.contains("bad.toml") && err.contains("mass_kg = -1"),
        "{err}"
    );
    let after: Vec<_> = std::fs::read_dir(dir.path()).expect("dir").collect();
    assert_eq!(before.len(), after.len(), "sim check wrote something");
}

/// Every shipped scenario (a user's starting points, `scenarios/` and `scenarios/participants/`)
/// is valid as `sim check` reads it, so none rots unnoticed.
#[test]
fn every_shipped_scenario_is_valid() {
    let mut checked = 0;
    for dir in ["scenarios", "scenarios/participants"] {
        for e in std::fs::read_dir(repo().join(dir)).expect("scenarios") {
            let path = e.expect("entry").path();
            if path.extension().is_some_and(|x| x == "toml") {
                if let Err(err) = coop_actors::scenario_file::load(&path) {
                    panic!("{}: {:#}", path.display(), anyhow::Error::from(err));
                }
                checked += 1;
            }
        }
    }
    assert!(checked >= 18, "the shipped scenarios were found: {checked}");
}
