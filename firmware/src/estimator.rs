//! The ice estimator: thickness ± σ and the medium (dry, water, glazed, rime)
//! from the two baseline-corrected currents and the air temperature, every
//! frame. A grid Bayes filter over thickness × medium plus a dry state, with
//! the response table of the simulator's Monte Carlo (thesis §5.4) as its
//! measurement model. `no_std`, no heap, `f32`, never panics on data.
//!
//! # Model
//!
//! State: *dry* (thickness 0) or medium k ∈ {water, glazed, rime} at
//! thickness dᵢ = (i + 1) · 0.1 mm, i < 150 (the table's rows).
//!
//! Measurement (thesis §5.4): x = (I1, I2) ~ N(μ_k(d), C_k(d)) with
//! C_k(d) = Σ_k(d) + R + g² μ_k(d) μ_k(d)ᵀ: Σ_k from the table (the spread
//! *between* accretions), R the measurement noise and baseline uncertainty,
//! g the relative uncertainty of the gain calibration (LED flux,
//! responsivity). The dry face reads x ~ N(0, R) (Sensor B, thesis §5.2.1).
//!
//! Temperature (thesis §5.2.3, §6.2: water reads like glazed ice, only a
//! second modality separates them): ice is plausible at T ≤ `ice_max_c`,
//! water at T ≥ `water_min_c`, as logistic factors of width `temp_scale_c`.
//! `None` (a failed NTC) gives no temperature evidence.
//!
//! Transitions over a frame of Δt: ice grows at a rate uniform in
//! [0, `max_growth_mm_per_h`] and shrinks (melts, evaporates) at up to
//! `max_shrink_mm_per_h` (a lattice walk of one row at a time, dry being
//! row −1 of every medium, so a new accretion starts at 0.1 mm), sheds to dry
//! at `shed_per_h`, and switches medium at the same thickness at
//! `switch_per_h` (water freezing to glaze, glaze thawing to water, …).
//!
//! # Persistent errors: one observation's worth of evidence
//!
//! Σ_k(d) is the spread between accretions: the surface tilt is drawn once
//! per accretion, the bubbles are frozen in. Within one accretion the
//! deviation x − μ_k(d) persists frame after frame (10 Hz, while the ice
//! grows ~0.0001 mm per frame). Multiplying the per-frame likelihoods as if
//! they were independent would count the same deviation thousands of times
//! and collapse the posterior onto a confident, wrong thickness.
//!
//! So the filter forgets (exponential forgetting, "tempered" likelihood):
//!
//! ```text
//! ℓ_t(c) = α · ln p̂_t(c) + (1 − α) · [ln L_t(c) + ln f_T(c) + ln π(c)],   α = exp(−Δt / τ)
//! ```
//!
//! with p̂ the prediction through the transitions and π the prior. For a face
//! that does not change, ℓ converges to ln π + ln L(x̄) + ln f_T: the
//! posterior of **one** observation x̄ (the exponentially weighted mean of the
//! last ~τ of frames, which also averages the frame noise) — the Bayes
//! posterior whose spread the Monte Carlo Σ describes, so its σ is honest
//! when the table is. The first valid frame enters with full weight (a node
//! reset with ice on its face has an estimate at once). Transitions still
//! act: a cell that no transition can reach holds exactly zero probability
//! (ice cannot appear 8 mm thick out of nothing), and over τ the posterior
//! can move by about the largest growth or shrink rate times τ.
//!
//! Frames without currents (saturated, invalid, an outlier that fits no
//! state) still predict and forget: the estimate widens instead of freezing.

pub(crate) mod fast_math;
mod grid;
#[rustfmt::skip]
pub mod table;

use grid::{Grid, Moments, Shared};

use fois_protocol::{IceEstimate, Medium};

