//! The estimator ([`Estimator`]) and its driver, the top of the estimator's
//! files (it reads the others, none reads it): one [`Estimator::step`] per
//! frame gathers the frames, and once per `update_period_s` predicts every
//! hypothesis' grid over the elapsed time and updates it with the frames'
//! robust mean (the first valid frame sets them at once); then the bank
//! learns the gain and the output posterior is the weighted mixture of the
//! grids'.

use fois_protocol::IceEstimate;

use super::fast_math;
use super::gain_bank::{GAINS, GainBank};
use super::grid::{self, Grid, Shared};
use super::grid_summary::Moments;
use super::history::{History, LEVELS, READY_TO_LOOK, Rate};
use super::params::{EstimatorParams, within};
use super::posterior::{Posterior, Update};
use super::response::{ROWS, STEP_MM, row_mm};

/// Prior probability of the dry face; the three media share the rest.
const PRIOR_DRY: f32 = 0.25;

/// Largest Δt one step accepts, s (longer gaps count as this).
const MAX_DT_S: f32 = 86_400.0;

/// Largest |current| that counts as a measurement, µA (far beyond the
/// 330 µA full scale of the default front end).
const MAX_CURRENT_UA: f32 = 10_000.0;

/// Most frames averaged into one update.
pub const MAX_PENDING: usize = 16;

/// `v` scaled to sum 1 (as it is when it cannot be).
fn normalised(mut v: [f32; LEVELS]) -> [f32; LEVELS] {
    let s: f32 = v.iter().sum();
    if s.is_finite() && s > 0.0 {
        for a in v.iter_mut() {
            *a /= s;
        }
    }
    v
}

/// ln(1 + eˣ), without overflow.
fn softplus(x: f32) -> f32 {
    if x > 20.0 {
        x
    } else {
        fast_math::ln(1.0 + fast_math::exp(x))
    }
}

/// The estimator: a bank of [`GAINS`] grid filters, one per hypothesis of
/// the optical gain, weighted by how well each foresaw the currents.
#[derive(Debug, Clone)]
pub struct Estimator {
    pub(super) params: EstimatorParams,
    pub(super) grids: [Grid; GAINS],
    /// The gain hypotheses, their weights and the temperature model.
    pub(super) bank: GainBank,
    /// ln of the normalising sum of the water prior exp(−d/scale).
    pub(super) water_log_norm: f32,
    /// Air temperature of the last frame, °C (`None`: no NTC).
    pub(super) air_temp_c: Option<f32>,
    /// Frames waiting for the next update (currents in nA).
    pub(super) pending: [[f32; 2]; MAX_PENDING],
    pub(super) pending_n: usize,
    /// Frames since the last update that read far below zero.
    pub(super) pending_negative: usize,
    /// Time since the last update, s.
    pub(super) pending_dt_s: f32,
    pub(super) update: Update,
    pub(super) posterior: Option<Posterior>,
    /// The growth history beside the bank.
    pub(super) history: History,
    /// The bank's P(rime) of the last summary.
    pub(super) bank_p_rime: f32,
    /// The bank's P(glazed) of the last summary.
    pub(super) bank_p_glazed: f32,
    /// The growth rate after the last step.
    pub(super) rate: Option<Rate>,
    /// The bank's likelihood gathered over parts, and the part done.
    pub(super) lik: [f32; LEVELS],
    pub(super) lik_part: u8,
    /// The icing-period flag (P(accreting) with hysteresis).
    pub(super) accreting: bool,
    /// The change looks can tell growth from a pause.
    pub(super) can_tell: bool,
    /// Time since P(accreting) was last at or below the off threshold, s.
    pub(super) since_low_s: f32,
}

impl Default for Estimator {
    fn default() -> Self {
        Self::new(EstimatorParams::default())
    }
}

