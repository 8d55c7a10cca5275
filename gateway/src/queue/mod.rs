//! The store-and-forward queue: every event and every measurement the
//! gateway decides to publish is first appended here, then published (QoS 1)
//! from here, and forgotten only once the broker has acknowledged it. While
//! the broker is unreachable the records simply wait; after a crash they are
//! read back and sent again. The file format is [`segment`]'s.
//!
//! ## Durability
//!
//! Appended records reach the kernel at every [`Queue::tick`] (the gateway
//! ticks every 100 ms), so a SIGKILL loses at most what arrived since the last
//! tick; the segment is `fdatasync`ed every [`SYNC_INTERVAL`] against power
//! loss. The `ack` file is rewritten at most every [`ACK_WRITE_INTERVAL`]:
//! records acknowledged in that window before a crash are published again
//! after the restart (duplicates that consumers drop by node `seq`/`uptime_ms`).
//!
//! ## What is lost, and that it is counted
//!
//! Every record the queue loses is counted in [`Queue::dropped`] (kept in
//! the `ack` file, published as `queue_dropped` in the gateway's status),
//! and measurements go first: events are never dropped.
//!
//! - **The bound.** The segment files never hold more than `max_bytes`
//!   (plus the segment being written): when they would, the oldest segment
//!   is deleted; its unacknowledged events are appended again at the end,
//!   its measurements are counted. Segments are `max_bytes / 16` (16 KiB to
//!   16 MiB), so a drop discards about 1/16 of the queue at once.
//! - **A failing disk** (full, read-only, gone). The queue keeps working in
//!   memory: records that have not reached the disk stay in memory (never
//!   evicted from the cache), at most `unsaved_bytes` of them; beyond that the
//!   oldest unsaved measurement is replaced by a tombstone and counted. The
//!   segment is cut back to what reached the disk, and every second the
//!   queue tries again: when the disk takes writes again, every record held
//!   in memory is written out, in order.
//! - **The directory removed** under a running gateway. It is made again;
//!   the records that were only in the removed files (not in memory) are
//!   counted as lost, the rest written out again; nothing is sent twice.
//!
//! A second gateway on the same directory is refused at start (the
//! directory's `lock`).

mod drop_log;
mod failure;
mod segment;
#[cfg(test)]
pub(crate) mod stall;
#[cfg(test)]
mod tests;

use std::collections::VecDeque;
use std::fs::{self, File, OpenOptions};
use std::io::{BufReader, BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use tracing::{info, warn};

use drop_log::{DropLine, DropLog};

pub use segment::{MAX_RECORD_BYTES, Record};
use segment::{SegReader, Segment, read_record, seg_path};

/// The segment file is synced to disk at least this often.
pub const SYNC_INTERVAL: Duration = Duration::from_secs(1);
/// The `ack` file is rewritten at most this often.
pub const ACK_WRITE_INTERVAL: Duration = Duration::from_millis(200);
/// A failing disk is tried again this often.
pub const RETRY_INTERVAL: Duration = Duration::from_secs(1);

/// Sizes of the queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct QueueLimits {
    /// Bound of the segment files, bytes.
    pub max_bytes: u64,
    /// Size at which a new segment is started, bytes.
    pub segment_bytes: u64,
    /// Newest records also kept in memory (so normal publishing never reads
    /// the disk), bytes.
    pub mem_bytes: usize,
    /// Records that could not be written to disk kept in memory, at most
    /// (bytes); beyond it the oldest such measurements are dropped.
    pub unsaved_bytes: usize,
}

impl QueueLimits {
    /// Limits for a bound of `max_bytes`.
    pub fn for_max_bytes(max_bytes: u64) -> QueueLimits {
        QueueLimits {
            max_bytes,
            segment_bytes: (max_bytes / 16).clamp(16 * 1024, 16 * 1024 * 1024),
            mem_bytes: 8 * 1024 * 1024,
            unsaved_bytes: 32 * 1024 * 1024,
        }
    }
}

/// What opening found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Recovery {
    /// Records waiting to be published.
    pub pending: u64,
    /// Bytes cut off torn or corrupt segment tails.
    pub truncated_bytes: u64,
}

