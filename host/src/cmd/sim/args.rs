//! The arguments the tracing subcommands share: the model options, one clap
//! `ValueEnum` per simulator enum, and the simulator config built from them.

use clap::{Args, ValueEnum};
use fois_sim::consts::MAX_THICKNESS_MM;
use fois_sim::{Coupling, DiffuseFresnel, Geometry, SimConfig};

use crate::cmd::args::{IceArg, SensorArg, f64_in, positive, threads};
use crate::exit::{self, Exit};

/// Face geometry ([`fois_sim::Geometry`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum GeometryArg {
    /// R = 2 mm, B = 4 mm (thesis §3.3).
    #[value(name = "thesis-ch3")]
    ThesisCh3,
    /// R = 4 mm, B = 3.2 mm (thesis §5.3.2; the measured sensor).
    #[value(name = "thesis-ch5")]
    ThesisCh5,
}

impl From<GeometryArg> for Geometry {
    fn from(a: GeometryArg) -> Self {
        match a {
            GeometryArg::ThesisCh3 => Geometry::ThesisCh3,
            GeometryArg::ThesisCh5 => Geometry::ThesisCh5,
        }
    }
}

/// Coupling of returning rays into the signal fibres ([`fois_sim::Coupling`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum CouplingArg {
    /// Thesis-literal: Fresnel transmittance only (eqs. 3.24–3.25).
    Thesis,
    /// Also require the ray inside the fibres' guided cone (rejects specular returns).
    Acceptance,
}

impl From<CouplingArg> for Coupling {
    fn from(a: CouplingArg) -> Self {
        match a {
            CouplingArg::Thesis => Coupling::ThesisLiteral,
            CouplingArg::Acceptance => Coupling::AcceptanceCone,
        }
    }
}

/// Fresnel angle of diffusely reflected rays ([`fois_sim::DiffuseFresnel`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DiffuseFresnelArg {
    /// At the micro-facet's angle of incidence (physical, total reflection beyond 49.8°).
    Facet,
    /// At the mean surface's angle; δ_R only deflects the ray (a reading of eq. 3.22).
    MeanSurface,
}

impl From<DiffuseFresnelArg> for DiffuseFresnel {
    fn from(a: DiffuseFresnelArg) -> Self {
        match a {
            DiffuseFresnelArg::Facet => DiffuseFresnel::Facet,
            DiffuseFresnelArg::MeanSurface => DiffuseFresnel::MeanSurface,
        }
    }
}

/// Largest ice thickness, mm: 0..=MAX_THICKNESS_MM.
pub fn max_mm(s: &str) -> Result<f64, String> {
    f64_in(0.0, MAX_THICKNESS_MM)(s)
}

/// Options shared by the subcommands that trace accretions.
#[derive(Debug, Args, Clone)]
pub struct ModelOpts {
    /// Sensor construction: a (transparent separation, dry offset) or b (opaque).
    #[arg(long, value_enum, default_value = "b")]
    pub sensor: SensorArg,
    /// Face geometry: thesis-ch3 (R = 2 mm, B = 4 mm) or thesis-ch5 (R = 4 mm, B = 3.2 mm).
    #[arg(long, value_enum, default_value = "thesis-ch5")]
    pub geometry: GeometryArg,
    /// Seed of the random streams (one stream per accretion).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Largest ice thickness, mm (0..=100).
    #[arg(long, default_value_t = 15.0, value_parser = max_mm)]
    pub max_mm: f64,
    /// Thickness step of the output, mm (> 0).
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.1, value_parser = positive)]
    pub step_mm: f64,
    /// Coupling model: thesis (Fresnel only, the default) or acceptance (guided cone too).
    #[arg(long, value_enum, default_value = "thesis")]
    pub coupling: CouplingArg,
    /// Override the diffuse reflection angle range δ_R ~ U(±deg), degrees (0..=60, 0 = off).
    #[arg(long, value_parser = f64_in(0.0, 60.0))]
    pub diffuse_deg: Option<f64>,
    /// Fresnel angle of diffusely reflected rays: facet (default) or mean-surface.
    #[arg(long, value_enum, default_value = "facet")]
    pub diffuse_fresnel: DiffuseFresnelArg,
    /// Every source fibre emits along its axis (no angular spread θ_f).
    #[arg(long)]
    pub no_spread: bool,
    /// Worker threads (>= 1; default: all cores). The output does not depend on it.
    #[arg(long, value_parser = threads)]
    pub threads: Option<usize>,
}

impl Default for ModelOpts {
    /// The defaults of the command line.
    fn default() -> Self {
        ModelOpts {
            sensor: SensorArg::B,
            geometry: GeometryArg::ThesisCh5,
            seed: 1,
            max_mm: 15.0,
            step_mm: 0.1,
            coupling: CouplingArg::Thesis,
            diffuse_deg: None,
            diffuse_fresnel: DiffuseFresnelArg::Facet,
            no_spread: false,
            threads: None,
        }
    }
}

/// The Monte Carlo's arguments (`montecarlo`, `crlb`).
#[derive(Debug, Args, Clone)]
pub struct McArgs {
    /// Medium.
    #[arg(long, value_enum, default_value = "rime")]
    pub ice: IceArg,
    /// Number of accretions M, >= 2.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(2..))]
    pub runs: u64,
    /// The model options.
    #[command(flatten)]
    pub model: ModelOpts,
}

impl McArgs {
    /// The simulator configuration.
    pub fn config(&self) -> anyhow::Result<SimConfig> {
        make_config(self.ice, &self.model)
    }
}

/// Build and validate the simulator configuration. A combination the
/// simulator refuses (e.g. more than 100 000 thickness steps) is a usage
/// error (exit code 2).
pub fn make_config(ice: IceArg, m: &ModelOpts) -> anyhow::Result<SimConfig> {
    let mut cfg = SimConfig::new(ice.into(), m.sensor.into(), m.geometry.into());
    cfg.max_mm = m.max_mm;
    cfg.step_mm = m.step_mm;
    cfg.coupling = m.coupling.into();
    cfg.fibre_spread = !m.no_spread;
    cfg.diffuse_fresnel = m.diffuse_fresnel.into();
    if let Some(d) = m.diffuse_deg {
        cfg.params.diffuse_max_rad = d.to_radians();
    }
    cfg.validate()
        .map_err(|e| Exit::new(exit::USAGE, e.to_string()))?;
    Ok(cfg)
}
