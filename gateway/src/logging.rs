//! Log lines through `tracing`: levels (error, warn, info, debug, trace),
//! filtered like `RUST_LOG` (`tracing_subscriber::EnvFilter`).
//!
//! Where they go (`--log-to`):
//!
//! - `auto` (the default): into the systemd journal when systemd connected
//!   the gateway's output to it (`JOURNAL_STREAM` is set, as it is for a
//!   service) and the journal answers — each entry with its priority
//!   (`journalctl -p warning` shows warnings and errors) and the syslog
//!   identifier `fois-gateway` (`tracing-journald`); otherwise to stdout;
//! - `stdout`: one line per event on stdout, its level first. The journal
//!   (or any collector) stamps lines itself, so timestamps are written only
//!   when stdout is a terminal (`--log-time always|never` decides
//!   otherwise), colours likewise;
//! - `journald`: the journal, or stdout with a warning when it cannot be
//!   reached.

use std::io::IsTerminal;

use clap::ValueEnum;
use tracing_subscriber::EnvFilter;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

/// When log lines carry a timestamp.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LogTime {
    /// Only when stdout is a terminal.
    Auto,
    /// Always (e.g. output redirected to a file).
    Always,
    /// Never (journald, or any collector that stamps lines itself).
    Never,
}

/// Where log entries go.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LogTo {
    /// The journal under systemd (`JOURNAL_STREAM` set and reachable), else stdout.
    Auto,
    /// Lines on stdout.
    Stdout,
    /// The journal (stdout when it cannot be reached).
    Journald,
}

/// The filter: `RUST_LOG` when set, otherwise `info` (`warn` when quiet).
pub fn filter(quiet: bool) -> EnvFilter {
    let default = if quiet { "warn" } else { "info" };
    EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default))
}

/// True when the journal is to be tried: asked for, or `auto` with systemd's
/// `JOURNAL_STREAM` (the `device:inode` of the journal stream it gave us).
pub fn wants_journald(to: LogTo, journal_stream: Option<&str>) -> bool {
    match to {
        LogTo::Journald => true,
        LogTo::Stdout => false,
        LogTo::Auto => journal_stream.is_some_and(|s| !s.is_empty()),
    }
}

/// Install the global subscriber (once, at start). A second call does
/// nothing.
pub fn init(quiet: bool, time: LogTime, to: LogTo) {
    let stream = std::env::var("JOURNAL_STREAM").ok();
    let mut unreachable = None;
    if wants_journald(to, stream.as_deref()) {
        match tracing_journald::layer() {
            Ok(journal) => {
                let journal = journal.with_syslog_identifier("fois-gateway".into());
                let _ = tracing_subscriber::registry()
                    .with(filter(quiet))
                    .with(journal)
                    .try_init();
                return;
            }
            Err(e) => unreachable = Some(e),
        }
    }
    let terminal = std::io::stdout().is_terminal();
    let stamped = match time {
        LogTime::Auto => terminal,
        LogTime::Always => true,
        LogTime::Never => false,
    };
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter(quiet))
        .with_target(false)
        .with_ansi(terminal)
        .with_writer(std::io::stdout);
    let _ = if stamped {
        builder.try_init()
    } else {
        builder.without_time().try_init()
    };
    if let Some(e) = unreachable
        && to == LogTo::Journald
    {
        tracing::warn!("the systemd journal cannot be reached ({e}): logging to stdout");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_journal_is_tried_under_systemd_or_when_asked() {
        assert!(wants_journald(LogTo::Auto, Some("8:12345")));
        assert!(!wants_journald(LogTo::Auto, None));
        assert!(!wants_journald(LogTo::Auto, Some("")));
        assert!(!wants_journald(LogTo::Stdout, Some("8:12345")));
        assert!(wants_journald(LogTo::Journald, None));
    }
}
