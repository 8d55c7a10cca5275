//! Test data (feature `fixtures`): one iced node as the wire carries it, shared by the tests
//! of this crate and of the crates that read nodes through it, so that they test against
//! the same numbers.

use fois_protocol::{DetectorState, GainEstimate, IceEstimate, Measurement, Medium, flags};

/// An iced node's measurement: I1 1.5 µA, I2 −0.25 µA, ambient 20 µA and 0, −5.12 °C,
/// V_DDA 3.3 V, alarm raised and acknowledged, NTC open.
pub fn iced_measurement() -> Measurement {
    Measurement {
        uptime_ms: 12_345,
        i1_na: 1_500,
        i2_na: -250,
        ambient1_na: 20_000,
        ambient2_na: 0,
        temperature_centi_c: -512,
        vdda_mv: 3300,
        flags: flags::ALARM | flags::ALARM_ACKED | flags::NTC_OPEN,
        state: DetectorState::Ice,
    }
}

/// Its estimate: 1.25 ± 0.08 mm of rime, probability 0.93.
pub fn rime_estimate() -> IceEstimate {
    IceEstimate {
        thickness_um: 1_250,
        sigma_um: 80,
        medium: Medium::Rime,
        probability_permille: 930,
    }
}

/// Its optical gain: 1.15026 ± 0.061.
pub fn gain_estimate() -> GainEstimate {
    GainEstimate {
        gain_ppm: 1_150_260,
        sigma_ppm: 61_000,
    }
}
