//! The durable measurement log: one CSV file with a header, one row per
//! measurement, event, answer, gap, link change or rejected frame, each with
//! the host's time. Opened in append mode, so a reconnect or a restart of
//! `foisctl monitor` continues the same file. Rows are handed to the kernel
//! at least every [`FLUSH_INTERVAL`], so a `kill -9` of the logger loses at
//! most that much.
//!
//! Columns: [`fois_link::log_row`] (one definition, shared with the fleet
//! gateway's daily logs); [`HEADER`], [`Row`] and [`row_fields`] are
//! re-exported here.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use csv::StringRecord;
use fois_link::timefmt::unix_ms_now;

pub use fois_link::log_row::{HEADER, Row, row_fields};

/// Rows reach the kernel at least this often (kill -9 loses at most this).
pub const FLUSH_INTERVAL: Duration = Duration::from_millis(250);

/// Errors of the log file.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// The file could not be opened, read or written.
    #[error("log file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A row could not be written.
    #[error("log file {path}: {source}")]
    Csv {
        /// The file.
        path: PathBuf,
        /// Why.
        source: csv::Error,
    },
    /// The file exists with another first line.
    #[error(
        "log file {0} exists but is not a foisctl log of this layout (its header differs: another program's file, or a log of an older foisctl, which plot, compare and estimate still read); log to another file"
    )]
    ForeignHeader(PathBuf),
}

/// The CSV log file.
pub struct CsvLog {
    path: PathBuf,
    out: csv::Writer<File>,
    last_flush: Instant,
    rows: u64,
}

fn csv_writer<W: std::io::Write>(w: W) -> csv::Writer<W> {
    csv::WriterBuilder::new()
        .has_headers(false)
        .buffer_capacity(64 * 1024)
        .from_writer(w)
}

impl CsvLog {
    /// Open (create or append to) `path`. A new or empty file gets the
    /// header; an existing file must start with it.
    pub fn open(path: &Path) -> Result<CsvLog, LogError> {
        let io = |source| LogError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .read(true)
            .open(path)
            .map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        let mut needs_newline = false;
        if len > 0 {
            let mut first = StringRecord::new();
            let mut rd = csv::ReaderBuilder::new()
                .has_headers(false)
                .flexible(true)
                .from_path(path)
                .map_err(|e| LogError::Csv {
                    path: path.to_path_buf(),
                    source: e,
                })?;
            let header_ok =
                rd.read_record(&mut first).unwrap_or(false) && first.iter().eq(HEADER.split(','));
            if !header_ok {
                return Err(LogError::ForeignHeader(path.to_path_buf()));
            }
            // A logger killed mid-row leaves a partial last line: end it so
            // the next row starts on its own line.
            let mut f = File::open(path).map_err(io)?;
            f.seek(SeekFrom::End(-1)).map_err(io)?;
            let mut last = [0u8; 1];
            f.read_exact(&mut last).map_err(io)?;
            needs_newline = last[0] != b'\n';
        }
        if needs_newline {
            use std::io::Write;
            (&file).write_all(b"\n").map_err(io)?;
        }
        let mut log = CsvLog {
            path: path.to_path_buf(),
            out: csv_writer(file),
            last_flush: Instant::now(),
            rows: 0,
        };
        if len == 0 {
            log.record(HEADER.split(','))?;
            log.flush()?;
        }
        Ok(log)
    }

