//! Plots laid out like the paper's Figs. 9–12, as PNG and SVG: per direction (x, y), four panels —
//! (a) the sum of the users' forces acting on the object (in a world of several, on the objects)
//! at each site, (b) the first object's position as each site believes it, with the reference run
//! dashed, (c) the desired and (d) the measured contact force of each user — plus the inter-site
//! divergence over time. Every panel names its object by the scenario's name for it.

use std::path::Path;

use anyhow::{anyhow, Context};
use coop_model::body::Vec3;
use coop_model::scenario::Scenario;
use coop_model::sim::RunResult;
use plotters::coord::Shift;
use plotters::prelude::*;

/// The TrueType font the plots use (Debian package `fonts-dejavu-core`).
pub const FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// Registers [`FONT`] as the plots' `sans-serif`, once per process (every plot of the tools).
pub(crate) fn ensure_font() -> anyhow::Result<()> {
    static DONE: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    DONE.get_or_init(|| {
        let bytes = std::fs::read(FONT)
            .map_err(|e| format!("reading {FONT} ({e}): install the fonts-dejavu-core package"))?;
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| format!("{FONT} is not a usable font"))
    })
    .clone()
    .map_err(|e| anyhow!(e))
}

struct Series {
    label: String,
    color: RGBColor,
    dashed: bool,
    /// A dot at every point (for sparse series, where a lone point draws no line).
    markers: bool,
    points: Vec<(f64, f64)>,
    /// Error bars: (x, low, high).
    bars: Vec<(f64, f64, f64)>,
}

/// The horizontal axis: its range and label.
struct XAxis<'a> {
    from: f64,
    to: f64,
    label: &'a str,
}

struct Panel {
    title: String,
    y_label: &'static str,
    series: Vec<Series>,
}

