//! The diffuse reflection of glazed ice (thesis eq. 3.22, decision 7 of sim/README) over all
//! thicknesses of one ray at once: where each reflected ray lands (all lanes), then the
//! Fresnel factors and the absorption of those that land; the thickness beyond which none
//! can land; the one-division Fresnel factor and the polynomial `exp` they use.

use glam::DVec3;

use crate::geometry::Bundles;
use crate::kernels::{Fresnel, LANES, exp_small, grow, small_sin_cos, vector_kernel};
use crate::pack::pack_landed;

/// What the diffuse reflection of one ray needs besides its thicknesses and draws.
#[derive(Clone, Copy, Debug)]
pub(crate) struct DiffuseRay {
    /// Ray direction in the ice (unit, z > 0).
    pub v: DVec3,
    /// Upward unit normal of the mean (tilted) ice surface.
    pub normal: DVec3,
    /// Position of the ray on the face, mm.
    pub p0: [f64; 2],
    /// Height of the surface plane above the ray's fibre at d = 0, mm.
    pub a: f64,
    /// v_z − tan δ_x v_x − tan δ_y v_y (> 0).
    pub den: f64,
    /// δ_R ~ U(±diffuse_max), rad.
    pub diffuse_max_rad: f64,
    /// sin and cos of diffuse_max/2 (the same for every ray of an accretion).
    pub half_max_sin_cos: (f64, f64),
    /// Take the Fresnel reflectance at the facet's angle (else at the mean surface's).
    pub facet_fresnel: bool,
    /// Refractive indices: the ice, the air above it, the fibre below.
    pub n_medium: f64,
    /// See `n_medium`.
    pub n_air: f64,
    /// See `n_medium`.
    pub n_fibre: f64,
    /// Absorption coefficient of the ice, 1/mm (Beer–Lambert, eq. 3.15).
    pub alpha_per_mm: f64,
}

impl DiffuseRay {
    /// The largest h0 = d + a at which a diffusely reflected ray can still land within
    /// `reach_mm` of the ray's entry point, whatever its δ_R (∞ when no bound holds). Beyond
    /// it the lanes need not be traced: their slot would be 2.
    ///
    /// The horizontal distance D from the entry point to the landing point is the length of
    /// v·t_up + r·t_down (the z parts cancel), with t_up = h0/den and the angle between v and
    /// −r twice the angle α between v and the facet normal; over t_down ≥ 0 that length is at
    /// least t_up·sin 2α (2α ≤ 90°) or t_up. α is at least α_min, the smallest angle between
    /// v and the normal turned by any φ = δ_R/2 in ±δ_max/2 about y: v·n(φ) = A cos φ +
    /// B sin φ + C, whose maximum over the interval is closed-form. A relative margin of 10⁻⁶
    /// covers the kernel's rounding (≈ 10⁻¹⁵).
    pub(crate) fn h0_cutoff_mm(&self, reach_mm: f64) -> f64 {
        let (v, n) = (self.v, self.normal);
        let (a, b, c) = (v.x * n.x + v.z * n.z, v.x * n.z - v.z * n.x, v.y * n.y);
        let (s, co) = self.half_max_sin_cos;
        // The peak of A cos φ + B sin φ, at φ = atan2(B, A), lies within ±φ_max iff A > 0 and
        // |B| ≤ A tan φ_max (φ_max ≤ 30°).
        let best = if a > 0.0 && b.abs() * co <= a * s {
            (a * a + b * b).sqrt()
        } else {
            (a * co + b * s).max(a * co - b * s)
        };
        let cos_min = (best + c).clamp(-1.0, 1.0);
        // sin 2α_min = 2 cos α sin α for α_min < 45°, else the bound is 1.
        let g = if cos_min > std::f64::consts::FRAC_1_SQRT_2 {
            2.0 * cos_min * (1.0 - cos_min * cos_min).max(0.0).sqrt()
        } else {
            1.0
        };
        if g < 1e-6 {
            return f64::INFINITY;
        }
        reach_mm * self.den / g * (1.0 + 1e-6) + 1e-9
    }
}

/// Per thickness, the diffusely reflected ray: outputs of [`reflect_diffuse`].
#[derive(Clone, Debug, Default)]
pub(crate) struct DiffuseLanes {
    /// 0 or 1 for the bundle the reflected ray lands on, 2 for none (also when it does not
    /// meet the surface from below or does not come back down).
    pub slot: Vec<u64>,
    /// The reflected direction (x, y and z apart).
    pub dir: [Vec<f64>; 3],
    /// Cosine of the angle of incidence of the Fresnel reflectance.
    cos_fresnel: Vec<f64>,
    /// Path length in the ice, up and back down, mm.
    path_mm: Vec<f64>,
    /// The lanes that land on a bundle, in order (the first `landed_count`).
    landed: Vec<u32>,
    landed_count: usize,
    /// The landed lanes' cosine, −direction z and path, packed.
    packed: [Vec<f64>; 3],
    /// Per landed lane: the fraction of the ray's forward flux that enters the bundle,
    /// Fresnel reflectance at the ice/air surface × Fresnel transmittance ice → fibre ×
    /// Beer–Lambert absorption over the path up and back down.
    weight: Vec<f64>,
}

