//! The timeline of `foisctl icing-report --plot`: the node's thickness
//! with its ±σ band over days, meteorological icing (accreting) and
//! instrumental icing (ice on the sensor) shaded. The series comes
//! decimated ([`crate::icing::timeline`]): a year draws as fast as a day.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::output::{Format, format_of, write_error};
use super::{WIDE, draw_err, draw_legend};
use crate::icing::render::utc_text;
use crate::icing::report::Report;

/// Draw the report's timeline to `out` (PNG or SVG by its extension).
pub fn plot_icing(r: &Report, out: &Path) -> anyhow::Result<()> {
    let format = format_of(out)?;
    super::register_fonts();
    match format {
        Format::Png => {
            let root = BitMapBackend::new(out, WIDE).into_drawing_area();
            draw(&root, r)?;
            root.present().map_err(|e| write_error(out, &e))
        }
        Format::Svg => {
            let root = SVGBackend::new(out, WIDE).into_drawing_area();
            draw(&root, r)?;
            root.present().map_err(|e| write_error(out, &e))
        }
    }
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, r: &Report) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(draw_err)?;
    let t0 = r.first_ms.unwrap_or(0);
    let days = |ms: u64| ms.saturating_sub(t0) as f64 / 86_400_000.0;
    let x_max = days(r.last_ms.unwrap_or(t0)).max(1.0 / 24.0);
    let tl = &r.timeline;
    let y_max = tl
        .buckets()
        .iter()
        .map(|b| b.mean_mm() + b.sigma_mm())
        .fold(1.0f64, f64::max)
        // Room above the peaks for the legend.
        * 1.4;
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!(
                "Icing timeline: meteorological {:.1} h, instrumental {:.1} h, IEA ice class {}",
                r.meteorological_h, r.instrumental_h, r.iea_class
            ),
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..x_max, 0.0..y_max)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc(format!("days since {} UTC", utc_text(t0)))
        .y_desc("ice thickness, mm")
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(draw_err)?;
    let instr_style = RGBColor(150, 150, 150).mix(0.25).filled();
    let met_style = RGBColor(30, 120, 220).mix(0.35).filled();
    chart
        .draw_series(
            r.instr_periods
                .iter()
                .map(|&(a, b)| Rectangle::new([(days(a), 0.0), (days(b), y_max)], instr_style)),
        )
        .map_err(draw_err)?
        .label("instrumental icing (ice on the sensor)")
        .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 16, y + 6)], instr_style));
    chart
        .draw_series(
            r.met_periods.iter().map(|&(a, b)| {
                Rectangle::new([(days(a), 0.0), (days(b), y_max * 0.08)], met_style)
            }),
        )
        .map_err(draw_err)?
        .label("meteorological icing (accreting), bar at the foot")
        .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 16, y + 6)], met_style));
    // Runs of consecutive buckets: lines and bands break at gaps.
    let w = tl.width_ms();
    let mut runs: Vec<Vec<(f64, f64, f64)>> = Vec::new();
    let mut last_index: Option<u64> = None;
    for b in tl.buckets() {
        if last_index.is_none_or(|l| b.index > l + 1) {
            runs.push(Vec::new());
        }
        last_index = Some(b.index);
        let x = days(tl.start_ms(b) + w / 2);
        if let Some(run) = runs.last_mut() {
            run.push((x, b.mean_mm(), b.sigma_mm()));
        }
    }
    let band = RGBColor(220, 60, 40).mix(0.25).filled();
    for (k, run) in runs.iter().enumerate() {
        let mut poly: Vec<(f64, f64)> = run.iter().map(|&(x, m, s)| (x, m + s)).collect();
        poly.extend(run.iter().rev().map(|&(x, m, s)| (x, (m - s).max(0.0))));
        let s = chart
            .draw_series(std::iter::once(Polygon::new(poly, band)))
            .map_err(draw_err)?;
        if k == 0 {
            s.label("thickness ± σ")
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 16, y + 6)], band));
        }
        let s = chart
            .draw_series(LineSeries::new(
                run.iter().map(|&(x, m, _)| (x, m)),
                RGBColor(180, 30, 20).stroke_width(2),
            ))
            .map_err(draw_err)?;
        if k == 0 {
            s.label("thickness (node's estimate)").legend(|(x, y)| {
                PathElement::new([(x, y), (x + 16, y)], RGBColor(180, 30, 20).stroke_width(2))
            });
        }
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight, 15)
}
