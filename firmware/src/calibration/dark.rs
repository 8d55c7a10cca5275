//! Dark calibration under noise: average the dry face's net currents as long
//! as the noise needs (within a bounded time), and refuse only what would
//! make the baseline wrong — a trend, a step, too much noise for the time,
//! saturation.
//!
//! The calibration measures *blocks*: synchronous detection as in a frame
//! (`photocurrent::acquire`, the config's settle time) with
//! [`CAL_BLOCK_CYCLES`] cycles each, whatever the frames' K (every cycle's
//! net has the same expectation), back to back. After
//! [`CAL_MIN_BLOCKS`] blocks it stops as soon as the standard error of the
//! mean of each channel is at most the onset rise / [`SE_FRACTION_OF_ONSET`]
//! (50 nA with the default 1 µA onset), or when the next block would pass
//! [`CAL_MAX_MS`] (or [`CAL_MAX_BLOCKS`] are stored). The mean of the blocks
//! is the baseline.
//!
//! Then, per channel, on the blocks x₁…xₙ with σ the block noise estimated
//! from the successive differences xᵢ₊₁ − xᵢ (a step moves one of them, a
//! spike two and a trend all of them by its slope only) — their mean square
//! without the outliers that the median difference points out:
//!
//! - **Step** if one block sits more than [`SPIKE_SIGMAS`] standard
//!   deviations *and* more than onset/4 off the mean of its two neighbours
//!   (a trend does not move that difference). This is what a change of ambient light
//!   inside an acquisition does — a cloud edge: synchronous detection
//!   cancels a steady or linearly changing ambient, but a step Δ between two
//!   samples leaves ±Δ/2 in that one cycle, ±Δ/(2c) in its block (the
//!   virtual node's physics, `vnode/tests/cloud_edge.rs`) — or a drop that
//!   lands and runs off.
//! - **Step** or **Trend** if a two-level model (the best split) or a line
//!   explains the blocks significantly better than a constant (|z| above
//!   [`STEP_SIGMAS`] / [`TREND_SIGMAS`]) *and* the change is material (more
//!   than onset/10 between the levels, or along the line over the whole
//!   calibration); whichever of the two fits better names the reason. A
//!   film drying off the face after cleaning is a trend; a drop landing, a
//!   hand or a cloth in front of the face a step.
//! - **Noisy** if the standard error target was not reached within the time.
//!
//! Both conditions — significant *and* material — must hold, so noise alone
//! (any level) never reads as drift, and a drift too small to matter never
//! refuses. The time bound keeps the worst answer of a command inside the
//! host's timeout (`platform::reply_time`).
//!
//! A steady reading can still be the wrong one: a water film starting on
//! the face (the rule still reads dry below the onset) is steady enough.
//! [`check_shift`] compares the new baseline with the stored one: a move
//! of either channel by more than onset / [`SHIFT_FRACTION_OF_ONSET`]
//! (250 nA at the default 1 µA onset) is refused unless forced. Why that
//! much: each baseline's standard error is at most onset / 20 (the stop
//! rule above), so the difference of two baselines of the same dry face
//! has a standard error of at most onset·√2 / 20 and onset / 4 is 3.5 of
//! those at the worst (a false refusal well under 1 in 1 000 per channel,
//! far fewer when the noise allows a smaller error); and a baseline moved
//! by more than a quarter of the onset delays the next alarm (and offsets
//! every thickness) by that quarter. Slow real changes between two
//! calibrations — a dirty or cleaned face, an ageing or new LED — pass it
//! too and need the `force` flag. With no stored baseline the zero the
//! rule uses is a placeholder, not a measurement of this face (crosstalk
//! and the window's reflection give a dry face a net current of its own):
//! the first calibration is held only by the rule's dry state (I1 under
//! the onset over zero) and the checks of the reading.

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use fois_protocol::{Baseline, BaselineShift, CalibrationRefusal, Config};

use crate::hal::{FactoryCal, PhotoAdc};
use crate::measure::photocurrent;
use crate::measure::vref;