impl DiffuseLanes {
    /// The lanes that land on a bundle, in order, and their weights.
    pub(crate) fn landed(&self) -> (&[u32], &[f64]) {
        let m = self.landed_count;
        (&self.landed[..m], &self.weight[..m])
    }
}

/// The diffusely reflected ray of one source ray at each thickness `thick_mm[n]` (all with
/// the surface above the fibre, h0 = d + a > 0; only the first `valid` count, the others
/// pad the lanes to whole vectors), its micro-facet turned by
/// δ_R = δ_max·(2u − 1) with u = `draws[n]`·2⁻³² (eq. 3.22). Two passes: where every ray
/// lands (all lanes), then the Fresnel factors and the absorption of the third that land
/// on a bundle.
pub(crate) fn reflect_diffuse(
    ray: &DiffuseRay,
    bundles: &Bundles,
    thick_mm: &[f64],
    valid: usize,
    draws: &[u32],
    out: &mut DiffuseLanes,
) {
    let n = thick_mm.len();
    let valid = valid.min(n);
    grow(&mut out.slot, n, 2);
    for d in &mut out.dir {
        grow(d, n, 0.0);
    }
    grow(&mut out.cos_fresnel, n, 0.0);
    grow(&mut out.path_mm, n, 0.0);
    diffuse_landing(ray, bundles, thick_mm, draws, out);
    // The landed lanes among the valid ones and their inputs packed, so that the second
    // pass runs on whole vectors (padded with lanes of normal incidence and no path).
    let room = valid.next_multiple_of(LANES);
    grow(&mut out.landed, room, 0);
    for p in &mut out.packed {
        grow(p, room, 0.0);
    }
    let [cos_p, rdz_p, path_p] = &mut out.packed;
    let (slot, cos_f, dir_z, path) = (
        &out.slot[..valid],
        &out.cos_fresnel[..valid],
        &out.dir[2][..valid],
        &out.path_mm[..valid],
    );
    let m = pack_landed(
        slot,
        [cos_f, dir_z, path],
        &mut out.landed,
        [cos_p, rdz_p, path_p],
    );
    let padded = m.next_multiple_of(LANES);
    cos_p[m..padded].fill(1.0);
    rdz_p[m..padded].fill(1.0);
    path_p[m..padded].fill(0.0);
    out.landed_count = m;
    grow(&mut out.weight, padded, 0.0);
    diffuse_weights(
        ray,
        &cos_p[..padded],
        &rdz_p[..padded],
        &path_p[..padded],
        &mut out.weight[..padded],
    );
}

