//! The figure of `foisctl plot`: a log over time in four panels sharing one
//! time axis (UTC, or node uptime / virtual time): the currents with alarm
//! periods shaded and link breaks marked; the node's state (dry / wet /
//! ice) and its estimated medium as coloured bands; the air temperature;
//! and, when the log has one (a v2 node's log, or `foisctl estimate`'s
//! output), the estimated thickness with its ±2σ band. Every line, band and
//! shading stops at a gap, a link loss, a restart or a time jump
//! ([`super::runs`]): nothing is drawn where there is no data.

use std::path::Path;

use anyhow::bail;
use fois_link::timefmt::iso_utc;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::log_layout::{Drawn, layout};
pub use super::log_series::TimeAxis;
use super::log_series::{State, TimePoint, TimeSeries, time_series};
use super::output::{Format, format_of, write_error};
use super::{WIDE, draw_err};

/// A label of the time axis at `x` s: UTC time of day for the host axis
/// (the date in the title; with the day when the log spans midnight), or
/// `h:mm:ss` of node uptime.
fn time_label(axis: TimeAxis, t0_unix_ms: Option<u64>, multi_day: bool, x: f64) -> String {
    match (axis, t0_unix_ms) {
        (TimeAxis::Host, Some(t0)) => {
            let iso = iso_utc(t0.saturating_add((x.max(0.0) * 1000.0) as u64));
            if multi_day {
                format!("{} {}", &iso[5..10], &iso[11..16])
            } else {
                iso[11..19].to_string()
            }
        }
        _ => {
            let s = x.max(0.0) as u64;
            format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
        }
    }
}

const C_DRY: RGBColor = RGBColor(225, 225, 225);
const C_WET: RGBColor = RGBColor(110, 170, 250);
const C_ICE: RGBColor = RGBColor(140, 80, 200);
const C_GLAZED: RGBColor = RGBColor(40, 160, 160);
const C_RIME: RGBColor = RGBColor(190, 160, 240);
const C_EST: RGBColor = RGBColor(255, 150, 0);
const C_ALARM: RGBColor = RGBColor(255, 170, 170);

fn state_color(s: State) -> RGBColor {
    match s {
        State::Dry => C_DRY,
        State::Wet => C_WET,
        State::Ice => C_ICE,
    }
}

fn medium_color(m: &str) -> RGBColor {
    match m {
        "water" => C_WET,
        "glazed" => C_GLAZED,
        "rime" => C_RIME,
        _ => C_DRY,
    }
}

/// Heights of the panels, pixels: title, currents, bands, temperature,
/// estimate (0 without one).
fn heights(with_est: bool) -> [u32; 5] {
    [40, 330, 120, 170, if with_est { 260 } else { 0 }]
}

/// `foisctl plot`: the figure of `log` to `out` (PNG or SVG by its
/// extension). Returns the number of measurements drawn.
pub fn plot_log(log: &Path, out: &Path, axis: TimeAxis) -> anyhow::Result<usize> {
    let format = format_of(out)?;
    let ts = time_series(log, axis)?;
    if ts.points.is_empty() {
        bail!("log {} holds no valid measurement to plot", log.display());
    }
    let drawn = layout(&ts);
    let with_est = !drawn.estimate.is_empty();
    let size = (WIDE.0, heights(with_est).iter().sum());
    let name = log
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
    super::register_fonts();
    let r = match format {
        Format::Png => {
            let root = BitMapBackend::new(out, size).into_drawing_area();
            draw_log(&root, &ts, &drawn, axis, &name)?;
            root.present().map_err(|e| write_error(out, &e))
        }
        Format::Svg => {
            let root = SVGBackend::new(out, size).into_drawing_area();
            draw_log(&root, &ts, &drawn, axis, &name)?;
            root.present().map_err(|e| write_error(out, &e))
        }
    };
    r?;
    Ok(ts.points.len())
}

