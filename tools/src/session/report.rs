//! `session run`'s report for people: the metrics table of `sim compare`, then per method the
//! objects' figures, each station's traffic, (attached) the session's time 0 in every clock, and
//! each station's loops and rollback figures.

use coop_model::scenario::Scenario;
use coop_rt::shm::rollback::RollbackFigures;

use super::outcome::{ObjectFigures, SessionOverruns, SessionRun, StationRow, OVERLOAD_SHARE};

/// Prints the report of `run` of `sc` (`attached`: the stations were not started here, so their
/// clocks differ from the launcher's).
pub fn print(sc: &Scenario, run: &SessionRun, attached: bool) {
    crate::sim::print_table(sc, &run.rows());
    print_objects(run);
    print_wire(run);
    if attached {
        print_epochs(run);
    }
    print_station_loops(run);
    print_overloads(run);
    println!(
        "# *-sim: the simulator; *-real: the stations (adopt step, E others, others did: simulator only)\n# recordings, logs, metrics.json and plots in {}/<method>/",
        run.out
    );
}

/// Per method, a line for each station that overran more than `OVERLOAD_SHARE` (1 %) of its physics
/// ticks: its `-real` row measures an overloaded machine, not only the method.
fn print_overloads(run: &SessionRun) {
    for (m, r) in &run.methods {
        for (site, st) in &r.stations {
            let Some(o) = st.figures.and_then(|r| r.overruns) else {
                continue;
            };
            if o.overloaded {
                println!(
                    "# OVERLOADED: {m}-real at {site}: physics overran {} of {} ticks ({:.1} %, more than {:.0} %); its figures say more about the machine than about the method",
                    o.physics,
                    o.physics_ticks,
                    100.0 * o.physics_share(),
                    100.0 * OVERLOAD_SHARE
                );
            }
        }
    }
}

/// Per method and object, the simulator's figures and the stations'.
fn print_objects(run: &SessionRun) {
    for (m, r) in &run.methods {
        for o in &r.objects {
            let f = |x: &ObjectFigures| {
                format!(
                    "div max {:.2} rms {:.2} final {:.2}, err ref max {:.2}",
                    x.div_max_mm, x.div_rms_mm, x.div_final_mm, x.err_ref_max_mm
                )
            };
            println!(
                "# object {:<10} {m}-sim: {} | {m}-real: {} (mm)",
                o.name,
                f(&o.simulated),
                f(&o.real)
            );
        }
    }
}

/// Per method, each station's traffic.
fn print_wire(run: &SessionRun) {
    for (m, r) in &run.methods {
        for w in &r.wire {
            let kinds: Vec<String> = w
                .kinds
                .iter()
                .filter(|k| k.1 > 0.0 || k.3 > 0.0)
                .map(|(kind, msgs, sent, got)| format!("{kind} {msgs:.0} msg/s {sent:.1}/{got:.1}"))
                .collect();
            println!(
                "# wire: {m:<9} {:<6} sent {:.1} kbit/s, received {:.1} kbit/s over {:.1} s ({})",
                w.site,
                w.sent_kbit_s,
                w.received_kbit_s,
                w.duration_s,
                kinds.join("; ")
            );
        }
    }
}

/// Per method, the session's time 0 in the launcher's clock and in each station's.
fn print_epochs(run: &SessionRun) {
    for (m, r) in &run.methods {
        let theirs: Vec<String> = r
            .stations
            .iter()
            .map(|(site, s)| format!("{site} {}", s.epoch_ns))
            .collect();
        println!(
            "# {m}: time 0 in the launcher's clock: {} ns; in the stations' clocks: {} ns",
            r.launcher_epoch_ns,
            theirs.join(", ")
        );
    }
}

/// A column of the `# stations:` rows: its heading, its width, and its figure from a station's
/// row (`-`: neither read nor answered, or a method that does not roll back).
type Column = (&'static str, usize, fn(Option<&StationRow>) -> String);

/// The `# stations:` rows' columns after the method and the site: physics overruns during the
/// session and compute p99 (methods side by side, so timewarp's cost shows beside paper's), and a
/// rolling-back method's rollbacks, depth, fallbacks, hash checks and mismatches, confirmed states
/// adopted, contact unfelt and phantom, missed contacts replayed, and ticks the own tool was
/// lagged. The one list of them: heading and figure side by side.
const STATION_COLUMNS: [Column; 12] = [
    ("physics overruns", 16, |l| {
        dash(l.and_then(|l| l.overruns).map(|o| o.physics))
    }),
    ("load", 10, |l| {
        l.and_then(|l| l.overruns)
            .map_or_else(|| "-".to_owned(), |o| load(&o))
    }),
    ("compute p99 us", 14, |l| {
        dash(l.map(|l| l.physics_compute_p99_us))
    }),
    ("rollbacks", 9, |l| dash(rollback(l).map(|r| r.rollbacks))),
    ("depth max/p99 ticks", 19, |l| {
        pair(rollback(l).map(|r| (r.max_depth, r.depth_p99)))
    }),
    ("fallbacks", 9, |l| dash(rollback(l).map(|r| r.fallbacks))),
    ("hash checks", 11, |l| {
        dash(rollback(l).map(|r| r.hash_checks))
    }),
    ("mismatches", 10, |l| {
        dash(rollback(l).map(|r| r.hash_mismatches))
    }),
    ("adopted", 7, |l| {
        dash(rollback(l).map(|r| r.adopted_states))
    }),
    ("unfelt/phantom ticks", 20, |l| {
        pair(rollback(l).map(|r| (r.unfelt_contact_ticks, r.phantom_contact_ticks)))
    }),
    ("replayed", 8, |l| dash(rollback(l).map(|r| r.replays))),
    ("lagged ticks", 12, |l| {
        dash(rollback(l).map(|r| r.lagged_ticks))
    }),
];

/// `overloaded` when more than `OVERLOAD_SHARE` (1 %) of the physics ticks overran, else `ok`.
fn load(o: &SessionOverruns) -> String {
    if o.overloaded {
        "OVERLOADED".to_owned()
    } else {
        "ok".to_owned()
    }
}

fn rollback(l: Option<&StationRow>) -> Option<RollbackFigures> {
    l.and_then(|l| l.rollback)
}

fn dash(x: Option<u64>) -> String {
    x.map_or_else(|| "-".to_owned(), |x| x.to_string())
}

/// Two figures as "a/b".
fn pair(x: Option<(u64, u64)>) -> String {
    x.map_or_else(|| "-".to_owned(), |(a, b)| format!("{a}/{b}"))
}

/// One `# stations:` line: the method and site, then the columns, right-aligned.
fn station_line(method: &str, site: &str, cells: impl Iterator<Item = (usize, String)>) -> String {
    let cells: Vec<String> = cells.map(|(w, c)| format!("{c:>w$}")).collect();
    format!("# stations: {method:<9} {site:<6} {}", cells.join("  "))
}

/// Per method and station, from the statuses read just before the end: [`STATION_COLUMNS`].
fn print_station_loops(run: &SessionRun) {
    let headings = STATION_COLUMNS
        .iter()
        .map(|(h, w, _)| (*w, (*h).to_owned()));
    println!("{}", station_line("method", "site", headings));
    for (m, r) in &run.methods {
        for (site, st) in &r.stations {
            let row = st.figures.as_ref();
            let cells = STATION_COLUMNS.iter().map(|(_, w, f)| (*w, f(row)));
            println!("{}", station_line(m, site, cells));
        }
    }
}
