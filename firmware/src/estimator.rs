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

mod fast_math;
#[rustfmt::skip]
pub mod table;

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
/// Most lattice sub-steps of one prediction (a frame period of up to ~2 h at
/// the default rates keeps its full movement; longer ones move less).
const MAX_SUBSTEPS: u32 = 512;
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

/// Covariance C = Σ + R + g²μμᵀ of a state, nA² (c₁₁, c₁₂, c₂₂), and μ, nA.
#[inline(always)]
fn covariance(e: &TableEntry, r_na2: [f32; 2], g2: f32) -> ([f32; 2], [f32; 3]) {
    let mu = [f32::from(e.mu_na[0]), f32::from(e.mu_na[1])];
    let s1 = f32::from(e.sd_na[0]);
    let s2 = f32::from(e.sd_na[1]);
    let rho = f32::from(e.rho_q15) * (1.0 / 32767.0);
    let c11 = s1 * s1 + r_na2[0] + g2 * mu[0] * mu[0];
    let c22 = s2 * s2 + r_na2[1] + g2 * mu[1] * mu[1];
    let c12 = rho * s1 * s2 + g2 * mu[0] * mu[1];
    (mu, [c11, c12, c22])
}

/// det C, never below r₁r₂ (|ρ| < 1 and R > 0 make it so; rounding may not).
#[inline(always)]
fn det(c: [f32; 3], r_na2: [f32; 2]) -> f32 {
    let d = c[0] * c[2] - c[1] * c[1];
    let floor = r_na2[0] * r_na2[1];
    if d > floor { d } else { floor }
}

/// Squared Mahalanobis distance of `x` from N(μ, C), nA.
#[inline(always)]
fn distance2(x: [f32; 2], mu: [f32; 2], c: [f32; 3], det: f32) -> f32 {
    let e1 = x[0] - mu[0];
    let e2 = x[1] - mu[1];
    (c[2] * e1 * e1 - 2.0 * c[1] * e1 * e2 + c[0] * e2 * e2) / det
}

/// What stays fixed between frames for a given set of parameters: the
/// measurement noise and gain terms, and ½ ln det C of every state.
#[derive(Debug, Clone)]
struct Model {
    r_na2: [f32; 2],
    g2: f32,
    half_ln_det_dry: f32,
    half_ln_det: [[f32; ROWS]; 3],
}

impl Model {
    #[inline(never)]
    fn new(p: &EstimatorParams) -> Self {
        let r_na2 = [
            (p.noise_ua[0] * 1000.0) * (p.noise_ua[0] * 1000.0),
            (p.noise_ua[1] * 1000.0) * (p.noise_ua[1] * 1000.0),
        ];
        let g2 = p.gain_sd * p.gain_sd;
        let mut half_ln_det = [[0.0; ROWS]; 3];
        for (k, row) in half_ln_det.iter_mut().enumerate() {
            for (h, e) in row.iter_mut().zip(table_of(k).iter()) {
                let (_, c) = covariance(e, r_na2, g2);
                *h = 0.5 * fast_math::ln(det(c, r_na2));
            }
        }
        Model {
            r_na2,
            g2,
            half_ln_det_dry: 0.5 * fast_math::ln(r_na2[0] * r_na2[1]),
            half_ln_det,
        }
    }

    /// ln N(x; μ, C) + ln 2π of row `i` of medium `k`, and the squared distance.
    #[inline(always)]
    fn log_lik(&self, x: [f32; 2], e: &TableEntry, half_ln_det: f32) -> (f32, f32) {
        let (mu, c) = covariance(e, self.r_na2, self.g2);
        let q = distance2(x, mu, c, det(c, self.r_na2));
        (-0.5 * q - half_ln_det, q)
    }

