//! `foisctl sim crlb`: the Cramér–Rao lower bound of the thickness from a
//! Monte Carlo (thesis §5.4, Fig. 5.18); with `--gain-sd`, beside it the bound
//! when the gain is an unknown nuisance parameter (`fois_sim::gain`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use fois_sim::crlb;
use fois_sim::gain::crlb_gain_unknown;
use fois_sim::montecarlo::{DEFAULT_FIT_HALF_WIDTH_MM, fit_quality};

use super::args::McArgs;
use super::figures::plot_crlb;
use super::output::{CRLB_GAIN_HEADER, CRLB_HEADER, CsvOut, check_writable, write_crlb};
use super::runs::{report_fit, run_mc};
use crate::cmd::args::{non_negative, positive};

/// `foisctl sim crlb`.
#[derive(Debug, Args)]
pub struct CrlbArgs {
    /// Medium, accretions, model.
    #[command(flatten)]
    pub mc: McArgs,
    /// Half-width of the local fits of μ(d) and Σ(d), mm (> 0).
    #[arg(long, allow_negative_numbers = true, default_value_t = DEFAULT_FIT_HALF_WIDTH_MM, value_parser = positive)]
    pub fit_half_width_mm: f64,
    /// Also the bound with the gain unknown: S, the prior standard deviation of ln g (the
    /// gain g multiplies both currents; 0.1 ≈ a gain known to 10 %; 0 = known). Adds the
    /// columns crlb_gain_std_mm,crlb_gain_no_dsigma_std_mm (one frame).
    #[arg(long, allow_negative_numbers = true, value_parser = non_negative)]
    pub gain_sd: Option<f64>,
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
    let header: &[&str] = if args.gain_sd.is_some() {
        &CRLB_GAIN_HEADER
    } else {
        &CRLB_HEADER
    };
    let out = CsvOut::create(&args.out, header)?;
    check_writable(args.plot.as_deref())?;
    let t0 = Instant::now();
    let mc = run_mc(&cfg, runs, model.seed, model.threads)?;
    let bound = crlb(&mc.points, args.fit_half_width_mm);
    let q = fit_quality(&mc.points, &bound, runs as usize);
    let with_gain = args.gain_sd.map(|s| (s, crlb_gain_unknown(&bound, s)));
    let dt = t0.elapsed();
    write_crlb(out, &bound, with_gain.as_ref().map(|(_, g)| g.as_slice()))?;
    report_fit(&q, dt.as_secs_f64(), runs);
    if let Some(p) = &args.plot {
        let title = format!(
            "How well thickness can be known (Cramér–Rao bound): {} ice, {} accretions",
            cfg.ice.name(),
            runs
        );
        let gain = with_gain.as_ref().map(|(s, g)| (*s, g.as_slice()));
        plot_crlb(p, &title, &bound, gain)?;
        println!("wrote the figure {}", p.display());
    }
    Ok(())
}
