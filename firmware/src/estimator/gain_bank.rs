//! The bank of gain hypotheses (`GainBank`): the estimator runs [`GAINS`]
//! grid filters, one per hypothesis of the sensor's relative optical gain
//! (spaced in ln g around a prior: a calibration, a kept learned gain, or
//! unknown), weighted by the forgetful mean of how well each foresaw the
//! currents; the bank follows the gain out of its range, and the
//! temperature model of the gain (thesis §5.2.3) scales every hypothesis by
//! the optics' temperature. It reads nothing of the estimator but its
//! settings and `fast_math`.

use super::fast_math;
use super::params::{EstimatorParams, within};

/// Gain hypotheses of the bank.
pub const GAINS: usize = 7;

/// Widest spacing of the hypotheses in ln g (a factor 1.165: seven of them
/// span 0.63 … 1.58 around gain 1).
const GAIN_STEP_MAX: f32 = 0.153;

/// Narrowest spacing in ln g (a calibrated gain).
const GAIN_STEP_MIN: f32 = 0.01;

/// Prior standard deviation of ln g when nothing is known (a new or
/// uncalibrated node: LED brightness groups, the face's coupling).
pub const UNKNOWN_GAIN_SD: f32 = 0.3;

/// Spread of the hypotheses' predictive likelihoods (nats) from which a
/// frame counts fully for the gain: below it the frame says little about
/// the gain (a dry face: nothing at all) and the gain's memory runs slower.
const GAIN_INFO_NATS: f32 = 1.0;

/// Weight of an outermost gain hypothesis beyond which the bank follows
/// the gain out of its range.
const FOLLOW_EDGE_WEIGHT: f32 = 0.35;

/// Reference temperature of the optical gain (the table's), °C.
pub const GAIN_REF_TEMP_C: f32 = 25.0;

/// Largest temperature coefficient of the gain the filter applies, 1/K.
const MAX_TEMPCO_PER_K: f32 = 0.05;

/// The sensor's relative optical gain as the estimator knows it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gain {
    /// Gain relative to the response table's (1 = as simulated), at the
    /// optoelectronics' temperature now (the temperature compensation
    /// included).
    pub gain: f32,
    /// Relative standard deviation (of ln g).
    pub sigma: f32,
}

/// The gain hypotheses, their prior, their evidence and weights, and the
/// temperature model of the gain. The estimator holds one and runs one grid
/// filter per hypothesis.
#[derive(Debug, Clone)]
pub(super) struct GainBank {
    /// ln g of each hypothesis (before the temperature compensation).
    ln_gains: [f32; GAINS],
    /// Spacing of the hypotheses in ln g.
    gain_step: f32,
    /// Prior of ln g: mean and standard deviation.
    prior: (f32, f32),
    /// Forgetful mean of each hypothesis' ln predictive likelihood.
    evidence: [f32; GAINS],
    /// False until the first frame with currents gave evidence.
    evidence_started: bool,
    /// Temperature coefficient of the gain, 1/K, and its standard deviation.
    tempco_per_k: f32,
    tempco_sd_per_k: f32,
    /// Temperature of the optoelectronics (the MCU's die), °C.
    optics_temp_c: Option<f32>,
    /// Weight of each hypothesis (sums to 1).
    weights: [f32; GAINS],
}

impl GainBank {
    /// The unknown gain: 1 ± [`UNKNOWN_GAIN_SD`], no temperature model.
    pub(super) fn new() -> Self {
        let mut bank = GainBank {
            ln_gains: [0.0; GAINS],
            gain_step: GAIN_STEP_MAX,
            prior: (0.0, UNKNOWN_GAIN_SD),
            evidence: [0.0; GAINS],
            evidence_started: false,
            tempco_per_k: 0.0,
            tempco_sd_per_k: 0.0,
            optics_temp_c: None,
            weights: [0.0; GAINS],
        };
        bank.set_prior(1.0, UNKNOWN_GAIN_SD);
        bank
    }

