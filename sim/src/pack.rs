//! The landed lanes of the glazed path packed (`diffuse::reflect_diffuse`, between its
//! two passes), so that the second pass runs on whole vectors: compress instructions with
//! AVX-512, a table of permutations with AVX2, a branchless loop otherwise; all three
//! write the same values (tested).

/// The lanes whose `slot` is below 2, packed: their numbers into `landed`, and from
/// `inputs` (cosine, direction z, path) the cosine, −direction z and path into `packed`.
/// Returns how many. With AVX-512 eight lanes at a time by compress instructions, with AVX2 four
/// at a time by a table of permutations, else one by one without a branch: every lane is
/// written at the count, which moves on for the landed ones only. All write the same values
/// below the count; the entries of `landed` and `packed` from the count up to `slot.len()`
/// are scratch (whole vectors are stored), for the caller to overwrite.
pub(crate) fn pack_landed(
    slot: &[u64],
    inputs: [&[f64]; 3],
    landed: &mut [u32],
    packed: [&mut [f64]; 3],
) -> usize {
    let n = slot.len();
    assert!(inputs.iter().all(|x| x.len() >= n) && landed.len() >= n);
    assert!(packed.iter().all(|x| x.len() >= n));
    #[cfg(target_arch = "x86_64")]
    match crate::kernels::isa() {
        // SAFETY: the CPU has AVX-512 F, DQ and VL (`isa`); every slice holds n lanes.
        crate::kernels::Isa::Avx512 => {
            return unsafe { pack_landed_avx512(slot, inputs, landed, packed) };
        }
        // SAFETY: the CPU has AVX2 (`isa`); every slice holds n lanes.
        crate::kernels::Isa::Avx2 => {
            return unsafe { pack_landed_avx2(slot, inputs, landed, packed) };
        }
        crate::kernels::Isa::Baseline => {}
    }
    pack_from(0, 0, slot, inputs, landed, packed)
}

/// The lanes from `k` on packed one by one after the `m` packed before them (m ≤ k), without
/// a branch: every lane is written at the count, which moves on for the landed ones only.
/// Returns the new count. The caller checked that every slice holds `slot.len()` lanes.
#[inline(always)]
fn pack_from(
    mut k: usize,
    mut m: usize,
    slot: &[u64],
    inputs: [&[f64]; 3],
    landed: &mut [u32],
    packed: [&mut [f64]; 3],
) -> usize {
    let [cos_f, dir_z, path] = inputs;
    let [cos_p, rdz_p, path_p] = packed;
    while let Some(&s) = slot.get(k) {
        // SAFETY: m ≤ k < n, within every slice (checked by the caller).
        unsafe {
            *landed.get_unchecked_mut(m) = k as u32;
            *cos_p.get_unchecked_mut(m) = *cos_f.get_unchecked(k);
            *rdz_p.get_unchecked_mut(m) = -*dir_z.get_unchecked(k);
            *path_p.get_unchecked_mut(m) = *path.get_unchecked(k);
        }
        m += usize::from(s < 2);
        k += 1;
    }
    m
}

/// [`pack_landed`] by compress instructions, eight lanes at a time: compressed in a
/// register, then stored whole (a compress straight to memory is microcoded and slow on
/// some CPUs, e.g. AMD Zen 4); the lanes beyond the count are overwritten by the next store
/// or left stale.
///
/// # Safety
/// The CPU has AVX-512 F and VL; `inputs`, `landed` and `packed` hold at least `slot.len()`
/// lanes each.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2,fma")]
unsafe fn pack_landed_avx512(
    slot: &[u64],
    inputs: [&[f64]; 3],
    landed: &mut [u32],
    packed: [&mut [f64]; 3],
) -> usize {
    use std::arch::x86_64::*;
    let n = slot.len();
    let [cos_f, dir_z, path] = inputs;
    let [cos_p, rdz_p, path_p] = packed;
    let two = _mm512_set1_epi64(2);
    let sign = _mm512_set1_pd(-0.0);
    let mut lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    let eight = _mm256_set1_epi32(8);
    let mut m = 0;
    let mut k = 0;
    while k + 8 <= n {
        // SAFETY: k + 8 ≤ n lanes are read from every input; m ≤ k, so the 8 lanes written
        // from m lie within n.
        unsafe {
            let s = _mm512_loadu_si512(slot.as_ptr().add(k).cast());
            let hit = _mm512_cmplt_epu64_mask(s, two);
            let kept = _mm256_maskz_compress_epi32(hit, lane);
            _mm256_storeu_si256(landed.as_mut_ptr().add(m).cast(), kept);
            let c = _mm512_loadu_pd(cos_f.as_ptr().add(k));
            _mm512_storeu_pd(cos_p.as_mut_ptr().add(m), _mm512_maskz_compress_pd(hit, c));
            let z = _mm512_xor_pd(_mm512_loadu_pd(dir_z.as_ptr().add(k)), sign);
            _mm512_storeu_pd(rdz_p.as_mut_ptr().add(m), _mm512_maskz_compress_pd(hit, z));
            let p = _mm512_loadu_pd(path.as_ptr().add(k));
            _mm512_storeu_pd(path_p.as_mut_ptr().add(m), _mm512_maskz_compress_pd(hit, p));
            m += hit.count_ones() as usize;
        }
        lane = _mm256_add_epi32(lane, eight);
        k += 8;
    }
    pack_from(
        k,
        m,
        slot,
        [cos_f, dir_z, path],
        landed,
        [cos_p, rdz_p, path_p],
    )
}