/// One row of the response table: mean and spread of (I1, I2) at one
/// thickness of one medium, in fixed point (10 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TableEntry {
    /// Mean μ of I1, I2, nA.
    pub mu_na: [u16; 2],
    /// Standard deviation of I1, I2, nA.
    pub sd_na: [u16; 2],
    /// Correlation of I1 and I2, × 32767.
    pub rho_q15: i16,
}

impl TableEntry {
    /// A row (the generated table is written with this).
    pub const fn new(mu1_na: u16, mu2_na: u16, sd1_na: u16, sd2_na: u16, rho_q15: i16) -> Self {
        TableEntry {
            mu_na: [mu1_na, mu2_na],
            sd_na: [sd1_na, sd2_na],
            rho_q15,
        }
    }
}

/// Rows per medium (thicknesses 0.1 … 15.0 mm).
pub const ROWS: usize = table::ROWS;
/// Thickness step between rows, mm.
pub const STEP_MM: f32 = table::STEP_UM as f32 / 1000.0;
/// The media of the grid, in table order.
pub const MEDIA: [Medium; 3] = [Medium::Water, Medium::Glazed, Medium::Rime];
/// Prior probability of the dry face; the three media share the rest.
const PRIOR_DRY: f32 = 0.25;
/// Largest Δt one step accepts, s (longer gaps count as this).
const MAX_DT_S: f32 = 86_400.0;
/// Largest |current| that counts as a measurement, µA (far beyond the
/// 330 µA full scale of the default front end).
const MAX_CURRENT_UA: f32 = 10_000.0;

fn table_of(k: usize) -> &'static [TableEntry; ROWS] {
    match k {
        0 => &table::WATER,
        1 => &table::GLAZED,
        _ => &table::RIME,
    }
}

/// The estimator's settings. Library settings with documented defaults (the
/// board and the virtual node pass them); they are not part of the protocol
/// `Config`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorParams {
    /// Forgetting time constant τ, s: the posterior carries about one
    /// observation's worth of the last τ of frames (default 30 s).
    pub forget_time_s: f32,
    /// Largest accretion rate, mm/h (default 10: severe in-cloud icing).
    pub max_growth_mm_per_h: f32,
    /// Largest melting / evaporation rate, mm/h (default 5).
    pub max_shrink_mm_per_h: f32,
    /// Rate of shedding (the whole layer falls off), per hour (default 0.5).
    pub shed_per_h: f32,
    /// Rate of a change of medium at the same thickness, per hour (default 0.5).
    pub switch_per_h: f32,
    /// Measurement noise and baseline uncertainty of I1, I2 (standard
    /// deviation), µA (default 0.15 µA: ~2 ADC steps at 10 kΩ; covers the
    /// frame noise, the worst mains-flicker residual after averaging, and a
    /// baseline drift).
    pub noise_ua: [f32; 2],
    /// Relative standard deviation of the gain calibration (LED flux ×
    /// responsivity against the simulator's absolute scale) (default 0.02).
    pub gain_sd: f32,
    /// Ice is plausible up to this air temperature, °C (default +1.0: the
    /// NTC's ±0.5 K and ice that is still melting).
    pub ice_max_c: f32,
    /// Water is plausible down to this air temperature, °C (default −1.0).
    pub water_min_c: f32,
    /// Width of both temperature transitions, K (default 0.5).
    pub temp_scale_c: f32,
    /// Scale of the prior of a water film's thickness, mm: films drain, so
    /// P(d) ∝ exp(−d / scale) (default 1.0 mm). Ice has a flat prior.
    pub water_scale_mm: f32,
    /// A frame whose currents are further than this squared Mahalanobis
    /// distance from every state fits no state and is skipped (default 50:
    /// p ≈ 10⁻¹¹ for a correct model).
    pub outlier_distance2: f32,
    /// The filter updates once per this period on the robust mean of the
    /// frames gathered in it, s (default 1.0: ten frames at 10 Hz; the
    /// alarm rule still runs every frame).
    pub update_period_s: f32,
    /// Memory of the gain's evidence, s of frames that tell the gain
    /// hypotheses apart (default 3600: one accretion's deviations persist
    /// along it, so the evidence is one observation's worth per hour).
    pub gain_memory_s: f32,
    /// Smallest relative gain spread within one gain hypothesis (default
    /// 0.02): a calibrated gain's hypotheses lie close together, each with
    /// at least this spread, so that none alone claims the ice is where the
    /// table's narrowest states sit (thick rime reads like 2 mm of rime at
    /// a few per cent more gain).
    pub gain_within_min: f32,
}

