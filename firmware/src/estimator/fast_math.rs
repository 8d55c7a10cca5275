//! `exp` and `ln` in `f32` arithmetic only, for the estimator's inner loop
//! (two per live state and frame), and the few helpers built on them.
//!
//! Why not `libm`: its `expf`/`logf` are exact to an ulp but cost more
//! instructions and flash (with `log1pf`, `expm1f`, `sqrtf` ≈ 2 KiB) than
//! the filter needs; its `exp2f`/`log2f` compute in `f64`, which the M4F's
//! single-precision FPU does in software. The filter needs a relative
//! accuracy of ~10⁻⁶ (its
//! forgetting carries an error of ln p into the next frames with weight
//! α/(1 − α) ≈ 300 at most), so short polynomials suffice:
//!
//! * `exp(x) = 2ⁿ · 2ᶠ`, n = round(x·log₂e), |f| ≤ ½, 2ᶠ by its Taylor series
//!   to degree 7 (truncation ≤ (½ ln 2)⁸/8! ≈ 5·10⁻⁹), n·ln 2 split in two
//!   (Cody–Waite); relative error < 10⁻⁶ (tested).
//! * `ln(x) = e·ln 2 + 2 atanh(s)`, x = m·2ᵉ with m ∈ [√½, √2),
//!   s = (m − 1)/(m + 1), |s| ≤ 0.172, atanh to s⁹ (truncation ≤ 2·10⁻⁹);
//!   error < 5·10⁻⁷ + one f32 ulp of the result (tested).
//!
//! Both are tested against `std` over their whole range in the unit tests.

const LOG2_E: f32 = core::f32::consts::LOG2_E;
/// ln 2 split for an exact n·ln 2 (Cody–Waite): the high part has 16 zero
/// low bits, so n · LN_2_HI is exact for |n| ≤ 256.
const LN_2_HI: f32 = 0.693_145_75;
const LN_2_LO: f32 = 1.428_606_8e-6;

/// eˣ. 0 for x < −87.3 (and for −∞), +∞ above 88.7, NaN for NaN.
/// One copy in flash for the rare calls; the filter's per-state loops use
/// [`exp_inline`].
#[inline(never)]
pub fn exp(x: f32) -> f32 {
    exp_inline(x)
}

/// ln x, see [`ln_inline`]. One copy in flash for the rare calls.
#[inline(never)]
pub fn ln(x: f32) -> f32 {
    ln_inline(x)
}

/// [`exp`], inlined (the per-state loops).
#[inline(always)]
pub fn exp_inline(x: f32) -> f32 {
    if x.is_nan() {
        return x;
    }
    if x < -87.3 {
        return 0.0;
    }
    if x > 88.7 {
        return f32::INFINITY;
    }
    let t = x * LOG2_E;
    // round to nearest without libm: t ∈ [−126, 128].
    let n = if t >= 0.0 {
        (t + 0.5) as i32
    } else {
        (t - 0.5) as i32
    };
    // f ∈ [−½, ½]; y = f·ln 2 = x − n·ln 2, in two exact-ish steps.
    let y = (x - n as f32 * LN_2_HI) - n as f32 * LN_2_LO;
    // e^y, |y| ≤ 0.347: Taylor to degree 7, Horner.
    let p = 1.0
        + y * (1.0
            + y * (0.5
                + y * (1.0 / 6.0
                    + y * (1.0 / 24.0
                        + y * (1.0 / 120.0 + y * (1.0 / 720.0 + y * (1.0 / 5040.0)))))));
    // 2ⁿ through the exponent bits; n ∈ [−126, 128] here, and n = 128 only
    // for x ≤ 88.7 where p < 1, so split the scale in two steps.
    let half = n / 2;
    let a = f32::from_bits(((half + 127) as u32) << 23);
    let b = f32::from_bits(((n - half + 127) as u32) << 23);
    p * a * b
}

