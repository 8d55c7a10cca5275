//! The specular reflection of one ray at the thicknesses it visits (thesis §3.2, eqs. 3.2,
//! 3.12, 3.21; Fig. 3.11 for the bubbles' forward flux): for a surface without diffuse
//! angles, fixed per accretion, the reflected ray's landing point moves on a line as the ice
//! grows, so where it lands and how much flux it brings are computed for all of a ray's
//! visited thicknesses in one vector pass (the tracer's pass 2 for rime, water and flat ice).

use glam::DVec2;

use crate::geometry::Bundles;
#[cfg(target_arch = "x86_64")]
use crate::kernels::{Isa, isa};
use crate::kernels::{LANES, one_vector_at_a_time, small_int, vector_kernel};

/// A ray's specular reflection against one accretion's surface: the landing point on the
/// face is p0 + w·h0 for a surface h0 = d + a above the fibre (thickness d).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SpecularLine {
    pub p0: DVec2,
    pub w: DVec2,
    pub a: f64,
}

impl SpecularLine {
    /// The bundle slot of the landing point at thickness `d_mm`: 0 or 1, and 2 for none or
    /// where the surface is not above the fibre (h0 ≤ 0). The same comparisons as
    /// `Geometry::region`.
    #[inline(always)]
    fn slot(&self, bundles: &Bundles, d_mm: f64) -> i32 {
        let h0 = d_mm + self.a;
        let land = self.p0 + self.w * h0;
        let on = bundles.slot_f64(land.x, land.y);
        small_int(if h0 <= 0.0 { 2.0 } else { on })
    }
}

/// What a ray's specular flux is made of at the visited thickness k (thesis eqs. 3.12,
/// 3.21, Fig. 3.11): Φ·R·T · F^(n_k) · e^(x₀ + k·x₁), with n_k the bubbles frozen in up to k.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SpecularFlux<'a> {
    /// Φ·R·T: the ray's flux, the Fresnel reflectance and the coupling.
    pub scale: f64,
    /// F^n for n = 0, 1, …, one entry more than the most bubbles frozen in.
    pub forward_pow: &'a [f64],
    /// The absorption up and back at the first visited thickness, e^x₀, and its ratio per
    /// step and per eight steps, e^x₁ and e^(8·x₁).
    pub absorption: [f64; 3],
}

/// One ray's specular reflection at the thicknesses it visits: its landing line, the
/// thicknesses and the bubbles frozen in at each (`frozen_by`, 0 where none; both padded to
/// whole vectors, the grid going on), how many are visited (`len`), the bubbles frozen in
/// before the first (`n_before`) and its flux.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SpecularRay<'a> {
    pub line: SpecularLine,
    pub thick_mm: &'a [f64],
    pub frozen_by: &'a [u32],
    pub len: usize,
    pub n_before: u32,
    pub flux: SpecularFlux<'a>,
}

impl SpecularFlux<'_> {
    /// The absorption of the first eight visited thicknesses, e^x₀·(e^x₁)^j on lane j:
    /// (e^x₁)^j as the product of the powers e^x₁, e^(2x₁) = (e^x₁)², e^(4x₁) = (e^(2x₁))²
    /// of j's binary digits, in that order, each missing one as a factor 1 (exact).
    #[inline(always)]
    fn first_absorption(&self) -> [f64; LANES] {
        let [att, s1, _] = self.absorption;
        let s2 = s1 * s1;
        let s4 = s2 * s2;
        let mut out = [0.0; LANES];
        for (j, o) in out.iter_mut().enumerate() {
            let b0 = if j & 1 != 0 { s1 } else { 1.0 };
            let b1 = if j & 2 != 0 { s2 } else { 1.0 };
            let b2 = if j & 4 != 0 { s4 } else { 1.0 };
            *o = att * ((b0 * b1) * b2);
        }
        out
    }
}

