//! The icing report's input: monitor logs (and the gateway's daily logs,
//! plain or gzip-compressed) read row by row, only the columns the report
//! needs, into [`Sample`]s. Nothing of a file is kept: a year at 1 Hz
//! streams through in bounded memory.
//!
//! Columns are found by name, so logs of every foisctl version read: with
//! the node's icing-rate columns (`est_rate_mm_per_h`,
//! `est_rate_sigma_mm_per_h`, `est_accreting`) and without them (older
//! logs: meteorological icing is then derived from the thickness series,
//! [`super::events`]).

use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use anyhow::Context;
use csv::ByteRecord;

use crate::csvlog::LastByte;

/// The medium the node names most likely (`est_kind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Medium {
    /// No estimate in the row.
    #[default]
    Unknown,
    /// A dry face.
    Dry,
    /// Liquid water.
    Water,
    /// Glazed (clear) ice.
    Glazed,
    /// Rime.
    Rime,
}

impl Medium {
    fn parse(b: &[u8]) -> Medium {
        match b {
            b"dry" => Medium::Dry,
            b"water" => Medium::Water,
            b"glazed" => Medium::Glazed,
            b"rime" => Medium::Rime,
            _ => Medium::Unknown,
        }
    }

    /// Glazed or rime.
    pub fn is_ice(self) -> bool {
        matches!(self, Medium::Glazed | Medium::Rime)
    }

    /// Its name in the log.
    pub fn name(self) -> &'static str {
        match self {
            Medium::Unknown => "-",
            Medium::Dry => "dry",
            Medium::Water => "water",
            Medium::Glazed => "glazed",
            Medium::Rime => "rime",
        }
    }
}

/// One measurement row, the report's columns only.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    /// Host time, Unix ms.
    pub t_ms: u64,
    /// The node's detector state is `Ice`.
    pub state_ice: bool,
    /// The node's thickness estimate, mm (None: a node without estimates).
    pub thickness_mm: Option<f64>,
    /// Its standard deviation, mm.
    pub sigma_mm: Option<f64>,
    /// The most likely medium.
    pub medium: Medium,
    /// The node's icing rate, mm/h (None: an older log or node).
    pub rate_mm_per_h: Option<f64>,
    /// Its standard deviation, mm/h.
    pub rate_sigma_mm_per_h: Option<f64>,
    /// The node's meteorological icing: `est_accreting` ≥ 0.5 (a
    /// probability or a 0/1 flag).
    pub accreting: Option<bool>,
}

/// What a file held besides its samples.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct FileStats {
    /// The file.
    pub path: PathBuf,
    /// Measurement rows read.
    pub measurements: u64,
    /// Rows of another width skipped (a line cut by a killed logger and
    /// continued by the next run).
    pub short_rows: u64,
    /// The last line was cut short (a logger still writing or killed):
    /// ignored.
    pub cut_last_line: bool,
    /// Measurement rows older than the one before (out of order): skipped.
    pub out_of_order: u64,
    /// Frames the node's sequence numbers say were lost (`gap` rows).
    pub frames_lost: u64,
    /// The file has the node's icing-rate columns.
    pub has_rate: bool,
    /// The file has the node's thickness estimate.
    pub has_estimate: bool,
}

#[derive(Debug, Clone, Copy)]
struct Columns {
    t: usize,
    kind: usize,
    state: Option<usize>,
    thickness: Option<usize>,
    sigma: Option<usize>,
    medium: Option<usize>,
    rate: Option<usize>,
    rate_sigma: Option<usize>,
    accreting: Option<usize>,
    frames_lost: Option<usize>,
}

/// Streams the samples of one log.
pub struct LogSamples {
    name: String,
    reader: csv::Reader<LastByte<Box<dyn Read>>>,
    cols: Columns,
    width: usize,
    ahead: ByteRecord,
    have_ahead: bool,
    row: ByteRecord,
    last_t: Option<u64>,
    /// What the file held so far.
    pub stats: FileStats,
}

/// True when the file starts with gzip's magic bytes.
fn is_gzip(path: &Path) -> std::io::Result<bool> {
    let mut magic = [0u8; 2];
    let mut f = File::open(path)?;
    let n = f.read(&mut magic)?;
    Ok(n == 2 && magic == [0x1f, 0x8b])
}

impl LogSamples {
    /// Open a log (gzip-compressed or not, told by its first bytes) and read
    /// its header.
    pub fn open(path: &Path) -> anyhow::Result<LogSamples> {
        let name = path.display().to_string();
        let gz = is_gzip(path).with_context(|| format!("cannot read log {name}"))?;
        let file = File::open(path).with_context(|| format!("cannot read log {name}"))?;
        let inner: Box<dyn Read> = if gz {
            Box::new(flate2::read::MultiGzDecoder::new(BufReader::with_capacity(
                1 << 16,
                file,
            )))
        } else {
            Box::new(file)
        };
        Self::from_reader(&name, inner, path)
    }