/// Cycles per calibration block: short blocks give enough of them to see a
/// trend or a step even at 5 ms settle (8 cycles × 2 × 5 ms = 80 ms a
/// block), long enough ones that 256 of them average 2 048 cycles.
pub const CAL_BLOCK_CYCLES: u16 = 8;
/// Blocks measured at least (a trend or a step needs some to be seen).
pub const CAL_MIN_BLOCKS: usize = 16;
/// Blocks stored at most (2 KiB of stack for the two channels).
pub const CAL_MAX_BLOCKS: usize = 256;
/// The calibration's time bound, ms: a block starts only if it ends within
/// this, by the upper bound of its duration ([`block_max_us`]). Part of the
/// worst answer time (`platform::reply_time::WORST_REPLY_MS`).
pub const CAL_MAX_MS: u32 = 2_000;
/// The baseline's standard error must be at most onset / this (50 nA at the
/// default 1 µA onset: the baseline error then moves the alarm threshold
/// by 5 % at one standard error).
pub const SE_FRACTION_OF_ONSET: u32 = 20;
/// The longest one `read_photo` (both channels) takes on the board, µs: two
/// conversions of 56 + 12 ADC cycles at 8 MHz (8.5 µs each) with the
/// converter kept on, and the register work around them, ≈ 19 µs
/// (`firmware/README.md`, the board binary), with room.
pub const PHOTO_PAIR_MAX_US: u32 = 30;

/// A block this many standard deviations off its neighbours' level is a
/// spike (a step inside an acquisition).
pub const SPIKE_SIGMAS: f32 = 5.5;
/// The line's slope must be this many standard errors from zero.
pub const TREND_SIGMAS: f32 = 5.0;
/// The best split's level difference must be this many standard errors
/// from zero (higher than for the line: it is the best of n − 1 splits).
pub const STEP_SIGMAS: f32 = 5.5;
/// An unforced calibration may move either channel's baseline by at most
/// onset / this ([`check_shift`]; the module doc says why).
pub const SHIFT_FRACTION_OF_ONSET: u32 = 4;
/// A spike matters from onset / this.
const SPIKE_FRACTION_OF_ONSET: u32 = 4;
/// A step or a trend matters from onset / this.
const DRIFT_FRACTION_OF_ONSET: u32 = 10;
/// A split leaves at least this many blocks on each side.
const MIN_SEGMENT: usize = 4;
/// Successive differences beyond this many of their first σ are left out
/// of the noise estimate.
const OUTLIER_SIGMAS: f32 = 5.0;
/// median|N(0, 2σ²)| = 0.6745 · √2 · σ.
const MEDIAN_ABS_DIFF_PER_SIGMA: f32 = 0.953_9;

/// How one calibration runs for a config.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Plan {
    /// Cycles per block.
    pub block_cycles: u16,
    /// Blocks that fit the time bound (at most [`CAL_MAX_BLOCKS`]).
    pub max_blocks: usize,
    /// Standard error target, nA.
    pub se_target_na: u32,
}

/// The upper bound of one block's duration, µs: 2c + 1 settle waits and
/// photo conversions, one V_DDA reading on top.
pub fn block_max_us(cycles: u16, settle_us: u16) -> u32 {
    let samples = 2 * u32::from(cycles.max(1)) + 1;
    samples * (u32::from(settle_us) + PHOTO_PAIR_MAX_US)
}

/// The plan for `config`.
pub fn plan(config: &Config) -> Plan {
    let block_cycles = CAL_BLOCK_CYCLES;
    let block_us = block_max_us(block_cycles, config.settle_us).max(1);
    let fit = (CAL_MAX_MS * 1_000 / block_us) as usize;
    Plan {
        block_cycles,
        max_blocks: fit.min(CAL_MAX_BLOCKS),
        se_target_na: (config.onset_rise_na / SE_FRACTION_OF_ONSET).max(1),
    }
}

/// A calibration that was accepted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    /// The baseline: the blocks' mean.
    pub baseline: Baseline,
    /// Blocks measured.
    pub blocks: usize,
    /// Squared standard error of each channel's mean, nA².
    pub se2_na2: [f32; 2],
}

/// The blocks of one calibration, per channel, nA.
#[derive(Debug, Clone)]
pub struct Blocks {
    x: [[i32; CAL_MAX_BLOCKS]; 2],
    n: usize,
}

impl Default for Blocks {
    fn default() -> Self {
        Self::new()
    }
}

