//! `foisctl estimate`: replay a CSV's rows, in order, as consecutive frames
//! through the node's own ice estimator (`fois_firmware::estimator`, the
//! same code the node runs) and write the file again with the estimate
//! appended.
//!
//! Two inputs are understood, told apart by their header:
//!
//! - a **monitor log** (`foisctl monitor --log`; columns `kind`, `uptime_ms`,
//!   `i1_ua`, `i2_ua`, `temperature_c`, `valid`): each `measurement` row is a
//!   frame, Δt from `uptime_ms`. The log holds the node's net currents, not
//!   its dark baseline, so the baseline is `--baseline-ua` (default 0, 0)
//!   until a `DarkCalibrated` answer in the log sets it (and the estimator
//!   to dry, as on the node). An empty `temperature_c` is a failed NTC (no
//!   temperature evidence); `valid` 0 a saturated frame (predict only).
//!   Other rows are copied with empty estimate columns. A log of a v2 node
//!   already has the node's `est_*` columns: they are kept, renamed
//!   `node_est_*`, so the node's and the replay's estimates sit side by side.
//! - a **`sim curve` CSV** (`thickness_mm,i1_ua,i2_ua`, optionally `run`):
//!   one accretion, rows in order of growing thickness, each a frame; Δt is
//!   the thickness step at `--rate-mm-per-h` (rows 0.1 mm apart at the
//!   default 2 mm/h are frames 180 s apart), the air at `--temperature-c`.
//!   A new `run` starts the estimator afresh.
//!
//! Appended columns: `est_thickness_mm`, `est_sigma_mm`, `est_kind`,
//! `est_p`, `est_gain`, `est_gain_sigma` (as the log's: the optical gain
//! against the response table's and its standard deviation; the replay
//! applies no temperature model: a log holds the air's temperature, not the
//! optics'), `est_rate_mm_per_h`, `est_rate_sigma_mm_per_h`, `est_accreting`
//! (as the log's: the icing rate now ± σ, mm/h, and the icing period 0/1 —
//! the node's growth history, so a replay of sparse rows, e.g. a `sim
//! curve` 180 s apart, updates it at every row) and `est_update`: what the
//! frame did —
//! `initialised`, `measured`, `waiting`, `no_currents` (a saturated row, or
//! currents that are not finite numbers or beyond ±10 mA: predicted only),
//! `outlier` (currents no state explains: predicted only), `restart` (the
//! node's uptime went back, or a new run: the estimator starts afresh). The
//! estimator updates once per second of frames on their robust mean, as on
//! the node: `est_update` is the last update's. The gain starts unknown
//! (1 ± 30 %) unless `--gain` gives a calibrated one.
//!
//! Errors (nothing written, the input never touched): an empty file, a
//! header without the needed columns, no frame rows, a `sim curve` whose
//! thickness does not grow (rows out of order) or is not a finite number
//! ≥ 0. The output is written to a temporary file beside `--out` and renamed
//! at the end, so an interrupted run leaves no half file.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use csv::StringRecord;
use fois_firmware::estimator::{Estimator, EstimatorParams, Update};

use crate::csvlog::LogReader;

/// The appended columns.
pub const EST_COLUMNS: [&str; 10] = [
    "est_thickness_mm",
    "est_sigma_mm",
    "est_kind",
    "est_p",
    "est_gain",
    "est_gain_sigma",
    "est_rate_mm_per_h",
    "est_rate_sigma_mm_per_h",
    "est_accreting",
    "est_update",
];

/// How to read a `sim curve` CSV (a log carries its own time and
/// temperature).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurveTiming {
    /// Growth rate that turns the thickness steps into frame periods, mm/h.
    pub rate_mm_per_h: f64,
    /// Air temperature, °C.
    pub temperature_c: f64,
}

impl Default for CurveTiming {
    fn default() -> Self {
        CurveTiming {
            rate_mm_per_h: 2.0,
            temperature_c: -5.0,
        }
    }
}

/// What the replay is told besides the file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReplayOptions {
    /// For `sim curve` files.
    pub curve: CurveTiming,
    /// The node's dark baseline (I1, I2), µA, until the log's own
    /// `DarkCalibrated` answer (logs only).
    pub baseline_ua: [f64; 2],
    /// The estimator's settings.
    pub params: EstimatorParams,
    /// A calibrated gain (gain, relative sd); `None`: unknown.
    pub gain_prior: Option<(f32, f32)>,
}

