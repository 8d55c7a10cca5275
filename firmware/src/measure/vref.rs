//! V_DDA from VREFINT, and the MCU's internal temperature sensor, both through
//! the factory calibration values (taken at V_DDA = 3.3 V).

use crate::hal::FactoryCal;

/// Supply at which the factory values were taken, mV.
pub const CAL_VDDA_MV: u32 = 3_300;
/// Lowest plausible V_DDA, mV (below: [`fois_protocol::flags::VDDA_OUT_OF_RANGE`]).
pub const VDDA_MIN_MV: u16 = 2_000;
/// Highest plausible V_DDA, mV.
pub const VDDA_MAX_MV: u16 = 3_600;

/// V_DDA in mV from a VREFINT code: 3300 mV × VREFINT_CAL / code. A zero code
/// (broken channel) gives `u16::MAX`, which is out of range.
pub fn vdda_mv(cal: &FactoryCal, vrefint_code: u16) -> u16 {
    if vrefint_code == 0 {
        return u16::MAX;
    }
    let code = u32::from(vrefint_code);
    let mv = (CAL_VDDA_MV * u32::from(cal.vrefint_cal) + code / 2) / code;
    u16::try_from(mv).unwrap_or(u16::MAX)
}

/// True when `mv` is a plausible supply (2.0–3.6 V, the F446's range).
pub fn vdda_in_range(mv: u16) -> bool {
    (VDDA_MIN_MV..=VDDA_MAX_MV).contains(&mv)
}

/// The value used to convert codes to volts: `mv` clamped to the plausible
/// range (a doubtful VREFINT reading must not blow the currents up).
pub fn vdda_for_conversion(mv: u16) -> u16 {
    mv.clamp(VDDA_MIN_MV, VDDA_MAX_MV)
}

/// Internal sensor temperature, 0.01 °C. The code is first rescaled to the
/// 3.3 V at which TS_CAL1 (30 °C) and TS_CAL2 (110 °C) were taken; then the
/// straight line through the two points.
pub fn internal_temp_centi_c(cal: &FactoryCal, code: u16, vdda_mv: u16) -> i16 {
    let cal = cal.or_typical();
    let c1 = i64::from(cal.ts_cal1);
    let span = i64::from(cal.ts_cal2) - c1; // > 100 after or_typical
    if span <= 0 {
        return i16::MAX;
    }
    // code at 3.3 V, scaled by 1000 for resolution.
    let code_x1000 = i64::from(code) * i64::from(vdda_mv) * 1000 / i64::from(CAL_VDDA_MV);
    let centi = 3_000 + (code_x1000 - c1 * 1000) * 8_000 / (span * 1000);
    clamp_i16(centi)
}

/// Saturating conversion to `i16`.
pub fn clamp_i16(v: i64) -> i16 {
    v.clamp(i64::from(i16::MIN), i64::from(i16::MAX)) as i16
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vdda_from_vrefint() {
        let cal = FactoryCal::TYPICAL;
        assert_eq!(vdda_mv(&cal, cal.vrefint_cal), 3_300);
        // A 3.0 V supply: VREFINT (1.21 V) reads 1.21 / 3.0 * 4095 = 1652.
        let mv = vdda_mv(&cal, 1652);
        assert!((2_995..=3_005).contains(&mv), "{mv}");
        assert_eq!(vdda_mv(&cal, 0), u16::MAX);
        assert!(!vdda_in_range(vdda_mv(&cal, 0)));
        assert!(!vdda_in_range(vdda_mv(&cal, 4095))); // 1.21 V
        assert_eq!(vdda_for_conversion(1_000), 2_000);
    }

    #[test]
    fn internal_sensor_at_its_calibration_points() {
        let cal = FactoryCal::TYPICAL;
        assert_eq!(internal_temp_centi_c(&cal, cal.ts_cal1, 3_300), 3_000);
        assert_eq!(internal_temp_centi_c(&cal, cal.ts_cal2, 3_300), 11_000);
        // Same voltage read at V_DDA = 3.0 V: code 958 * 3.3 / 3.0 = 1054.
        let t = internal_temp_centi_c(&cal, 1054, 3_000);
        assert!((2_980..=3_020).contains(&t), "{t}");
        // Garbage calibration falls back to typical values, no division by zero.
        let bad = FactoryCal {
            vrefint_cal: 0xFFFF,
            ts_cal1: 0xFFFF,
            ts_cal2: 0xFFFF,
        };
        assert_eq!(internal_temp_centi_c(&bad, 958, 3_300), 3_000);
    }
}
