//! The NTC divider on PA4: 10 kΩ (25 °C), B = 3950, NTC from PA4 to GND and
//! 10 kΩ from PA4 to 3V3. The divider and the ADC share the 3.3 V rail, so the
//! reading is ratiometric: R_ntc = 10 kΩ × code / (4095 − code).

use crate::hal::ADC_MAX;

/// NTC resistance at 25 °C, Ω.
pub const R25_OHM: f32 = 10_000.0;
/// The fixed divider resistor, Ω.
pub const R_FIXED_OHM: f32 = 10_000.0;
/// Beta constant, K.
pub const BETA_K: f32 = 3_950.0;
/// At or above this code the NTC reads open (R ≥ 4 MΩ, colder than −68 °C).
pub const OPEN_CODE: u16 = 4_085;
/// At or below this code the NTC reads shorted (R ≤ 24 Ω, hotter than +200 °C).
pub const SHORT_CODE: u16 = 10;

const T25_K: f32 = 298.15;
const KELVIN: f32 = 273.15;

/// An NTC reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NtcReading {
    /// Temperature, 0.01 °C.
    Ok(i16),
    /// Open circuit (broken wire, unplugged).
    Open,
    /// Short circuit.
    Short,
}

/// Natural logarithm for `x > 0` without libm: x = 2^e · m, m ∈ [√½, √2),
/// ln m = 2·atanh((m−1)/(m+1)) by its series (error < 1e-7 on this range).
pub fn ln(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        return f32::NEG_INFINITY;
    }
    if x.is_infinite() {
        return f32::INFINITY;
    }
    let bits = x.to_bits();
    let mut e = ((bits >> 23) & 0xFF) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007F_FFFF) | 0x3F80_0000); // [1, 2)
    if ((bits >> 23) & 0xFF) == 0 {
        // Subnormal: scale up first.
        return ln(x * 8_388_608.0) - 23.0 * core::f32::consts::LN_2;
    }
    if m > core::f32::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let series = 1.0 + s2 * (1.0 / 3.0 + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0))));
    2.0 * s * series + e as f32 * core::f32::consts::LN_2
}

/// Temperature from an NTC divider code (beta equation).
pub fn temperature(code: u16) -> NtcReading {
    let code = code.min(ADC_MAX);
    if code >= OPEN_CODE {
        return NtcReading::Open;
    }
    if code <= SHORT_CODE {
        return NtcReading::Short;
    }
    let c = f32::from(code);
    let ratio = (R_FIXED_OHM / R25_OHM) * c / (f32::from(ADC_MAX) - c); // R / R25
    let inv_t = 1.0 / T25_K + ln(ratio) / BETA_K;
    let celsius = 1.0 / inv_t - KELVIN;
    let centi = celsius * 100.0;
    // Rounded, saturating (the code range above keeps it within ±200 °C).
    let rounded = if centi >= 0.0 {
        centi + 0.5
    } else {
        centi - 0.5
    };
    NtcReading::Ok(crate::measure::vref::clamp_i16(rounded as i64))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The code a B = 3950 NTC gives at `celsius` (test helper, std maths).
    fn code_at(celsius: f64) -> u16 {
        let r = 10_000.0 * ((1.0 / (celsius + 273.15) - 1.0 / 298.15) * 3950.0).exp();
        (4095.0 * r / (r + 10_000.0)).round() as u16
    }

    #[test]
    fn ln_matches_std() {
        for &x in &[
            1e-30f32, 1e-3, 0.1, 0.5, 0.999, 1.0, 1.5, 2.0, 10.0, 402.0, 1e20,
        ] {
            let err = (ln(x) - x.ln()).abs();
            assert!(err < 2e-6 * x.ln().abs().max(1.0), "ln({x}) err {err}");
        }
        assert_eq!(ln(0.0), f32::NEG_INFINITY);
        assert_eq!(ln(-1.0), f32::NEG_INFINITY);
    }

    #[test]
    fn beta_equation_over_the_outdoor_range() {
        // 25 °C: half scale.
        assert_eq!(code_at(25.0), 2048);
        for &t in &[-40.0, -20.0, -5.0, 0.0, 0.5, 2.5, 25.0, 60.0] {
            let NtcReading::Ok(centi) = temperature(code_at(t)) else {
                panic!("{t} °C read as a fault");
            };
            // One ADC step is < 0.1 °C near 0 °C and < 0.35 °C at −40 °C.
            let err = (f64::from(centi) - t * 100.0).abs();
            assert!(err < 35.0, "{t} °C → {centi}");
        }
        let NtcReading::Ok(zero) = temperature(code_at(0.0)) else {
            panic!()
        };
        assert!(zero.abs() <= 6, "0 °C → {zero}");
    }

    #[test]
    fn open_and_short() {
        assert_eq!(temperature(4095), NtcReading::Open);
        assert_eq!(temperature(OPEN_CODE), NtcReading::Open);
        assert_eq!(temperature(u16::MAX), NtcReading::Open);
        assert_eq!(temperature(0), NtcReading::Short);
        assert_eq!(temperature(SHORT_CODE), NtcReading::Short);
        assert!(matches!(temperature(OPEN_CODE - 1), NtcReading::Ok(t) if t < -6_000));
        assert!(matches!(temperature(SHORT_CODE + 1), NtcReading::Ok(t) if t > 18_000));
    }
}
