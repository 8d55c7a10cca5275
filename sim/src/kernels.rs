//! The tracer's arithmetic over many lanes at once (thicknesses of one ray, or its bubbles),
//! written as loops over slices that the compiler vectorises, and the tiers they are compiled
//! for ([`Isa`]: eight f64 lanes with AVX-512, four with AVX2, two with the SSE2 of every
//! x86-64; picked at run time). Each lane performs the same IEEE-754 operations in the same
//! order as the scalar formula (Rust never fuses a multiply and an add on its own), so the
//! results are bit-identical on every tier; the golden-value tests of the crate check this.
//! Here too: the one-division Fresnel factor and the polynomial `exp` that the kernels use,
//! and the lane padding ([`LANES`]).

/// The instruction sets the vectorised kernels are compiled for. Every tier runs the same
/// IEEE-754 operations in the same order per lane, so the results are bit-identical on all
/// of them (the golden-value tests and the kernels' own tests check this); only the speed
/// differs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Isa {
    /// The target's baseline (SSE2 on x86-64): two f64 lanes.
    Baseline,
    /// AVX2 and FMA: four f64 lanes.
    Avx2,
    /// AVX-512 (F, DQ, VL) with FMA: eight f64 lanes, 64-bit integer multiplies in vectors
    /// (the counter-based streams' hashes and the PCG draws).
    Avx512,
}

impl Isa {
    /// Name as the environment variable `FOIS_SIM_ISA` and `foisctl sim bench` spell it.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Baseline => "baseline",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }

    /// The best tier this CPU runs.
    fn detected() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx512f") && has!("avx512dq") && has!("avx512vl") && has!("fma") {
                return Isa::Avx512;
            }
            if has!("avx2") && has!("fma") {
                return Isa::Avx2;
            }
        }
        Isa::Baseline
    }
}

/// The tier the kernels run on: the best this CPU has, capped by the environment variable
/// `FOIS_SIM_ISA` (`baseline`, `avx2` or `avx512`; to measure one tier against another) and,
/// on the calling thread, by [`with_isa`]. Detected once per process.
pub fn isa() -> Isa {
    static GLOBAL: std::sync::OnceLock<Isa> = std::sync::OnceLock::new();
    let global = *GLOBAL.get_or_init(|| {
        let best = Isa::detected();
        let cap = match std::env::var("FOIS_SIM_ISA").as_deref() {
            Ok("baseline") => Isa::Baseline,
            Ok("avx2") => Isa::Avx2,
            Ok("avx512") | Ok("") | Err(_) => Isa::Avx512,
            Ok(other) => {
                eprintln!(
                    "FOIS_SIM_ISA={other}: not one of avx512, avx2, baseline; ignored \
                     (the kernels run on {})",
                    best.name()
                );
                Isa::Avx512
            }
        };
        best.min(cap)
    });
    THREAD_CAP
        .with(|c| c.get())
        .map_or(global, |cap| global.min(cap))
}

thread_local! {
    static THREAD_CAP: std::cell::Cell<Option<Isa>> = const { std::cell::Cell::new(None) };
}

/// Run `f` with the kernels of this thread capped at `cap` (tests compare the tiers).
pub fn with_isa<R>(cap: Isa, f: impl FnOnce() -> R) -> R {
    let before = THREAD_CAP.with(|c| c.replace(Some(cap)));
    let out = f();
    THREAD_CAP.with(|c| c.set(before));
    out
}

/// A kernel compiled three times: for AVX-512 and for AVX2 with FMA when the CPU has them
/// ([`isa`], checked at run time) and for the baseline x86-64 (or any other target). All
/// run the same body, so the results are bit-identical (an explicit `mul_add` is exactly
/// rounded either way, one instruction with FMA and a libm call without; the compiler never
/// fuses a multiply and an add on its own).
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
            $(#[$meta])*
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2,fma")]
            fn kernel_avx512($($arg: $ty),*) {
                kernel_body($($arg),*)
            }
            #[cfg(target_arch = "x86_64")]
            match $crate::kernels::isa() {
                // SAFETY: `isa` reports a tier only when the CPU has its features.
                $crate::kernels::Isa::Avx512 => return unsafe { kernel_avx512($($arg),*) },
                // SAFETY: as above.
                $crate::kernels::Isa::Avx2 => return unsafe { kernel_avx2($($arg),*) },
                $crate::kernels::Isa::Baseline => {}
            }
            kernel_body($($arg),*)
        }
    };
}
pub(crate) use vector_kernel;

