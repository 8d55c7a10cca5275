//! `foisctl icing-report`: icing events, monthly totals, the share of the
//! period with meteorological and instrumental icing and the IEA Wind ice
//! class it implies, from monitor or gateway logs (plain or `.csv.gz`),
//! streamed in one pass with bounded memory.
//!
//! | module | what lives there |
//! | --- | --- |
//! | [`input`] | the logs read row by row (gzip told by its magic bytes), the report's columns, errors naming file and line |
//! | [`events`] | the definitions with hysteresis: meteorological and instrumental icing, events, gaps, per-month sums |
//! | [`timeline`] | the thickness series decimated for the figure (bounded buckets) |
//! | [`iea`] | the IEA Wind Task 19 ice classes |
//! | [`report`] | files in time order through one pass; totals, shares, class |
//! | [`render`] | the readable table, the events as CSV, the report as JSON |
//! | [`synthetic`] | synthetic logs of known icing: the benchmark's year, the tests |
//!
//! The figure is [`crate::plot::icing`].

pub mod events;
pub mod iea;
pub mod input;
pub mod render;
pub mod report;
pub mod synthetic;
pub mod timeline;

#[cfg(test)]
mod tests;

use std::time::Instant;

use events::Thresholds;
use input::LogSamples;
use synthetic::SyntheticLog;

/// What the benchmark measured.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchResult {
    /// Rows read.
    pub rows: u64,
    /// Bytes of CSV text.
    pub bytes: u64,
    /// Wall time, s.
    pub seconds: f64,
    /// Events found.
    pub events: usize,
    /// Meteorological icing, hours.
    pub meteorological_h: f64,
    /// The process's peak resident memory, KiB (Linux; None elsewhere).
    pub peak_rss_kib: Option<u64>,
}

impl BenchResult {
    /// Rows per second.
    pub fn rows_per_s(&self) -> f64 {
        self.rows as f64 / self.seconds.max(1e-9)
    }
}

/// Counts the bytes passing through.
struct Counted<R> {
    inner: R,
    bytes: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl<R: std::io::Read> std::io::Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.bytes
            .fetch_add(n as u64, std::sync::atomic::Ordering::Relaxed);
        Ok(n)
    }
}

/// The peak resident memory of this process, KiB (`VmHWM`, Linux).
pub fn peak_rss_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Run the report over `days` synthetic days at 1 Hz (an icing day every
/// 10th), generated on the fly, on this thread; time it.
pub fn bench(days: u64) -> anyhow::Result<BenchResult> {
    let bytes = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let log = Counted {
        inner: SyntheticLog::new(days, 1, 10, true),
        bytes: bytes.clone(),
    };
    let start = Instant::now();
    let src = LogSamples::from_reader(
        "synthetic year",
        Box::new(log),
        std::path::Path::new("synthetic"),
    );
    let r = report::analyse_sources([src], Thresholds::default())?;
    let seconds = start.elapsed().as_secs_f64();
    Ok(BenchResult {
        rows: r.measurements,
        bytes: bytes.load(std::sync::atomic::Ordering::Relaxed),
        seconds,
        events: r.events.len(),
        meteorological_h: r.meteorological_h,
        peak_rss_kib: peak_rss_kib(),
    })
}
