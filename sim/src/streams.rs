//! The random-stream layout (ARCHITECTURE.md, simulator conventions; sim/README decision 12):
//! every draw of the simulator comes from one of these streams, keyed by (seed, run) and a
//! stream id, so an accretion is a pure function of (seed, run) whatever the thread count.
//!
//! | stream | id | generator | draws |
//! |---|---|---|---|
//! | the sensor's fibre angles | `fibre_seed`, stream 1 | PCG32 | θ_f (Box–Muller), azimuth, once per sensor |
//! | accretion (seed, run) | `STREAM_ACCRETION` = 0 | PCG32 keyed by `accretion_key` | surface slopes δ_S,x, δ_S,y |
//! | bubbles of ray r, dense (rime) | `bubble_stream` = 2 + 2r | `CounterStream` | gap of bubble n from word 2⌊n/2⌋, its angles from word 2n + 1 |
//! | bubbles of ray r, sparse (glazed) | 2 + 2r | PCG32 | gap (`geometric_gap`), cos θ_B, azimuth by rejection |
//! | diffuse angles of ray r | `diffuse_stream` = 3 + 2r | PCG32, filled in blocks (`fill_u32`) | one δ_R per thickness |
//!
//! PCG32 is `rand_pcg::Pcg32` (XSH RR 64/32); `fill_u32` produces exactly its outputs four
//! at a time. The hardware-in-loop suite's lossy link draws from [`SplitMix64`].

use rand_core::Rng;
use rand_pcg::Pcg32;

/// Increment of the SplitMix64 sequence (2⁶⁴/φ, odd).
pub(crate) const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// 2⁻³²: a 32-bit draw to [0, 1).
pub(crate) const INV_2_POW_32: f64 = 1.0 / 4_294_967_296.0;

/// Stream id of the accretion's own draws (the surface slopes).
pub(crate) const STREAM_ACCRETION: u64 = 0;

/// Stream id of ray r's bubbles.
#[inline]
pub(crate) fn bubble_stream(ray: usize) -> u64 {
    2 + 2 * ray as u64
}

/// Stream id of ray r's diffuse angles.
#[inline]
pub(crate) fn diffuse_stream(ray: usize) -> u64 {
    3 + 2 * ray as u64
}

/// The multipliers of the SplitMix64 finaliser, in order.
pub(crate) const MIX64_MULTIPLIERS: [u64; 2] = [0xBF58_476D_1CE4_E5B9, 0x94D0_49BB_1331_11EB];

/// SplitMix64 finaliser (Steele, Lea & Flood, "Fast splittable pseudorandom number
/// generators", OOPSLA 2014), one step included: spreads a seed into a generator state.
#[inline(always)]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(GOLDEN_GAMMA);
    z = (z ^ (z >> 30)).wrapping_mul(MIX64_MULTIPLIERS[0]);
    z = (z ^ (z >> 27)).wrapping_mul(MIX64_MULTIPLIERS[1]);
    z ^ (z >> 31)
}

/// The PCG state of accretion `run` of `seed`.
#[inline]
pub(crate) fn accretion_key(seed: u64, run: u64) -> u64 {
    mix64(mix64(seed) ^ run.wrapping_mul(0xD6E8_FEB8_6659_FD93))
}

/// SplitMix64 as a sequential generator: output n is [`mix64`] of seed + n·γ.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// The generator started at `seed`.
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// The next 64 bits.
    pub fn next_u64(&mut self) -> u64 {
        let z = mix64(self.0);
        self.0 = self.0.wrapping_add(GOLDEN_GAMMA);
        z
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A counter-based random stream: word n is the SplitMix64 output n + 1 steps after the
/// stream's start, i.e. a pure function of (start, n). Any word can be computed without
/// the ones before it, in any order, in vector lanes.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct CounterStream {
    start: u64,
}

impl CounterStream {
    /// The stream `id` of the accretion with PCG key `key`.
    pub(crate) fn new(key: u64, id: u64) -> Self {
        CounterStream {
            start: mix64(key ^ mix64(id)),
        }
    }

    /// Word n of the stream: [`mix64`] of its counter.
    #[inline(always)]
    pub(crate) fn word(self, n: u64) -> u64 {
        mix64(self.counter(n))
    }

    /// The counter of word n, start + n·γ.
    #[inline(always)]
    pub(crate) fn counter(self, n: u64) -> u64 {
        self.start.wrapping_add(n.wrapping_mul(GOLDEN_GAMMA))
    }
}