impl Default for ReplayOptions {
    fn default() -> Self {
        ReplayOptions {
            curve: CurveTiming::default(),
            baseline_ua: [0.0, 0.0],
            params: EstimatorParams::default(),
            gain_prior: None,
        }
    }
}

/// Totals of a replay.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReplaySummary {
    /// Which input it was (`monitor log` or `sim curve`).
    pub input_kind: &'static str,
    /// Rows written (every input row).
    pub rows: u64,
    /// Rows replayed as frames.
    pub frames: u64,
    /// Frames predicted only (invalid, not numbers, out of range).
    pub no_currents: u64,
    /// Frames the estimator took for outliers.
    pub outliers: u64,
    /// Estimator restarts (node restarts, new runs).
    pub restarts: u64,
    /// The last estimate as the monitor shows it.
    pub last: Option<String>,
}

/// The columns of a monitor log the replay reads.
#[derive(Clone, Copy)]
struct LogCols {
    kind: usize,
    uptime: usize,
    i: [usize; 2],
    temp: Option<usize>,
    valid: Option<usize>,
    detail: Option<usize>,
}

/// The layout of the input.
enum Layout {
    Log(LogCols),
    Curve {
        thickness: usize,
        i: [usize; 2],
        run: Option<usize>,
    },
}

fn layout(rd: &LogReader) -> anyhow::Result<Layout> {
    if rd.col("kind").is_some() && rd.col("uptime_ms").is_some() {
        Ok(Layout::Log(LogCols {
            kind: rd.need("kind")?,
            uptime: rd.need("uptime_ms")?,
            i: [rd.need("i1_ua")?, rd.need("i2_ua")?],
            temp: rd.col("temperature_c"),
            valid: rd.col("valid"),
            detail: rd.col("detail"),
        }))
    } else if rd.col("thickness_mm").is_some() {
        Ok(Layout::Curve {
            thickness: rd.need("thickness_mm")?,
            i: [rd.need("i1_ua")?, rd.need("i2_ua")?],
            run: rd.col("run"),
        })
    } else {
        bail!(
            "neither a monitor log (columns kind, uptime_ms, i1_ua, i2_ua) nor a `sim curve` \
             CSV (columns thickness_mm, i1_ua, i2_ua); its columns: {}",
            rd.header().join(", ")
        )
    }
}

/// A text field as a number (`None` when empty; NaN when not a number, so
/// the frame is flagged instead of the file refused).
fn number(field: &str) -> Option<f64> {
    let t = field.trim();
    (!t.is_empty()).then(|| t.parse::<f64>().unwrap_or(f64::NAN))
}

/// `DarkCalibrated i1_ua=0.123 i2_ua=0.045` in an answer's detail.
fn dark_baseline(detail: &str) -> Option<[f64; 2]> {
    let rest = detail.split("DarkCalibrated").nth(1)?;
    let mut out = [None, None];
    for word in rest.split_whitespace() {
        if let Some(v) = word.strip_prefix("i1_ua=") {
            out[0] = v.parse::<f64>().ok().filter(|v| v.is_finite());
        } else if let Some(v) = word.strip_prefix("i2_ua=") {
            out[1] = v.parse::<f64>().ok().filter(|v| v.is_finite());
        }
    }
    Some([out[0]?, out[1]?])
}

fn update_name(u: Update) -> &'static str {
    match u {
        Update::Waiting => "waiting",
        Update::Initialised => "initialised",
        Update::Measured => "measured",
        Update::NoCurrents => "no_currents",
        Update::Outlier => "outlier",
    }
}

/// Currents in µA as the estimator takes them: `None` unless both are
/// present (a row with an empty current is predicted only).
fn currents(a: Option<f64>, b: Option<f64>) -> Option<[f32; 2]> {
    Some([a? as f32, b? as f32])
}

/// The replay itself, row by row; `emit` gets each input row's fields and
/// the appended ones.
struct Replay {
    est: Estimator,
    sum: ReplaySummary,
    baseline_ua: [f64; 2],
    last_uptime_ms: Option<f64>,
    last_thickness_mm: Option<f64>,
    last_run: Option<String>,
    gain_prior: Option<(f32, f32)>,
}