/// For each 4-bit mask of landed lanes, the permutation that moves them to the front, as
/// pairs of 32-bit lanes (one f64 each) for `_mm256_permutevar8x32_ps`.
const PACK4_F64: [[i32; 8]; 16] = {
    let mut t = [[0i32; 8]; 16];
    let mut mask = 0;
    while mask < 16 {
        let (mut out, mut lane) = (0, 0);
        while lane < 4 {
            if mask & (1 << lane) != 0 {
                t[mask][2 * out] = 2 * lane;
                t[mask][2 * out + 1] = 2 * lane + 1;
                out += 1;
            }
            lane += 1;
        }
        mask += 1;
    }
    t
};

/// [`pack_landed`] by a permutation table, four lanes at a time.
///
/// # Safety
/// The CPU has AVX2; `inputs`, `landed` and `packed` hold at least `slot.len()` lanes each.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn pack_landed_avx2(
    slot: &[u64],
    inputs: [&[f64]; 3],
    landed: &mut [u32],
    packed: [&mut [f64]; 3],
) -> usize {
    use std::arch::x86_64::*;
    let n = slot.len();
    let [cos_f, dir_z, path] = inputs;
    let [cos_p, rdz_p, path_p] = packed;
    let two = _mm256_set1_epi64x(2);
    let sign = _mm256_set1_pd(-0.0);
    let mut m = 0;
    let mut k = 0;
    while k + 4 <= n {
        // SAFETY: k + 4 ≤ n lanes are read from every input; m ≤ k, so the 4 lanes written
        // from m lie within n.
        unsafe {
            let s = _mm256_loadu_si256(slot.as_ptr().add(k).cast());
            // The slots are 0, 1 or 2: a signed comparison is exact.
            let hit = _mm256_movemask_pd(_mm256_castsi256_pd(_mm256_cmpgt_epi64(two, s))) as usize;
            let perm = _mm256_loadu_si256(PACK4_F64[hit].as_ptr().cast());
            let pack =
                |v: __m256d| _mm256_castps_pd(_mm256_permutevar8x32_ps(_mm256_castpd_ps(v), perm));
            _mm256_storeu_pd(
                cos_p.as_mut_ptr().add(m),
                pack(_mm256_loadu_pd(cos_f.as_ptr().add(k))),
            );
            let z = _mm256_xor_pd(_mm256_loadu_pd(dir_z.as_ptr().add(k)), sign);
            _mm256_storeu_pd(rdz_p.as_mut_ptr().add(m), pack(z));
            _mm256_storeu_pd(
                path_p.as_mut_ptr().add(m),
                pack(_mm256_loadu_pd(path.as_ptr().add(k))),
            );
            // The lane numbers: the even 32-bit entries of the table, halved, plus k.
            let lanes = _mm256_add_epi32(_mm256_srli_epi32::<1>(perm), _mm256_set1_epi32(k as i32));
            let even =
                _mm256_permutevar8x32_epi32(lanes, _mm256_setr_epi32(0, 2, 4, 6, 0, 2, 4, 6));
            _mm_storeu_si128(
                landed.as_mut_ptr().add(m).cast(),
                _mm256_castsi256_si128(even),
            );
            m += hit.count_ones() as usize;
        }
        k += 4;
    }
    pack_from(
        k,
        m,
        slot,
        [cos_f, dir_z, path],
        landed,
        [cos_p, rdz_p, path_p],
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::{Isa, isa, with_isa};

    /// Every tier this CPU runs packs the same lanes as the branchless loop, for every
    /// pattern of landed lanes and lengths that leave a remainder.
    #[test]
    fn every_tier_packs_the_same_lanes() {
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut next = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for len in [0usize, 1, 3, 4, 5, 8, 9, 15, 16, 17, 63, 151] {
            for _ in 0..20 {
                let slot: Vec<u64> = (0..len).map(|_| next() % 3).collect();
                let inputs: [Vec<f64>; 3] = std::array::from_fn(|_| {
                    (0..len).map(|_| next() as f64 * 1e-19 - 0.9).collect()
                });
                let run = |tier: Isa| {
                    with_isa(tier, || {
                        let mut landed = vec![u32::MAX; len];
                        let mut packed: [Vec<f64>; 3] =
                            std::array::from_fn(|_| vec![f64::NAN; len]);
                        let [a, b, c] = &mut packed;
                        let m = pack_landed(
                            &slot,
                            [&inputs[0], &inputs[1], &inputs[2]],
                            &mut landed,
                            [a, b, c],
                        );
                        landed.truncate(m);
                        let bits =
                            packed.map(|p| p[..m].iter().map(|v| v.to_bits()).collect::<Vec<_>>());
                        (landed, bits)
                    })
                };
                let want = run(Isa::Baseline);
                let count = slot.iter().filter(|&&s| s < 2).count();
                assert_eq!(want.0.len(), count);
                assert!(want.0.iter().all(|&k| slot[k as usize] < 2));
                assert!(
                    want.1[1]
                        .iter()
                        .zip(&want.0)
                        .all(|(&z, &k)| f64::from_bits(z) == -inputs[1][k as usize])
                );
                for tier in [Isa::Avx2, Isa::Avx512] {
                    if tier <= isa() {
                        assert_eq!(run(tier), want, "{tier:?}, {len} lanes");
                    }
                }
            }
        }
    }
}
