//! The figure of `foisctl plot`: a log's currents over time, alarm periods
//! shaded, link breaks marked; below them the ice estimate (thickness with
//! its ±2σ band) when the log has one (a v2 node's log, or `foisctl
//! estimate`'s output).

use std::path::Path;

use anyhow::{Context, bail};
use plotters::prelude::*;

use super::{WIDE, draw_err};
use crate::csvlog::LogReader;

/// One logged measurement for the time plot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimePoint {
    /// Host time since the first row, s.
    pub t_s: f64,
    /// I1, I2, µA.
    pub i_ua: [f64; 2],
    /// Alarm output on.
    pub alarm: bool,
    /// The ice estimate: thickness and its σ, mm (empty for a v1 node).
    pub est_mm: Option<(f64, f64)>,
}

/// What a log holds for the time plot: points, and the breaks (link lost,
/// gaps, restarts) as times.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TimeSeries {
    /// Valid measurements.
    pub points: Vec<TimePoint>,
    /// Times of `gap`, `link_lost` and `node_restart` rows, s.
    pub breaks_s: Vec<f64>,
}

/// The time axis of `plot`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum TimeAxis {
    /// Host clock, from the first row (survives node restarts).
    #[default]
    Host,
    /// Node uptime (virtual time of a virtual node; restarts start over).
    Node,
}

impl TimeAxis {
    /// The x-axis caption, with the time unit.
    fn describe(self, unit: &str) -> String {
        match self {
            TimeAxis::Host => format!("host time since the first row ({unit})"),
            TimeAxis::Node => format!("node uptime ({unit})"),
        }
    }
}

/// Extract the time series from a foisctl log, row by row.
pub fn time_series(path: &Path, axis: TimeAxis) -> anyhow::Result<TimeSeries> {
    let mut rd = LogReader::open(path)?;
    let need = |rd: &LogReader, name: &str| {
        rd.need(name)
            .with_context(|| format!("is {} a foisctl log?", path.display()))
    };
    let (ms, kind, i1, i2, alarm) = (
        need(
            &rd,
            match axis {
                TimeAxis::Host => "host_unix_ms",
                TimeAxis::Node => "uptime_ms",
            },
        )?,
        need(&rd, "kind")?,
        need(&rd, "i1_ua")?,
        need(&rd, "i2_ua")?,
        need(&rd, "alarm")?,
    );
    let valid = rd.col("valid");
    let est = rd.col("est_thickness_mm").zip(rd.col("est_sigma_mm"));
    let num = |s: &str| s.trim().parse::<f64>().ok().filter(|x| x.is_finite());
    let mut t0: Option<f64> = None;
    let mut out = TimeSeries::default();
    let mut r = csv::StringRecord::new();
    while rd.next_row(&mut r)? {
        let Some(tm) = num(&r[ms]) else { continue };
        let t_s = match axis {
            TimeAxis::Host => (tm - *t0.get_or_insert(tm)) / 1000.0,
            TimeAxis::Node => tm / 1000.0,
        };
        match &r[kind] {
            "measurement" => {
                if valid.is_some_and(|v| r[v].trim() == "0") {
                    continue;
                }
                if let (Some(a), Some(b)) = (num(&r[i1]), num(&r[i2])) {
                    out.points.push(TimePoint {
                        t_s,
                        i_ua: [a, b],
                        alarm: r[alarm].trim() == "1",
                        est_mm: est.and_then(|(d, s)| num(&r[d]).zip(num(&r[s]))),
                    });
                }
            }
            "gap" | "link_lost" | "node_restart" => out.breaks_s.push(t_s),
            _ => {}
        }
    }
    Ok(out)
}

