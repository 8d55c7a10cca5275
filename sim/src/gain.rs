//! The Cramér–Rao bound of the thickness when the gain is unknown: a nuisance parameter.
//!
//! The thesis's bound (§5.4, Fig. 5.18; [`crate::montecarlo::crlb`]) knows the gain of the
//! optical path exactly. A real node does not: a dirty face, an aged LED or a drifted
//! phototransistor multiply *both* channel currents by one factor g. Then one frame
//! x = g · y with y ~ N(μ(d), Σ(d)) has mean g μ(d) and covariance g² Σ(d), and the parameter
//! is (d, λ) with λ = ln g, whose prior is N(0, S²) (S is about the relative gain spread:
//! S = 0.1 is a gain known to about 10 %). At the nominal gain (λ = 0):
//!
//! ```text
//! ∂m/∂d = μ′   ∂m/∂λ = μ   ∂C/∂d = Σ′   ∂C/∂λ = 2Σ
//! J_dd = μ′ᵀΣ⁻¹μ′ + ½ tr(Σ⁻¹Σ′Σ⁻¹Σ′)          (the known-gain Fisher information)
//! J_dλ = μ′ᵀΣ⁻¹μ  + tr(Σ⁻¹Σ′)
//! J_λλ = μᵀΣ⁻¹μ   + 2 · 2 + 1/S²             (two channels; the prior's information)
//! σ_d  = √[J⁻¹]_dd = 1/√(J_dd − J_dλ²/J_λλ)
//! ```
//!
//! The mean-term-only variant (like `crlb_no_dsigma_std_mm`) drops the trace terms and the 4.
//! The information lost is J_dλ²/J_λλ: a thickness change that looks like a gain change
//! (μ′ parallel to μ in the metric Σ⁻¹, i.e. both currents rising in proportion) cannot be
//! told from one; only the prior and the noise's shape then pin the gain down.

use crate::montecarlo::CrlbPoint;

/// A Fisher information of (d, ln g): `[[J_dd, J_dλ], [J_dλ, J_λλ]]`.
pub type GainFisher = [[f64; 2]; 2];

/// The 2×2 inverse of a covariance, or `None` when it is not positive definite (the same
/// test as [`crate::montecarlo::fisher`]).
fn inverse(sigma: [[f64; 2]; 2]) -> Option<[[f64; 2]; 2]> {
    let det = sigma[0][0] * sigma[1][1] - sigma[0][1] * sigma[1][0];
    let scale = sigma[0][0].abs().max(sigma[1][1].abs());
    if sigma[0][0].is_nan() || sigma[0][0] <= 0.0 || det.is_nan() || det <= 1e-12 * scale * scale {
        return None;
    }
    Some([
        [sigma[1][1] / det, -sigma[0][1] / det],
        [-sigma[1][0] / det, sigma[0][0] / det],
    ])
}

/// uᵀ A v.
fn form(u: [f64; 2], a: [[f64; 2]; 2], v: [f64; 2]) -> f64 {
    u[0] * (a[0][0] * v[0] + a[0][1] * v[1]) + u[1] * (a[1][0] * v[0] + a[1][1] * v[1])
}

/// A B for 2×2 matrices.
fn product(a: [[f64; 2]; 2], b: [[f64; 2]; 2]) -> [[f64; 2]; 2] {
    let mut p = [[0.0; 2]; 2];
    for (r, pr) in p.iter_mut().enumerate() {
        for (c, prc) in pr.iter_mut().enumerate() {
            *prc = a[r][0] * b[0][c] + a[r][1] * b[1][c];
        }
    }
    p
}

/// Fisher information of (d, ln g) for one frame, the prior's information 1/S² on ln g
/// included: `(full, mean_only)`, each `[[J_dd, J_dλ], [J_dλ, J_λλ]]`. `full` holds the
/// covariance terms of the Gaussian information too (like `crlb_std_mm` of
/// [`crate::montecarlo::crlb`]), `mean_only` the mean terms alone (like its
/// `crlb_no_dsigma_std_mm`). `mu_ua`, `sigma_ua2` at the nominal gain, with their thickness
/// derivatives. A `gain_sd` of 0 is a known gain (J_λλ = ∞). `None` when Σ is not positive
/// definite.
pub fn fisher_with_gain(
    mu_ua: [f64; 2],
    dmu_ua_per_mm: [f64; 2],
    sigma_ua2: [[f64; 2]; 2],
    dsigma_ua2_per_mm: [[f64; 2]; 2],
    gain_sd: f64,
) -> Option<(GainFisher, GainFisher)> {
    let inv = inverse(sigma_ua2)?;
    let a = product(inv, dsigma_ua2_per_mm); // Σ⁻¹Σ′
    let aa = product(a, a);
    let prior = (gain_sd * gain_sd).recip();
    let (m_dd, m_dl, m_ll) = (
        form(dmu_ua_per_mm, inv, dmu_ua_per_mm),
        form(dmu_ua_per_mm, inv, mu_ua),
        form(mu_ua, inv, mu_ua),
    );
    // ½ tr(Σ⁻¹Σ′Σ⁻¹Σ′); ½ tr(Σ⁻¹Σ′ Σ⁻¹2Σ) = tr(Σ⁻¹Σ′); ½ tr(Σ⁻¹2Σ Σ⁻¹2Σ) = ½ tr(4 I₂) = 4.
    let (c_dd, c_dl, c_ll) = (0.5 * (aa[0][0] + aa[1][1]), a[0][0] + a[1][1], 4.0);
    let matrix = |dd: f64, dl: f64, ll: f64| [[dd, dl], [dl, ll + prior]];
    Some((
        matrix(m_dd + c_dd, m_dl + c_dl, m_ll + c_ll),
        matrix(m_dd, m_dl, m_ll),
    ))
}

/// √[J⁻¹]_dd of a Fisher information of (d, ln g), mm: 1/√(J_dd − J_dλ²/J_λλ) (the Schur
/// complement, the information on d left once ln g is estimated too; a known gain, J_λλ = ∞,
/// loses nothing). NaN when that information is not positive.
pub fn thickness_std_mm(j: GainFisher) -> f64 {
    let lost = if j[1][1].is_infinite() {
        0.0
    } else {
        j[0][1] * j[0][1] / j[1][1]
    };
    let info = j[0][0] - lost;
    if info > 0.0 && info.is_finite() {
        info.sqrt().recip()
    } else {
        f64::NAN
    }
}

/// The bound on the thickness with the gain unknown (prior standard deviation `gain_sd` of
/// ln g) at every point of a [`crate::montecarlo::crlb`] result (its fitted μ, μ′, Σ, Σ′),
/// mm: `(full, mean_only)` per point. NaN where the known-gain bound is NaN (a singular Σ,
/// the dry face).
pub fn crlb_gain_unknown(bound: &[CrlbPoint], gain_sd: f64) -> Vec<(f64, f64)> {
    bound
        .iter()
        .map(|p| {
            if p.crlb_std_mm.is_nan() {
                return (f64::NAN, f64::NAN);
            }
            match fisher_with_gain(
                p.mu_ua,
                p.dmu_ua_per_mm,
                p.sigma_ua2,
                p.dsigma_ua2_per_mm,
                gain_sd,
            ) {
                Some((full, mean_only)) => (thickness_std_mm(full), thickness_std_mm(mean_only)),
                None => (f64::NAN, f64::NAN),
            }
        })
        .collect()
}