    /// `f(state, ln L, q)` for every state (dry first, then each medium's
    /// rows; `state` indexes like [`Estimator::state_mut`]). Not inlined: the
    /// rare paths (first frame, states out of reach) share this one loop.
    #[inline(never)]
    fn for_each(&self, x: [f32; 2], f: &mut dyn FnMut(usize, f32, f32)) {
        let (l, q) = self.log_lik_dry(x);
        f(0, l, q);
        for k in 0..3 {
            for (i, (e, &h)) in table_of(k)
                .iter()
                .zip(self.half_ln_det[k].iter())
                .enumerate()
            {
                let (l, q) = self.log_lik(x, e, h);
                f(1 + k * ROWS + i, l, q);
            }
        }
    }

    /// The same for the dry face: N(0, R).
    fn log_lik_dry(&self, x: [f32; 2]) -> (f32, f32) {
        let q = x[0] * x[0] / self.r_na2[0] + x[1] * x[1] / self.r_na2[1];
        (-0.5 * q - self.half_ln_det_dry, q)
    }
}

/// A state whose probability falls below this (relative to the most likely
/// one, e^−27.6) is ruled out: set to exactly zero, it returns only through
/// the transitions from a live neighbour, or when the currents fit nothing
/// else ([`REBIRTH_NATS`]). Without the cut, the forgetting would lift any
/// leak, however small, back to the level its likelihood allows within a
/// few τ — thick clear ice (which reads almost like a dry face) would seep
/// through thin water states into the posterior of a clean dry face.
const PRUNE: f32 = 1e-12;

/// Log-probability given back to states the filter had ruled out when the
/// currents fit only those (relative to the best state), nats: such a state
/// is then unlikely but reachable, and the evidence decides within ~τ.
const REBIRTH_NATS: f32 = 25.0;

/// The grid Bayes filter: one `f32` per state (~0.9 KiB) and ½ ln det C per
/// state (~0.9 KiB).
#[derive(Debug, Clone)]
pub struct Estimator {
    params: EstimatorParams,
    model: Model,
    /// Probability of each state, unnormalised (the largest is 1).
    dry: f32,
    cells: [[f32; ROWS]; 3],
    /// ln of the normalising sum of the water prior exp(−d/scale).
    water_log_norm: f32,
    initialised: bool,
    /// Air temperature of the last frame, °C (`None`: no NTC).
    air_temp_c: Option<f32>,
    update: Update,
    posterior: Option<Posterior>,
}

impl Default for Estimator {
    fn default() -> Self {
        Self::new(EstimatorParams::default())
    }
}

impl Estimator {
    /// A filter with these settings (sanitised), waiting for its first frame.
    #[inline(never)]
    pub fn new(params: EstimatorParams) -> Self {
        let params = params.sanitized();
        let mut sum = 0.0f32;
        for i in 0..ROWS {
            sum += fast_math::exp(-row_mm(i) / params.water_scale_mm);
        }
        Estimator {
            model: Model::new(&params),
            params,
            dry: 0.0,
            cells: [[0.0; ROWS]; 3],
            water_log_norm: fast_math::ln(if sum > 0.0 { sum } else { 1.0 }),
            initialised: false,
            air_temp_c: None,
            update: Update::Waiting,
            posterior: None,
        }
    }

    /// The settings in force.
    pub fn params(&self) -> &EstimatorParams {
        &self.params
    }

    /// Forget everything: the next valid frame starts afresh.
    pub fn reset(&mut self) {
        self.dry = 0.0;
        self.cells = [[0.0; ROWS]; 3];
        self.initialised = false;
        self.air_temp_c = None;
        self.update = Update::Waiting;
        self.posterior = None;
    }