    /// Set the gain's prior: `gain` relative to the table (at
    /// [`GAIN_REF_TEMP_C`]) with relative standard deviation `sd` (0.02 for a
    /// calibrated gain, [`UNKNOWN_GAIN_SD`] for none). The hypotheses are
    /// centred on it, spaced by its standard deviation (within
    /// 0.01 … 0.153 in ln g); what the frames had taught about the gain is
    /// forgotten. Values out of range (gain outside 0.1 … 10, NaN) leave
    /// the prior unknown.
    pub(super) fn set_prior(&mut self, gain: f32, sd: f32) {
        let (mean, sd) = if gain.is_finite() && (0.1..=10.0).contains(&gain) {
            (fast_math::ln(gain), within(sd, 0.001, 1.0, UNKNOWN_GAIN_SD))
        } else {
            (0.0, UNKNOWN_GAIN_SD)
        };
        self.prior = (mean, sd);
        self.gain_step = sd.clamp(GAIN_STEP_MIN, GAIN_STEP_MAX);
        let mid = (GAINS / 2) as f32;
        for (j, l) in self.ln_gains.iter_mut().enumerate() {
            *l = mean + (j as f32 - mid) * self.gain_step;
        }
        self.evidence = [0.0; GAINS];
        self.evidence_started = false;
        self.weights = self.prior_weights();
    }

    /// Forget what the frames had taught about the gain: the weights back
    /// to the prior's.
    pub(super) fn forget_evidence(&mut self) {
        self.evidence = [0.0; GAINS];
        self.evidence_started = false;
        self.weights = self.prior_weights();
    }

    /// The gain's prior (gain at [`GAIN_REF_TEMP_C`], relative sd).
    pub(super) fn prior(&self) -> (f32, f32) {
        (fast_math::exp(self.prior.0), self.prior.1)
    }

    /// The temperature model of the gain: g(T) = g₂₅ · exp(κ (T − 25 °C))
    /// with κ = `tempco_ppm_per_k` · 10⁻⁶ (clamped to ±5 %/K) applied to
    /// the currents, and its uncertainty (documentation of the residual the
    /// gain state absorbs).
    pub(super) fn set_temperature_model(&mut self, tempco_ppm_per_k: i32, sd_ppm_per_k: u32) {
        self.tempco_per_k =
            (tempco_ppm_per_k as f32 * 1e-6).clamp(-MAX_TEMPCO_PER_K, MAX_TEMPCO_PER_K);
        self.tempco_sd_per_k = (sd_ppm_per_k as f32 * 1e-6).min(MAX_TEMPCO_PER_K);
    }

    /// The temperature of the optoelectronics (LED, phototransistors: the
    /// MCU's die sensor beside them), °C; `None` keeps the last one.
    pub(super) fn set_optics_temp_c(&mut self, t_c: Option<f32>) {
        if let Some(t) = t_c.filter(|t| t.is_finite()) {
            self.optics_temp_c = Some(t.clamp(-60.0, 150.0));
        }
    }

    /// The gain factor the temperature model applies now: exp(κ (T − 25 °C))
    /// (1 without a temperature).
    pub(super) fn compensation(&self) -> f32 {
        match self.optics_temp_c {
            Some(t) => fast_math::exp(self.tempco_per_k * (t - GAIN_REF_TEMP_C)),
            None => 1.0,
        }
    }

    /// The gain estimate (the mixture of the hypotheses, at the
    /// temperature now).
    pub(super) fn gain(&self) -> Gain {
        let (mut m, mut m2) = (0.0f32, 0.0f32);
        for (w, l) in self.weights.iter().zip(self.ln_gains) {
            m += w * l;
            m2 += w * l * l;
        }
        // The spread of the weights, and the width of one hypothesis' cell.
        let cell = self.gain_step * (1.0 / 3.464_102); // spacing / √12
        let var = (m2 - m * m).max(0.0) + cell * cell;
        Gain {
            gain: fast_math::exp(m) * self.compensation(),
            sigma: fast_math::sqrt(var),
        }
    }

    /// The weight of each gain hypothesis (sums to 1).
    pub(super) fn weights(&self) -> &[f32; GAINS] {
        &self.weights
    }

    /// The gain hypotheses (at [`GAIN_REF_TEMP_C`]).
    pub(super) fn hypotheses(&self) -> [f32; GAINS] {
        self.ln_gains.map(fast_math::exp)
    }

