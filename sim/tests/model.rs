//! The ray tracer against the analytic model and the thesis's qualitative results.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use fois_sim::analytic::analytic_curve;
use fois_sim::consts::*;
use fois_sim::laws::{critical_angle, snell_angle};
use fois_sim::*;

fn cfg(ice: IceKind, sensor: SensorKind, geo: Geometry) -> SimConfig {
    SimConfig::new(ice, sensor, geo)
}

/// (thickness, value) of the maximum.
fn peak(xy: impl Iterator<Item = (f64, f64)>) -> (f64, f64) {
    xy.fold((0.0, f64::MIN), |a, b| if b.1 > a.1 { b } else { a })
}

fn peaks_of(c: &Curve) -> [(f64, f64); 2] {
    [
        peak(c.points.iter().map(|p| (p.thickness_mm, p.i1_ua))),
        peak(c.points.iter().map(|p| (p.thickness_mm, p.i2_ua))),
    ]
}

#[test]
fn source_grid_has_about_2546_fibres_inside_the_half_disc() {
    for geo in [Geometry::ThesisCh3, Geometry::ThesisCh5] {
        let g = geo.source_grid_mm();
        assert_eq!(g.len(), 2553);
        let r = geo.radius_mm();
        assert!(
            g.iter()
                .all(|&(x, y)| x <= 0.0 && x * x + y * y <= r * r + 1e-9)
        );
    }
    let m = SensorModel::new(&cfg(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5));
    assert_eq!(m.n_rays(), 2553);
    assert_eq!(m.ray_evaluations(), 2553 * 151);
}

#[test]
fn regions_follow_design_section_5() {
    let g = Geometry::ThesisCh5; // R = 4, B = 3.2
    assert_eq!(g.region(-1.0, 0.0), Region::Source);
    assert_eq!(g.region(-3.9, 3.9), Region::Outside);
    assert_eq!(g.region(0.0, 3.9), Region::Bundle1);
    assert_eq!(g.region(3.2, -4.0), Region::Bundle1);
    assert_eq!(g.region(7.1, 0.0), Region::Bundle2);
    assert_eq!(g.region(7.3, 0.0), Region::Outside);
    assert_eq!(g.region(1.0, 4.1), Region::Outside);
    assert_eq!(Geometry::default(), Geometry::ThesisCh5);
}

#[test]
fn zero_spread_tracer_reproduces_the_analytic_model() {
    for geo in [Geometry::ThesisCh3, Geometry::ThesisCh5] {
        let mut c = cfg(IceKind::Flat, SensorKind::B, geo);
        c.fibre_spread = false;
        let tr = accretion_curve(&c, 1, 0);
        let an = analytic_curve(geo, N_ICE, &c.thicknesses_mm());
        let ap = [
            peak(an.iter().map(|a| (a.0, a.1))),
            peak(an.iter().map(|a| (a.0, a.2))),
        ];
        let tp = peaks_of(&tr);
        for k in 0..2 {
            // The analytic I1 has a plateau (image wholly on bundle 1) falling only by
            // absorption, so compare the level and the peak within the plateau's flatness.
            assert!(
                (tp[k].1 - ap[k].1).abs() < 0.03 * ap[k].1,
                "{geo:?} bundle {k}: tracer {tp:?} analytic {ap:?}"
            );
            assert!(
                (tp[k].0 - ap[k].0).abs() <= 0.1 + 1e-9,
                "{geo:?} bundle {k}: tracer {tp:?} analytic {ap:?}"
            );
        }
        // Point by point within a few % of the peak (grid quantisation of the overlap).
        for (p, a) in tr.points.iter().zip(&an) {
            assert!((p.i1_ua - a.1).abs() < 0.04 * ap[0].1, "{geo:?} d={}", a.0);
            assert!((p.i2_ua - a.2).abs() < 0.04 * ap[1].1, "{geo:?} d={}", a.0);
        }
    }
}

#[test]
fn with_the_thesis_spread_rays_beyond_the_ice_air_critical_angle_raise_and_advance_the_peak() {
    let geo = Geometry::ThesisCh3;
    let c = cfg(IceKind::Flat, SensorKind::B, geo);
    let tr = accretion_curve(&c, 1, 0);
    let an = analytic_curve(geo, N_ICE, &c.thicknesses_mm());
    let a1 = peak(an.iter().map(|a| (a.0, a.1)));
    let [t1, t2] = peaks_of(&tr);
    // The steepest rays: 30° + θ_max,f = 50.4° in the fibre → 72° in ice, beyond the ice/air
    // critical angle of 49.8° (a fibre angle of 12.4° is enough): they reflect totally
    // (R = 1 instead of 3.4 %) and land far out, early.
    let crit = critical_angle(N_ICE, N_AIR).unwrap();
    assert!((crit.to_degrees() - 49.8).abs() < 0.1);
    let need = snell_angle(crit, N_ICE, N_FIBRE).unwrap().to_degrees() - INCLINATION_DEG;
    assert!((need - 8.9).abs() < 0.5, "{need}");
    assert!(t1.1 > 1.5 * a1.1, "tracer {t1:?} vs analytic {a1:?}");
    assert!(t1.0 < a1.0, "tracer {t1:?} vs analytic {a1:?}");
    assert!(t2.1 > 0.0);
}

