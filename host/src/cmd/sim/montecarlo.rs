//! `foisctl sim montecarlo`: mean and covariance of (I1, I2) over random
//! accretions (thesis §5.4).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;

use super::args::McArgs;
use super::figures::plot_mc;
use super::output::{CsvOut, MONTECARLO_HEADER, check_writable, write_montecarlo};
use super::runs::run_mc;

/// `foisctl sim montecarlo`.
#[derive(Debug, Args)]
pub struct MontecarloArgs {
    /// Medium, accretions, model.
    #[command(flatten)]
    pub mc: McArgs,
    /// Output CSV file.
    #[arg(long)]
    pub out: PathBuf,
    /// Also draw samples, means and ±1σ bars (like Fig. 5.17) to this PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// Run `foisctl sim montecarlo`.
pub fn run(args: MontecarloArgs) -> Result<()> {
    let McArgs {
        runs, ref model, ..
    } = args.mc;
    let cfg = args.mc.config()?;
    let out = CsvOut::create(&args.out, &MONTECARLO_HEADER)?;
    check_writable(args.plot.as_deref())?;
    let mc = run_mc(&cfg, runs, model.seed, model.threads)?;
    write_montecarlo(out, &mc.points)?;
    if let Some(p) = &args.plot {
        let title = format!("Monte Carlo: {} ice, {} accretions", cfg.ice.name(), runs);
        plot_mc(p, &title, &mc)?;
        println!("wrote the figure {}", p.display());
    }
    Ok(())
}