/// The writer of the newest segment and what of it reached the disk.
struct Writer {
    out: BufWriter<File>,
    /// Records and bytes of the segment handed to the kernel.
    flushed: (u64, u64),
}

/// The queue.
pub struct Queue {
    dir: PathBuf,
    limits: QueueLimits,
    segments: VecDeque<Segment>,
    /// `None` while the disk fails: records are then held in memory.
    writer: Option<Writer>,
    /// Why the disk fails, and when it was last tried.
    failing: Option<(String, Instant)>,
    /// Every record below this index is on disk (or acknowledged).
    on_disk: u64,
    next: u64,
    acked: u64,
    dropped: u64,
    unsynced: bool,
    last_sync: Instant,
    ack_dirty: bool,
    last_ack_write: Instant,
    /// The newest records, contiguous from `mem.front()` to `next - 1`.
    mem: VecDeque<(u64, Record)>,
    mem_bytes: usize,
    /// Memory of the records not on disk (index ≥ `on_disk`).
    held_bytes: usize,
    reader: Option<SegReader>,
    /// The drops told in the log.
    drop_log: DropLog,
    _lock: File,
}

impl Queue {
    /// Open (or create) the queue in `dir`: take its lock, recover the
    /// segments, cut off a torn tail, read the acknowledged offset.
    pub fn open(dir: &Path, limits: QueueLimits) -> anyhow::Result<(Queue, Recovery)> {
        fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the queue directory {}", dir.display()))?;
        let lock = segment::lock(dir)?;
        let ack = fs::read_to_string(dir.join("ack"))
            .ok()
            .and_then(|t| segment::parse_ack(&t));
        let mut rec = Recovery::default();
        let mut segments = VecDeque::new();
        for first in segment::segment_firsts(dir)? {
            let path = seg_path(dir, first);
            let (count, bytes, file_len) = segment::scan_segment(&path)?;
            if bytes < file_len {
                rec.truncated_bytes += file_len - bytes;
                segment::truncate(&path, bytes)
                    .with_context(|| format!("cannot cut the torn end of {}", path.display()))?;
            }
            segments.push_back(Segment {
                first,
                count,
                bytes,
                path,
            });
        }
        let first_index = segments.front().map_or(0, |s| s.first);
        let next = segments.back().map_or(0, |s| s.end());
        let (mut acked, dropped) = ack.unwrap_or((first_index, 0));
        let next = next.max(acked.min(u64::MAX / 2));
        acked = acked.clamp(first_index.min(next), next);
        // Delete what is acknowledged, except the last segment.
        while segments.len() > 1 && segments.front().is_some_and(|s| s.end() <= acked) {
            if let Some(s) = segments.pop_front() {
                let _ = fs::remove_file(&s.path);
            }
        }
        let reuse = segments
            .back()
            .is_some_and(|s| s.bytes < limits.segment_bytes && s.end() == next);
        if !reuse {
            segments.push_back(Segment::new(dir, next));
        }
        let (path, flushed) = segments
            .back()
            .map(|s| (s.path.clone(), (s.count, s.bytes)))
            .unwrap_or_default();
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .with_context(|| format!("cannot open the queue segment {}", path.display()))?;
        rec.pending = next - acked;
        let now = Instant::now();
        let mut q = Queue {
            dir: dir.to_path_buf(),
            limits,
            segments,
            writer: Some(Writer {
                out: BufWriter::with_capacity(64 * 1024, file),
                flushed,
            }),
            failing: None,
            on_disk: next,
            next,
            acked,
            dropped,
            unsynced: false,
            last_sync: now,
            ack_dirty: true,
            last_ack_write: now - ACK_WRITE_INTERVAL,
            mem: VecDeque::new(),
            mem_bytes: 0,
            held_bytes: 0,
            reader: None,
            drop_log: DropLog::new(dropped),
            _lock: lock,
        };
        q.write_ack()?;
        Ok((q, rec))
    }

