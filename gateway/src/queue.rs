//! The store-and-forward queue: every event and every measurement the
//! gateway decides to publish is first appended here, then published (QoS 1)
//! from here, and forgotten only once the broker has acknowledged it. While
//! the broker is unreachable the records simply wait; after a crash they are
//! read back and sent again.
//!
//! ## On disk
//!
//! A directory of append-only segment files `<first index, 20 digits>.seg`
//! and a small `ack` file:
//!
//! - a record is `len: u32 LE | crc32(body): u32 LE | body`, the body being
//!   `topic_len: u16 LE | topic (UTF-8) | payload`; records are numbered from
//!   the segment's first index on; a record cut short by a kill (or whose CRC
//!   fails) ends its segment and is cut off when the queue is opened;
//! - `ack` holds `acked N` (every record below index N was acknowledged by
//!   the broker) and `dropped M` (records discarded by the bound, ever); it is
//!   replaced atomically (write + rename). A missing or unreadable `ack` file
//!   means "nothing acknowledged": records are sent again, never lost;
//! - a segment whose records are all acknowledged is deleted.
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
//! ## Bound
//!
//! The segment files never hold more than `max_bytes` (plus the one segment
//! being written): when they would, the oldest segment is deleted, its
//! unacknowledged records are counted in [`Queue::dropped`], and sending goes
//! on with the oldest record left. Segments are `max_bytes / 16` (16 KiB to
//! 16 MiB), so a drop discards about 1/16 of the queue at once.

use std::collections::VecDeque;
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;

/// The segment file is synced to disk at least this often.
pub const SYNC_INTERVAL: Duration = Duration::from_secs(1);
/// The `ack` file is rewritten at most this often.
pub const ACK_WRITE_INTERVAL: Duration = Duration::from_millis(200);
/// The largest record accepted (a corrupt length above it ends a segment).
pub const MAX_RECORD_BYTES: usize = 1 << 20;

const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
const HEADER_BYTES: u64 = 8;

/// One queued message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Record {
    /// MQTT topic.
    pub topic: String,
    /// Payload (JSON).
    pub payload: Vec<u8>,
}

impl Record {
    fn encode(&self) -> Vec<u8> {
        let topic = self.topic.as_bytes();
        let topic_len = u16::try_from(topic.len()).unwrap_or(u16::MAX);
        let topic = &topic[..usize::from(topic_len)];
        let mut body = Vec::with_capacity(2 + topic.len() + self.payload.len());
        body.extend_from_slice(&topic_len.to_le_bytes());
        body.extend_from_slice(topic);
        body.extend_from_slice(&self.payload);
        let mut out = Vec::with_capacity(8 + body.len());
        out.extend_from_slice(&(body.len() as u32).to_le_bytes());
        out.extend_from_slice(&CRC.checksum(&body).to_le_bytes());
        out.extend_from_slice(&body);
        out
    }

    fn decode(body: &[u8]) -> Option<Record> {
        let (len, rest) = body.split_first_chunk::<2>()?;
        let len = usize::from(u16::from_le_bytes(*len));
        let topic = rest.get(..len)?;
        let payload = rest.get(len..)?;
        Some(Record {
            topic: String::from_utf8(topic.to_vec()).ok()?,
            payload: payload.to_vec(),
        })
    }

    fn mem_size(&self) -> usize {
        self.topic.len() + self.payload.len() + 64
    }
}

/// Read one record; `Ok(None)` at a clean end, `Err` on a torn or corrupt one.
fn read_record(r: &mut impl Read) -> io::Result<Option<(Record, u64)>> {
    let mut head = [0u8; 8];
    let mut got = 0;
    while got < head.len() {
        match r.read(&mut head[got..])? {
            0 if got == 0 => return Ok(None),
            0 => return Err(io::ErrorKind::UnexpectedEof.into()),
            n => got += n,
        }
    }
    let len = u32::from_le_bytes([head[0], head[1], head[2], head[3]]) as usize;
    let crc = u32::from_le_bytes([head[4], head[5], head[6], head[7]]);
    if len > MAX_RECORD_BYTES {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            "record too long",
        ));
    }
    let mut body = vec![0u8; len];
    r.read_exact(&mut body)?;
    if CRC.checksum(&body) != crc {
        return Err(io::Error::new(io::ErrorKind::InvalidData, "CRC mismatch"));
    }
    let rec = Record::decode(&body)
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidData, "bad record body"))?;
    Ok(Some((rec, HEADER_BYTES + len as u64)))
}

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
}

