//! The estimator ([`Estimator`]) and its driver, the top of the estimator's
//! files (it reads the others, none reads it): one [`Estimator::step`] per
//! frame gathers the frames, and once per `update_period_s` predicts every
//! hypothesis' grid over the elapsed time and updates it with the frames'
//! robust mean (the first valid frame sets them at once); then the bank
//! learns the gain and the output posterior is the weighted mixture of the
//! grids'.

use fois_protocol::{IceEstimate, IcingEstimate};

use super::fast_math;
use super::gain_bank::{GAINS, Gain, GainBank, UNKNOWN_GAIN_SD};
use super::grid::{self, Grid, Moments, Shared};
use super::history::{self, History, LEVELS, READY_TO_LOOK, Rate};
use super::params::{EstimatorParams, within};
use super::posterior::{Posterior, Update, to_u16};
use super::response::{ROWS, STEP_MM, row_mm};

/// Prior probability of the dry face; the three media share the rest.
const PRIOR_DRY: f32 = 0.25;

/// Largest Δt one step accepts, s (longer gaps count as this).
const MAX_DT_S: f32 = 86_400.0;

/// Largest |current| that counts as a measurement, µA (far beyond the
/// 330 µA full scale of the default front end).
const MAX_CURRENT_UA: f32 = 10_000.0;

/// P(accreting) above which an icing period starts.
pub const ACCRETING_ON: f32 = 0.7;

/// P(accreting) below which an icing period ends.
pub const ACCRETING_OFF: f32 = 0.3;

/// Meteorological icing as the node states it: three-valued, since where
/// the currents barely move with the thickness (thick rime or glaze) the
/// node cannot tell growth from a pause within the clearing time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IcingState {
    /// The icing period is on: ice accretes now.
    Accreting,
    /// P(accreting) ≤ [`ACCRETING_OFF`]: no ice accretes.
    NotAccreting,
    /// Neither: the evidence cannot tell (P between the thresholds, or the
    /// change looks too weak for the period to stay on).
    Uncertain,
}

impl IcingState {
    /// From the icing period's flag and P(accreting) (as carried on the
    /// wire).
    pub fn of(accreting: bool, p_accreting: f32) -> Self {
        if accreting {
            IcingState::Accreting
        } else if p_accreting <= ACCRETING_OFF {
            IcingState::NotAccreting
        } else {
            IcingState::Uncertain
        }
    }
}

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
    params: EstimatorParams,
    grids: [Grid; GAINS],
    /// The gain hypotheses, their weights and the temperature model.
    bank: GainBank,
    /// ln of the normalising sum of the water prior exp(−d/scale).
    water_log_norm: f32,
    /// Air temperature of the last frame, °C (`None`: no NTC).
    air_temp_c: Option<f32>,
    /// Frames waiting for the next update (currents in nA).
    pending: [[f32; 2]; MAX_PENDING],
    pending_n: usize,
    /// Frames since the last update that read far below zero.
    pending_negative: usize,
    /// Time since the last update, s.
    pending_dt_s: f32,
    update: Update,
    posterior: Option<Posterior>,
    /// The growth history beside the bank.
    history: History,
    /// The bank's P(rime) of the last summary.
    bank_p_rime: f32,
    /// The growth rate after the last step.
    rate: Option<Rate>,
    /// The bank's likelihood gathered over parts, and the part done.
    lik: [f32; LEVELS],
    lik_part: u8,
    /// The icing-period flag (P(accreting) with hysteresis).
    accreting: bool,
    /// The change looks can tell growth from a pause.
    can_tell: bool,
}

impl Default for Estimator {
    fn default() -> Self {
        Self::new(EstimatorParams::default())
    }
}

impl Estimator {
    /// A filter with these settings (sanitised), waiting for its first
    /// frame, its gain unknown (1 ± [`UNKNOWN_GAIN_SD`]).
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
            rate: None,
            lik: [0.0; LEVELS],
            lik_part: 0,
            accreting: false,
            can_tell: true,
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

    /// The growth rate and P(accreting) after the last step (`None` before
    /// the first valid frame, or with the history off).
    pub fn rate(&self) -> Option<Rate> {
        self.rate
    }

    /// Meteorological icing now: P(accreting) with hysteresis — set above
    /// [`ACCRETING_ON`] while the node can tell growth from a pause, cleared
    /// below [`ACCRETING_OFF`] or when it no longer can.
    pub fn accreting(&self) -> bool {
        self.accreting
    }

    /// The icing state (`None` before the first valid frame or with the
    /// history off): accreting (the icing period's flag), not accreting
    /// (P(accreting) ≤ [`ACCRETING_OFF`]), else uncertain — what a host
    /// reads from the flag and P(accreting) on the wire.
    pub fn icing_state(&self) -> Option<IcingState> {
        self.rate
            .map(|r| IcingState::of(self.accreting, r.p_accreting))
    }