/// Uniform f64 in [0, 1) with 53 bits (one 64-bit PCG output).
#[inline]
pub(crate) fn uniform(rng: &mut Pcg32) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Uniform in (0, 1].
#[inline]
pub(crate) fn uniform_open0(rng: &mut Pcg32) -> f64 {
    1.0 - uniform(rng)
}

/// Uniform in [0, 1) with 32 random bits (one PCG output): enough for angles and positions.
#[inline]
pub(crate) fn uniform32(rng: &mut Pcg32) -> f64 {
    rng.next_u32() as f64 * INV_2_POW_32
}

/// Standard normal by Box–Muller.
pub(crate) fn std_normal(rng: &mut Pcg32) -> f64 {
    let u1 = uniform_open0(rng);
    let u2 = uniform(rng);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Geometric number of failures before the first success, ln_q = ln(1 − P(success)).
#[inline]
pub(crate) fn geometric_gap(rng: &mut Pcg32, ln_q: f64) -> u32 {
    if ln_q == f64::NEG_INFINITY {
        return 0;
    }
    let g = (uniform_open0(rng).ln() / ln_q).floor();
    if g >= (u32::MAX / 2) as f64 {
        u32::MAX / 2
    } else {
        g as u32
    }
}

/// The draws of a uniform point on the unit circle by rejection: (a, b, q = a² + b²) with
/// 0 < q ≤ 1; the point is (a, b)/√q.
#[inline]
pub(crate) fn unit_circle_unnormalised(rng: &mut Pcg32) -> (f64, f64, f64) {
    loop {
        let a = 2.0 * uniform32(rng) - 1.0;
        let b = 2.0 * uniform32(rng) - 1.0;
        let q = a * a + b * b;
        if q > 1e-12 && q <= 1.0 {
            return (a, b, q);
        }
    }
}

/// The LCG multiplier of PCG32 (`rand_pcg`).
const PCG_MULTIPLIER: u64 = 6_364_136_223_846_793_005;

/// PCG32's output permutation (XSH RR) of a state.
#[inline(always)]
fn pcg_output(state: u64) -> u32 {
    let rot = (state >> 59) as u32;
    let xsh = (((state >> 18) ^ state) >> 27) as u32;
    xsh.rotate_right(rot)
}

/// Interleaved copies of the LCG in [`fill_u32`]: two AVX-512 vectors of 64-bit lanes
/// (one vector's multiply-add chain waits on its multiply's latency).
const PCG_LANES: usize = 16;

/// The LCG stepped k times is x ↦ Mᵏ·x + inc·Gₖ with Gₖ = 1 + M + … + Mᵏ⁻¹ (M the
/// multiplier): (Mᵏ, Gₖ) for k = 0 … `PCG_LANES`, independent of the stream's increment.
const PCG_JUMPS: [(u64, u64); PCG_LANES + 1] = {
    let mut t = [(1u64, 0u64); PCG_LANES + 1];
    let mut k = 1;
    while k <= PCG_LANES {
        let (m, g) = t[k - 1];
        t[k] = (
            m.wrapping_mul(PCG_MULTIPLIER),
            g.wrapping_mul(PCG_MULTIPLIER).wrapping_add(1),
        );
        k += 1;
    }
    t
};

crate::kernels::vector_kernel! {
/// The first `out.len()` outputs of `Pcg32::new(state, stream)`, exactly, sixteen at a
/// time: sixteen interleaved copies of the LCG, each stepping by sixteen, so the steps do
/// not wait on each other (one 64-bit multiply-add chain per output otherwise bounds the
/// loop); with AVX-512 the sixteen are two vectors.
pub(crate) fn fill_u32(state: u64, stream: u64, out: &mut [u32]) {
    let inc = (stream << 1) | 1;
    // Pcg32::new: state + inc, one step; the first output is of the state after that.
    let s0 = state
        .wrapping_add(inc)
        .wrapping_mul(PCG_MULTIPLIER)
        .wrapping_add(inc);
    let mut lanes = [0u64; PCG_LANES];
    for (s, &(m, g)) in lanes.iter_mut().zip(&PCG_JUMPS) {
        *s = s0.wrapping_mul(m).wrapping_add(inc.wrapping_mul(g));
    }
    let (m16, g16) = PCG_JUMPS[PCG_LANES];
    let c16 = inc.wrapping_mul(g16);
    let mut chunks = out.chunks_exact_mut(PCG_LANES);
    for chunk in &mut chunks {
        for (o, s) in chunk.iter_mut().zip(lanes.iter_mut()) {
            *o = pcg_output(*s);
            *s = s.wrapping_mul(m16).wrapping_add(c16);
        }
    }
    for (o, s) in chunks.into_remainder().iter_mut().zip(lanes) {
        *o = pcg_output(s);
    }
}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_u32_is_pcg32_exactly() {
        for (state, stream) in [
            (0, 0),
            (1, 3),
            (u64::MAX, 5),
            (0x1234_5678_9ABC_DEF0, 2 * 2553 + 1),
        ] {
            for n in [0, 1, 3, 4, 5, 150, 151, 1000] {
                let mut rng = Pcg32::new(state, stream);
                let want: Vec<u32> = (0..n).map(|_| rng.next_u32()).collect();
                let mut got = vec![0; n];
                fill_u32(state, stream, &mut got);
                assert_eq!(got, want, "state {state}, stream {stream}, n {n}");
            }
        }
    }

    #[test]
    fn split_mix_is_the_counter_stream_read_in_order() {
        let mut g = SplitMix64::new(77);
        for n in 0..20u64 {
            assert_eq!(
                g.next_u64(),
                mix64(77u64.wrapping_add(n.wrapping_mul(GOLDEN_GAMMA)))
            );
        }
        // Reference value of SplitMix64 seeded with 0 (Vigna's splitmix64.c).
        assert_eq!(SplitMix64::new(0).next_u64(), 0xE220_A839_7B1D_CDAF);
        let mean = (0..100_000).map(|_| g.uniform()).sum::<f64>() / 100_000.0;
        assert!((mean - 0.5).abs() < 4.0 * (1.0f64 / 12.0 / 100_000.0).sqrt());
    }

    #[test]
    fn counter_stream_is_a_pure_function_of_its_counter() {
        let s = CounterStream::new(123, 4);
        let forward: Vec<u64> = (0..50).map(|n| s.word(n)).collect();
        let backward: Vec<u64> = (0..50).rev().map(|n| s.word(n)).collect();
        assert!(forward.iter().eq(backward.iter().rev()));
        // Word n is SplitMix64's output after n + 1 steps from the start (mix64 adds the
        // first step), and no two words repeat.
        let mut state = s.start;
        for &w in &forward {
            assert_eq!(w, mix64(state));
            state = state.wrapping_add(GOLDEN_GAMMA);
        }
        let mut sorted = forward.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), forward.len());
        // Different streams and keys differ.
        assert_ne!(CounterStream::new(123, 5).word(0), s.word(0));
        assert_ne!(CounterStream::new(124, 4).word(0), s.word(0));
        // Bits are balanced: mean of the upper 32 bits as a uniform.
        let n = 100_000u64;
        let mean = (0..n)
            .map(|k| (s.word(k) >> 32) as f64 * INV_2_POW_32)
            .sum::<f64>()
            / n as f64;
        assert!(
            (mean - 0.5).abs() < 4.0 * (1.0 / 12.0 / n as f64).sqrt(),
            "{mean}"
        );
    }

    #[test]
    fn geometric_gap_has_mean_q_over_p() {
        let p: f64 = 0.0015;
        let ln_q = (1.0 - p).ln();
        let mut rng = Pcg32::new(1, 1);
        let n = 20_000;
        let mean = (0..n)
            .map(|_| geometric_gap(&mut rng, ln_q) as f64)
            .sum::<f64>()
            / n as f64;
        let want = (1.0 - p) / p; // 665.7
        assert!((mean - want).abs() < 0.03 * want, "{mean}");
    }

    #[test]
    fn unit_circle_is_uniform_and_unit() {
        let mut rng = Pcg32::new(2, 3);
        let mut quad = [0usize; 4];
        for _ in 0..40_000 {
            let (a, b, q) = unit_circle_unnormalised(&mut rng);
            let s = q.sqrt().recip();
            let (c, s) = (a * s, b * s);
            assert!((c * c + s * s - 1.0).abs() < 1e-12);
            quad[(c < 0.0) as usize * 2 + (s < 0.0) as usize] += 1;
        }
        for q in quad {
            assert!((q as f64 - 10_000.0).abs() < 400.0, "{quad:?}");
        }
    }
}
