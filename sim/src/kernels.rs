//! The tracer's arithmetic over all thicknesses of one ray at once, written as loops over
//! slices so that the compiler vectorises them: the divisions and square roots that bound
//! the scalar loop run four lanes at a time with AVX2 (detected at run time), two with the
//! SSE2 of every x86-64. Each lane performs the same IEEE-754 operations in the same order
//! as the scalar formula (Rust never fuses a multiply and an add on its own), so the results
//! are bit-identical to it; the golden-value tests of the crate check this.

use glam::DVec2;

use crate::geometry::Bundles;

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
            _ => Isa::Avx512,
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