/// The specular reflection of one ray at its `len` visited thicknesses k = 0, 1, …
/// ([`SpecularRay`]; the padding lanes add nothing): where it lands (`SpecularLine::slot`),
/// and its flux ([`SpecularFlux`]; n_k the running maximum of `frozen_by` from `n_before`
/// on), added to the sum of its bundle (`sums0` for 0, `sums1` for 1). The absorption is
/// [`SpecularFlux::first_absorption`] on the eight lanes of the first vector, times
/// e^(8·x₁) from one vector to the next: products, no `exp` per thickness. With AVX-512
/// in one pass of intrinsics ([`specular_reflection_avx512`]), otherwise in two passes
/// that the compiler vectorises ([`specular_reflection_lanes`], with `count` and `bundle`
/// as its scratch); the same operations in the same order either way, so the same bits
/// (tested).
pub(crate) fn specular_reflection(
    ray: &SpecularRay,
    bundles: &Bundles,
    sums0: &mut [f64],
    sums1: &mut [f64],
    count: &mut [u32],
    bundle: &mut [i32],
) {
    #[cfg(target_arch = "x86_64")]
    if isa() == Isa::Avx512 {
        // SAFETY: the CPU has AVX-512 F, DQ, VL and FMA (`isa`).
        return unsafe { specular_reflection_avx512(ray, bundles, sums0, sums1) };
    }
    specular_reflection_lanes(ray, bundles, sums0, sums1, count, bundle);
}