fn draw_log<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    ts: &TimeSeries,
    d: &Drawn,
    axis: TimeAxis,
    name: &str,
) -> anyhow::Result<()> {
    root.fill(&WHITE).map_err(draw_err)?;
    let h = heights(!d.estimate.is_empty());
    let (title, rest) = root.split_vertically(h[0]);
    let (cur, rest) = rest.split_vertically(h[1]);
    let (bands, rest) = rest.split_vertically(h[2]);
    let (temp, est) = rest.split_vertically(h[3]);

    let t = |p: &TimePoint| p.t_s;
    let x0 = ts.points.iter().map(t).fold(f64::INFINITY, f64::min);
    let x1 = ts.points.iter().map(t).fold(f64::NEG_INFINITY, f64::max);
    let x1 = if x1 > x0 { x1 } else { x0 + 1.0 };
    let date = ts.t0_unix_ms.map(|t| iso_utc(t)[..10].to_string());
    let multi_day = ts
        .t0_unix_ms
        .is_some_and(|t0| iso_utc(t0)[..10] != iso_utc(t0 + (x1 * 1000.0) as u64)[..10]);
    let fmt_x = |x: &f64| time_label(axis, ts.t0_unix_ms, multi_day, *x);
    let x_desc = match axis {
        TimeAxis::Host => format!(
            "UTC time{}",
            date.as_ref()
                .map(|d| format!(" on {d}"))
                .unwrap_or_default()
        ),
        TimeAxis::Node => "node uptime h:mm:ss (a virtual node: virtual time)".to_string(),
    };
    let node = ts
        .node_id
        .as_ref()
        .map_or("node (id not in the log)".to_string(), |id| {
            format!("node {id}")
        });
    let title_text = format!(
        "FOIS {node} — {} — {name}",
        date.map_or("date unknown".to_string(), |d| format!("{d} (UTC)"))
    );
    title
        .draw_text(
            &title_text,
            &("sans-serif", 22).into_font().color(&BLACK),
            (70, 10),
        )
        .map_err(draw_err)?;

    // Currents.
    let (mut y_min, mut y_max) = (0.0f64, 1.0f64);
    for p in &ts.points {
        for v in p.i_ua {
            y_min = y_min.min(v);
            y_max = y_max.max(v);
        }
    }
    let pad = 0.05 * (y_max - y_min);
    let (y_lo, y_hi) = (y_min - pad, y_max + pad);
    let mut chart = ChartBuilder::on(&cur)
        .margin(10)
        .margin_right(40)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, y_lo..y_hi)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_label_formatter(&fmt_x)
        .y_desc("net photocurrent (µA)")
        .label_style(("sans-serif", 14))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(draw_err)?;
    if !d.alarm.is_empty() {
        chart
            .draw_series(
                d.alarm.iter().map(|&(a, b)| {
                    Rectangle::new([(a, y_lo), (b, y_hi)], C_ALARM.mix(0.5).filled())
                }),
            )
            .map_err(draw_err)?
            .label("alarm on")
            .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 20, y + 6)], C_ALARM.filled()));
    }
    if !ts.breaks_s.is_empty() {
        chart
            .draw_series(ts.breaks_s.iter().map(|&t| {
                PathElement::new(vec![(t, y_lo), (t, y_hi)], BLACK.mix(0.35).stroke_width(1))
            }))
            .map_err(draw_err)?
            .label("gap / link lost / restart")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.35)));
    }
    let colors = [BLUE, RGBColor(0, 140, 0)];
    for (c, name) in ["I1", "I2"].iter().enumerate() {
        let color = colors[c];
        for (k, line) in d.currents[c].iter().enumerate() {
            let a = chart
                .draw_series(LineSeries::new(line.iter().copied(), color.stroke_width(2)))
                .map_err(draw_err)?;
            if k == 0 {
                a.label(*name).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
                });
            }
        }
    }
    super::draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)?;

    // State and medium bands, with their key above.
    let (key, strip) = bands.split_vertically(26);
    let mut x = 80;
    let font = ("sans-serif", 14).into_font().color(&BLACK);
    let entries: [(&str, RGBColor); 7] = [
        ("node state: dry", C_DRY),
        ("wet", C_WET),
        ("ice", C_ICE),
        ("   estimated medium: water", C_WET),
        ("glazed", C_GLAZED),
        ("rime", C_RIME),
        ("dry", C_DRY),
    ];
    for (label, color) in entries {
        let w = key.estimate_text_size(label, &font).map_err(draw_err)?.0 as i32;
        key.draw_text(label, &font, (x, 6)).map_err(draw_err)?;
        x += w + 4;
        key.draw(&Rectangle::new([(x, 6), (x + 18, 20)], color.filled()))
            .map_err(draw_err)?;
        x += 28;
    }
    let row_label = |y: &f64| {
        if (y - 1.5).abs() < 1e-6 {
            "state".to_string()
        } else if (y - 0.5).abs() < 1e-6 {
            "medium".to_string()
        } else {
            String::new()
        }
    };
    let mut chart = ChartBuilder::on(&strip)
        .margin(10)
        .margin_right(40)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, 0.0..2.0)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .disable_y_mesh()
        .disable_x_mesh()
        .y_labels(5)
        .y_label_formatter(&row_label)
        .x_label_formatter(&fmt_x)
        .label_style(("sans-serif", 14))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(draw_err)?;
    chart
        .draw_series(
            d.states
                .iter()
                .map(|&(a, b, s)| Rectangle::new([(a, 1.05), (b, 1.95)], state_color(s).filled())),
        )
        .map_err(draw_err)?;
    chart
        .draw_series(
            d.media
                .iter()
                .map(|&(a, b, m)| Rectangle::new([(a, 0.05), (b, 0.95)], medium_color(m).filled())),
        )
        .map_err(draw_err)?;

    // Temperature.
    let temps = d.temperature.iter().flatten().map(|p| p.1);
    let (t_min, t_max) = temps.fold((0.0f64, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
    let t_pad = (0.1 * (t_max - t_min)).max(1.0);
    let mut chart = ChartBuilder::on(&temp)
        .margin(10)
        .margin_right(40)
        .x_label_area_size(if d.estimate.is_empty() { 45 } else { 30 })
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, (t_min - t_pad)..(t_max + t_pad))
        .map_err(draw_err)?;
    let mut mesh = chart.configure_mesh();
    mesh.x_label_formatter(&fmt_x)
        .light_line_style(WHITE.mix(0.0))
        .y_desc("air (°C)")
        .label_style(("sans-serif", 14));
    if d.estimate.is_empty() {
        mesh.x_desc(x_desc.clone());
    }
    mesh.draw().map_err(draw_err)?;
    chart
        .draw_series(std::iter::once(PathElement::new(
            vec![(x0, 0.0), (x1, 0.0)],
            BLACK.mix(0.3).stroke_width(1),
        )))
        .map_err(draw_err)?;
    let red = RGBColor(200, 40, 40);
    for line in &d.temperature {
        chart
            .draw_series(LineSeries::new(line.iter().copied(), red.stroke_width(2)))
            .map_err(draw_err)?;
    }

    if !d.estimate.is_empty() {
        draw_estimate(&est, d, x0, x1, &fmt_x, &x_desc)?;
    }
    Ok(())
}

