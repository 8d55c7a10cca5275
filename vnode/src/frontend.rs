//! The analog front end between light and ADC codes: load resistors (I·R_L),
//! the phototransistors' clip (the emitter never rises above V_DDA −
//! V_CE(sat), ~3.05 V on 3.3 V: strong sun saturates the transistor well
//! below the ADC's full scale), the V_DDA reference, 12-bit quantisation,
//! Gaussian noise from a seeded stream; the NTC divider (10 kΩ NTC, B = 3950,
//! to GND; 10 kΩ to 3V3 on PA4; ratiometric), VREFINT and the internal
//! temperature sensor (from the factory calibration). The conversions are
//! the firmware's own (`fois_firmware::sim_board::codes`, also behind its
//! tests' simulated board); this adds the noise.

use fois_firmware::FactoryCal;
use fois_firmware::sim_board::codes;
use rand_core::Rng;
use rand_pcg::Pcg32;

pub use codes::CAL_VDDA_V;

/// The front end's parameters and noise stream.
#[derive(Debug, Clone)]
pub struct FrontEnd {
    /// Load resistors of the two phototransistors, Ω (default: the node's
    /// config defaults).
    pub load_ohm: [f64; 2],
    /// Analog supply and ADC reference, V.
    pub vdda_v: f64,
    /// V_CE(sat) of the phototransistors, V: their collectors sit on the
    /// 3V3 rail (= V_DDA), so the emitter clips at `vdda_v − vce_sat_v`.
    pub vce_sat_v: f64,
    /// The MCU's factory calibration (VREFINT, temperature sensor).
    pub cal: FactoryCal,
    /// Force the NTC code (fault injection: 4095 = open, 0 = short).
    pub ntc_code_override: Option<u16>,
    rng: Pcg32,
}

impl FrontEnd {
    /// Defaults: R_L from `Config::default()`, V_DDA 3.3 V, V_CE(sat)
    /// 0.25 V, typical calibration; noise stream from `seed`.
    pub fn new(seed: u64) -> Self {
        let c = fois_protocol::Config::default();
        FrontEnd {
            load_ohm: [f64::from(c.load_r1_ohm), f64::from(c.load_r2_ohm)],
            vdda_v: CAL_VDDA_V,
            vce_sat_v: codes::VCE_SAT_TYPICAL_V,
            cal: FactoryCal::TYPICAL,
            ntc_code_override: None,
            rng: Pcg32::new(seed ^ 0x9E37_79B9_7F4A_7C15, 0xF015),
        }
    }

