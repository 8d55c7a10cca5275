//! When the disk fails (full, read-only, the directory removed): records
//! are held in memory, the segment is cut back to what reached the disk, and
//! every [`RETRY_INTERVAL`](super::RETRY_INTERVAL) the queue tries to write everything it holds;
//! what cannot be kept is counted (see the module doc of [`super`]).

use std::fs::{self, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use tracing::{error, info, warn};

use super::segment::{self, Segment};
use super::{Queue, Writer};

impl Queue {
    /// The disk failed: drop the writer's buffer (those records are in
    /// memory), cut the segment back to what reached the disk, and hold new
    /// records in memory until [`Queue::tick`] can write them.
    pub(super) fn fail(&mut self, why: String) {
        if let Some(w) = self.writer.take() {
            let (count, bytes) = w.flushed;
            let _ = w.out.into_parts();
            if let Some(seg) = self.segments.back_mut() {
                seg.count = count;
                seg.bytes = bytes;
                let _ = segment::truncate(&seg.path, bytes);
            }
            error!(
                "the disk queue in {} fails ({why}): records are kept in memory (at most {} MiB \
                 of them; then the oldest measurements are dropped and counted) until the disk \
                 takes writes again",
                self.dir.display(),
                self.limits.unsaved_bytes / (1024 * 1024)
            );
        }
        self.reader = None;
        self.failing = Some((why, Instant::now()));
    }

    /// A segment could not be read at `i`: its records from `i` on are
    /// counted as lost and the file forgotten. Returns false for the
    /// segment being written: the queue is then rebuilt from memory (its
    /// file removed, so the rebuild counts what memory does not hold).
    pub(super) fn lose_segment(&mut self, seg_first: u64, i: u64, e: &anyhow::Error) -> bool {
        let Some(k) = self.segments.iter().position(|s| s.first == seg_first) else {
            return true;
        };
        if k + 1 == self.segments.len() {
            if let Some(s) = self.segments.back() {
                let _ = fs::remove_file(&s.path);
            }
            self.fail(format!("{e:#}"));
            return false;
        }
        if let Some(s) = self.segments.remove(k) {
            let mem_first = self.mem.front().map_or(self.next, |m| m.0);
            let lost = s.end().min(mem_first).saturating_sub(i);
            warn!(
                "queue segment {} cannot be read ({e:#}): {lost} record(s) lost",
                s.path.display()
            );
            self.dropped += lost;
            self.ack_dirty = true;
            self.reader = None;
            let _ = fs::remove_file(&s.path);
        }
        true
    }

    /// Try the disk again: make the directory if it is gone, write every
    /// record held in memory to a segment, the `ack` file; on success the
    /// queue is healthy again.
    pub(super) fn recover(&mut self) {
        match self.try_recover() {
            Ok((written, lost)) => {
                self.failing = None;
                info!(
                    "the disk queue in {} works again: {written} record(s) written from memory{}",
                    self.dir.display(),
                    if lost > 0 {
                        format!(
                            "; {lost} record(s) that were only in removed files are lost (counted)"
                        )
                    } else {
                        String::new()
                    }
                );
            }
            Err(e) => {
                let first = self.failing.is_none();
                self.failing = Some((format!("{e:#}"), Instant::now()));
                if first {
                    error!("the disk queue in {} fails: {e:#}", self.dir.display());
                }
            }
        }
    }

    fn try_recover(&mut self) -> anyhow::Result<(u64, u64)> {
        fs::create_dir_all(&self.dir)
            .with_context(|| format!("cannot create {}", self.dir.display()))?;
        if !self.dir.join("lock").exists() {
            self._lock = segment::lock(&self.dir)?;
        }
        let mem_first = self.mem.front().map_or(self.next, |m| m.0);
        let mut lost = 0;
        let gone = self
            .segments
            .iter()
            .any(|s| s.count > 0 && !s.path.exists());
        if gone {
            // The files were removed: what memory does not hold is lost.
            lost = mem_first.saturating_sub(self.acked);
            self.dropped += lost;
            self.acked = self.acked.max(mem_first);
            for s in self.segments.drain(..) {
                let _ = fs::remove_file(&s.path);
            }
            self.on_disk = self.acked;
            let on_disk = self.on_disk;
            self.held_bytes = self
                .mem
                .iter()
                .filter(|(i, _)| *i >= on_disk)
                .map(|(_, r)| r.mem_size())
                .sum();
        }
        let start = self.on_disk.max(self.acked);
        let append = self
            .segments
            .back()
            .is_some_and(|s| s.end() == start && s.path.exists());
        if !append {
            self.segments.push_back(Segment::new(&self.dir, start));
        }
        let (path, before) = self
            .segments
            .back()
            .map(|s| (s.path.clone(), (s.count, s.bytes)))
            .unwrap_or_default();
        let written = self.write_held(&path, start).inspect_err(|_| {
            if let Some(seg) = self.segments.back_mut() {
                (seg.count, seg.bytes) = before;
                let _ = segment::truncate(&path, before.1);
            }
        })?;
        self.ack_dirty = true;
        self.write_ack()?;
        Ok((written, lost))
    }

    /// Write the records held in memory from index `start` on to the segment
    /// at `path` (the last one), sync it, and make it the writer's.
    fn write_held(&mut self, path: &Path, start: u64) -> anyhow::Result<u64> {
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .with_context(|| format!("cannot open the queue segment {}", path.display()))?;
        let mut out = BufWriter::with_capacity(64 * 1024, file);
        let (mut count, mut bytes) = (0u64, 0u64);
        for (_, r) in self.mem.iter().filter(|(i, _)| *i >= start) {
            let b = r.encode();
            out.write_all(&b)
                .with_context(|| format!("cannot write {}", path.display()))?;
            count += 1;
            bytes += b.len() as u64;
        }
        out.flush()
            .with_context(|| format!("cannot write {}", path.display()))?;
        out.get_ref().sync_data()?;
        let seg = self
            .segments
            .back_mut()
            .context("the queue has no segment")?;
        seg.count += count;
        seg.bytes += bytes;
        self.writer = Some(Writer {
            out,
            flushed: (seg.count, seg.bytes),
        });
        self.on_disk = self.next;
        self.held_bytes = 0;
        self.trim_mem();
        Ok(count)
    }
}
