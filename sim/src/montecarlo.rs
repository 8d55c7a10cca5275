//! Monte Carlo over accretions (thesis §5.4): mean μ(d), covariance Σ(d) of (I1, I2), a
//! smooth fit of both, and the Cramér–Rao lower bound of the thickness.

use rayon::prelude::*;

use crate::model::{Curve, SensorModel, SimConfig};

/// Statistics at one thickness.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct McPoint {
    /// Thickness, mm.
    pub thickness_mm: f64,
    /// Mean (I1, I2), µA.
    pub mean_ua: [f64; 2],
    /// Covariance of (I1, I2), µA² (unbiased, M − 1).
    pub cov_ua2: [[f64; 2]; 2],
}

/// Result of a Monte Carlo run.
#[derive(Clone, Debug, PartialEq)]
pub struct MonteCarlo {
    /// Per-thickness statistics.
    pub points: Vec<McPoint>,
    /// Every accretion, in run order (for scatter plots like Fig. 5.17).
    pub runs: Vec<Curve>,
}

/// Run `runs` accretions of `cfg` (runs 0..runs of `seed`) in parallel on the current rayon
/// pool. `on_done` is called once per finished accretion (progress bars). The result is the
/// same for any thread count: each accretion has its own random streams and the statistics
/// are summed in run order.
pub fn monte_carlo(
    cfg: &SimConfig,
    runs: u64,
    seed: u64,
    on_done: &(dyn Fn() + Sync),
) -> MonteCarlo {
    let model = SensorModel::new(cfg);
    let curves: Vec<Curve> = (0..runs)
        .into_par_iter()
        .map(|r| {
            let c = model.accretion(seed, r);
            on_done();
            c
        })
        .collect();
    MonteCarlo {
        points: statistics(&curves),
        runs: curves,
    }
}

/// Mean and covariance per thickness of a set of curves on the same grid.
pub fn statistics(curves: &[Curve]) -> Vec<McPoint> {
    let Some(first) = curves.first() else {
        return Vec::new();
    };
    let m = curves.len() as f64;
    (0..first.points.len())
        .map(|i| {
            let mut s = [0.0f64; 2];
            for c in curves {
                s[0] += c.points[i].i1_ua;
                s[1] += c.points[i].i2_ua;
            }
            let mean = [s[0] / m, s[1] / m];
            let mut cov = [[0.0f64; 2]; 2];
            for c in curves {
                let e = [c.points[i].i1_ua - mean[0], c.points[i].i2_ua - mean[1]];
                cov[0][0] += e[0] * e[0];
                cov[0][1] += e[0] * e[1];
                cov[1][1] += e[1] * e[1];
            }
            let k = if curves.len() > 1 {
                1.0 / (m - 1.0)
            } else {
                0.0
            };
            cov[0][0] *= k;
            cov[0][1] *= k;
            cov[1][1] *= k;
            cov[1][0] = cov[0][1];
            McPoint {
                thickness_mm: first.points[i].thickness_mm,
                mean_ua: mean,
                cov_ua2: cov,
            }
        })
        .collect()
}

#[inline]
fn tricube(u: f64) -> f64 {
    let a = u.abs();
    if a >= 1.0 {
        0.0
    } else {
        let t = 1.0 - a * a * a;
        t * t * t
    }
}

/// Local quadratic regression (LOESS with a tricube kernel of half-width `half_width_mm`):
/// the fitted value and first derivative at every x. A local fit follows the sharp peak
/// and dip of the mean curves between 1 and 4 mm, which one global polynomial cannot
/// (ARCHITECTURE.md, simulator conventions).
pub fn local_quadratic(x: &[f64], y: &[f64], half_width_mm: f64) -> Vec<(f64, f64)> {
    x.iter()
        .map(|&x0| {
            // Weighted normal equations for y ≈ c0 + c1 t + c2 t², t = x − x0.
            let mut s = [0.0f64; 5];
            let mut b = [0.0f64; 3];
            for (&xi, &yi) in x.iter().zip(y) {
                let t = xi - x0;
                let w = tricube(t / half_width_mm);
                if w == 0.0 {
                    continue;
                }
                let mut tp = w;
                for (k, sk) in s.iter_mut().enumerate() {
                    *sk += tp;
                    if k < 3 {
                        b[k] += tp * yi;
                    }
                    tp *= t;
                }
            }
            let a = [[s[0], s[1], s[2]], [s[1], s[2], s[3]], [s[2], s[3], s[4]]];
            match solve3(a, b) {
                Some(c) => (c[0], c[1]),
                None => (f64::NAN, f64::NAN),
            }
        })
        .collect()
}

