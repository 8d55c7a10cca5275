//! The thickness bound with the gain an unknown nuisance parameter (`fois_sim::gain`) against
//! closed forms and against the Gaussian Fisher information computed from scratch.
// A test crate: unwrap and expect are assertions here.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use fois_sim::gain::{crlb_gain_unknown, fisher_with_gain, thickness_std_mm};
use fois_sim::montecarlo::{DEFAULT_FIT_HALF_WIDTH_MM, fisher};
use fois_sim::*;

type M2 = [[f64; 2]; 2];

fn inv(s: M2) -> M2 {
    let d = s[0][0] * s[1][1] - s[0][1] * s[1][0];
    [[s[1][1] / d, -s[0][1] / d], [-s[1][0] / d, s[0][0] / d]]
}

fn mul(a: M2, b: M2) -> M2 {
    let mut p = [[0.0; 2]; 2];
    for r in 0..2 {
        for c in 0..2 {
            p[r][c] = a[r][0] * b[0][c] + a[r][1] * b[1][c];
        }
    }
    p
}

/// The Fisher information of θ = (d, λ) for x ~ N(m(θ), C(θ)) from central differences of
/// m(d, λ) = e^λ (μ + μ′ (d − d₀)), C(d, λ) = e^{2λ} (Σ + Σ′ (d − d₀)): the general formula
/// J_ij = m_iᵀ C⁻¹ m_j + ½ tr(C⁻¹ C_i C⁻¹ C_j), written without the algebra of the module.
fn fisher_by_differences(mu: [f64; 2], dmu: [f64; 2], sigma: M2, dsigma: M2) -> M2 {
    let m = |d: f64, l: f64| [0, 1].map(|k| l.exp() * (mu[k] + dmu[k] * d));
    let c = |d: f64, l: f64| {
        let mut x = [[0.0; 2]; 2];
        for r in 0..2 {
            for k in 0..2 {
                x[r][k] = (2.0 * l).exp() * (sigma[r][k] + dsigma[r][k] * d);
            }
        }
        x
    };
    let h = 1e-5;
    let dm = [
        [0, 1].map(|k| (m(h, 0.0)[k] - m(-h, 0.0)[k]) / (2.0 * h)),
        [0, 1].map(|k| (m(0.0, h)[k] - m(0.0, -h)[k]) / (2.0 * h)),
    ];
    let dc = |which: usize| {
        let (p, q) = if which == 0 {
            (c(h, 0.0), c(-h, 0.0))
        } else {
            (c(0.0, h), c(0.0, -h))
        };
        let mut x = [[0.0; 2]; 2];
        for r in 0..2 {
            for k in 0..2 {
                x[r][k] = (p[r][k] - q[r][k]) / (2.0 * h);
            }
        }
        x
    };
    let ci = inv(c(0.0, 0.0));
    let mut j = [[0.0; 2]; 2];
    for a in 0..2 {
        for b in 0..2 {
            let quad: f64 = (0..2)
                .flat_map(|r| (0..2).map(move |k| (r, k)))
                .map(|(r, k)| dm[a][r] * ci[r][k] * dm[b][k])
                .sum();
            let t = mul(mul(ci, dc(a)), mul(ci, dc(b)));
            j[a][b] = quad + 0.5 * (t[0][0] + t[1][1]);
        }
    }
    j
}

#[test]
fn fisher_matrix_matches_the_gaussian_information_from_scratch() {
    // The rime numbers at 5 mm (1000 accretions, seed 1) and a made-up correlated case.
    let cases = [
        (
            [25.159, 9.563],
            [1.664, -0.505],
            [[0.2316, -0.0607], [-0.0607, 0.3782]],
            [[-0.2554, 0.4380], [0.4380, -0.1675]],
        ),
        (
            [3.0, 7.0],
            [-0.4, 2.5],
            [[2.0, 0.9], [0.9, 1.5]],
            [[0.3, -0.2], [-0.2, 0.7]],
        ),
    ];
    for (mu, dmu, sigma, dsigma) in cases {
        let want = fisher_by_differences(mu, dmu, sigma, dsigma);
        // No prior (S = ∞): the data's information alone.
        let (full, _) = fisher_with_gain(mu, dmu, sigma, dsigma, f64::INFINITY).unwrap();
        for r in 0..2 {
            for c in 0..2 {
                let rel = (full[r][c] - want[r][c]).abs() / want[r][c].abs().max(1.0);
                assert!(rel < 1e-6, "{r}{c}: {} vs {}", full[r][c], want[r][c]);
            }
        }
        // J_dd is the known-gain information of `montecarlo::fisher`, both forms.
        let (f_full, f_mean) = fisher(dmu, sigma, dsigma);
        let (_, mean_only) = fisher_with_gain(mu, dmu, sigma, dsigma, 0.1).unwrap();
        assert!((full[0][0] - f_full).abs() < 1e-12 * f_full);
        assert!((mean_only[0][0] - f_mean).abs() < 1e-12 * f_mean);
        // The prior adds 1/S² to J_λλ only.
        let (with_prior, _) = fisher_with_gain(mu, dmu, sigma, dsigma, 0.1).unwrap();
        assert!((with_prior[1][1] - full[1][1] - 100.0).abs() < 1e-9);
        assert_eq!(with_prior[0][1], full[0][1]);
    }
}