    /// Read a log from any byte stream (`name` is how errors name it).
    pub fn from_reader(
        name: &str,
        inner: Box<dyn Read>,
        path: &Path,
    ) -> anyhow::Result<LogSamples> {
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .buffer_capacity(1 << 17)
            .from_reader(LastByte { inner, last: None });
        let mut header = ByteRecord::new();
        let got = reader
            .read_byte_record(&mut header)
            .with_context(|| format!("{name}, line 1: cannot read the header"))?;
        if !got {
            anyhow::bail!("log {name} is empty");
        }
        let col = |n: &str| header.iter().position(|c| c == n.as_bytes());
        let need = |n: &str| {
            col(n).ok_or_else(|| {
                anyhow::anyhow!(
                    "{name}, line 1: no column `{n}`: not a foisctl monitor or gateway log (columns: {})",
                    header
                        .iter()
                        .map(String::from_utf8_lossy)
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })
        };
        let cols = Columns {
            t: need("host_unix_ms")?,
            kind: need("kind")?,
            state: col("state"),
            thickness: col("est_thickness_mm"),
            sigma: col("est_sigma_mm"),
            medium: col("est_kind"),
            rate: col("est_rate_mm_per_h"),
            rate_sigma: col("est_rate_sigma_mm_per_h"),
            accreting: col("est_accreting"),
            frames_lost: col("frames_lost"),
        };
        let stats = FileStats {
            path: path.to_path_buf(),
            has_rate: cols.rate.is_some() && cols.accreting.is_some(),
            has_estimate: cols.thickness.is_some(),
            ..FileStats::default()
        };
        let mut s = LogSamples {
            name: name.to_string(),
            reader,
            cols,
            width: header.len(),
            ahead: ByteRecord::new(),
            have_ahead: false,
            row: ByteRecord::new(),
            last_t: None,
            stats,
        };
        s.have_ahead = s.read_ahead()?;
        Ok(s)
    }

    fn read_ahead(&mut self) -> anyhow::Result<bool> {
        let name = &self.name;
        self.reader.read_byte_record(&mut self.ahead).map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            anyhow::anyhow!("{name}, line {line}: {e}")
        })
    }

    /// The next measurement, `None` at the end. A row that is not a
    /// measurement is skipped (a `gap` row's frames counted); a
    /// measurement whose time or estimate is not a number is an error
    /// naming the file and the line.
    pub fn next_sample(&mut self) -> anyhow::Result<Option<Sample>> {
        while self.have_ahead {
            std::mem::swap(&mut self.row, &mut self.ahead);
            self.have_ahead = self.read_ahead()?;
            if !self.have_ahead && self.reader.get_ref().last != Some(b'\n') {
                self.stats.cut_last_line = true;
                return Ok(None);
            }
            if self.row.len() != self.width {
                self.stats.short_rows += 1;
                continue;
            }
            let c = self.cols;
            let kind = &self.row[c.kind];
            if kind == b"gap" {
                if let Some(i) = c.frames_lost {
                    self.stats.frames_lost += parse_u64(&self.row[i]).unwrap_or(0);
                }
                continue;
            }
            if kind != b"measurement" {
                continue;
            }
            let line = || self.row.position().map_or(0, |p| p.line());
            let bad = |what: &str, v: &[u8]| {
                anyhow::anyhow!(
                    "{}, line {}: {what} `{}` is not a number",
                    self.name,
                    line(),
                    String::from_utf8_lossy(v)
                )
            };
            let t_raw = &self.row[c.t];
            let t_ms = parse_u64(t_raw).ok_or_else(|| bad("host_unix_ms", t_raw))?;
            let num = |i: Option<usize>, what: &str| -> anyhow::Result<Option<f64>> {
                match i.map(|i| &self.row[i]) {
                    None => Ok(None),
                    Some(b"") => Ok(None),
                    Some(v) => parse_f64(v).map(Some).ok_or_else(|| bad(what, v)),
                }
            };
            let sample = Sample {
                t_ms,
                state_ice: c.state.is_some_and(|i| &self.row[i] == b"Ice"),
                thickness_mm: num(c.thickness, "est_thickness_mm")?,
                sigma_mm: num(c.sigma, "est_sigma_mm")?,
                medium: c
                    .medium
                    .map_or(Medium::Unknown, |i| Medium::parse(&self.row[i])),
                rate_mm_per_h: num(c.rate, "est_rate_mm_per_h")?,
                rate_sigma_mm_per_h: num(c.rate_sigma, "est_rate_sigma_mm_per_h")?,
                accreting: num(c.accreting, "est_accreting")?.map(|p| p >= 0.5),
            };
            if self.last_t.is_some_and(|l| t_ms < l) {
                self.stats.out_of_order += 1;
                continue;
            }
            self.last_t = Some(t_ms);
            self.stats.measurements += 1;
            return Ok(Some(sample));
        }
        Ok(None)
    }

    /// The first measurement's time (opens the file a second time; to put
    /// files in order).
    pub fn first_time(path: &Path) -> anyhow::Result<Option<u64>> {
        LogSamples::open(path)?
            .next_sample()
            .map(|s| s.map(|s| s.t_ms))
    }
}

fn parse_u64(b: &[u8]) -> Option<u64> {
    if b.is_empty() || b.len() > 19 {
        return None;
    }
    b.iter().try_fold(0u64, |acc, &d| {
        d.is_ascii_digit().then(|| acc * 10 + u64::from(d - b'0'))
    })
}

fn parse_f64(b: &[u8]) -> Option<f64> {
    std::str::from_utf8(b)
        .ok()?
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_parse_strictly() {
        assert_eq!(parse_u64(b"1735689600000"), Some(1_735_689_600_000));
        assert_eq!(parse_u64(b"12a"), None);
        assert_eq!(parse_u64(b""), None);
        assert_eq!(parse_f64(b"-0.125"), Some(-0.125));
        assert_eq!(parse_f64(b"NaN"), None);
        assert_eq!(parse_f64(b"x"), None);
    }
}
