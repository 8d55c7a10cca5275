//! `foisctl sim analytic`: the conventional analytic model on flat ice
//! (thesis §2.1, §3.3).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use clap::ValueEnum;
use fois_sim::analytic_curve;

use super::args::{GeometryArg, ModelOpts, make_config, max_mm};
use super::figures::plot_analytic;
use super::output::{ANALYTIC_HEADER, CsvOut, check_writable, write_analytic};
use crate::cmd::args::{IceArg, positive};

/// `flat` or `water`: the media the analytic model holds for.
fn flat_medium(s: &str) -> Result<IceArg, String> {
    match IceArg::from_str(s, true) {
        Ok(m @ (IceArg::Flat | IceArg::Water)) => Ok(m),
        _ => Err(format!(
            "`{s}`: the analytic model is for a flat, clear medium: flat or water"
        )),
    }
}

/// `foisctl sim analytic`.
#[derive(Debug, Args)]
pub struct AnalyticArgs {
    /// Face geometry.
    #[arg(long, value_enum, default_value = "thesis-ch5")]
    pub geometry: GeometryArg,
    /// Medium: flat (ice, n = 1.31) or water (n = 1.33).
    #[arg(long, default_value = "flat", value_parser = flat_medium)]
    pub ice: IceArg,
    /// Largest ice thickness, mm (0..=100).
    #[arg(long, default_value_t = 15.0, value_parser = max_mm)]
    pub max_mm: f64,
    /// Thickness step, mm (> 0).
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.1, value_parser = positive)]
    pub step_mm: f64,
    /// Output CSV file.
    #[arg(long)]
    pub out: PathBuf,
    /// Also draw the analytic and ray-traced curves to this PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// Run `foisctl sim analytic`.
pub fn run(args: AnalyticArgs) -> Result<()> {
    let m = ModelOpts {
        geometry: args.geometry,
        max_mm: args.max_mm,
        step_mm: args.step_mm,
        ..ModelOpts::default()
    };
    let cfg = make_config(args.ice, &m)?;
    let out = CsvOut::create(&args.out, &ANALYTIC_HEADER)?;
    check_writable(args.plot.as_deref())?;
    let a = analytic_curve(cfg.geometry, cfg.params.n_medium, &cfg.thicknesses_mm());
    write_analytic(out, &a)?;
    if let Some(p) = &args.plot {
        plot_analytic(p, &cfg)?;
        println!("wrote the figure {}", p.display());
    }
    Ok(())
}
