//! The learned optical gain as the node keeps it: the estimator's prior at
//! boot and after a calibration (the kept gain, widened, else the last
//! calibration, else unknown), the `GAIN_OUT_OF_BAND` flag, and once an hour
//! whether the learned gain is worth a flash write. The arithmetic is
//! [`crate::calibration::gain`].

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use fois_protocol::GainEstimate;

use super::Node;
use crate::calibration::gain;
use crate::hal::PhotoAdc;
use crate::storage::Storage;
use crate::update::UpdateSlots;

impl<A, L, AL, IND, D, S, U> Node<A, L, AL, IND, D, S, U>
where
    A: PhotoAdc,
    L: OutputPin,
    AL: OutputPin,
    IND: OutputPin,
    D: DelayNs,
    S: Storage,
    U: UpdateSlots,
{
    /// The estimator's temperature model from the config, and its gain
    /// prior: the kept learned gain (widened), else the last calibration,
    /// else unknown.
    pub(super) fn start_estimator(&mut self) {
        self.estimator.set_temperature_model(
            self.config.gain_tempco_ppm_per_k,
            self.config.gain_tempco_sd_ppm_per_k,
        );
        let kept = self.kept_learned_gain();
        let calibrated = self.gain_calibration.as_ref().and_then(gain::from_estimate);
        match (kept, calibrated) {
            (Some((g, sd)), _) => {
                let (g, sd) = gain::prior_from_kept(g, sd);
                self.estimator.set_gain_prior(g, sd);
            }
            (None, Some((g, sd))) => self.estimator.set_gain_prior(g, sd),
            (None, None) => self.estimator.reset_gain(),
        }
    }

    /// After each frame: the out-of-band flag, and once an hour (not in the
    /// first hour after boot) whether the learned gain is worth keeping.
    pub(super) fn track_gain(&mut self, now_ms: u64) {
        let Some(g) = self.estimator.gain() else {
            return;
        };
        let band = (
            f32::from(self.config.gain_low_permille) * 1e-3,
            f32::from(self.config.gain_high_permille) * 1e-3,
        );
        self.gain_out_of_band = gain::out_of_band(self.gain_out_of_band, g.gain, g.sigma, band);
        if now_ms
            < self
                .gain_checked_ms
                .saturating_add(gain::SAVE_GAIN_INTERVAL_MS)
        {
            return;
        }
        self.gain_checked_ms = now_ms;
        // Kept at the reference temperature: the compensation taken out.
        let at_ref = g.gain / self.estimator.compensation();
        let kept = self.kept_learned_gain();
        if gain::worth_saving((at_ref, g.sigma), kept) {
            self.gain_kept = Some(gain::to_estimate(at_ref, g.sigma));
            self.changed(now_ms);
        }
    }

    /// The optical gain estimate as the protocol carries it (at the optics'
    /// temperature now), once the estimator has one.
    pub fn gain_estimate(&self) -> Option<GainEstimate> {
        self.estimator
            .gain()
            .map(|g| gain::to_estimate(g.gain, g.sigma))
    }

    /// The learned gain as kept in the store (`None`: none kept).
    pub fn gain_kept(&self) -> Option<GainEstimate> {
        self.gain_kept
    }

    /// The kept gain as (gain, relative sd) when it was learned, i.e. is not
    /// the last calibration itself (a calibration is not widened as a
    /// learned gain is). Inlined at both call sites, as the code was before
    /// it was written once: the QEMU instruction counts stay the same.
    #[inline(always)]
    fn kept_learned_gain(&self) -> Option<(f32, f32)> {
        self.gain_kept
            .filter(|k| Some(*k) != self.gain_calibration)
            .as_ref()
            .and_then(gain::from_estimate)
    }
}
