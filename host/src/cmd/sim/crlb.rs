//! `foisctl sim crlb`: the Cramér–Rao lower bound of the thickness from a
//! Monte Carlo (thesis §5.4, Fig. 5.18).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use fois_sim::crlb;
use fois_sim::montecarlo::{DEFAULT_FIT_HALF_WIDTH_MM, fit_quality};

use super::args::McArgs;
use super::figures::plot_crlb;
use super::output::{CRLB_HEADER, CsvOut, check_writable, write_crlb};
use super::runs::{report_fit, run_mc};
use crate::cmd::args::positive;

/// `foisctl sim crlb`.
#[derive(Debug, Args)]
pub struct CrlbArgs {
    /// Medium, accretions, model.
    #[command(flatten)]
    pub mc: McArgs,
    /// Half-width of the local fits of μ(d) and Σ(d), mm (> 0).
    #[arg(long, default_value_t = DEFAULT_FIT_HALF_WIDTH_MM, value_parser = positive)]
    pub fit_half_width_mm: f64,
    /// Output CSV file.
    #[arg(long)]
    pub out: PathBuf,
    /// Also draw the bound to this PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// Run `foisctl sim crlb`.
pub fn run(args: CrlbArgs) -> Result<()> {
    let McArgs {
        runs, ref model, ..
    } = args.mc;
    let cfg = args.mc.config()?;
    let out = CsvOut::create(&args.out, &CRLB_HEADER)?;
    check_writable(args.plot.as_deref())?;
    let t0 = Instant::now();
    let mc = run_mc(&cfg, runs, model.seed, model.threads)?;
    let bound = crlb(&mc.points, args.fit_half_width_mm);
    let q = fit_quality(&mc.points, &bound, runs as usize);
    let dt = t0.elapsed();
    write_crlb(out, &bound)?;
    report_fit(&q, dt.as_secs_f64(), runs);
    if let Some(p) = &args.plot {
        let title = format!("CRLB: {} ice, {} accretions", cfg.ice.name(), runs);
        plot_crlb(p, &title, &bound)?;
    }
    Ok(())
}
