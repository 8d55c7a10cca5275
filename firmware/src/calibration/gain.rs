//! The optical gain's calibration and bookkeeping: a calibration against a
//! known target on the face (`CalibrateGain`), the prior a kept estimate
//! gives after a reset, when a learned gain is worth a flash write, and the
//! out-of-band maintenance flag.
//!
//! A *target* is a reference the operator puts on the face (a diffuse
//! reflector of known reflectance in a fixed holder, or a reference ice
//! sample) whose net currents at gain 1 — the response table's gain — were
//! measured on a reference node or computed with the simulator. The node
//! measures the baseline-corrected currents x over a few frames and fits
//! x = g · c · μ (c the temperature compensation now) by least squares:
//! g = (x · μ) / (c · μ · μ).

use crate::estimator::fast_math::{exp, ln, sqrt};
use fois_protocol::{CalibrationRefusal, GainEstimate, GainTarget};

/// Frames averaged by a gain calibration.
pub const GAIN_CAL_FRAMES: usize = 4;
/// Relative standard deviation of a calibrated gain (the target's own
/// tolerance dominates the frames' noise).
pub const CALIBRATED_GAIN_SD: f32 = 0.02;
/// Smallest target current that is measured well enough, nA (per channel
/// sum).
pub const MIN_TARGET_NA: u32 = 1_000;
/// The gains a calibration accepts (outside: a wrong target, a broken LED).
pub const GAIN_RANGE: (f32, f32) = (0.25, 4.0);
/// Largest spread of the frames around their mean (relative to the mean's
/// size) before the calibration is refused as a step (something moved).
const MAX_SPREAD: f32 = 0.05;
/// Largest misfit of the shape (the currents' ratio) to the target's,
/// relative: beyond it the target is not what the operator said.
const MAX_SHAPE_MISFIT: f32 = 0.15;
/// Added to a kept gain's standard deviation when it becomes the prior
/// after a reset (the face may have changed while the node was off).
pub const KEPT_GAIN_EXTRA_SD: f32 = 0.01;
/// A learned gain is written to flash at most this often, ms (through the
/// node's rate-limited saves; the first one an hour after boot at the
/// earliest).
pub const SAVE_GAIN_INTERVAL_MS: u64 = 3_600_000;
/// A learned gain is worth a write when ln g moved by more than this …
const SAVE_LN_GAIN_STEP: f32 = 0.02;
/// … or its standard deviation changed by more than this factor.
const SAVE_SD_RATIO: f32 = 1.25;

/// A gain calibration's result: the gain at the reference temperature
/// (the compensation removed) and its relative standard deviation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibrated {
    /// Gain at the reference temperature of the temperature model.
    pub gain: f32,
    /// Relative standard deviation.
    pub sd: f32,
}

/// Fit the gain to `frames` (baseline-corrected currents, nA; `None` for a
/// saturated or invalid frame) against `target` at temperature
/// compensation `compensation`.
pub fn calibrate(
    frames: &[Option<[i32; 2]>],
    target: GainTarget,
    compensation: f32,
) -> Result<Calibrated, CalibrationRefusal> {
    let mu = [target.i1_na as f32, target.i2_na as f32];
    if target.i1_na.saturating_add(target.i2_na) < MIN_TARGET_NA {
        return Err(CalibrationRefusal::InvalidTarget);
    }
    if frames.is_empty() || frames.iter().any(Option::is_none) {
        return Err(CalibrationRefusal::Saturated);
    }
    let n = frames.len() as f32;
    let mut mean = [0.0f32; 2];
    for x in frames.iter().flatten() {
        mean[0] += x[0] as f32 / n;
        mean[1] += x[1] as f32 / n;
    }
    let size = (mean[0].abs() + mean[1].abs()).max(1.0);
    for x in frames.iter().flatten() {
        let dev = (x[0] as f32 - mean[0]).abs() + (x[1] as f32 - mean[1]).abs();
        if dev > MAX_SPREAD * size {
            return Err(CalibrationRefusal::Step);
        }
    }
    if !(compensation.is_finite() && compensation > 0.0) {
        return Err(CalibrationRefusal::ImplausibleGain);
    }
    let mu2 = mu[0] * mu[0] + mu[1] * mu[1];
    let g_now = (mean[0] * mu[0] + mean[1] * mu[1]) / mu2;
    let gain = g_now / compensation;
    if !(gain.is_finite() && gain >= GAIN_RANGE.0 && gain <= GAIN_RANGE.1) {
        return Err(CalibrationRefusal::ImplausibleGain);
    }
    // The residual of the fit: the target's shape must match.
    let r = [mean[0] - g_now * mu[0], mean[1] - g_now * mu[1]];
    let misfit = sqrt(r[0] * r[0] + r[1] * r[1]) / (g_now * sqrt(mu2));
    if misfit > MAX_SHAPE_MISFIT {
        return Err(CalibrationRefusal::ImplausibleGain);
    }
    Ok(Calibrated {
        gain,
        sd: CALIBRATED_GAIN_SD,
    })
}