impl Replay {
    fn frame(
        &mut self,
        dt_s: f64,
        x: Option<[f32; 2]>,
        temp_c: Option<f64>,
        restarted: bool,
    ) -> [String; 10] {
        let e = self.est.step(dt_s as f32, x, temp_c.map(|t| t as f32));
        self.sum.frames += 1;
        let update = self.est.last_update();
        match update {
            Update::NoCurrents => self.sum.no_currents += 1,
            Update::Outlier => self.sum.outliers += 1,
            _ => {}
        }
        let what = if restarted {
            "restart"
        } else {
            update_name(update)
        };
        let gain = self.est.gain();
        let icing = self.est.icing_estimate();
        match e {
            Some(e) => {
                let mut last = crate::text::estimate_text(&e);
                if let Some(i) = &icing {
                    last = format!("{last}, {}", crate::text::icing_text(i));
                }
                self.sum.last = Some(last);
                [
                    format!("{:.3}", f64::from(e.thickness_um) / 1000.0),
                    format!("{:.3}", f64::from(e.sigma_um) / 1000.0),
                    e.medium.name().to_string(),
                    format!("{:.3}", f64::from(e.probability_permille) / 1000.0),
                    gain.map_or(String::new(), |g| format!("{:.3}", g.gain)),
                    gain.map_or(String::new(), |g| format!("{:.3}", g.gain * g.sigma)),
                    icing.map_or(String::new(), |i| {
                        format!("{:.3}", f64::from(i.rate_um_per_h) / 1000.0)
                    }),
                    icing.map_or(String::new(), |i| {
                        format!("{:.3}", f64::from(i.sigma_um_per_h) / 1000.0)
                    }),
                    icing.map_or(String::new(), |i| u8::from(i.accreting).to_string()),
                    what.to_string(),
                ]
            }
            None => std::array::from_fn(|k| {
                if k == EST_COLUMNS.len() - 1 {
                    what.to_string()
                } else {
                    String::new()
                }
            }),
        }
    }

    fn restart(&mut self) {
        self.est.reset();
        self.sum.restarts += 1;
    }

    fn log_row(&mut self, f: &StringRecord, c: LogCols) -> Option<[String; 10]> {
        let LogCols {
            kind,
            uptime,
            i,
            temp,
            valid,
            detail,
        } = c;
        if let Some(b) = detail
            .filter(|_| &f[kind] == "ack")
            .and_then(|d| dark_baseline(&f[d]))
        {
            self.baseline_ua = b;
            // As the node: the gain back to its calibration (or unknown),
            // the face dry.
            match self.gain_prior {
                Some((g, sd)) => self.est.set_gain_prior(g, sd),
                None => self.est.reset_gain(),
            }
            self.est.set_dry();
            return None;
        }
        if &f[kind] != "measurement" {
            return None;
        }
        let up = number(&f[uptime]).filter(|u| u.is_finite() && *u >= 0.0);
        let mut restarted = false;
        let dt_s = match (up, self.last_uptime_ms) {
            (Some(u), Some(last)) if u < last => {
                self.restart();
                restarted = true;
                0.0
            }
            (Some(u), Some(last)) => (u - last) / 1000.0,
            _ => 0.0,
        };
        if up.is_some() {
            self.last_uptime_ms = up;
        }
        let ok = valid.is_none_or(|v| f[v].trim() != "0");
        let x = currents(
            number(&f[i[0]]).map(|v| v - self.baseline_ua[0]),
            number(&f[i[1]]).map(|v| v - self.baseline_ua[1]),
        )
        .filter(|_| ok);
        let temp_c = temp.and_then(|t| number(&f[t]));
        Some(self.frame(dt_s, x, temp_c, restarted))
    }

    fn curve_row(
        &mut self,
        f: &StringRecord,
        line: u64,
        thickness: usize,
        i: [usize; 2],
        run: Option<usize>,
        timing: CurveTiming,
    ) -> anyhow::Result<[String; 10]> {
        let mut restarted = false;
        if let Some(r) = run {
            let this = f[r].trim().to_string();
            if self.last_run.as_ref().is_some_and(|last| *last != this) {
                self.restart();
                self.last_thickness_mm = None;
                restarted = true;
            }
            self.last_run = Some(this);
        }
        let d = number(&f[thickness])
            .filter(|d| d.is_finite() && *d >= 0.0)
            .with_context(|| {
                format!(
                    "line {line}: thickness_mm `{}` is not a thickness (a finite number ≥ 0 mm)",
                    &f[thickness]
                )
            })?;
        let dt_s = match self.last_thickness_mm {
            Some(last) if d <= last => bail!(
                "line {line}: thickness_mm {d} does not grow (the row before had {last}): \
                 rows out of order; a `sim curve` file is replayed as one growing accretion"
            ),
            Some(last) => (d - last) / timing.rate_mm_per_h * 3600.0,
            None => 0.0,
        };
        self.last_thickness_mm = Some(d);
        let x = currents(number(&f[i[0]]), number(&f[i[1]]));
        Ok(self.frame(dt_s, x, Some(timing.temperature_c), restarted))
    }
}

