//! The dense bubbles of rime ice (thesis §3.2.2–§3.2.3, Fig. 3.11): after the walk has found
//! where along a ray they lie (walk.rs), which way each scatters and where its scattered ray
//! lands on the face.
//!
//! Each bubble's draws come from a counter-based stream ([`CounterStream`]: the words a
//! bubble uses are fixed by its number, below), so no draw depends on a branch taken before
//! it. Where the scattered rays of one ray land is then decided at once by [`land_scattered`],
//! loops the compiler vectorises (AVX-512 or AVX2 with FMA when the CPU has them): in single
//! precision, sixteen lanes to a vector, with a margin ten times its error bound; the few
//! bubbles whose landing point lies within the margin of an edge are decided again in double
//! precision, so every slot is the double-precision one, on every tier. The scattered rays
//! that land are then computed in double precision ([`BubbleLanes::scattered`]).
//!
//! Layout of the draws of bubble n (the even words hold gaps, the odd words angles):
//! - the gap of empty layers before it: word 2⌊n/2⌋, its upper 32 bits for even n, its
//!   lower 32 bits for odd n;
//! - cos θ_B = 1 − u, u uniform in [0, 1): the lower 32 bits of word 2n + 1 (the
//!   scattered ray is isotropic over the lower hemisphere, as in the thesis's bubble model);
//! - the azimuth φ: the upper 32 bits of word 2n + 1 (2 bits of quadrant, 30 of angle).

use std::ops::{Add, Mul, Neg, Sub};

use glam::DVec2;

use crate::consts::BUBBLE_LAYER_MM;
use crate::geometry::Bundles;
use crate::kernels::{LANES, grow, one_vector_at_a_time, small_int, u32_to_f64, vector_kernel};
use crate::streams::{CounterStream, INV_2_POW_32};
use crate::walk::{GROUP_RAYS, GapSampler, GroupWalk};

/// The point on the unit circle at azimuth φ = 2π (u + ½)/2³² for a 32-bit draw u (given
/// as an f64, exactly): the quadrant from its upper 2 bits, the angle within it from the
/// other 30, by polynomials; float operations only, so that it vectorises.
#[inline(always)]
pub(crate) fn unit_circle_of(u: f64) -> (f64, f64) {
    let (quadrant, t) = quadrant_and_angle(u);
    let (s, c) = sin_cos_octant(t);
    into_quadrant(quadrant, c, s, std::f64::consts::FRAC_1_SQRT_2)
}

/// The quadrant of φ = 2π (u + ½)/2³² (0 to 3, from u's upper 2 bits) and the angle t
/// within it about its middle, |t| ≤ π/4 (from the other 30 bits).
#[inline(always)]
fn quadrant_and_angle(u: f64) -> (f64, f64) {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};
    const QUARTER: f64 = 1_073_741_824.0; // 2³⁰
    let quadrant = (u * (1.0 / QUARTER)).floor();
    let within = u - quadrant * QUARTER; // exact
    (quadrant, (within + 0.5) * (FRAC_PI_2 / QUARTER) - FRAC_PI_4)
}

/// The point at angle π/4 + t (from cos t, sin t), turned by `quadrant`·π/2: by π/2 in
/// quadrants 1 and 3, then by π in 2 and 3. In f64 or f32.
#[inline(always)]
fn into_quadrant<T>(quadrant: T, c: T, s: T, frac_1_sqrt_2: T) -> (T, T)
where
    T: Copy
        + PartialOrd
        + From<u8>
        + Neg<Output = T>
        + Add<Output = T>
        + Sub<Output = T>
        + Mul<Output = T>,
{
    let (x, y) = ((c - s) * frac_1_sqrt_2, (c + s) * frac_1_sqrt_2);
    let odd = (quadrant == T::from(1)) | (quadrant == T::from(3));
    let (x, y) = (if odd { -y } else { x }, if odd { x } else { y });
    let half = quadrant >= T::from(2);
    (if half { -x } else { x }, if half { -y } else { y })
}

/// sin and cos for |x| ≤ π/4 by Taylor series to x¹³ / x¹⁴ (Horner with fused
/// multiply-adds): error below 3e-14.
#[inline(always)]
fn sin_cos_octant(x: f64) -> (f64, f64) {
    debug_assert!(x.abs() <= std::f64::consts::FRAC_PI_4 + 1e-12);
    // 1/k! for the odd and even k.
    const S: [f64; 6] = [
        -1.0 / 6.0,
        1.0 / 120.0,
        -1.0 / 5_040.0,
        1.0 / 362_880.0,
        -1.0 / 39_916_800.0,
        1.0 / 6_227_020_800.0,
    ];
    const C: [f64; 7] = [
        -1.0 / 2.0,
        1.0 / 24.0,
        -1.0 / 720.0,
        1.0 / 40_320.0,
        -1.0 / 3_628_800.0,
        1.0 / 479_001_600.0,
        -1.0 / 87_178_291_200.0,
    ];
    let x2 = x * x;
    let mut s = S[5];
    for &k in S[..5].iter().rev() {
        s = s.mul_add(x2, k);
    }
    let mut c = C[6];
    for &k in C[..6].iter().rev() {
        c = c.mul_add(x2, k);
    }
    ((x * x2).mul_add(s, x), x2.mul_add(c, 1.0))
}