/// The protocol's form of a gain and its relative sd (ppm, absolute sd).
pub fn to_estimate(gain: f32, rel_sd: f32) -> GainEstimate {
    let ppm = |x: f32| {
        if x.is_finite() && x > 0.0 {
            (x * 1e6).min(u32::MAX as f32) as u32
        } else {
            0
        }
    };
    GainEstimate {
        gain_ppm: ppm(gain),
        sigma_ppm: ppm(gain * rel_sd),
    }
}

/// A stored gain estimate as (gain, relative sd), `None` if unusable.
pub fn from_estimate(e: &GainEstimate) -> Option<(f32, f32)> {
    let g = e.gain_ppm as f32 * 1e-6;
    let sd = e.sigma_ppm as f32 * 1e-6;
    (g > 0.0 && g.is_finite() && sd.is_finite()).then(|| (g, sd / g))
}

/// The prior a kept estimate (gain, relative sd) gives after a reset: the
/// same gain, its sd widened by [`KEPT_GAIN_EXTRA_SD`].
pub fn prior_from_kept(gain: f32, rel_sd: f32) -> (f32, f32) {
    (gain, rel_sd + KEPT_GAIN_EXTRA_SD)
}

/// Is the learned gain (gain, relative sd) worth a flash write against the
/// stored one? Only when it moved or narrowed noticeably.
pub fn worth_saving(learned: (f32, f32), stored: Option<(f32, f32)>) -> bool {
    let Some(stored) = stored else {
        return true;
    };
    let (g, sd) = learned;
    let (g0, sd0) = stored;
    if !(g > 0.0 && g0 > 0.0 && sd > 0.0 && sd0 > 0.0) {
        return g.is_finite() && g > 0.0;
    }
    let moved = ln(g / g0).abs() > SAVE_LN_GAIN_STEP;
    let ratio = sd / sd0;
    moved || !(1.0 / SAVE_SD_RATIO..=SAVE_SD_RATIO).contains(&ratio)
}

/// The out-of-band flag with hysteresis: raised when the probability that
/// the gain lies outside [low, high] exceeds 0.95, cleared below 0.5.
pub fn out_of_band(raised: bool, gain: f32, rel_sd: f32, band: (f32, f32)) -> bool {
    let p = outside_probability(gain, rel_sd, band);
    if raised { p >= 0.5 } else { p > 0.95 }
}

/// P(g ∉ [low, high]) for ln g ~ N(ln gain, rel_sd²).
fn outside_probability(gain: f32, rel_sd: f32, band: (f32, f32)) -> f32 {
    if !(gain.is_finite() && gain > 0.0) {
        return 0.0;
    }
    let sd = rel_sd.max(1e-6);
    let m = ln(gain);
    let below = normal_cdf((ln(band.0.max(1e-6)) - m) / sd);
    let above = 1.0 - normal_cdf((ln(band.1.max(1e-6)) - m) / sd);
    below + above
}