/// ln x. −∞ for 0, NaN for x < 0 or NaN, +∞ for +∞; subnormals are exact
/// enough (they are scaled up first). Inlined (the per-state loops).
#[inline(always)]
pub fn ln_inline(x: f32) -> f32 {
    if x.is_nan() || x < 0.0 {
        return f32::NAN;
    }
    if x == 0.0 {
        return f32::NEG_INFINITY;
    }
    if x == f32::INFINITY {
        return x;
    }
    let (x, bias) = if x < f32::MIN_POSITIVE {
        (x * 16_777_216.0, -24) // 2²⁴
    } else {
        (x, 0)
    };
    let bits = x.to_bits();
    let mut e = ((bits >> 23) & 0xFF) as i32 - 127 + bias;
    let mut m = f32::from_bits((bits & 0x007F_FFFF) | 0x3F80_0000); // [1, 2)
    if m > core::f32::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let atanh =
        s * (1.0 + s2 * (1.0 / 3.0 + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0)))));
    let ef = e as f32;
    (ef * LN_2_HI + 2.0 * atanh) + ef * LN_2_LO
}

/// 1 − e⁻ˣ for x ≥ 0 (a probability of an event at rate λ over Δt,
/// x = λΔt), accurate also for tiny x where 1 − exp(−x) would cancel.
#[inline]
pub fn one_minus_exp_neg(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        0.0
    } else if x < 0.1 {
        // Series to x⁵ (truncation < x⁵/720 relative: 1.4·10⁻⁸ at 0.1).
        x * (1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x * (1.0 / 120.0)))))
    } else {
        1.0 - exp(-x)
    }
}

/// √x for x ≥ 0 (0 for x ≤ 0 or NaN): e^(½ ln x), relative error < 10⁻⁶.
#[inline]
pub fn sqrt(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        0.0
    } else {
        exp(0.5 * ln(x))
    }
}

/// The smallest integer ≥ x, for 0 ≤ x < 2²⁴ (0 below, NaN → 0).
#[inline]
pub fn ceil(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    let x = x.min(16_777_216.0);
    let t = x as u32 as f32;
    if t < x { t + 1.0 } else { t }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_matches_std_to_a_ppm() {
        let mut worst = 0.0f64;
        let mut x = -87.0f32;
        while x <= 88.0 {
            let want = f64::from(x).exp();
            let got = f64::from(exp(x));
            worst = worst.max(((got - want) / want).abs());
            x += 0.0137;
        }
        assert!(worst < 1e-6, "worst relative error {worst}");
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(exp(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp(-200.0), 0.0);
        assert_eq!(exp(100.0), f32::INFINITY);
        assert!(exp(f32::NAN).is_nan());
    }

    #[test]
    fn ln_matches_std_to_half_a_ppm_plus_an_ulp() {
        let mut worst = 0.0f64;
        let mut x = 1e-38f32;
        while x < 1e38 {
            let want = f64::from(x).ln();
            let got = f64::from(ln(x));
            // One f32 ulp of the result is 1.2e-7 relative.
            worst = worst.max((got - want).abs() / (5e-7 + 1.2e-7 * want.abs()));
            x *= 1.000_731;
        }
        assert!(worst < 1.0, "worst error {worst} of the allowance");
        // Subnormals.
        let tiny = 1e-40f32;
        assert!((f64::from(ln(tiny)) - f64::from(tiny).ln()).abs() < 1e-5);
        assert_eq!(ln(0.0), f32::NEG_INFINITY);
        assert_eq!(ln(1.0), 0.0);
        assert!(ln(-1.0).is_nan());
        assert!(ln(f32::NAN).is_nan());
        assert_eq!(ln(f32::INFINITY), f32::INFINITY);
    }

    #[test]
    fn helpers_match_std() {
        for x in [1e-9f32, 1e-5, 1e-3, 0.0999, 0.1, 0.5, 3.0, 40.0] {
            let want = -(-f64::from(x)).exp_m1();
            let got = f64::from(one_minus_exp_neg(x));
            assert!(
                ((got - want) / want).abs() < 2e-6,
                "1 − e^−{x}: {got} vs {want}"
            );
        }
        assert_eq!(one_minus_exp_neg(0.0), 0.0);
        assert_eq!(one_minus_exp_neg(f32::NAN), 0.0);
        for x in [1e-30f32, 1e-6, 0.25, 2.0, 1e6, 3e38] {
            let want = f64::from(x).sqrt();
            assert!(((f64::from(sqrt(x)) - want) / want).abs() < 1e-6, "√{x}");
        }
        assert_eq!(sqrt(0.0), 0.0);
        assert_eq!(sqrt(-1.0), 0.0);
        assert_eq!(ceil(0.0), 0.0);
        assert_eq!(ceil(0.2), 1.0);
        assert_eq!(ceil(3.0), 3.0);
        assert_eq!(ceil(3.000_001), 4.0);
        assert_eq!(ceil(f32::NAN), 0.0);
    }
}
