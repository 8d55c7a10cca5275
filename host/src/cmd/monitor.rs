//! `foisctl monitor`: the live view of a node, optionally logged to CSV.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use clap::Args;

use super::args::{PortArgs, non_negative};
use crate::monitor::{self, MonitorOptions};

/// `foisctl monitor`.
#[derive(Debug, Args)]
pub struct MonitorArgs {
    /// The serial port of the node.
    #[command(flatten)]
    pub port: PortArgs,
    /// Append every measurement, event, gap and error to this CSV file
    /// (created with a header if new; columns in host/README.md).
    #[arg(long, value_name = "FILE")]
    pub log: Option<PathBuf>,
    /// Stop after this many seconds (default: run until Ctrl-C).
    #[arg(long, allow_negative_numbers = true, value_name = "SECONDS", value_parser = non_negative)]
    pub duration: Option<f64>,
    /// Print a plain status line each second instead of a redrawn one.
    #[arg(long)]
    pub plain: bool,
    /// Also print the protocol's chatter: every answer (`ack ...`) and the
    /// node's full hello (its 24-hex-digit unique id, reset reason).
    #[arg(long)]
    pub verbose: bool,
    /// Do not print the legend of the status lines at the start.
    #[arg(long)]
    pub no_legend: bool,
}

/// Run `foisctl monitor` until `stop`, the duration, or an error that
/// reconnecting cannot fix; prints the totals.
pub fn run(args: MonitorArgs, stop: &AtomicBool) -> anyhow::Result<()> {
    let mut opts = MonitorOptions::new(args.port.port);
    opts.baud = args.port.baud;
    opts.log = args.log;
    opts.plain = args.plain;
    opts.verbose = args.verbose;
    opts.legend = !args.no_legend;
    opts.duration = args.duration.map(Duration::from_secs_f64);
    let sum = monitor::run(&opts, stop)?;
    println!(
        "monitor: {} frames, {} measurements, {} lost, {} rejected, {} disconnect(s){}",
        sum.frames,
        sum.measurements,
        sum.lost,
        sum.rejected,
        sum.disconnects,
        opts.log
            .as_ref()
            .map(|p| format!(", {} rows appended to {}", sum.log_rows, p.display()))
            .unwrap_or_default()
    );
    Ok(())
}