/// The estimate panel: posterior mean thickness and its ±2σ band (clipped
/// at 0 mm), over the same time axis as the currents.
fn draw_estimate<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    points: &[TimePoint],
    div: f64,
    x_max: f64,
    unit: &str,
    axis: TimeAxis,
) -> anyhow::Result<()> {
    let est: Vec<(f64, f64, f64)> = points
        .iter()
        .filter_map(|p| p.est_mm.map(|(d, s)| (p.t_s / div, d, s)))
        .collect();
    // At most ~3000 points per line (a day at 10 Hz draws fast).
    let stride = est.len().div_ceil(3000).max(1);
    let est: Vec<(f64, f64, f64)> = est.into_iter().step_by(stride).collect();
    let y_hi = est
        .iter()
        .map(|&(_, d, s)| d + 2.0 * s)
        .fold(1.0f64, f64::max)
        * 1.05;
    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.0..x_max.max(1e-6), 0.0..y_hi)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc(axis.describe(unit))
        .y_desc("ice estimate (mm)")
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(draw_err)?;
    let band_color = RGBColor(255, 150, 0);
    let mut band: Vec<(f64, f64)> = est
        .iter()
        .map(|&(t, d, s)| (t, (d + 2.0 * s).min(y_hi)))
        .collect();
    band.extend(
        est.iter()
            .rev()
            .map(|&(t, d, s)| (t, (d - 2.0 * s).max(0.0))),
    );
    chart
        .draw_series(std::iter::once(Polygon::new(
            band,
            band_color.mix(0.3).filled(),
        )))
        .map_err(draw_err)?
        .label("±2σ")
        .legend(move |(x, y)| {
            Rectangle::new([(x, y - 6), (x + 20, y + 6)], band_color.mix(0.3).filled())
        });
    chart
        .draw_series(LineSeries::new(
            est.iter().map(|&(t, d, _)| (t, d)),
            band_color.stroke_width(2),
        ))
        .map_err(draw_err)?
        .label("estimated thickness")
        .legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 20, y)], band_color.stroke_width(3))
        });
    super::draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 15)?;
    Ok(())
}

/// Alarm periods (start, end) in s: runs of measurements with the alarm on.
pub fn alarm_periods(points: &[TimePoint]) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut start: Option<f64> = None;
    let mut last = 0.0;
    for p in points {
        match (p.alarm, start) {
            (true, None) => start = Some(p.t_s),
            (false, Some(s)) => {
                out.push((s, p.t_s));
                start = None;
            }
            _ => {}
        }
        last = p.t_s;
    }
    if let Some(s) = start {
        out.push((s, last));
    }
    out
}

/// At most `2 * buckets` points: the minimum and the maximum of each run of
/// consecutive points, in their order (spikes survive, a day at 10 Hz draws
/// fast).
pub fn decimate(points: &[(f64, f64)], buckets: usize) -> Vec<(f64, f64)> {
    if points.len() <= 2 * buckets.max(1) {
        return points.to_vec();
    }
    let size = points.len().div_ceil(buckets.max(1));
    let mut out = Vec::with_capacity(2 * buckets);
    for chunk in points.chunks(size) {
        let mut lo = 0;
        let mut hi = 0;
        for (i, p) in chunk.iter().enumerate() {
            if p.1 < chunk[lo].1 {
                lo = i;
            }
            if p.1 > chunk[hi].1 {
                hi = i;
            }
        }
        let (a, b) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        out.push(chunk[a]);
        if b != a {
            out.push(chunk[b]);
        }
    }
    out
}