impl Default for EstimatorParams {
    fn default() -> Self {
        EstimatorParams {
            forget_time_s: 30.0,
            max_growth_mm_per_h: 10.0,
            max_shrink_mm_per_h: 5.0,
            shed_per_h: 0.5,
            switch_per_h: 0.5,
            noise_ua: [0.15, 0.15],
            gain_sd: 0.02,
            ice_max_c: 1.0,
            water_min_c: -1.0,
            temp_scale_c: 0.5,
            water_scale_mm: 1.0,
            outlier_distance2: 50.0,
            update_period_s: 1.0,
            gain_memory_s: 3600.0,
            gain_within_min: 0.02,
        }
    }
}

/// `x` if finite and within `lo..=hi`, else `default`.
fn within(x: f32, lo: f32, hi: f32, default: f32) -> f32 {
    if x.is_finite() && x >= lo && x <= hi {
        x
    } else {
        default
    }
}

impl EstimatorParams {
    /// Every field in its valid range; a field that is not (NaN, negative,
    /// absurd) takes its default.
    pub fn sanitized(self) -> Self {
        let d = EstimatorParams::default();
        EstimatorParams {
            forget_time_s: within(self.forget_time_s, 0.1, 86_400.0, d.forget_time_s),
            max_growth_mm_per_h: within(
                self.max_growth_mm_per_h,
                0.0,
                1_000.0,
                d.max_growth_mm_per_h,
            ),
            max_shrink_mm_per_h: within(
                self.max_shrink_mm_per_h,
                0.0,
                1_000.0,
                d.max_shrink_mm_per_h,
            ),
            shed_per_h: within(self.shed_per_h, 0.0, 3_600.0, d.shed_per_h),
            switch_per_h: within(self.switch_per_h, 0.0, 3_600.0, d.switch_per_h),
            noise_ua: [
                within(self.noise_ua[0], 0.001, 100.0, d.noise_ua[0]),
                within(self.noise_ua[1], 0.001, 100.0, d.noise_ua[1]),
            ],
            gain_sd: within(self.gain_sd, 0.0, 1.0, d.gain_sd),
            ice_max_c: within(self.ice_max_c, -50.0, 50.0, d.ice_max_c),
            water_min_c: within(self.water_min_c, -50.0, 50.0, d.water_min_c),
            temp_scale_c: within(self.temp_scale_c, 0.01, 20.0, d.temp_scale_c),
            water_scale_mm: within(self.water_scale_mm, 0.01, 1_000.0, d.water_scale_mm),
            outlier_distance2: within(self.outlier_distance2, 1.0, 1.0e6, d.outlier_distance2),
            update_period_s: within(self.update_period_s, 0.0, 60.0, d.update_period_s),
            gain_memory_s: within(self.gain_memory_s, 1.0, 1.0e7, d.gain_memory_s),
            gain_within_min: within(self.gain_within_min, 0.0, 0.5, d.gain_within_min),
        }
    }
}

/// What the last [`Estimator::step`] did with its frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Update {
    /// No valid frame yet: no estimate.
    Waiting,
    /// The first valid frame set the posterior.
    Initialised,
    /// Predicted, then updated with the currents.
    Measured,
    /// Predicted only: no currents (invalid or saturated frame).
    NoCurrents,
    /// Predicted only: the currents fit no state (further than
    /// `outlier_distance2` from all of them).
    Outlier,
}