    /// The icing rate as the protocol carries it (µm/h, ‰, the icing
    /// period's flag); `None` before the first valid frame or with the
    /// history off.
    pub fn icing_estimate(&self) -> Option<IcingEstimate> {
        self.rate.map(|r| IcingEstimate {
            rate_um_per_h: to_u16(r.mean_mm_per_h * 1000.0),
            sigma_um_per_h: to_u16(r.sigma_mm_per_h * 1000.0),
            accreting_permille: to_u16(r.p_accreting * 1000.0).min(1000),
            accreting: self.accreting,
        })
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
    fn shared(&self) -> Shared {
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
            self.history
                .gather_currents(dt_s, x_change, gain, self.bank_p_rime, &hp);
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

    /// The output posterior: the weighted mixture of the grids', each
    /// weighted by the history's thickness marginal (mixed with a flat
    /// share, the history's `escape`); the bank's own marginal is kept for
    /// the history's next measurement, and the rate is the history's,
    /// widened towards its prior as far as the bank's evidence falls
    /// outside what the history foresaw.
    fn summarise(&mut self) {
        let shared = self.shared();
        let hp = self.params.history;
        let use_history = hp.enabled && self.history.initialised;
        let mut h = [1.0 / LEVELS as f32; LEVELS];
        if use_history {
            let flat = hp.escape / LEVELS as f32;
            let mut top = 0.0f32;
            for (a, m) in h.iter_mut().zip(self.history.weight()) {
                *a = (1.0 - hp.escape) * m + flat;
                top = top.max(*a);
            }
            // Dry against ice stays the bank's call: the dry face weighs
            // as the history's likeliest level. Thick clear ice reads
            // almost like a dry face; weighted by a history that had shed
            // it, glaze at 10 mm/h and gain 0.85 read confidently thin in
            // 890 frames of 10 accretions.
            if let Some(d) = h.first_mut() {
                *d = top;
            }
        }
        let mut parts = [None; GAINS];
        let mut p_medium = [0.0f32; 4];
        for ((p, g), w) in parts
            .iter_mut()
            .zip(self.grids.iter())
            .zip(*self.bank.weights())
        {
            *p = g
                .summarise_weighted(&shared, &h, w, &mut p_medium)
                .map(|(m, ratio)| (w * ratio, m));
        }
        // Thickness from the product with the history; the medium from the
        // bank alone (the history weighs thickness, not medium: weighted,
        // rime's broad branch lost to glaze's narrow one between 1 and 3 mm
        // — medium right 78 % of glazed frames instead of 93 %).
        let post = Moments::mixture(parts.iter().filter_map(|m| *m)).map(|mut p| {
            let s: f32 = p_medium.iter().sum();
            if s > 0.0 {
                for (a, b) in p.p_medium.iter_mut().zip(p_medium) {
                    *a = b / s;
                }
            }
            p
        });
        if post.is_none() {
            // A state that cannot be normalised (never expected) restarts
            // the filter rather than report nonsense.
            let update = self.update;
            self.reset();
            self.update = update;
            self.posterior = None;
            return;
        }
        self.bank_p_rime = p_medium[3];
        self.posterior = post;
        self.rate = if use_history {
            // Credibility of the history: the share of the output's weight
            // its own part carries against the flat escape.
            let w = self.history.credibility();
            let (hr, pr) = (self.history.rate(), history::prior_rate());
            let mean = w * hr.mean_mm_per_h + (1.0 - w) * pr.mean_mm_per_h;
            let m2 = w
                * (hr.sigma_mm_per_h * hr.sigma_mm_per_h + hr.mean_mm_per_h * hr.mean_mm_per_h)
                + (1.0 - w)
                    * (pr.sigma_mm_per_h * pr.sigma_mm_per_h + pr.mean_mm_per_h * pr.mean_mm_per_h);
            let p_water = post.map(|p| p.p_medium[1]).unwrap_or(0.0);
            let p_acc = w * hr.p_accreting + (1.0 - w) * pr.p_accreting;
            Some(Rate {
                mean_mm_per_h: mean,
                sigma_mm_per_h: fast_math::sqrt((m2 - mean * mean).max(0.0)),
                p_accreting: (p_acc * (1.0 - p_water)).clamp(0.0, 1.0),
            })
        } else {
            None
        };
        // The icing period: P(accreting) with hysteresis, while the change
        // looks can tell growth from a pause (else "uncertain", the period
        // ends: thick rime or glaze barely moves the currents).
        self.can_tell = self
            .history
            .discern_nats(&hp)
            .is_none_or(|d| d >= hp.tell_nats);
        if let Some(r) = self.rate {
            if r.p_accreting >= ACCRETING_ON && self.can_tell {
                self.accreting = true;
            } else if r.p_accreting <= ACCRETING_OFF || !self.can_tell {
                self.accreting = false;
            }
        } else {
            self.accreting = false;
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