/// The bubbles of one ray, one entry per bubble in walk order, padded to a multiple of
/// `LANES` with copies of the last bubble (never read): inputs and outputs of
/// [`land_scattered`]. Structure of arrays (layers as f64, exactly), so that the kernel is
/// made of loops of float operations that the compiler vectorises.
#[derive(Clone, Debug, Default)]
pub(crate) struct BubbleLanes {
    count: usize,
    /// The walks of a group of rays (layer index j of each bubble), their streams, and the
    /// ray's lane.
    walk: GroupWalk,
    streams: [CounterStream; GROUP_RAYS],
    lane: usize,
    /// Output: the output index (thickness) from which the bubble is frozen in.
    pub index: Vec<i32>,
    /// Output: 0 or 1 for the bundle the scattered ray lands on, 2 for none.
    pub slot: Vec<i32>,
    /// The draws of cos θ_B and φ (32-bit integers held exactly as f64).
    draw_cos: Vec<f64>,
    draw_phi: Vec<f64>,
    /// The single-precision test's inputs (`landing_inputs_f32`).
    f32_z: Vec<f32>,
    f32_sin2: Vec<f32>,
    f32_cos: Vec<f32>,
    f32_a: Vec<f32>,
    f32_q: Vec<f32>,
}

impl BubbleLanes {
    /// Number of bubbles.
    pub(crate) fn len(&self) -> usize {
        self.count
    }

    /// The scattered ray of bubble `n` (after [`land_scattered`]), in double precision:
    /// its direction's sideways part only if `sideways` (else 0: the thesis's coupling
    /// needs only cos θ_B).
    pub(crate) fn scattered(&self, n: usize, sideways: bool) -> Scattered {
        let (j, cos_b) = (self.layer()[n], cos_b_of(self.draw_cos[n]));
        if sideways {
            let (c_phi, s_phi) = unit_circle_of(self.draw_phi[n]);
            scattered_ray(j, cos_b, c_phi, s_phi)
        } else {
            let z_mm = (j + 0.5) * BUBBLE_LAYER_MM;
            Scattered {
                z_mm,
                dir: [0.0, 0.0, -cos_b],
                reach_mm: z_mm / cos_b,
            }
        }
    }

    /// After [`land_scattered`]: at each output index where bubbles are frozen in, how many
    /// are frozen in up to it (`frozen_by`; the indices never decrease along the walk, so
    /// the last bubble of an index writes its number + 1, by plain stores), and the list of
    /// the bubbles whose scattered ray lands on a bundle (≈ 1 in 8; gathered without a
    /// branch into `landed`, which only grows): their number.
    // Its own function: inside the tracer the running values would live on the stack.
    #[inline(never)]
    pub(crate) fn tally(&self, frozen_by: &mut [u32], landed: &mut Vec<u32>) -> usize {
        let count = self.count;
        // Room for whole vectors of sixteen.
        grow(landed, count.next_multiple_of(16), 0);
        #[cfg(target_arch = "x86_64")]
        if crate::kernels::isa() == crate::kernels::Isa::Avx512 {
            // SAFETY: the CPU has AVX-512 F (`isa`); `landed` has room for whole vectors.
            return unsafe {
                tally_avx512(&self.index[..count], &self.slot[..count], frozen_by, landed)
            };
        }
        let mut m = 0;
        let bubbles = self.index[..count].iter().zip(&self.slot[..count]);
        for (n, (&i, &k)) in (0u32..).zip(bubbles) {
            frozen_by[i as usize] = n + 1;
            landed[m] = n;
            m += usize::from(k < 2);
        }
        m
    }

    /// Walk the layers j < `j_end[ℓ]` of a group of rays, one to a lane ℓ with stream
    /// `streams[ℓ]`: where their bubbles are (walk.rs). Then [`BubbleLanes::select`] one.
    pub(crate) fn walk_group(
        &mut self,
        streams: [CounterStream; GROUP_RAYS],
        gaps: &GapSampler,
        j_end: [u32; GROUP_RAYS],
    ) {
        self.walk.walk(streams, gaps, j_end);
        self.streams = streams;
    }

    /// The bubbles of the ray of lane `lane` of the group walked last.
    pub(crate) fn select(&mut self, lane: usize) {
        self.lane = lane;
        let n = self.walk.len(lane);
        self.count = n;
        // Pad to whole vectors with copies of the last bubble (or of zeros).
        let column = self.walk.column_mut(lane);
        let last = column[n.saturating_sub(1)];
        column[n..n.next_multiple_of(LANES)].fill(last);
    }

    /// Walk one ray (in a group of its own): its layers j < `j_end`.
    #[cfg(test)]
    pub(crate) fn walk(&mut self, stream: CounterStream, gaps: &GapSampler, j_end: u32) {
        let mut j_ends = [0; GROUP_RAYS];
        j_ends[0] = j_end;
        self.walk_group([stream; GROUP_RAYS], gaps, j_ends);
        self.select(0);
    }

