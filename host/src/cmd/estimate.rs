//! `foisctl estimate`: replay a log or a `sim curve` CSV through the node's
//! ice estimator and write it again with the estimate appended.

use std::path::PathBuf;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use super::args::{f64_in, positive, ua_pair};
use crate::estimate::{self, CurveTiming, ReplayOptions};
use crate::exit::{self, Exit};

/// `foisctl estimate`.
#[derive(Debug, Args)]
pub struct EstimateArgs {
    /// The CSV to replay: a `foisctl monitor` log (each measurement row a
    /// frame, Δt from uptime_ms) or a `sim curve` CSV (thickness_mm, i1_ua,
    /// i2_ua: one accretion, rows of growing thickness). Never modified.
    #[arg(long, value_name = "FILE.csv")]
    pub input: PathBuf,
    /// Where to write the input's rows with est_thickness_mm, est_sigma_mm
    /// (mm), est_kind (dry/water/glazed/rime), est_p (0-1), est_gain,
    /// est_gain_sigma (the optical gain against the response table's),
    /// est_rate_mm_per_h, est_rate_sigma_mm_per_h (the icing rate),
    /// est_accreting (the icing period, 0/1) and est_update appended. Must not be the input; an existing file is replaced (only
    /// once the replay has succeeded).
    #[arg(long, value_name = "FILE.csv")]
    pub out: PathBuf,
    /// `sim curve` input: growth rate that turns the thickness steps into
    /// frame periods, mm/h (> 0). Rows 0.1 mm apart at 2 mm/h are frames
    /// 180 s apart; at 10 mm/h (the estimator's largest growth rate) 36 s.
    #[arg(long, allow_negative_numbers = true, value_name = "MM_PER_H", default_value_t = 2.0, value_parser = positive)]
    pub rate_mm_per_h: f64,
    /// `sim curve` input: air temperature, °C (-60..=80).
    #[arg(long, value_name = "CELSIUS", default_value_t = -5.0,
          value_parser = f64_in(-60.0, 80.0), allow_negative_numbers = true)]
    pub temperature_c: f64,
    /// Monitor log input: the node's dark baseline (I1,I2 or one value for
    /// both), µA, subtracted from the logged net currents as the node does,
    /// until a DarkCalibrated answer in the log replaces it.
    #[arg(long, value_name = "UA1,UA2", default_value = "0", value_parser = ua_pair)]
    pub baseline_ua: [f64; 2],
    /// The sensor's optical gain against the response table's, as a gain
    /// calibration measured it (0.25..=4). Without it the gain is unknown
    /// (1 ± 30 %) and learned from the frames, as on a new node.
    #[arg(long, value_name = "GAIN", value_parser = f64_in(0.25, 4.0))]
    pub gain: Option<f64>,
    /// Relative standard deviation of --gain (0.001..=1; a calibration
    /// against a target: 0.02).
    #[arg(long, value_name = "SD", default_value_t = 0.02, requires = "gain",
          value_parser = f64_in(0.001, 1.0))]
    pub gain_sd: f64,
}

/// Run `foisctl estimate`.
pub fn run(args: EstimateArgs) -> anyhow::Result<()> {
    if estimate::same_file(&args.input, &args.out) {
        return Err(Exit::new(
            exit::USAGE,
            format!(
                "--out {} is the input: choose another file (the input is never overwritten)",
                args.out.display()
            ),
        )
        .into());
    }
    let opts = ReplayOptions {
        curve: CurveTiming {
            rate_mm_per_h: args.rate_mm_per_h,
            temperature_c: args.temperature_c,
        },
        baseline_ua: args.baseline_ua,
        gain_prior: args.gain.map(|g| (g as f32, args.gain_sd as f32)),
        ..ReplayOptions::default()
    };
    let pb = ProgressBar::new_spinner();
    if let Ok(style) = ProgressStyle::with_template("{spinner} replaying: {pos} rows {elapsed}") {
        pb.set_style(style);
    }
    let sum = estimate::replay(&args.input, &args.out, &opts, |n| pb.set_position(n))?;
    pb.finish_and_clear();
    println!(
        "{}: {} rows, {} frames replayed ({} predicted only: no usable currents; {} outliers; \
         {} restarts); last: {}; written to {}",
        sum.input_kind,
        sum.rows,
        sum.frames,
        sum.no_currents,
        sum.outliers,
        sum.restarts,
        sum.last.as_deref().unwrap_or("no estimate"),
        args.out.display()
    );
    Ok(())
}
