//! `foisctl sim ...`: the front end of the `fois-sim` ray tracer, one
//! module per subcommand; [`args`] the options they share, [`runs`] the
//! parallel runs behind progress bars, [`output`] the CSV files,
//! [`figures`] the PNGs.

pub mod analytic;
pub mod args;
pub mod bench;
pub mod crlb;
pub mod curve;
pub mod figures;
pub mod gallery;
pub mod montecarlo;
pub mod output;
pub mod runs;
pub mod table;

use clap::{Args, Subcommand};

/// Arguments of `foisctl sim`.
#[derive(Debug, Args)]
#[command(
    about = "Ray-trace simulator of the sensor (thesis chapters 3 and 5)",
    long_about = "Ray-trace simulator of the fibre-optic ice sensor (thesis chapters 3 and 5).\n\
    Units: thickness in mm, currents in µA, variances in µA², angles in degrees.\n\
    Random numbers come from seeded streams, one per accretion: the same --seed gives the \
    same output whatever the thread count."
)]
pub struct SimArgs {
    /// The subcommand.
    #[command(subcommand)]
    pub cmd: SimCmd,
}

/// The simulator's subcommands.
#[derive(Debug, Subcommand)]
pub enum SimCmd {
    /// Trace accretions: one CSV row per run and thickness.
    ///
    /// CSV header: run,thickness_mm,i1_ua,i2_ua,i1_refl_ua,i1_scat_ua,i2_refl_ua,i2_scat_ua
    #[command(after_help = crate::exit::OFFLINE_TABLE)]
    Curve(curve::CurveArgs),
    /// The conventional analytic model on flat ice (thesis §2.1, §3.3).
    ///
    /// CSV header: thickness_mm,i1_ua,i2_ua
    #[command(after_help = crate::exit::OFFLINE_TABLE)]
    Analytic(analytic::AnalyticArgs),
    /// Monte Carlo over accretions (thesis §5.4): mean and covariance of (I1, I2).
    ///
    /// CSV header: thickness_mm,mean_i1_ua,mean_i2_ua,var_i1,var_i2,cov_i1_i2 (µA²)
    #[command(after_help = crate::exit::OFFLINE_TABLE)]
    Montecarlo(montecarlo::MontecarloArgs),
    /// Cramér–Rao lower bound of the thickness from a Monte Carlo (thesis §5.4, Fig. 5.18).
    ///
    /// CSV header: thickness_mm,crlb_std_mm,crlb_no_dsigma_std_mm (the first with the dΣ/dd
    /// term of the Gaussian Fisher information, the second without; NaN where Σ is singular).
    #[command(after_help = crate::exit::OFFLINE_TABLE)]
    Crlb(crlb::CrlbArgs),
    /// Print ray evaluations per second (total and per thread) for rime, glazed and water,
    /// thesis-ch5.
    ///
    /// One ray evaluation = one source ray at one thickness (surface reflection plus the
    /// bubbles newly frozen in).
    #[command(after_help = crate::exit::OFFLINE_TABLE)]
    Bench(bench::BenchArgs),
    /// The node estimator's response table: Monte Carlo of rime, glazed and
    /// water (Sensor B, thesis chapter-5 geometry, 0–15 mm), smoothed, packed
    /// (μ, σ in nA, correlation), written as the Rust source the firmware
    /// embeds (default firmware/src/estimator/table.rs, relative to the
    /// repository root). The same file `FOIS_BLESS=1 cargo test -p
    /// fois-firmware --test estimator_table` writes; that test fails while
    /// the checked-in table differs from the simulator's.
    #[command(after_help = crate::exit::OFFLINE_TABLE)]
    Table(table::TableArgs),
    /// Draw every gallery PNG of sim/README.md (thesis Figs. 3.19–3.23, 5.13–5.18).
    #[command(after_help = crate::exit::OFFLINE_TABLE)]
    Gallery(gallery::GalleryArgs),
}

/// Run `foisctl sim`.
pub fn run(args: SimArgs) -> anyhow::Result<()> {
    match args.cmd {
        SimCmd::Curve(a) => curve::run(a),
        SimCmd::Analytic(a) => analytic::run(a),
        SimCmd::Montecarlo(a) => montecarlo::run(a),
        SimCmd::Crlb(a) => crlb::run(a),
        SimCmd::Bench(a) => bench::run(a),
        SimCmd::Gallery(a) => gallery::run(a),
        SimCmd::Table(a) => table::run(a),
    }
}