    /// Layer index j of each bubble, then the padding.
    fn layer(&self) -> &[f64] {
        self.walk.column(self.lane)
    }
}

/// [`BubbleLanes::tally`] sixteen bubbles at a time: `frozen_by` by a scatter (of lanes
/// with equal indices the last is stored, as by the loop), the landed bubbles' numbers by a
/// compress.
///
/// # Safety
/// The CPU has AVX-512 F; `landed` has room for `index.len()` rounded up to sixteen.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2,fma")]
unsafe fn tally_avx512(
    index: &[i32],
    slot: &[i32],
    frozen_by: &mut [u32],
    landed: &mut [u32],
) -> usize {
    use std::arch::x86_64::*;
    let count = index.len().min(slot.len());
    assert!(landed.len() >= count.next_multiple_of(16));
    let ramp = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    let (two, sixteen) = (_mm512_set1_epi32(2), _mm512_set1_epi32(16));
    let len = _mm512_set1_epi32(frozen_by.len().min(i32::MAX as usize) as i32);
    let mut number = ramp;
    let mut m = 0;
    for start in (0..count).step_by(16) {
        let valid: __mmask16 = if count - start >= 16 {
            0xFFFF
        } else {
            (1 << (count - start)) - 1
        };
        // SAFETY: the valid lanes lie within `index` and `slot`; the others are not read.
        let (i, k) = unsafe {
            (
                _mm512_maskz_loadu_epi32(valid, index.as_ptr().add(start)),
                _mm512_maskz_loadu_epi32(valid, slot.as_ptr().add(start)),
            )
        };
        // Every index within `frozen_by`, as the loop's bounds check asks.
        assert_eq!(
            _mm512_mask_cmplt_epu32_mask(valid, i, len),
            valid,
            "freeze-in index"
        );
        // SAFETY: the valid lanes' indices are below frozen_by.len() (checked above); lanes
        // with equal indices are stored from the lowest to the highest.
        unsafe {
            _mm512_mask_i32scatter_epi32::<4>(
                frozen_by.as_mut_ptr().cast(),
                valid,
                i,
                _mm512_add_epi32(number, _mm512_set1_epi32(1)),
            );
        }
        let hit = _mm512_mask_cmplt_epi32_mask(valid, k, two);
        // SAFETY: m + 16 ≤ start + 16 ≤ landed.len() (m ≤ start).
        unsafe {
            _mm512_storeu_si512(
                landed.as_mut_ptr().add(m).cast(),
                _mm512_maskz_compress_epi32(hit, number),
            );
        }
        m += hit.count_ones() as usize;
        number = _mm512_add_epi32(number, sixteen);
    }
    m
}

/// The draws of the scattering angles of bubble n, as f64 (exactly): cos θ_B from the lower
/// and φ from the upper 32 bits of word 2n + 1.
#[inline(always)]
fn angle_draws(stream: CounterStream, n: u64) -> (f64, f64) {
    let w = stream.word(2 * n + 1);
    (u32_to_f64(w), u32_to_f64(w >> 32))
}

/// One source ray as the bubble kernel sees it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BubbleRay {
    /// Position of the ray on the face, mm.
    pub p0: DVec2,
    /// Sideways travel per height along the ray, (v_x, v_y)/v_z.
    pub slope_xy: DVec2,
    /// Height of the surface plane above the ray's fibre at d = 0, mm.
    pub a: f64,
    /// The plane's rise per height along the ray, tan δ_x·slope_x + tan δ_y·slope_y.
    pub off1: f64,
    /// 1 / output step, mm⁻¹.
    pub inv_step: f64,
    /// First output index with ice (d > 0).
    pub first_wet: u32,
}

impl BubbleRay {
    /// The mean thickness from which layer j is covered, in output steps (minus 1e-9):
    /// d_j = (j + 1)·Δ − a − off1·z_b, with z_b = (j + ½)·Δ.
    #[inline(always)]
    pub(crate) fn cover_steps(&self, j: f64) -> f64 {
        let z_top = (j + 1.0) * BUBBLE_LAYER_MM;
        let z_b = (j + 0.5) * BUBBLE_LAYER_MM;
        (z_top - self.a - self.off1 * z_b) * self.inv_step - 1e-9
    }
}

/// The scattered ray of one bubble (thesis §3.2.2, Fig. 3.11).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Scattered {
    /// Height of the bubble above the face, (j + ½)·Δ_Ice, mm.
    pub z_mm: f64,
    /// Direction of the scattered ray (unit, z = −cos θ_B < 0).
    pub dir: [f64; 3],
    /// Its path from the bubble down to the face, z / cos θ_B, mm.
    pub reach_mm: f64,
}