/// Nadaraya–Watson kernel average (tricube): non-negative weights, so averaging positive
/// semi-definite matrices entry by entry keeps the result positive semi-definite.
pub fn kernel_average(x: &[f64], y: &[f64], half_width_mm: f64) -> Vec<f64> {
    x.iter()
        .map(|&x0| {
            let (mut sw, mut sy) = (0.0, 0.0);
            for (&xi, &yi) in x.iter().zip(y) {
                let w = tricube((xi - x0) / half_width_mm);
                sw += w;
                sy += w * yi;
            }
            if sw > 0.0 { sy / sw } else { f64::NAN }
        })
        .collect()
}

fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&a);
    let scale = a[0][0].abs() * a[1][1].abs() * a[2][2].abs();
    if d.is_nan() || d.abs() <= 1e-12 * scale {
        return None;
    }
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut m = a;
        for r in 0..3 {
            m[r][k] = b[r];
        }
        *xk = det(&m) / d;
    }
    Some(x)
}

/// Fitted model and bound at one thickness.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct CrlbPoint {
    /// Thickness, mm.
    pub thickness_mm: f64,
    /// Fitted mean (I1, I2), µA.
    pub mu_ua: [f64; 2],
    /// Derivative dμ/dd, µA/mm.
    pub dmu_ua_per_mm: [f64; 2],
    /// Smoothed covariance, µA² (positive semi-definite by construction).
    pub sigma_ua2: [[f64; 2]; 2],
    /// Derivative dΣ/dd, µA²/mm.
    pub dsigma_ua2_per_mm: [[f64; 2]; 2],
    /// CRLB standard deviation of d with the full Gaussian Fisher information
    /// (μ′ᵀΣ⁻¹μ′ + ½ tr(Σ⁻¹Σ′Σ⁻¹Σ′)), mm. NaN where Σ is singular.
    pub crlb_std_mm: f64,
    /// CRLB standard deviation from the mean term only (μ′ᵀΣ⁻¹μ′), mm.
    pub crlb_no_dsigma_std_mm: f64,
    /// Residual of the mean fit, raw mean − fitted mean, µA.
    pub residual_ua: [f64; 2],
}

/// Quality of the fit of μ(d): RMS residual against the standard error of the raw means.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitQuality {
    /// RMS of (raw mean − fit) for I1 and I2, µA.
    pub rms_residual_ua: [f64; 2],
    /// RMS standard error of the raw means σ/√M, µA: a good fit has residuals of this size.
    pub rms_std_error_ua: [f64; 2],
}

/// Default half-width of the local fits, mm.
pub const DEFAULT_FIT_HALF_WIDTH_MM: f64 = 0.6;

/// Fit μ(d) and Σ(d) of a Monte Carlo result and compute the CRLB of the thickness
/// (thesis §5.4, Fig. 5.18). μ: local quadratic regression; Σ: kernel average (stays
/// positive semi-definite); dΣ/dd: local quadratic slope of each entry.
pub fn crlb(points: &[McPoint], half_width_mm: f64) -> Vec<CrlbPoint> {
    let x: Vec<f64> = points.iter().map(|p| p.thickness_mm).collect();
    let col = |f: &dyn Fn(&McPoint) -> f64| points.iter().map(f).collect::<Vec<f64>>();
    let m1 = local_quadratic(&x, &col(&|p| p.mean_ua[0]), half_width_mm);
    let m2 = local_quadratic(&x, &col(&|p| p.mean_ua[1]), half_width_mm);
    let c11 = col(&|p| p.cov_ua2[0][0]);
    let c12 = col(&|p| p.cov_ua2[0][1]);
    let c22 = col(&|p| p.cov_ua2[1][1]);
    let s11 = kernel_average(&x, &c11, half_width_mm);
    let s12 = kernel_average(&x, &c12, half_width_mm);
    let s22 = kernel_average(&x, &c22, half_width_mm);
    let d11 = local_quadratic(&x, &c11, half_width_mm);
    let d12 = local_quadratic(&x, &c12, half_width_mm);
    let d22 = local_quadratic(&x, &c22, half_width_mm);
    (0..points.len())
        .map(|i| {
            let sigma = [[s11[i], s12[i]], [s12[i], s22[i]]];
            let dsig = [[d11[i].1, d12[i].1], [d12[i].1, d22[i].1]];
            let dmu = [m1[i].1, m2[i].1];
            // Where the raw covariance is singular (the dry face: every run reads the same),
            // the Gaussian model does not hold: report NaN rather than a smoothed number.
            let raw = points[i].cov_ua2;
            let raw_det = raw[0][0] * raw[1][1] - raw[0][1] * raw[1][0];
            let (full, mean_only) = if raw_det > 0.0 && raw[0][0] > 0.0 {
                fisher(dmu, sigma, dsig)
            } else {
                (f64::NAN, f64::NAN)
            };
            CrlbPoint {
                thickness_mm: x[i],
                mu_ua: [m1[i].0, m2[i].0],
                dmu_ua_per_mm: dmu,
                sigma_ua2: sigma,
                dsigma_ua2_per_mm: dsig,
                crlb_std_mm: full.sqrt().recip(),
                crlb_no_dsigma_std_mm: mean_only.sqrt().recip(),
                residual_ua: [
                    points[i].mean_ua[0] - m1[i].0,
                    points[i].mean_ua[1] - m2[i].0,
                ],
            }
        })
        .map(|mut p| {
            if !p.crlb_std_mm.is_finite() {
                p.crlb_std_mm = f64::NAN;
            }
            if !p.crlb_no_dsigma_std_mm.is_finite() {
                p.crlb_no_dsigma_std_mm = f64::NAN;
            }
            p
        })
        .collect()
}