/// The posterior in full precision (tests, evaluation, the host's replay).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Posterior {
    /// Posterior mean thickness over every state (dry counts 0), mm.
    pub thickness_mm: f32,
    /// Posterior standard deviation of the thickness, mm (includes the
    /// 0.1 mm grid: a row stands for ±0.05 mm).
    pub sigma_mm: f32,
    /// Probability of dry, water, glazed, rime.
    pub p_medium: [f32; 4],
}

impl Posterior {
    /// The most likely medium and its probability.
    pub fn medium(&self) -> (Medium, f32) {
        let all = [Medium::Dry, Medium::Water, Medium::Glazed, Medium::Rime];
        let mut best = (Medium::Dry, self.p_medium[0]);
        for (m, &p) in all.iter().zip(&self.p_medium).skip(1) {
            if p > best.1 {
                best = (*m, p);
            }
        }
        best
    }

    /// As the protocol carries it (µm and ‰, saturating).
    pub fn ice_estimate(&self) -> IceEstimate {
        let (medium, p) = self.medium();
        IceEstimate {
            thickness_um: to_u16(self.thickness_mm * 1000.0),
            sigma_um: to_u16(self.sigma_mm * 1000.0),
            medium,
            probability_permille: to_u16(p * 1000.0).min(1000),
        }
    }
}

fn to_u16(x: f32) -> u16 {
    if x.is_nan() || x <= 0.0 {
        0
    } else if x >= 65_535.0 {
        u16::MAX
    } else {
        (x + 0.5) as u16
    }
}

/// ln(1 + eˣ), without overflow.
fn softplus(x: f32) -> f32 {
    if x > 20.0 {
        x
    } else {
        fast_math::ln(1.0 + fast_math::exp(x))
    }
}

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
/// Most frames averaged into one update.
pub const MAX_PENDING: usize = 16;
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

