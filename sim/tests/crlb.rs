//! Fits and the Cramér–Rao bound (thesis §5.4) against closed forms.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use fois_sim::montecarlo::*;
use fois_sim::*;

#[test]
fn fisher_information_closed_form() {
    // Independent channels: J = Σ_k μ_k'²/σ_k² + ½ Σ_k (σ_k²'/σ_k²)².
    let (full, mean) = fisher(
        [2.0, 1.0],
        [[4.0, 0.0], [0.0, 1.0]],
        [[0.8, 0.0], [0.0, -0.5]],
    );
    let want_mean = 4.0 / 4.0 + 1.0 / 1.0;
    let want_full = want_mean + 0.5 * ((0.8f64 / 4.0).powi(2) + (0.5f64 / 1.0).powi(2));
    assert!((mean - want_mean).abs() < 1e-12);
    assert!((full - want_full).abs() < 1e-12);
    // Correlated: μ'ᵀΣ⁻¹μ' with Σ = [[2, 1], [1, 2]], μ' = (1, 1): Σ⁻¹μ' = (1/3, 1/3) → 2/3.
    let (f, m) = fisher([1.0, 1.0], [[2.0, 1.0], [1.0, 2.0]], [[0.0; 2]; 2]);
    assert!((m - 2.0 / 3.0).abs() < 1e-12 && (f - m).abs() < 1e-12);
    // Singular Σ: not defined.
    assert!(
        fisher([1.0, 1.0], [[1.0, 1.0], [1.0, 1.0]], [[0.0; 2]; 2])
            .0
            .is_nan()
    );
    assert!(fisher([1.0, 1.0], [[0.0; 2]; 2], [[0.0; 2]; 2]).1.is_nan());
}

#[test]
fn local_quadratic_is_exact_on_quadratics_and_gives_the_slope() {
    let x: Vec<f64> = (0..=150).map(|i| i as f64 * 0.1).collect();
    let y: Vec<f64> = x.iter().map(|&v| 3.0 - 2.0 * v + 0.25 * v * v).collect();
    for (i, (f, d)) in local_quadratic(&x, &y, 0.6).into_iter().enumerate() {
        assert!((f - y[i]).abs() < 1e-8, "{i}");
        assert!((d - (-2.0 + 0.5 * x[i])).abs() < 1e-7, "{i}");
    }
}

#[test]
fn kernel_average_keeps_covariances_positive_definite() {
    // Rough, nearly singular covariances in a row: the average stays PD.
    let x: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
    let mut c11 = Vec::new();
    let mut c12 = Vec::new();
    let mut c22 = Vec::new();
    for i in 0..50 {
        let a = 1.0 + (i % 7) as f64;
        let b = 0.5 + (i % 3) as f64;
        let rho = if i % 2 == 0 { 0.999 } else { -0.999 };
        c11.push(a * a);
        c22.push(b * b);
        c12.push(rho * a * b);
    }
    let (s11, s12, s22) = (
        kernel_average(&x, &c11, 0.6),
        kernel_average(&x, &c12, 0.6),
        kernel_average(&x, &c22, 0.6),
    );
    for i in 0..50 {
        assert!(
            s11[i] > 0.0 && s11[i] * s22[i] - s12[i] * s12[i] > 0.0,
            "{i}"
        );
    }
    // A local quadratic of the same entries would not guarantee it; the kernel average does.
}

#[test]
fn rime_crlb_is_finite_and_the_local_fit_beats_a_global_polynomial() {
    let c = SimConfig::new(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
    let mc = monte_carlo(&c, 200, 3, &|| {});
    let bound = crlb(&mc.points, DEFAULT_FIT_HALF_WIDTH_MM);
    assert_eq!(bound.len(), 151);
    // d = 0: every run reads 0 → Σ singular → undefined, not a fake number.
    assert!(bound[0].crlb_std_mm.is_nan());
    for p in &bound[10..] {
        assert!(p.crlb_std_mm.is_finite() && p.crlb_std_mm > 0.0, "{p:?}");
        // The dΣ term only adds information.
        assert!(p.crlb_std_mm <= p.crlb_no_dsigma_std_mm + 1e-12, "{p:?}");
        let s = p.sigma_ua2;
        assert!(s[0][0] > 0.0 && s[0][0] * s[1][1] - s[0][1] * s[1][0] > 0.0);
    }
    // Thesis Fig. 5.18: the uncertainty grows with thickness beyond the reflection region.
    assert!(bound[150].crlb_std_mm > bound[60].crlb_std_mm);
    // Judge the fit by its residuals: within ~the standard error of the raw means.
    let q = fit_quality(&mc.points, &bound, 200);
    for k in 0..2 {
        assert!(q.rms_residual_ua[k] < 1.5 * q.rms_std_error_ua[k], "{q:?}");
    }
    // One global polynomial of moderate degree follows the peak and dip badly.
    let x: Vec<f64> = mc.points.iter().map(|p| p.thickness_mm).collect();
    let y: Vec<f64> = mc.points.iter().map(|p| p.mean_ua[0]).collect();
    let g = global_polynomial_fit(&x, &y, 6);
    let rms_g = (x
        .iter()
        .enumerate()
        .map(|(i, _)| (y[i] - g[i]).powi(2))
        .sum::<f64>()
        / x.len() as f64)
        .sqrt();
    assert!(
        rms_g > 3.0 * q.rms_residual_ua[0],
        "global {rms_g} local {q:?}"
    );
}
