//! The rime walk of one ray (thesis §3.2.2–§3.2.3): where along the ray its bubbles lie.
//! Every layer of Δ_Ice holds a bubble with probability P_B, independently, so the numbers
//! of empty layers between bubbles are geometric: one draw per bubble ([`GapSampler`]), not
//! one per layer. The gap before bubble n is drawn from word 2⌊n/2⌋ of the ray's
//! counter-based stream (its upper 32 bits for even n, its lower 32 bits for odd n; the
//! layout is in bubbles.rs), so the gaps of many bubbles can be drawn at once: with AVX-512
//! sixteen at a time, their layers by a prefix sum ([`walk_layers`]); otherwise one by one.
//! Both find the same layers (integers: exact on every tier; tested).

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

/// Bubbles one step of the vectorised walk finds at most; the walk may write this many
/// layers beyond the last bubble.
pub(crate) const WALK_BLOCK: usize = 16;

/// The layers j < `j_end` that hold a bubble along one ray, in order, as f64 (exactly) into
/// `layer`, which has room for `j_end` + [`WALK_BLOCK`] entries (those beyond the count are
/// overwritten freely). Returns the number of bubbles.
pub(crate) fn walk_layers(
    stream: CounterStream,
    gaps: &GapSampler,
    j_end: u32,
    layer: &mut [f64],
) -> usize {
    assert!(layer.len() >= j_end as usize + WALK_BLOCK);
    #[cfg(target_arch = "x86_64")]
    if crate::kernels::isa() == crate::kernels::Isa::Avx512 {
        // SAFETY: the CPU has AVX-512 F and DQ (`isa`); `layer` has room checked above.
        return unsafe { walk_avx512(stream, gaps, j_end, layer) };
    }
    walk_scalar(stream, gaps, j_end, layer)
}

/// [`walk_layers`] one bubble at a time.
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
            // SAFETY: every bubble takes a layer of its own, so n ≤ j < j_end < len
            // (checked by the caller).
            unsafe { *layer.get_unchecked_mut(n) = f64::from(j) };
            j += 1;
            n += 1;
        }
    }
    n
}