/// The estimate panel: posterior mean thickness and its ±2σ band (clipped
/// at 0 mm), one piece per run of data.
fn draw_estimate<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    d: &Drawn,
    x0: f64,
    x1: f64,
    fmt_x: &dyn Fn(&f64) -> String,
    x_desc: &str,
) -> anyhow::Result<()> {
    let y_hi = d
        .estimate
        .iter()
        .flatten()
        .map(|&(_, m, s)| m + 2.0 * s)
        .fold(1.0f64, f64::max)
        * 1.05;
    let mut chart = ChartBuilder::on(area)
        .margin(10)
        .margin_right(40)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, 0.0..y_hi)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_label_formatter(&fmt_x)
        .x_desc(x_desc)
        .y_desc("ice estimate (mm)")
        .label_style(("sans-serif", 14))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(draw_err)?;
    for (k, piece) in d.estimate.iter().enumerate() {
        let mut band: Vec<(f64, f64)> = piece
            .iter()
            .map(|&(t, m, s)| (t, (m + 2.0 * s).min(y_hi)))
            .collect();
        band.extend(
            piece
                .iter()
                .rev()
                .map(|&(t, m, s)| (t, (m - 2.0 * s).max(0.0))),
        );
        let a = chart
            .draw_series(std::iter::once(Polygon::new(band, C_EST.mix(0.3).filled())))
            .map_err(draw_err)?;
        if k == 0 {
            a.label("±2σ (95 % of the truth inside)")
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 6), (x + 20, y + 6)], C_EST.mix(0.3).filled())
                });
        }
        let a = chart
            .draw_series(LineSeries::new(
                piece.iter().map(|&(t, m, _)| (t, m)),
                C_EST.stroke_width(2),
            ))
            .map_err(draw_err)?;
        if k == 0 {
            a.label("estimated thickness").legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], C_EST.stroke_width(3))
            });
        }
    }
    super::draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 14)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// PNG height from the IHDR chunk.
    fn png_height(path: &Path) -> u32 {
        let b = std::fs::read(path).unwrap();
        assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n");
        u32::from_be_bytes([b[20], b[21], b[22], b[23]])
    }

    #[test]
    fn the_estimate_is_read_and_drawn_below_the_currents() {
        use crate::csvlog::{CsvLog, Row};
        use fois_protocol::{DetectorState, DeviceMsg, IceEstimate, Measurement, MeasurementV2};
        let dir = tempfile::tempdir().unwrap();
        let m = |t: u64| Measurement {
            uptime_ms: t,
            i1_na: 20_000,
            i2_na: 7_000,
            ambient1_na: 0,
            ambient2_na: 0,
            temperature_centi_c: -500,
            vdda_mv: 3300,
            flags: 0,
            state: DetectorState::Ice,
        };
        let write = |name: &str, v2: bool| {
            let path = dir.path().join(name);
            let mut log = CsvLog::open(&path).unwrap();
            for (i, t) in [100u64, 200, 300].into_iter().enumerate() {
                let msg = if v2 {
                    DeviceMsg::MeasurementV2(MeasurementV2 {
                        measurement: m(t),
                        estimate: (i > 0).then_some(IceEstimate {
                            thickness_um: 2000 + 100 * i as u16,
                            sigma_um: 300,
                            medium: fois_protocol::Medium::Rime,
                            probability_permille: 950,
                        }),
                    })
                } else {
                    DeviceMsg::Measurement(m(t))
                };
                log.write(&Row::device(i as u32, &msg)).unwrap();
            }
            log.close().unwrap();
            path
        };
        let v2 = write("v2.csv", true);
        let ts = time_series(&v2, TimeAxis::Node).unwrap();
        let est: Vec<Option<(f64, f64)>> = ts.points.iter().map(|p| p.est_mm).collect();
        assert_eq!(est, [None, Some((2.1, 0.3)), Some((2.2, 0.3))]);
        let png = dir.path().join("v2.png");
        plot_log(&v2, &png, TimeAxis::Node).unwrap();
        assert_eq!(png_height(&png), heights(true).iter().sum::<u32>());

        let svg = dir.path().join("v2.svg");
        plot_log(&v2, &svg, TimeAxis::Host).unwrap();
        let text = std::fs::read_to_string(&svg).unwrap();
        assert!(
            text.starts_with("<svg") && text.contains("ice estimate (mm)"),
            "SVG"
        );
        let e = plot_log(&v2, &dir.path().join("no/such/dir.png"), TimeAxis::Host).unwrap_err();
        assert!(format!("{e:#}").contains("does not exist"), "{e:#}");

        // A log of a foisctl before the `faults` column reads the same.
        let old = dir.path().join("old.csv");
        let text = std::fs::read_to_string(&v2).unwrap();
        let drop_faults = |line: &str| {
            let mut f: Vec<&str> = line.split(',').collect();
            f.remove(15);
            f.join(",")
        };
        assert_eq!(crate::csvlog::HEADER.split(',').nth(15), Some("faults"));
        let old_text: Vec<String> = text.lines().map(drop_faults).collect();
        std::fs::write(&old, old_text.join("\n") + "\n").unwrap();
        assert_eq!(
            time_series(&old, TimeAxis::Node).unwrap(),
            time_series(&v2, TimeAxis::Node).unwrap()
        );

        let v1 = write("v1.csv", false);
        let ts = time_series(&v1, TimeAxis::Node).unwrap();
        assert!(ts.points.iter().all(|p| p.est_mm.is_none()));
        let png = dir.path().join("v1.png");
        plot_log(&v1, &png, TimeAxis::Node).unwrap();
        assert_eq!(png_height(&png), heights(false).iter().sum::<u32>());
    }
}
