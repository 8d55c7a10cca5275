//! The specular reflection of one ray at the thicknesses it visits (thesis §3.2, eqs. 3.2,
//! 3.12, 3.21; Fig. 3.11 for the bubbles' forward flux): for a surface without diffuse
//! angles, fixed per accretion, the reflected ray's landing point moves on a line as the ice
//! grows, so where it lands and how much flux it brings are computed for all of a ray's
//! visited thicknesses in one vector pass (the tracer's pass 2 for rime, water and flat ice).

use glam::DVec2;

use crate::geometry::Bundles;
use crate::kernels::{LANES, exp_small, one_vector_at_a_time, small_int, vector_kernel};

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

vector_kernel! {
/// The specular reflection of one ray at its `len` visited thicknesses k = 0, 1, …
/// (`thick_mm[k]`; the arrays are padded to whole vectors, the padding lanes add nothing):
/// where it lands (`SpecularLine::slot`), and the flux left after the n_k bubbles frozen in
/// up to k (n_k the running maximum of `frozen_by` from `n_before` on) times the Fresnel
/// reflectance, the coupling and the absorption up and back, Φ·R·T·F^(n_k)·e^(x₀ + k·x₁)
/// (thesis eqs. 3.12, 3.21, Fig. 3.11; `factors` = [Φ·R·T, ln F, x₀, x₁]), added to the
/// sum of its bundle (`sums0` for 0, `sums1` for 1). Two passes a vector at a time, so that
/// no lane waits on the one before it: where the ray lands, the running maximum (a scan in
/// three steps, then the maximum of the vectors before) and the exponent of its flux into
/// `exponent` and `bundle`; then F^n and the absorption by one polynomial `exp`
/// ([`exp_small`]) and the sums.
#[allow(clippy::too_many_arguments)]
pub(crate) fn specular_reflection(
    line: &SpecularLine,
    bundles: &Bundles,
    thick_mm: &[f64],
    frozen_by: &[u32],
    sums0: &mut [f64],
    sums1: &mut [f64],
    len: usize,
    n_before: u32,
    factors: [f64; 4],
    exponent: &mut [f64],
    bundle: &mut [i32],
) {
    // The scan's steps 1, 2, 4 cover eight lanes.
    const _: () = assert!(LANES == 8);
    let [scale, ln_forward, x0, x1] = factors;
    // Two passes, so that each holds its constants in registers (AVX2 has sixteen).
    let chunks = thick_mm
        .chunks_exact(LANES)
        .zip(frozen_by.chunks_exact(LANES))
        .zip(exponent.chunks_exact_mut(LANES))
        .zip(bundle.chunks_exact_mut(LANES));
    let mut most = n_before;
    // The thickness steps k as f64 (one conversion per vector: AVX2 has no vector
    // conversion from 64-bit integers).
    let mut first_k = 0.0;
    for (first, (((d, frozen), x), on)) in (0..).step_by(LANES).zip(chunks) {
        one_vector_at_a_time();
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
            // The counts fit an i32 (a ray has at most 20 000 layers): a vector conversion.
            let n = f64::from(bubbles[k] as i32);
            x[k] = n.mul_add(ln_forward, (first_k + k as f64).mul_add(x1, x0));
        }
        first_k += LANES as f64;
    }
    let chunks = exponent
        .chunks_exact(LANES)
        .zip(bundle.chunks_exact(LANES))
        .zip(sums0.chunks_exact_mut(LANES))
        .zip(sums1.chunks_exact_mut(LANES));
    for (((x, on), s0), s1) in chunks {
        one_vector_at_a_time();
        for k in 0..LANES {
            let flux = scale * exp_small(x[k]);
            // The sums are ≥ +0, so adding +0 leaves them as they are.
            s0[k] += if on[k] == 0 { flux } else { 0.0 };
            s1[k] += if on[k] == 1 { flux } else { 0.0 };
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
    /// bits on every tier; nothing added past `len` or to the bundle it does not land on.
    #[test]
    fn specular_reflection_follows_the_law_on_every_tier() {
        use crate::geometry::{Geometry, Region};
        use rand_core::Rng;
        use rand_pcg::Pcg32;
        let mut rng = Pcg32::new(5, 9);
        let geo = Geometry::ThesisCh5;
        let bundles = geo.bundles();
        let ln_f = 0.95f64.ln();
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
            let line = SpecularLine {
                p0: DVec2::new(u(-4.0, 0.0), u(-4.0, 4.0)),
                w: DVec2::new(u(-1.0, 2.0), u(-1.0, 1.0)),
                a: u(-1.0, 1.0),
            };
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
                    specular_reflection(
                        &line,
                        &bundles,
                        &thick,
                        &frozen_by,
                        &mut s0,
                        &mut s1,
                        len,
                        n_before,
                        [scale, ln_f, x0, x1],
                        &mut vec![0.0; lanes],
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