/// [`specular_reflection`] in AVX-512 intrinsics, one vector of eight thicknesses per
/// step: the bundle as two masks (the comparisons of `Bundles::slot_f64`, NaN included),
/// the running maximum by a scan in three shifts and the maximum carried from the vector
/// before (kept in a register), F^n by a gather, and a masked add to each bundle's sums.
///
/// # Safety
/// The CPU has AVX-512 F, DQ, VL and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2,fma")]
unsafe fn specular_reflection_avx512(
    ray: &SpecularRay,
    bundles: &Bundles,
    sums0: &mut [f64],
    sums1: &mut [f64],
) {
    use std::arch::x86_64::*;
    const _: () = assert!(LANES == 8);
    let SpecularRay {
        line,
        thick_mm,
        frozen_by,
        len,
        n_before,
        flux,
    } = *ray;
    let lanes = len.next_multiple_of(LANES);
    assert!(
        thick_mm.len() >= lanes
            && frozen_by.len() >= lanes
            && sums0.len() >= lanes
            && sums1.len() >= lanes,
        "the specular pass's arrays hold whole vectors"
    );
    let pow = flux.forward_pow;
    let pow_len = _mm256_set1_epi32(pow.len().min(i32::MAX as usize) as i32);
    let scale = _mm512_set1_pd(flux.scale);
    let (a, p0x, p0y) = (
        _mm512_set1_pd(line.a),
        _mm512_set1_pd(line.p0.x),
        _mm512_set1_pd(line.p0.y),
    );
    let (wx, wy) = (_mm512_set1_pd(line.w.x), _mm512_set1_pd(line.w.y));
    let (r, b, r2) = (
        _mm512_set1_pd(bundles.radius_mm()),
        _mm512_set1_pd(bundles.length_b_mm()),
        _mm512_set1_pd(bundles.radius2_mm2()),
    );
    let zero = _mm512_setzero_pd();
    let (no_bubbles, last_lane) = (_mm256_setzero_si256(), _mm256_set1_epi32(7));
    let lane = _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 6, 7);
    let mut most = _mm256_set1_epi32(n_before as i32);
    // The absorption of the first vector, and e^(8·x₁) per vector.
    let first = flux.first_absorption();
    // SAFETY: eight f64 are loaded.
    let mut absorb = unsafe { _mm512_loadu_pd(first.as_ptr()) };
    let step = _mm512_set1_pd(flux.absorption[2]);
    for first in (0..lanes).step_by(LANES) {
        // SAFETY: first + 8 ≤ lanes ≤ every array's length (asserted above).
        let (d, frozen, s0, s1) = unsafe {
            (
                _mm512_loadu_pd(thick_mm.as_ptr().add(first)),
                _mm256_loadu_si256(frozen_by.as_ptr().add(first).cast()),
                _mm512_loadu_pd(sums0.as_ptr().add(first)),
                _mm512_loadu_pd(sums1.as_ptr().add(first)),
            )
        };
        // Where it lands: p0 + w·h0, h0 = d + a (`SpecularLine::slot`).
        let h0 = _mm512_add_pd(d, a);
        let x = _mm512_add_pd(p0x, _mm512_mul_pd(wx, h0));
        let y = _mm512_add_pd(p0y, _mm512_mul_pd(wy, h0));
        // The comparisons of `Bundles::slot_f64` (the negated ones true for NaN), each
        // masked by the ones before: the lanes before `len`, !(|y| > r), !(x < 0), the
        // surface above the fibre (!(h0 ≤ 0)); then x ≤ B for bundle 0, and !(x ≤ B) with
        // (x − B)² + y² ≤ R² for bundle 1.
        let valid = _mm512_cmplt_epi64_mask(lane, _mm512_set1_epi64((len - first) as i64));
        let hit = _mm512_mask_cmp_pd_mask::<_CMP_NGT_UQ>(valid, _mm512_abs_pd(y), r);
        let hit = _mm512_mask_cmp_pd_mask::<_CMP_NLT_UQ>(hit, x, zero);
        let hit = _mm512_mask_cmp_pd_mask::<_CMP_NLE_UQ>(hit, h0, zero);
        let dx = _mm512_sub_pd(x, b);
        let q = _mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(y, y));
        let on0 = _mm512_mask_cmp_pd_mask::<_CMP_LE_OQ>(hit, x, b);
        let beyond = _mm512_mask_cmp_pd_mask::<_CMP_NLE_UQ>(hit, x, b);
        let on1 = _mm512_mask_cmp_pd_mask::<_CMP_LE_OQ>(beyond, q, r2);
        // The running maximum: lane k takes the maximum of lanes ≤ k, then of the vectors
        // before.
        let mut n = frozen;
        n = _mm256_max_epu32(n, _mm256_alignr_epi32::<7>(n, no_bubbles));
        n = _mm256_max_epu32(n, _mm256_alignr_epi32::<6>(n, no_bubbles));
        n = _mm256_max_epu32(n, _mm256_alignr_epi32::<4>(n, no_bubbles));
        n = _mm256_max_epu32(n, most);
        most = _mm256_permutexvar_epi32(last_lane, n);
        // F^n where the ray lands (0 elsewhere), every such n within the table (as
        // indexing checks).
        let landed = _kor_mask8(on0, on1);
        assert_eq!(
            _mm256_mask_cmplt_epu32_mask(landed, n, pow_len),
            landed,
            "bubbles frozen in beyond the table of F^n"
        );
        // SAFETY: the landed lanes' n are below pow.len() (checked above).
        let fwd = unsafe { _mm512_mask_i32gather_pd::<8>(zero, landed, n, pow.as_ptr().cast()) };
        let flux = _mm512_mul_pd(_mm512_mul_pd(scale, fwd), absorb);
        absorb = _mm512_mul_pd(absorb, step);
        // SAFETY: as the loads.
        unsafe {
            _mm512_storeu_pd(
                sums0.as_mut_ptr().add(first),
                _mm512_mask_add_pd(s0, on0, s0, flux),
            );
            _mm512_storeu_pd(
                sums1.as_mut_ptr().add(first),
                _mm512_mask_add_pd(s1, on1, s1, flux),
            );
        }
    }
}

