//! The season's data on the gateway's disk (`[log] dir = …`): every node's
//! frames as daily CSV files in `foisctl monitor`'s format, so
//! `foisctl icing-report` (and `plot`, `estimate`) run on fleet data
//! without Home Assistant.
//!
//! The runtime thread only turns a node report into rows
//! ([`rows_of`], the rows `foisctl monitor` would log) and hands them to
//! the log's own thread over a bounded channel, never waiting: when the
//! disk is so slow that the channel fills, rows are dropped and counted.
//! The thread ([`daily::DailyFiles`]) writes, flushes every second,
//! compresses a finished day after midnight UTC and deletes days beyond
//! the days kept. A disk error is logged (at most once a minute, with the
//! count of those not shown) and never stops the gateway.

pub mod daily;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use fois_link::log_row::Row;
use fois_protocol::SeqEvent;
use tracing::{info, warn};

use crate::config::LogConfig;
use crate::reader::{NodeMsg, NodeUpdate};

use daily::DailyFiles;

/// Rows waiting for the disk at most (about 40 s of 100 nodes at 10 Hz).
pub const CHANNEL_ROWS: usize = 1 << 15;
/// Buffered rows reach the kernel at least this often.
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);
/// A disk error is logged at most this often.
pub const ERROR_EVERY: Duration = Duration::from_secs(60);

/// The clock of the log's thread: Unix ms (tests inject their own).
pub type Clock = Arc<dyn Fn() -> u64 + Send + Sync>;

/// The rows `foisctl monitor` logs for a node report: a gap or restart
/// note, then the frame's row; link up and lost; rejected frames.
/// Command results are the gateway's, not the node's: none.
pub fn rows_of(m: &NodeMsg) -> Vec<Row> {
    let t = m.host_unix_ms;
    let at = |r: Row| Row {
        host_unix_ms: t,
        ..r
    };
    match &m.update {
        NodeUpdate::Frame(f, ev) => {
            let mut rows = Vec::with_capacity(2);
            match ev {
                SeqEvent::Gap(n) => rows.push(at(Row::gap(f.seq, *n))),
                SeqEvent::Restart => rows.push(at(Row {
                    seq: Some(f.seq),
                    ..Row::note("node_restart", "sequence number went backwards")
                })),
                _ => {}
            }
            rows.push(at(Row::device(f.seq, &f.msg)));
            rows
        }
        NodeUpdate::Up(h) => vec![at(Row::note("link_up", fois_link::text::hello_text(h)))],
        NodeUpdate::Down(reason) => vec![at(Row::note("link_lost", reason.clone()))],
        NodeUpdate::Rejected => vec![at(Row::note("rejected", "frame rejected by the decoder"))],
        NodeUpdate::UpdateDone { ok, detail } => vec![at(Row::note(
            if *ok { "update_done" } else { "update_failed" },
            detail.clone(),
        ))],
        NodeUpdate::Unreachable(_)
        | NodeUpdate::CommandResult { .. }
        | NodeUpdate::Update(_)
        | NodeUpdate::RolloutEnd(_) => Vec::new(),
    }
}

/// Logs at most once per [`ERROR_EVERY`], counting what it holds back.
#[derive(Debug, Default)]
pub struct ErrorLimiter {
    last: Option<Instant>,
    held_back: u64,
}

impl ErrorLimiter {
    /// The line to log for `error` at `now`, or `None` (held back).
    pub fn admit(&mut self, error: &str, now: Instant) -> Option<String> {
        if self
            .last
            .is_some_and(|l| now.saturating_duration_since(l) < ERROR_EVERY)
        {
            self.held_back += 1;
            return None;
        }
        self.last = Some(now);
        let more = std::mem::take(&mut self.held_back);
        Some(if more > 0 {
            format!("{error} ({more} more log error(s) since the last one shown)")
        } else {
            error.to_string()
        })
    }
}

enum Msg {
    Rows(String, Vec<Row>),
}