const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    title: &str,
    panels: &[Panel],
    x: &XAxis<'_>,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing: {e:?}");
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(err)?;
    let areas = root.split_evenly((panels.len(), 1));
    for (area, p) in areas.iter().zip(panels) {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for s in &p.series {
            for &(_, y) in &s.points {
                lo = lo.min(y);
                hi = hi.max(y);
            }
            for &(_, l, h) in s.bars.iter().filter(|b| b.1.is_finite() && b.2.is_finite()) {
                lo = lo.min(l);
                hi = hi.max(h);
            }
        }
        if !lo.is_finite() {
            (lo, hi) = (-1.0, 1.0);
        }
        let pad = ((hi - lo) * 0.08).max(1e-6);
        let mut chart = ChartBuilder::on(area)
            .caption(&p.title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(28)
            .y_label_area_size(64)
            .build_cartesian_2d(x.from..x.to, (lo - pad)..(hi + pad))
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(x.label)
            .y_desc(p.y_label)
            .label_style(("sans-serif", 12))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(err)?;
        for s in &p.series {
            let style = ShapeStyle::from(&s.color).stroke_width(if s.dashed { 1 } else { 2 });
            if s.markers {
                let c = s.color;
                chart
                    .draw_series(
                        s.points
                            .iter()
                            .map(|&p| Circle::new(p, 4, ShapeStyle::from(&c).filled())),
                    )
                    .map_err(err)?;
            }
            let bar_style = ShapeStyle::from(&s.color).stroke_width(1);
            chart
                .draw_series(
                    s.bars
                        .iter()
                        // One value has no interval.
                        .filter(|b| b.1.is_finite() && b.2.is_finite())
                        .map(|&(x, l, h)| PathElement::new(vec![(x, l), (x, h)], bar_style)),
                )
                .map_err(err)?;
            let drawn = if s.dashed {
                chart
                    .draw_series(DashedLineSeries::new(s.points.iter().copied(), 6, 4, style))
                    .map_err(err)?
            } else {
                chart
                    .draw_series(LineSeries::new(s.points.iter().copied(), style))
                    .map_err(err)?
            };
            let c = s.color;
            drawn.label(&s.label).legend(move |(x, y)| {
                PathElement::new(
                    vec![(x, y), (x + 18, y)],
                    ShapeStyle::from(&c).stroke_width(2),
                )
            });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .label_font(("sans-serif", 12))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(())
}

fn write_both(
    dir: &Path,
    stem: &str,
    title: &str,
    panels: &[Panel],
    x: &XAxis<'_>,
    size: (u32, u32),
) -> anyhow::Result<()> {
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    draw(
        BitMapBackend::new(&png, size).into_drawing_area(),
        title,
        panels,
        x,
    )
    .with_context(|| format!("plotting {}", png.display()))?;
    draw(
        SVGBackend::new(&svg, size).into_drawing_area(),
        title,
        panels,
        x,
    )
    .with_context(|| format!("plotting {}", svg.display()))?;
    Ok(())
}

/// Writes `fig_x`, `fig_y` (the first object) and `divergence` (every object), and in a world of
/// several objects `objects_x`, `objects_y` and `objects_z` (a panel per object), PNG and SVG,
/// for a run into `dir`.
///
/// # Errors
/// The font is missing, or a file cannot be written.
pub fn figures(
    dir: &Path,
    sc: &Scenario,
    r: &RunResult,
    reference: &RunResult,
) -> anyhow::Result<()> {
    ensure_font()?;
    let time_axis = &XAxis {
        from: 0.0,
        to: sc.duration_s,
        label: "time (s)",
    };
    let name = |i: usize| sc.site[i].name.clone();
    let series = |f: &dyn Fn(usize, usize) -> f64, dashed_ref: Option<&dyn Fn(usize) -> f64>| {
        let mut out: Vec<Series> = (0..r.sites.len())
            .map(|i| Series {
                label: name(i),
                color: COLORS[i % COLORS.len()],
                dashed: false,
                markers: false,
                points: r.t.iter().enumerate().map(|(k, &t)| (t, f(i, k))).collect(),
                bars: Vec::new(),
            })
            .collect();
        if let Some(g) = dashed_ref {
            out.push(Series {
                label: "reference".into(),
                color: BLACK,
                dashed: true,
                markers: false,
                points: reference
                    .t
                    .iter()
                    .enumerate()
                    .map(|(k, &t)| (t, g(k)))
                    .collect(),
                bars: Vec::new(),
            });
        }
        out
    };
    let method = r.mode.name();
    let objects = r.sites.first().map_or(1, |s| s.objects());
    // Each panel names the object it shows: a world of several has no single "the object".
    let first = sc.object_name(0);
    let forces_on = if objects > 1 {
        "the objects".to_owned()
    } else {
        format!("the {first}")
    };
    for (axis, stem, label) in [(0usize, "fig_x", "x"), (1, "fig_y", "y")] {
        let c = |v: Vec3| v[axis];
        let panels = [
            Panel {
                title: format!("(a) sum of users' {label}-forces on {forces_on}, per site"),
                y_label: "N",
                series: series(&|i, k| c(r.sites[i].f_on_object[k]), None),
            },
            Panel {
                title: format!("(b) {first} {label} position as each site believes it"),
                y_label: "m",
                series: series(
                    &|i, k| c(r.sites[i].obj_pos[k]),
                    Some(&|k| c(reference.sites[0].obj_pos[k])),
                ),
            },
            Panel {
                title: format!("(c) desired {label}-force at each user's hand"),
                y_label: "N",
                series: series(&|i, k| c(r.sites[i].f_desired[k]), None),
            },
            Panel {
                title: format!("(d) measured {label}-force at each user's hand"),
                y_label: "N",
                series: series(&|i, k| c(r.sites[i].f_measured[k]), None),
            },
        ];
        let title = format!(
            "scenario {}, method {method}: {}-direction (cf. paper Figs. 9-12)",
            sc.name, label
        );
        write_both(dir, stem, &title, &panels, time_axis, (1000, 1300))?;
    }
    // A world of several objects: every object's position as each site believes it, one panel
    // per object, per axis.
    if objects > 1 {
        for (axis, stem, label) in [
            (0usize, "objects_x", "x"),
            (1, "objects_y", "y"),
            (2, "objects_z", "z"),
        ] {
            let panels: Vec<Panel> = (0..objects)
                .map(|o| Panel {
                    title: format!(
                        "{} {label} position as each site believes it",
                        sc.object_name(o)
                    ),
                    y_label: "m",
                    series: series(
                        &|i, k| r.sites[i].object_pos(o)[k][axis],
                        Some(&|k| reference.sites[0].object_pos(o)[k][axis]),
                    ),
                })
                .collect();
            let title = format!(
                "scenario {}, method {method}: every object, {label}",
                sc.name
            );
            let height = (260 * objects as u32).clamp(400, 4200);
            write_both(dir, stem, &title, &panels, time_axis, (1000, height))?;
        }
    }
    let div: Vec<(f64, f64)> =
        r.t.iter()
            .enumerate()
            .map(|(k, &t)| (t, coop_model::metrics::divergence(r, k) * 1e3))
            .collect();
    let panels = [Panel {
        title: if objects > 1 {
            "largest distance between any two sites' copies of any object".into()
        } else {
            format!("largest distance between any two sites' copies of the {first}")
        },
        y_label: "mm",
        series: vec![Series {
            label: method.into(),
            color: COLORS[1],
            dashed: false,
            markers: false,
            points: div,
            bars: Vec::new(),
        }],
    }];
    write_both(
        dir,
        "divergence",
        &format!(
            "scenario {}, method {method}: inter-site divergence",
            sc.name
        ),
        &panels,
        time_axis,
        (1000, 400),
    )
}

/// One method's line in the sweep plot: (delay ms, mean phases passed) and (delay ms, mean
/// co-contact divergence mm; delays where no user pair ever touched together are left out).
#[derive(Debug, Clone, PartialEq)]
pub struct SweepLine {
    /// Method name.
    pub label: String,
    /// (delay ms, phases passed).
    pub phases: Vec<(f64, f64)>,
    /// (delay ms, co-contact divergence max, mm).
    pub co_div_mm: Vec<(f64, f64)>,
}

/// Writes `sweep.png` and `sweep.svg` into `dir`: phases passed (of `phases_total`) and co-contact
/// divergence against delay, one line per method.
///
/// # Errors
/// The font is missing, or a file cannot be written.
pub fn sweep(
    dir: &Path,
    title: &str,
    phases_total: usize,
    lines: &[SweepLine],
) -> anyhow::Result<()> {
    ensure_font()?;
    let delays = lines
        .iter()
        .flat_map(|l| l.phases.iter().chain(&l.co_div_mm).map(|p| p.0));
    let (lo, hi) = delays.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
        (a.min(d), b.max(d))
    });
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    let x = XAxis {
        from: lo,
        to: if hi > lo { hi } else { lo + 1.0 },
        label: "one-way delay (ms)",
    };
    let series = |f: &dyn Fn(&SweepLine) -> Vec<(f64, f64)>| -> Vec<Series> {
        lines
            .iter()
            .enumerate()
            .map(|(i, l)| Series {
                label: l.label.clone(),
                color: COLORS[i % COLORS.len()],
                dashed: false,
                markers: true,
                points: f(l),
                bars: Vec::new(),
            })
            .collect()
    };
    let panels = [
        Panel {
            title: format!("task phases passed, of {phases_total} (all sites)"),
            y_label: "phases",
            series: series(&|l| l.phases.clone()),
        },
        Panel {
            title: "largest distance between the copies while two or more users touch".into(),
            y_label: "mm",
            series: series(&|l| l.co_div_mm.clone()),
        },
    ];
    write_both(dir, "sweep", title, &panels, &x, (1000, 800))
}

