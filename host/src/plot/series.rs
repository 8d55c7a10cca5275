//! PNG plots of the simulator results, laid out like the thesis figures: ice thickness in mm
//! on x, currents in µA on y, I1 blue and I2 red.

use std::path::Path;

use anyhow::Result;
use plotters::prelude::*;

/// Plot size, pixels (kept small for the gallery).
pub const SIZE: (u32, u32) = (800, 500);

/// Colour of I1 (thesis: blue).
pub const C_I1: RGBColor = RGBColor(0, 70, 220);
/// Colour of I2 (thesis: red).
pub const C_I2: RGBColor = RGBColor(220, 30, 30);
/// Colour of the mean of I1 (thesis Fig. 5.17: cyan).
pub const C_I1_MEAN: RGBColor = RGBColor(0, 200, 220);
/// Colour of the mean of I2 (thesis Fig. 5.17: yellow/orange).
pub const C_I2_MEAN: RGBColor = RGBColor(240, 180, 0);
/// Green (analytic I1, thesis Fig. 3.19).
pub const C_GREEN: RGBColor = RGBColor(0, 160, 60);
/// Magenta (ray tracer I2, thesis Fig. 3.19).
pub const C_MAGENTA: RGBColor = RGBColor(200, 0, 200);
/// Cyan (analytic I2, thesis Fig. 3.19).
pub const C_CYAN: RGBColor = RGBColor(0, 190, 210);

/// How a series is drawn.
#[derive(Clone, Copy, Debug)]
pub enum Kind {
    /// Solid line of this width.
    Line(u32),
    /// Dashed line.
    Dashed,
    /// Small dots of this radius.
    Dots(u32),
}

/// One series of (x, y) points.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend label (None: not in the legend).
    pub label: Option<String>,
    /// Colour.
    pub color: RGBColor,
    /// Style.
    pub kind: Kind,
    /// Points (x mm, y).
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// A series.
    pub fn new(label: Option<&str>, color: RGBColor, kind: Kind, points: Vec<(f64, f64)>) -> Self {
        Series {
            label: label.map(str::to_owned),
            color,
            kind,
            points,
        }
    }
}

/// A vertical error bar: (x, low, mid, high, colour).
pub type ErrBar = (f64, f64, f64, f64, RGBColor);

/// Draw a figure to `path`.
pub fn plot(
    path: &Path,
    title: &str,
    y_desc: &str,
    series: &[Series],
    bars: &[ErrBar],
) -> Result<()> {
    let format = super::output::format_of(path)?;
    super::register_fonts();
    let drawn = match format {
        super::output::Format::Png => {
            let root = BitMapBackend::new(path, SIZE).into_drawing_area();
            draw(&root, title, y_desc, series, bars).and_then(|()| Ok(root.present()?))
        }
        super::output::Format::Svg => {
            let root = SVGBackend::new(path, SIZE).into_drawing_area();
            draw(&root, title, y_desc, series, bars).and_then(|()| Ok(root.present()?))
        }
    };
    drawn.map_err(|e| super::output::write_error(path, &e))
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    y_desc: &str,
    series: &[Series],
    bars: &[ErrBar],
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let mut x_max = f64::MIN;
    let mut x_min = f64::MAX;
    let mut y_max = 0.0f64;
    let mut y_min = 0.0f64;
    for s in series {
        for &(x, y) in &s.points {
            if x.is_finite() && y.is_finite() {
                x_max = x_max.max(x);
                x_min = x_min.min(x);
                y_max = y_max.max(y);
                y_min = y_min.min(y);
            }
        }
    }
    for &(x, lo, _, hi, _) in bars {
        if lo.is_finite() && hi.is_finite() {
            x_max = x_max.max(x);
            x_min = x_min.min(x);
            y_max = y_max.max(hi);
            y_min = y_min.min(lo);
        }
    }
    if x_min >= x_max {
        x_min = 0.0;
        x_max = x_max.max(1.0);
    }
    if y_max <= y_min {
        y_max = y_min + 1.0;
    }
    let y_top = y_max + 0.08 * (y_max - y_min);
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(x_min..x_max, y_min..y_top)?;
    chart
        .configure_mesh()
        .x_desc("ice thickness d (mm)")
        .y_desc(y_desc)
        .label_style(("sans-serif", 15))
        .light_line_style(WHITE.mix(0.0))
        .draw()?;
    let mut any_label = false;
    for s in series {
        let color = s.color;
        let pts = s
            .points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite());
        let anno = match s.kind {
            Kind::Line(w) => chart.draw_series(LineSeries::new(pts, color.stroke_width(w)))?,
            Kind::Dashed => chart.draw_series(DashedLineSeries::new(
                pts.collect::<Vec<_>>(),
                8,
                5,
                color.stroke_width(2),
            ))?,
            Kind::Dots(r) => {
                chart.draw_series(pts.map(|(x, y)| Circle::new((x, y), r, color.filled())))?
            }
        };
        if let Some(l) = &s.label {
            any_label = true;
            let dashed = matches!(s.kind, Kind::Dashed);
            anno.label(l.clone()).legend(move |(x, y)| {
                let st = color.stroke_width(3);
                let (a, b) = if dashed {
                    ((0, 8), (12, 20))
                } else {
                    ((0, 10), (10, 20))
                };
                EmptyElement::at((x, y))
                    + PathElement::new(vec![(a.0, 0), (a.1, 0)], st)
                    + PathElement::new(vec![(b.0, 0), (b.1, 0)], st)
            });
        }
    }
    if !bars.is_empty() {
        chart.draw_series(
            bars.iter()
                .filter(|b| b.1.is_finite() && b.3.is_finite())
                .map(|&(x, lo, mid, hi, c)| {
                    ErrorBar::new_vertical(x, lo, mid, hi, c.stroke_width(2), 8)
                }),
        )?;
    }
    if any_label {
        super::draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 15)?;
    }
    Ok(())
}