vector_kernel! {
/// [`specular_reflection`] in two passes a vector at a time, so that no lane waits on the
/// one before it and each pass holds its constants in registers (AVX2 has sixteen): where
/// the ray lands and the running maximum (a scan in three steps, then the maximum of the
/// vectors before) into `bundle` and `count`; then F^n from the table, the flux and the sums.
fn specular_reflection_lanes(
    ray: &SpecularRay,
    bundles: &Bundles,
    sums0: &mut [f64],
    sums1: &mut [f64],
    count: &mut [u32],
    bundle: &mut [i32],
) {
    // The scan's steps 1, 2, 4 cover eight lanes.
    const _: () = assert!(LANES == 8);
    let SpecularRay {
        line,
        thick_mm,
        frozen_by,
        len,
        n_before,
        flux,
    } = *ray;
    let chunks = thick_mm
        .chunks_exact(LANES)
        .zip(frozen_by.chunks_exact(LANES))
        .zip(count.chunks_exact_mut(LANES))
        .zip(bundle.chunks_exact_mut(LANES));
    let mut most = n_before;
    let mut written = 0;
    for (first, (((d, frozen), n), on)) in (0..).step_by(LANES).zip(chunks) {
        one_vector_at_a_time();
        written = first + LANES;
        let mut bubbles: [u32; LANES] = std::array::from_fn(|k| frozen[k]);
        for shift in [1, 2, 4] {
            let before: [u32; LANES] =
                std::array::from_fn(|k| if k >= shift { bubbles[k - shift] } else { 0 });
            for k in 0..LANES {
                bubbles[k] = bubbles[k].max(before[k]);
            }
        }
        for b in &mut bubbles {
            *b = (*b).max(most);
        }
        most = bubbles[LANES - 1];
        for k in 0..LANES {
            on[k] = if first + k < len {
                line.slot(bundles, d[k])
            } else {
                2
            };
            n[k] = bubbles[k];
        }
    }
    let mut absorb = flux.first_absorption();
    let step = flux.absorption[2];
    // Every count written is at most the last (a running maximum), so within the table.
    let pow = flux.forward_pow;
    assert!((most as usize) < pow.len(), "bubbles frozen in beyond the table of F^n");
    let chunks = count[..written]
        .chunks_exact(LANES)
        .zip(bundle.chunks_exact(LANES))
        .zip(sums0.chunks_exact_mut(LANES))
        .zip(sums1.chunks_exact_mut(LANES));
    for (((n, on), s0), s1) in chunks {
        one_vector_at_a_time();
        for k in 0..LANES {
            // SAFETY: n[k] was written above, so n[k] ≤ most < pow.len().
            let fwd = unsafe { *pow.get_unchecked(n[k] as usize) };
            let f = (flux.scale * fwd) * absorb[k];
            absorb[k] *= step;
            // The sums are ≥ +0, so adding +0 leaves them as they are.
            s0[k] += if on[k] == 0 { f } else { 0.0 };
            s1[k] += if on[k] == 1 { f } else { 0.0 };
        }
    }
}
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::{Isa, isa, with_isa};

    /// The specular reflection against the law written out thickness by thickness (the
    /// bundle from `Geometry::region`, libm's `exp`, F^n by `powi`): within 10⁻¹³; the same
    /// bits on every tier; nothing added past `len` or to the bundle it does not land on; lines
    /// that land exactly on an edge of the bundles at every thickness.
    #[test]
    fn specular_reflection_follows_the_law_on_every_tier() {
        use crate::geometry::{Geometry, Region};
        use rand_core::Rng;
        use rand_pcg::Pcg32;
        let mut rng = Pcg32::new(5, 9);
        let geo = Geometry::ThesisCh5;
        let bundles = geo.bundles();
        // F^n as the tracer keeps it: each entry the one before times F.
        let mut forward_pow = vec![1.0f64];
        for _ in 0..200 {
            forward_pow.push(forward_pow[forward_pow.len() - 1] * 0.95);
        }
        let mut landed = [0usize; 3];
        for (case, len) in [1usize, 7, 8, 9, 30, 55, 64]
            .into_iter()
            .cycle()
            .take(70)
            .enumerate()
        {
            let lanes = len.next_multiple_of(LANES);
            let mut u =
                |lo: f64, hi: f64| lo + (hi - lo) * (rng.next_u32() as f64 / 4_294_967_296.0);
            let mut line = SpecularLine {
                p0: DVec2::new(u(-4.0, 0.0), u(-4.0, 4.0)),
                w: DVec2::new(u(-1.0, 2.0), u(-1.0, 1.0)),
                a: u(-1.0, 1.0),
            };
            // Lines that run along an edge, landing exactly on it at every thickness:
            // x = B, x = B + R with y = 0 (on the arc), x = 0, y = ±R.
            let (r, b) = (bundles.radius_mm(), bundles.length_b_mm());
            let along = [
                (DVec2::new(b, -0.5), DVec2::new(0.0, 0.3)),
                (DVec2::new(b + r, 0.0), DVec2::ZERO),
                (DVec2::new(0.0, -0.5), DVec2::new(0.0, 0.2)),
                (DVec2::new(-0.5, r), DVec2::new(0.4, 0.0)),
                (DVec2::new(-0.5, -r), DVec2::new(0.4, 0.0)),
            ];
            if let Some(&(p0, w)) = along.get(case % 14) {
                (line.p0, line.w) = (p0, w);
            }
            let d0 = u(0.0, 5.0);
            let thick: Vec<f64> = (0..lanes).map(|k| d0 + 0.1 * k as f64).collect();
            // Bubbles frozen in at a few thicknesses (0 elsewhere), counts that grow.
            let mut count = 0;
            let frozen_by: Vec<u32> = (0..lanes)
                .map(|_| {
                    if rng.next_u32().is_multiple_of(4) {
                        count += 1 + rng.next_u32() % 3;
                        count
                    } else {
                        0
                    }
                })
                .collect();
            let (n_before, x0, x1, scale) = (2u32, -0.05, -0.0031, 1.7e-6);
            let mut want = [vec![0.5; lanes], vec![0.25; lanes]];
            let mut n = n_before;
            for k in 0..len {
                n = n.max(frozen_by[k]);
                let h0 = thick[k] + line.a;
                let at = line.p0 + line.w * h0;
                let bundle = match geo.region(at.x, at.y) {
                    Region::Bundle1 if h0 > 0.0 => 0,
                    Region::Bundle2 if h0 > 0.0 => 1,
                    _ => 2,
                };
                landed[bundle] += 1;
                let flux = scale * 0.95f64.powi(n as i32) * (x0 + k as f64 * x1).exp();
                if bundle < 2 {
                    want[bundle][k] += flux;
                }
            }
            let mut first_tier: Option<[Vec<f64>; 2]> = None;
            for tier in [Isa::Baseline, Isa::Avx2, Isa::Avx512] {
                if tier > isa() {
                    continue;
                }
                let (mut s0, mut s1) = (vec![0.5; lanes], vec![0.25; lanes]);
                with_isa(tier, || {
                    let ray = SpecularRay {
                        line,
                        thick_mm: &thick,
                        frozen_by: &frozen_by,
                        len,
                        n_before,
                        flux: SpecularFlux {
                            scale,
                            forward_pow: &forward_pow,
                            absorption: [x0.exp(), x1.exp(), (8.0 * x1).exp()],
                        },
                    };
                    specular_reflection(
                        &ray,
                        &bundles,
                        &mut s0,
                        &mut s1,
                        &mut vec![0; lanes],
                        &mut vec![0; lanes],
                    )
                });
                for (got, want) in [(&s0, &want[0]), (&s1, &want[1])] {
                    for k in 0..lanes {
                        assert!(
                            (got[k] - want[k]).abs() <= 1e-13 * want[k],
                            "case {case}, len {len}, lane {k}, {tier:?}: {} vs {}",
                            got[k],
                            want[k]
                        );
                    }
                }
                let got = [s0, s1];
                match &first_tier {
                    None => first_tier = Some(got),
                    Some(first) => assert_eq!(first, &got, "case {case}, {tier:?}"),
                }
            }
        }
        // Both bundles and neither were met.
        assert!(landed.iter().all(|&n| n > 50), "{landed:?}");
    }
}
