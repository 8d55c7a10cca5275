//! The rime walk (thesis §3.2.2–§3.2.3): where along a ray its bubbles lie.
//! Every layer of Δ_Ice holds a bubble with probability P_B, independently, so the numbers
//! of empty layers between bubbles are geometric: one draw per bubble ([`GapSampler`]), not
//! one per layer. The gap before bubble n is drawn from word 2⌊n/2⌋ of the ray's
//! counter-based stream (its upper 32 bits for even n, its lower 32 bits for odd n; the
//! layout is in bubbles.rs). Eight rays are walked side by side ([`GroupWalk`]): with
//! AVX-512 one ray to a lane, two bubbles of each per step, then the rows turned into a
//! column per ray; otherwise ray after ray, gap by gap.
//! Both find the same layers (integers: exact on every tier; tested).

use crate::kernels::grow;
use crate::streams::CounterStream;

/// Bits of a draw that index the bucket table of [`GapSampler`].
const GAP_BUCKET_BITS: u32 = 12;

/// Geometric gaps from one 32-bit draw: the number of layers without a bubble before the
/// next bubble, P(gap ≥ k) = (1 − P_B)^k, by inversion against a table of thresholds.
#[derive(Clone, Debug)]
pub(crate) struct GapSampler {
    /// threshold[k − 1] = round((1 − P_B)^k · 2³²): gap ≥ k iff the draw is below it.
    /// Non-increasing, ends with a 0 (no draw is below it), so that every gap g has a
    /// `threshold[g]`.
    threshold: Vec<u32>,
    /// Per bucket of the draw's upper `GAP_BUCKET_BITS` bits, one load answers: the
    /// smallest gap g in the bucket (bits 32–63) and the threshold below which the gap is
    /// g + 1 (bits 0–31; 0 if the whole bucket has gap g). `MANY` in bits 32–63 marks the
    /// few buckets near a draw of 0 that straddle more than one threshold.
    bucket: Box<[u64; 1 << GAP_BUCKET_BITS]>,
}

/// Marks a bucket whose gaps are counted threshold by threshold.
const MANY: u64 = u64::MAX << 32;

impl GapSampler {
    /// The sampler for P_B = `p_bubble` (`DENSE_ABOVE` < P_B ≤ 1).
    pub(crate) fn new(p_bubble: f64) -> Self {
        let q = 1.0 - p_bubble;
        let mut threshold = Vec::new();
        let mut qk = q;
        loop {
            let t = (qk * 4_294_967_296.0).round().min(u32::MAX as f64);
            if t < 1.0 {
                break;
            }
            threshold.push(t as u32);
            qk *= q;
        }
        threshold.push(0);
        let count = |u: u32| threshold.iter().take_while(|&&t| u < t).count() as u64;
        let width = 1u64 << (32 - GAP_BUCKET_BITS);
        // A fixed-size table: the index (the draw's upper bits) needs no bounds check.
        let bucket = Box::new(std::array::from_fn(|b| {
            let b = b as u64;
            let (least, most) = (
                count(((b + 1) * width - 1) as u32),
                count((b * width) as u32),
            );
            match most - least {
                0 => least << 32,
                1 => (least << 32) | u64::from(threshold[least as usize]),
                _ => MANY,
            }
        }));
        GapSampler { threshold, bucket }
    }

    /// The gap for the draw `u`: #{k ≥ 1 : u < threshold of k}.
    #[inline(always)]
    pub(crate) fn gap(&self, u: u32) -> u32 {
        let entry = self.bucket[(u >> (32 - GAP_BUCKET_BITS)) as usize];
        if entry == MANY {
            return self.threshold.iter().take_while(|&&t| u < t).count() as u32;
        }
        (entry >> 32) as u32 + u32::from(u < entry as u32)
    }
}

/// The draws of the gaps before bubbles 2m and 2m + 1 from word 2m: its upper, then its
/// lower 32 bits.
#[inline(always)]
fn gap_draws(w: u64) -> [u32; 2] {
    [(w >> 32) as u32, w as u32]
}

/// Rays walked side by side, one to a lane of an AVX-512 vector.
pub(crate) const GROUP_RAYS: usize = 8;