impl Estimator {
    /// A filter with these settings (sanitised), waiting for its first
    /// frame, its gain unknown (1 ± [`UNKNOWN_GAIN_SD`](super::gain_bank::UNKNOWN_GAIN_SD)).
    #[inline(never)]
    pub fn new(params: EstimatorParams) -> Self {
        let params = params.sanitized();
        let mut sum = 0.0f32;
        for i in 0..ROWS {
            sum += fast_math::exp(-row_mm(i) / params.water_scale_mm);
        }
        Estimator {
            params,
            grids: [const { Grid::new() }; GAINS],
            bank: GainBank::new(),
            water_log_norm: fast_math::ln(if sum > 0.0 { sum } else { 1.0 }),
            air_temp_c: None,
            pending: [[0.0; 2]; MAX_PENDING],
            pending_n: 0,
            pending_negative: 0,
            pending_dt_s: 0.0,
            update: Update::Waiting,
            posterior: None,
            history: {
                let mut h = History::new();
                h.set_output_weight(params.history.output_weight);
                h
            },
            bank_p_rime: 0.0,
            bank_p_glazed: 0.0,
            rate: None,
            lik: [0.0; LEVELS],
            lik_part: 0,
            accreting: false,
            can_tell: true,
            since_low_s: 0.0,
        }
    }

    /// The settings in force.
    pub fn params(&self) -> &EstimatorParams {
        &self.params
    }

    /// Forget the face: the next valid frame starts afresh. The gain prior
    /// stays; what the frames had taught about the gain is forgotten.
    pub fn reset(&mut self) {
        for g in self.grids.iter_mut() {
            g.reset();
        }
        self.bank.forget_evidence();
        self.air_temp_c = None;
        self.clear_pending();
        self.update = Update::Waiting;
        self.posterior = None;
        self.history = History::new();
        self.history
            .set_output_weight(self.params.history.output_weight);
        self.lik_part = 0;
        self.rate = None;
        self.accreting = false;
        self.can_tell = true;
        self.since_low_s = 0.0;
    }

    /// The face is known to be clean and dry (a dark calibration has just
    /// been taken on it): all probability on *dry*. Ice must then grow
    /// through thin layers, which the currents show, before the filter can
    /// believe in a thick one (thick clear ice reads almost like a dry face).
    /// The gain's evidence stays.
    pub fn set_dry(&mut self) {
        for g in self.grids.iter_mut() {
            g.set_dry();
        }
        self.clear_pending();
        self.history.set_dry();
        self.update = Update::Initialised;
        self.summarise();
    }

    /// Each hypothesis' own posterior (tests, plots).
    pub fn hypothesis_posteriors(&self) -> [Option<Posterior>; GAINS] {
        let shared = self.shared();
        let mut out = [None; GAINS];
        for (o, g) in out.iter_mut().zip(self.grids.iter()) {
            *o = g
                .summarise(&shared)
                .and_then(|m| Moments::mixture(core::iter::once((1.0, m))));
        }
        out
    }

    /// What the last step did.
    pub fn last_update(&self) -> Update {
        self.update
    }

    /// The posterior after the last step (`None` before the first valid frame).
    pub fn posterior(&self) -> Option<Posterior> {
        self.posterior
    }

    /// The estimate as the protocol carries it.
    pub fn estimate(&self) -> Option<IceEstimate> {
        self.posterior.map(|p| p.ice_estimate())
    }

    /// The filtered optical evidence of every state of the most likely gain
    /// hypothesis, unnormalised, before the prior and the temperature:
    /// `(dry, [medium][row])` (tests, plots).
    pub fn cells(&self) -> (f32, &[[f32; ROWS]; 3]) {
        let weights = self.bank.weights();
        let mut best = 0;
        for (j, w) in weights.iter().enumerate() {
            if *w > weights.get(best).copied().unwrap_or(0.0) {
                best = j;
            }
        }
        let g = self.grids.get(best).unwrap_or(&self.grids[0]);
        (g.dry, &g.cells)
    }

