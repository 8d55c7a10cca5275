//! `foisctl sim ...`: the front end of the `fois-sim` ray tracer (issue 3).
//!
//! Subcommands: `curve`, `analytic`, `montecarlo`, `crlb`, `bench`, `gallery`. Every CSV is
//! written with a header line; currents in µA, variances in µA², thicknesses in mm.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand, ValueEnum};
use fois_sim::montecarlo::{DEFAULT_FIT_HALF_WIDTH_MM, FitQuality, fit_quality};
use fois_sim::{
    Coupling, CrlbPoint, Curve, DiffuseFresnel, Geometry, IceKind, McPoint, MonteCarlo, SensorKind,
    SensorModel, SimConfig, analytic_curve, crlb, monte_carlo,
};
use indicatif::{ProgressBar, ProgressStyle};

use crate::plot::series as plot;
use plot::{C_I1, C_I1_MEAN, C_I2, C_I2_MEAN, ErrBar, Kind, Series};

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
    #[command(subcommand)]
    pub cmd: SimCmd,
}

/// The accreted medium.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum IceArg {
    /// Ideal clear ice: flat surface, no bubbles (thesis §3.3).
    Flat,
    /// Glazed ice: slopes ±15°, P_B = 0.0015, diffuse ±30° (§5.3.3).
    Glazed,
    /// Rime ice: slopes ±10°, P_B = 0.21, no diffuse (§5.3.4).
    Rime,
    /// Clear water, n = 1.33, flat (§5.2.3).
    Water,
}

impl From<IceArg> for IceKind {
    fn from(a: IceArg) -> Self {
        match a {
            IceArg::Flat => IceKind::Flat,
            IceArg::Glazed => IceKind::Glazed,
            IceArg::Rime => IceKind::Rime,
            IceArg::Water => IceKind::Water,
        }
    }
}

/// Sensor construction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SensorArg {
    /// Transparent separation: dry offset in I1 (thesis §5.2.1).
    A,
    /// Opaque separation: dry face reads ~0.
    B,
}

impl From<SensorArg> for SensorKind {
    fn from(a: SensorArg) -> Self {
        match a {
            SensorArg::A => SensorKind::A,
            SensorArg::B => SensorKind::B,
        }
    }
}

/// Face geometry.
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

/// Coupling of returning rays into the signal fibres.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum CouplingArg {
    /// Thesis-literal: Fresnel transmittance only (eqs. 3.24–3.25).
    Thesis,
    /// Also require the ray inside the fibres' guided cone (rejects specular returns).
    Acceptance,
}

/// Fresnel angle of diffusely reflected rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum DiffuseFresnelArg {
    /// At the micro-facet's angle of incidence (physical, total reflection beyond 49.8°).
    Facet,
    /// At the mean surface's angle; δ_R only deflects the ray (a reading of eq. 3.22).
    MeanSurface,
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
    /// Largest ice thickness, mm.
    #[arg(long, default_value_t = 15.0)]
    pub max_mm: f64,
    /// Thickness step of the output, mm (> 0).
    #[arg(long, default_value_t = 0.1)]
    pub step_mm: f64,
    /// Coupling model: thesis (Fresnel only, the default) or acceptance (guided cone too).
    #[arg(long, value_enum, default_value = "thesis")]
    pub coupling: CouplingArg,
    /// Override the diffuse reflection angle range δ_R ~ U(±deg), degrees (0 = off).
    #[arg(long)]
    pub diffuse_deg: Option<f64>,
    /// Fresnel angle of diffusely reflected rays: facet (default) or mean-surface.
    #[arg(long, value_enum, default_value = "facet")]
    pub diffuse_fresnel: DiffuseFresnelArg,
    /// Every source fibre emits along its axis (no angular spread θ_f).
    #[arg(long)]
    pub no_spread: bool,
    /// Worker threads (default: all cores). The output does not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
}