impl Blocks {
    /// No blocks yet.
    pub const fn new() -> Self {
        Blocks {
            x: [[0; CAL_MAX_BLOCKS]; 2],
            n: 0,
        }
    }

    /// Add one block's net currents; false (and nothing stored) when full.
    pub fn push(&mut self, net_na: [i32; 2]) -> bool {
        if self.n >= CAL_MAX_BLOCKS {
            return false;
        }
        for (ch, v) in net_na.into_iter().enumerate() {
            if let Some(slot) = self.x.get_mut(ch).and_then(|c| c.get_mut(self.n)) {
                *slot = v;
            }
        }
        self.n += 1;
        true
    }

    /// Blocks stored.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True before the first block.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    fn channel(&self, ch: usize) -> &[i32] {
        self.x.get(ch).and_then(|c| c.get(..self.n)).unwrap_or(&[])
    }

    /// Squared standard error of the channel's mean from the mean squared
    /// successive difference, nA² (infinite below two blocks).
    pub fn se2_na2(&self, ch: usize) -> f32 {
        let x = self.channel(ch);
        let n = x.len();
        if n < 2 {
            return f32::INFINITY;
        }
        let mut ss = 0.0f32;
        for w in x.windows(2) {
            if let [a, b] = w {
                let d = (i64::from(*b) - i64::from(*a)) as f32;
                ss += d * d;
            }
        }
        let var = ss / (2.0 * (n - 1) as f32);
        var / n as f32
    }

    /// True once [`CAL_MIN_BLOCKS`] are in and both channels' standard
    /// error is within the plan's target.
    pub fn precise_enough(&self, plan: &Plan) -> bool {
        let target = plan.se_target_na as f32;
        self.n >= CAL_MIN_BLOCKS && (0..2).all(|ch| self.se2_na2(ch) <= target * target)
    }

    /// Decide: the baseline, or why not.
    pub fn analyse(&self, config: &Config, plan: &Plan) -> Result<Outcome, CalibrationRefusal> {
        if self.n < 2 {
            return Err(CalibrationRefusal::Noisy);
        }
        let onset = config.onset_rise_na.max(1);
        let mut verdict: Option<CalibrationRefusal> = None;
        for ch in 0..2 {
            let r = drift(
                self.channel(ch),
                (onset / SPIKE_FRACTION_OF_ONSET) as f32,
                (onset / DRIFT_FRACTION_OF_ONSET) as f32,
            );
            // A step anywhere outranks a trend elsewhere.
            if r == Some(CalibrationRefusal::Step) || verdict.is_none() {
                verdict = r.or(verdict);
            }
        }
        if let Some(reason) = verdict {
            return Err(reason);
        }
        let se2 = [self.se2_na2(0), self.se2_na2(1)];
        let target = plan.se_target_na as f32;
        if se2.iter().any(|s| *s > target * target) {
            return Err(CalibrationRefusal::Noisy);
        }
        let mean = |ch: usize| {
            let x = self.channel(ch);
            let sum: i64 = x.iter().map(|v| i64::from(*v)).sum();
            let n = x.len().max(1) as i64;
            // Rounded to nearest.
            let m = if sum >= 0 {
                (sum + n / 2) / n
            } else {
                (sum - n / 2) / n
            };
            m.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
        };
        Ok(Outcome {
            baseline: Baseline {
                i1_na: mean(0),
                i2_na: mean(1),
            },
            blocks: self.n,
            se2_na2: se2,
        })
    }
}

/// The block noise σ² of `x`, nA², robust to a few outliers: a first σ
/// from the median absolute successive difference, then the mean squared
/// successive difference over the differences within [`OUTLIER_SIGMAS`] of
/// it (a spike's two and a step's one are left out; the median alone
/// scatters too much to set thresholds by). At least 1 nA².
fn robust_var(x: &[i32]) -> f32 {
    let mut d = [0u32; CAL_MAX_BLOCKS];
    let mut m = 0;
    for (slot, w) in d.iter_mut().zip(x.windows(2)) {
        if let [a, b] = w {
            *slot = (i64::from(*b) - i64::from(*a))
                .unsigned_abs()
                .min(u64::from(u32::MAX)) as u32;
            m += 1;
        }
    }
    let Some(diffs) = d.get_mut(..m) else {
        return 1.0;
    };
    if diffs.is_empty() {
        return 1.0;
    }
    diffs.sort_unstable();
    let med = diffs.get(diffs.len() / 2).copied().unwrap_or(0) as f32;
    // |d| ≤ k·√2·σ₁ with σ₁ = med / 0.954 (at least one ADC-free nA).
    let limit =
        OUTLIER_SIGMAS * core::f32::consts::SQRT_2 * (med / MEDIAN_ABS_DIFF_PER_SIGMA).max(1.0);
    let (mut ss, mut k) = (0.0f32, 0usize);
    for v in diffs.iter().map(|v| *v as f32).filter(|v| *v <= limit) {
        ss += v * v;
        k += 1;
    }
    if k == 0 {
        return 1.0;
    }
    (ss / (2.0 * k as f32)).max(1.0)
}

