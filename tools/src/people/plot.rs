//! The two figures of `sim people`, PNG and SVG: movement time against the index of difficulty
//! (each participant's mean per condition, the least-squares line, and the span of slopes
//! people show drawn from the line's intercept), and one reach's speed profile over its peak
//! against time over its movement time, beside the minimum-jerk bell.

use std::path::Path;

use anyhow::{anyhow, Context};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::measure::Fit;

const BLUE: RGBColor = RGBColor(31, 119, 180);
const GREY: RGBColor = RGBColor(190, 190, 190);

/// What the Fitts plot shows.
#[derive(Debug, Clone, PartialEq)]
pub struct FittsPlot {
    /// (ID bits, MT s): each participant's mean per condition.
    pub points: Vec<(f64, f64)>,
    /// The least-squares line through them.
    pub fit: Fit,
    /// The slopes people show, s/bit.
    pub human_slopes: (f64, f64),
    /// The participants (for the title).
    pub participants: u64,
}

fn draw_fitts<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, p: &FittsPlot) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing: {e:?}");
    root.fill(&WHITE).map_err(err)?;
    let x_hi = p.points.iter().map(|q| q.0).fold(0.0, f64::max) + 0.5;
    let line = |b: f64, x: f64| p.fit.a + b * x;
    let y_hi = p
        .points
        .iter()
        .map(|q| q.1)
        .fold(line(p.human_slopes.1, x_hi), f64::max)
        * 1.05;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "movement time against index of difficulty, {} simulated participants",
                p.participants
            ),
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..x_hi, 0.0..y_hi)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("ID = log2(D/W + 1), bits")
        .y_desc("MT, s")
        .label_style(("sans-serif", 12))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(err)?;
    let (lo, hi) = p.human_slopes;
    chart
        .draw_series(std::iter::once(Polygon::new(
            vec![
                (0.0, line(lo, 0.0)),
                (x_hi, line(lo, x_hi)),
                (x_hi, line(hi, x_hi)),
            ],
            GREY.mix(0.5).filled(),
        )))
        .map_err(err)?
        .label(format!(
            "people's slopes, {lo:.2}–{hi:.2} s/bit, from the fit's intercept"
        ))
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], GREY.mix(0.5).filled()));
    chart
        .draw_series(
            p.points
                .iter()
                .map(|&q| Circle::new(q, 3, BLUE.mix(0.6).filled())),
        )
        .map_err(err)?
        .label("a participant's mean MT in one condition")
        .legend(|(x, y)| Circle::new((x + 9, y), 3, BLUE.filled()));
    chart
        .draw_series(LineSeries::new(
            [(0.0, line(p.fit.b, 0.0)), (x_hi, line(p.fit.b, x_hi))],
            BLACK.stroke_width(2),
        ))
        .map_err(err)?
        .label(format!(
            "MT = {:.3} s + {:.3} s/bit × ID (r² {:.3})",
            p.fit.a, p.fit.b, p.fit.r2
        ))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.stroke_width(2)));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 12))
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)
}

/// What the profile plot shows.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfilePlot {
    /// (t/MT from the onset, speed over its peak) of the reach.
    pub reach: Vec<(f64, f64)>,
    /// The same of the minimum-jerk bell.
    pub bell: Vec<(f64, f64)>,
    /// What reach it is (for the title).
    pub title: String,
}

fn draw_profile<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    p: &ProfilePlot,
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing: {e:?}");
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(&p.title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d(-0.15..1.15, 0.0..1.1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("t / MT (from the speed crossing 5 % of its peak)")
        .y_desc("v / v_peak")
        .label_style(("sans-serif", 12))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(err)?;
    chart
        .draw_series(DashedLineSeries::new(
            p.bell.iter().copied(),
            6,
            4,
            BLACK.stroke_width(1),
        ))
        .map_err(err)?
        .label("minimum jerk (Flash & Hogan 1985)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.stroke_width(1)));
    chart
        .draw_series(LineSeries::new(
            p.reach.iter().copied(),
            BLUE.stroke_width(2),
        ))
        .map_err(err)?
        .label("the participant's reach")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLUE.stroke_width(2)));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 12))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(err)?;
    root.present().map_err(err)
}

/// Writes `fitts.png`, `fitts.svg`, `profile.png` and `profile.svg` into `dir` (created if
/// missing).
///
/// # Errors
/// The font is missing, or a file cannot be written.
pub fn write(dir: &Path, fitts: &FittsPlot, profile: &ProfilePlot) -> anyhow::Result<()> {
    crate::plots::ensure_font()?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let size = (900, 600);
    let path = |stem: &str, ext: &str| dir.join(format!("{stem}.{ext}"));
    let (png, svg) = (path("fitts", "png"), path("fitts", "svg"));
    draw_fitts(BitMapBackend::new(&png, size).into_drawing_area(), fitts)
        .with_context(|| format!("plotting {}", png.display()))?;
    draw_fitts(SVGBackend::new(&svg, size).into_drawing_area(), fitts)
        .with_context(|| format!("plotting {}", svg.display()))?;
    let (png, svg) = (path("profile", "png"), path("profile", "svg"));
    draw_profile(BitMapBackend::new(&png, size).into_drawing_area(), profile)
        .with_context(|| format!("plotting {}", png.display()))?;
    draw_profile(SVGBackend::new(&svg, size).into_drawing_area(), profile)
        .with_context(|| format!("plotting {}", svg.display()))?;
    Ok(())
}