/// A point with its 95 % interval: (x, value, low, high).
pub type WithInterval = (f64, f64, f64, f64);

/// One method's lines in the task plot: (delay ms, value, 95 % low, 95 % high).
#[derive(Debug, Clone, PartialEq)]
pub struct TaskLine {
    /// Method name.
    pub label: String,
    /// Share of trials done at every site, %.
    pub success_pct: Vec<WithInterval>,
    /// Mean completion time of the trials done, s.
    pub completion_s: Vec<WithInterval>,
}

/// Writes `task.png` and `task.svg` into `dir`: the share of trials done and the mean completion
/// time against delay, one line per method, with their 95 % intervals as bars.
///
/// # Errors
/// The font is missing, or a file cannot be written.
pub fn task(dir: &Path, title: &str, lines: &[TaskLine]) -> anyhow::Result<()> {
    task_against(dir, title, "one-way delay (ms)", lines)
}

/// [`task`] against `x_label` (the lines' first coordinate), not the delay.
///
/// # Errors
/// As [`task`].
pub fn task_against(
    dir: &Path,
    title: &str,
    x_label: &str,
    lines: &[TaskLine],
) -> anyhow::Result<()> {
    let panel =
        |title: &str, y_label: &'static str, f: &dyn Fn(&TaskLine) -> &Vec<WithInterval>| {
            LinePanel {
                title: title.into(),
                y_label,
                lines: lines
                    .iter()
                    .map(|l| (l.label.clone(), f(l).clone()))
                    .collect(),
            }
        };
    let panels = [
        panel(
            "trials done at every site (95 % Wilson interval)",
            "%",
            &|l| &l.success_pct,
        ),
        panel(
            "mean completion time of the trials done (95 % interval)",
            "s",
            &|l| &l.completion_s,
        ),
    ];
    intervals_against(dir, "task", title, x_label, &panels)
}

