//! One grid Bayes filter over thickness × medium plus a dry state, for one
//! hypothesis of the sensor's optical gain g: the response table's means and
//! spreads scaled by g (thesis §5.4: every current is proportional to the
//! LED's flux and the phototransistors' responsivity). The estimator
//! (`filter.rs`) runs several of these side by side; the tempered update,
//! the transitions and the pruning are described in the module
//! documentation (`mod.rs`).

use super::fast_math;
use super::params::EstimatorParams;
use super::posterior::Update;
use super::response::{MEDIA, ROWS, STEP_MM, table_of};
use super::table_entry::TableEntry;

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

/// Most lattice sub-steps of one prediction (a period of up to ~2 h at the
/// default rates keeps its full movement; longer ones move less).
const MAX_SUBSTEPS: u32 = 512;

/// What every grid of the bank shares for one update: the noise, the
/// within-hypothesis gain spread, and the static factors of the posterior
/// (prior × temperature) per medium.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shared {
    /// Measurement noise variance of I1, I2, nA².
    pub r_na2: [f32; 2],
    /// Relative gain variance within one hypothesis (the calibration's, and
    /// half the spacing to the next hypothesis).
    pub g2: f32,
    /// Static factor of the dry state.
    pub dry_factor: f32,
    /// Static factor of row 0 of each medium (prior × temperature).
    pub factor: [f32; 3],
    /// Ratio of one row's factor to the previous one's, per medium (the
    /// water film's exponential prior; 1 for ice).
    pub row_ratio: [f32; 3],
    /// The temperature's factor per medium without the prior (the dry
    /// face's is 1): the history measures the bank's likelihood, not its
    /// prior, which would count once per look.
    pub temp_factor: [f32; 3],
}

/// Covariance C = g²Σ + R + s²(gμ)(gμ)ᵀ of a state for gain g, nA²
/// (c₁₁, c₁₂, c₂₂), and gμ, nA.
#[inline(always)]
fn covariance(e: &TableEntry, gain: f32, r_na2: [f32; 2], g2: f32) -> ([f32; 2], [f32; 3]) {
    let mu = [gain * f32::from(e.mu_na[0]), gain * f32::from(e.mu_na[1])];
    let s1 = gain * f32::from(e.sd_na[0]);
    let s2 = gain * f32::from(e.sd_na[1]);
    let rho = f32::from(e.rho_q15) * (1.0 / 32767.0);
    let c11 = s1 * s1 + r_na2[0] + g2 * mu[0] * mu[0];
    let c22 = s2 * s2 + r_na2[1] + g2 * mu[1] * mu[1];
    let c12 = rho * s1 * s2 + g2 * mu[0] * mu[1];
    (mu, [c11, c12, c22])
}

/// ln N(x; μ, C) + ln 2π of a state, and the squared Mahalanobis distance.
#[inline(always)]
fn log_lik(x: [f32; 2], e: &TableEntry, gain: f32, s: &Shared) -> (f32, f32) {
    let (mu, c) = covariance(e, gain, s.r_na2, s.g2);
    // det C, never below r₁r₂ (|ρ| < 1 and R > 0 make it so; rounding may not).
    let floor = s.r_na2[0] * s.r_na2[1];
    let d = c[0] * c[2] - c[1] * c[1];
    let det = if d > floor { d } else { floor };
    let e1 = x[0] - mu[0];
    let e2 = x[1] - mu[1];
    let q = (c[2] * e1 * e1 - 2.0 * c[1] * e1 * e2 + c[0] * e2 * e2) / det;
    (-0.5 * q - 0.5 * fast_math::ln_inline(det), q)
}

/// The same for the dry face: N(0, R), whatever the gain.
fn log_lik_dry(x: [f32; 2], s: &Shared) -> (f32, f32) {
    let q = x[0] * x[0] / s.r_na2[0] + x[1] * x[1] / s.r_na2[1];
    (-0.5 * q - 0.5 * fast_math::ln(s.r_na2[0] * s.r_na2[1]), q)
}

/// `f(state, ln L, q)` for every state (dry first, then each medium's rows;
/// `state` indexes like [`Grid::state_mut`]). Not inlined: the rare paths
/// (first frame, states out of reach) share this one loop.
#[inline(never)]
fn for_each(x: [f32; 2], gain: f32, s: &Shared, f: &mut dyn FnMut(usize, f32, f32)) {
    let (l, q) = log_lik_dry(x, s);
    f(0, l, q);
    for k in 0..MEDIA.len() {
        for (i, e) in table_of(k).iter().enumerate() {
            let (l, q) = log_lik(x, e, gain, s);
            f(1 + k * ROWS + i, l, q);
        }
    }
}