/// Replay `input` into `out` (see the module doc). `progress` is called
/// with the number of rows done every 4096 rows.
pub fn replay(
    input: &Path,
    out: &Path,
    opts: &ReplayOptions,
    mut progress: impl FnMut(u64),
) -> anyhow::Result<ReplaySummary> {
    let mut rd = LogReader::open(input)?;
    let layout = layout(&rd)?;
    let mut header: Vec<String> = rd.header().to_vec();
    if matches!(layout, Layout::Log(_)) {
        for h in &mut header {
            if h.starts_with("est_") {
                *h = format!("node_{h}");
            }
        }
    }
    if let Some(dup) = header.iter().find(|h| EST_COLUMNS.contains(&h.as_str())) {
        bail!("{} already has a column `{dup}`", input.display());
    }
    header.extend(EST_COLUMNS.iter().map(|s| s.to_string()));

    let tmp = temp_path(out);
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_path(&tmp)
        .with_context(|| format!("cannot write {}", tmp.display()))?;
    let result = (|| -> anyhow::Result<ReplaySummary> {
        w.write_record(&header)?;
        let mut est = Estimator::new(opts.params);
        if let Some((g, sd)) = opts.gain_prior {
            est.set_gain_prior(g, sd);
        }
        let mut r = Replay {
            est,
            sum: ReplaySummary {
                input_kind: match layout {
                    Layout::Log(_) => "monitor log",
                    Layout::Curve { .. } => "sim curve",
                },
                ..ReplaySummary::default()
            },
            baseline_ua: opts.baseline_ua,
            last_uptime_ms: None,
            last_thickness_mm: None,
            last_run: None,
            gain_prior: opts.gain_prior,
        };
        let mut fields = StringRecord::new();
        let mut line = 1u64;
        let empty = || std::array::from_fn::<String, 10, _>(|_| String::new());
        while rd.next_row(&mut fields)? {
            line += 1;
            let est = match layout {
                Layout::Log(c) => r.log_row(&fields, c).unwrap_or_else(empty),
                Layout::Curve { thickness, i, run } => {
                    r.curve_row(&fields, line, thickness, i, run, opts.curve)?
                }
            };
            w.write_record(fields.iter().chain(est.iter().map(String::as_str)))?;
            r.sum.rows += 1;
            if r.sum.rows.is_multiple_of(4096) {
                progress(r.sum.rows);
            }
        }
        if r.sum.frames == 0 {
            bail!(
                "{} holds no frames to replay (no measurement rows / no curve rows)",
                input.display()
            );
        }
        w.flush()?;
        Ok(r.sum)
    })();
    drop(w);
    match result {
        Ok(sum) => {
            std::fs::rename(&tmp, out)
                .with_context(|| format!("cannot move {} to {}", tmp.display(), out.display()))?;
            Ok(sum)
        }
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e.context(format!("{}: nothing written", input.display())))
        }
    }
}

/// `out` with `.partial` appended (same directory, so the rename is atomic).
fn temp_path(out: &Path) -> PathBuf {
    let mut name = out.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    out.with_file_name(name)
}

/// Whether two paths name the same file (the same path, or both existing
/// and the same after resolving links and `..`).
pub fn same_file(a: &Path, b: &Path) -> bool {
    if a == b {
        return true;
    }
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dark_baseline_is_read_from_the_answer_text() {
        assert_eq!(
            dark_baseline("id=3 DarkCalibrated i1_ua=0.125 i2_ua=-0.040"),
            Some([0.125, -0.040])
        );
        assert_eq!(dark_baseline("id=3 Stopped"), None);
        assert_eq!(dark_baseline("id=3 DarkCalibrated i1_ua=x i2_ua=1"), None);
    }

    #[test]
    fn numbers_empty_and_garbage() {
        assert_eq!(number(" 1.5 "), Some(1.5));
        assert_eq!(number(""), None);
        assert!(number("abc").is_some_and(f64::is_nan));
        assert!(number("inf").is_some_and(f64::is_infinite));
    }
}
