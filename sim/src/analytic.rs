//! The conventional analytic model (thesis §2.1, §3.3): on flat clear ice every source ray
//! leaves along the fibre axis, so the reflection is the source half-disc mirrored and
//! shifted by s = 2 d tan θ_Ice toward +x; the flux on a bundle is the overlap area times the
//! Fresnel factors and the absorption along the central ray.

use crate::consts::*;
use crate::geometry::Geometry;
use crate::laws::{beer_lambert, fr_dielectric, fresnel_transmittance, snell_angle};

/// ∫₀ᵘ 2√(R² − t²) dt, the area of a circle strip (closed form).
fn strip(u: f64, r: f64) -> f64 {
    let u = u.clamp(-r, r);
    u * (r * r - u * u).max(0.0).sqrt() + r * r * (u / r).asin()
}

/// ∫ₐᵇ 2√(R² − (x − c)²) dx for a ≤ b (0 if a ≥ b).
fn chord_integral(a: f64, b: f64, c: f64, r: f64) -> f64 {
    if b <= a {
        0.0
    } else {
        strip(b - c, r) - strip(a - c, r)
    }
}

/// Overlap areas (bundle 1, bundle 2), mm², of the source half-disc shifted by `shift_mm`
/// toward +x with the two signal bundles.
pub fn overlap_areas_mm2(geo: Geometry, shift_mm: f64) -> (f64, f64) {
    let r = geo.radius_mm();
    let b = geo.length_b_mm();
    let s = shift_mm;
    // The shifted half-disc covers x ∈ [s − R, s] with chord 2√(R² − (x − s)²) ≤ 2R.
    let a1 = chord_integral((s - r).max(0.0), s.min(b), s, r);
    // Bundle 2 (x ≥ B, chord 2√(R² − (x − B)²)): take the smaller chord; the circle whose
    // centre is farther from x has the smaller chord. The centres are B and s (s > B).
    let lo = (s - r).max(b);
    let hi = s.min(b + r);
    let a2 = if hi > lo {
        let m = 0.5 * (s + b);
        chord_integral(lo, hi.min(m), s, r) + chord_integral(lo.max(m), hi, b, r)
    } else {
        0.0
    };
    (a1, a2)
}

/// The analytic curve (thickness_mm, flux1_w, flux2_w) on flat ice of index `n_medium`.
pub fn analytic_flux(geo: Geometry, n_medium: f64, thicknesses_mm: &[f64]) -> Vec<(f64, f64, f64)> {
    let incl = INCLINATION_DEG.to_radians();
    // Total internal reflection at the fibre face: no light enters the
    // medium (never for a medium of index > 1: n_fibre · sin 30° < 1).
    let Some(th_ice) = snell_angle(incl, N_FIBRE, n_medium) else {
        return thicknesses_mm.iter().map(|&d| (d, 0.0, 0.0)).collect();
    };
    let t_in = fresnel_transmittance(incl.cos(), N_FIBRE, n_medium);
    let r_surf = fr_dielectric(th_ice.cos(), n_medium, N_AIR);
    let t_out = fresnel_transmittance(th_ice.cos(), n_medium, N_FIBRE);
    let r = geo.radius_mm();
    let a_src = 0.5 * std::f64::consts::PI * r * r;
    thicknesses_mm
        .iter()
        .map(|&d| {
            if d <= 0.0 {
                return (d, 0.0, 0.0);
            }
            let (a1, a2) = overlap_areas_mm2(geo, 2.0 * d * th_ice.tan());
            let k = SOURCE_FLUX_W
                * t_in
                * r_surf
                * t_out
                * beer_lambert(2.0 * d / th_ice.cos(), ALPHA_PER_MM)
                / a_src;
            (d, k * a1, k * a2)
        })
        .collect()
}

/// The analytic curve in µA (same responsivity as the ray tracer): (thickness, I1, I2).
pub fn analytic_curve(
    geo: Geometry,
    n_medium: f64,
    thicknesses_mm: &[f64],
) -> Vec<(f64, f64, f64)> {
    let ua = RESPONSIVITY_A_PER_W * 1e6;
    analytic_flux(geo, n_medium, thicknesses_mm)
        .into_iter()
        .map(|(d, f1, f2)| (d, f1 * ua, f2 * ua))
        .collect()
}