/// `foisctl plot`: I1 and I2 over host time, alarm periods shaded, breaks
/// in the link as grey lines.
pub fn plot_log(log: &Path, out: &Path, axis: TimeAxis) -> anyhow::Result<usize> {
    let ts = time_series(log, axis)?;
    if ts.points.is_empty() {
        bail!("log {} holds no valid measurement to plot", log.display());
    }
    let span = ts.points.last().map_or(1.0, |p| p.t_s).max(1e-3);
    let (unit, div) = if span > 7200.0 {
        ("h", 3600.0)
    } else if span > 300.0 {
        ("min", 60.0)
    } else {
        ("s", 1.0)
    };
    let x_max = span / div;
    let (mut y_min, mut y_max) = (0.0f64, 1.0f64);
    for p in &ts.points {
        for v in p.i_ua {
            y_min = y_min.min(v);
            y_max = y_max.max(v);
        }
    }
    let pad = 0.05 * (y_max - y_min);
    let (y_lo, y_hi) = (y_min - pad, y_max + pad);
    super::register_fonts();
    let with_est = ts.points.iter().any(|p| p.est_mm.is_some());
    let size = if with_est {
        (WIDE.0, WIDE.1 + 350)
    } else {
        WIDE
    };
    let root = BitMapBackend::new(out, size).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err)?;
    let (top, bottom) = root.split_vertically(WIDE.1);
    let mut chart = ChartBuilder::on(&top)
        .caption(
            format!(
                "FOIS log {}",
                log.file_name()
                    .map_or(String::new(), |n| n.to_string_lossy().into_owned())
            ),
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.0..x_max.max(1e-6), y_lo..y_hi)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc(axis.describe(unit))
        .y_desc("net photocurrent (µA)")
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(draw_err)?;
    let periods = alarm_periods(&ts.points);
    chart
        .draw_series(periods.iter().map(|&(a, b)| {
            Rectangle::new(
                [(a / div, y_lo), (b / div, y_hi)],
                RGBColor(255, 170, 170).mix(0.5).filled(),
            )
        }))
        .map_err(draw_err)?
        .label("alarm on")
        .legend(|(x, y)| {
            Rectangle::new(
                [(x, y - 6), (x + 20, y + 6)],
                RGBColor(255, 170, 170).filled(),
            )
        });
    if !ts.breaks_s.is_empty() {
        chart
            .draw_series(ts.breaks_s.iter().map(|&t| {
                PathElement::new(
                    vec![(t / div, y_lo), (t / div, y_hi)],
                    BLACK.mix(0.35).stroke_width(1),
                )
            }))
            .map_err(draw_err)?
            .label("gap / link lost / restart")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.35)));
    }
    let colors = [BLUE, RGBColor(0, 140, 0)];
    for (c, name) in ["I1", "I2"].iter().enumerate() {
        let color = colors[c];
        // Break the line at gaps longer than 5 s so lost time is visible.
        let mut segs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        let mut prev: Option<f64> = None;
        for p in &ts.points {
            if prev.is_some_and(|q| p.t_s - q > 5.0) {
                segs.push(Vec::new());
            }
            prev = Some(p.t_s);
            if let Some(s) = segs.last_mut() {
                s.push((p.t_s / div, p.i_ua[c]));
            }
        }
        for (k, s) in segs.into_iter().enumerate() {
            let s = decimate(&s, 3000);
            let a = chart
                .draw_series(LineSeries::new(s, color.stroke_width(2)))
                .map_err(draw_err)?;
            if k == 0 {
                a.label(*name).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
                });
            }
        }
    }
    super::draw_legend(&mut chart, SeriesLabelPosition::UpperLeft, 15)?;
    if with_est {
        draw_estimate(&bottom, &ts.points, div, x_max, unit, axis)?;
    }
    root.present().map_err(draw_err)?;
    Ok(ts.points.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decimation_keeps_extremes_in_order() {
        let pts: Vec<(f64, f64)> = (0..10_000)
            .map(|i| {
                (
                    f64::from(i),
                    if i == 4321 { 99.0 } else { f64::from(i % 7) },
                )
            })
            .collect();
        let d = decimate(&pts, 100);
        assert!(d.len() <= 200);
        assert!(d.windows(2).all(|w| w[0].0 < w[1].0));
        assert!(d.contains(&(4321.0, 99.0)));
        assert_eq!(decimate(&pts[..50], 100).len(), 50);
    }

    #[test]
    fn alarm_periods_are_runs_of_alarm_rows() {
        let p = |t: f64, a: bool| TimePoint {
            t_s: t,
            i_ua: [0.0; 2],
            alarm: a,
            est_mm: None,
        };
        let pts = [
            p(0.0, false),
            p(1.0, true),
            p(2.0, true),
            p(3.0, false),
            p(4.0, true),
            p(5.0, true),
        ];
        assert_eq!(alarm_periods(&pts), vec![(1.0, 3.0), (4.0, 5.0)]);
    }

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
        assert_eq!(png_height(&png), WIDE.1 + 350);

        let v1 = write("v1.csv", false);
        let ts = time_series(&v1, TimeAxis::Node).unwrap();
        assert!(ts.points.iter().all(|p| p.est_mm.is_none()));
        let png = dir.path().join("v1.png");
        plot_log(&v1, &png, TimeAxis::Node).unwrap();
        assert_eq!(png_height(&png), WIDE.1);
    }
}
