//! `foisctl sim gallery`: every figure of the gallery in sim/README.md
//! (thesis Figs. 3.19–3.23, 5.13–5.18 and four extras), from one seed.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use fois_sim::gain::crlb_gain_unknown;
use fois_sim::montecarlo::{DEFAULT_FIT_HALF_WIDTH_MM, fit_quality};
use fois_sim::{Coupling, DiffuseFresnel, Geometry, IceKind, SensorKind, SimConfig, crlb};

use super::figures::{plot_analytic, plot_components, plot_crlb, plot_curves, plot_mc, plot_pair};
use super::runs::{report_fit, run_mc, trace_runs};

/// `foisctl sim gallery`.
#[derive(Debug, Args)]
pub struct GalleryArgs {
    /// Output directory (created if missing).
    #[arg(long, default_value = "sim/gallery")]
    pub out_dir: PathBuf,
    /// Accretions of the Monte Carlo figures (5.17, 5.18), >= 2.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(2..))]
    pub runs: u64,
    /// Seed of the random streams.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// The prior standard deviation of ln g of the unknown-gain figure: a gain known to ≈ 10 %.
const GALLERY_GAIN_SD: f64 = 0.1;

fn geo_cfg(ice: IceKind, geo: Geometry) -> SimConfig {
    SimConfig::new(ice, SensorKind::B, geo)
}

/// Run `foisctl sim gallery`.
pub fn run(args: GalleryArgs) -> Result<()> {
    let GalleryArgs {
        out_dir,
        runs,
        seed,
    } = args;
    let dir = out_dir.as_path();
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
        None,
    )?;
    // The same bound with the gain unknown, known to 10 % beforehand (fois_sim::gain).
    plot_crlb(
        &f("extra_crlb_unknown_gain.png"),
        &format!("CRLB, rime ice, {runs} accretions: gain known vs unknown (S = 0.1)"),
        &bound,
        Some((GALLERY_GAIN_SD, &crlb_gain_unknown(&bound, GALLERY_GAIN_SD))),
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