/// [`walk_layers`] sixteen bubbles at a time: eight words hashed at once, their sixteen
/// draws turned into gaps by two gathers from the bucket table (a bucket that straddles
/// several thresholds is counted one by one), the layers by a prefix sum of gap + 1, and
/// the bubbles below `j_end` (a prefix of the sixteen: the layers grow) counted.
///
/// # Safety
/// The CPU has AVX-512 F and DQ; `layer` has room for `j_end` + 16 entries.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2,fma")]
unsafe fn walk_avx512(
    stream: CounterStream,
    gaps: &GapSampler,
    j_end: u32,
    layer: &mut [f64],
) -> usize {
    use crate::streams::{GOLDEN_GAMMA, MIX64_MULTIPLIERS};
    use std::arch::x86_64::*;
    let splat64 = |x: u64| _mm512_set1_epi64(x as i64);
    let [mul_a, mul_b] = MIX64_MULTIPLIERS.map(splat64);
    let gamma = splat64(GOLDEN_GAMMA);
    // The counters of words 0, 2, …, 14, then 16 words on per step.
    let even = _mm512_setr_epi64(0, 2, 4, 6, 8, 10, 12, 14);
    let mut counter = _mm512_add_epi64(splat64(stream.counter(0)), _mm512_mullo_epi64(even, gamma));
    let step = splat64(16u64.wrapping_mul(GOLDEN_GAMMA));
    // The halves of eight 64-bit bucket entries as sixteen 32-bit lanes, in bubble order.
    let upper = _mm512_setr_epi32(1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31);
    let lower = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
    let (zero, one) = (_mm512_setzero_si512(), _mm512_set1_epi32(1));
    let many = _mm512_set1_epi32(-1); // the upper half of `MANY`
    let end = _mm512_set1_epi32(j_end as i32);
    let bucket = gaps.bucket.as_ptr().cast::<i64>();
    // The layer before which the next gap starts, and the bubbles found.
    let mut j0: u32 = 0;
    let mut n: usize = 0;
    loop {
        // SplitMix64 of the eight counters (`streams::mix64`).
        let mut z = _mm512_add_epi64(counter, gamma);
        z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64::<30>(z)), mul_a);
        z = _mm512_mullo_epi64(_mm512_xor_si512(z, _mm512_srli_epi64::<27>(z)), mul_b);
        z = _mm512_xor_si512(z, _mm512_srli_epi64::<31>(z));
        counter = _mm512_add_epi64(counter, step);
        // Sixteen draws in bubble order: each word's upper half, then its lower half.
        let u = _mm512_shuffle_epi32::<0xB1>(z);
        let index = _mm512_srli_epi32::<{ 32 - GAP_BUCKET_BITS }>(u);
        // SAFETY: the indices are below 2^GAP_BUCKET_BITS, the table's length.
        let (entries_a, entries_b) = unsafe {
            (
                _mm512_i32gather_epi64::<8>(_mm512_castsi512_si256(index), bucket),
                _mm512_i32gather_epi64::<8>(_mm512_extracti64x4_epi64::<1>(index), bucket),
            )
        };
        let least = _mm512_permutex2var_epi32(entries_a, upper, entries_b);
        let below = _mm512_permutex2var_epi32(entries_a, lower, entries_b);
        let gap = if _mm512_cmpeq_epi32_mask(least, many) == 0 {
            // `GapSampler::gap`: the bucket's least gap, one more below its threshold.
            _mm512_mask_add_epi32(least, _mm512_cmplt_epu32_mask(u, below), least, one)
        } else {
            let mut draws = [0u32; WALK_BLOCK];
            // SAFETY: sixteen u32 are stored into and loaded from the array.
            unsafe {
                _mm512_storeu_si512(draws.as_mut_ptr().cast(), u);
                let gap = draws.map(|u| gaps.gap(u));
                _mm512_loadu_si512(gap.as_ptr().cast())
            }
        };
        // The layer of each bubble: j0 + (the sum of gap + 1 up to it) − 1. No overflow: j0
        // < j_end ≤ 20 000, and sixteen gaps are below 16 × 1100.
        let mut sum = _mm512_add_epi32(gap, one);
        sum = _mm512_add_epi32(sum, _mm512_alignr_epi32::<15>(sum, zero));
        sum = _mm512_add_epi32(sum, _mm512_alignr_epi32::<14>(sum, zero));
        sum = _mm512_add_epi32(sum, _mm512_alignr_epi32::<12>(sum, zero));
        sum = _mm512_add_epi32(sum, _mm512_alignr_epi32::<8>(sum, zero));
        let layers = _mm512_add_epi32(sum, _mm512_set1_epi32(j0.wrapping_sub(1) as i32));
        let found = _mm512_cmplt_epu32_mask(layers, end).count_ones() as usize;
        // SAFETY: n ≤ j_end (each bubble below j_end has a layer of its own), so the sixteen
        // entries from n lie within the room the caller checked.
        unsafe {
            let out = layer.as_mut_ptr().add(n);
            _mm512_storeu_pd(out, _mm512_cvtepu32_pd(_mm512_castsi512_si256(layers)));
            let upper_half = _mm512_extracti64x4_epi64::<1>(layers);
            _mm512_storeu_pd(out.add(8), _mm512_cvtepu32_pd(upper_half));
        }
        n += found;
        if found < WALK_BLOCK {
            return n;
        }
        let last = _mm512_extracti32x4_epi32::<3>(sum);
        j0 = j0.wrapping_add(_mm_extract_epi32::<3>(last) as u32);
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
        for p in [0.021, 0.21, 0.5, 1.0] {
            let gaps = GapSampler::new(p);
            for id in 0..300 {
                let stream = CounterStream::new(42, id);
                for j_end in [0, 1, 15, 16, 17, 150, 1000] {
                    let (want, near_0) = by_definition(&gaps, stream, j_end);
                    counted_one_by_one += usize::from(near_0 && p < 1.0);
                    for tier in [Isa::Baseline, Isa::Avx2, Isa::Avx512] {
                        if tier > isa() {
                            continue;
                        }
                        let mut layer = vec![f64::NAN; j_end as usize + WALK_BLOCK];
                        let n = with_isa(tier, || walk_layers(stream, &gaps, j_end, &mut layer));
                        assert_eq!(
                            layer[..n],
                            want[..],
                            "P_B {p}, stream {id}, j_end {j_end}, {tier:?}"
                        );
                    }
                }
            }
        }
        assert!(counted_one_by_one > 10, "{counted_one_by_one}");
    }
}