/// A panel of lines with intervals: its title, its y label, and per line its label and points
/// `(x, value, low, high)`.
#[derive(Debug, Clone, PartialEq)]
pub struct LinePanel {
    /// The panel's title.
    pub title: String,
    /// Its vertical axis's label.
    pub y_label: &'static str,
    /// Its lines.
    pub lines: Vec<(String, Vec<WithInterval>)>,
}

/// Writes `<stem>.png` and `<stem>.svg` into `dir`: `panels` one above the other against
/// `x_label`, each line's intervals as bars, the lines side by side at each x.
///
/// # Errors
/// The font is missing, or a file cannot be written.
pub fn intervals_against(
    dir: &Path,
    stem: &str,
    title: &str,
    x_label: &str,
    panels: &[LinePanel],
) -> anyhow::Result<()> {
    ensure_font()?;
    let xs = panels
        .iter()
        .flat_map(|p| p.lines.iter().flat_map(|l| l.1.iter().map(|p| p.0)));
    let (lo, hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
        (a.min(d), b.max(d))
    });
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    let most = panels.iter().map(|p| p.lines.len()).max().unwrap_or(1);
    // Lines side by side at each x, so their bars do not hide one another.
    let nudge = (hi - lo).max(1.0) * 0.008;
    let x = XAxis {
        from: lo - nudge * most as f64,
        to: hi + nudge * most as f64,
        label: x_label,
    };
    let drawn: Vec<Panel> = panels
        .iter()
        .map(|p| Panel {
            title: p.title.clone(),
            y_label: p.y_label,
            series: p
                .lines
                .iter()
                .enumerate()
                .map(|(i, (label, points))| {
                    let dx = (i as f64 - (p.lines.len() as f64 - 1.0) / 2.0) * nudge;
                    Series {
                        label: label.clone(),
                        color: COLORS[i % COLORS.len()],
                        dashed: false,
                        markers: true,
                        points: points.iter().map(|q| (q.0 + dx, q.1)).collect(),
                        bars: points.iter().map(|q| (q.0 + dx, q.2, q.3)).collect(),
                    }
                })
                .collect(),
        })
        .collect();
    let height = 400 * drawn.len().max(1) as u32;
    write_both(dir, stem, title, &drawn, &x, (1000, height))
}
