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

//! # Files
//!
//! The files import in one direction: [`filter`] (the [`Estimator`] and its
//! driver: frames, updates, the history's parts) reads [`gain_bank`], `grid`,
//! `grid_summary`, [`history`], [`posterior`], [`response`], [`params`];
//! [`output`] (the posterior, the icing rate, period and state) and
//! `gain_settings` (the gain's prior and temperature model as API) add
//! methods to the [`Estimator`] and read [`filter`] (which reads neither);
//! `grid_summary` (a grid's moments, the mixture, the history's likelihood)
//! reads `grid` (the grid filter: predict, update), which reads the response
//! table through [`response`] and [`table_entry`]; [`history`] (the growth
//! history: thickness × rate × growing/paused; its stages, its look, its
//! marginal — with `history/predict.rs`, its transitions, and
//! `history/rate.rs`, the icing rate read out) reads [`params`],
//! [`response`] and `change` (the change look: the currents' windows
//! against paused and growing states, and a fall to a dry face's reading);
//! the generated [`table`]
//! reads only [`table_entry`]. This file declares them and re-exports their
//! items.

mod change;
pub(crate) mod fast_math;
pub mod filter;
pub mod gain_bank;
mod gain_settings;
mod grid;
mod grid_summary;
pub mod history;
pub mod output;
pub mod params;
pub mod posterior;
pub mod response;
#[rustfmt::skip]
pub mod table;
pub mod table_entry;

pub use filter::{Estimator, MAX_PENDING};
pub use gain_bank::{GAIN_REF_TEMP_C, GAINS, Gain, UNKNOWN_GAIN_SD};
pub use history::{RATE_BINS, RATE_MAX_MM_PER_H, RATE_MIN_MM_PER_H, Rate};
pub use output::{ACCRETING_OFF, ACCRETING_ON, IcingState};
pub use params::{EstimatorParams, HistoryParams};
pub use posterior::{Posterior, Update};
pub use response::{MEDIA, ROWS, STEP_MM};
pub use table_entry::TableEntry;
