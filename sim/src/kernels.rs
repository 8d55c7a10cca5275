//! The tracer's arithmetic over all thicknesses of one ray at once, written as loops over
//! slices so that the compiler vectorises them: the divisions and square roots that bound
//! the scalar loop run four lanes at a time with AVX2 (detected at run time), two with the
//! SSE2 of every x86-64. Each lane performs the same IEEE-754 operations in the same order
//! as the scalar formula (Rust never fuses a multiply and an add on its own), so the results
//! are bit-identical to it; the golden-value tests of the crate check this.

use glam::{DVec2, DVec3};

use crate::geometry::Bundles;
use crate::laws::fr_dielectric;

/// A kernel compiled twice: for the CPU's AVX2 and FMA when it has them (checked at run
/// time) and for the baseline x86-64 (or any other target). Both run the same body, so the
/// results are bit-identical (an explicit `mul_add` is exactly rounded either way; the
/// compiler never fuses a multiply and an add on its own).
macro_rules! vector_kernel {
    ($(#[$meta:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $body:block) => {
        $(#[$meta])*
        $vis fn $name($($arg: $ty),*) {
            $(#[$meta])*
            #[inline(always)]
            fn kernel_body($($arg: $ty),*) $body
            $(#[$meta])*
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            fn kernel_avx2($($arg: $ty),*) {
                kernel_body($($arg),*)
            }
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU supports AVX2 and FMA (checked just above).
                return unsafe { kernel_avx2($($arg),*) };
            }
            kernel_body($($arg),*)
        }
    };
}
pub(crate) use vector_kernel;

/// A small non-negative integer held in an f64 (an index or a slot), as i32 in a way that
/// vectorises: `as i32` saturates and handles NaN lane by lane, which the compiler does
/// with scalar instructions.
// Not `clamp`: it passes NaN through, and NaN must not reach the conversion.
#[allow(clippy::manual_clamp)]
#[inline(always)]
pub(crate) fn small_int(x: f64) -> i32 {
    // NaN goes to 0 (`max` ignores it), and the value is clamped into 0..=2³⁰.
    let x = x.max(0.0).min(1_073_741_824.0);
    // SAFETY: x is finite and within the range of i32.
    unsafe { x.to_int_unchecked::<i32>() }
}

/// A 32-bit unsigned integer as an f64 (exactly), by the exponent trick: 2⁵² + x has x in
/// its low mantissa bits. `f64::from(u32)` is done lane by lane with scalar instructions.
#[inline(always)]
pub(crate) fn u32_to_f64(x: u64) -> f64 {
    const TWO_52: f64 = 4_503_599_627_370_496.0;
    f64::from_bits(TWO_52.to_bits() | (x & 0xFFFF_FFFF)) - TWO_52
}

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
    /// Take the Fresnel reflectance at the facet's angle (else at the mean surface's).
    pub facet_fresnel: bool,
    /// Refractive indices: the ice, the air above it, the fibre below.
    pub n_medium: f64,
    /// See `n_medium`.
    pub n_air: f64,
    /// See `n_medium`.
    pub n_fibre: f64,
}

/// Per thickness, the diffusely reflected ray: outputs of [`reflect_diffuse`].
#[derive(Clone, Debug, Default)]
pub(crate) struct DiffuseLanes {
    /// 0 or 1 for the bundle the reflected ray lands on, 2 for none (also when it does not
    /// meet the surface from below or does not come back down).
    pub slot: Vec<u32>,
    /// Fresnel reflectance at the ice/air surface.
    pub reflectance: Vec<f64>,
    /// Fresnel transmittance ice → fibre at the landing point.
    pub couple: Vec<f64>,
    /// Path length in the ice, up and back down, mm.
    pub path_mm: Vec<f64>,
    /// The reflected direction.
    pub dir: Vec<[f64; 3]>,
}

/// The diffusely reflected ray of one source ray at each thickness `thick_mm[n]` (all with
/// the surface above the fibre, h0 = d + a > 0), its micro-facet turned by
/// δ_R = δ_max·(2u − 1) with u = `draws[n]`·2⁻³² (eq. 3.22). The same arithmetic as the
/// scalar loop it replaces in `SensorModel::accretion`.
pub(crate) fn reflect_diffuse(
    ray: &DiffuseRay,
    bundles: &Bundles,
    thick_mm: &[f64],
    draws: &[u32],
    out: &mut DiffuseLanes,
) {
    let n = thick_mm.len();
    out.slot.resize(n, 2);
    out.reflectance.resize(n, 0.0);
    out.couple.resize(n, 0.0);
    out.path_mm.resize(n, 0.0);
    out.dir.resize(n, [0.0; 3]);
    reflect_diffuse_lanes(ray, bundles, thick_mm, draws, out);
}

vector_kernel! {
fn reflect_diffuse_lanes(
    ray: &DiffuseRay,
    bundles: &Bundles,
    thick_mm: &[f64],
    draws: &[u32],
    out: &mut DiffuseLanes,
) {
    let n = thick_mm.len();
    let (v, normal) = (ray.v, ray.normal);
    let cos_mean = v.dot(normal);
    let draws = &draws[..n];
    let slot = &mut out.slot[..n];
    let reflectance = &mut out.reflectance[..n];
    let couple = &mut out.couple[..n];
    let path = &mut out.path_mm[..n];
    let dir = &mut out.dir[..n];
    for k in 0..n {
        // Reflection at the ice/air surface, h0 = d + a above the fibre.
        let h0 = thick_mm[k] + ray.a;
        let t_up = h0 / ray.den;
        let z_hit = v.z * t_up;
        let u = draws[k] as f64 * (1.0 / 4_294_967_296.0);
        let dr = ray.diffuse_max_rad * (2.0 * u - 1.0);
        // δ_R deflects the reflected ray by δ_R (eq. 3.22): micro-facet normal turned by
        // δ_R/2 about the y axis (`laws::facet_normal`, without the libm call).
        let (sh, ch) = small_sin_cos(0.5 * dr);
        let nrm_x = normal.x * ch + normal.z * sh;
        let nrm_y = normal.y;
        let nrm_z = -normal.x * sh + normal.z * ch;
        // v · n and the law of reflection (`laws::reflect`), written out.
        let cos_i = (v.x * nrm_x) + (v.y * nrm_y) + (v.z * nrm_z);
        let twice = 2.0 * cos_i;
        let rd_x = v.x - twice * nrm_x;
        let rd_y = v.y - twice * nrm_y;
        let rd_z = v.z - twice * nrm_z;
        let t_down = z_hit / -rd_z;
        let land_x = (ray.p0[0] + v.x * t_up) + rd_x * t_down;
        let land_y = (ray.p0[1] + v.y * t_up) + rd_y * t_down;
        let bundle = bundles.slot(land_x, land_y) as u32;
        let meets = cos_i > 0.0 && rd_z < -1e-9;
        slot[k] = if meets { bundle } else { 2 };
        let cos_f = if ray.facet_fresnel { cos_i } else { cos_mean };
        reflectance[k] = fr_dielectric(cos_f, ray.n_medium, ray.n_air);
        couple[k] = 1.0 - fr_dielectric(-rd_z, ray.n_medium, ray.n_fibre);
        path[k] = t_up + t_down;
        dir[k] = [rd_x, rd_y, rd_z];
    }
}
}

vector_kernel! {
/// The bundle slot of a specular reflection's landing point p0 + w·h0, h0 = d + a, at each
/// thickness d = `thick_mm[n]`: 0 or 1, and 2 for none or where the surface is not above
/// the fibre (h0 ≤ 0). The same comparisons as `Geometry::region`.
pub(crate) fn specular_slots(
    p0: DVec2,
    w: DVec2,
    a: f64,
    bundles: &Bundles,
    thick_mm: &[f64],
    slot: &mut [i32],
) {
    let n = thick_mm.len().min(slot.len());
    let (thick_mm, slot) = (&thick_mm[..n], &mut slot[..n]);
    for k in 0..n {
        let h0 = thick_mm[k] + a;
        let land = p0 + w * h0;
        let on = bundles.slot_f64(land.x, land.y);
        slot[k] = small_int(if h0 <= 0.0 { 2.0 } else { on });
    }
}
}

/// sin and cos of a small angle (|x| ≤ 0.53 rad, i.e. δ_R/2 ≤ 30°) by Taylor series to x¹¹:
/// error below 1e-13, without a libm call.
#[inline(always)]
pub(crate) fn small_sin_cos(x: f64) -> (f64, f64) {
    debug_assert!(x.abs() <= 0.53);
    let x2 = x * x;
    let s = x
        * (1.0
            - x2 / 6.0
                * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0 * (1.0 - x2 / 72.0 * (1.0 - x2 / 110.0)))));
    let c = 1.0
        - x2 / 2.0
            * (1.0
                - x2 / 12.0
                    * (1.0
                        - x2 / 30.0 * (1.0 - x2 / 56.0 * (1.0 - x2 / 90.0 * (1.0 - x2 / 132.0)))));
    (s, c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_int_and_u32_to_f64_are_exact_and_total() {
        assert_eq!(small_int(2.0), 2);
        assert_eq!(small_int(150.0), 150);
        assert_eq!(small_int(f64::NAN), 0);
        assert_eq!(small_int(-3.0), 0);
        assert_eq!(small_int(f64::INFINITY), 1 << 30);
        for x in [0u64, 1, 0xFFFF_FFFF, 0x8000_0000, 0x1234_5678_9ABC_DEF0] {
            assert_eq!(u32_to_f64(x), f64::from(x as u32), "{x:#x}");
        }
    }
    use crate::geometry::Geometry;
    use crate::laws::{facet_normal, reflect};

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
        let ray = DiffuseRay {
            v,
            normal,
            p0: [-4.0 * next(), 4.0 * (next() - 0.5)],
            a: 2.0 * (next() - 0.5),
            den: 0.5 + next(),
            diffuse_max_rad: (60.0 * next()).to_radians(),
            facet_fresnel: next() < 0.5,
            n_medium: 1.31,
            n_air: 1.00028,
            n_fibre: 1.581,
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
    fn diffuse_kernel_is_bit_identical_to_the_scalar_formula() {
        let bundles = Geometry::ThesisCh5.bundles();
        let mut landed = 0;
        for seed in 0..200 {
            let (ray, thick, draws) = case(seed);
            // The dispatched kernel (AVX2 where the CPU has it) and the generic one (SSE2).
            let mut fast = DiffuseLanes::default();
            reflect_diffuse(&ray, &bundles, &thick, &draws, &mut fast);
            let mut generic = DiffuseLanes::default();
            generic.slot.resize(thick.len(), 2);
            generic.reflectance.resize(thick.len(), 0.0);
            generic.couple.resize(thick.len(), 0.0);
            generic.path_mm.resize(thick.len(), 0.0);
            generic.dir.resize(thick.len(), [0.0; 3]);
            reflect_diffuse_lanes(&ray, &bundles, &thick, &draws, &mut generic);
            for k in 0..thick.len() {
                // Scalar reference from the laws (facet_normal takes libm's sin/cos, so the
                // direction agrees to rounding; the kernel's own lanes agree to the bit).
                let dr = ray.diffuse_max_rad * (2.0 * (draws[k] as f64 / 4_294_967_296.0) - 1.0);
                let rd = reflect(ray.v, facet_normal(ray.normal, dr));
                assert!(
                    (DVec3::from(fast.dir[k]) - rd).length() < 1e-12,
                    "{seed} {k}"
                );
                assert_eq!(fast.slot[k], generic.slot[k]);
                for (a, b) in [
                    (fast.reflectance[k], generic.reflectance[k]),
                    (fast.couple[k], generic.couple[k]),
                    (fast.path_mm[k], generic.path_mm[k]),
                ] {
                    assert_eq!(a.to_bits(), b.to_bits(), "{seed} {k}");
                }
                landed += usize::from(fast.slot[k] < 2);
            }
        }
        // The cases land on the bundles often enough to mean something.
        assert!(landed > 5_000, "{landed}");
    }
}