    /// One frame: `dt_s` since the previous frame, the baseline-corrected
    /// currents in µA (`None` for an invalid or saturated frame) and the air
    /// temperature in °C (`None` when the NTC has failed). Frames are
    /// gathered and the filter updates once per `update_period_s` on their
    /// robust mean (the first valid frame at once). Returns the estimate
    /// after the frame (`None` until the first valid frame).
    pub fn step(
        &mut self,
        dt_s: f32,
        currents_ua: Option<[f32; 2]>,
        air_temp_c: Option<f32>,
    ) -> Option<IceEstimate> {
        let dt_s = within(dt_s, 0.0, MAX_DT_S, 0.0);
        let x = currents_ua
            .filter(|x| x.iter().all(|v| v.is_finite() && v.abs() <= MAX_CURRENT_UA))
            .map(|x| [x[0] * 1000.0, x[1] * 1000.0]);
        self.air_temp_c = air_temp_c
            .filter(|t| t.is_finite())
            .map(|t| t.clamp(-100.0, 200.0));
        // Below zero by more than 6σ of the noise fits no state (Sensor B
        // reads ≥ 0; the Gaussian tails of a broad state would otherwise
        // take it): e.g. a baseline taken with ice on the face.
        let r = self.params.noise_ua;
        let negative = x.is_some_and(|x| x[0] < -6000.0 * r[0] || x[1] < -6000.0 * r[1]);
        if !self.grids.iter().any(|g| g.initialised) {
            self.clear_pending();
            let x = if negative { None } else { x };
            return match x {
                Some(x) => self.initialise(x),
                None => {
                    self.update = Update::Waiting;
                    None
                }
            };
        }
        self.pending_dt_s += dt_s;
        match x {
            Some(_) if negative => self.pending_negative += 1,
            Some(x) => {
                if let Some(slot) = self.pending.get_mut(self.pending_n) {
                    *slot = x;
                    self.pending_n += 1;
                }
            }
            None => {}
        }
        if self.pending_dt_s + 1e-4 >= self.params.update_period_s || self.pending_n >= MAX_PENDING
        {
            self.run_update();
        }
        self.estimate()
    }

    fn clear_pending(&mut self) {
        self.pending_n = 0;
        self.pending_negative = 0;
        self.pending_dt_s = 0.0;
    }

    /// The robust mean of the pending frames, nA: the median per channel,
    /// frames further from it than max(6σ of the noise, 10 % of the median)
    /// dropped (a spike, a flicker burst), the mean of the rest.
    fn pending_mean(&self) -> Option<[f32; 2]> {
        let frames = self.pending.get(..self.pending_n)?;
        if frames.is_empty() {
            return None;
        }
        let mut median = [0.0f32; 2];
        for (ch, m) in median.iter_mut().enumerate() {
            let mut v = [0.0f32; MAX_PENDING];
            for (a, f) in v.iter_mut().zip(frames) {
                *a = f[ch];
            }
            let v = v.get_mut(..frames.len())?;
            v.sort_unstable_by(f32::total_cmp);
            *m = *v.get(v.len() / 2)?;
        }
        let r = self.params.noise_ua;
        let tol = [
            (6000.0 * r[0]).max(0.1 * median[0].abs()),
            (6000.0 * r[1]).max(0.1 * median[1].abs()),
        ];
        let (mut sum, mut n) = ([0.0f32; 2], 0.0f32);
        for f in frames {
            if (f[0] - median[0]).abs() <= tol[0] && (f[1] - median[1]).abs() <= tol[1] {
                sum[0] += f[0];
                sum[1] += f[1];
                n += 1.0;
            }
        }
        if n > 0.0 {
            Some([sum[0] / n, sum[1] / n])
        } else {
            Some(median)
        }
    }