/// The kernels' arrays are padded to a multiple of this many lanes (one AVX-512 vector of
/// f64, two of AVX2), so that no lane is left to a scalar remainder loop: there a lane's
/// polynomials would run one dependent operation after another. The padding lanes compute
/// values that are never read.
pub(crate) const LANES: usize = 8;

/// Marks a loop over whole vectors whose body, unrolled over the lanes, is to become one
/// vector operation per step: an empty `asm!` keeps the compiler from vectorising across
/// the steps (it did, with gathers and scatters) or unrolling them into wider steps that
/// leave a remainder to narrower loops, and costs nothing. (On targets without the x86-64
/// tiers it does nothing: `asm!` is not on every target.)
#[inline(always)]
pub(crate) fn one_vector_at_a_time() {
    // SAFETY: an empty instruction sequence.
    #[cfg(target_arch = "x86_64")]
    unsafe {
        std::arch::asm!("", options(nomem, nostack, preserves_flags))
    };
}

/// `v` at least `n` long, filled with `fill` where it grows. The kernels' buffers only grow:
/// a ray uses their first lanes, so no fill runs per ray.
#[inline(always)]
pub(crate) fn grow<T: Clone>(v: &mut Vec<T>, n: usize, fill: T) {
    if v.len() < n {
        v.resize(n, fill);
    }
}

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

/// sin and cos of a small angle (|x| ≤ 0.53 rad, i.e. δ_R/2 ≤ 30°) by Taylor series to x¹¹
/// and x¹² in Horner form with the reciprocal factorials and fused multiply-adds (exactly
/// rounded on every CPU, see [`vector_kernel`]): error below 1e-13, without a libm call or a
/// division.
#[inline(always)]
pub(crate) fn small_sin_cos(x: f64) -> (f64, f64) {
    debug_assert!(x.abs() <= 0.53);
    const SIN: [f64; 5] = [
        1.0 / 362_880.0,
        -1.0 / 5_040.0,
        1.0 / 120.0,
        -1.0 / 6.0,
        1.0,
    ];
    const COS: [f64; 6] = [
        -1.0 / 3_628_800.0,
        1.0 / 40_320.0,
        -1.0 / 720.0,
        1.0 / 24.0,
        -0.5,
        1.0,
    ];
    let x2 = x * x;
    let mut s: f64 = -1.0 / 39_916_800.0;
    for k in SIN {
        s = s.mul_add(x2, k);
    }
    let mut c: f64 = 1.0 / 479_001_600.0;
    for k in COS {
        c = c.mul_add(x2, k);
    }
    (x * s, c)
}

/// The Fresnel reflectance of one interface (`laws::fr_dielectric`, eqs. 3.8, 3.9, 3.12) with
/// one division instead of two: R = ½ (r_⊥² + r_∥²) over the common denominator. Agrees with
/// `fr_dielectric` to rounding (tested).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Fresnel {
    n_i: f64,
    n_t: f64,
    eta2: f64,
}

impl Fresnel {
    #[inline(always)]
    pub(crate) fn new(n_i: f64, n_t: f64) -> Self {
        let eta = n_i / n_t;
        Fresnel {
            n_i,
            n_t,
            eta2: eta * eta,
        }
    }

