//! The icing report of one node's logs: the files put in time order,
//! streamed through one [`Tracker`], and the totals, shares and IEA class
//! worked out from its findings.

use std::path::PathBuf;

use super::events::{Findings, IcingEvent, MetSources, MonthTotals, Thresholds, Tracker};
use super::iea::{class_of_meteorological, classes_of_instrumental};
use super::input::{FileStats, LogSamples};

/// The report.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    /// What each file held.
    pub files: Vec<FileStats>,
    /// The event definitions' thresholds.
    pub thresholds: Thresholds,
    /// Measurements read.
    pub measurements: u64,
    /// The first measurement, Unix ms.
    pub first_ms: Option<u64>,
    /// The last measurement, Unix ms.
    pub last_ms: Option<u64>,
    /// Hours with data.
    pub covered_h: f64,
    /// Hours in gaps (no data).
    pub gap_h: f64,
    /// Hours of meteorological icing.
    pub meteorological_h: f64,
    /// Hours of instrumental icing.
    pub instrumental_h: f64,
    /// Meteorological icing, % of the covered time.
    pub meteorological_pct: f64,
    /// Instrumental icing, % of the covered time.
    pub instrumental_pct: f64,
    /// The IEA Wind ice class the meteorological share implies.
    pub iea_class: u8,
    /// The classes whose instrumental range holds the instrumental share.
    pub iea_instrumental_classes: Vec<u8>,
    /// Where meteorological icing came from (samples).
    pub meteorological_source: MetSources,
    /// The events.
    pub events: Vec<IcingEvent>,
    /// Per-month totals.
    pub months: Vec<MonthTotals>,
    /// Periods of meteorological icing (for the figure).
    #[serde(skip)]
    pub met_periods: Vec<(u64, u64)>,
    /// Periods of instrumental icing (for the figure).
    #[serde(skip)]
    pub instr_periods: Vec<(u64, u64)>,
    /// The decimated thickness series (for the figure).
    #[serde(skip)]
    pub timeline: super::timeline::Timeline,
}

impl Report {
    /// A sentence on where meteorological icing came from.
    pub fn source_text(&self) -> &'static str {
        let s = self.meteorological_source;
        match (s.node > 0, s.derived > 0) {
            (true, false) => "the node's est_accreting",
            (false, true) => {
                "derived from the thickness series' growth (the logs have no est_accreting column)"
            }
            (true, true) => "the node's est_accreting where logged, else derived from the growth",
            (false, false) => "unavailable (the logs have no thickness estimate)",
        }
    }

    /// Less than 365 days between the first and the last measurement.
    pub fn shorter_than_a_year(&self) -> bool {
        match (self.first_ms, self.last_ms) {
            (Some(a), Some(b)) => b - a < 365 * 86_400_000,
            _ => true,
        }
    }
}

/// Stream `sources` (in time order) through one pass.
pub fn analyse_sources(
    sources: impl IntoIterator<Item = anyhow::Result<LogSamples>>,
    th: Thresholds,
) -> anyhow::Result<Report> {
    let mut tracker = Tracker::new(th);
    let mut files = Vec::new();
    let mut last_t: Option<u64> = None;
    for src in sources {
        let mut src = src?;
        while let Some(s) = src.next_sample()? {
            if last_t.is_some_and(|l| s.t_ms < l) {
                // Overlaps the previous file.
                src.stats.out_of_order += 1;
                src.stats.measurements -= 1;
                continue;
            }
            last_t = Some(s.t_ms);
            tracker.push(s);
        }
        files.push(src.stats);
    }
    Ok(summarise(tracker.finish(), files, th))
}

/// The report of a node's log files: plain or gzip-compressed, in any
/// order on the command line (sorted by their first measurement).
pub fn analyse(paths: &[PathBuf], th: Thresholds) -> anyhow::Result<Report> {
    let mut ordered = Vec::with_capacity(paths.len());
    for p in paths {
        ordered.push((LogSamples::first_time(p)?, p));
    }
    ordered.sort_by_key(|&(t, _)| t);
    analyse_sources(ordered.into_iter().map(|(_, p)| LogSamples::open(p)), th)
}

fn summarise(f: Findings, files: Vec<FileStats>, th: Thresholds) -> Report {
    let sum = |g: fn(&MonthTotals) -> f64| f.months.iter().map(g).sum::<f64>();
    let covered_h = sum(|m| m.covered_h);
    let met_h = sum(|m| m.meteorological_h);
    let instr_h = sum(|m| m.instrumental_h);
    let pct = |h: f64| {
        if covered_h > 0.0 {
            100.0 * h / covered_h
        } else {
            0.0
        }
    };
    Report {
        measurements: files.iter().map(|s| s.measurements).sum(),
        files,
        thresholds: th,
        first_ms: f.span_ms.map(|s| s.0),
        last_ms: f.span_ms.map(|s| s.1),
        covered_h,
        gap_h: sum(|m| m.gap_h),
        meteorological_h: met_h,
        instrumental_h: instr_h,
        meteorological_pct: pct(met_h),
        instrumental_pct: pct(instr_h),
        iea_class: class_of_meteorological(pct(met_h)).class,
        iea_instrumental_classes: classes_of_instrumental(pct(instr_h)),
        meteorological_source: f.sources,
        events: f.events,
        months: f.months,
        met_periods: f.met_periods,
        instr_periods: f.instr_periods,
        timeline: f.timeline,
    }
}
