//! A `foisctl` log read into the time series `foisctl plot` draws: each
//! measurement's time on the chosen axis (UTC, or node uptime / virtual
//! time), currents, temperature, state, alarm and estimate, and where the
//! log breaks (gaps, link losses, restarts).

use std::path::Path;

use anyhow::Context;

use crate::csvlog::LogReader;

/// The node's state as a measurement row gives it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    /// `Dry`.
    Dry,
    /// `Wet`: a film above the freeze limit.
    Wet,
    /// `Ice`: the alarm rule's ice.
    Ice,
}

impl State {
    fn parse(s: &str) -> Option<State> {
        match s.trim() {
            "Dry" => Some(State::Dry),
            "Wet" => Some(State::Wet),
            "Ice" => Some(State::Ice),
            _ => None,
        }
    }
}

/// One logged measurement for the time plot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimePoint {
    /// Time on the plot's axis, s (host: since the first row; node: uptime).
    pub t_s: f64,
    /// The node's frame sequence number.
    pub seq: Option<u32>,
    /// I1, I2, µA.
    pub i_ua: [f64; 2],
    /// Alarm output on.
    pub alarm: bool,
    /// The ice estimate: thickness and its σ, mm (empty for a v1 node).
    pub est_mm: Option<(f64, f64)>,
    /// Air temperature, °C.
    pub temp_c: Option<f64>,
    /// The node's state.
    pub state: Option<State>,
    /// The estimate's most likely medium (`dry`, `water`, `glazed`, `rime`).
    pub medium: Option<&'static str>,
}

/// What a log holds for the time plot.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TimeSeries {
    /// Valid measurements, in log order.
    pub points: Vec<TimePoint>,
    /// Times of `gap`, `link_lost` and `node_restart` rows, s, sorted.
    pub breaks_s: Vec<f64>,
    /// Host time of the first row, Unix ms (the date in the title, the
    /// origin of the UTC axis).
    pub t0_unix_ms: Option<u64>,
    /// The node's unique id (from a `hello` or `link_up` row).
    pub node_id: Option<String>,
}

/// The time axis of `plot`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum TimeAxis {
    /// Host clock as UTC time of day (survives node restarts).
    #[default]
    Host,
    /// Node uptime (the virtual time of a virtual node; restarts start over).
    Node,
}

fn medium_named(s: &str) -> Option<&'static str> {
    ["dry", "water", "glazed", "rime"]
        .into_iter()
        .find(|m| *m == s.trim())
}

/// Extract the time series from a foisctl log, row by row (logs of any
/// foisctl version: columns are found by name; temperature, state and the
/// estimate are optional).
pub fn time_series(path: &Path, axis: TimeAxis) -> anyhow::Result<TimeSeries> {
    let mut rd = LogReader::open(path)?;
    let need = |rd: &LogReader, name: &str| {
        rd.need(name)
            .with_context(|| format!("is {} a foisctl log?", path.display()))
    };
    let (host_ms, up_ms, kind, i1, i2, alarm) = (
        need(&rd, "host_unix_ms")?,
        need(&rd, "uptime_ms")?,
        need(&rd, "kind")?,
        need(&rd, "i1_ua")?,
        need(&rd, "i2_ua")?,
        need(&rd, "alarm")?,
    );
    let col = |name: &str| rd.col(name);
    let (valid, seq_col, temp, state, detail, medium) = (
        col("valid"),
        col("seq"),
        col("temperature_c"),
        col("state"),
        col("detail"),
        col("est_kind"),
    );
    let est = col("est_thickness_mm").zip(col("est_sigma_mm"));
    let num = |s: &str| s.trim().parse::<f64>().ok().filter(|x| x.is_finite());
    let mut out = TimeSeries::default();
    let mut r = csv::StringRecord::new();
    let mut last_uptime_s: Option<f64> = None;
    while rd.next_row(&mut r)? {
        let host = num(&r[host_ms]);
        if out.t0_unix_ms.is_none() {
            out.t0_unix_ms = host.map(|h| h as u64);
        }
        let t0 = out.t0_unix_ms.map_or(0.0, |t| t as f64);
        let t_s = match axis {
            TimeAxis::Host => host.map(|h| (h - t0) / 1000.0),
            // Rows without an uptime (link changes) sit at the last one.
            TimeAxis::Node => num(&r[up_ms]).map(|u| u / 1000.0).or(last_uptime_s),
        };
        let kind = &r[kind];
        if matches!(kind, "hello" | "link_up")
            && out.node_id.is_none()
            && let Some(d) = detail
        {
            out.node_id = r[d]
                .split_whitespace()
                .find_map(|w| w.strip_prefix("id="))
                .map(str::to_string);
        }
        let Some(t_s) = t_s else { continue };
        match kind {
            "measurement" => {
                last_uptime_s = Some(t_s).filter(|_| axis == TimeAxis::Node);
                if valid.is_some_and(|v| r[v].trim() == "0") {
                    continue;
                }
                if let (Some(a), Some(b)) = (num(&r[i1]), num(&r[i2])) {
                    out.points.push(TimePoint {
                        t_s,
                        seq: seq_col.and_then(|c| r[c].trim().parse().ok()),
                        i_ua: [a, b],
                        alarm: r[alarm].trim() == "1",
                        est_mm: est.and_then(|(d, s)| num(&r[d]).zip(num(&r[s]))),
                        temp_c: temp.and_then(|c| num(&r[c])),
                        state: state.and_then(|c| State::parse(&r[c])),
                        medium: medium.and_then(|c| medium_named(&r[c])),
                    });
                }
            }
            "gap" | "link_lost" | "node_restart" => out.breaks_s.push(t_s),
            _ => {}
        }
    }
    out.breaks_s.sort_by(f64::total_cmp);
    Ok(out)
}