/// The scattered ray of the bubble of layer j: it leaves downward at θ_B from the vertical
/// and azimuth φ, and reaches the face after z / cos θ_B.
#[inline(always)]
fn scattered_ray(j: f64, cos_b: f64, c_phi: f64, s_phi: f64) -> Scattered {
    let z = (j + 0.5) * BUBBLE_LAYER_MM;
    let sin_b = (1.0 - cos_b * cos_b).max(0.0).sqrt();
    Scattered {
        z_mm: z,
        dir: [sin_b * c_phi, sin_b * s_phi, -cos_b],
        reach_mm: z / cos_b,
    }
}

/// Where a scattered ray lands, mm: its bubble lies on the source ray at p0 + `slope_xy`·z,
/// and it travels z·tan θ_B sideways (the horizontal part of its direction times its reach).
#[inline(always)]
fn landing(ray: &BubbleRay, z_mm: f64, dir_x: f64, dir_y: f64, reach_mm: f64) -> [f64; 2] {
    [
        dir_x.mul_add(reach_mm, ray.slope_xy.x.mul_add(z_mm, ray.p0.x)),
        dir_y.mul_add(reach_mm, ray.slope_xy.y.mul_add(z_mm, ray.p0.y)),
    ]
}

/// cos θ_B from its draw u: 1 − u·2⁻³², in (0, 1] (isotropic over the lower hemisphere).
#[inline(always)]
fn cos_b_of(draw: f64) -> f64 {
    1.0 - draw * INV_2_POW_32
}

/// The bundle slot (0, 1; 2 for none) where the scattered ray of the bubble of layer `j`
/// with angle draws (`draw_cos`, `draw_phi`) lands, in double precision: the rule the
/// single-precision test reproduces.
#[inline(always)]
fn landing_slot_exact(
    ray: &BubbleRay,
    bundles: &Bundles,
    j: f64,
    draw_cos: f64,
    draw_phi: f64,
) -> i32 {
    let (c_phi, s_phi) = unit_circle_of(draw_phi);
    let s = scattered_ray(j, cos_b_of(draw_cos), c_phi, s_phi);
    let land = landing(ray, s.z_mm, s.dir[0], s.dir[1], s.reach_mm);
    small_int(bundles.slot_f64(land[0], land[1]))
}

/// Lanes of a vector of f32 with AVX-512: the single-precision pass runs over whole ones.
const F32_LANES: usize = 2 * LANES;

/// A ray and the bundles in single precision, for [`landing_slot_f32`].
#[derive(Clone, Copy)]
struct LandingF32 {
    p0: [f32; 2],
    slope: [f32; 2],
    r: f32,
    b: f32,
}

impl LandingF32 {
    #[inline(always)]
    fn new(ray: &BubbleRay, bundles: &Bundles) -> Self {
        LandingF32 {
            p0: [ray.p0.x as f32, ray.p0.y as f32],
            slope: [ray.slope_xy.x as f32, ray.slope_xy.y as f32],
            r: bundles.radius_mm() as f32,
            b: bundles.length_b_mm() as f32,
        }
    }
}

/// The inputs of [`landing_slot_f32`] for the bubble of layer `j` with angle draws
/// (`draw_cos`, `draw_phi`), each computed in double precision (exactly, but for sin² θ:
/// within 10⁻¹⁶) and rounded once to single: the bubble's height z, sin² θ = t·(2 − t) with
/// t = 1 − cos θ, cos θ (both keep their relative precision however small), the angle a
/// within φ's quadrant about its middle (|a| ≤ π/4, as in `unit_circle_of`) and the
/// quadrant.
#[inline(always)]
fn landing_inputs_f32(j: f64, draw_cos: f64, draw_phi: f64) -> [f32; 5] {
    let (quadrant, a) = quadrant_and_angle(draw_phi);
    [
        ((j + 0.5) * BUBBLE_LAYER_MM) as f32,
        {
            // t and 2 − t are exact (32 and 34 significant bits).
            let t = draw_cos * INV_2_POW_32;
            (t * (2.0 - t)) as f32
        },
        ((4_294_967_296.0 - draw_cos) * INV_2_POW_32) as f32,
        a as f32,
        quadrant as f32,
    ]
}