#[test]
fn a_thickness_change_that_looks_like_a_gain_change_is_told_only_by_the_prior() {
    // Independent channels, Σ′ = 0, μ′ = c·μ: the mean-term information on d left is
    // c² μᵀΣ⁻¹μ · (1/S²) / (μᵀΣ⁻¹μ + 1/S²).
    let (mu, c) = ([20.0, 8.0], 0.05f64);
    let sigma = [[0.25, 0.0], [0.0, 0.16]];
    let q: f64 = 20.0 * 20.0 / 0.25 + 8.0 * 8.0 / 0.16; // μᵀΣ⁻¹μ = 2000
    for s in [0.01, 0.1, 1.0] {
        let p = 1.0 / (s * s);
        let want = 1.0 / (c * c * q * p / (q + p)).sqrt();
        let (_, mean_only) =
            fisher_with_gain(mu, [c * mu[0], c * mu[1]], sigma, [[0.0; 2]; 2], s).unwrap();
        let got = thickness_std_mm(mean_only);
        assert!((got - want).abs() < 1e-9 * want, "S = {s}: {got} vs {want}");
    }
    // Known gain: 1/(c √q) = 0.447 mm; S = 0.1: √(1 + q S²) = √21 ≈ 4.6 times that.
    let known = 1.0 / (c * q.sqrt());
    let (_, m0) = fisher_with_gain(mu, [c * mu[0], c * mu[1]], sigma, [[0.0; 2]; 2], 0.0).unwrap();
    assert!((thickness_std_mm(m0) - known).abs() < 1e-12);
    let (_, m1) = fisher_with_gain(mu, [c * mu[0], c * mu[1]], sigma, [[0.0; 2]; 2], 0.1).unwrap();
    assert!((thickness_std_mm(m1) / known - 21f64.sqrt()).abs() < 1e-9);
}

#[test]
fn a_slope_orthogonal_to_the_gain_loses_nothing() {
    // μ′ᵀΣ⁻¹μ = 0 and Σ′ = 0: J_dλ = 0, the bound is the known-gain one for any prior.
    let (mu, sigma) = ([10.0, 5.0], [[1.0, 0.0], [0.0, 0.25]]);
    let dmu = [1.0, -0.5]; // 10·1/1 + 5·(−0.5)/0.25 = 0
    let known = thickness_std_mm(
        fisher_with_gain(mu, dmu, sigma, [[0.0; 2]; 2], 0.0)
            .unwrap()
            .0,
    );
    for s in [0.01, 1.0, f64::INFINITY] {
        let (full, _) = fisher_with_gain(mu, dmu, sigma, [[0.0; 2]; 2], s).unwrap();
        assert_eq!(full[0][1], 0.0);
        assert_eq!(thickness_std_mm(full), known);
    }
    assert!(fisher_with_gain(mu, dmu, [[1.0, 1.0], [1.0, 1.0]], [[0.0; 2]; 2], 0.1).is_none());
}

#[test]
fn rime_loses_most_where_both_currents_rise_together() {
    let c = SimConfig::new(IceKind::Rime, SensorKind::B, Geometry::ThesisCh5);
    let mc = monte_carlo(&c, 300, 5, &|| {});
    let bound = crlb(&mc.points, DEFAULT_FIT_HALF_WIDTH_MM);
    let loose = crlb_gain_unknown(&bound, 0.1);
    let tight = crlb_gain_unknown(&bound, 0.01);
    let known = crlb_gain_unknown(&bound, 0.0);
    // The dry face stays undefined; a known gain is the thesis's bound.
    assert!(loose[0].0.is_nan() && loose[0].1.is_nan());
    for (i, p) in bound.iter().enumerate().skip(10) {
        assert!(
            (known[i].0 - p.crlb_std_mm).abs() < 1e-9 * p.crlb_std_mm,
            "{i}"
        );
        // A looser prior never helps: known ≤ tight ≤ loose.
        assert!(tight[i].0 >= known[i].0 * (1.0 - 1e-12), "{i}");
        assert!(loose[i].0 >= tight[i].0 * (1.0 - 1e-12), "{i}");
    }
    // 2 mm: the reflection peak, I1 and I2 move apart: the gain costs little (< 25 %).
    // 6 mm: both rise in proportion (μ′ ∥ μ), the bound grows several times.
    let ratio = |i: usize| loose[i].0 / bound[i].crlb_std_mm;
    assert!(ratio(20) < 1.25, "2 mm: {}", ratio(20));
    assert!(ratio(60) > 3.0, "6 mm: {}", ratio(60));
    assert!(ratio(150) > 1.5, "15 mm: {}", ratio(150));
}