    /// Append a record; returns its index. Never fails: when the disk does,
    /// the record is held in memory (see the module doc).
    pub fn push(&mut self, rec: Record) -> u64 {
        let index = self.next;
        self.next += 1;
        let bytes = rec.encode();
        self.mem_bytes += rec.mem_size();
        self.held_bytes += rec.mem_size();
        self.mem.push_back((index, rec));
        if let Some(w) = &mut self.writer {
            match w.out.write_all(&bytes) {
                Ok(()) => {
                    self.unsynced = true;
                    if let Some(seg) = self.segments.back_mut() {
                        seg.count += 1;
                        seg.bytes += bytes.len() as u64;
                    }
                }
                Err(e) => self.fail(format!("cannot write the queue: {e}")),
            }
        }
        if self.writer.is_some()
            && self
                .segments
                .back()
                .is_some_and(|s| s.bytes >= self.limits.segment_bytes)
            && let Err(e) = self.roll()
        {
            self.fail(format!("{e:#}"));
        }
        self.enforce_bound();
        self.trim_mem();
        index
    }

    /// Hand the segment's buffered records to the kernel; what reached it
    /// is on disk.
    fn flush(&mut self) -> anyhow::Result<()> {
        if let Some(w) = &mut self.writer {
            w.out.flush().context("cannot write the queue")?;
            if let Some(seg) = self.segments.back() {
                w.flushed = (seg.count, seg.bytes);
            }
            self.on_disk = self.next;
            self.held_bytes = 0;
        }
        Ok(())
    }