/// The walks of [`GROUP_RAYS`] rays ([`GroupWalk::walk`]): each lane's layers, in order,
/// in a column of its own.
#[derive(Clone, Debug, Default)]
pub(crate) struct GroupWalk {
    /// Lane ℓ's bubble n at `columns[ℓ·stride + n]` (as f64, exactly).
    columns: Vec<f64>,
    stride: usize,
    count: [usize; GROUP_RAYS],
    /// AVX-512: the walk's rows, bubble n of lane ℓ at `rows[n·8 + ℓ]`, before they are
    /// turned into columns.
    rows: Vec<f64>,
}

impl GroupWalk {
    /// Walk the layers j < `j_end[ℓ]` of eight rays, one to a lane ℓ with stream
    /// `streams[ℓ]`. The same layers on every tier (integers: exact; tested).
    ///
    /// One ray at a time, each step of a walk waits on the one before it (hash, table
    /// lookup, the test for the end); side by side, the eight rays' steps are independent:
    /// with AVX-512 two bubbles of every lane per step, otherwise lane after lane.
    pub(crate) fn walk(
        &mut self,
        streams: [CounterStream; GROUP_RAYS],
        gaps: &GapSampler,
        j_end: [u32; GROUP_RAYS],
    ) {
        // Every bubble takes a layer of its own (at most j_end of them); the AVX-512 walk
        // writes rows in pairs, and turns blocks of eight rows into columns.
        let most = j_end.iter().copied().max().unwrap_or(0) as usize;
        self.stride = (most + 2).next_multiple_of(GROUP_RAYS);
        grow(&mut self.columns, self.stride * GROUP_RAYS, 0.0);
        #[cfg(target_arch = "x86_64")]
        if crate::kernels::isa() == crate::kernels::Isa::Avx512 {
            grow(&mut self.rows, self.stride * GROUP_RAYS, 0.0);
            // SAFETY: the CPU has AVX-512 F and DQ (`isa`); both buffers hold `stride`
            // rows of eight, stride ≥ max(j_end) + 2.
            self.count = unsafe {
                walk_rows_avx512(
                    streams,
                    gaps,
                    j_end,
                    &mut self.rows[..self.stride * GROUP_RAYS],
                )
            };
            let blocks = self
                .count
                .iter()
                .copied()
                .max()
                .unwrap_or(0)
                .div_ceil(GROUP_RAYS);
            // SAFETY: as above; blocks·8 ≤ stride (count ≤ max(j_end)).
            unsafe { rows_to_columns_avx512(&self.rows, blocks, self.stride, &mut self.columns) };
            return;
        }
        for (lane, count) in self.count.iter_mut().enumerate() {
            let column = &mut self.columns[lane * self.stride..(lane + 1) * self.stride];
            *count = walk_scalar(streams[lane], gaps, j_end[lane], column);
        }
    }

    /// Number of bubbles of lane `lane`.
    pub(crate) fn len(&self, lane: usize) -> usize {
        self.count[lane]
    }

    /// Lane `lane`'s column: its layers, then room for at least `LANES` − 1 more.
    pub(crate) fn column(&self, lane: usize) -> &[f64] {
        &self.columns[lane * self.stride..(lane + 1) * self.stride]
    }

    /// [`GroupWalk::column`], to write the padding after its layers.
    pub(crate) fn column_mut(&mut self, lane: usize) -> &mut [f64] {
        &mut self.columns[lane * self.stride..(lane + 1) * self.stride]
    }
}

/// One ray's walk, one bubble at a time, its layers into `layer` (room for `j_end`).
/// Returns the number of bubbles.
fn walk_scalar(stream: CounterStream, gaps: &GapSampler, j_end: u32, layer: &mut [f64]) -> usize {
    let mut j: u32 = 0;
    let mut n: usize = 0;
    'walk: for m in 0.. {
        let w = stream.word(2 * m);
        for u in gap_draws(w) {
            // No overflow: j < j_end ≤ 20 000 before, and a gap is below the length of
            // the threshold table (≈ 1100 for P_B = 0.02).
            j = j.wrapping_add(gaps.gap(u));
            if j >= j_end {
                break 'walk;
            }
            // Every bubble takes a layer of its own, so n ≤ j < j_end: within the room.
            layer[n] = f64::from(j);
            j += 1;
            n += 1;
        }
    }
    n
}