    /// The shared factors of this update: noise, the within-hypothesis gain
    /// spread, prior × temperature per medium.
    pub(super) fn shared(&self) -> Shared {
        let p = &self.params;
        let (ln_water_t, ln_ice_t) = match self.air_temp_c {
            Some(t) => (
                -softplus(-(t - p.water_min_c) / p.temp_scale_c),
                -softplus(-(p.ice_max_c - t) / p.temp_scale_c),
            ),
            None => (0.0, 0.0),
        };
        // Prior: dry PRIOR_DRY; each medium (1 − PRIOR_DRY)/3, flat in
        // thickness for ice, ∝ exp(−d / scale) for water.
        let medium = (1.0 - PRIOR_DRY) / 3.0;
        let ice_row = medium / ROWS as f32;
        let within = self.bank.within_sd(&self.params);
        Shared {
            r_na2: [
                (p.noise_ua[0] * 1000.0) * (p.noise_ua[0] * 1000.0),
                (p.noise_ua[1] * 1000.0) * (p.noise_ua[1] * 1000.0),
            ],
            g2: within * within,
            dry_factor: PRIOR_DRY,
            factor: [
                medium * fast_math::exp(ln_water_t - self.water_log_norm),
                ice_row * fast_math::exp(ln_ice_t),
                ice_row * fast_math::exp(ln_ice_t),
            ],
            row_ratio: [fast_math::exp(-STEP_MM / p.water_scale_mm), 1.0, 1.0],
            temp_factor: [
                fast_math::exp(ln_water_t),
                fast_math::exp(ln_ice_t),
                fast_math::exp(ln_ice_t),
            ],
        }
    }

    /// The first frame with currents that fit some state sets every grid
    /// with full weight.
    #[inline(never)]
    fn initialise(&mut self, x: [f32; 2]) -> Option<IceEstimate> {
        let shared = self.shared();
        let gains = self.bank.gains_now();
        let mut ln_z = [f32::NEG_INFINITY; GAINS];
        let mut any = false;
        for ((g, gain), z) in self.grids.iter_mut().zip(gains).zip(ln_z.iter_mut()) {
            let s = g.initialise(x, gain, &self.params, &shared);
            if let Some(l) = s.ln_z {
                *z = l;
                any = true;
            }
        }
        if !any {
            self.reset();
            return None;
        }
        self.learn_gain(0.0, &ln_z);
        self.update = Update::Initialised;
        self.summarise();
        if !self.history.initialised {
            // The first look at full weight: the output after it is the
            // bank's (one look, not two).
            let lik = normalised(self.bank_likelihood(0..GAINS));
            self.history.initialise_from(&lik, 0.05);
        }
        self.estimate()
    }