    /// Weight of the two outermost hypotheses: near 1, the gain may lie
    /// beyond the range the bank covers.
    pub(super) fn outside(&self) -> f32 {
        self.weights.first().copied().unwrap_or(0.0) + self.weights.last().copied().unwrap_or(0.0)
    }

    /// Gain spread within one hypothesis (ln g): the calibration's
    /// `gain_sd` and half the spacing to the neighbours.
    pub(super) fn within_sd(&self, params: &EstimatorParams) -> f32 {
        let h = self.gain_step * (1.0 / 3.464_102); // spacing / √12
        let sd = fast_math::sqrt(params.gain_sd * params.gain_sd + h * h);
        sd.max(params.gain_within_min)
    }

    /// The gain of hypothesis `j` now: its ln g and the temperature model.
    pub(super) fn gains_now(&self) -> [f32; GAINS] {
        let c = self.compensation();
        self.ln_gains.map(|l| fast_math::exp(l) * c)
    }

    pub(super) fn prior_weights(&self) -> [f32; GAINS] {
        let (m, sd) = self.prior;
        let mut w = self.ln_gains.map(|l| {
            let z = (l - m) / sd;
            fast_math::exp(-0.5 * z * z)
        });
        normalise(&mut w);
        w
    }

    /// Each hypothesis' evidence: the forgetful mean of its ln predictive
    /// likelihood, with memory `gain_memory_s` counted in frames that tell
    /// the hypotheses apart (a dry face tells nothing: the learned gain
    /// stays). The first frame counts fully. True when the bank followed the
    /// gain out of its range (its prior moved: [`Self::set_prior`]).
    pub(super) fn learn(&mut self, dt_s: f32, ln_z: &[f32; GAINS], gain_memory_s: f32) -> bool {
        let mut hi = f32::NEG_INFINITY;
        let mut lo = f32::INFINITY;
        for &l in ln_z {
            hi = hi.max(l);
            lo = lo.min(l);
        }
        if !hi.is_finite() {
            return false;
        }
        // A hypothesis that foresaw nothing keeps a floor (it can return).
        let floor = hi - 50.0;
        if !self.evidence_started {
            for (e, &l) in self.evidence.iter_mut().zip(ln_z) {
                *e = l.max(floor);
            }
            self.evidence_started = true;
        } else {
            let info = ((hi - lo.max(floor)) / GAIN_INFO_NATS).min(1.0);
            let a = fast_math::one_minus_exp_neg(dt_s * info / gain_memory_s);
            for (e, &l) in self.evidence.iter_mut().zip(ln_z) {
                *e += a * (l.max(floor) - *e);
            }
        }
        let prior = self.prior_weights();
        let mut max = f32::NEG_INFINITY;
        for &e in &self.evidence {
            max = max.max(e);
        }
        for ((w, p), e) in self.weights.iter_mut().zip(prior).zip(self.evidence) {
            *w = p * fast_math::exp(e - max);
        }
        if !normalise(&mut self.weights) {
            self.weights = prior;
        }
        self.follow()
    }

    /// The gain left the hypotheses' range (an LED failing after a
    /// calibration, a face fouling, a gain beyond 0.63 … 1.58): when an
    /// outermost hypothesis holds more than 35 % of the weight, the bank moves
    /// its centre there and doubles its spread (up to the unknown prior's);
    /// the evidence starts again, the grids keep what they hold. True when
    /// it moved.
    fn follow(&mut self) -> bool {
        let first = self.weights.first().copied().unwrap_or(0.0);
        let last = self.weights.last().copied().unwrap_or(0.0);
        if first.max(last) <= FOLLOW_EDGE_WEIGHT {
            return false;
        }
        let mut m = 0.0f32;
        for (w, l) in self.weights.iter().zip(self.ln_gains) {
            m += w * l;
        }
        let sd = (2.0 * self.prior.1).min(UNKNOWN_GAIN_SD);
        let g = fast_math::exp(m);
        if (0.1..=10.0).contains(&g) {
            self.set_prior(g, sd);
            return true;
        }
        false
    }
}

/// Scale `w` to sum 1; false if it cannot be.
fn normalise(w: &mut [f32]) -> bool {
    let s: f32 = w.iter().sum();
    if !(s.is_finite() && s > 0.0) {
        return false;
    }
    for x in w.iter_mut() {
        *x /= s;
    }
    true
}
