//! The sensor's relative optical gain g: what multiplies the LED-induced
//! photocurrents of the ray-traced curves (which are the response table's
//! gain, g = 1) on the virtual hardware.
//!
//! g = LED output factor × temperature factor × t², where
//!
//! - the **LED output factor** is the segment's `led_factor` (ageing, a weak
//!   driver);
//! - the **temperature factor** is exp(κ·(T_optics − 25 °C)): the net
//!   temperature coefficient κ of the LED's output and the phototransistors'
//!   responsivity (per K; a 940 nm LED loses ~0.3–0.6 %/K as it warms, so κ
//!   is negative and the gain *rises* in the cold). This is the law the
//!   node's gain estimator compensates with (its temperature model,
//!   g(T) = g₂₅·exp(κ·(T − 25 °C)) with κ from the config's
//!   `gain_tempco_ppm_per_k` and T from the MCU's internal temperature
//!   sensor: `fois_firmware::estimator::Estimator::set_temperature_model`
//!   and `compensation`), referred to the firmware's own reference temperature
//!   [`GAIN_REFERENCE_TEMP_C`]: one form, here for the hardware and there
//!   for the model, so a scenario that tells the node the true κ leaves it
//!   nothing to absorb;
//! - **t** is the transmission of a fouled face (dust, salt, a film of
//!   grime; 1 = clean): the LED's light crosses the face twice (out to the
//!   ice and back to the receiving bundles), so the LED-induced signal
//!   scales with t², while ambient light crosses it once and scales with t.
//!
//! T_optics is the temperature of the optoelectronics, which sit beside the
//! MCU in the enclosure: the air temperature plus the enclosure's
//! self-heating (`optics_above_air_k`, default 0 K: a node at a few mW in a
//! ventilated housing; a sealed box in still air may run a few K warm). The
//! internal sensor reads exactly this (the ADC's `read_internal_temp`), so
//! the node sees the temperature that sets the gain.

/// Temperature at which the temperature factor is 1, °C: the response
/// table's and the node's compensation reference, the firmware's
/// `estimator::GAIN_REF_TEMP_C`.
pub const GAIN_REFERENCE_TEMP_C: f64 = fois_firmware::estimator::GAIN_REF_TEMP_C as f64;

/// exp(κ·(T_optics − 25 °C)): the optical gain's temperature factor for a
/// net coefficient `tempco_per_k` (κ, 1/K) at `optics_temp_c`.
pub fn temperature_factor(tempco_per_k: f64, optics_temp_c: f64) -> f64 {
    (tempco_per_k * (optics_temp_c - GAIN_REFERENCE_TEMP_C)).exp()
}

/// A ppm/K coefficient (the node config's unit) as 1/K.
pub fn tempco_per_k_from_ppm(ppm_per_k: f64) -> f64 {
    ppm_per_k * 1e-6
}

/// The factors of the optical gain at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OpticalGain {
    /// LED output relative to nominal.
    pub led_factor: f64,
    /// exp(κ·(T_optics − 25 °C)).
    pub temperature_factor: f64,
    /// Transmission of the face (1 = clean).
    pub face_transmission: f64,
}

impl OpticalGain {
    /// The relative gain of the LED-induced signal: LED × temperature × t².
    pub fn signal_gain(&self) -> f64 {
        self.led_factor * self.temperature_factor * self.face_transmission.powi(2)
    }

    /// The factor on ambient light: t (one pass through the face).
    pub fn ambient_gain(&self) -> f64 {
        self.face_transmission
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_temperature_factor_is_one_at_25_c_and_rises_in_the_cold() {
        let k = tempco_per_k_from_ppm(-6_000.0);
        assert!((k + 0.006).abs() < 1e-15);
        assert!((temperature_factor(k, 25.0) - 1.0).abs() < 1e-15);
        // −25 °C: exp(−0.006 × −50) = exp(0.3) = 1.349 86.
        assert!((temperature_factor(k, -25.0) - 1.349_858_8).abs() < 1e-6);
        // −2 °C: exp(0.162) = 1.175 86.
        assert!((temperature_factor(k, -2.0) - 1.175_860_2).abs() < 1e-6);
        // No coefficient: no temperature dependence.
        assert_eq!(temperature_factor(0.0, -40.0), 1.0);
    }

    #[test]
    fn fouling_costs_the_signal_twice_and_the_ambient_once() {
        let g = OpticalGain {
            led_factor: 0.9,
            temperature_factor: 1.2,
            face_transmission: 0.8,
        };
        // 0.9 × 1.2 × 0.64 = 0.6912.
        assert!((g.signal_gain() - 0.6912).abs() < 1e-12);
        assert_eq!(g.ambient_gain(), 0.8);
    }
}
