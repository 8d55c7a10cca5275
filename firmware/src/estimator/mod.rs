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
pub mod filter;
pub mod gain_bank;
mod grid;
pub mod params;
#[rustfmt::skip]
pub mod table;

use fois_protocol::{IceEstimate, Medium};

pub use filter::MAX_PENDING;
pub use gain_bank::{GAIN_REF_TEMP_C, GAINS, Gain, UNKNOWN_GAIN_SD};
pub use params::EstimatorParams;

use grid::Grid;

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

fn table_of(k: usize) -> &'static [TableEntry; ROWS] {
    match k {
        0 => &table::WATER,
        1 => &table::GLAZED,
        _ => &table::RIME,
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

/// Thickness of row `i`, mm.
#[inline]
fn row_mm(i: usize) -> f32 {
    (i + 1) as f32 * STEP_MM
}
