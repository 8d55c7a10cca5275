//! `foisctl sim curve`: trace accretions, one CSV row per run and thickness.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use super::args::{ModelOpts, make_config};
use super::figures::plot_curves;
use super::output::{CURVE_HEADER, CsvOut, check_writable, write_curves};
use super::runs::trace_runs;
use crate::cmd::args::IceArg;

/// `foisctl sim curve`.
#[derive(Debug, Args)]
pub struct CurveArgs {
    /// Medium: flat, glazed, rime or water.
    #[arg(long, value_enum)]
    pub ice: IceArg,
    /// Number of accretions (runs 0..N of the seed), >= 1.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub runs: u64,
    /// The model options.
    #[command(flatten)]
    pub model: ModelOpts,
    /// Output CSV file.
    #[arg(long)]
    pub out: PathBuf,
    /// Also draw the curves to this PNG (800×500).
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// Run `foisctl sim curve`.
pub fn run(args: CurveArgs) -> Result<()> {
    let cfg = make_config(args.ice, &args.model)?;
    let out = CsvOut::create(&args.out, &CURVE_HEADER)?;
    check_writable(args.plot.as_deref())?;
    let curves = trace_runs(&cfg, args.runs, args.model.seed, args.model.threads)?;
    write_curves(out, &curves)?;
    if let Some(p) = &args.plot {
        let title = format!(
            "{} ice, sensor {:?}, {}: {} run(s)",
            cfg.ice.name(),
            cfg.sensor,
            cfg.geometry.name(),
            args.runs
        );
        plot_curves(p, &title, &curves, args.runs == 1)?;
        println!("wrote the figure {}", p.display());
    }
    Ok(())
}