impl QueueLimits {
    /// Limits for a bound of `max_bytes`.
    pub fn for_max_bytes(max_bytes: u64) -> QueueLimits {
        QueueLimits {
            max_bytes,
            segment_bytes: (max_bytes / 16).clamp(16 * 1024, 16 * 1024 * 1024),
            mem_bytes: 8 * 1024 * 1024,
        }
    }
}

#[derive(Debug)]
struct Segment {
    first: u64,
    count: u64,
    bytes: u64,
    path: PathBuf,
}

impl Segment {
    fn end(&self) -> u64 {
        self.first + self.count
    }
}

struct SegReader {
    seg_first: u64,
    next: u64,
    file: BufReader<File>,
}

/// What opening found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Recovery {
    /// Records waiting to be published.
    pub pending: u64,
    /// Bytes cut off torn or corrupt segment tails.
    pub truncated_bytes: u64,
}

/// The queue.
pub struct Queue {
    dir: PathBuf,
    limits: QueueLimits,
    segments: VecDeque<Segment>,
    writer: BufWriter<File>,
    next: u64,
    acked: u64,
    dropped: u64,
    unflushed: bool,
    unsynced: bool,
    last_sync: Instant,
    ack_dirty: bool,
    last_ack_write: Instant,
    mem: VecDeque<(u64, Record)>,
    mem_bytes: usize,
    reader: Option<SegReader>,
}

fn seg_path(dir: &Path, first: u64) -> PathBuf {
    dir.join(format!("{first:020}.seg"))
}

fn parse_ack(text: &str) -> Option<(u64, u64)> {
    let mut acked = None;
    let mut dropped = None;
    for line in text.lines() {
        match line.split_once(' ') {
            Some(("acked", v)) => acked = v.trim().parse().ok(),
            Some(("dropped", v)) => dropped = v.trim().parse().ok(),
            _ => {}
        }
    }
    Some((acked?, dropped?))
}