vector_kernel! {
/// Where each diffusely reflected ray lands ([`reflect_diffuse`], first pass).
fn diffuse_landing(
    ray: &DiffuseRay,
    bundles: &Bundles,
    thick_mm: &[f64],
    draws: &[u32],
    out: &mut DiffuseLanes,
) {
    let n = thick_mm.len();
    let (v, normal) = (ray.v, ray.normal);
    let cos_mean = v.dot(normal);
    let inv_den = 1.0 / ray.den;
    let half_max = 0.5 * ray.diffuse_max_rad;
    let half_max_per_draw = half_max * (2.0 / 4_294_967_296.0);
    let draws = &draws[..n];
    let slot = &mut out.slot[..n];
    let [dir_x, dir_y, dir_z] = &mut out.dir;
    let (dir_x, dir_y, dir_z) = (&mut dir_x[..n], &mut dir_y[..n], &mut dir_z[..n]);
    let cos_fresnel = &mut out.cos_fresnel[..n];
    let path = &mut out.path_mm[..n];
    // Three passes of shorter chains, so that the processor overlaps more lanes (one loop
    // body waited on its long chain and on the division: −12 % of glazed's time with AVX2,
    // −7 % with AVX-512). The direction arrays hold the intermediate values.
    // 1. The micro-facet's turn: sin and cos of δ_R/2 (into x and y).
    for k in 0..n {
        // u ∈ [0, 1) from the draw; δ_R/2 = δ_max/2 · (2u − 1), by one fused multiply-add:
        // draw·(δ_max/2·2⁻³¹) − δ_max/2 has the exact value δ_max/2·(2u − 1) (the factor is
        // δ_max/2 scaled by a power of two), rounded once, as the product was before.
        let x = (draws[k] as f64).mul_add(half_max_per_draw, -half_max);
        // δ_R deflects the reflected ray by δ_R (eq. 3.22): micro-facet normal turned by
        // δ_R/2 about the y axis (`laws::facet_normal`, without the libm call).
        let (sh, ch) = small_sin_cos(x);
        dir_x[k] = sh;
        dir_y[k] = ch;
    }
    // 2. The reflected direction.
    for k in 0..n {
        let (sh, ch) = (dir_x[k], dir_y[k]);
        let nrm_x = normal.x.mul_add(ch, normal.z * sh);
        let nrm_y = normal.y;
        let nrm_z = normal.z.mul_add(ch, -normal.x * sh);
        // v · n and the law of reflection (`laws::reflect`), written out.
        let cos_i = v.x.mul_add(nrm_x, v.y.mul_add(nrm_y, v.z * nrm_z));
        let twice = -2.0 * cos_i;
        cos_fresnel[k] = cos_i;
        dir_x[k] = twice.mul_add(nrm_x, v.x);
        dir_y[k] = twice.mul_add(nrm_y, v.y);
        dir_z[k] = twice.mul_add(nrm_z, v.z);
    }
    // 3. Where it lands, h0 = d + a above the fibre.
    for k in 0..n {
        let (rd_x, rd_y, rd_z, cos_i) = (dir_x[k], dir_y[k], dir_z[k], cos_fresnel[k]);
        let h0 = thick_mm[k] + ray.a;
        let t_up = h0 * inv_den;
        let z_hit = v.z * t_up;
        let t_down = z_hit / -rd_z;
        let land_x = rd_x.mul_add(t_down, v.x.mul_add(t_up, ray.p0[0]));
        let land_y = rd_y.mul_add(t_down, v.y.mul_add(t_up, ray.p0[1]));
        let bundle = bundles.slot(land_x, land_y) as u64;
        let meets = cos_i > 0.0 && rd_z < -1e-9;
        slot[k] = if meets { bundle } else { 2 };
        if !ray.facet_fresnel {
            cos_fresnel[k] = cos_mean;
        }
        path[k] = t_up + t_down;
    }
}
}