    /// Predict over the pending time and update every grid with the pending
    /// frames' robust mean.
    #[inline(never)]
    fn run_update(&mut self) {
        let dt_s = self.pending_dt_s;
        self.since_low_s = (self.since_low_s + dt_s).min(MAX_DT_S);
        let x = self.pending_mean();
        let negative = x.is_none() && self.pending_negative > 0;
        self.clear_pending();
        // The history predicts to now before the output is formed, and
        // looks at the bank after it, in parts (`History::advance`, and the
        // bank's likelihood in three): at 10 Hz one part per update, its
        // cost spread over seconds; all at once when the updates are slow
        // (a replay of sparse frames).
        let hp = self.params.history;
        let slow = dt_s >= 1.5;
        let mut look_now = false;
        if hp.enabled && self.history.initialised {
            let x_change = if negative { None } else { x };
            let gain = self.bank.gain().gain;
            let noise_na = self.params.noise_ua.map(|s| s * 1000.0);
            self.history
                .gather_currents(dt_s, x_change, noise_na, gain, self.bank_p_rime, &hp);
            let due = self.history.gather(dt_s, hp.period_s);
            let stage = self.history.stage();
            if stage == READY_TO_LOOK {
                look_now = true;
            } else if stage != 0 || due {
                if slow {
                    self.history.finish(&hp);
                    if self.history.stage() == 0 && due {
                        self.history.advance(&hp);
                        self.history.finish(&hp);
                    }
                    look_now = self.history.stage() == READY_TO_LOOK;
                } else {
                    self.history.advance(&hp);
                }
            }
        }
        let shared = self.shared();
        let gains = self.bank.gains_now();
        if negative {
            for g in self.grids.iter_mut() {
                g.forget(dt_s, &self.params);
            }
            self.update = Update::Outlier;
            self.summarise();
            return;
        }
        let mut ln_z = [f32::NEG_INFINITY; GAINS];
        let mut all_have = x.is_some();
        let mut updates = [Update::NoCurrents; GAINS];
        for (j, (g, gain)) in self.grids.iter_mut().zip(gains).enumerate() {
            let s = if g.initialised {
                g.update(dt_s, x, gain, &self.params, &shared)
            } else {
                match x {
                    Some(x) => g.initialise(x, gain, &self.params, &shared),
                    None => grid::Step {
                        update: Update::Waiting,
                        ln_z: None,
                        best_q: f32::INFINITY,
                    },
                }
            };
            if let Some(u) = updates.get_mut(j) {
                *u = s.update;
            }
            match (s.ln_z, ln_z.get_mut(j)) {
                (Some(l), Some(z)) => *z = l,
                _ => all_have = false,
            }
        }
        // What the bank did: measured if the likely hypotheses measured.
        let weights = self.bank.weights();
        let mut best = 0;
        for (j, w) in weights.iter().enumerate() {
            if *w > weights.get(best).copied().unwrap_or(0.0) {
                best = j;
            }
        }
        self.update = updates.get(best).copied().unwrap_or(Update::NoCurrents);
        if self.update == Update::Waiting {
            self.update = Update::NoCurrents;
        }
        if all_have {
            self.learn_gain(dt_s, &ln_z);
        }
        self.summarise();
        if look_now {
            if self.update != Update::Measured {
                self.lik_part = 0;
                self.history.skip_measure();
            } else if slow {
                self.lik_part = 0;
                let lik = normalised(self.bank_likelihood(0..GAINS));
                self.history.look(&lik, self.bank_p_rime, &hp);
                self.history.finish(&hp);
            } else {
                // Three parts: half the grids, the rest, the look.
                match self.lik_part {
                    0 => {
                        self.lik = self.bank_likelihood(0..GAINS / 2);
                        self.lik_part = 1;
                    }
                    1 => {
                        let rest = self.bank_likelihood(GAINS / 2..GAINS);
                        for (a, b) in self.lik.iter_mut().zip(rest) {
                            *a += b;
                        }
                        self.lik_part = 2;
                    }
                    _ => {
                        let lik = normalised(self.lik);
                        self.history.look(&lik, self.bank_p_rime, &hp);
                        self.lik_part = 0;
                    }
                }
            }
        }
    }

    /// The bank learns the gain from each hypothesis' ln predictive
    /// likelihood; when it followed the gain out of its range, the posterior
    /// is mixed anew with the new weights.
    fn learn_gain(&mut self, dt_s: f32, ln_z: &[f32; GAINS]) {
        if self.bank.learn(dt_s, ln_z, self.params.gain_memory_s) && self.posterior.is_some() {
            self.summarise();
        }
    }

    /// The bank's thickness likelihood, gain and medium summed out, over
    /// the gain hypotheses `part` (each grid's normalised, times its
    /// weight): the history's measurement.
    fn bank_likelihood(&self, part: core::ops::Range<usize>) -> [f32; LEVELS] {
        let shared = self.shared();
        let mut lik = [0.0f32; LEVELS];
        let weights = self.bank.weights();
        for j in part {
            if let (Some(g), Some(w)) = (self.grids.get(j), weights.get(j)) {
                g.add_likelihood(&shared, *w, &mut lik);
            }
        }
        lik
    }
}