impl Queue {
    /// Open (or create) the queue in `dir`: recover the segments, cut off a
    /// torn tail, read the acknowledged offset.
    pub fn open(dir: &Path, limits: QueueLimits) -> anyhow::Result<(Queue, Recovery)> {
        fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the queue directory {}", dir.display()))?;
        let ack = fs::read_to_string(dir.join("ack"))
            .ok()
            .and_then(|t| parse_ack(&t));
        let mut firsts: Vec<u64> = fs::read_dir(dir)
            .with_context(|| format!("cannot read the queue directory {}", dir.display()))?
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().into_string().ok()?;
                name.strip_suffix(".seg")?.parse::<u64>().ok()
            })
            .collect();
        firsts.sort_unstable();
        let mut rec = Recovery::default();
        let mut segments = VecDeque::new();
        for first in firsts {
            let path = seg_path(dir, first);
            let (count, bytes, file_len) = scan_segment(&path)?;
            if bytes < file_len {
                rec.truncated_bytes += file_len - bytes;
                OpenOptions::new()
                    .write(true)
                    .open(&path)
                    .and_then(|f| f.set_len(bytes))
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
            segments.push_back(Segment {
                first: next,
                count: 0,
                bytes: 0,
                path: seg_path(dir, next),
            });
        }
        let cur = segments.back().map(|s| s.path.clone()).unwrap_or_default();
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&cur)
            .with_context(|| format!("cannot open the queue segment {}", cur.display()))?;
        rec.pending = next - acked;
        let now = Instant::now();
        let mut q = Queue {
            dir: dir.to_path_buf(),
            limits,
            segments,
            writer: BufWriter::with_capacity(64 * 1024, file),
            next,
            acked,
            dropped,
            unflushed: false,
            unsynced: false,
            last_sync: now,
            ack_dirty: true,
            last_ack_write: now - ACK_WRITE_INTERVAL,
            mem: VecDeque::new(),
            mem_bytes: 0,
            reader: None,
        };
        q.write_ack()?;
        Ok((q, rec))
    }

    /// Append a record; returns its index.
    pub fn push(&mut self, rec: Record) -> anyhow::Result<u64> {
        let bytes = rec.encode();
        self.writer
            .write_all(&bytes)
            .with_context(|| format!("cannot write the queue in {}", self.dir.display()))?;
        self.unflushed = true;
        self.unsynced = true;
        let index = self.next;
        self.next += 1;
        if let Some(seg) = self.segments.back_mut() {
            seg.count += 1;
            seg.bytes += bytes.len() as u64;
        }
        self.mem_bytes += rec.mem_size();
        self.mem.push_back((index, rec));
        while self.mem_bytes > self.limits.mem_bytes {
            match self.mem.pop_front() {
                Some((_, r)) => self.mem_bytes -= r.mem_size(),
                None => break,
            }
        }
        if self
            .segments
            .back()
            .is_some_and(|s| s.bytes >= self.limits.segment_bytes)
        {
            self.roll()?;
        }
        self.enforce_bound();
        Ok(index)
    }

    fn roll(&mut self) -> anyhow::Result<()> {
        self.writer.flush()?;
        self.writer.get_ref().sync_data()?;
        let path = seg_path(&self.dir, self.next);
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .with_context(|| format!("cannot open the queue segment {}", path.display()))?;
        self.writer = BufWriter::with_capacity(64 * 1024, file);
        self.unflushed = false;
        self.unsynced = false;
        self.last_sync = Instant::now();
        self.segments.push_back(Segment {
            first: self.next,
            count: 0,
            bytes: 0,
            path,
        });
        Ok(())
    }

    fn enforce_bound(&mut self) {
        while self.segments.len() > 1 && self.bytes() > self.limits.max_bytes {
            let Some(s) = self.segments.pop_front() else {
                break;
            };
            let lost = s.end().saturating_sub(self.acked.max(s.first));
            self.dropped += lost;
            self.acked = self.acked.max(s.end());
            self.ack_dirty = true;
            if self.reader.as_ref().is_some_and(|r| r.seg_first == s.first) {
                self.reader = None;
            }
            let _ = fs::remove_file(&s.path);
        }
        self.trim_mem();
    }

    fn trim_mem(&mut self) {
        while self.mem.front().is_some_and(|(i, _)| *i < self.acked) {
            if let Some((_, r)) = self.mem.pop_front() {
                self.mem_bytes -= r.mem_size();
            }
        }
    }

    /// The first record at index `from` or later that is not acknowledged
    /// (holes left by a corrupt segment are skipped), with its index.
    pub fn get(&mut self, from: u64) -> anyhow::Result<Option<(u64, Record)>> {
        let mut i = from.max(self.acked);
        if i >= self.next {
            return Ok(None);
        }
        if let Some((first, _)) = self.mem.front()
            && *first <= i
        {
            let (idx, r) = &self.mem[(i - first) as usize];
            return Ok(Some((*idx, r.clone())));
        }
        // Older than the memory holds: read the segment files.
        if self.unflushed {
            self.writer.flush()?;
            self.unflushed = false;
        }
        let Some(seg) = self.segments.iter().find(|s| s.end() > i && s.count > 0) else {
            return Ok(None);
        };
        i = i.max(seg.first);
        let (seg_first, seg_path) = (seg.first, seg.path.clone());
        let usable = self
            .reader
            .as_ref()
            .is_some_and(|r| r.seg_first == seg_first && r.next <= i);
        if !usable {
            let mut f = File::open(&seg_path)
                .with_context(|| format!("cannot read the queue segment {}", seg_path.display()))?;
            f.seek(SeekFrom::Start(0))?;
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
                .with_context(|| format!("queue segment {} is damaged", seg_path.display()))?;
            let Some((rec, _)) = got else {
                self.reader = None;
                anyhow::bail!(
                    "queue segment {} ends before record {i}",
                    seg_path.display()
                );
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
    /// when due. Call every 100 ms or so.
    pub fn tick(&mut self) -> anyhow::Result<()> {
        if self.unflushed {
            self.writer.flush().context("cannot write the queue")?;
            self.unflushed = false;
        }
        if self.unsynced && self.last_sync.elapsed() >= SYNC_INTERVAL {
            self.writer.get_ref().sync_data()?;
            self.unsynced = false;
            self.last_sync = Instant::now();
        }
        if self.ack_dirty && self.last_ack_write.elapsed() >= ACK_WRITE_INTERVAL {
            self.write_ack()?;
        }
        Ok(())
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

    /// Flush, sync and record the acknowledged offset (clean shutdown).
    pub fn close(mut self) -> anyhow::Result<()> {
        self.writer.flush()?;
        self.writer.get_ref().sync_data()?;
        self.write_ack()
    }

    /// Index the next record will get.
    pub fn next_index(&self) -> u64 {
        self.next
    }

    /// Every record below this was acknowledged (or dropped).
    pub fn acked(&self) -> u64 {
        self.acked
    }

    /// Records not yet acknowledged.
    pub fn pending(&self) -> u64 {
        self.next - self.acked
    }

    /// Records dropped by the bound, ever (kept in the `ack` file).
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

/// Count the valid records of a segment: (records, valid bytes, file bytes).
fn scan_segment(path: &Path) -> anyhow::Result<(u64, u64, u64)> {
    let f = File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let file_len = f.metadata()?.len();
    let mut r = BufReader::with_capacity(64 * 1024, f);
    let (mut count, mut bytes) = (0u64, 0u64);
    while let Ok(Some((_, n))) = read_record(&mut r) {
        count += 1;
        bytes += n;
    }
    Ok((count, bytes, file_len))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(i: u64) -> Record {
        Record {
            topic: format!("fois/gw/n{}/event", i % 3),
            payload: format!(
                "{{\"seq\":{i},\"pad\":\"{}\"}}",
                "x".repeat((i % 50) as usize)
            )
            .into_bytes(),
        }
    }

    fn small(max: u64) -> QueueLimits {
        QueueLimits {
            max_bytes: max,
            segment_bytes: max / 8,
            mem_bytes: 2048,
        }
    }

    fn drain(q: &mut Queue) -> Vec<(u64, Record)> {
        let mut out = vec![];
        let mut at = q.acked();
        while let Some((i, r)) = q.get(at).unwrap() {
            out.push((i, r));
            at = i + 1;
        }
        out
    }

    #[test]
    fn records_come_back_in_order_from_memory_and_disk_and_after_reopen() {
        let dir = tempfile::tempdir().unwrap();
        let (mut q, rec0) = Queue::open(dir.path(), small(1 << 20)).unwrap();
        assert_eq!(rec0.pending, 0);
        for i in 0..500 {
            assert_eq!(q.push(rec(i)).unwrap(), i);
        }
        // 2 KiB of memory holds only the newest few: most come from disk.
        assert!(q.mem.len() < 50, "{}", q.mem.len());
        let got = drain(&mut q);
        assert_eq!(got.len(), 500);
        for (k, (i, r)) in got.iter().enumerate() {
            assert_eq!(*i, k as u64);
            assert_eq!(*r, rec(k as u64));
        }
        q.ack_through(200);
        q.close().unwrap();
        let (mut q, r) = Queue::open(dir.path(), small(1 << 20)).unwrap();
        assert_eq!(r.pending, 300);
        assert_eq!(q.acked(), 200);
        let got = drain(&mut q);
        assert_eq!(got.first().map(|g| g.0), Some(200));
        assert_eq!(got.last().map(|g| g.0), Some(499));
        assert_eq!(q.push(rec(500)).unwrap(), 500, "indexes continue");
    }

    #[test]
    fn a_torn_tail_is_cut_and_what_was_ticked_survives_a_kill() {
        let dir = tempfile::tempdir().unwrap();
        let (mut q, _) = Queue::open(dir.path(), small(1 << 20)).unwrap();
        for i in 0..40 {
            q.push(rec(i)).unwrap();
        }
        q.tick().unwrap(); // 40 records reach the kernel
        for i in 40..45 {
            q.push(rec(i)).unwrap(); // these stay in the process's buffer
        }
        std::mem::forget(q); // SIGKILL: no destructor, no flush
        // And a half-written record at the end of the segment.
        let seg = fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|x| x == "seg"))
            .unwrap();
        let mut f = OpenOptions::new().append(true).open(&seg).unwrap();
        f.write_all(&rec(999).encode()[..20]).unwrap();
        drop(f);
        let (mut q, r) = Queue::open(dir.path(), small(1 << 20)).unwrap();
        assert_eq!(r.pending, 40);
        assert_eq!(r.truncated_bytes, 20);
        let got = drain(&mut q);
        assert_eq!(got.len(), 40);
        assert_eq!(got[39].1, rec(39));
        assert_eq!(q.push(rec(40)).unwrap(), 40);
        assert_eq!(drain(&mut q).len(), 41);
    }

    #[test]
    fn a_corrupt_record_ends_its_segment_and_is_not_delivered() {
        let dir = tempfile::tempdir().unwrap();
        let (mut q, _) = Queue::open(dir.path(), small(1 << 20)).unwrap();
        for i in 0..10 {
            q.push(rec(i)).unwrap();
        }
        q.close().unwrap();
        let seg = seg_path(dir.path(), 0);
        let mut bytes = fs::read(&seg).unwrap();
        let at = rec(0).encode().len() + rec(1).encode().len() + 12;
        bytes[at] ^= 0xff; // inside record 2's body: its CRC fails
        fs::write(&seg, &bytes).unwrap();
        let (mut q, r) = Queue::open(dir.path(), small(1 << 20)).unwrap();
        assert_eq!(r.pending, 2);
        let got = drain(&mut q);
        assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), vec![0, 1]);
    }

    #[test]
    fn the_bound_drops_the_oldest_and_counts_them() {
        let dir = tempfile::tempdir().unwrap();
        let limits = small(64 * 1024);
        let (mut q, _) = Queue::open(dir.path(), limits).unwrap();
        let n = 3000u64;
        for i in 0..n {
            q.push(rec(i)).unwrap();
            assert!(
                q.bytes() <= limits.max_bytes + limits.segment_bytes + 200,
                "{} bytes",
                q.bytes()
            );
        }
        let got = drain(&mut q);
        assert!(q.dropped() > 0);
        assert_eq!(
            q.dropped() + got.len() as u64,
            n,
            "every record is either kept or counted"
        );
        // What is left is the newest, contiguous, in order.
        assert_eq!(got.last().unwrap().0, n - 1);
        assert!(got.windows(2).all(|w| w[1].0 == w[0].0 + 1));
        assert_eq!(got[0].0, q.dropped());
        // The counter survives a restart.
        let dropped = q.dropped();
        q.close().unwrap();
        let (q, _) = Queue::open(dir.path(), limits).unwrap();
        assert_eq!(q.dropped(), dropped);
    }

    #[test]
    fn acknowledged_segments_are_deleted() {
        let dir = tempfile::tempdir().unwrap();
        let (mut q, _) = Queue::open(dir.path(), small(256 * 1024)).unwrap();
        for i in 0..2000 {
            q.push(rec(i)).unwrap();
        }
        let before = q.segment_count();
        assert!(before > 3, "{before}");
        q.ack_through(2000);
        assert_eq!(q.segment_count(), 1);
        assert_eq!(q.pending(), 0);
        let files = fs::read_dir(dir.path())
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "seg"))
            })
            .count();
        assert_eq!(files, 1);
        assert_eq!(q.get(0).unwrap(), None);
    }

    #[test]
    fn an_unreadable_ack_file_resends_rather_than_loses() {
        let dir = tempfile::tempdir().unwrap();
        let (mut q, _) = Queue::open(dir.path(), small(1 << 20)).unwrap();
        for i in 0..10 {
            q.push(rec(i)).unwrap();
        }
        q.ack_through(6);
        q.close().unwrap();
        fs::write(dir.path().join("ack"), "garbage").unwrap();
        let (q, r) = Queue::open(dir.path(), small(1 << 20)).unwrap();
        assert_eq!(r.pending, 10);
        assert_eq!(q.acked(), 0);
    }
}