/// The walk of eight rays side by side: per step, bubbles 2m and 2m + 1 of every lane
/// from its word 2m, into rows 2m and 2m + 1 of `rows` (bubble n of lane ℓ at n·8 + ℓ).
/// Returns each lane's number of bubbles.
///
/// # Safety
/// The CPU has AVX-512 F and DQ; `rows` holds max(`j_end`) + 2 rows of eight.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2,fma")]
unsafe fn walk_rows_avx512(
    streams: [CounterStream; GROUP_RAYS],
    gaps: &GapSampler,
    j_end: [u32; GROUP_RAYS],
    rows: &mut [f64],
) -> [usize; GROUP_RAYS] {
    use crate::streams::{GOLDEN_GAMMA, MIX64_MULTIPLIERS};
    use std::arch::x86_64::*;
    let splat64 = |x: u64| _mm512_set1_epi64(x as i64);
    let [mul_a, mul_b] = MIX64_MULTIPLIERS.map(splat64);
    let gamma = splat64(GOLDEN_GAMMA);
    let starts = streams.map(|s| s.counter(0));
    // SAFETY: eight u64 and eight u32 are loaded.
    let (mut counter, end) = unsafe {
        (
            _mm512_loadu_si512(starts.as_ptr().cast()),
            _mm512_cvtepu32_epi64(_mm256_loadu_si256(j_end.as_ptr().cast())),
        )
    };
    let step = splat64(2u64.wrapping_mul(GOLDEN_GAMMA));
    let low32 = splat64(0xFFFF_FFFF);
    let one = splat64(1);
    let many = splat64(MANY);
    let bucket = gaps.bucket.as_ptr().cast::<i64>();
    // Per lane: the layer before which the next gap starts, and the bubbles found.
    let (mut j, mut count) = (_mm512_setzero_si512(), _mm512_setzero_si512());
    let mut active: __mmask8 = 0xFF;
    let out = rows.as_mut_ptr();
    let mut m = 0;
    while active != 0 {
        // SplitMix64 of each lane's word 2m (`streams::mix64`).
        let mut z = _mm512_add_epi64(counter, gamma);
        z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64::<30>(z)), mul_a);
        z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64::<27>(z)), mul_b);
        z = _mm512_xor_si512(z, _mm512_srli_epi64::<31>(z));
        counter = _mm512_add_epi64(counter, step);
        // The draws of bubbles 2m (upper half) and 2m + 1 (lower half): `GapSampler::gap`.
        let (u_a, u_b) = (_mm512_srli_epi64::<32>(z), _mm512_and_si512(z, low32));
        let bucket_of = |u: __m512i| _mm512_srli_epi64::<{ 32 - GAP_BUCKET_BITS }>(u);
        // SAFETY: the indices are below 2^GAP_BUCKET_BITS, the table's length.
        let (e_a, e_b) = unsafe {
            (
                _mm512_i64gather_epi64::<8>(bucket_of(u_a), bucket),
                _mm512_i64gather_epi64::<8>(bucket_of(u_b), bucket),
            )
        };
        let gap_of = |u: __m512i, e: __m512i| {
            let least = _mm512_srli_epi64::<32>(e);
            let below = _mm512_cmplt_epu64_mask(u, _mm512_and_si512(e, low32));
            _mm512_mask_add_epi64(least, below, least, one)
        };
        let (mut g_a, mut g_b) = (gap_of(u_a, e_a), gap_of(u_b, e_b));
        if (_mm512_cmpeq_epi64_mask(e_a, many) | _mm512_cmpeq_epi64_mask(e_b, many)) != 0 {
            // A bucket that straddles several thresholds: counted one by one.
            let (mut ua, mut ub) = ([0u64; GROUP_RAYS], [0u64; GROUP_RAYS]);
            // SAFETY: eight u64 are stored into and loaded from each array.
            unsafe {
                _mm512_storeu_si512(ua.as_mut_ptr().cast(), u_a);
                _mm512_storeu_si512(ub.as_mut_ptr().cast(), u_b);
                let ga = ua.map(|u| u64::from(gaps.gap(u as u32)));
                let gb = ub.map(|u| u64::from(gaps.gap(u as u32)));
                g_a = _mm512_loadu_si512(ga.as_ptr().cast());
                g_b = _mm512_loadu_si512(gb.as_ptr().cast());
            }
        }
        // `walk_scalar`'s steps, lane by lane. No overflow: an active lane has j < j_end
        // ≤ 20 000 and gaps below 2³²; an inactive lane's values are not used.
        let j_a = _mm512_add_epi64(j, g_a);
        let ok_a = _mm512_mask_cmplt_epu64_mask(active, j_a, end);
        let j_b = _mm512_add_epi64(_mm512_add_epi64(j_a, one), g_b);
        let ok_b = _mm512_mask_cmplt_epu64_mask(ok_a, j_b, end);
        // SAFETY: a lane is active at step m only with 2m bubbles below its j_end, each in
        // a layer of its own, so 2m + 1 ≤ max(j_end) + 1: within the rows (caller).
        unsafe {
            let row = out.add(2 * m * GROUP_RAYS);
            _mm512_storeu_pd(row, _mm512_cvtepu64_pd(j_a));
            _mm512_storeu_pd(row.add(GROUP_RAYS), _mm512_cvtepu64_pd(j_b));
        }
        count = _mm512_mask_add_epi64(count, ok_a, count, one);
        count = _mm512_mask_add_epi64(count, ok_b, count, one);
        active = ok_b;
        j = _mm512_add_epi64(j_b, one);
        m += 1;
    }
    let mut counts = [0u64; GROUP_RAYS];
    // SAFETY: eight u64 are stored.
    unsafe { _mm512_storeu_si512(counts.as_mut_ptr().cast(), count) };
    counts.map(|c| c as usize)
}