/// Where the scattered ray of a bubble lands, decided in single precision (sixteen lanes
/// to a vector) from [`landing_inputs_f32`]: the slot as [`landing_slot_exact`] finds it,
/// or 3 where the landing point lies so near an edge of the bundles (the lines |y| = R,
/// x = 0, x = B, the arc) that the rounding of single precision could put it on the other
/// side; those are decided again in double precision.
///
/// Error bound: every input is rounded once to single precision (relative error
/// u = 2⁻²⁴ ≈ 6·10⁻⁸) and each operation adds at most u: the sideways travel
/// ρ = (z·sin θ)·(1/cos θ) carries ≲ 7u of relative error, (cos φ, sin φ) from the series
/// below ≲ 2·10⁻⁷, the bubble's position ≲ 3u of (|b| + z), the landing point
/// ≲ 10⁻⁶·(ρ + |b| + z) in all, and double precision differs from exact by ≈ 10⁻¹⁵. The
/// margin is ten times that.
#[inline(always)]
fn landing_slot_f32(l: &LandingF32, [z, sin2_b, cos_b, a, quadrant]: [f32; 5]) -> i32 {
    let sin_b = sin2_b.sqrt();
    // 1/cos θ apart, so that the division runs beside the square root.
    let rho = (z * sin_b) * (1.0 / cos_b);
    // sin and cos of a by their series to a⁹ and a¹⁰ (error below 2·10⁻⁹), then turned
    // into φ's quadrant as in `unit_circle_of`.
    let a2 = a * a;
    let s = (1.0f32 / 362_880.0)
        .mul_add(a2, -1.0 / 5_040.0)
        .mul_add(a2, 1.0 / 120.0)
        .mul_add(a2, -1.0 / 6.0);
    let s = (a * a2).mul_add(s, a);
    let c = (-1.0f32 / 3_628_800.0)
        .mul_add(a2, 1.0 / 40_320.0)
        .mul_add(a2, -1.0 / 720.0)
        .mul_add(a2, 1.0 / 24.0)
        .mul_add(a2, -0.5)
        .mul_add(a2, 1.0);
    let (c_phi, s_phi) = into_quadrant(quadrant, c, s, std::f32::consts::FRAC_1_SQRT_2);
    // The landing point and its side of every edge.
    let bx = l.slope[0].mul_add(z, l.p0[0]);
    let by = l.slope[1].mul_add(z, l.p0[1]);
    let x = rho.mul_add(c_phi, bx);
    let y = rho.mul_add(s_phi, by);
    let margin = 1e-5 * (rho + bx.abs() + by.abs() + z + 1.0);
    let (r, b) = (l.r, l.b);
    let dx = x - b;
    let d2 = dx.mul_add(dx, y * y);
    let near = ((y.abs() - r).abs() < margin)
        | (x.abs() < margin)
        | (dx.abs() < margin)
        | ((d2 - r * r).abs() < margin * (2.0 * r + margin));
    // `Bundles::slot_f64`; a NaN fails every comparison and goes to double precision.
    let face = (y.abs() <= r) & (x >= 0.0);
    let off_face = (y.abs() > r) | (x < 0.0);
    let on = if x <= b {
        0
    } else if d2 <= r * r {
        1
    } else {
        2
    };
    if near | !(face | off_face) {
        3
    } else if face {
        on
    } else {
        2
    }
}

/// Per bubble: the output index at which it is frozen in (the first index ≥ its cover
/// thickness, not before the first wet one) and the bundle its scattered ray lands on.
pub(crate) fn land_scattered(ray: &BubbleRay, bundles: &Bundles, lanes: &mut BubbleLanes) {
    // The output buffers only grow (their tails are stale and never read). The passes in
    // double precision run over whole vectors of eight, the one in single precision over
    // whole vectors of sixteen (its last eight lanes may hold stale inputs; their slots are
    // never read): no lane is left to a remainder loop.
    let n = lanes.count.next_multiple_of(LANES);
    let n_f32 = lanes.count.next_multiple_of(F32_LANES);
    grow(&mut lanes.index, n, 0);
    grow(&mut lanes.slot, n_f32, 0);
    for out in [&mut lanes.draw_cos, &mut lanes.draw_phi] {
        grow(out, n, 0.0);
    }
    for out in [
        &mut lanes.f32_z,
        &mut lanes.f32_sin2,
        &mut lanes.f32_cos,
        &mut lanes.f32_a,
        &mut lanes.f32_q,
    ] {
        grow(out, n_f32, 0.0);
    }
    let mut any_near = [0];
    land_scattered_lanes(
        ray,
        bundles,
        lanes.streams[lanes.lane],
        &lanes.walk.column(lanes.lane)[..n],
        &mut lanes.index[..n],
        &mut lanes.slot[..n_f32],
        &mut lanes.draw_cos[..n],
        &mut lanes.draw_phi[..n],
        &mut lanes.f32_z[..n_f32],
        &mut lanes.f32_sin2[..n_f32],
        &mut lanes.f32_cos[..n_f32],
        &mut lanes.f32_a[..n_f32],
        &mut lanes.f32_q[..n_f32],
        &mut any_near,
    );
    // The few lanes too near an edge for single precision, in double precision.
    if any_near[0] == 0 {
        return;
    }
    for k in 0..n {
        if lanes.slot[k] == 3 {
            lanes.slot[k] = landing_slot_exact(
                ray,
                bundles,
                lanes.layer()[k],
                lanes.draw_cos[k],
                lanes.draw_phi[k],
            );
        }
    }
}