/// Fisher information of d for x ~ N(μ(d), Σ(d)) in two dimensions:
/// (full, mean term only). NaN when Σ is not positive definite.
pub fn fisher(dmu: [f64; 2], sigma: [[f64; 2]; 2], dsigma: [[f64; 2]; 2]) -> (f64, f64) {
    let det = sigma[0][0] * sigma[1][1] - sigma[0][1] * sigma[1][0];
    let scale = sigma[0][0].abs().max(sigma[1][1].abs());
    if sigma[0][0].is_nan() || sigma[0][0] <= 0.0 || det.is_nan() || det <= 1e-12 * scale * scale {
        return (f64::NAN, f64::NAN);
    }
    let inv = [
        [sigma[1][1] / det, -sigma[0][1] / det],
        [-sigma[1][0] / det, sigma[0][0] / det],
    ];
    let mean_term = dmu[0] * (inv[0][0] * dmu[0] + inv[0][1] * dmu[1])
        + dmu[1] * (inv[1][0] * dmu[0] + inv[1][1] * dmu[1]);
    // A = Σ⁻¹ Σ′; tr(A A).
    let mut a = [[0.0; 2]; 2];
    for (r, ar) in a.iter_mut().enumerate() {
        for (c, arc) in ar.iter_mut().enumerate() {
            *arc = inv[r][0] * dsigma[0][c] + inv[r][1] * dsigma[1][c];
        }
    }
    let tr = a[0][0] * a[0][0] + 2.0 * a[0][1] * a[1][0] + a[1][1] * a[1][1];
    (mean_term + 0.5 * tr, mean_term)
}

/// RMS residual of the mean fit against the standard error of the raw means (M runs).
pub fn fit_quality(points: &[McPoint], fit: &[CrlbPoint], runs: usize) -> FitQuality {
    let mut r = [0.0f64; 2];
    let mut e = [0.0f64; 2];
    let mut n = 0.0;
    for (p, f) in points.iter().zip(fit) {
        if !(f.residual_ua[0].is_finite() && f.residual_ua[1].is_finite()) {
            continue;
        }
        n += 1.0;
        for k in 0..2 {
            r[k] += f.residual_ua[k] * f.residual_ua[k];
            e[k] += p.cov_ua2[k][k] / runs.max(1) as f64;
        }
    }
    let n = f64::max(n, 1.0);
    FitQuality {
        rms_residual_ua: [(r[0] / n).sqrt(), (r[1] / n).sqrt()],
        rms_std_error_ua: [(e[0] / n).sqrt(), (e[1] / n).sqrt()],
    }
}

/// Least-squares fit of one global polynomial of `degree` (x scaled to [−1, 1]); returns the
/// fitted values. Kept to show (README, tests) why the thesis's global polynomial follows the
/// sharp peak and dip of the mean curves badly.
pub fn global_polynomial_fit(x: &[f64], y: &[f64], degree: usize) -> Vec<f64> {
    let n = degree + 1;
    let (lo, hi) = x
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    let span = (hi - lo).max(1e-12);
    let u = |v: f64| 2.0 * (v - lo) / span - 1.0;
    let mut a = vec![vec![0.0f64; n + 1]; n];
    for (&xi, &yi) in x.iter().zip(y) {
        let t = u(xi);
        let pw: Vec<f64> = (0..n)
            .scan(1.0, |p, _| {
                let r = *p;
                *p *= t;
                Some(r)
            })
            .collect();
        for r in 0..n {
            for c in 0..n {
                a[r][c] += pw[r] * pw[c];
            }
            a[r][n] += pw[r] * yi;
        }
    }
    // Gaussian elimination with partial pivoting.
    for col in 0..n {
        let piv = (col..n)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap_or(col);
        a.swap(col, piv);
        let d = a[col][col];
        if d.abs() < 1e-300 {
            return vec![f64::NAN; x.len()];
        }
        let pivot_row = a[col].clone();
        for (r, row) in a.iter_mut().enumerate() {
            if r != col {
                let f = row[col] / d;
                for (x, p) in row.iter_mut().zip(&pivot_row).skip(col) {
                    *x -= f * p;
                }
            }
        }
    }
    let coef: Vec<f64> = (0..n).map(|r| a[r][n] / a[r][r]).collect();
    x.iter()
        .map(|&xi| {
            let t = u(xi);
            coef.iter().rev().fold(0.0, |acc, &c| acc * t + c)
        })
        .collect()
}
