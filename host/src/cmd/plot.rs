//! `foisctl plot`: a log's currents over time as a PNG.

use std::path::PathBuf;

use clap::Args;

use crate::plot::log::{TimeAxis, plot_log};

/// `foisctl plot`.
#[derive(Debug, Args)]
pub struct PlotArgs {
    /// A `foisctl monitor` CSV log.
    #[arg(long, value_name = "FILE")]
    pub log: PathBuf,
    /// The PNG to write.
    #[arg(long, value_name = "FILE.png")]
    pub out: PathBuf,
    /// Time axis: host (host clock since the first row) or node (node
    /// uptime: the virtual time of a virtual node).
    #[arg(long, value_enum, default_value = "host")]
    pub time: TimeAxis,
}

/// Run `foisctl plot`.
pub fn run(args: PlotArgs) -> anyhow::Result<()> {
    let n = plot_log(&args.log, &args.out, args.time)?;
    println!("{n} measurements drawn to {}", args.out.display());
    Ok(())
}