/// What one update of a grid found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Step {
    /// What the grid did with the currents.
    pub update: Update,
    /// ln of the predictive likelihood of the currents (before the update:
    /// how well this gain hypothesis foresaw them), `None` without currents.
    pub ln_z: Option<f32>,
    /// Smallest squared distance of the currents from a live state.
    pub best_q: f32,
}

/// One grid: one `f32` per state (~1.8 KiB).
#[derive(Debug, Clone)]
pub(crate) struct Grid {
    /// Probability of each state, unnormalised (the largest is 1), before
    /// the prior and the temperature.
    pub dry: f32,
    pub cells: [[f32; ROWS]; 3],
    pub initialised: bool,
}

impl Grid {
    pub const fn new() -> Self {
        Grid {
            dry: 0.0,
            cells: [[0.0; ROWS]; 3],
            initialised: false,
        }
    }

    /// Forget everything.
    pub fn reset(&mut self) {
        *self = Grid::new();
    }

    /// All probability on a dry face.
    pub fn set_dry(&mut self) {
        self.dry = 1.0;
        self.cells = [[0.0; ROWS]; 3];
        self.initialised = true;
    }

    /// State `s` (0 dry, then medium k row i at 1 + k·ROWS + i).
    fn state_mut(&mut self, s: usize) -> Option<&mut f32> {
        match s.checked_sub(1) {
            None => Some(&mut self.dry),
            Some(j) => self.cells.get_mut(j / ROWS)?.get_mut(j % ROWS),
        }
    }

    /// The first currents that fit some state set the grid with full
    /// weight; `None` if they fit no state (the grid stays waiting).
    #[inline(never)]
    pub fn initialise(&mut self, x: [f32; 2], gain: f32, p: &EstimatorParams, s: &Shared) -> Step {
        let mut best_q = f32::INFINITY;
        let mut max = f32::NEG_INFINITY;
        for_each(x, gain, s, &mut |_, l, q| {
            best_q = best_q.min(q);
            max = max.max(l);
        });
        if best_q.is_nan() || best_q > p.outlier_distance2 || !max.is_finite() {
            self.reset();
            return Step {
                update: Update::Waiting,
                ln_z: None,
                best_q,
            };
        }
        // The predictive likelihood of a fresh grid is the prior's.
        let mut z = Predictive::new(s);
        let mut values = [0.0f32; 1 + 3 * ROWS];
        for_each(x, gain, s, &mut |st, l, _| {
            if let Some(v) = values.get_mut(st) {
                *v = l;
            }
            z.add(static_factor(s, st), l);
        });
        for (st, v) in values.iter().enumerate() {
            if let Some(c) = self.state_mut(st) {
                *c = *v;
            }
        }
        self.initialised = true;
        self.exponentiate(max);
        Step {
            update: Update::Initialised,
            ln_z: z.ln_z(),
            best_q,
        }
    }

    /// Predict over `dt_s`, then the tempered update with the currents `x`
    /// (nA; `None`: predict and forget only) under gain `gain`.
    pub fn update(
        &mut self,
        dt_s: f32,
        x: Option<[f32; 2]>,
        gain: f32,
        p: &EstimatorParams,
        s: &Shared,
    ) -> Step {
        self.predict(dt_s, p);
        // Tempered update: ℓ = α ln p̂ + (1 − α) ln L, the largest ℓ, and
        // the predictive likelihood Σ p̂·F·L / Σ p̂·F (F the static factor).
        let alpha = fast_math::exp(-dt_s / p.forget_time_s);
        let w = 1.0 - alpha;
        let mut best_q = f32::INFINITY;
        let mut max = f32::NEG_INFINITY;
        let mut z = Predictive::new(s);
        let dry_l = x.map(|x| log_lik_dry(x, s));
        if let Some((l, _)) = dry_l
            && self.dry > 0.0
        {
            z.add(self.dry * s.dry_factor, l);
        }
        self.dry = tempered(self.dry, alpha, w, dry_l, &mut best_q, &mut max);
        for k in 0..MEDIA.len() {
            let (cells, table) = (&mut self.cells[k], table_of(k));
            let mut f_row = s.factor[k] * s.row_ratio[k];
            for (c, e) in cells.iter_mut().zip(table.iter()) {
                let l = if *c > 0.0 {
                    x.map(|x| log_lik(x, e, gain, s))
                } else {
                    None
                };
                if let Some((l, _)) = l {
                    z.add(*c * f_row, l);
                }
                f_row *= s.row_ratio[k];
                *c = tempered(*c, alpha, w, l, &mut best_q, &mut max);
            }
        }
        let mut update = Update::NoCurrents;
        let mut ln_z = None;
        if let Some(x) = x {
            update = Update::Measured;
            ln_z = z.ln_z();
            if best_q > p.outlier_distance2 {
                let (m, fits) = self.not_reachable(x, gain, w, max, p, s);
                max = m;
                if !fits {
                    update = Update::Outlier;
                    ln_z = None;
                }
            }
        }
        if !self.exponentiate(max) {
            self.reset();
        }
        Step {
            update,
            ln_z,
            best_q,
        }
    }

