//! The figure of `foisctl compare`: per channel, the simulator's band
//! μ(d) ± kσ(d), μ(d), and the logged samples against thickness.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::output::{Format, format_of, write_error};

use super::{WIDE, draw_err};
use crate::compare::{Comparison, band_at};

/// The figure of `foisctl compare`: per channel, the band μ ± kσ, μ, and
/// the logged samples against thickness.
/// PNG or SVG by the extension of `out`.
pub fn plot_comparison(c: &Comparison, ice: &str, out: &Path) -> anyhow::Result<()> {
    let format = format_of(out)?;
    super::register_fonts();
    match format {
        Format::Png => {
            let root = BitMapBackend::new(out, WIDE).into_drawing_area();
            draw_comparison(&root, c, ice)?;
            root.present().map_err(|e| write_error(out, &e))
        }
        Format::Svg => {
            let root = SVGBackend::new(out, WIDE).into_drawing_area();
            draw_comparison(&root, c, ice)?;
            root.present().map_err(|e| write_error(out, &e))
        }
    }
}

fn draw_comparison<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: &Comparison,
    ice: &str,
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(draw_err)?;
    let panels = root.split_evenly((1, 2));
    let d_max = c
        .samples
        .iter()
        .map(|s| s.thickness_mm)
        .fold(0.5, f64::max)
        .min(15.0);
    for (ch, area) in panels.iter().enumerate() {
        // The band's grid up to the axis' end, closed by an interpolated
        // point exactly at d_max (nothing is drawn past the axis).
        let mut grid: Vec<f64> = c
            .band
            .iter()
            .map(|p| p.thickness_mm)
            .filter(|&d| d < d_max - 1e-9)
            .collect();
        grid.push(d_max);
        let lo: Vec<(f64, f64)> = grid
            .iter()
            .map(|&d| (d, band_at(&c.band, d)))
            .map(|(d, (m, s))| (d, m[ch] - c.k_sigma * s[ch]))
            .collect();
        let hi: Vec<(f64, f64)> = grid
            .iter()
            .map(|&d| (d, band_at(&c.band, d)))
            .map(|(d, (m, s))| (d, m[ch] + c.k_sigma * s[ch]))
            .collect();
        let mu: Vec<(f64, f64)> = grid
            .iter()
            .map(|&d| (d, band_at(&c.band, d).0[ch]))
            .collect();
        let mut y_min = 0.0f64;
        let mut y_max = 1.0f64;
        for &(_, y) in lo.iter().chain(hi.iter()) {
            y_min = y_min.min(y);
            y_max = y_max.max(y);
        }
        for s in &c.samples {
            y_min = y_min.min(s.i_ua[ch]);
            y_max = y_max.max(s.i_ua[ch]);
        }
        let pad = 0.05 * (y_max - y_min);
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!(
                    "I{} vs simulated {ice}: RMS {:.2} µA, {:.0} % inside",
                    ch + 1,
                    c.channels[ch].rms_ua,
                    100.0 * c.channels[ch].inside
                ),
                ("sans-serif", 18),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..d_max, (y_min - pad)..(y_max + pad))
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_desc("ice thickness d (mm)")
            .y_desc(format!("I{} (µA)", ch + 1))
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(draw_err)?;
        let mut poly = lo.clone();
        poly.extend(hi.iter().rev());
        chart
            .draw_series(std::iter::once(Polygon::new(
                poly,
                RGBColor(255, 200, 120).mix(0.6).filled(),
            )))
            .map_err(draw_err)?
            .label(format!("μ ± {}σ (Monte Carlo)", c.k_sigma))
            .legend(|(x, y)| {
                Rectangle::new(
                    [(x, y - 6), (x + 20, y + 6)],
                    RGBColor(255, 200, 120).filled(),
                )
            });
        chart
            .draw_series(LineSeries::new(mu, RGBColor(200, 90, 0).stroke_width(2)))
            .map_err(draw_err)?
            .label("μ(d)")
            .legend(|(x, y)| {
                PathElement::new(
                    vec![(x, y), (x + 20, y)],
                    RGBColor(200, 90, 0).stroke_width(3),
                )
            });
        // At most ~4000 dots.
        let step = (c.samples.len() / 4000).max(1);
        chart
            .draw_series(
                c.samples
                    .iter()
                    .step_by(step)
                    .map(|s| Circle::new((s.thickness_mm, s.i_ua[ch]), 2, BLUE.mix(0.5).filled())),
            )
            .map_err(draw_err)?
            .label("logged")
            .legend(|(x, y)| Circle::new((x + 10, y), 3, BLUE.filled()));
        super::draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)?;
    }
    Ok(())
}
