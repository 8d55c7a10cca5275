//! The daily files of the nodes' logs: `<dir>/<node>/<node>-YYYY-MM-DD.csv`
//! in `foisctl monitor`'s format (the header and row fields of
//! [`fois_link::log_row`], one definition for both), a file per UTC day of
//! the rows' host time; a day that is over is gzip-compressed to
//! `…csv.gz`; files older than the days kept are deleted. Blocking file IO:
//! runs on the log's own thread ([`super::SeasonLog`]), never on the async
//! runtime. Every method takes the time `now` as an argument (tests drive
//! days and midnights without waiting for them).

use std::collections::HashMap;
use std::fs::{File, OpenOptions};
use std::io::{BufReader, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use fois_link::log_row::{HEADER, Row, row_fields};
use fois_link::timefmt::{civil_from_days, days_from_civil};

/// One day, ms.
pub const DAY_MS: u64 = 86_400_000;

/// `YYYY-MM-DD` of a day number (days since 1970-01-01).
pub fn date_text(day: i64) -> String {
    let (y, m, d) = civil_from_days(day);
    format!("{y:04}-{m:02}-{d:02}")
}

/// The day number of a `YYYY-MM-DD` text.
fn parse_date(s: &str) -> Option<i64> {
    let b = s.as_bytes();
    if b.len() != 10 || b[4] != b'-' || b[7] != b'-' {
        return None;
    }
    let y: i64 = s.get(0..4)?.parse().ok()?;
    let m: u32 = s.get(5..7)?.parse().ok()?;
    let d: u32 = s.get(8..10)?.parse().ok()?;
    ((1..=12).contains(&m) && (1..=31).contains(&d)).then(|| days_from_civil(y, m, d))
}

/// The day of a log file of `node` by its name (`<node>-YYYY-MM-DD…`),
/// and whether it is compressed; `None` for other files.
pub fn file_day(node: &str, file_name: &str) -> Option<(i64, bool)> {
    let rest = file_name.strip_prefix(node)?.strip_prefix('-')?;
    let day = parse_date(rest.get(..10)?)?;
    let tail = &rest[10..];
    if tail.ends_with(".csv.gz") {
        Some((day, true))
    } else if tail.ends_with(".csv") {
        Some((day, false))
    } else {
        None
    }
}

struct OpenDay {
    day: i64,
    path: PathBuf,
    out: csv::Writer<File>,
}

/// The daily files of all nodes under one directory.
pub struct DailyFiles {
    dir: PathBuf,
    days_kept: u32,
    open: HashMap<String, OpenDay>,
    last_housekeeping_day: Option<i64>,
    /// Rows written.
    pub rows: u64,
}

/// A file error: which file, what went wrong.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {source}")]
pub struct FileError {
    /// The file or directory.
    pub path: PathBuf,
    /// Why.
    pub source: std::io::Error,
}

fn at(path: &Path) -> impl FnOnce(std::io::Error) -> FileError + '_ {
    move |source| FileError {
        path: path.to_path_buf(),
        source,
    }
}

fn csv_writer(f: File) -> csv::Writer<File> {
    csv::WriterBuilder::new()
        .has_headers(false)
        .buffer_capacity(64 * 1024)
        .from_writer(f)
}

fn csv_err(path: &Path, e: csv::Error) -> FileError {
    FileError {
        path: path.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
    }
}

impl DailyFiles {
    /// Logs under `dir` (created when the first row comes), keeping
    /// `days_kept` days.
    pub fn new(dir: PathBuf, days_kept: u32) -> DailyFiles {
        DailyFiles {
            dir,
            days_kept: days_kept.max(1),
            open: HashMap::new(),
            last_housekeeping_day: None,
            rows: 0,
        }
    }

    /// The directory of a node's files.
    pub fn node_dir(&self, node: &str) -> PathBuf {
        self.dir.join(node)
    }

    /// Append a row of `node` to the file of its day.
    pub fn write(&mut self, node: &str, row: &Row) -> Result<(), FileError> {
        let day = (row.host_unix_ms / DAY_MS) as i64;
        if self.open.get(node).is_none_or(|o| o.day != day) {
            if let Some(old) = self.open.remove(node) {
                self.close(old)?;
            }
            let o = self.open_day(node, day)?;
            self.open.insert(node.to_string(), o);
        }
        if let Some(o) = self.open.get_mut(node) {
            o.out
                .write_record(row_fields(row.host_unix_ms, row))
                .map_err(|e| csv_err(&o.path, e))?;
            self.rows += 1;
        }
        Ok(())
    }

    /// Open (or continue) the file of `node`'s `day`: a new file gets the
    /// header; an existing one with another header (an older layout) is
    /// left alone and the day continues in `…-YYYY-MM-DD.2.csv`, `.3`, …
    fn open_day(&self, node: &str, day: i64) -> Result<OpenDay, FileError> {
        let dir = self.node_dir(node);
        std::fs::create_dir_all(&dir).map_err(at(&dir))?;
        let date = date_text(day);
        for n in 1..100u32 {
            let name = if n == 1 {
                format!("{node}-{date}.csv")
            } else {
                format!("{node}-{date}.{n}.csv")
            };
            let path = dir.join(name);
            let mut f = OpenOptions::new()
                .create(true)
                .append(true)
                .read(true)
                .open(&path)
                .map_err(at(&path))?;
            let len = f.metadata().map_err(at(&path))?.len();
            if len == 0 {
                f.write_all(format!("{HEADER}\n").as_bytes())
                    .map_err(at(&path))?;
            } else {
                let mut first = String::new();
                let mut r = BufReader::new(File::open(&path).map_err(at(&path))?);
                std::io::BufRead::read_line(&mut r, &mut first).map_err(at(&path))?;
                if first.trim_end_matches(['\n', '\r']) != HEADER {
                    continue;
                }
                // A gateway killed mid-row: end the partial line.
                f.seek(SeekFrom::End(-1)).map_err(at(&path))?;
                let mut last = [0u8; 1];
                f.read_exact(&mut last).map_err(at(&path))?;
                if last[0] != b'\n' {
                    f.write_all(b"\n").map_err(at(&path))?;
                }
            }
            return Ok(OpenDay {
                day,
                path,
                out: csv_writer(f),
            });
        }
        Err(FileError {
            path: dir,
            source: std::io::Error::other(format!("no usable log file name for {date}")),
        })
    }