    /// The face is known to be clean and dry (a dark calibration has just
    /// been taken on it): all probability on *dry*. Ice must then grow
    /// through thin layers, which the currents show, before the filter can
    /// believe in a thick one (thick clear ice reads almost like a dry face).
    pub fn set_dry(&mut self) {
        self.dry = 1.0;
        self.cells = [[0.0; ROWS]; 3];
        self.initialised = true;
        self.update = Update::Initialised;
        let _ = self.summarise();
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

    /// The filtered optical evidence of every state, unnormalised, before
    /// the prior and the temperature: (dry, [medium][row]) (tests, plots).
    pub fn cells(&self) -> (f32, &[[f32; ROWS]; 3]) {
        (self.dry, &self.cells)
    }

    /// One frame: `dt_s` since the previous frame, the baseline-corrected
    /// currents in µA (`None` for an invalid or saturated frame) and the air
    /// temperature in °C (`None` when the NTC has failed). Returns the
    /// estimate after the frame (`None` until the first valid frame).
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
        if !self.initialised {
            return if negative {
                self.initialise(None)
            } else {
                self.initialise(x)
            };
        }
        if negative {
            self.predict(dt_s);
            let alpha = fast_math::exp(-dt_s / self.params.forget_time_s);
            let (mut best_q, mut max) = (f32::INFINITY, f32::NEG_INFINITY);
            self.dry = tempered(self.dry, alpha, 0.0, None, &mut best_q, &mut max);
            for c in self.cells.iter_mut().flatten() {
                *c = tempered(*c, alpha, 0.0, None, &mut best_q, &mut max);
            }
            self.update = Update::Outlier;
            return self.exponentiate(max);
        }
        self.predict(dt_s);

        // Tempered update: ℓ = α ln p̂ + (1 − α) ln L, and the largest ℓ.
        let alpha = fast_math::exp(-dt_s / self.params.forget_time_s);
        let w = 1.0 - alpha;
        let m = &self.model;
        let mut best_q = f32::INFINITY;
        let mut max = f32::NEG_INFINITY;
        let dry_l = x.map(|x| m.log_lik_dry(x));
        self.dry = tempered(self.dry, alpha, w, dry_l, &mut best_q, &mut max);
        for k in 0..3 {
            let (cells, table, h) = (&mut self.cells[k], table_of(k), &m.half_ln_det[k]);
            for ((c, e), &h) in cells.iter_mut().zip(table.iter()).zip(h.iter()) {
                let l = if *c > 0.0 {
                    x.map(|x| m.log_lik(x, e, h))
                } else {
                    None
                };
                *c = tempered(*c, alpha, w, l, &mut best_q, &mut max);
            }
        }
        self.update = Update::NoCurrents;
        if let Some(x) = x {
            self.update = Update::Measured;
            if best_q > self.params.outlier_distance2 {
                max = self.not_reachable(x, w, max);
            }
        }
        self.exponentiate(max)
    }

    /// State `s` (0 dry, then medium k row i at 1 + k·ROWS + i).
    fn state_mut(&mut self, s: usize) -> Option<&mut f32> {
        match s.checked_sub(1) {
            None => Some(&mut self.dry),
            Some(j) => self.cells.get_mut(j / ROWS)?.get_mut(j % ROWS),
        }
    }

    /// The first frame with currents that fit some state sets the posterior
    /// with full weight.
    #[inline(never)]
    fn initialise(&mut self, x: Option<[f32; 2]>) -> Option<IceEstimate> {
        let Some(x) = x else {
            self.update = Update::Waiting;
            return None;
        };
        let mut best_q = f32::INFINITY;
        let mut max = f32::NEG_INFINITY;
        self.model.for_each(x, &mut |_, l, q| {
            best_q = best_q.min(q);
            max = max.max(l);
        });
        if best_q.is_nan() || best_q > self.params.outlier_distance2 {
            self.reset();
            return None;
        }
        let mut values = [0.0f32; 1 + 3 * ROWS];
        self.model.for_each(x, &mut |s, l, _| {
            if let Some(v) = values.get_mut(s) {
                *v = l;
            }
        });
        for (s, v) in values.iter().enumerate() {
            if let Some(c) = self.state_mut(s) {
                *c = *v;
            }
        }
        self.initialised = true;
        self.update = Update::Initialised;
        self.exponentiate(max)
    }