    /// Currents below zero by far (a baseline taken with ice on the face):
    /// predict and forget, no evidence.
    pub fn forget(&mut self, dt_s: f32, p: &EstimatorParams) {
        self.predict(dt_s, p);
        let alpha = fast_math::exp(-dt_s / p.forget_time_s);
        let (mut best_q, mut max) = (f32::INFINITY, f32::NEG_INFINITY);
        self.dry = tempered(self.dry, alpha, 0.0, None, &mut best_q, &mut max);
        for c in self.cells.iter_mut().flatten() {
            *c = tempered(*c, alpha, 0.0, None, &mut best_q, &mut max);
        }
        if !self.exponentiate(max) {
            self.reset();
        }
    }

    /// The currents fit no state the grid holds possible. If they fit
    /// states it had ruled out, those come back with a small probability
    /// (the face changed in a way the transitions do not model: cleaned, a
    /// chunk fell off, …); if they fit no state at all, the frame is an
    /// outlier and its evidence is taken back. Returns the new largest ℓ
    /// and whether any state fits.
    #[inline(never)]
    fn not_reachable(
        &mut self,
        x: [f32; 2],
        gain: f32,
        w: f32,
        max: f32,
        p: &EstimatorParams,
        s: &Shared,
    ) -> (f32, bool) {
        let limit = p.outlier_distance2;
        let mut fits = false;
        for_each(x, gain, s, &mut |_, _, q| fits |= q <= limit);
        let floor = max - REBIRTH_NATS;
        let mut values = [0.0f32; 1 + 3 * ROWS];
        for_each(x, gain, s, &mut |st, l, q| {
            if let Some(v) = values.get_mut(st) {
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
        for (st, v) in values.iter().enumerate() {
            if let Some(c) = self.state_mut(st) {
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
        (new_max, fits)
    }

    /// Transitions over `dt_s`: growth / shrinkage (lattice walk), change of
    /// medium, shedding; one pass over the rows per sub-step. Probability is
    /// conserved.
    fn predict(&mut self, dt_s: f32, p: &EstimatorParams) {
        if dt_s <= 0.0 {
            return;
        }
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

    /// p = exp(ℓ − max) for every state (the largest becomes 1). False when
    /// the grid cannot be normalised (never expected).
    fn exponentiate(&mut self, max: f32) -> bool {
        if !max.is_finite() {
            return false;
        }
        let prune = |p: f32| if p < PRUNE { 0.0 } else { p };
        self.dry = prune(fast_math::exp(self.dry - max));
        for c in self.cells.iter_mut().flatten() {
            *c = prune(fast_math::exp_inline(*c - max));
        }
        true
    }
}

/// Static factor (prior × temperature) of state `st` (as in `for_each`).
fn static_factor(s: &Shared, st: usize) -> f32 {
    match st.checked_sub(1) {
        None => s.dry_factor,
        Some(j) => {
            let k = (j / ROWS).min(2);
            let i = j % ROWS;
            let mut f = s.factor[k];
            let r = s.row_ratio[k];
            if r != 1.0 {
                f *= fast_math::exp((i + 1) as f32 * fast_math::ln(r));
            }
            f
        }
    }
}

/// The predictive likelihood Σ F·L / Σ F of the currents (F the weight of
/// a state before the update: predicted probability × static factor), summed
/// in linear terms relative to the largest ln L any state can have
/// (det C ≥ r₁r₂): no term overflows; one that underflows is a state whose
/// fit is hopeless.
#[derive(Debug, Clone, Copy)]
struct Predictive {
    l_ref: f32,
    z: f32,
    weight: f32,
}

impl Predictive {
    fn new(s: &Shared) -> Self {
        Predictive {
            l_ref: -0.5 * fast_math::ln(s.r_na2[0] * s.r_na2[1]),
            z: 0.0,
            weight: 0.0,
        }
    }

    /// A state of weight `f` whose ln L is `ln_l`.
    #[inline(always)]
    fn add(&mut self, f: f32, ln_l: f32) {
        if f > 0.0 {
            self.z += f * fast_math::exp_inline(ln_l - self.l_ref);
            self.weight += f;
        }
    }

    /// ln of the predictive likelihood; `None` without any weight. Every
    /// state's fit underflowing gives a floor 100 nats below the best
    /// possible (hopeless for this gain).
    fn ln_z(&self) -> Option<f32> {
        if self.weight.is_nan() || self.weight <= 0.0 {
            return None;
        }
        let lz = if self.z > 0.0 {
            fast_math::ln(self.z)
        } else {
            -100.0
        };
        Some(self.l_ref + lz - fast_math::ln(self.weight))
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