    fn close(&mut self, mut o: OpenDay) -> Result<(), FileError> {
        o.out.flush().map_err(at(&o.path))?;
        drop(o.out);
        compress(&o.path)
    }

    /// Hand buffered rows to the kernel (call about once a second: a
    /// `kill -9` loses at most that much).
    pub fn flush(&mut self) -> Result<(), FileError> {
        let mut first_err = None;
        for o in self.open.values_mut() {
            if let Err(e) = o.out.flush() {
                first_err.get_or_insert(FileError {
                    path: o.path.clone(),
                    source: e,
                });
            }
        }
        first_err.map_or(Ok(()), Err)
    }

    /// At `now_ms`: close and compress the files of days that are over;
    /// once a day (and at the first call) compress any file of an earlier
    /// day left uncompressed (a crash) and delete the files older than the
    /// days kept. Returns the errors met (each already skipped).
    pub fn housekeeping(&mut self, now_ms: u64) -> Vec<FileError> {
        let today = (now_ms / DAY_MS) as i64;
        let mut errors = Vec::new();
        let over: Vec<String> = self
            .open
            .iter()
            .filter(|(_, o)| o.day < today)
            .map(|(k, _)| k.clone())
            .collect();
        for node in over {
            if let Some(o) = self.open.remove(&node)
                && let Err(e) = self.close(o)
            {
                errors.push(e);
            }
        }
        if self.last_housekeeping_day != Some(today) {
            self.last_housekeeping_day = Some(today);
            errors.extend(self.sweep(today));
        }
        errors
    }

    /// Every node directory: compress earlier days, delete old days.
    fn sweep(&self, today: i64) -> Vec<FileError> {
        let mut errors = Vec::new();
        let Ok(nodes) = std::fs::read_dir(&self.dir) else {
            return errors;
        };
        let oldest_kept = today - i64::from(self.days_kept) + 1;
        for node_dir in nodes.flatten() {
            let path = node_dir.path();
            if !path.is_dir() {
                continue;
            }
            let node = node_dir.file_name().to_string_lossy().into_owned();
            let Ok(files) = std::fs::read_dir(&path) else {
                continue;
            };
            for f in files.flatten() {
                let name = f.file_name().to_string_lossy().into_owned();
                let Some((day, gz)) = file_day(&node, &name) else {
                    continue;
                };
                let p = f.path();
                if day < oldest_kept {
                    if let Err(e) = std::fs::remove_file(&p) {
                        errors.push(FileError { path: p, source: e });
                    }
                } else if !gz
                    && day < today
                    && let Err(e) = compress(&p)
                {
                    errors.push(e);
                }
            }
        }
        errors
    }

    /// Flush and close every file (at the gateway's stop). Today's stays
    /// uncompressed: the next run continues it.
    pub fn close_all(&mut self) -> Result<(), FileError> {
        let r = self.flush();
        for (_, o) in self.open.drain() {
            let _ = o.out.get_ref().sync_data();
        }
        r
    }
}

/// Compress `x.csv` to `x.csv.gz` (written beside it, synced, renamed) and
/// remove `x.csv`. An existing `x.csv.gz` (rows of that day written after
/// it was compressed, a clock set back) gets the new rows as a further
/// gzip member: gzip readers read the members in a row.
pub fn compress(path: &Path) -> Result<(), FileError> {
    let mut gz_name = path.as_os_str().to_os_string();
    gz_name.push(".gz");
    let gz_path = PathBuf::from(gz_name);
    let mut tmp_name = gz_path.as_os_str().to_os_string();
    tmp_name.push(".tmp");
    let tmp = PathBuf::from(tmp_name);
    let mut input = File::open(path).map_err(at(path))?;
    {
        let out = File::create(&tmp).map_err(at(&tmp))?;
        let mut enc = flate2::write::GzEncoder::new(
            std::io::BufWriter::new(out),
            flate2::Compression::default(),
        );
        std::io::copy(&mut input, &mut enc).map_err(at(&tmp))?;
        let out = enc.finish().map_err(at(&tmp))?;
        let out = out.into_inner().map_err(|e| FileError {
            path: tmp.clone(),
            source: e.into_error(),
        })?;
        out.sync_all().map_err(at(&tmp))?;
    }
    if gz_path.exists() {
        let mut member = File::open(&tmp).map_err(at(&tmp))?;
        let mut existing = OpenOptions::new()
            .append(true)
            .open(&gz_path)
            .map_err(at(&gz_path))?;
        std::io::copy(&mut member, &mut existing).map_err(at(&gz_path))?;
        existing.sync_all().map_err(at(&gz_path))?;
        std::fs::remove_file(&tmp).map_err(at(&tmp))?;
    } else {
        std::fs::rename(&tmp, &gz_path).map_err(at(&gz_path))?;
    }
    std::fs::remove_file(path).map_err(at(path))
}
