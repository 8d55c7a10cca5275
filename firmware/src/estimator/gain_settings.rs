//! The optical gain as the estimator's API: its prior (calibrated or
//! unknown), the temperature model, and what the bank of gain hypotheses
//! has learnt. Reads the estimator (`filter.rs`) and the bank.

use super::filter::Estimator;
use super::gain_bank::{GAINS, Gain, UNKNOWN_GAIN_SD};

impl Estimator {
    /// Set the gain's prior: `gain` relative to the table (at
    /// [`GAIN_REF_TEMP_C`](super::gain_bank::GAIN_REF_TEMP_C)) with relative standard
    /// deviation `sd` (0.02 for a calibrated gain, [`UNKNOWN_GAIN_SD`] for
    /// none). The hypotheses are centred on it, spaced by its standard
    /// deviation (within 0.01 … 0.153 in ln g); what the frames had taught
    /// about the gain is forgotten. Values out of range (gain outside
    /// 0.1 … 10, NaN) leave the prior unknown.
    pub fn set_gain_prior(&mut self, gain: f32, sd: f32) {
        self.bank.set_prior(gain, sd);
        if self.posterior.is_some() {
            self.summarise();
        }
    }

    /// Forget the gain: back to the unknown prior 1 ± [`UNKNOWN_GAIN_SD`].
    pub fn reset_gain(&mut self) {
        self.set_gain_prior(1.0, UNKNOWN_GAIN_SD);
    }

    /// The gain's prior (gain at [`GAIN_REF_TEMP_C`](super::gain_bank::GAIN_REF_TEMP_C),
    /// relative sd).
    pub fn gain_prior(&self) -> (f32, f32) {
        self.bank.prior()
    }

    /// The temperature model of the gain: g(T) = g₂₅ · exp(κ (T − 25 °C))
    /// with κ = `tempco_ppm_per_k` · 10⁻⁶ (clamped to ±5 %/K) applied to
    /// the currents, and its uncertainty (documentation of the residual the
    /// gain state absorbs).
    pub fn set_temperature_model(&mut self, tempco_ppm_per_k: i32, sd_ppm_per_k: u32) {
        self.bank
            .set_temperature_model(tempco_ppm_per_k, sd_ppm_per_k);
    }

    /// The temperature of the optoelectronics (LED, phototransistors: the
    /// MCU's die sensor beside them), °C; `None` keeps the last one.
    pub fn set_optics_temp_c(&mut self, t_c: Option<f32>) {
        self.bank.set_optics_temp_c(t_c);
    }

    /// The gain factor the temperature model applies now: exp(κ (T − 25 °C))
    /// (1 without a temperature).
    pub fn compensation(&self) -> f32 {
        self.bank.compensation()
    }

    /// The gain estimate (the mixture of the hypotheses, at the
    /// temperature now); `None` before the first valid frame.
    pub fn gain(&self) -> Option<Gain> {
        self.posterior?;
        Some(self.bank.gain())
    }

    /// The weight of each gain hypothesis (sums to 1).
    pub fn gain_weights(&self) -> &[f32; GAINS] {
        self.bank.weights()
    }

    /// The gain hypotheses (at [`GAIN_REF_TEMP_C`](super::gain_bank::GAIN_REF_TEMP_C)).
    pub fn gain_hypotheses(&self) -> [f32; GAINS] {
        self.bank.hypotheses()
    }

    /// Weight of the two outermost hypotheses: near 1, the gain may lie
    /// beyond the range the bank covers.
    pub fn gain_outside(&self) -> f32 {
        self.bank.outside()
    }
}