/// Spike, step or trend in one channel's blocks (`None`: steady).
/// `spike_min` and `drift_min` are the material sizes, nA.
fn drift(x: &[i32], spike_min: f32, drift_min: f32) -> Option<CalibrationRefusal> {
    let n = x.len();
    if n < 2 {
        return None;
    }
    let var = robust_var(x);
    // Spikes: a block off the level of its neighbours (their mean; the one
    // neighbour at either end), which a trend does not move.
    let spike = (0..n).any(|i| {
        let at = |j: usize| x.get(j).map_or(0.0, |v| *v as f32);
        let (dev, var_dev) = match (i.checked_sub(1), i + 1 < n) {
            (Some(a), true) => (at(i) - (at(a) + at(i + 1)) / 2.0, 1.5 * var),
            (Some(a), false) => (at(i) - at(a), 2.0 * var),
            (None, true) => (at(i) - at(i + 1), 2.0 * var),
            (None, false) => (0.0, var),
        };
        dev * dev > SPIKE_SIGMAS * SPIKE_SIGMAS * var_dev && dev.abs() > spike_min
    });
    if spike {
        return Some(CalibrationRefusal::Step);
    }
    // Centre on the first block to keep f32 sums small.
    let origin = x.first().copied().unwrap_or(0);
    let y = |i: usize| {
        x.get(i)
            .map_or(0.0, |v| (i64::from(*v) - i64::from(origin)) as f32)
    };
    let nf = n as f32;
    let mean = (0..n).map(y).sum::<f32>() / nf;

    // The line: slope b over the block index, var(b) = σ²/Σ(i − ī)².
    let i_mean = (nf - 1.0) / 2.0;
    let sxx: f32 = (0..n)
        .map(|i| (i as f32 - i_mean) * (i as f32 - i_mean))
        .sum();
    let sxy: f32 = (0..n).map(|i| (i as f32 - i_mean) * (y(i) - mean)).sum();
    let (line_gain, line_z2, line_change) = if sxx > 0.0 {
        let b = sxy / sxx;
        (b * sxy, b * b * sxx / var, b * (nf - 1.0))
    } else {
        (0.0, 0.0, 0.0)
    };

    // The best split: levels before and after block k; its gain over the
    // constant is Δ²·k(n−k)/n.
    let (mut step_gain, mut step_delta) = (0.0f32, 0.0f32);
    if n >= 2 * MIN_SEGMENT {
        let total = mean * nf;
        let mut left = 0.0f32;
        for k in 1..n {
            left += y(k - 1);
            if k < MIN_SEGMENT || n - k < MIN_SEGMENT {
                continue;
            }
            let (kf, rf) = (k as f32, (n - k) as f32);
            let delta = (total - left) / rf - left / kf;
            let gain = delta * delta * kf * rf / nf;
            if gain > step_gain {
                (step_gain, step_delta) = (gain, delta);
            }
        }
    }
    // Whichever model explains more names the change; it must be
    // significant and material.
    if step_gain > line_gain {
        let z2 = step_gain / var;
        (z2 > STEP_SIGMAS * STEP_SIGMAS && step_delta.abs() > drift_min)
            .then_some(CalibrationRefusal::Step)
    } else {
        (line_z2 > TREND_SIGMAS * TREND_SIGMAS && line_change.abs() > drift_min)
            .then_some(CalibrationRefusal::Trend)
    }
}