    /// The currents fit no state the filter holds possible. If they fit
    /// states it had ruled out, those come back with a small probability
    /// (the face changed in a way the transitions do not model: cleaned,
    /// a chunk fell off, …); if they fit no state at all, the frame is an
    /// outlier and its evidence is taken back. Returns the new largest ℓ.
    #[inline(never)]
    fn not_reachable(&mut self, x: [f32; 2], w: f32, max: f32) -> f32 {
        let limit = self.params.outlier_distance2;
        let mut fits = false;
        self.model.for_each(x, &mut |_, _, q| fits |= q <= limit);
        if !fits {
            self.update = Update::Outlier;
        }
        let floor = max - REBIRTH_NATS;
        let mut values = [0.0f32; 1 + 3 * ROWS];
        self.model.for_each(x, &mut |s, l, q| {
            if let Some(v) = values.get_mut(s) {
                // Reseed: a state out of reach that fits; outlier: take
                // back the frame's evidence (NaN marks "unchanged").
                *v = if fits {
                    if q <= limit { floor + w * l } else { f32::NAN }
                } else {
                    -w * l
                };
            }
        });
        let mut new_max = f32::NEG_INFINITY;
        for (s, v) in values.iter().enumerate() {
            if let Some(c) = self.state_mut(s) {
                if fits {
                    if *c == f32::NEG_INFINITY && !v.is_nan() {
                        *c = *v;
                    }
                } else if *c > f32::NEG_INFINITY {
                    *c += *v;
                }
                new_max = new_max.max(*c);
            }
        }
        new_max
    }

    /// Transitions over `dt_s`: growth / shrinkage (lattice walk), change of
    /// medium, shedding; one pass over the rows per sub-step. Probability is
    /// conserved.
    fn predict(&mut self, dt_s: f32) {
        if dt_s <= 0.0 {
            return;
        }
        let p = self.params;
        // Mean displacement of a rate uniform in [0, r_max] over Δt, in rows.
        let rows_per_s = 1.0 / (3600.0 * 2.0 * STEP_MM);
        let up = p.max_growth_mm_per_h * rows_per_s * dt_s;
        let down = p.max_shrink_mm_per_h * rows_per_s * dt_s;
        let n = fast_math::ceil((up + down) / 0.5).clamp(1.0, MAX_SUBSTEPS as f32);
        let u = (up / n).min(0.25);
        let v = (down / n).min(0.25);
        let shed = fast_math::one_minus_exp_neg(p.shed_per_h * dt_s / 3600.0 / n);
        let switch = fast_math::one_minus_exp_neg(p.switch_per_h * dt_s / 3600.0 / n);
        for _ in 0..n as u32 {
            self.substep(u, v, shed, switch);
        }
    }

    /// One lattice step: each row moves up with probability `u`, down with
    /// `v` (dry is row −1 of every medium: a third of its upward flow starts
    /// each medium; the top row keeps what would grow beyond it); then each
    /// row changes medium with probability `switch` (shared by the two
    /// others) and sheds with probability `shed`.
    fn substep(&mut self, u: f32, v: f32, shed: f32, switch: f32) {
        let keep = (1.0 - shed) * (1.0 - switch);
        let share = (1.0 - shed) * switch * 0.5;
        let from_dry = u * self.dry * (1.0 / 3.0);
        let mut below = [from_dry; 3]; // what flows up into the current row
        let mut to_dry = 0.0;
        for i in 0..ROWS {
            let mut new = [0.0f32; 3];
            for k in 0..3 {
                let cells = &self.cells[k];
                let here = cells[i];
                let (above, out_up) = match cells.get(i + 1) {
                    Some(&a) => (a, u * here),
                    None => (0.0, 0.0),
                };
                new[k] = here - out_up - v * here + below[k] + v * above;
                below[k] = u * here;
            }
            if i == 0 {
                to_dry = v * (self.cells[0][0] + self.cells[1][0] + self.cells[2][0]);
            }
            let [a, b, c] = new;
            self.cells[0][i] = a * keep + (b + c) * share;
            self.cells[1][i] = b * keep + (a + c) * share;
            self.cells[2][i] = c * keep + (a + b) * share;
            to_dry += (a + b + c) * shed;
        }
        self.dry += to_dry - u * self.dry;
    }