#[test]
fn one_accretion_is_one_ice_body() {
    // Bubbles stay frozen in: the scattered light only grows with thickness.
    let c = cfg(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
    let a = accretion_curve(&c, 3, 7);
    for w in a.points.windows(2) {
        assert!(w[1].i1_scat_ua >= w[0].i1_scat_ua);
        assert!(w[1].i2_scat_ua >= w[0].i2_scat_ua);
        // No jumps: a new 0.1 mm layer changes I1 by a small part of its range.
        assert!((w[1].i1_ua - w[0].i1_ua).abs() < 5.0, "{w:?}");
    }
    // The same body seen on a coarser grid: identical at the common thicknesses.
    let mut c2 = c.clone();
    c2.step_mm = 0.5;
    let b = accretion_curve(&c2, 3, 7);
    assert_eq!(b.points.len(), 31);
    for p in &b.points {
        let i = (p.thickness_mm / 0.1).round() as usize;
        let q = a.points[i];
        assert!(
            (p.i1_ua - q.i1_ua).abs() < 1e-9 * (1.0 + q.i1_ua),
            "{p:?} {q:?}"
        );
        assert!((p.i2_scat_ua - q.i2_scat_ua).abs() < 1e-9 * (1.0 + q.i2_ua));
    }
}

#[test]
fn same_seed_same_curve_other_run_other_curve() {
    let c = cfg(IceKind::Glazed, SensorKind::B, Geometry::ThesisCh5);
    let a = accretion_curve(&c, 42, 3);
    let b = accretion_curve(&c, 42, 3);
    assert_eq!(a, b);
    let d = accretion_curve(&c, 42, 4);
    assert_ne!(a, d);
    let e = accretion_curve(&c, 43, 3);
    assert_ne!(a, e);
}

/// A thread keeps the buffers of one accretion for the next: an accretion traced after
/// others (other media, sensors, thickness grids and bubble counts) on the same thread is
/// the one traced first on a fresh thread, bit for bit.
#[test]
fn an_accretion_does_not_depend_on_the_accretions_before_it_on_its_thread() {
    let mut rime = cfg(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
    rime.max_mm = 6.0;
    let fresh = {
        let c = rime.clone();
        std::thread::spawn(move || accretion_curve(&c, 17, 2))
            .join()
            .unwrap()
    };
    let mut others = [
        cfg(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5),
        cfg(IceKind::Glazed, SensorKind::A, Geometry::ThesisCh3),
        cfg(IceKind::Water, SensorKind::B, Geometry::ThesisCh5),
    ];
    others[0].max_mm = 15.0;
    others[1].step_mm = 0.05;
    let after = std::thread::spawn(move || {
        for (k, c) in others.iter().enumerate() {
            accretion_curve(c, 5, k as u64);
        }
        accretion_curve(&rime, 17, 2)
    })
    .join()
    .unwrap();
    assert_eq!(after, fresh);
}

#[test]
fn monte_carlo_is_identical_for_one_and_two_threads() {
    let mut c = cfg(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
    c.max_mm = 5.0;
    let run = |n: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| montecarlo::monte_carlo(&c, 24, 9, &|| {}))
    };
    let one = run(1);
    let two = run(2);
    assert_eq!(one, two); // bit for bit: f64 PartialEq on every field
    let three = run(3);
    assert_eq!(one, three);
    // And each run equals the stand-alone accretion.
    assert_eq!(one.runs[5], accretion_curve(&c, 9, 5));
}

#[test]
fn sensor_a_has_a_dry_offset_sensor_b_none() {
    let a = accretion_curve(
        &cfg(IceKind::Glazed, SensorKind::A, Geometry::ThesisCh5),
        1,
        0,
    );
    let b = accretion_curve(
        &cfg(IceKind::Glazed, SensorKind::B, Geometry::ThesisCh5),
        1,
        0,
    );
    // Thesis §5.2.1: I1 ≈ 13 µA, I2 ≈ 2.5 µA on the dry Sensor A.
    let (a1, a2) = a.currents_at(0.0);
    assert!((a1 - 13.0).abs() < 1.0, "{a1}");
    assert!((a2 - 2.5).abs() < 0.5, "{a2}");
    assert_eq!(b.currents_at(0.0), (0.0, 0.0));
    // Ice lowers the face reflection (n 1.31 instead of 1): I1 first drops (Fig. 5.5).
    assert!(a.currents_at(0.2).0 < a1 - 5.0);
    // Sensor B: I1 rises at once when ice forms (Fig. 5.6).
    assert!(b.currents_at(0.3).0 > 1.0);
}

#[test]
fn glazed_reflection_dominates_scattering() {
    let c = cfg(IceKind::Glazed, SensorKind::B, Geometry::ThesisCh5);
    let mc = montecarlo::monte_carlo(&c, 40, 5, &|| {});
    let mut refl = [0.0; 2];
    let mut scat = [0.0; 2];
    for r in &mc.runs {
        for p in &r.points {
            refl[0] += p.i1_refl_ua;
            refl[1] += p.i2_refl_ua;
            scat[0] += p.i1_scat_ua;
            scat[1] += p.i2_scat_ua;
        }
    }
    assert!(refl[0] > 3.0 * scat[0], "{refl:?} {scat:?}");
    assert!(refl[1] > 3.0 * scat[1], "{refl:?} {scat:?}");
    // Bubbles keep the currents above zero at 15 mm (thesis Fig. 3.20, 5.13).
    let end = mc.points.last().unwrap();
    assert!(end.mean_ua[0] > 0.01 && end.mean_ua[1] > 0.01);
}

#[test]
fn rime_matches_the_thesis_levels() {
    let c = cfg(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
    let mc = montecarlo::monte_carlo(&c, 300, 11, &|| {});
    let at = |d: f64| mc.points[(d / 0.1).round() as usize];
    // Fig. 5.7 / 5.16: I1 ≈ 30 µA at 15 mm (the responsivity is chosen for this).
    let end = at(15.0);
    assert!((end.mean_ua[0] - 30.0).abs() < 1.5, "{end:?}");
    // I1 ≈ 3·I2 at 15 mm. The thesis reads "roughly three times" off six measurements; the
    // model's ratio depends on the undocumented scattering-angle law, so accept 2..4.
    let ratio = end.mean_ua[0] / end.mean_ua[1];
    assert!((2.0..=4.0).contains(&ratio), "I1/I2 = {ratio}");
    // Mean I1 rises monotonically beyond 5 mm (0.5 mm steps, far above the MC noise).
    let mut prev = at(5.0).mean_ua[0];
    for k in 11..=30 {
        let v = at(k as f64 * 0.5).mean_ua[0];
        assert!(
            v > prev,
            "not rising at {} mm: {v} ≤ {prev}",
            k as f64 * 0.5
        );
        prev = v;
    }
    // > 25 µA below ~2 mm (§5.2.2) on average, and a reflection peak then a dip (2.5–5 mm).
    assert!(at(2.0).mean_ua[0] > 25.0, "{:?}", at(2.0));
    assert!(at(3.0).mean_ua[0] < at(2.0).mean_ua[0]);
    // Scattering dominates beyond 5 mm (Fig. 3.23).
    let r = &mc.runs[0].points[100];
    assert!(r.i1_scat_ua > 5.0 * r.i1_refl_ua, "{r:?}");
    // Small spread beyond 5 mm compared with the signal (Fig. 5.16).
    assert!(at(10.0).cov_ua2[0][0].sqrt() < 0.05 * at(10.0).mean_ua[0]);
}

#[test]
fn water_reads_like_flat_glazed_ice() {
    let w = accretion_curve(
        &cfg(IceKind::Water, SensorKind::B, Geometry::ThesisCh5),
        1,
        0,
    );
    let mut g = cfg(IceKind::Glazed, SensorKind::B, Geometry::ThesisCh5);
    g.params.slope_max_rad = 0.0;
    g.params.diffuse_max_rad = 0.0;
    let gl = accretion_curve(&g, 1, 0);
    let (pw, pg) = (peaks_of(&w), peaks_of(&gl));
    for k in 0..2 {
        assert!((pw[k].1 - pg[k].1).abs() < 0.15 * pg[k].1, "{pw:?} {pg:?}");
        assert!((pw[k].0 - pg[k].0).abs() <= 0.5, "{pw:?} {pg:?}");
    }
}

#[test]
fn acceptance_cone_rejects_the_specular_return() {
    let mut c = cfg(IceKind::Flat, SensorKind::B, Geometry::ThesisCh5);
    let lit = peaks_of(&accretion_curve(&c, 1, 0));
    c.coupling = Coupling::AcceptanceCone;
    let cone = peaks_of(&accretion_curve(&c, 1, 0));
    assert!(lit[0].1 > 10.0);
    assert!(cone[0].1 < 0.01 * lit[0].1, "{cone:?} vs {lit:?}");
}

#[test]
fn currents_at_interpolates_and_clamps() {
    let c = accretion_curve(
        &cfg(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5),
        1,
        0,
    );
    let (p, q) = (c.points[20], c.points[21]);
    let (i1, i2) = c.currents_at(2.05);
    assert!((i1 - 0.5 * (p.i1_ua + q.i1_ua)).abs() < 1e-9);
    assert!((i2 - 0.5 * (p.i2_ua + q.i2_ua)).abs() < 1e-9);
    assert_eq!(c.currents_at(-1.0), c.currents_at(0.0));
    let last = c.points.last().unwrap();
    assert_eq!(c.currents_at(99.0), (last.i1_ua, last.i2_ua));
    assert_eq!(c.currents_at(f64::NAN), c.currents_at(0.0));
    assert_eq!(Curve::default().currents_at(1.0), (0.0, 0.0));
    for p in &c.points {
        assert!((p.i1_ua - p.i1_refl_ua - p.i1_scat_ua).abs() < 1e-9);
        assert!((p.i2_ua - p.i2_refl_ua - p.i2_scat_ua).abs() < 1e-9);
    }
}

#[test]
fn bad_configs_are_rejected() {
    let mut c = cfg(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
    assert!(c.validate().is_ok());
    c.step_mm = 0.0;
    assert!(c.validate().is_err());
    c.step_mm = f64::NAN;
    assert!(c.validate().is_err());
    c.step_mm = 0.1;
    c.max_mm = -1.0;
    assert!(c.validate().is_err());
    c.max_mm = 15.0;
    c.params.p_bubble = 1.5;
    assert!(c.validate().is_err());
    let d = SimConfig::new(IceKind::Flat, SensorKind::A, Geometry::ThesisCh3);
    assert_eq!((d.max_mm, d.step_mm), (15.0, 0.1));
    assert_eq!(d.thicknesses_mm().len(), 151);
}

#[test]
fn diffuse_reflection_lowers_glazed_levels_only_with_mean_surface_fresnel() {
    // Mean over 60 accretions of the peak of the mean I1, with and without δ_R.
    let peak_mean = |diffuse: bool, fresnel: DiffuseFresnel| {
        let mut c = cfg(IceKind::Glazed, SensorKind::B, Geometry::ThesisCh5);
        if !diffuse {
            c.params.diffuse_max_rad = 0.0;
        }
        c.diffuse_fresnel = fresnel;
        let mc = montecarlo::monte_carlo(&c, 60, 2, &|| {});
        peak(mc.points.iter().map(|p| (p.thickness_mm, p.mean_ua[0]))).1
    };
    let none = peak_mean(false, DiffuseFresnel::Facet);
    let facet = peak_mean(true, DiffuseFresnel::Facet);
    let mean_surface = peak_mean(true, DiffuseFresnel::MeanSurface);
    // Thesis Fig. 5.14: diffuse reflection lowers the levels — reproduced when the Fresnel
    // factor stays that of the mean surface; with facet Fresnel, facets tilted toward +x
    // reflect totally and the levels do not drop (README, "Where they differ").
    assert!(mean_surface < 0.9 * none, "{mean_surface} vs {none}");
    assert!(facet > 0.95 * none, "{facet} vs {none}");
    // Without diffuse angles the option changes nothing.
    assert_eq!(
        peak_mean(false, DiffuseFresnel::MeanSurface).to_bits(),
        none.to_bits()
    );
}

#[test]
#[should_panic(expected = "invalid SimConfig: bad parameter: step")]
fn an_invalid_config_panics_with_a_message_instead_of_allocating_forever() {
    let mut c = cfg(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
    c.step_mm = 0.0;
    let _ = accretion_curve(&c, 1, 0);
}

#[test]
fn extreme_parameters_finish_quickly() {
    // Very rare bubbles (huge geometric gaps) and the steepest allowed slope: no hang, no NaN.
    let mut c = cfg(IceKind::Glazed, SensorKind::A, Geometry::ThesisCh5);
    c.params.p_bubble = 1e-12;
    c.params.slope_max_rad = 20f64.to_radians();
    for run in 0..20 {
        let k = accretion_curve(&c, 5, run);
        assert!(
            k.points
                .iter()
                .all(|p| p.i1_ua.is_finite() && p.i2_ua.is_finite())
        );
    }
    c.params.p_bubble = 1.0;
    let k = accretion_curve(&c, 5, 0);
    assert!(
        k.points
            .iter()
            .all(|p| p.i1_ua.is_finite() && p.i1_ua >= 0.0)
    );
}