    /// One standard normal draw (Box–Muller).
    pub fn gaussian(&mut self) -> f64 {
        let u1 = ((self.rng.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
        let u2 = (self.rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }

    /// Quantise a voltage to a 12-bit code (plus `noise_lsb` rms noise),
    /// clamped to 0..=4095.
    pub fn quantise(&mut self, volts: f64, noise_lsb: f64) -> u16 {
        let mut x = codes::lsb(volts, self.vdda_v);
        if noise_lsb > 0.0 {
            x += noise_lsb * self.gaussian();
        }
        codes::code(x)
    }

    /// Codes of the two phototransistor channels for these currents, µA:
    /// I·R_L, clipped at V_DDA − V_CE(sat) (`sim_board::codes::photo_volts`),
    /// plus noise.
    pub fn photo_codes(&mut self, current_ua: [f64; 2], noise_lsb: f64) -> [u16; 2] {
        [0, 1].map(|k| {
            let v = codes::photo_volts(
                current_ua[k] * 1e3,
                self.load_ohm[k],
                self.vdda_v,
                self.vce_sat_v,
            );
            self.quantise(v, noise_lsb)
        })
    }

    /// NTC divider code at `air_temp_c` (ratiometric: independent of V_DDA).
    pub fn ntc_code(&mut self, air_temp_c: f64) -> u16 {
        match self.ntc_code_override {
            Some(c) => c.min(fois_firmware::hal::ADC_MAX),
            None => codes::ntc_code(air_temp_c),
        }
    }

    /// VREFINT code: VREFINT_CAL · 3.3 V / V_DDA.
    pub fn vrefint_code(&self) -> u16 {
        codes::vrefint_code(&self.cal, self.vdda_v)
    }

    /// Internal temperature sensor code at die temperature `die_temp_c`
    /// (linear between TS_CAL1 at 30 °C and TS_CAL2 at 110 °C, at 3.3 V).
    /// The die's temperature above the air (self-heating) is the
    /// environment's: `Truth::optics_temp_c`.
    pub fn internal_temp_code(&self, die_temp_c: f64) -> u16 {
        codes::internal_temp_code(&self.cal, die_temp_c, self.vdda_v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_follow_ohms_law_and_saturate() {
        let mut fe = FrontEnd::new(1);
        let c = fois_protocol::Config::default();
        assert_eq!(
            fe.load_ohm,
            [f64::from(c.load_r1_ohm), f64::from(c.load_r2_ohm)]
        );
        fe.load_ohm = [22_000.0; 2];
        // 30 µA × 22 kΩ = 0.66 V → 0.66/3.3 × 4095 = 819.
        assert_eq!(fe.photo_codes([30.0, 0.0], 0.0), [819, 0]);
        // 200 µA × 22 kΩ = 4.4 V: the transistor saturates at
        // 3.3 − 0.25 = 3.05 V → 3.05/3.3 × 4095 = 3784.8, not full scale.
        assert_eq!(fe.photo_codes([200.0, -5.0], 0.0), [3785, 0]);
        // Just below the clip it is still Ohm's law: 138 µA × 22 kΩ = 3.036 V.
        assert_eq!(fe.photo_codes([138.0, 0.0], 0.0)[0], 3767);
        fe.vdda_v = 3.0;
        assert_eq!(fe.photo_codes([30.0, 0.0], 0.0)[0], 901);
        // The clip follows the supply: 2.75 V of 3.0 V → 3753.75.
        assert_eq!(fe.photo_codes([200.0, 0.0], 0.0)[0], 3754);
        // Noise rides on the clipped level (it is the ADC's), and stays
        // within a few codes of it.
        let noisy = fe.photo_codes([200.0, 0.0], 2.0)[0];
        assert!((3740..=3768).contains(&noisy), "{noisy}");
    }

    #[test]
    fn noise_has_the_requested_rms_and_is_seeded() {
        let mut a = FrontEnd::new(7);
        let mut b = FrontEnd::new(7);
        let n = 20_000;
        let xs: Vec<f64> = (0..n)
            .map(|_| f64::from(a.quantise(1.65, 3.0)) - 2047.5)
            .collect();
        let ys: Vec<f64> = (0..n)
            .map(|_| f64::from(b.quantise(1.65, 3.0)) - 2047.5)
            .collect();
        assert_eq!(xs, ys);
        let mean = xs.iter().sum::<f64>() / n as f64;
        let rms = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        assert!((rms - 3.0).abs() < 0.15, "rms {rms}");
        assert!(mean.abs() < 0.1, "mean {mean}");
    }

    #[test]
    fn ntc_vref_and_internal_sensor_codes() {
        let mut fe = FrontEnd::new(1);
        // 25 °C: R = 10 kΩ, half scale.
        assert_eq!(fe.ntc_code(25.0), 2048);
        // 0 °C: R = 10k·exp(3950·(1/273.15 − 1/298.15)) = 33.6 kΩ → 3156.
        assert_eq!(fe.ntc_code(0.0), 3156);
        assert!(fe.ntc_code(-10.0) > fe.ntc_code(0.0));
        assert_eq!(fe.vrefint_code(), FactoryCal::TYPICAL.vrefint_cal);
        fe.vdda_v = 3.0;
        assert_eq!(fe.vrefint_code(), 1652);
        fe.vdda_v = 3.3;
        assert_eq!(fe.internal_temp_code(30.0), FactoryCal::TYPICAL.ts_cal1);
        assert_eq!(fe.internal_temp_code(110.0), FactoryCal::TYPICAL.ts_cal2);
        // The firmware reads our NTC code back as the same temperature.
        for t in [-20.0, -5.0, 0.5, 12.0] {
            let code = fe.ntc_code(t);
            match fois_firmware::measure::ntc::temperature(code) {
                fois_firmware::measure::ntc::NtcReading::Ok(c) => {
                    assert!((f64::from(c) / 100.0 - t).abs() < 0.1, "{t} °C read {c}")
                }
                other => panic!("{t} °C: {other:?}"),
            }
        }
    }
}