/// The estimator: a bank of [`GAINS`] grid filters, one per hypothesis of
/// the optical gain, weighted by how well each foresaw the currents.
#[derive(Debug, Clone)]
pub struct Estimator {
    params: EstimatorParams,
    grids: [Grid; GAINS],
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
    weights: [f32; GAINS],
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
        let mut est = Estimator {
            params,
            grids: [const { Grid::new() }; GAINS],
            ln_gains: [0.0; GAINS],
            gain_step: GAIN_STEP_MAX,
            prior: (0.0, UNKNOWN_GAIN_SD),
            evidence: [0.0; GAINS],
            evidence_started: false,
            tempco_per_k: 0.0,
            tempco_sd_per_k: 0.0,
            optics_temp_c: None,
            water_log_norm: fast_math::ln(if sum > 0.0 { sum } else { 1.0 }),
            air_temp_c: None,
            pending: [[0.0; 2]; MAX_PENDING],
            pending_n: 0,
            pending_negative: 0,
            pending_dt_s: 0.0,
            update: Update::Waiting,
            posterior: None,
            weights: [0.0; GAINS],
        };
        est.set_gain_prior(1.0, UNKNOWN_GAIN_SD);
        est
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
        self.evidence = [0.0; GAINS];
        self.evidence_started = false;
        self.air_temp_c = None;
        self.clear_pending();
        self.update = Update::Waiting;
        self.posterior = None;
        self.weights = self.prior_weights();
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
        self.update = Update::Initialised;
        self.summarise();
    }

    /// Set the gain's prior: `gain` relative to the table (at
    /// [`GAIN_REF_TEMP_C`]) with relative standard deviation `sd` (0.02 for a
    /// calibrated gain, [`UNKNOWN_GAIN_SD`] for none). The hypotheses are
    /// centred on it, spaced by its standard deviation (within
    /// 0.01 … 0.153 in ln g); what the frames had taught about the gain is
    /// forgotten. Values out of range (gain outside 0.1 … 10, NaN) leave
    /// the prior unknown.
    pub fn set_gain_prior(&mut self, gain: f32, sd: f32) {
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
        if self.posterior.is_some() {
            self.summarise();
        }
    }

    /// Forget the gain: back to the unknown prior 1 ± [`UNKNOWN_GAIN_SD`].
    pub fn reset_gain(&mut self) {
        self.set_gain_prior(1.0, UNKNOWN_GAIN_SD);
    }

    /// The gain's prior (gain at [`GAIN_REF_TEMP_C`], relative sd).
    pub fn gain_prior(&self) -> (f32, f32) {
        (fast_math::exp(self.prior.0), self.prior.1)
    }

    /// The temperature model of the gain: g(T) = g₂₅ · exp(κ (T − 25 °C))
    /// with κ = `tempco_ppm_per_k` · 10⁻⁶ (clamped to ±5 %/K) applied to
    /// the currents, and its uncertainty (documentation of the residual the
    /// gain state absorbs).
    pub fn set_temperature_model(&mut self, tempco_ppm_per_k: i32, sd_ppm_per_k: u32) {
        self.tempco_per_k =
            (tempco_ppm_per_k as f32 * 1e-6).clamp(-MAX_TEMPCO_PER_K, MAX_TEMPCO_PER_K);
        self.tempco_sd_per_k = (sd_ppm_per_k as f32 * 1e-6).min(MAX_TEMPCO_PER_K);
    }

    /// The temperature of the optoelectronics (LED, phototransistors: the
    /// MCU's die sensor beside them), °C; `None` keeps the last one.
    pub fn set_optics_temp_c(&mut self, t_c: Option<f32>) {
        if let Some(t) = t_c.filter(|t| t.is_finite()) {
            self.optics_temp_c = Some(t.clamp(-60.0, 150.0));
        }
    }

    /// The gain factor the temperature model applies now: exp(κ (T − 25 °C))
    /// (1 without a temperature).
    pub fn compensation(&self) -> f32 {
        match self.optics_temp_c {
            Some(t) => fast_math::exp(self.tempco_per_k * (t - GAIN_REF_TEMP_C)),
            None => 1.0,
        }
    }

    /// The gain estimate (the mixture of the hypotheses, at the
    /// temperature now); `None` before the first valid frame.
    pub fn gain(&self) -> Option<Gain> {
        self.posterior?;
        let (mut m, mut m2) = (0.0f32, 0.0f32);
        for (w, l) in self.weights.iter().zip(self.ln_gains) {
            m += w * l;
            m2 += w * l * l;
        }
        // The spread of the weights, and the width of one hypothesis' cell.
        let cell = self.gain_step * (1.0 / 3.464_102); // spacing / √12
        let var = (m2 - m * m).max(0.0) + cell * cell;
        Some(Gain {
            gain: fast_math::exp(m) * self.compensation(),
            sigma: fast_math::sqrt(var),
        })
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

    /// The weight of each gain hypothesis (sums to 1).
    pub fn gain_weights(&self) -> &[f32; GAINS] {
        &self.weights
    }

    /// The gain hypotheses (at [`GAIN_REF_TEMP_C`]).
    pub fn gain_hypotheses(&self) -> [f32; GAINS] {
        self.ln_gains.map(fast_math::exp)
    }

    /// Weight of the two outermost hypotheses: near 1, the gain may lie
    /// beyond the range the bank covers.
    pub fn gain_outside(&self) -> f32 {
        self.weights.first().copied().unwrap_or(0.0) + self.weights.last().copied().unwrap_or(0.0)
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
    /// (dry, [medium][row]) (tests, plots).
    pub fn cells(&self) -> (f32, &[[f32; ROWS]; 3]) {
        let mut best = 0;
        for (j, w) in self.weights.iter().enumerate() {
            if *w > self.weights.get(best).copied().unwrap_or(0.0) {
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
        let within = self.within_gain_sd();
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
        }
    }

    /// Gain spread within one hypothesis (ln g): the calibration's
    /// `gain_sd` and half the spacing to the neighbours.
    fn within_gain_sd(&self) -> f32 {
        let h = self.gain_step * (1.0 / 3.464_102); // spacing / √12
        let sd = fast_math::sqrt(self.params.gain_sd * self.params.gain_sd + h * h);
        sd.max(self.params.gain_within_min)
    }

    /// The gain of hypothesis `j` now: its ln g and the temperature model.
    fn gains_now(&self) -> [f32; GAINS] {
        let c = self.compensation();
        self.ln_gains.map(|l| fast_math::exp(l) * c)
    }

    fn prior_weights(&self) -> [f32; GAINS] {
        let (m, sd) = self.prior;
        let mut w = self.ln_gains.map(|l| {
            let z = (l - m) / sd;
            fast_math::exp(-0.5 * z * z)
        });
        normalise(&mut w);
        w
    }

    /// The first frame with currents that fit some state sets every grid
    /// with full weight.
    #[inline(never)]
    fn initialise(&mut self, x: [f32; 2]) -> Option<IceEstimate> {
        let shared = self.shared();
        let gains = self.gains_now();
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
        let shared = self.shared();
        let gains = self.gains_now();
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
        let mut best = 0;
        for (j, w) in self.weights.iter().enumerate() {
            if *w > self.weights.get(best).copied().unwrap_or(0.0) {
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
    }

    /// Each hypothesis' evidence: the forgetful mean of its ln predictive
    /// likelihood, with memory `gain_memory_s` counted in frames that tell
    /// the hypotheses apart (a dry face tells nothing: the learned gain
    /// stays). The first frame counts fully.
    fn learn_gain(&mut self, dt_s: f32, ln_z: &[f32; GAINS]) {
        let mut hi = f32::NEG_INFINITY;
        let mut lo = f32::INFINITY;
        for &l in ln_z {
            hi = hi.max(l);
            lo = lo.min(l);
        }
        if !hi.is_finite() {
            return;
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
            let a = fast_math::one_minus_exp_neg(dt_s * info / self.params.gain_memory_s);
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
        self.follow();
    }

    /// The gain left the hypotheses' range (an LED failing after a
    /// calibration, a face fouling, a gain beyond 0.63 … 1.58): when an
    /// outermost hypothesis holds more than 35 % of the weight, the bank moves
    /// its centre there and doubles its spread (up to the unknown prior's);
    /// the evidence starts again, the grids keep what they hold.
    fn follow(&mut self) {
        let first = self.weights.first().copied().unwrap_or(0.0);
        let last = self.weights.last().copied().unwrap_or(0.0);
        if first.max(last) <= FOLLOW_EDGE_WEIGHT {
            return;
        }
        let mut m = 0.0f32;
        for (w, l) in self.weights.iter().zip(self.ln_gains) {
            m += w * l;
        }
        let sd = (2.0 * self.prior.1).min(UNKNOWN_GAIN_SD);
        let g = fast_math::exp(m);
        if (0.1..=10.0).contains(&g) {
            self.set_gain_prior(g, sd);
        }
    }

    /// The output posterior: the weighted mixture of the grids'.
    fn summarise(&mut self) {
        let shared = self.shared();
        let mut parts = [None; GAINS];
        for (p, g) in parts.iter_mut().zip(self.grids.iter()) {
            *p = g.summarise(&shared);
        }
        let post = Moments::mixture(
            parts
                .iter()
                .zip(self.weights)
                .filter_map(|(m, w)| m.map(|m| (w, m))),
        );
        if post.is_none() {
            // A state that cannot be normalised (never expected) restarts
            // the filter rather than report nonsense.
            let update = self.update;
            self.reset();
            self.update = update;
        }
        self.posterior = post;
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

/// Thickness of row `i`, mm.
#[inline]
fn row_mm(i: usize) -> f32 {
    (i + 1) as f32 * STEP_MM
}