    fn record<I, T>(&mut self, fields: I) -> Result<(), LogError>
    where
        I: IntoIterator<Item = T>,
        T: AsRef<[u8]>,
    {
        self.out
            .write_record(fields)
            .map_err(|source| LogError::Csv {
                path: self.path.clone(),
                source,
            })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Rows written by this writer.
    pub fn rows(&self) -> u64 {
        self.rows
    }

    /// Append a row (timestamped now if `host_unix_ms` is 0); flushes if the
    /// last flush is older than [`FLUSH_INTERVAL`].
    pub fn write(&mut self, row: &Row) -> Result<(), LogError> {
        let ms = if row.host_unix_ms == 0 {
            unix_ms_now()
        } else {
            row.host_unix_ms
        };
        self.record(row_fields(ms, row))?;
        self.rows += 1;
        self.tick()
    }

    /// Flush if due; call it at least every 100 ms even when no rows come.
    pub fn tick(&mut self) -> Result<(), LogError> {
        if self.last_flush.elapsed() >= FLUSH_INTERVAL {
            self.flush()?;
        }
        Ok(())
    }

    /// Hand every buffered row to the kernel now.
    pub fn flush(&mut self) -> Result<(), LogError> {
        self.last_flush = Instant::now();
        self.out.flush().map_err(|source| LogError::Io {
            path: self.path.clone(),
            source,
        })
    }

    /// Flush and ask the disk to keep it (on exit).
    pub fn close(mut self) -> Result<(), LogError> {
        self.flush()?;
        self.out
            .get_ref()
            .sync_data()
            .map_err(|source| LogError::Io {
                path: self.path.clone(),
                source,
            })
    }
}

/// The CSV line of a row (with newline), as [`CsvLog::write`] writes it.
pub fn format_row(host_unix_ms: u64, r: &Row) -> String {
    let mut w = csv_writer(Vec::new());
    // Writing to memory cannot fail.
    let _ = w.write_record(row_fields(host_unix_ms, r));
    let bytes = w.into_inner().unwrap_or_default();
    String::from_utf8_lossy(&bytes).into_owned()
}

/// A log read back: the header's columns and every row as text fields
/// (only the columns asked for, to keep a day of 10 Hz rows small).
#[derive(Debug, Clone, Default)]
pub struct LogTable {
    /// Every column of the file's header.
    pub header: Vec<String>,
    /// The columns kept, in the order of the rows' fields.
    pub columns: Vec<String>,
    /// Rows, fields as text.
    pub rows: Vec<Vec<String>>,
}

impl LogTable {
    /// Read a CSV file with a header (a foisctl log, or any CSV with the
    /// columns a command needs). A partial last line is ignored.
    pub fn read(path: &Path) -> anyhow::Result<LogTable> {
        Self::read_columns(path, None)
    }

    /// Read only the columns named in `wanted` (those the file has; all
    /// when `None`).
    pub fn read_columns(path: &Path, wanted: Option<&[&str]>) -> anyhow::Result<LogTable> {
        let mut rd = LogReader::open(path)?;
        let header = rd.header().to_vec();
        let keep: Vec<usize> = match wanted {
            None => (0..header.len()).collect(),
            Some(names) => names.iter().filter_map(|n| rd.col(n)).collect(),
        };
        let columns = keep.iter().map(|&i| header[i].clone()).collect();
        let mut rows = Vec::new();
        let mut fields = StringRecord::new();
        while rd.next_row(&mut fields)? {
            rows.push(keep.iter().map(|&i| fields[i].to_string()).collect());
        }
        Ok(LogTable {
            header,
            columns,
            rows,
        })
    }

    /// Index of a column among those kept.
    pub fn col(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }

    /// The numbers of a column (NaN where empty or not a number).
    pub fn numbers(&self, col: usize) -> Vec<f64> {
        self.rows
            .iter()
            .map(|r| r[col].trim().parse::<f64>().unwrap_or(f64::NAN))
            .collect()
    }
}

/// A reader that remembers the last byte it delivered (at the end of the
/// file: whether the last line was ended). Also the icing report's.
pub(crate) struct LastByte<R> {
    pub(crate) inner: R,
    pub(crate) last: Option<u8>,
}

impl<R: Read> Read for LastByte<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        if let Some(&b) = buf[..n].last() {
            self.last = Some(b);
        }
        Ok(n)
    }
}

/// Reads a CSV log row by row without keeping it (a day at 10 Hz is
/// 864 000 rows).
pub struct LogReader {
    path: PathBuf,
    reader: csv::Reader<LastByte<File>>,
    header: Vec<String>,
    /// The row read ahead: the last one is dropped if its line was not ended.
    ahead: Option<StringRecord>,
}

impl LogReader {
    /// Open a CSV file and read its header.
    pub fn open(path: &Path) -> anyhow::Result<LogReader> {
        let file =
            File::open(path).with_context(|| format!("cannot read log {}", path.display()))?;
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .buffer_capacity(1 << 16)
            .from_reader(LastByte {
                inner: file,
                last: None,
            });
        let mut first = StringRecord::new();
        if !reader
            .read_record(&mut first)
            .with_context(|| format!("cannot read log {}", path.display()))?
        {
            anyhow::bail!("log {} is empty", path.display());
        }
        let mut rd = LogReader {
            path: path.to_path_buf(),
            reader,
            header: first.iter().map(str::to_string).collect(),
            ahead: None,
        };
        rd.ahead = rd.read_ahead()?;
        Ok(rd)
    }

    fn read_ahead(&mut self) -> anyhow::Result<Option<StringRecord>> {
        let mut rec = StringRecord::new();
        let more = self
            .reader
            .read_record(&mut rec)
            .with_context(|| format!("cannot read log {}", self.path.display()))?;
        Ok(more.then_some(rec))
    }