    /// Reflectance for the angle of incidence whose cosine is `cos_i`; 1 on total internal
    /// reflection.
    #[inline(always)]
    pub(crate) fn reflectance(self, cos_i: f64) -> f64 {
        let cos_i = cos_i.clamp(0.0, 1.0);
        let sin2_t = self.eta2 * (1.0 - cos_i * cos_i);
        let total = sin2_t >= 1.0;
        let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
        // r_⊥ = (a − b)/(a + b), r_∥ = (e − f)/(e + f).
        let (a, b) = (self.n_i * cos_i, self.n_t * cos_t);
        let (e, f) = (self.n_t * cos_i, self.n_i * cos_t);
        let (ab, ef) = (a + b, e + f);
        let (am, em) = ((a - b) * ef, (e - f) * ab);
        let den = ab * ef;
        let r = 0.5 * (am * am + em * em) / (den * den);
        if total { 1.0 } else { r }
    }
}

/// e^x for the absorption factors (|x| up to a few units; clamped to ±700) without a libm
/// call, so that it vectorises (fused multiply-adds, exactly rounded on every CPU): x = k ln 2 + r, |r| ≤ ln 2 / 2, e^r by its Taylor series to
/// r¹² (truncation below 2·10⁻¹⁶), 2^k from the exponent bits. Within 4 ulp of libm's `exp`
/// (tested).
#[inline(always)]
pub(crate) fn exp_small(x: f64) -> f64 {
    const LOG2_E: f64 = std::f64::consts::LOG2_E;
    // ln 2 in two parts (fdlibm): k·LN2_HI is exact for |k| < 2¹¹.
    const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76);
    // 1.5·2⁵²: adding it rounds to an integer held in the low mantissa bits.
    const ROUND: f64 = 6_755_399_441_055_744.0;
    let x = x.clamp(-700.0, 700.0);
    let t = x * LOG2_E + ROUND;
    let k = t - ROUND;
    let r = (-k).mul_add(LN2_LO, (-k).mul_add(LN2_HI, x));
    let mut p: f64 = 1.0 / 479_001_600.0; // 1/12!
    for c in [
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p.mul_add(r, c);
    }
    let k_int = (t.to_bits() as i64).wrapping_sub(ROUND.to_bits() as i64);
    let scale = f64::from_bits(((k_int + 1023) << 52) as u64);
    p * scale
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::laws::fr_dielectric;

    #[test]
    fn small_sin_cos_matches_libm() {
        for k in -530..=530 {
            let x = k as f64 * 1e-3;
            let (s, c) = small_sin_cos(x);
            assert!((s - x.sin()).abs() < 1e-13, "{x}");
            assert!((c - x.cos()).abs() < 1e-13, "{x}");
        }
    }

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

    #[test]
    fn one_division_fresnel_agrees_with_the_law() {
        for (n_i, n_t) in [(1.31, 1.00028), (1.31, 1.581), (1.33, 1.581), (1.581, 1.31)] {
            let f = Fresnel::new(n_i, n_t);
            for k in 0..=10_000 {
                let c = k as f64 / 10_000.0;
                let (got, want) = (f.reflectance(c), fr_dielectric(c, n_i, n_t));
                assert!(
                    (got - want).abs() <= 4e-16 + 1e-13 * want,
                    "{n_i} {n_t} {c}"
                );
            }
            assert_eq!(f.reflectance(-0.5), fr_dielectric(-0.5, n_i, n_t));
        }
        // Total internal reflection beyond the critical angle (ice/air: 49.8°).
        assert_eq!(Fresnel::new(1.31, 1.00028).reflectance(0.6), 1.0);
    }

    #[test]
    fn exp_small_is_within_a_few_ulp_of_libm() {
        for k in -200_000..=20_000 {
            let x = k as f64 * 1.37e-4; // −27.4 … 2.7
            let (got, want) = (exp_small(x), x.exp());
            assert!(
                (got - want).abs() <= 4.0 * f64::EPSILON * want,
                "{x}: {got} vs {want}"
            );
        }
        assert_eq!(exp_small(0.0), 1.0);
        assert!(exp_small(-800.0) > 0.0 && exp_small(-800.0) < 1e-300);
    }
}