/// The simulator's subcommands.
#[derive(Debug, Subcommand)]
pub enum SimCmd {
    /// Trace accretions: one CSV row per run and thickness.
    ///
    /// CSV header: run,thickness_mm,i1_ua,i2_ua,i1_refl_ua,i1_scat_ua,i2_refl_ua,i2_scat_ua
    Curve {
        /// Medium: flat, glazed, rime or water.
        #[arg(long, value_enum)]
        ice: IceArg,
        /// Number of accretions (runs 0..N of the seed), ≥ 1.
        #[arg(long, default_value_t = 1)]
        runs: u64,
        #[command(flatten)]
        model: ModelOpts,
        /// Output CSV file.
        #[arg(long)]
        out: PathBuf,
        /// Also draw the curves to this PNG (800×500).
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// The conventional analytic model on flat ice (thesis §2.1, §3.3).
    ///
    /// CSV header: thickness_mm,i1_ua,i2_ua
    Analytic {
        /// Face geometry.
        #[arg(long, value_enum, default_value = "thesis-ch5")]
        geometry: GeometryArg,
        /// Medium: flat (ice, n = 1.31) or water (n = 1.33).
        #[arg(long, value_enum, default_value = "flat")]
        ice: IceArg,
        /// Largest ice thickness, mm.
        #[arg(long, default_value_t = 15.0)]
        max_mm: f64,
        /// Thickness step, mm (> 0).
        #[arg(long, default_value_t = 0.1)]
        step_mm: f64,
        /// Output CSV file.
        #[arg(long)]
        out: PathBuf,
        /// Also draw the analytic and ray-traced curves to this PNG.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Monte Carlo over accretions (thesis §5.4): mean and covariance of (I1, I2).
    ///
    /// CSV header: thickness_mm,mean_i1_ua,mean_i2_ua,var_i1,var_i2,cov_i1_i2 (µA²)
    Montecarlo {
        /// Medium.
        #[arg(long, value_enum, default_value = "rime")]
        ice: IceArg,
        /// Number of accretions M, ≥ 2.
        #[arg(long, default_value_t = 1000)]
        runs: u64,
        #[command(flatten)]
        model: ModelOpts,
        /// Output CSV file.
        #[arg(long)]
        out: PathBuf,
        /// Also draw samples, means and ±1σ bars (like Fig. 5.17) to this PNG.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Cramér–Rao lower bound of the thickness from a Monte Carlo (thesis §5.4, Fig. 5.18).
    ///
    /// CSV header: thickness_mm,crlb_std_mm,crlb_no_dsigma_std_mm (the first with the dΣ/dd
    /// term of the Gaussian Fisher information, the second without; NaN where Σ is singular).
    Crlb {
        /// Medium.
        #[arg(long, value_enum, default_value = "rime")]
        ice: IceArg,
        /// Number of accretions M, ≥ 2.
        #[arg(long, default_value_t = 1000)]
        runs: u64,
        #[command(flatten)]
        model: ModelOpts,
        /// Half-width of the local fits of μ(d) and Σ(d), mm (> 0).
        #[arg(long, default_value_t = DEFAULT_FIT_HALF_WIDTH_MM)]
        fit_half_width_mm: f64,
        /// Output CSV file.
        #[arg(long)]
        out: PathBuf,
        /// Also draw the bound to this PNG.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Print ray evaluations per second (total and per thread) on rime ice, thesis-ch5.
    ///
    /// One ray evaluation = one source ray at one thickness (surface reflection plus the
    /// bubbles newly frozen in).
    Bench {
        /// Accretions per measurement (≥ 1).
        #[arg(long, default_value_t = 200)]
        runs: u64,
        /// Worker threads for the parallel measurement (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Draw every gallery PNG of sim/README.md (thesis Figs. 3.19–3.23, 5.13–5.18).
    Gallery {
        /// Output directory (created if missing).
        #[arg(long, default_value = "sim/gallery")]
        out_dir: PathBuf,
        /// Accretions of the Monte Carlo figures (5.17, 5.18).
        #[arg(long, default_value_t = 1000)]
        runs: u64,
        /// Seed of the random streams.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
}

/// Run `foisctl sim`.
pub fn run(args: SimArgs) -> Result<()> {
    match args.cmd {
        SimCmd::Curve {
            ice,
            runs,
            model,
            out,
            plot,
        } => cmd_curve(ice, runs, &model, &out, plot.as_deref()),
        SimCmd::Analytic {
            geometry,
            ice,
            max_mm,
            step_mm,
            out,
            plot,
        } => cmd_analytic(geometry, ice, max_mm, step_mm, &out, plot.as_deref()),
        SimCmd::Montecarlo {
            ice,
            runs,
            model,
            out,
            plot,
        } => cmd_montecarlo(ice, runs, &model, &out, plot.as_deref()),
        SimCmd::Crlb {
            ice,
            runs,
            model,
            fit_half_width_mm,
            out,
            plot,
        } => cmd_crlb(ice, runs, &model, fit_half_width_mm, &out, plot.as_deref()),
        SimCmd::Bench { runs, threads } => cmd_bench(runs, threads),
        SimCmd::Gallery {
            out_dir,
            runs,
            seed,
        } => cmd_gallery(&out_dir, runs, seed),
    }
}

/// Build and validate the simulator configuration.
pub fn make_config(ice: IceArg, m: &ModelOpts) -> Result<SimConfig> {
    let mut cfg = SimConfig::new(ice.into(), m.sensor.into(), m.geometry.into());
    cfg.max_mm = m.max_mm;
    cfg.step_mm = m.step_mm;
    cfg.coupling = match m.coupling {
        CouplingArg::Thesis => Coupling::ThesisLiteral,
        CouplingArg::Acceptance => Coupling::AcceptanceCone,
    };
    cfg.fibre_spread = !m.no_spread;
    cfg.diffuse_fresnel = match m.diffuse_fresnel {
        DiffuseFresnelArg::Facet => DiffuseFresnel::Facet,
        DiffuseFresnelArg::MeanSurface => DiffuseFresnel::MeanSurface,
    };
    if let Some(d) = m.diffuse_deg {
        if !(0.0..=60.0).contains(&d) {
            bail!("--diffuse-deg must be in 0..=60 degrees, got {d}");
        }
        cfg.params.diffuse_max_rad = d.to_radians();
    }
    cfg.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(cfg)
}

fn pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be ≥ 1");
        }
        b = b.num_threads(n);
    }
    b.build().context("cannot start worker threads")
}

fn create(path: &Path) -> Result<BufWriter<File>> {
    let f = File::create(path).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(BufWriter::new(f))
}

/// Check early that a plot path is writable (so a long run does not fail at the end).
fn check_writable(path: Option<&Path>) -> Result<()> {
    if let Some(p) = path {
        File::create(p).with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}

fn bar(n: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(n);
    pb.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    pb.set_message(what.to_owned());
    pb
}

fn trace_runs(cfg: &SimConfig, runs: u64, seed: u64, threads: Option<usize>) -> Result<Vec<Curve>> {
    let model = SensorModel::new(cfg);
    let pb = bar(runs, "tracing");
    let pool = pool(threads)?;
    let curves = pool.install(|| {
        use rayon::prelude::*;
        (0..runs)
            .into_par_iter()
            .map(|r| {
                let c = model.accretion(seed, r);
                pb.inc(1);
                c
            })
            .collect()
    });
    pb.finish_and_clear();
    Ok(curves)
}

fn cmd_curve(ice: IceArg, runs: u64, m: &ModelOpts, out: &Path, plot: Option<&Path>) -> Result<()> {
    let cfg = make_config(ice, m)?;
    if runs == 0 {
        bail!("--runs must be ≥ 1");
    }
    let mut w = create(out)?;
    check_writable(plot)?;
    let curves = trace_runs(&cfg, runs, m.seed, m.threads)?;
    writeln!(
        w,
        "run,thickness_mm,i1_ua,i2_ua,i1_refl_ua,i1_scat_ua,i2_refl_ua,i2_scat_ua"
    )?;
    for (r, c) in curves.iter().enumerate() {
        for p in &c.points {
            writeln!(
                w,
                "{r},{:.4},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}",
                p.thickness_mm,
                p.i1_ua,
                p.i2_ua,
                p.i1_refl_ua,
                p.i1_scat_ua,
                p.i2_refl_ua,
                p.i2_scat_ua
            )?;
        }
    }
    w.flush()
        .with_context(|| format!("cannot write {}", out.display()))?;
    if let Some(p) = plot {
        let title = format!(
            "{} ice, sensor {:?}, {}: {} run(s)",
            cfg.ice.name(),
            cfg.sensor,
            cfg.geometry.name(),
            runs
        );
        plot_curves(p, &title, &curves, runs == 1)?;
    }
    Ok(())
}

/// Curves of several runs (I1 blue, I2 red); with `components`, reflection and scattering
/// parts dashed / thin as in thesis Figs. 3.21 and 3.23.
pub fn plot_curves(path: &Path, title: &str, curves: &[Curve], components: bool) -> Result<()> {
    let mut s = Vec::new();
    for (k, c) in curves.iter().enumerate() {
        let lab = |t: &'static str| if k == 0 { Some(t) } else { None };
        let xy = |f: fn(&fois_sim::CurvePoint) -> f64| {
            c.points
                .iter()
                .map(|p| (p.thickness_mm, f(p)))
                .collect::<Vec<_>>()
        };
        s.push(Series::new(lab("I1"), C_I1, Kind::Line(2), xy(|p| p.i1_ua)));
        s.push(Series::new(lab("I2"), C_I2, Kind::Line(2), xy(|p| p.i2_ua)));
        if components {
            s.push(Series::new(
                Some("I1 reflection"),
                C_I1_MEAN,
                Kind::Dashed,
                xy(|p| p.i1_refl_ua),
            ));
            s.push(Series::new(
                Some("I1 scattering"),
                plot::C_GREEN,
                Kind::Dashed,
                xy(|p| p.i1_scat_ua),
            ));
            s.push(Series::new(
                Some("I2 reflection"),
                C_I2_MEAN,
                Kind::Dashed,
                xy(|p| p.i2_refl_ua),
            ));
            s.push(Series::new(
                Some("I2 scattering"),
                plot::C_MAGENTA,
                Kind::Dashed,
                xy(|p| p.i2_scat_ua),
            ));
        }
    }
    plot::plot(path, title, "current (µA)", &s, &[])
}

fn cmd_analytic(
    geometry: GeometryArg,
    ice: IceArg,
    max_mm: f64,
    step_mm: f64,
    out: &Path,
    plot: Option<&Path>,
) -> Result<()> {
    if !matches!(ice, IceArg::Flat | IceArg::Water) {
        bail!("the analytic model is for a flat, clear medium: --ice flat or water");
    }
    let m = ModelOpts {
        sensor: SensorArg::B,
        geometry,
        seed: 1,
        max_mm,
        step_mm,
        coupling: CouplingArg::Thesis,
        diffuse_deg: None,
        diffuse_fresnel: DiffuseFresnelArg::Facet,
        no_spread: false,
        threads: None,
    };
    let cfg = make_config(ice, &m)?;
    let mut w = create(out)?;
    check_writable(plot)?;
    let a = analytic_curve(cfg.geometry, cfg.params.n_medium, &cfg.thicknesses_mm());
    writeln!(w, "thickness_mm,i1_ua,i2_ua")?;
    for (d, i1, i2) in &a {
        writeln!(w, "{d:.4},{i1:.6},{i2:.6}")?;
    }
    w.flush()
        .with_context(|| format!("cannot write {}", out.display()))?;
    if let Some(p) = plot {
        plot_analytic(p, &cfg)?;
    }
    Ok(())
}

/// Analytic model against the ray tracer (with and without the fibres' angular spread), like
/// thesis Fig. 3.19.
pub fn plot_analytic(path: &Path, cfg: &SimConfig) -> Result<()> {
    let a = analytic_curve(cfg.geometry, cfg.params.n_medium, &cfg.thicknesses_mm());
    let tracer = fois_sim::accretion_curve(cfg, 1, 0);
    let mut c0 = cfg.clone();
    c0.fibre_spread = false;
    let tracer0 = fois_sim::accretion_curve(&c0, 1, 0);
    let pts = |c: &Curve, k: usize| {
        c.points
            .iter()
            .map(|p| (p.thickness_mm, if k == 0 { p.i1_ua } else { p.i2_ua }))
            .collect::<Vec<_>>()
    };
    // The tracer without spread first, wide and light, so the analytic dashes run inside it.
    let s = vec![
        Series::new(
            Some("tracer, no fibre spread"),
            RGB_GREY,
            Kind::Line(6),
            pts(&tracer0, 0),
        ),
        Series::new(None, RGB_GREY, Kind::Line(6), pts(&tracer0, 1)),
        Series::new(Some("I1 ray tracer"), C_I1, Kind::Line(2), pts(&tracer, 0)),
        Series::new(
            Some("I2 ray tracer"),
            plot::C_MAGENTA,
            Kind::Line(2),
            pts(&tracer, 1),
        ),
        Series::new(
            Some("I1 analytic"),
            plot::C_GREEN,
            Kind::Dashed,
            a.iter().map(|x| (x.0, x.1)).collect(),
        ),
        Series::new(
            Some("I2 analytic"),
            plot::C_CYAN,
            Kind::Dashed,
            a.iter().map(|x| (x.0, x.2)).collect(),
        ),
    ];
    let title = format!(
        "{} ice, {}: ray tracer vs analytic",
        cfg.ice.name(),
        cfg.geometry.name()
    );
    plot::plot(path, &title, "current (µA)", &s, &[])
}

const RGB_GREY: plotters::style::RGBColor = plotters::style::RGBColor(190, 190, 190);

fn check_mc_runs(runs: u64) -> Result<()> {
    if runs < 2 {
        bail!("--runs must be ≥ 2 for a covariance, got {runs}");
    }
    Ok(())
}

/// Run a Monte Carlo with a progress bar.
pub fn run_mc(cfg: &SimConfig, runs: u64, seed: u64, threads: Option<usize>) -> Result<MonteCarlo> {
    let pb = bar(runs, "monte carlo");
    let pool = pool(threads)?;
    eprintln!(
        "monte carlo: {runs} accretions on {} threads",
        pool.current_num_threads()
    );
    let inc = || pb.inc(1);
    let mc = pool.install(|| monte_carlo(cfg, runs, seed, &inc));
    pb.finish_and_clear();
    Ok(mc)
}

fn cmd_montecarlo(
    ice: IceArg,
    runs: u64,
    m: &ModelOpts,
    out: &Path,
    plot: Option<&Path>,
) -> Result<()> {
    let cfg = make_config(ice, m)?;
    check_mc_runs(runs)?;
    let mut w = create(out)?;
    check_writable(plot)?;
    let mc = run_mc(&cfg, runs, m.seed, m.threads)?;
    writeln!(
        w,
        "thickness_mm,mean_i1_ua,mean_i2_ua,var_i1,var_i2,cov_i1_i2"
    )?;
    for p in &mc.points {
        writeln!(
            w,
            "{:.4},{:.6},{:.6},{:.6},{:.6},{:.6}",
            p.thickness_mm,
            p.mean_ua[0],
            p.mean_ua[1],
            p.cov_ua2[0][0],
            p.cov_ua2[1][1],
            p.cov_ua2[0][1]
        )?;
    }
    w.flush()
        .with_context(|| format!("cannot write {}", out.display()))?;
    if let Some(p) = plot {
        let title = format!("Monte Carlo: {} ice, {} accretions", cfg.ice.name(), runs);
        plot_mc(p, &title, &mc)?;
    }
    Ok(())
}

/// Samples (dots), means and ±1σ bars every millimetre, like thesis Fig. 5.17.
pub fn plot_mc(path: &Path, title: &str, mc: &MonteCarlo) -> Result<()> {
    let mut s = Vec::new();
    // Samples every 0.5 mm of at most 300 runs keep the PNG light.
    let n_show = mc.runs.len().min(300);
    let step = mc
        .points
        .get(1)
        .map(|p| p.thickness_mm)
        .filter(|&d| d > 0.0)
        .unwrap_or(0.1);
    let every = ((0.5 / step).round() as usize).max(1);
    let mut d1 = Vec::new();
    let mut d2 = Vec::new();
    for c in &mc.runs[..n_show] {
        for p in c.points.iter().step_by(every) {
            d1.push((p.thickness_mm, p.i1_ua));
            d2.push((p.thickness_mm, p.i2_ua));
        }
    }
    s.push(Series::new(Some("I1 samples"), C_I1, Kind::Dots(1), d1));
    s.push(Series::new(Some("I2 samples"), C_I2, Kind::Dots(1), d2));
    let mean = |k: usize| {
        mc.points
            .iter()
            .map(|p| (p.thickness_mm, p.mean_ua[k]))
            .collect()
    };
    s.push(Series::new(
        Some("mean I1"),
        C_I1_MEAN,
        Kind::Line(3),
        mean(0),
    ));
    s.push(Series::new(
        Some("mean I2"),
        C_I2_MEAN,
        Kind::Line(3),
        mean(1),
    ));
    let every_mm = ((1.0 / step).round() as usize).max(1);
    let mut bars: Vec<ErrBar> = Vec::new();
    for p in mc.points.iter().step_by(every_mm) {
        for (k, c) in [(0, C_I1_MEAN), (1, C_I2_MEAN)] {
            let sd = p.cov_ua2[k][k].max(0.0).sqrt();
            let m = p.mean_ua[k];
            bars.push((p.thickness_mm, m - sd, m, m + sd, c));
        }
    }
    plot::plot(path, title, "current (µA)", &s, &bars)
}

fn cmd_crlb(
    ice: IceArg,
    runs: u64,
    m: &ModelOpts,
    half_width: f64,
    out: &Path,
    plot: Option<&Path>,
) -> Result<()> {
    let cfg = make_config(ice, m)?;
    check_mc_runs(runs)?;
    if !(half_width.is_finite() && half_width > 0.0) {
        bail!("--fit-half-width-mm must be > 0, got {half_width}");
    }
    let mut w = create(out)?;
    check_writable(plot)?;
    let t0 = Instant::now();
    let mc = run_mc(&cfg, runs, m.seed, m.threads)?;
    let bound = crlb(&mc.points, half_width);
    let q = fit_quality(&mc.points, &bound, runs as usize);
    let dt = t0.elapsed();
    writeln!(w, "thickness_mm,crlb_std_mm,crlb_no_dsigma_std_mm")?;
    for p in &bound {
        writeln!(
            w,
            "{:.4},{:.6},{:.6}",
            p.thickness_mm, p.crlb_std_mm, p.crlb_no_dsigma_std_mm
        )?;
    }
    w.flush()
        .with_context(|| format!("cannot write {}", out.display()))?;
    report_fit(&q, dt.as_secs_f64(), runs);
    if let Some(p) = plot {
        let title = format!("CRLB: {} ice, {} accretions", cfg.ice.name(), runs);
        plot_crlb(p, &title, &bound)?;
    }
    Ok(())
}

fn report_fit(q: &FitQuality, secs: f64, runs: u64) {
    eprintln!(
        "monte carlo + crlb: {runs} accretions in {secs:.2} s; fit of μ(d): RMS residual \
         I1 {:.3} µA, I2 {:.3} µA (standard error of the means {:.3}, {:.3} µA)",
        q.rms_residual_ua[0], q.rms_residual_ua[1], q.rms_std_error_ua[0], q.rms_std_error_ua[1]
    );
}

/// The bound with and without the dΣ/dd term, like thesis Fig. 5.18.
pub fn plot_crlb(path: &Path, title: &str, bound: &[CrlbPoint]) -> Result<()> {
    let s = vec![
        Series::new(
            Some("CRLB std (with dΣ/dd)"),
            C_I1,
            Kind::Line(2),
            bound
                .iter()
                .map(|p| (p.thickness_mm, p.crlb_std_mm))
                .collect(),
        ),
        Series::new(
            Some("CRLB std (mean term only)"),
            C_I2,
            Kind::Dashed,
            bound
                .iter()
                .map(|p| (p.thickness_mm, p.crlb_no_dsigma_std_mm))
                .collect(),
        ),
    ];
    plot::plot(path, title, "std of thickness estimate (mm)", &s, &[])
}

fn cmd_bench(runs: u64, threads: Option<usize>) -> Result<()> {
    if runs == 0 {
        bail!("--runs must be ≥ 1");
    }
    let cfg = SimConfig::new(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
    let model = SensorModel::new(&cfg);
    let evals = model.ray_evaluations() as f64;
    println!(
        "rime ice, thesis-ch5: {} rays × {} thicknesses = {} ray evaluations per accretion",
        model.n_rays(),
        cfg.thicknesses_mm().len(),
        evals
    );
    // One thread.
    let pb = bar(runs, "1 thread");
    let t0 = Instant::now();
    let mut sink = 0.0;
    for r in 0..runs {
        sink += model.accretion(7, r).points.last().map_or(0.0, |p| p.i1_ua);
        pb.inc(1);
    }
    let t1 = t0.elapsed().as_secs_f64();
    pb.finish_and_clear();
    let single = evals * runs as f64 / t1;
    println!(
        "1 thread:  {:.3e} ray evaluations/s ({:.2} ms per accretion)",
        single,
        1e3 * t1 / runs as f64
    );
    // All threads.
    let pool = pool(threads)?;
    let n = pool.current_num_threads();
    let pb = bar(runs, "all threads");
    let t0 = Instant::now();
    let par: f64 = pool.install(|| {
        use rayon::prelude::*;
        (0..runs)
            .into_par_iter()
            .map(|r| {
                let v = model.accretion(7, r).points.last().map_or(0.0, |p| p.i1_ua);
                pb.inc(1);
                v
            })
            .sum()
    });
    let tp = t0.elapsed().as_secs_f64();
    pb.finish_and_clear();
    let total = evals * runs as f64 / tp;
    println!(
        "{n} threads: {:.3e} ray evaluations/s total, {:.3e} per thread",
        total,
        total / n as f64
    );
    println!(
        "estimated full thesis Monte Carlo (1000 accretions): {:.2} s",
        1000.0 * evals / total
    );
    if !(sink.is_finite() && par.is_finite()) {
        bail!("non-finite currents");
    }
    Ok(())
}

fn geo_cfg(ice: IceKind, geo: Geometry) -> SimConfig {
    SimConfig::new(ice, SensorKind::B, geo)
}

fn cmd_gallery(dir: &Path, runs: u64, seed: u64) -> Result<()> {
    check_mc_runs(runs)?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let t0 = Instant::now();
    let f = |n: &str| dir.join(n);
    let ch3 = Geometry::ThesisCh3;
    let ch5 = Geometry::ThesisCh5;
    // 3.19: analytic vs ray tracer on flat ice.
    plot_analytic(
        &f("fig3_19_flat_analytic_vs_tracer.png"),
        &geo_cfg(IceKind::Flat, ch3),
    )?;
    // 3.20–3.23: one glazed and one rime accretion, total and components.
    for (ice, tot, comp) in [
        (
            IceKind::Glazed,
            "fig3_20_glazed.png",
            "fig3_21_glazed_components.png",
        ),
        (
            IceKind::Rime,
            "fig3_22_rime.png",
            "fig3_23_rime_components.png",
        ),
    ] {
        let c = fois_sim::accretion_curve(&geo_cfg(ice, ch3), seed, 0);
        plot_curves(
            &f(tot),
            &format!("{} ice, thesis-ch3: I1, I2", ice.name()),
            std::slice::from_ref(&c),
            false,
        )?;
        plot_components(
            &f(comp),
            &format!("{} ice, thesis-ch3: reflection vs scattering", ice.name()),
            &c,
        )?;
    }
    // 5.13, 5.14, 5.16: ten accretions each, thesis-ch5.
    let mut g0 = geo_cfg(IceKind::Glazed, ch5);
    g0.params.diffuse_max_rad = 0.0;
    let mut g_mean = geo_cfg(IceKind::Glazed, ch5);
    g_mean.diffuse_fresnel = DiffuseFresnel::MeanSurface;
    for (cfg, name, title) in [
        (
            g_mean,
            "fig5_14b_glazed_diffuse_mean_surface_fresnel.png",
            "glazed, δ_R ~ U(±30°), Fresnel at the mean surface: 10 accretions",
        ),
        (
            g0,
            "fig5_13_glazed_no_diffuse.png",
            "glazed ice, δ_R = 0: 10 accretions",
        ),
        (
            geo_cfg(IceKind::Glazed, ch5),
            "fig5_14_glazed_diffuse.png",
            "glazed ice, δ_R ~ U(±30°): 10 accretions",
        ),
        (
            geo_cfg(IceKind::Rime, ch5),
            "fig5_16_rime.png",
            "rime ice: 10 accretions",
        ),
    ] {
        let curves = trace_runs(&cfg, 10, seed, None)?;
        plot_curves(&f(name), title, &curves, false)?;
    }
    // 5.17, 5.18: Monte Carlo and CRLB of rime ice.
    let rime = geo_cfg(IceKind::Rime, ch5);
    let t_mc = Instant::now();
    let mc = run_mc(&rime, runs, seed, None)?;
    let bound = crlb(&mc.points, DEFAULT_FIT_HALF_WIDTH_MM);
    let secs = t_mc.elapsed().as_secs_f64();
    report_fit(&fit_quality(&mc.points, &bound, runs as usize), secs, runs);
    plot_mc(
        &f("fig5_17_rime_monte_carlo.png"),
        &format!("rime ice: {runs} accretions, mean ± 1σ"),
        &mc,
    )?;
    plot_crlb(
        &f("fig5_18_rime_crlb.png"),
        &format!("CRLB, rime ice, {runs} accretions"),
        &bound,
    )?;
    // Extras: the acceptance-cone trap, water vs glazed, Sensor A vs B.
    let mut acc = geo_cfg(IceKind::Flat, ch5);
    let lit = fois_sim::accretion_curve(&acc, seed, 0);
    acc.coupling = Coupling::AcceptanceCone;
    let cone = fois_sim::accretion_curve(&acc, seed, 0);
    plot_pair(
        &f("extra_coupling_flat.png"),
        "flat ice, thesis-ch5: thesis coupling (solid) vs acceptance cone (dashed)",
        &lit,
        &cone,
    )?;
    let water = fois_sim::accretion_curve(&geo_cfg(IceKind::Water, ch5), seed, 0);
    let mut glz = geo_cfg(IceKind::Glazed, ch5);
    glz.params.slope_max_rad = 0.0;
    glz.params.diffuse_max_rad = 0.0;
    let glazed_flat = fois_sim::accretion_curve(&glz, seed, 0);
    plot_pair(
        &f("extra_water_vs_flat_glazed.png"),
        "water (solid) vs flat glazed ice (dashed), thesis-ch5",
        &water,
        &glazed_flat,
    )?;
    let mut sa = geo_cfg(IceKind::Glazed, ch5);
    sa.sensor = SensorKind::A;
    let a = fois_sim::accretion_curve(&sa, seed, 0);
    let b = fois_sim::accretion_curve(&geo_cfg(IceKind::Glazed, ch5), seed, 0);
    plot_pair(
        &f("extra_sensor_a_vs_b.png"),
        "glazed ice: Sensor A (solid) vs Sensor B (dashed)",
        &a,
        &b,
    )?;
    eprintln!(
        "gallery written to {} in {:.1} s",
        dir.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

fn plot_components(path: &Path, title: &str, c: &Curve) -> Result<()> {
    let xy = |f: fn(&fois_sim::CurvePoint) -> f64| {
        c.points
            .iter()
            .map(|p| (p.thickness_mm, f(p)))
            .collect::<Vec<_>>()
    };
    let s = vec![
        Series::new(
            Some("I1 reflection"),
            C_I1,
            Kind::Line(2),
            xy(|p| p.i1_refl_ua),
        ),
        Series::new(
            Some("I1 scattering"),
            C_I1,
            Kind::Dashed,
            xy(|p| p.i1_scat_ua),
        ),
        Series::new(
            Some("I2 reflection"),
            C_I2,
            Kind::Line(2),
            xy(|p| p.i2_refl_ua),
        ),
        Series::new(
            Some("I2 scattering"),
            C_I2,
            Kind::Dashed,
            xy(|p| p.i2_scat_ua),
        ),
    ];
    plot::plot(path, title, "current (µA)", &s, &[])
}

fn plot_pair(path: &Path, title: &str, a: &Curve, b: &Curve) -> Result<()> {
    let xy = |c: &Curve, k: usize| {
        c.points
            .iter()
            .map(|p| (p.thickness_mm, if k == 0 { p.i1_ua } else { p.i2_ua }))
            .collect::<Vec<_>>()
    };
    let s = vec![
        Series::new(Some("I1"), C_I1, Kind::Line(2), xy(a, 0)),
        Series::new(Some("I2"), C_I2, Kind::Line(2), xy(a, 1)),
        Series::new(None, C_I1, Kind::Dashed, xy(b, 0)),
        Series::new(None, C_I2, Kind::Dashed, xy(b, 1)),
    ];
    plot::plot(path, title, "current (µA)", &s, &[])
}

/// Re-exported for tests: the statistics type.
pub type McStats = McPoint;
