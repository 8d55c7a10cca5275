//! `foisctl compare`: logged currents beside the simulator's Monte Carlo
//! band; prints the deviations, optionally draws them.

use std::path::PathBuf;

use clap::Args;

use super::args::{IceArg, SensorArg, non_negative, positive};
use crate::compare::{self, CompareOptions, ThicknessSource};

/// `foisctl compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The log: a `foisctl monitor` CSV, or any CSV with i1_ua, i2_ua and
    /// the thickness (or uptime_ms) column.
    #[arg(long, value_name = "FILE")]
    pub log: PathBuf,
    /// The medium to simulate.
    #[arg(long, value_enum)]
    pub ice: IceArg,
    /// Column holding the reference thickness, mm (e.g. a laser distance sensor).
    #[arg(
        long,
        value_name = "NAME",
        conflicts_with = "rate_mm_per_h",
        required_unless_present = "rate_mm_per_h"
    )]
    pub thickness_col: Option<String>,
    /// Constant accretion rate, mm/h (> 0): d = rate x (uptime - start).
    #[arg(long, allow_negative_numbers = true, value_name = "MM_PER_H", value_parser = positive)]
    pub rate_mm_per_h: Option<f64>,
    /// With --rate-mm-per-h: node uptime at which accretion started, s
    /// (default: the first measurement in the log).
    #[arg(long, allow_negative_numbers = true, value_name = "SECONDS", requires = "rate_mm_per_h", value_parser = non_negative)]
    pub start_s: Option<f64>,
    /// Monte Carlo accretions (1..=100000).
    #[arg(long, default_value_t = 100, value_name = "N",
          value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub runs: u64,
    /// Seed of the Monte Carlo.
    #[arg(long, default_value_t = 1, value_name = "N")]
    pub seed: u64,
    /// Band half-width, in sigma (> 0).
    #[arg(long, allow_negative_numbers = true, default_value_t = 1.0, value_name = "K", value_parser = positive)]
    pub k_sigma: f64,
    /// Measurement noise of one logged sample, rms µA (>= 0), added in
    /// quadrature to the Monte Carlo spread (which models only the ice).
    /// The node's frame noise at the default config is about 0.035 µA.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.035, value_name = "UA", value_parser = non_negative)]
    pub noise_ua: f64,
    /// Sensor construction.
    #[arg(long, value_enum, default_value = "b")]
    pub sensor: SensorArg,
    /// Also draw the comparison (PNG).
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
}

/// Run `foisctl compare`.
pub fn run(args: CompareArgs) -> anyhow::Result<()> {
    let thickness = match (args.thickness_col, args.rate_mm_per_h) {
        (Some(c), _) => ThicknessSource::Column(c),
        (None, Some(r)) => ThicknessSource::Rate {
            mm_per_h: r,
            start_s: args.start_s,
        },
        // clap requires one of the two.
        (None, None) => anyhow::bail!("give --thickness-col or --rate-mm-per-h"),
    };
    let opts = CompareOptions {
        log: args.log,
        ice: args.ice.into(),
        sensor: args.sensor.into(),
        thickness,
        runs: args.runs,
        seed: args.seed,
        k_sigma: args.k_sigma,
        noise_ua: args.noise_ua,
    };
    let c = compare::run(&opts)?;
    print!("{}", compare::report(&c));
    if let Some(p) = &args.plot {
        crate::plot::comparison::plot_comparison(&c, opts.ice.name(), p)?;
        println!("figure: {}", p.display());
    }
    Ok(())
}