    fn roll(&mut self) -> anyhow::Result<()> {
        self.flush()?;
        if let Some(w) = &self.writer {
            w.out.get_ref().sync_data()?;
        }
        let seg = Segment::new(&self.dir, self.next);
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&seg.path)
            .with_context(|| format!("cannot open the queue segment {}", seg.path.display()))?;
        self.writer = Some(Writer {
            out: BufWriter::with_capacity(64 * 1024, file),
            flushed: (0, 0),
        });
        self.unsynced = false;
        self.last_sync = Instant::now();
        self.segments.push_back(seg);
        Ok(())
    }

    /// The bound: delete the oldest segment while the files are too big;
    /// its unacknowledged events are appended again, its measurements
    /// counted as dropped.
    fn enforce_bound(&mut self) {
        while self.segments.len() > 1 && self.bytes() > self.limits.max_bytes {
            let Some(s) = self.segments.pop_front() else {
                break;
            };
            let from = self.acked.max(s.first);
            let mut events = Vec::new();
            let mut lost = s.end().saturating_sub(from);
            if let Ok(f) = File::open(&s.path) {
                let mut r = BufReader::new(f);
                let mut i = s.first;
                while let Ok(Some((rec, _))) = read_record(&mut r) {
                    if i >= from && rec.is_tombstone() {
                        lost -= 1; // counted when it was dropped
                    } else if i >= from && !rec.is_measurement() {
                        events.push(rec);
                    }
                    i += 1;
                }
            }
            lost -= events.len() as u64;
            self.dropped += lost;
            self.acked = self.acked.max(s.end());
            self.ack_dirty = true;
            if self.reader.as_ref().is_some_and(|r| r.seg_first == s.first) {
                self.reader = None;
            }
            let _ = fs::remove_file(&s.path);
            for e in events {
                self.push(e);
            }
        }
    }

    /// Forget acknowledged records; keep the cache within its size (only
    /// records on disk leave it); keep the records not on disk within
    /// `unsaved_bytes` by dropping the oldest of those measurements.
    fn trim_mem(&mut self) {
        while self.mem.front().is_some_and(|(i, _)| *i < self.acked) {
            if let Some((i, r)) = self.mem.pop_front() {
                self.mem_bytes -= r.mem_size();
                if i >= self.on_disk {
                    self.held_bytes -= r.mem_size();
                }
            }
        }
        while self.mem_bytes > self.limits.mem_bytes
            && self.mem.front().is_some_and(|(i, _)| *i < self.on_disk)
        {
            if let Some((_, r)) = self.mem.pop_front() {
                self.mem_bytes -= r.mem_size();
            }
        }
        if self.held_bytes <= self.limits.unsaved_bytes {
            return;
        }
        let on_disk = self.on_disk;
        for (i, r) in self.mem.iter_mut() {
            if self.held_bytes <= self.limits.unsaved_bytes {
                break;
            }
            if *i >= on_disk && r.is_measurement() {
                let freed = r.mem_size() - Record::tombstone().mem_size();
                *r = Record::tombstone();
                self.mem_bytes -= freed;
                self.held_bytes -= freed;
                self.dropped += 1;
                self.ack_dirty = true;
            }
        }
    }

    /// The first record at index `from` or later that is not acknowledged
    /// and not a tombstone, with its index. A segment that cannot be read
    /// is counted as lost and skipped.
    pub fn get(&mut self, from: u64) -> Option<(u64, Record)> {
        let mut i = from.max(self.acked);
        loop {
            if i >= self.next {
                return None;
            }
            if let Some((first, _)) = self.mem.front()
                && *first <= i
            {
                let (idx, r) = &self.mem[(i - first) as usize];
                if r.is_tombstone() {
                    i += 1;
                    continue;
                }
                return Some((*idx, r.clone()));
            }
            match self.read_disk(i) {
                Ok(Some((idx, r))) if r.is_tombstone() => i = idx + 1,
                Ok(Some(found)) => return Some(found),
                Ok(None) => {
                    // Not on disk (a segment counted as lost): go on with
                    // what memory holds.
                    let mem_first = self.mem.front().map_or(self.next, |m| m.0);
                    if mem_first <= i {
                        return None;
                    }
                    i = mem_first;
                }
                Err((seg_first, e)) => {
                    if !self.lose_segment(seg_first, i, &e) {
                        // The segment being written: the pump tries again
                        // once the disk queue is rebuilt.
                        return None;
                    }
                }
            }
        }
    }

    /// Record `i` (or the next one a segment holds) from the segment files.
    fn read_disk(&mut self, i: u64) -> Result<Option<(u64, Record)>, (u64, anyhow::Error)> {
        let Some(seg) = self.segments.iter().find(|s| s.end() > i && s.count > 0) else {
            return Ok(None);
        };
        let (seg_first, seg_path) = (seg.first, seg.path.clone());
        let i = i.max(seg_first);
        if self.segments.back().is_some_and(|s| s.first == seg_first) {
            self.flush().map_err(|e| (seg_first, e))?;
        }
        let usable = self
            .reader
            .as_ref()
            .is_some_and(|r| r.seg_first == seg_first && r.next <= i);
        if !usable {
            let open = File::open(&seg_path)
                .and_then(|mut f| f.seek(SeekFrom::Start(0)).map(|_| f))
                .with_context(|| format!("cannot read the queue segment {}", seg_path.display()));
            let f = open.map_err(|e| (seg_first, e))?;
            self.reader = Some(SegReader {
                seg_first,
                next: seg_first,
                file: BufReader::with_capacity(64 * 1024, f),
            });
        }
        let Some(r) = self.reader.as_mut() else {
            return Ok(None);
        };
        loop {
            let got = read_record(&mut r.file)
                .with_context(|| format!("queue segment {} is damaged", seg_path.display()))
                .map_err(|e| (seg_first, e))?;
            let Some((rec, _)) = got else {
                self.reader = None;
                return Err((
                    seg_first,
                    anyhow::anyhow!(
                        "queue segment {} ends before record {i}",
                        seg_path.display()
                    ),
                ));
            };
            let idx = r.next;
            r.next += 1;
            if idx == i {
                return Ok(Some((idx, rec)));
            }
        }
    }

    /// Every record below `upto` was acknowledged by the broker.
    pub fn ack_through(&mut self, upto: u64) {
        let upto = upto.min(self.next);
        if upto <= self.acked {
            return;
        }
        self.acked = upto;
        self.ack_dirty = true;
        self.trim_mem();
        while self.segments.len() > 1 && self.segments.front().is_some_and(|s| s.end() <= upto) {
            if let Some(s) = self.segments.pop_front() {
                if self.reader.as_ref().is_some_and(|r| r.seg_first == s.first) {
                    self.reader = None;
                }
                let _ = fs::remove_file(&s.path);
            }
        }
    }

    /// Hand appended records to the kernel; sync and write the `ack` file
    /// when due; notice a removed directory; retry a failing disk; log when
    /// records are being dropped ([`drop_log`]). Call every 100 ms or so.
    pub fn tick(&mut self) {
        #[cfg(test)]
        stall::wait(&self.dir);
        self.tick_disk();
        self.log_drops(Instant::now());
    }

    /// Tell the log, once per episode, that records are being dropped.
    fn log_drops(&mut self, now: Instant) {
        let cause = match &self.failing {
            Some((why, _)) => format!(
                "the disk fails ({why}) and the records held in memory reached {} bytes",
                self.limits.unsaved_bytes
            ),
            None => format!(
                "the queue reached its bound of {} bytes (the broker away too long)",
                self.limits.max_bytes
            ),
        };
        match self.drop_log.observe(self.dropped, now) {
            Some(DropLine::Started { dropped }) => warn!(
                "queue {}: dropping the oldest measurements: {cause}; {dropped} dropped \
                 (events are kept)",
                self.dir.display()
            ),
            Some(DropLine::Continuing { since, episode }) => warn!(
                "queue {}: still dropping measurements ({cause}): {since} since the last \
                 such line, {episode} since it began",
                self.dir.display()
            ),
            Some(DropLine::Ended { episode }) => info!(
                "queue {}: no longer dropping measurements; {episode} were lost",
                self.dir.display()
            ),
            None => {}
        }
    }

    fn tick_disk(&mut self) {
        if self.writer.is_some() && !self.dir.is_dir() {
            self.fail(format!("the directory {} was removed", self.dir.display()));
        }
        if self.writer.is_none() {
            if self
                .failing
                .as_ref()
                .is_none_or(|(_, at)| at.elapsed() >= RETRY_INTERVAL)
            {
                self.recover();
            }
            return;
        }
        if let Err(e) = self.flush() {
            self.fail(format!("{e:#}"));
            return;
        }
        self.trim_mem();
        if self.unsynced && self.last_sync.elapsed() >= SYNC_INTERVAL {
            let synced = self.writer.as_ref().map(|w| w.out.get_ref().sync_data());
            if let Some(Err(e)) = synced {
                self.fail(format!("cannot sync the queue: {e}"));
                return;
            }
            self.unsynced = false;
            self.last_sync = Instant::now();
        }
        if self.ack_dirty
            && self.last_ack_write.elapsed() >= ACK_WRITE_INTERVAL
            && let Err(e) = self.write_ack()
        {
            self.fail(format!("{e:#}"));
        }
    }

    fn write_ack(&mut self) -> anyhow::Result<()> {
        let tmp = self.dir.join("ack.tmp");
        fs::write(
            &tmp,
            format!("acked {}\ndropped {}\n", self.acked, self.dropped),
        )
        .and_then(|_| fs::rename(&tmp, self.dir.join("ack")))
        .with_context(|| format!("cannot write {}", self.dir.join("ack").display()))?;
        self.ack_dirty = false;
        self.last_ack_write = Instant::now();
        Ok(())
    }

    /// Flush, sync and record the acknowledged offset (clean shutdown). A
    /// failing disk is tried once more; what it still cannot take is lost
    /// (and said).
    pub fn close(mut self) -> anyhow::Result<()> {
        if self.writer.is_none() {
            self.recover();
        }
        self.flush()?;
        if let Some(w) = &self.writer {
            w.out.get_ref().sync_data()?;
        } else {
            let unsaved = self.next - self.on_disk.max(self.acked);
            anyhow::bail!(
                "the disk queue in {} still fails: {unsaved} record(s) held in memory are lost",
                self.dir.display()
            );
        }
        self.write_ack()
    }

    /// Why the disk fails, while it does.
    pub fn failing(&self) -> Option<&str> {
        self.failing.as_ref().map(|(why, _)| why.as_str())
    }

    /// Every record below this was acknowledged (or dropped).
    pub fn acked(&self) -> u64 {
        self.acked
    }

    /// Records not yet acknowledged.
    pub fn pending(&self) -> u64 {
        self.next - self.acked
    }

    /// Records the queue lost, ever (kept in the `ack` file).
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Bytes of the segment files.
    pub fn bytes(&self) -> u64 {
        self.segments.iter().map(|s| s.bytes).sum()
    }

    /// Segment files now.
    pub fn segment_count(&self) -> usize {
        self.segments.len()
    }
}