/// The largest baseline shift of either channel an unforced calibration
/// may make, nA: onset / [`SHIFT_FRACTION_OF_ONSET`] (at least 1).
pub fn allowed_shift_na(config: &Config) -> u32 {
    (config.onset_rise_na / SHIFT_FRACTION_OF_ONSET).max(1)
}

/// The baseline-shift guard: `new` against the `stored` baseline. `Err`
/// with both and the allowance when either channel moved by more than
/// [`allowed_shift_na`]; always `Ok` with nothing stored (the first
/// calibration, see the module doc).
pub fn check_shift(
    stored: Option<Baseline>,
    new: Baseline,
    config: &Config,
) -> Result<(), BaselineShift> {
    let Some(old) = stored else {
        return Ok(());
    };
    let shift = BaselineShift {
        old,
        new,
        allowed_na: allowed_shift_na(config),
    };
    if shift.shift_na() > shift.allowed_na {
        Err(shift)
    } else {
        Ok(())
    }
}

/// Run a dark calibration on the hardware: V_DDA once, then blocks until
/// the plan says stop; a saturated block refuses at once (`Saturated`).
/// The LED is left off.
pub fn run<A, L, D>(
    adc: &mut A,
    led: &mut L,
    delay: &mut D,
    config: &Config,
    cal: &FactoryCal,
) -> Result<Outcome, CalibrationRefusal>
where
    A: PhotoAdc,
    L: OutputPin,
    D: DelayNs,
{
    let plan = plan(config);
    let vdda_mv = vref::vdda_mv(cal, adc.read_vrefint());
    let conv_mv = vref::vdda_for_conversion(vdda_mv);
    let sat = photocurrent::saturation_code(conv_mv);
    let loads = [config.load_r1_ohm, config.load_r2_ohm];
    let mut blocks = Blocks::new();
    while blocks.len() < plan.max_blocks {
        let acq = photocurrent::acquire(adc, led, delay, plan.block_cycles, config.settle_us, sat);
        if acq.saturated.iter().any(|s| *s) {
            return Err(CalibrationRefusal::Saturated);
        }
        blocks.push(photocurrent::currents(&acq, conv_mv, loads).net_na);
        if blocks.precise_enough(&plan) {
            break;
        }
    }
    blocks.analyse(config, &plan)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> Config {
        Config::default()
    }

    /// A reproducible Gaussian stream (Box–Muller on a 64-bit LCG).
    struct Noise(u64);
    impl Noise {
        fn uniform(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn gauss(&mut self) -> f64 {
            let (u1, u2) = (self.uniform(), self.uniform());
            (-2.0 * u1.ln()).sqrt() * (2.0 * core::f64::consts::PI * u2).cos()
        }
    }

    /// Blocks from `gen` (block index → currents) as `run` takes them: until
    /// precise enough or the plan's maximum.
    fn calibrate(plan: &Plan, mut generate: impl FnMut(usize) -> [f64; 2]) -> Blocks {
        let mut b = Blocks::new();
        while b.len() < plan.max_blocks {
            b.push(generate(b.len()).map(|x| x.round() as i32));
            if b.precise_enough(plan) {
                break;
            }
        }
        b
    }

    fn blocks(values: impl Iterator<Item = [f64; 2]>) -> Blocks {
        let mut b = Blocks::new();
        for v in values {
            b.push(v.map(|x| x.round() as i32));
        }
        b
    }

    #[test]
    fn the_plan_fits_the_time_bound() {
        // Default: K = 8, 200 µs: 17 × 230 µs = 3.91 ms a block, 511 fit in
        // 2 s, 256 stored; SE target 1 000 / 20 = 50 nA.
        let p = plan(&cfg());
        assert_eq!(block_max_us(8, 200), 3_910);
        assert_eq!(
            p,
            Plan {
                block_cycles: 8,
                max_blocks: 256,
                se_target_na: 50
            }
        );
        // The slowest config: K = 64, 5 ms settle: blocks of 8 cycles,
        // 17 × 5.03 ms = 85.5 ms, 23 of them in 2 s (≥ the minimum 16).
        let slow = Config {
            cycles_per_frame: 64,
            settle_us: 5_000,
            ..cfg()
        };
        let p = plan(&slow);
        assert_eq!((p.block_cycles, p.max_blocks), (8, 23));
        assert!(p.max_blocks >= CAL_MIN_BLOCKS);
        assert!(p.max_blocks as u32 * block_max_us(8, 5_000) <= CAL_MAX_MS * 1_000);
        // K = 1 (fast frames): still blocks of 8 cycles, as many of them.
        let p = plan(&Config {
            cycles_per_frame: 1,
            ..cfg()
        });
        assert_eq!((p.block_cycles, p.max_blocks), (8, 256));
        // The smallest onset (50 nA): SE target 2 nA.
        let p = plan(&Config {
            onset_rise_na: 50,
            ..cfg()
        });
        assert_eq!(p.se_target_na, 2);
    }

    #[test]
    fn steady_noise_is_calibrated_at_any_level_the_time_allows() {
        let plan = plan(&cfg());
        for (seed, sigma) in [(1u64, 0.0), (2, 40.0), (3, 317.0), (4, 700.0)] {
            let mut noise = Noise(seed);
            let b = calibrate(&plan, |_| {
                [600.0 + sigma * noise.gauss(), -50.0 + sigma * noise.gauss()]
            });
            let out = b.analyse(&cfg(), &plan).expect("steady noise calibrates");
            // Blocks needed: (σ / 50 nA)², at least 16.
            let need = (sigma / 50.0) * (sigma / 50.0);
            let lo = (need * 0.7).max(CAL_MIN_BLOCKS as f64);
            let hi = (need * 1.4).max(CAL_MIN_BLOCKS as f64);
            assert!(
                (lo..=hi).contains(&(out.blocks as f64)),
                "σ {sigma}: {} blocks, expected ≈ {need:.0}",
                out.blocks
            );
            let err = (out.baseline.i1_na - 600).abs();
            assert!(err <= 3 * 50, "σ {sigma}: baseline off by {err} nA");
            assert!(out.se2_na2[0] <= 50.0 * 50.0);
        }
    }

    #[test]
    fn too_much_noise_for_the_time_is_noisy() {
        let plan = plan(&cfg());
        let mut noise = Noise(9);
        // σ = 1 µA per block: 400 blocks needed, 256 allowed.
        let b = blocks((0..plan.max_blocks).map(|_| [1_000.0 * noise.gauss(), 0.0]));
        assert_eq!(b.analyse(&cfg(), &plan), Err(CalibrationRefusal::Noisy));
    }

    #[test]
    fn a_trend_is_refused_and_a_tiny_one_is_not() {
        let plan = plan(&cfg());
        for seed in 0..200 {
            let mut noise = Noise(seed);
            // A film drying off: −20 nA per block over 40 blocks = −780 nA, σ 100 nA.
            let b =
                blocks((0..40).map(|i| [2_000.0 - 20.0 * i as f64 + 100.0 * noise.gauss(), 0.0]));
            let r = b.analyse(&cfg(), &plan);
            assert_eq!(r, Err(CalibrationRefusal::Trend), "seed {seed}");
        }
        let mut noise = Noise(5);
        // The same on channel 2.
        let b = blocks((0..40).map(|i| [0.0, 20.0 * i as f64 + 100.0 * noise.gauss()]));
        assert_eq!(b.analyse(&cfg(), &plan), Err(CalibrationRefusal::Trend));
        // Significant but immaterial: 1 nA per block without noise (39 nA
        // over the calibration, under onset/10 = 100 nA).
        let b = blocks((0..40).map(|i| [i as f64, 0.0]));
        assert!(b.analyse(&cfg(), &plan).is_ok());
    }

    #[test]
    fn a_step_is_refused_and_named() {
        let plan = plan(&cfg());
        for seed in 0..200 {
            let mut noise = Noise(seed);
            // A drop lands after block 25: +600 nA, σ 100 nA.
            let b = blocks((0..50).map(|i| {
                let level = if i < 25 { 0.0 } else { 600.0 };
                [level + 100.0 * noise.gauss(), 0.0]
            }));
            let r = b.analyse(&cfg(), &plan);
            assert_eq!(r, Err(CalibrationRefusal::Step), "seed {seed}");
        }
        // 90 nA is below onset/10: accepted.
        let b = blocks((0..50).map(|i| [if i < 25 { 0.0 } else { 90.0 }, 0.0]));
        assert!(b.analyse(&cfg(), &plan).is_ok());
    }

    #[test]
    fn a_spike_is_a_step_in_the_light() {
        let plan = plan(&cfg());
        // A cloud edge in bright sun, 80 µA → 8 µA, inside block 10 of 8
        // cycles: (8 − 80)/16 = −4.5 µA in that block; 8 LSB of noise
        // (317 nA a block). The spike test's threshold is 5.5 × √1.5 × σ =
        // 2.1 µA: half of the edges of 34 µA are seen, all from ~55 µA.
        for seed in 0..200 {
            let mut noise = Noise(seed);
            let b = calibrate(&plan, |i| {
                let spike = if i == 10 { -4_500.0 } else { 0.0 };
                [spike + 317.0 * noise.gauss(), 317.0 * noise.gauss()]
            });
            let r = b.analyse(&cfg(), &plan);
            assert_eq!(r, Err(CalibrationRefusal::Step), "seed {seed}");
        }
        // A cloud over 5 µA of ambient (to 1 µA): −250 nA hides in the
        // same noise and moves the mean by ~6 nA: calibrated.
        let mut noise = Noise(7);
        let b = calibrate(&plan, |i| {
            let spike = if i == 10 { -250.0 } else { 0.0 };
            [spike + 317.0 * noise.gauss(), 317.0 * noise.gauss()]
        });
        let out = b.analyse(&cfg(), &plan).expect("a small cloud is harmless");
        assert!(out.baseline.i1_na.abs() <= 150, "{:?}", out.baseline);
    }

    #[test]
    fn no_false_refusals_over_many_seeds() {
        let plan = plan(&cfg());
        for seed in 100..1_100u64 {
            let mut noise = Noise(seed);
            let b = calibrate(&plan, |_| [317.0 * noise.gauss(), 317.0 * noise.gauss()]);
            let r = b.analyse(&cfg(), &plan);
            assert!(r.is_ok(), "seed {seed}: {r:?} after {} blocks", b.len());
        }
    }

    #[test]
    fn the_shift_guard_allows_a_quarter_of_the_onset() {
        let c = cfg();
        assert_eq!(allowed_shift_na(&c), 250);
        let old = Baseline {
            i1_na: 120,
            i2_na: -40,
        };
        // The same dry face within the noise: accepted.
        let same = Baseline {
            i1_na: 370,
            i2_na: 200,
        };
        assert_eq!(check_shift(Some(old), same, &c), Ok(()));
        // A film starting: +354 nA on I1.
        let film = Baseline {
            i1_na: 474,
            i2_na: -40,
        };
        let e = check_shift(Some(old), film, &c).unwrap_err();
        assert_eq!(
            (e.old, e.new, e.allowed_na, e.shift_na()),
            (old, film, 250, 354)
        );
        // Channel 2 alone, downwards (an LED that lost output).
        let dim = Baseline {
            i1_na: 120,
            i2_na: -300,
        };
        assert_eq!(check_shift(Some(old), dim, &c).unwrap_err().shift_na(), 260);
        // Nothing stored: the first calibration is not compared with zero.
        assert_eq!(check_shift(None, film, &c), Ok(()));
        // The extremes neither overflow nor panic.
        let far = Baseline {
            i1_na: i32::MIN,
            i2_na: i32::MAX,
        };
        let e = check_shift(
            Some(far),
            Baseline {
                i1_na: i32::MAX,
                i2_na: i32::MIN,
            },
            &c,
        );
        assert_eq!(e.unwrap_err().shift_na(), u32::MAX);
        // The smallest onset still allows something.
        let tight = Config {
            onset_rise_na: 50,
            ..cfg()
        };
        assert_eq!(allowed_shift_na(&tight), 12);
    }

    #[test]
    fn absurd_values_never_panic() {
        let plan = plan(&cfg());
        let b = blocks((0..64).map(|i| {
            if i % 2 == 0 {
                [f64::from(i32::MAX), f64::from(i32::MIN)]
            } else {
                [f64::from(i32::MIN), f64::from(i32::MAX)]
            }
        }));
        assert!(b.analyse(&cfg(), &plan).is_err());
        let mut full = Blocks::new();
        for _ in 0..CAL_MAX_BLOCKS {
            assert!(full.push([1, 1]));
        }
        assert!(!full.push([1, 1]));
        assert!(Blocks::new().analyse(&cfg(), &plan).is_err());
    }
}
