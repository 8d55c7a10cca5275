//! The queue on disk: records, segment files, the `ack` file, the lock.
//!
//! A record is `len: u32 LE | crc32(body): u32 LE | body`, the body being
//! `topic_len: u16 LE | topic (UTF-8) | payload`; records are numbered from
//! their segment's first index on (the file name, 20 digits, `.seg`). A
//! record with an empty topic is a *tombstone*: a measurement the queue
//! had to drop, kept as a place holder so the numbering stays contiguous.
//! A record cut short by a kill (or whose CRC fails) ends its segment.

use std::fs::{File, OpenOptions};
use std::io::{self, BufReader, Read};
use std::path::{Path, PathBuf};

use anyhow::Context;

/// The largest record accepted (a corrupt length above it ends a segment).
pub const MAX_RECORD_BYTES: usize = 1 << 20;

const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
pub(super) const HEADER_BYTES: u64 = 8;

/// One queued message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Record {
    /// MQTT topic (empty: a tombstone).
    pub topic: String,
    /// Payload (JSON).
    pub payload: Vec<u8>,
}

impl Record {
    /// The place holder of a dropped record.
    pub fn tombstone() -> Record {
        Record {
            topic: String::new(),
            payload: Vec::new(),
        }
    }

    /// True for the place holder of a dropped record.
    pub fn is_tombstone(&self) -> bool {
        self.topic.is_empty()
    }

    /// True for a measurement (what the queue drops first; never an event).
    pub fn is_measurement(&self) -> bool {
        self.topic.ends_with("/measurement")
    }

    pub(super) fn encode(&self) -> Vec<u8> {
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

    /// Bytes the record takes in memory (its share of the queue's caches).
    pub(super) fn mem_size(&self) -> usize {
        self.topic.len() + self.payload.len() + 64
    }
}

/// Read one record; `Ok(None)` at a clean end, `Err` on a torn or corrupt one.
pub(super) fn read_record(r: &mut impl Read) -> io::Result<Option<(Record, u64)>> {
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

/// One segment file.
#[derive(Debug)]
pub(super) struct Segment {
    pub first: u64,
    pub count: u64,
    pub bytes: u64,
    pub path: PathBuf,
}

impl Segment {
    pub fn new(dir: &Path, first: u64) -> Segment {
        Segment {
            first,
            count: 0,
            bytes: 0,
            path: seg_path(dir, first),
        }
    }

    pub fn end(&self) -> u64 {
        self.first + self.count
    }
}

/// A reader positioned in a segment.
pub(super) struct SegReader {
    pub seg_first: u64,
    pub next: u64,
    pub file: BufReader<File>,
}

pub(super) fn seg_path(dir: &Path, first: u64) -> PathBuf {
    dir.join(format!("{first:020}.seg"))
}

/// The first indexes of the segment files in `dir`, in order.
pub(super) fn segment_firsts(dir: &Path) -> anyhow::Result<Vec<u64>> {
    let mut firsts: Vec<u64> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read the queue directory {}", dir.display()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            name.strip_suffix(".seg")?.parse::<u64>().ok()
        })
        .collect();
    firsts.sort_unstable();
    Ok(firsts)
}

/// Count the valid records of a segment: (records, valid bytes, file bytes).
pub(super) fn scan_segment(path: &Path) -> anyhow::Result<(u64, u64, u64)> {
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

/// Cut a segment file to `len` bytes (a torn tail, unflushed records).
pub(super) fn truncate(path: &Path, len: u64) -> io::Result<()> {
    OpenOptions::new().write(true).open(path)?.set_len(len)
}

/// The `ack` file: `acked N` and `dropped M`.
pub(super) fn parse_ack(text: &str) -> Option<(u64, u64)> {
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

/// The queue directory's lock: held (an advisory `flock`) as long as the
/// queue is open, so a second gateway on the same directory is refused at
/// start instead of interleaving its records with this one's.
pub(super) fn lock(dir: &Path) -> anyhow::Result<File> {
    use std::io::Write;
    let path = dir.join("lock");
    let mut f = OpenOptions::new()
        .create(true)
        .truncate(false)
        .read(true)
        .write(true)
        .open(&path)
        .with_context(|| format!("cannot open {}", path.display()))?;
    match f.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            let mut owner = String::new();
            let _ = f.read_to_string(&mut owner);
            anyhow::bail!(
                "the queue directory {} is in use by another running gateway ({}): two \
                 gateways must not share a queue (nor a name); give each its own `name` and \
                 [queue] dir",
                dir.display(),
                owner.trim()
            );
        }
        Err(std::fs::TryLockError::Error(e)) => {
            return Err(e).with_context(|| format!("cannot lock {}", path.display()));
        }
    }
    f.set_len(0)?;
    writeln!(f, "pid {}", std::process::id())?;
    Ok(f)
}
