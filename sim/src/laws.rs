//! The optical laws of thesis §3.1, each a small pure function.
//!
//! Conventions: directions are unit vectors of propagation; a surface normal passed to a law
//! points into the medium the light comes from (so `dir · normal < 0`); angles in radians.

use glam::DVec3;

/// Law of reflection (thesis eq. 3.2) in vector form: the angle of incidence equals the angle
/// of reflection, both in the plane of incidence. `normal` is a unit normal of the surface.
#[inline]
pub fn reflect(dir: DVec3, normal: DVec3) -> DVec3 {
    dir - 2.0 * dir.dot(normal) * normal
}

/// Law of refraction (Snell, thesis eq. 3.3) in 3-D. `dir` is the incident propagation
/// direction, `normal` the unit normal on the incident side (`dir · normal < 0`), `n_i` and
/// `n_t` the refractive indices. Returns the transmitted direction, or `None` on total
/// internal reflection (thesis §3.1.5, eq. 3.14).
#[inline]
pub fn refract(dir: DVec3, normal: DVec3, n_i: f64, n_t: f64) -> Option<DVec3> {
    let eta = n_i / n_t;
    let cos_i = -dir.dot(normal);
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i).max(0.0);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some(eta * dir + (eta * cos_i - cos_t) * normal)
}

/// Snell's law for angles (eq. 3.3): the refraction angle, or `None` beyond the critical angle.
#[inline]
pub fn snell_angle(theta_i: f64, n_i: f64, n_t: f64) -> Option<f64> {
    let s = n_i / n_t * theta_i.sin();
    if s.abs() >= 1.0 { None } else { Some(s.asin()) }
}

/// Critical angle of total internal reflection, thesis eq. 3.14: θ_c = asin(n_t / n_i).
/// `None` when `n_t >= n_i` (no total internal reflection possible).
#[inline]
pub fn critical_angle(n_i: f64, n_t: f64) -> Option<f64> {
    if n_t >= n_i {
        None
    } else {
        Some((n_t / n_i).asin())
    }
}

/// Amplitude coefficients of the Fresnel equations, thesis eqs. 3.4–3.7:
/// `(r_perp, t_perp, r_par, t_par)` for the incidence angle whose cosine is `cos_i`.
/// `None` on total internal reflection.
pub fn fresnel_amplitudes(cos_i: f64, n_i: f64, n_t: f64) -> Option<(f64, f64, f64, f64)> {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (n_i / n_t).powi(2) * (1.0 - cos_i * cos_i);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_perp = (n_i * cos_i - n_t * cos_t) / (n_i * cos_i + n_t * cos_t); // (3.4)
    let t_perp = 2.0 * n_i * cos_i / (n_i * cos_i + n_t * cos_t); // (3.5)
    let r_par = (n_t * cos_i - n_i * cos_t) / (n_i * cos_t + n_t * cos_i); // (3.6)
    let t_par = 2.0 * n_i * cos_i / (n_i * cos_t + n_t * cos_i); // (3.7)
    Some((r_perp, t_perp, r_par, t_par))
}

/// Reflectance of a dielectric interface for unpolarised light, thesis eqs. 3.8, 3.9, 3.12:
/// R = (r_⊥² + r_∥²) / 2; 1 on total internal reflection (§3.1.5). Like pbrt-v4's
/// `FrDielectric`, written with the cosines only.
/// Written without a branch (both outcomes computed, one selected) so that loops over many
/// rays vectorise.
#[inline]
pub fn fr_dielectric(cos_i: f64, n_i: f64, n_t: f64) -> f64 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let eta = n_i / n_t;
    let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    let total = sin2_t >= 1.0;
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let r_perp = (n_i * cos_i - n_t * cos_t) / (n_i * cos_i + n_t * cos_t);
    let r_par = (n_t * cos_i - n_i * cos_t) / (n_i * cos_t + n_t * cos_i);
    let r = 0.5 * (r_perp * r_perp + r_par * r_par);
    if total { 1.0 } else { r }
}

/// Transmittance for unpolarised light, thesis eq. 3.13: T = 1 − R.
#[inline]
pub fn fresnel_transmittance(cos_i: f64, n_i: f64, n_t: f64) -> f64 {
    1.0 - fr_dielectric(cos_i, n_i, n_t)
}

/// Transmittance computed directly from the amplitude coefficients, thesis eqs. 3.10, 3.11:
/// T = (n_t cos θ_t)/(n_i cos θ_i) · (t_⊥² + t_∥²)/2. Used to check R + T = 1 (eq. 3.13).
pub fn transmittance_from_amplitudes(cos_i: f64, n_i: f64, n_t: f64) -> f64 {
    match fresnel_amplitudes(cos_i, n_i, n_t) {
        None => 0.0,
        Some((_, t_perp, _, t_par)) => {
            let cos_i = cos_i.clamp(0.0, 1.0);
            let sin2_t = (n_i / n_t).powi(2) * (1.0 - cos_i * cos_i);
            let cos_t = (1.0 - sin2_t).sqrt();
            let k = (n_t * cos_t) / (n_i * cos_i);
            0.5 * k * (t_perp * t_perp + t_par * t_par)
        }
    }
}

/// Beer–Lambert law, thesis eq. 3.15: the fraction of flux left after a path of `path_mm`
/// in a medium with absorption coefficient `alpha_per_mm`.
#[inline]
pub fn beer_lambert(path_mm: f64, alpha_per_mm: f64) -> f64 {
    (-alpha_per_mm * path_mm).exp()
}

/// Maximum acceptance angle in the outer medium, thesis eq. 3.16/3.17: sin θ_max = NA / n_i.
#[inline]
pub fn theta_max(na: f64, n_outer: f64) -> f64 {
    (na / n_outer).min(1.0).asin()
}

/// Maximum angle inside the fibre core, thesis eq. 3.18:
/// θ_max,f = asin(n_outer / n_fibre · sin θ_max).
#[inline]
pub fn theta_max_fibre(theta_max: f64, n_outer: f64, n_fibre: f64) -> f64 {
    (n_outer / n_fibre * theta_max.sin()).asin()
}

/// Micro-facet normal for a diffuse deflection (thesis eq. 3.22, θ_S = θ_Ice + δ): turning the
/// surface normal by δ/2 about the y axis turns a ray reflected in the x–z plane by δ.
#[inline]
pub fn facet_normal(normal: DVec3, deflection_rad: f64) -> DVec3 {
    let (s, c) = (0.5 * deflection_rad).sin_cos();
    DVec3::new(
        normal.x * c + normal.z * s,
        normal.y,
        -normal.x * s + normal.z * c,
    )
}