/// The handle of the log's thread.
pub struct SeasonLog {
    tx: Option<SyncSender<Msg>>,
    thread: Option<JoinHandle<()>>,
    dropped: Arc<AtomicU64>,
    written: Arc<AtomicU64>,
    limiter: ErrorLimiter,
}

impl SeasonLog {
    /// Start the log's thread with the system clock.
    pub fn start(cfg: &LogConfig) -> anyhow::Result<SeasonLog> {
        Self::start_with_clock(cfg, Arc::new(fois_link::timefmt::unix_ms_now))
    }

    /// Start the log's thread with `clock` (tests: an injected clock).
    pub fn start_with_clock(cfg: &LogConfig, clock: Clock) -> anyhow::Result<SeasonLog> {
        let (tx, rx) = std::sync::mpsc::sync_channel(CHANNEL_ROWS);
        let written = Arc::new(AtomicU64::new(0));
        let files = DailyFiles::new(cfg.dir.clone(), cfg.days_kept);
        let w = written.clone();
        let thread = std::thread::Builder::new()
            .name("season-log".into())
            .spawn(move || writer(files, rx, clock, w))?;
        info!(
            "logging every node's frames to daily CSV files under {} ({} day(s) kept, compressed after the day)",
            cfg.dir.display(),
            cfg.days_kept
        );
        Ok(SeasonLog {
            tx: Some(tx),
            thread: Some(thread),
            dropped: Arc::new(AtomicU64::new(0)),
            written,
            limiter: ErrorLimiter::default(),
        })
    }

    /// Hand `rows` of the node named `node` to the log's thread (never
    /// waits; rows are dropped and counted when it lags far behind).
    pub fn record(&mut self, node: &str, rows: Vec<Row>) {
        if rows.is_empty() {
            return;
        }
        let n = rows.len() as u64;
        let Some(tx) = &self.tx else {
            return;
        };
        match tx.try_send(Msg::Rows(node.to_string(), rows)) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                let total = self.dropped.fetch_add(n, Ordering::Relaxed) + n;
                if let Some(line) = self.limiter.admit(
                    &format!("daily log: the disk lags behind, {total} row(s) dropped so far"),
                    Instant::now(),
                ) {
                    warn!("{line}");
                }
            }
        }
    }

    /// Rows dropped because the log's thread lagged.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Rows written to files.
    pub fn written(&self) -> u64 {
        self.written.load(Ordering::Relaxed)
    }

    /// Write what is queued, flush, stop the thread.
    pub fn stop(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        drop(self.tx.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for SeasonLog {
    fn drop(&mut self) {
        self.shutdown();
    }
}

fn report(e: &dyn std::fmt::Display, limiter: &mut ErrorLimiter) {
    if let Some(line) = limiter.admit(&format!("daily log: {e}"), Instant::now()) {
        warn!("{line}");
    }
}

fn writer(mut files: DailyFiles, rx: Receiver<Msg>, clock: Clock, written: Arc<AtomicU64>) {
    let mut limiter = ErrorLimiter::default();
    for e in files.housekeeping(clock()) {
        report(&e, &mut limiter);
    }
    let mut last_flush = Instant::now();
    loop {
        match rx.recv_timeout(FLUSH_EVERY) {
            Ok(Msg::Rows(node, rows)) => {
                for r in &rows {
                    if let Err(e) = files.write(&node, r) {
                        report(&e, &mut limiter);
                    }
                }
                written.store(files.rows, Ordering::Relaxed);
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if last_flush.elapsed() >= FLUSH_EVERY {
            last_flush = Instant::now();
            if let Err(e) = files.flush() {
                report(&e, &mut limiter);
            }
            for e in files.housekeeping(clock()) {
                report(&e, &mut limiter);
            }
        }
    }
    for e in files.housekeeping(clock()) {
        report(&e, &mut limiter);
    }
    if let Err(e) = files.close_all() {
        report(&e, &mut limiter);
    }
    written.store(files.rows, Ordering::Relaxed);
}

#[cfg(test)]
mod tests;