vector_kernel! {
// Every array its own argument: the compiler then knows that they do not overlap.
#[allow(clippy::too_many_arguments)]
fn land_scattered_lanes(
    ray: &BubbleRay,
    bundles: &Bundles,
    stream: CounterStream,
    layer: &[f64],
    index: &mut [i32],
    slot: &mut [i32],
    draw_cos: &mut [f64],
    draw_phi: &mut [f64],
    f32_z: &mut [f32],
    f32_sin2: &mut [f32],
    f32_cos: &mut [f32],
    f32_a: &mut [f32],
    f32_q: &mut [f32],
    any_near: &mut [i32; 1],
) {
    let n = layer.len();
    let n_f32 = slot.len().max(n);
    let (f32_z, f32_sin2) = (&mut f32_z[..n_f32], &mut f32_sin2[..n_f32]);
    let f32_cos = &mut f32_cos[..n_f32];
    let (f32_a, f32_q) = (&mut f32_a[..n_f32], &mut f32_q[..n_f32]);
    let (index, slot) = (&mut index[..n], &mut slot[..n_f32]);
    let (draw_cos, draw_phi) = (&mut draw_cos[..n], &mut draw_phi[..n]);
    // Passes of short chains of dependent operations, so that the processor overlaps many
    // bubbles (one long loop body is bound by the latency of its chain).
    // Each pass vector by vector: the compiler then leaves no lane to a narrower remainder
    // loop.
    const W: usize = LANES;
    // 1. The draws of the angles.
    let draws = draw_cos.chunks_exact_mut(W).zip(draw_phi.chunks_exact_mut(W));
    for (first, (dc, dp)) in (0u64..).step_by(W).zip(draws) {
        one_vector_at_a_time();
        for k in 0..W {
            (dc[k], dp[k]) = angle_draws(stream, first + k as u64);
        }
    }
    // 2. The freeze-in index.
    let first_wet = f64::from(ray.first_wet);
    for (j, i) in layer.chunks_exact(W).zip(index.chunks_exact_mut(W)) {
        one_vector_at_a_time();
        for k in 0..W {
            // ceil is exact; the walk keeps j below the layer whose index would pass the
            // last.
            i[k] = small_int(ray.cover_steps(j[k]).ceil().max(first_wet));
        }
    }
    // 3. Where the scattered ray lands, in single precision (3: too near an edge to tell):
    // its inputs from double precision, eight lanes to a vector, then sixteen.
    let outputs = f32_z
        .chunks_exact_mut(W)
        .zip(f32_sin2.chunks_exact_mut(W))
        .zip(f32_cos.chunks_exact_mut(W))
        .zip(f32_a.chunks_exact_mut(W))
        .zip(f32_q.chunks_exact_mut(W));
    let inputs = layer
        .chunks_exact(W)
        .zip(draw_cos.chunks_exact(W))
        .zip(draw_phi.chunks_exact(W));
    for (((((z, t), c), a), q), ((j, dc), dp)) in outputs.zip(inputs) {
        one_vector_at_a_time();
        for k in 0..W {
            [z[k], t[k], c[k], a[k], q[k]] = landing_inputs_f32(j[k], dc[k], dp[k]);
        }
    }
    let l = LandingF32::new(ray, bundles);
    let mut near = 0;
    // Vector by vector: the compiler then leaves no lane to a narrower remainder loop.
    const V: usize = F32_LANES;
    let inputs = f32_z
        .chunks_exact(V)
        .zip(f32_sin2.chunks_exact(V))
        .zip(f32_cos.chunks_exact(V))
        .zip(f32_a.chunks_exact(V))
        .zip(f32_q.chunks_exact(V));
    for (((((z, t), c), a), q), s) in inputs.zip(slot.chunks_exact_mut(V)) {
        one_vector_at_a_time();
        for k in 0..V {
            s[k] = landing_slot_f32(&l, [z[k], t[k], c[k], a[k], q[k]]);
            near |= i32::from(s[k] == 3);
        }
    }
    any_near[0] = near;
}
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Geometry;

    #[test]
    fn unit_circle_is_unit_and_uniform_in_angle() {
        let s = CounterStream::new(9, 9);
        let mut sector = [0usize; 16];
        let n = 160_000u64;
        for k in 0..n {
            let u = (s.word(k) >> 32) as u32;
            let (x, y) = unit_circle_of(f64::from(u));
            assert!((x * x + y * y - 1.0).abs() < 1e-13);
            // The same angle as libm gives for φ = 2π (u + ½)/2³².
            let phi = std::f64::consts::TAU * (f64::from(u) + 0.5) * INV_2_POW_32;
            assert!(
                (x - phi.cos()).abs() < 1e-13 && (y - phi.sin()).abs() < 1e-13,
                "{u}"
            );
            let a = y.atan2(x).rem_euclid(std::f64::consts::TAU);
            sector[((a / std::f64::consts::TAU * 16.0) as usize).min(15)] += 1;
        }
        for c in sector {
            assert!((c as f64 - 10_000.0).abs() < 400.0, "{sector:?}");
        }
        // Quadrant edges.
        let (x, y) = unit_circle_of(0.0);
        assert!((x - 1.0).abs() < 1e-9 && y.abs() < 1e-8);
        let (x, y) = unit_circle_of(f64::from(u32::MAX));
        assert!((x - 1.0).abs() < 1e-9 && y.abs() < 1e-8);
        let (x, y) = unit_circle_of(f64::from(1u32 << 30));
        assert!(x.abs() < 1e-8 && (y - 1.0).abs() < 1e-9);
    }

    /// The single-precision landing test with its fallback gives the double-precision slot
    /// for every bubble of 20 000 random rays (positions over and around the face, slopes up
    /// to 60°, bubbles up to 15 mm high), on every tier; its margin sends a few lanes to the
    /// fallback and no more.
    #[test]
    fn single_precision_landing_gives_the_exact_slot() {
        use crate::kernels::{Isa, isa, with_isa};
        use crate::streams::uniform;
        use rand_pcg::Pcg32;
        let mut rng = Pcg32::new(3, 5);
        let gaps = GapSampler::new(0.21);
        let mut lanes = BubbleLanes::default();
        let (mut bubbles, mut near, mut landed) = (0usize, 0usize, 0usize);
        for geo in [Geometry::ThesisCh3, Geometry::ThesisCh5] {
            let bundles = geo.bundles();
            for r in 0..10_000u64 {
                let mut u = |lo: f64, hi: f64| lo + (hi - lo) * uniform(&mut rng);
                let ray = BubbleRay {
                    p0: DVec2::new(u(-6.0, 10.0), u(-6.0, 6.0)),
                    slope_xy: DVec2::new(u(-1.7, 1.7), u(-1.7, 1.7)),
                    a: u(-1.0, 1.0),
                    off1: u(-0.3, 0.3),
                    inv_step: 10.0,
                    first_wet: 1,
                };
                let stream = CounterStream::new(77, r);
                for tier in [Isa::Baseline, Isa::Avx2, Isa::Avx512] {
                    if tier > isa() {
                        continue;
                    }
                    lanes.walk(stream, &gaps, 150);
                    with_isa(tier, || land_scattered(&ray, &bundles, &mut lanes));
                    for n in 0..lanes.len() {
                        let (j, dc, dp) = (lanes.layer()[n], lanes.draw_cos[n], lanes.draw_phi[n]);
                        let want = landing_slot_exact(&ray, &bundles, j, dc, dp);
                        assert_eq!(lanes.slot[n], want, "{geo:?} ray {r} bubble {n} {tier:?}");
                        let inputs = landing_inputs_f32(j, dc, dp);
                        let l = LandingF32::new(&ray, &bundles);
                        near += usize::from(landing_slot_f32(&l, inputs) == 3);
                        landed += usize::from(want < 2);
                        bubbles += 1;
                    }
                }
            }
        }
        assert!(landed * 20 > bubbles, "{landed} of {bubbles} land");
        assert!(
            near > 0 && near * 1000 < bubbles,
            "{near} of {bubbles} near an edge"
        );
        // Rays moved so that one bubble's scattered ray lands within 10⁻⁷–10⁻⁵ mm of an
        // edge (either side): single precision alone would misjudge some of these.
        let (r_mm, b_mm) = (4.0, 3.2);
        let bundles = Geometry::ThesisCh5.bundles();
        let mut hits = [0usize; 3];
        for r in 0..4_000u64 {
            let mut u = |lo: f64, hi: f64| lo + (hi - lo) * uniform(&mut rng);
            let mut ray = BubbleRay {
                p0: DVec2::new(u(-2.0, 6.0), u(-3.0, 3.0)),
                slope_xy: DVec2::new(u(-1.2, 1.2), u(-1.2, 1.2)),
                a: 0.0,
                off1: 0.0,
                inv_step: 10.0,
                first_wet: 1,
            };
            let stream = CounterStream::new(78, r);
            lanes.walk(stream, &gaps, 150);
            let k = (r as usize) % lanes.len().max(1);
            if lanes.len() == 0 {
                continue;
            }
            land_scattered(&ray, &bundles, &mut lanes);
            let sc = lanes.scattered(k, true);
            let land = DVec2::from(landing(&ray, sc.z_mm, sc.dir[0], sc.dir[1], sc.reach_mm));
            let delta = [-1e-5, -1e-6, -1e-7, 1e-7, 1e-6, 1e-5][(r / 4) as usize % 6];
            let target = match r % 4 {
                0 => DVec2::new(delta, u(-r_mm, r_mm)),
                1 => DVec2::new(b_mm + delta, u(-r_mm, r_mm)),
                2 => DVec2::new(u(0.0, b_mm), r_mm + delta),
                _ => {
                    let alpha = u(-1.5, 1.5);
                    DVec2::new(b_mm, 0.0) + DVec2::new(alpha.cos(), alpha.sin()) * (r_mm + delta)
                }
            };
            ray.p0 += target - land;
            for tier in [Isa::Baseline, Isa::Avx2, Isa::Avx512] {
                if tier > isa() {
                    continue;
                }
                with_isa(tier, || land_scattered(&ray, &bundles, &mut lanes));
                let (j, dc, dp) = (lanes.layer()[k], lanes.draw_cos[k], lanes.draw_phi[k]);
                let want = landing_slot_exact(&ray, &bundles, j, dc, dp);
                assert_eq!(
                    lanes.slot[k],
                    want,
                    "ray {r}, bubble {k}, edge {}, {tier:?}",
                    r % 4
                );
                hits[want as usize] += 1;
            }
        }
        // Both sides of the edges were met.
        assert!(hits.iter().all(|&h| h > 500), "{hits:?}");
    }

    /// The tally on every tier: the same `frozen_by` (the last bubble of each index wins)
    /// and the same landed list as a loop bubble by bubble, for counts around whole
    /// vectors and indices that repeat.
    #[test]
    fn tally_is_the_same_on_every_tier() {
        use crate::kernels::{Isa, isa, with_isa};
        use rand_core::Rng;
        use rand_pcg::Pcg32;
        let mut rng = Pcg32::new(11, 3);
        let mut lanes = BubbleLanes::default();
        for count in [0usize, 1, 5, 15, 16, 17, 31, 32, 33, 47, 64, 100] {
            for _ in 0..20 {
                // Non-decreasing indices from 1, often repeated; slots 0, 1 or 2.
                let mut i = 1;
                lanes.index = (0..count)
                    .map(|_| {
                        i += i32::from(rng.next_u32().is_multiple_of(3));
                        i
                    })
                    .collect();
                lanes.slot = (0..count).map(|_| (rng.next_u32() % 3) as i32).collect();
                lanes.count = count;
                let nt = 2 + count;
                let (mut want_frozen, mut want_landed) = (vec![0u32; nt], Vec::new());
                for n in 0..count {
                    want_frozen[lanes.index[n] as usize] = n as u32 + 1;
                    if lanes.slot[n] < 2 {
                        want_landed.push(n as u32);
                    }
                }
                for tier in [Isa::Baseline, Isa::Avx2, Isa::Avx512] {
                    if tier > isa() {
                        continue;
                    }
                    let (mut frozen, mut landed) = (vec![0u32; nt], Vec::new());
                    let m = with_isa(tier, || lanes.tally(&mut frozen, &mut landed));
                    assert_eq!(frozen, want_frozen, "{count} {tier:?}");
                    assert_eq!(landed[..m], want_landed[..], "{count} {tier:?}");
                }
            }
        }
    }

    #[test]
    fn landing_kernel_is_bit_identical_to_the_scalar_formula() {
        let geo = Geometry::ThesisCh5;
        let bundles = geo.bundles();
        let gaps = GapSampler::new(0.21);
        let mut lanes = BubbleLanes::default();
        let (p0, slope) = (DVec2::new(-1.3, 0.7), DVec2::new(0.45, -0.12));
        let ray = BubbleRay {
            p0,
            slope_xy: slope,
            a: -0.3,
            off1: 0.05,
            inv_step: 10.0,
            first_wet: 1,
        };
        let stream = CounterStream::new(5, 8);
        lanes.walk(stream, &gaps, 150);
        assert!(lanes.len() > 15, "{}", lanes.len());
        land_scattered(&ray, &bundles, &mut lanes);
        // The walk again, by hand: gaps, then the draws of each bubble.
        let (mut j, mut landed) = (0u32, 0);
        for n in 0..lanes.len() {
            let w0 = stream.word(2 * (n as u64 / 2));
            j += gaps.gap(if n.is_multiple_of(2) {
                (w0 >> 32) as u32
            } else {
                w0 as u32
            });
            let w1 = stream.word(2 * n as u64 + 1);
            let (u_cos, u_phi) = (f64::from(w1 as u32), f64::from((w1 >> 32) as u32));
            assert_eq!(lanes.layer()[n], f64::from(j), "bubble {n}");
            let z = (f64::from(j) + 0.5) * 0.1;
            let q = ((f64::from(j) + 1.0) * 0.1 + 0.3 - 0.05 * z) * 10.0 - 1e-9;
            assert_eq!(f64::from(lanes.index[n]), q.ceil().max(1.0), "bubble {n}");
            let cos_b = 1.0 - u_cos * INV_2_POW_32;
            let sin_b = (1.0 - cos_b * cos_b).max(0.0).sqrt();
            let (c, s) = unit_circle_of(u_phi);
            let reach = z / cos_b;
            let land = DVec2::new(
                (sin_b * c).mul_add(reach, slope.x.mul_add(z, p0.x)),
                (sin_b * s).mul_add(reach, slope.y.mul_add(z, p0.y)),
            );
            let want = match geo.region(land.x, land.y) {
                crate::geometry::Region::Bundle1 => 0,
                crate::geometry::Region::Bundle2 => 1,
                _ => 2,
            };
            assert_eq!(lanes.slot[n], want, "bubble {n}");
            let sc = lanes.scattered(n, true);
            assert_eq!(sc.z_mm.to_bits(), z.to_bits());
            assert_eq!(sc.reach_mm.to_bits(), reach.to_bits());
            assert_eq!(sc.dir, [sin_b * c, sin_b * s, -cos_b]);
            landed += usize::from(want < 2);
            j += 1;
        }
        // The next gap passes the end.
        let n = lanes.len() as u64;
        let w0 = stream.word(2 * (n / 2));
        assert!(
            j + gaps.gap(if n.is_multiple_of(2) {
                (w0 >> 32) as u32
            } else {
                w0 as u32
            }) >= 150
        );
        assert!(landed > 0);
    }
}