/// Φ(z), the standard normal CDF (Abramowitz & Stegun 7.1.26, |ε| < 1.5·10⁻⁷).
fn normal_cdf(z: f32) -> f32 {
    let x = z.abs() / core::f32::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly = t
        * (0.254_829_6
            + t * (-0.284_496_74 + t * (1.421_413_7 + t * (-1.453_152_1 + t * 1.061_405_4))));
    let erf = 1.0 - poly * exp(-x * x);
    if z >= 0.0 {
        0.5 * (1.0 + erf)
    } else {
        0.5 * (1.0 - erf)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TARGET: GainTarget = GainTarget {
        i1_na: 20_000,
        i2_na: 8_000,
    };

    #[test]
    fn a_steady_target_gives_its_gain() {
        let x = Some([17_000, 6_800]); // 0.85 × the target
        let c = calibrate(&[x; GAIN_CAL_FRAMES], TARGET, 1.0).unwrap();
        assert!((c.gain - 0.85).abs() < 1e-4, "{c:?}");
        assert_eq!(c.sd, CALIBRATED_GAIN_SD);
        // At −25 °C with +30 % from the temperature model: 0.85 / 1.3.
        let c = calibrate(&[x; GAIN_CAL_FRAMES], TARGET, 1.3).unwrap();
        assert!((c.gain - 0.85 / 1.3).abs() < 1e-4, "{c:?}");
    }

    #[test]
    fn refusals_say_why() {
        let x = Some([17_000, 6_800]);
        let tiny = GainTarget {
            i1_na: 300,
            i2_na: 200,
        };
        assert_eq!(
            calibrate(&[x; 4], tiny, 1.0),
            Err(CalibrationRefusal::InvalidTarget)
        );
        assert_eq!(
            calibrate(&[x, None, x, x], TARGET, 1.0),
            Err(CalibrationRefusal::Saturated)
        );
        assert_eq!(
            calibrate(&[], TARGET, 1.0),
            Err(CalibrationRefusal::Saturated)
        );
        // Something moved: one frame 10 % off.
        let moved = Some([18_700, 7_480]);
        assert_eq!(
            calibrate(&[x, x, moved, x], TARGET, 1.0),
            Err(CalibrationRefusal::Step)
        );
        // A gain of 5 or 0.1: a wrong target or a dead LED.
        assert_eq!(
            calibrate(&[Some([100_000, 40_000]); 4], TARGET, 1.0),
            Err(CalibrationRefusal::ImplausibleGain)
        );
        assert_eq!(
            calibrate(&[Some([2_000, 800]); 4], TARGET, 1.0),
            Err(CalibrationRefusal::ImplausibleGain)
        );
        // The right size but the wrong shape (channel 2 twice what it should be).
        assert_eq!(
            calibrate(&[Some([17_000, 13_600]); 4], TARGET, 1.0),
            Err(CalibrationRefusal::ImplausibleGain)
        );
        assert_eq!(
            calibrate(&[x; 4], TARGET, f32::NAN),
            Err(CalibrationRefusal::ImplausibleGain)
        );
    }

    #[test]
    fn estimates_round_trip_through_ppm() {
        let e = to_estimate(0.85, 0.02);
        assert_eq!(e.gain_ppm, 850_000);
        assert_eq!(e.sigma_ppm, 17_000);
        let (g, sd) = from_estimate(&e).unwrap();
        assert!((g - 0.85).abs() < 1e-6 && (sd - 0.02).abs() < 1e-6);
        assert_eq!(from_estimate(&to_estimate(f32::NAN, 0.1)), None);
        assert_eq!(prior_from_kept(0.9, 0.03), (0.9, 0.04));
    }

    #[test]
    fn only_a_changed_gain_is_saved() {
        assert!(worth_saving((1.0, 0.1), None));
        assert!(!worth_saving((1.01, 0.1), Some((1.0, 0.1))));
        assert!(worth_saving((1.03, 0.1), Some((1.0, 0.1))));
        assert!(!worth_saving((1.0, 0.11), Some((1.0, 0.1))));
        assert!(worth_saving((1.0, 0.05), Some((1.0, 0.1))));
    }

    #[test]
    fn the_out_of_band_flag_has_hysteresis() {
        let band = (0.6, 1.5);
        assert!(!out_of_band(false, 1.0, 0.05, band));
        // 0.5 ± 5 %: surely below 0.6.
        assert!(out_of_band(false, 0.5, 0.05, band));
        // 0.58 ± 5 %: ~75 % below — not raised, but held once raised.
        assert!(!out_of_band(false, 0.58, 0.05, band));
        assert!(out_of_band(true, 0.58, 0.05, band));
        // Back to 0.65: cleared.
        assert!(!out_of_band(true, 0.65, 0.05, band));
        // A wide estimate at 1 says nothing: not raised.
        assert!(!out_of_band(false, 1.0, 0.3, band));
        assert!((normal_cdf(0.0) - 0.5).abs() < 1e-6);
        assert!((normal_cdf(1.96) - 0.975).abs() < 1e-3);
    }
}
