//! The figures of the simulator commands, laid out like the thesis's:
//! curves, components, Monte Carlo samples with ±1σ bars, the CRLB, the
//! analytic model against the tracer.

use std::path::Path;

use anyhow::Result;
use fois_sim::{CrlbPoint, Curve, MonteCarlo, SimConfig, analytic_curve};

use crate::plot::series::{
    self as plot, C_GREEN, C_I1, C_I1_MEAN, C_I2, C_I2_MEAN, C_MAGENTA, ErrBar, Kind, Series,
};

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

/// The bound with and without the dΣ/dd term, like thesis Fig. 5.18.
/// With `gain` (S and the unknown-gain bound per point, `fois_sim::gain`) its two curves too.
pub fn plot_crlb(
    path: &Path,
    title: &str,
    bound: &[CrlbPoint],
    gain: Option<(f64, &[(f64, f64)])>,
) -> Result<()> {
    let mut s = vec![
        Series::new(
            Some("best possible σ of the thickness (Cramér–Rao bound)"),
            C_I1,
            Kind::Line(2),
            bound
                .iter()
                .map(|p| (p.thickness_mm, p.crlb_std_mm))
                .collect(),
        ),
        Series::new(
            Some("… from the mean currents alone (their spread unused)"),
            C_I2,
            Kind::Dashed,
            bound
                .iter()
                .map(|p| (p.thickness_mm, p.crlb_no_dsigma_std_mm))
                .collect(),
        ),
    ];
    if let Some((sd, g)) = gain {
        let xy = |f: fn(&(f64, f64)) -> f64| {
            bound
                .iter()
                .zip(g)
                .map(|(p, v)| (p.thickness_mm, f(v)))
                .collect::<Vec<_>>()
        };
        s.push(Series::new(
            Some(&format!(
                "… optical gain uncalibrated (±{:.0} %)",
                100.0 * sd
            )),
            C_GREEN,
            Kind::Line(2),
            xy(|v| v.0),
        ));
        s.push(Series::new(
            Some("… gain uncalibrated, mean currents alone"),
            C_MAGENTA,
            Kind::Dashed,
            xy(|v| v.1),
        ));
    }
    plot::plot(
        path,
        title,
        "smallest possible σ of a thickness estimate (mm)",
        &s,
        &[],
    )
}

/// Reflection and scattering parts of one accretion (thesis Figs. 3.21, 3.23).
pub fn plot_components(path: &Path, title: &str, c: &Curve) -> Result<()> {
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

/// Two accretions' I1 and I2 (solid, dashed).
pub fn plot_pair(path: &Path, title: &str, a: &Curve, b: &Curve) -> Result<()> {
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