vector_kernel! {
/// The weights of the landed lanes ([`reflect_diffuse`], second pass), from their cosines,
/// downward directions and paths packed in `cos_fresnel`, `minus_rd_z`, `path_mm`.
fn diffuse_weights(
    ray: &DiffuseRay,
    cos_fresnel: &[f64],
    minus_rd_z: &[f64],
    path_mm: &[f64],
    weight: &mut [f64],
) {
    let to_air = Fresnel::new(ray.n_medium, ray.n_air);
    let to_fibre = Fresnel::new(ray.n_medium, ray.n_fibre);
    let m = weight.len();
    let (cos_fresnel, minus_rd_z, path_mm) = (&cos_fresnel[..m], &minus_rd_z[..m], &path_mm[..m]);
    for j in 0..m {
        let reflectance = to_air.reflectance(cos_fresnel[j]);
        let couple = 1.0 - to_fibre.reflectance(minus_rd_z[j]);
        weight[j] = reflectance * couple * exp_small(-ray.alpha_per_mm * path_mm[j]);
    }
}
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Geometry;
    use crate::laws::{facet_normal, fr_dielectric, reflect};

    /// A random source ray and surface, and thicknesses with draws.
    fn case(seed: u64) -> (DiffuseRay, Vec<f64>, Vec<u32>) {
        let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let v = DVec3::new(next() - 0.2, next() - 0.5, 1.0).normalize();
        let normal = DVec3::new(0.3 * (next() - 0.5), 0.3 * (next() - 0.5), 1.0).normalize();
        let diffuse_max_rad = (60.0 * next()).to_radians();
        let ray = DiffuseRay {
            v,
            normal,
            p0: [-4.0 * next(), 4.0 * (next() - 0.5)],
            a: 2.0 * (next() - 0.5),
            den: 0.5 + next(),
            diffuse_max_rad,
            half_max_sin_cos: (0.5 * diffuse_max_rad).sin_cos(),
            facet_fresnel: next() < 0.5,
            n_medium: 1.31,
            n_air: 1.00028,
            n_fibre: 1.581,
            alpha_per_mm: 0.012,
        };
        let thick: Vec<f64> = (0..151).map(|i| i as f64 * 0.1).collect();
        let draws: Vec<u32> = (0..151)
            .map(|_| (next() * 4_294_967_296.0) as u32)
            .collect();
        (ray, thick, draws)
    }

    // One index addresses the draws and the outputs of both kernels.
    #[allow(clippy::needless_range_loop)]
    #[test]
    fn diffuse_kernels_match_the_laws() {
        let bundles = Geometry::ThesisCh5.bundles();
        let mut landed = 0;
        for seed in 0..200 {
            let (ray, thick, draws) = case(seed);
            // The dispatched kernels (AVX2 where the CPU has it), twice into one buffer: the
            // second call leaves nothing of the first.
            let mut fast = DiffuseLanes::default();
            reflect_diffuse(&ray, &bundles, &thick, thick.len(), &draws, &mut fast);
            let generic = fast.clone();
            let (other, _, other_draws) = case(seed + 1000);
            reflect_diffuse(&other, &bundles, &thick[..77], 77, &other_draws, &mut fast);
            reflect_diffuse(&ray, &bundles, &thick, thick.len(), &draws, &mut fast);
            assert_eq!(fast.landed().0, generic.landed().0);
            let cos_mean = ray.v.dot(ray.normal);
            let mut landed_here = 0;
            for k in 0..thick.len() {
                // Scalar reference from the laws (libm's sin, cos, exp and two divisions per
                // Fresnel factor: it agrees to rounding; the kernel's own lanes to the bit).
                let dr = ray.diffuse_max_rad * (2.0 * (draws[k] as f64 / 4_294_967_296.0) - 1.0);
                let nrm = facet_normal(ray.normal, dr);
                let rd = reflect(ray.v, nrm);
                let dir = DVec3::new(fast.dir[0][k], fast.dir[1][k], fast.dir[2][k]);
                assert!((dir - rd).length() < 1e-12, "{seed} {k}");
                assert_eq!(fast.slot[k], generic.slot[k]);
                let t_up = (thick[k] + ray.a) / ray.den;
                let t_down = ray.v.z * t_up / -rd.z;
                let cos_f = if ray.facet_fresnel {
                    ray.v.dot(nrm)
                } else {
                    cos_mean
                };
                let want = fr_dielectric(cos_f, ray.n_medium, ray.n_air)
                    * (1.0 - fr_dielectric(-rd.z, ray.n_medium, ray.n_fibre))
                    * (-ray.alpha_per_mm * (t_up + t_down)).exp();
                if fast.slot[k] < 2 {
                    let j = fast.landed().0[landed_here];
                    assert_eq!(j as usize, k);
                    let w = fast.landed().1[landed_here];
                    assert_eq!(w.to_bits(), generic.landed().1[landed_here].to_bits());
                    assert!(
                        (w - want).abs() <= 1e-12 * want,
                        "{seed} {k}: {w} vs {want}"
                    );
                    landed_here += 1;
                }
            }
            assert_eq!(landed_here, fast.landed().0.len());
            landed += landed_here;
        }
        // The cases land on the bundles often enough to mean something.
        assert!(landed > 5_000, "{landed}");
    }

    // One index addresses the thicknesses and the kernel's outputs.
    #[allow(clippy::needless_range_loop)]
    #[test]
    fn no_ray_lands_beyond_the_cutoff() {
        let bundles = Geometry::ThesisCh5.bundles();
        let (mut beyond, mut cut) = (0, 0);
        for seed in 0..400 {
            let (ray, _, draws) = case(seed);
            // Thicknesses to 40 mm; every landing point within 12 mm of the entry point
            // counts, not only the bundles.
            let thick: Vec<f64> = (0..151).map(|i| i as f64 * 0.27).collect();
            let reach = 12.0;
            let h0_max = ray.h0_cutoff_mm(reach);
            let mut out = DiffuseLanes::default();
            reflect_diffuse(&ray, &bundles, &thick, thick.len(), &draws, &mut out);
            for k in 0..thick.len() {
                let h0 = thick[k] + ray.a;
                if h0 <= h0_max || h0 <= 0.0 {
                    continue;
                }
                beyond += 1;
                let t_up = h0 / ray.den;
                let t_down = ray.v.z * t_up / -out.dir[2][k];
                let dx = ray.v.x * t_up + out.dir[0][k] * t_down;
                let dy = ray.v.y * t_up + out.dir[1][k] * t_down;
                assert!(
                    t_down < 0.0 || dx.hypot(dy) > reach,
                    "{seed} {k}: lands {} mm away beyond the cutoff {h0_max} (h0 {h0})",
                    dx.hypot(dy)
                );
            }
            cut += usize::from(h0_max.is_finite());
        }
        // The bound cuts most rays, and many lanes lie beyond it.
        assert!(cut > 300 && beyond > 10_000, "{cut} {beyond}");
    }
}
