//! Log lines through `tracing`: levels (error, warn, info, debug, trace),
//! filtered like `RUST_LOG` (`tracing_subscriber::EnvFilter`), written to
//! stdout one event per line. Under systemd, journald stamps every line
//! with its own time, so by default the gateway writes timestamps only when
//! stdout is a terminal (`--log-time always|never` decides otherwise), and
//! colours only on a terminal.

use std::io::IsTerminal;

use clap::ValueEnum;
use tracing_subscriber::EnvFilter;

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

/// The filter: `RUST_LOG` when set, otherwise `info` (`warn` when quiet).
pub fn filter(quiet: bool) -> EnvFilter {
    let default = if quiet { "warn" } else { "info" };
    EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default))
}

/// Install the global subscriber (once, at start). A second call does
/// nothing.
pub fn init(quiet: bool, time: LogTime) {
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
}
