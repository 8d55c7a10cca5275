//! `foisctl sim montecarlo`: mean and covariance of (I1, I2) over random
//! accretions (thesis §5.4).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use super::args::{ModelOpts, make_config};
use super::figures::plot_mc;
use super::output::{CsvOut, MONTECARLO_HEADER, check_writable, write_montecarlo};
use super::runs::run_mc;
use crate::cmd::args::IceArg;

/// `foisctl sim montecarlo`.
#[derive(Debug, Args)]
pub struct MontecarloArgs {
    /// Medium.
    #[arg(long, value_enum, default_value = "rime")]
    pub ice: IceArg,
    /// Number of accretions M, >= 2.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(2..))]
    pub runs: u64,
    /// The model options.
    #[command(flatten)]
    pub model: ModelOpts,
    /// Output CSV file.
    #[arg(long)]
    pub out: PathBuf,
    /// Also draw samples, means and ±1σ bars (like Fig. 5.17) to this PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// Run `foisctl sim montecarlo`.
pub fn run(args: MontecarloArgs) -> Result<()> {
    let cfg = make_config(args.ice, &args.model)?;
    let out = CsvOut::create(&args.out, &MONTECARLO_HEADER)?;
    check_writable(args.plot.as_deref())?;
    let mc = run_mc(&cfg, args.runs, args.model.seed, args.model.threads)?;
    write_montecarlo(out, &mc.points)?;
    if let Some(p) = &args.plot {
        let title = format!(
            "Monte Carlo: {} ice, {} accretions",
            cfg.ice.name(),
            args.runs
        );
        plot_mc(p, &title, &mc)?;
    }
    Ok(())
}