/// The first `blocks` blocks of eight rows of `rows` (bubble n of lane ℓ at n·8 + ℓ) into
/// columns (at ℓ·`stride` + n), an 8×8 transpose per block.
///
/// # Safety
/// The CPU has AVX-512 F; `rows` holds 8·`blocks` rows of eight, `columns` eight columns of
/// `stride` ≥ 8·`blocks`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2,fma")]
unsafe fn rows_to_columns_avx512(rows: &[f64], blocks: usize, stride: usize, columns: &mut [f64]) {
    use std::arch::x86_64::*;
    debug_assert!(rows.len() >= blocks * 64 && stride >= blocks * 8 && columns.len() >= 8 * stride);
    // Within 128-bit pairs of lanes: even pairs (0, 2) then odd (1, 3) of each source.
    const EVEN: i32 = 0b10_00_10_00;
    const ODD: i32 = 0b11_01_11_01;
    let base = columns.as_mut_ptr();
    for b in 0..blocks {
        // SAFETY: rows 8b..8b + 8 and entries 8b..8b + 8 of each column are in bounds
        // (caller).
        unsafe {
            let src = rows.as_ptr().add(b * 64);
            let r: [__m512d; 8] = std::array::from_fn(|k| _mm512_loadu_pd(src.add(8 * k)));
            // Pairs of rows interleaved: lo = (r_2i[0], r_2i+1[0], r_2i[2], …), hi the odd.
            let lo: [__m512d; 4] =
                std::array::from_fn(|i| _mm512_unpacklo_pd(r[2 * i], r[2 * i + 1]));
            let hi: [__m512d; 4] =
                std::array::from_fn(|i| _mm512_unpackhi_pd(r[2 * i], r[2 * i + 1]));
            for (t, first) in [(lo, 0), (hi, 1)] {
                // Lanes {0, 4} (EVEN) and {2, 6} (ODD) of rows 0–3, and of rows 4–7.
                let u0 = _mm512_shuffle_f64x2::<EVEN>(t[0], t[1]);
                let u1 = _mm512_shuffle_f64x2::<ODD>(t[0], t[1]);
                let u2 = _mm512_shuffle_f64x2::<EVEN>(t[2], t[3]);
                let u3 = _mm512_shuffle_f64x2::<ODD>(t[2], t[3]);
                let column = |lane: usize| base.add((first + lane) * stride + 8 * b);
                _mm512_storeu_pd(column(0), _mm512_shuffle_f64x2::<EVEN>(u0, u2));
                _mm512_storeu_pd(column(4), _mm512_shuffle_f64x2::<ODD>(u0, u2));
                _mm512_storeu_pd(column(2), _mm512_shuffle_f64x2::<EVEN>(u1, u3));
                _mm512_storeu_pd(column(6), _mm512_shuffle_f64x2::<ODD>(u1, u3));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::{Isa, isa, with_isa};

    #[test]
    fn gap_table_matches_counting_every_threshold() {
        for p in [0.021, 0.21, 0.5, 0.99, 1.0] {
            let g = GapSampler::new(p);
            let brute = |u: u32| g.threshold.iter().filter(|&&t| u < t).count() as u32;
            assert_eq!(g.threshold.last(), Some(&0));
            // Every threshold, each side of it, and a spread of other draws.
            let mut us: Vec<u32> = vec![0, 1, u32::MAX, u32::MAX - 1];
            for &t in &g.threshold {
                us.extend([t.wrapping_sub(1), t, t.wrapping_add(1)]);
            }
            us.extend((0..100_000u32).map(|k| k.wrapping_mul(0x9E37_79B9)));
            for u in us {
                assert_eq!(g.gap(u), brute(u), "p {p}, u {u}");
            }
        }
    }

    #[test]
    fn gaps_are_geometric() {
        // P_B = 0.21 (rime): mean gap (1 − p)/p = 3.762, P(gap = 0) = 0.21, P(gap ≥ 10) = 0.79¹⁰.
        let p: f64 = 0.21;
        let g = GapSampler::new(p);
        let s = CounterStream::new(7, 2);
        let n = 200_000u64;
        let gaps: Vec<u32> = (0..n).map(|k| g.gap((s.word(k) >> 32) as u32)).collect();
        let mean = gaps.iter().map(|&x| f64::from(x)).sum::<f64>() / n as f64;
        let sd_of_mean = ((1.0 - p).sqrt() / p) / (n as f64).sqrt(); // 0.0095
        assert!((mean - 3.7619).abs() < 4.0 * sd_of_mean, "{mean}");
        let zero = gaps.iter().filter(|&&x| x == 0).count() as f64 / n as f64;
        assert!(
            (zero - 0.21).abs() < 4.0 * (0.21f64 * 0.79 / n as f64).sqrt(),
            "{zero}"
        );
        let ten = gaps.iter().filter(|&&x| x >= 10).count() as f64 / n as f64;
        let want = 0.79f64.powi(10); // 0.0947
        assert!(
            (ten - want).abs() < 4.0 * (want * (1.0 - want) / n as f64).sqrt(),
            "{ten}"
        );
        // P_B = 1: every layer holds a bubble.
        let all = GapSampler::new(1.0);
        assert!((0..1000).all(|k| all.gap((s.word(k) >> 32) as u32) == 0));
    }

    /// Every tier walks to the same layers as the walk by definition (gap after gap), for
    /// P_B from sparse-dense to 1, short and long walks, and streams that meet the buckets
    /// counted one by one.
    #[test]
    fn every_tier_walks_to_the_same_layers() {
        // The layers gap after gap, and whether a draw fell in the buckets near 0 that are
        // counted one by one (below 2²⁰).
        let by_definition = |gaps: &GapSampler, stream: CounterStream, j_end: u32| {
            let (mut j, mut out, mut near_0) = (0u32, Vec::new(), false);
            for n in 0u64.. {
                let w = stream.word(2 * (n / 2));
                let u = if n % 2 == 0 {
                    (w >> 32) as u32
                } else {
                    w as u32
                };
                near_0 |= u < 1 << 20;
                j += gaps.gap(u);
                if j >= j_end {
                    break;
                }
                out.push(f64::from(j));
                j += 1;
            }
            (out, near_0)
        };
        let mut counted_one_by_one = 0;
        // Groups of eight rays, each lane with its own stream and end (among them 0, a
        // block's edge, and a lane far longer than the others), the groups one after
        // another in the same buffers (so that a short group follows a long one).
        let ends = [0, 1, 15, 16, 17, 150, 1000, 2];
        let mut group = GroupWalk::default();
        for p in [0.021, 0.21, 0.5, 1.0] {
            let gaps = GapSampler::new(p);
            for g in 0..300u64 {
                let streams = std::array::from_fn(|l| CounterStream::new(42, 8 * g + l as u64));
                // Rotated per group: every lane meets every end.
                let j_end: [u32; GROUP_RAYS] =
                    std::array::from_fn(|l| ends[(l + g as usize) % ends.len()]);
                let want: [Vec<f64>; GROUP_RAYS] = std::array::from_fn(|l| {
                    let (want, near_0) = by_definition(&gaps, streams[l], j_end[l]);
                    counted_one_by_one += usize::from(near_0 && p < 1.0);
                    want
                });
                for tier in [Isa::Baseline, Isa::Avx2, Isa::Avx512] {
                    if tier > isa() {
                        continue;
                    }
                    with_isa(tier, || group.walk(streams, &gaps, j_end));
                    for (l, want) in want.iter().enumerate() {
                        let n = group.len(l);
                        assert_eq!(
                            group.column(l)[..n],
                            want[..],
                            "P_B {p}, group {g}, lane {l}, j_end {}, {tier:?}",
                            j_end[l]
                        );
                    }
                }
            }
        }
        assert!(counted_one_by_one > 10, "{counted_one_by_one}");
    }
}