    /// p = exp(ℓ − max) for every state (the largest becomes 1), and the
    /// output posterior from it. A state that cannot be normalised (never
    /// expected) restarts the filter rather than report nonsense.
    fn exponentiate(&mut self, max: f32) -> Option<IceEstimate> {
        if !max.is_finite() {
            return self.restart();
        }
        let prune = |p: f32| if p < PRUNE { 0.0 } else { p };
        self.dry = prune(fast_math::exp(self.dry - max));
        for c in self.cells.iter_mut().flatten() {
            *c = prune(fast_math::exp_inline(*c - max));
        }
        self.summarise()
    }

    /// The output posterior: the filtered optical evidence times the static
    /// knowledge of this frame, the prior π and the temperature factors.
    /// They act at once (a film at +5 °C is never ice, not after τ) and do
    /// not accumulate from frame to frame (the air temperature persists just
    /// like the optical deviations do).
    #[inline(never)]
    fn summarise(&mut self) -> Option<IceEstimate> {
        let p = self.params;
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
        let water_ratio = fast_math::exp(-STEP_MM / p.water_scale_mm);
        let factor = [
            medium * fast_math::exp(ln_water_t - self.water_log_norm),
            ice_row * fast_math::exp(ln_ice_t),
            ice_row * fast_math::exp(ln_ice_t),
        ];
        let dry = self.dry * PRIOR_DRY;
        let mut total = dry;
        let mut p_medium = [dry, 0.0, 0.0, 0.0];
        let (mut m1, mut m2) = (0.0f32, 0.0f32);
        for (k, (cells, f)) in self.cells.iter().zip(factor).enumerate() {
            let mut row_factor = if k == 0 { water_ratio } else { 1.0 };
            let step = row_factor;
            let (mut pk, mut s1, mut s2) = (0.0f32, 0.0f32, 0.0f32);
            let mut d = STEP_MM;
            for &c in cells.iter() {
                let q = c * row_factor;
                row_factor *= step;
                pk += q;
                s1 += q * d;
                s2 += q * d * d;
                d += STEP_MM;
            }
            if let Some(slot) = p_medium.get_mut(k + 1) {
                *slot = pk * f;
            }
            total += pk * f;
            m1 += s1 * f;
            m2 += s2 * f;
        }
        if !(total.is_finite() && total > 0.0) {
            return self.restart();
        }
        let inv = 1.0 / total;
        for pm in p_medium.iter_mut() {
            *pm *= inv;
        }
        let (m1, m2) = (m1 * inv, m2 * inv);
        let var = (m2 - m1 * m1).max(0.0) + (1.0 - p_medium[0]) * STEP_MM * STEP_MM / 12.0;
        let post = Posterior {
            thickness_mm: m1,
            sigma_mm: fast_math::sqrt(var),
            p_medium,
        };
        self.posterior = Some(post);
        Some(post.ice_estimate())
    }

    fn restart(&mut self) -> Option<IceEstimate> {
        let update = self.update;
        self.reset();
        self.update = update;
        None
    }
}

/// One state's tempered update: α ln p̂ + (1 − α) ln L (ln L = 0 without
/// currents), −∞ where p̂ = 0 (a state no transition reaches stays
/// impossible). Tracks the best fit and the largest ℓ.
#[inline(always)]
fn tempered(
    pred: f32,
    alpha: f32,
    w: f32,
    lik: Option<(f32, f32)>,
    best_q: &mut f32,
    max: &mut f32,
) -> f32 {
    if pred.is_nan() || pred <= 0.0 {
        return f32::NEG_INFINITY;
    }
    let mut l = alpha * fast_math::ln_inline(pred);
    if let Some((ln_l, q)) = lik {
        l += w * ln_l;
        if q < *best_q {
            *best_q = q;
        }
    }
    if l > *max {
        *max = l;
    }
    l
}

/// Thickness of row `i`, mm.
#[inline]
fn row_mm(i: usize) -> f32 {
    (i + 1) as f32 * STEP_MM
}