    /// The header's columns.
    pub fn header(&self) -> &[String] {
        &self.header
    }

    /// Index of a column.
    pub fn col(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|c| c == name)
    }

    /// Index of a column, or an error naming the file and its columns.
    pub fn need(&self, name: &str) -> anyhow::Result<usize> {
        self.col(name).ok_or_else(|| {
            anyhow::anyhow!(
                "log {} has no column `{name}` (columns: {})",
                self.path.display(),
                self.header.join(", ")
            )
        })
    }

    /// The next complete row with as many fields as the header, into
    /// `fields`; `false` at the end. A last line cut short (a killed
    /// logger) is ignored, and so are rows of the wrong width.
    pub fn next_row(&mut self, fields: &mut StringRecord) -> anyhow::Result<bool> {
        while let Some(row) = self.ahead.take() {
            self.ahead = self.read_ahead()?;
            let cut_short = self.ahead.is_none() && self.reader.get_ref().last != Some(b'\n');
            if cut_short {
                return Ok(false);
            }
            if row.len() == self.header.len() {
                *fields = row;
                return Ok(true);
            }
        }
        Ok(false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fois_protocol::{DetectorState, DeviceMsg, IceEstimate, Measurement, flags};
    use std::io::Write;

    fn meas() -> Measurement {
        Measurement {
            uptime_ms: 1234,
            i1_na: 25_500,
            i2_na: -7,
            ambient1_na: 100,
            ambient2_na: 0,
            temperature_centi_c: -512,
            vdda_mv: 3300,
            flags: flags::ALARM,
            state: DetectorState::Ice,
        }
    }

    #[test]
    fn the_faults_column_names_the_fault_bits_beside_flags() {
        let mut m = meas();
        m.flags = flags::ALARM | flags::NTC_OPEN | flags::GAIN_OUT_OF_BAND;
        let line = format_row(0, &Row::device(7, &DeviceMsg::Measurement(m)));
        let f = fields(&line);
        let col = |name: &str| HEADER.split(',').position(|c| c == name).unwrap();
        assert_eq!(f[col("flags")], "8260");
        assert_eq!(f[col("faults")], "ntc_open gain_out_of_band");
        let ev = fois_protocol::Event {
            uptime_ms: 5,
            kind: fois_protocol::EventKind::FaultRaised(flags::NTC_SHORT),
            i1_na: 0,
            i2_na: 0,
            rise1_na: 0,
            temperature_centi_c: 0,
            frames: 1,
        };
        let f = fields(&format_row(0, &Row::device(8, &DeviceMsg::Event(ev))));
        assert_eq!(f[col("faults")], "ntc_short");
        assert_eq!(
            fields(&format_row(
                0,
                &Row::device(9, &DeviceMsg::Measurement(meas()))
            ))[col("faults")],
            ""
        );
    }

    #[test]
    fn row_text_matches_header() {
        let line = format_row(0, &Row::device(42, &DeviceMsg::Measurement(meas())));
        assert_eq!(
            line,
            "1970-01-01T00:00:00.000Z,0,measurement,42,1234,25.500,-0.007,0.100,0.000,-5.12,3300,Ice,1,1,64,,,,,,,,,,,,\n"
        );
        let v2 = DeviceMsg::MeasurementV2(fois_protocol::MeasurementV2 {
            measurement: meas(),
            estimate: Some(IceEstimate {
                thickness_um: 2345,
                sigma_um: 310,
                medium: fois_protocol::Medium::Rime,
                probability_permille: 970,
            }),
        });
        assert_eq!(
            format_row(0, &Row::device(42, &v2)),
            "1970-01-01T00:00:00.000Z,0,measurement,42,1234,25.500,-0.007,0.100,0.000,-5.12,3300,Ice,1,1,64,,,,2.345,0.310,rime,0.970,,,,,\n"
        );
        let v3 = DeviceMsg::MeasurementV3(fois_protocol::MeasurementV3 {
            measurement: meas(),
            estimate: None,
            gain: Some(fois_protocol::GainEstimate {
                gain_ppm: 1_150_260,
                sigma_ppm: 61_000,
            }),
        });
        assert_eq!(
            format_row(0, &Row::device(42, &v3)),
            "1970-01-01T00:00:00.000Z,0,measurement,42,1234,25.500,-0.007,0.100,0.000,-5.12,3300,Ice,1,1,64,,,,,,,,1.1503,0.0610,,,\n"
        );
        let v5 = DeviceMsg::MeasurementV5(fois_protocol::MeasurementV5 {
            measurement: meas(),
            estimate: None,
            gain: None,
            icing: Some(fois_protocol::IcingEstimate {
                rate_um_per_h: 2_150,
                sigma_um_per_h: 600,
                accreting_permille: 940,
                accreting: true,
            }),
        });
        assert_eq!(
            format_row(0, &Row::device(42, &v5)),
            "1970-01-01T00:00:00.000Z,0,measurement,42,1234,25.500,-0.007,0.100,0.000,-5.12,3300,Ice,1,1,64,,,,,,,,,,2.150,0.600,1\n"
        );
        assert_eq!(fields(&line).len(), HEADER.split(',').count());
        let g = format_row(5, &Row::gap(10, 3));
        let f = fields(&g);
        assert_eq!(f[2], "gap");
        assert_eq!(f[16], "3");
    }

    /// One CSV line read back by the csv crate.
    fn fields(line: &str) -> Vec<String> {
        let mut rd = csv::ReaderBuilder::new()
            .has_headers(false)
            .from_reader(line.as_bytes());
        let mut r = StringRecord::new();
        assert!(rd.read_record(&mut r).unwrap());
        r.iter().map(str::to_string).collect()
    }

    #[test]
    fn quoting_round_trips() {
        let r = Row::note("note", "a, \"b\"\nc");
        let line = format_row(1, &r);
        let f = fields(&line);
        assert_eq!(f[17], "a, \"b\"\nc");
        assert_eq!(f.len(), 27);
    }

    #[test]
    fn reader_skips_a_cut_last_line_and_rows_of_another_width() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.csv");
        for (text, want) in [
            ("a,b\n1,2\n3,4\n", vec!["1", "3"]),
            ("a,b\n1,2\n3,4", vec!["1"]),
            ("a,b\n1,2\n\n5\n\"6,x\",7\n8,", vec!["1", "6,x"]),
            ("a,b\n", vec![]),
        ] {
            std::fs::write(&p, text).unwrap();
            let t = LogTable::read(&p).unwrap();
            let got: Vec<&str> = t.rows.iter().map(|r| r[0].as_str()).collect();
            assert_eq!(got, want, "{text:?}");
        }
        std::fs::write(&p, "").unwrap();
        let err = LogReader::open(&p).err().map(|e| e.to_string());
        assert!(err.is_some_and(|e| e.contains("empty")));
    }

    #[test]
    fn append_keeps_header_once_and_refuses_foreign_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("log.csv");
        {
            let mut log = CsvLog::open(&p).unwrap();
            log.write(&Row::device(1, &DeviceMsg::Measurement(meas())))
                .unwrap();
            log.close().unwrap();
        }
        // A partial line, as a kill -9 mid-write could leave.
        std::fs::OpenOptions::new()
            .append(true)
            .open(&p)
            .unwrap()
            .write_all(b"2026-01-01T00:00")
            .unwrap();
        {
            let mut log = CsvLog::open(&p).unwrap();
            log.write(&Row::device(2, &DeviceMsg::Measurement(meas())))
                .unwrap();
            log.close().unwrap();
        }
        let t = LogTable::read(&p).unwrap();
        assert_eq!(t.columns.len(), 27);
        let seqs: Vec<&str> = t.rows.iter().map(|r| r[3].as_str()).collect();
        assert_eq!(seqs, ["1", "2"]);
        let text = std::fs::read_to_string(&p).unwrap();
        assert_eq!(text.matches("host_time_utc").count(), 1);

        let other = dir.path().join("other.csv");
        std::fs::write(&other, "a,b\n1,2\n").unwrap();
        assert!(matches!(
            CsvLog::open(&other),
            Err(LogError::ForeignHeader(_))
        ));
        // A log of the layout before the gain (or the icing-rate) columns
        // is not appended to (its rows would be narrower than the new
        // ones): a clear refusal.
        let older = dir.path().join("older.csv");
        let old_header = HEADER.trim_end_matches(
            ",est_gain,est_gain_sigma,est_rate_mm_per_h,est_rate_sigma_mm_per_h,est_accreting",
        );
        std::fs::write(&older, format!("{old_header}\n")).unwrap();
        let err = CsvLog::open(&older).err().map(|e| e.to_string());
        assert!(
            err.as_deref()
                .is_some_and(|e| e.contains("log to another file")),
            "{err:?}"
        );
        assert_eq!(
            std::fs::read_to_string(&older).unwrap(),
            format!("{old_header}\n"),
            "the older log is left as it was"
        );
    }
}
