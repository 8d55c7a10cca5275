//! The growth history (`History`): a second grid filter beside the gain
//! bank, over thickness × growth rate × {growing, paused}, that remembers
//! how the ice grew. Ice grows monotonically during an event at a slowly
//! varying rate; it pauses, resumes, sheds to a dry face. The bank's
//! posterior (gain and medium summed out) is this filter's measurement,
//! **tempered**: an accretion's deviation from the table's mean persists
//! along it (correlation 0.97–1.0 over 1 mm), so a look counts
//! `HistoryParams::looks_per_mm` per mm of growth (and a little per hour of
//! time), never once per update. The estimator's output multiplies the
//! bank's posterior by this filter's thickness marginal (not fed back into
//! the bank). It reads only the response table's dimensions and `fast_math`.
//!
//! States: level j ∈ 0..=[`ROWS`] (0 the dry face, j the bank's row j − 1),
//! rate bin b (log-spaced [`RATE_MIN_MM_PER_H`] … [`RATE_MAX_MM_PER_H`]),
//! growing or paused. Growing states move up by r·Δt (whole rows, a phase
//! per rate bin: no numerical diffusion); the rate walks to a neighbouring
//! bin; growth pauses and resumes (a dry face is the paused level 0, so the
//! onset of an event is a resume); any ice sheds to the dry face; a small
//! share of the probability restarts anywhere (what the model does not
//! know: a rate beyond the grid, melting, a face cleaned).

use super::fast_math;
use super::response::{ROWS, STEP_MM};

/// Levels of the history: the dry face and the bank's rows.
pub const LEVELS: usize = ROWS + 1;

/// Rate bins of the history.
pub const RATE_BINS: usize = 8;

/// Slowest and fastest growth rate the history models, mm/h: a rate beyond
/// the top is out of model (the output falls back to the bank's, wide).
pub const RATE_MIN_MM_PER_H: f32 = 0.3;
/// See [`RATE_MIN_MM_PER_H`].
pub const RATE_MAX_MM_PER_H: f32 = 13.0;

/// A level's probability below this (relative to the sum) is set to zero.
const FLOOR: f32 = 1e-20;

/// The history's settings (library settings with documented defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HistoryParams {
    /// Off: the estimator's output is the bank's alone (the design before).
    pub enabled: bool,
    /// The history updates once per this period, s (default 5).
    pub period_s: f32,
    /// Rate of a step of the rate to a neighbouring bin, per hour (default 1).
    pub rate_walk_per_h: f32,
    /// Growth pauses at this rate, per hour (default 0.2; 0: no pause
    /// state — the design without it).
    pub pause_per_h: f32,
    /// Paused growth (and a dry face) starts growing at this rate, per hour
    /// (default 1).
    pub resume_per_h: f32,
    /// The ice sheds to a dry face at this rate, per hour (default 0.5).
    pub shed_per_h: f32,
    /// Share of the probability that restarts anywhere, per hour (default
    /// 0.1): the model's escape.
    pub restart_per_h: f32,
    /// Looks of the bank's evidence per mm of expected growth (default 0.3:
    /// one look per ~3 mm).
    pub looks_per_mm: f32,
    /// Extra looks per mm in the first `early_mm` of an accretion, scaled
    /// by the bank's probability of rime (default 0.7): rime's thin layers
    /// are where its history resolves the most; glazed ice does not get it.
    pub early_rime_looks_per_mm: f32,
    /// Thickness below which the early trust acts, mm (default 1.5).
    pub early_mm: f32,
    /// Looks per hour of time, whatever the growth (default 1): a dry face,
    /// a pause, a stop are seen in time.
    pub looks_per_h: f32,
    /// Prior weight of "the history is wrong" in the output (default 0.05):
    /// where the bank's evidence falls outside what the history foresaw,
    /// the output is the bank's.
    pub escape: f32,
    /// Exponent of the history's marginal in the output (default 0.5): the
    /// history is itself built of tempered looks at the same bank; at full
    /// weight its product with the bank's narrow, wrong branches (rime read
    /// as glaze at 1–3 mm) was confident.
    pub output_weight: f32,
}

impl Default for HistoryParams {
    fn default() -> Self {
        HistoryParams {
            enabled: true,
            period_s: 5.0,
            rate_walk_per_h: 1.0,
            pause_per_h: 0.2,
            resume_per_h: 1.0,
            shed_per_h: 0.5,
            restart_per_h: 0.1,
            looks_per_mm: 0.3,
            early_rime_looks_per_mm: 0.7,
            early_mm: 1.5,
            looks_per_h: 1.0,
            escape: 0.05,
            output_weight: 0.5,
        }
    }
}

impl HistoryParams {
    /// Every field in its valid range; a field that is not takes its default.
    pub fn sanitized(self) -> Self {
        use super::params::within;
        let d = HistoryParams::default();
        HistoryParams {
            enabled: self.enabled,
            period_s: within(self.period_s, 0.0, 600.0, d.period_s),
            rate_walk_per_h: within(self.rate_walk_per_h, 0.0, 100.0, d.rate_walk_per_h),
            pause_per_h: within(self.pause_per_h, 0.0, 100.0, d.pause_per_h),
            resume_per_h: within(self.resume_per_h, 0.0, 100.0, d.resume_per_h),
            shed_per_h: within(self.shed_per_h, 0.0, 100.0, d.shed_per_h),
            restart_per_h: within(self.restart_per_h, 0.0, 100.0, d.restart_per_h),
            looks_per_mm: within(self.looks_per_mm, 0.0, 100.0, d.looks_per_mm),
            early_rime_looks_per_mm: within(
                self.early_rime_looks_per_mm,
                0.0,
                100.0,
                d.early_rime_looks_per_mm,
            ),
            early_mm: within(self.early_mm, 0.0, 15.0, d.early_mm),
            looks_per_h: within(self.looks_per_h, 0.0, 3600.0, d.looks_per_h),
            escape: within(self.escape, 1e-4, 1.0, d.escape),
            output_weight: within(self.output_weight, 0.0, 1.0, d.output_weight),
        }
    }
}

/// The growth rate as the node reports it: meteorological icing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rate {
    /// Mean growth rate now (0 while paused or dry), mm/h.
    pub mean_mm_per_h: f32,
    /// Its standard deviation, mm/h.
    pub sigma_mm_per_h: f32,
    /// Probability that ice accretes now.
    pub p_accreting: f32,
}

/// Growth rate of bin `b`, mm/h.
pub fn rate_of_bin(b: usize) -> f32 {
    let step = fast_math::ln(RATE_MAX_MM_PER_H / RATE_MIN_MM_PER_H) / (RATE_BINS - 1) as f32;
    RATE_MIN_MM_PER_H * fast_math::exp(step * b as f32)
}

/// The history filter (~5 KiB: one `f32` per state).
#[derive(Debug, Clone)]
pub(crate) struct History {
    grow: [[f32; LEVELS]; RATE_BINS],
    pause: [[f32; LEVELS]; RATE_BINS],
    /// Rows moved so far, fractional part, per rate bin.
    phase: [f32; RATE_BINS],
    /// Rate of each bin, mm/h.
    rates: [f32; RATE_BINS],
    /// Thickness marginal (sums to 1).
    marginal: [f32; LEVELS],
    /// The output's weight per level: the marginal to `output_weight`
    /// (sums to 1).
    weight: [f32; LEVELS],
    /// `output_weight` in force.
    gamma: f32,
    /// Expected growth since the last measurement, mm.
    growth_mm: f32,
    /// Time since the last measurement, s.
    since_measure_s: f32,
    /// Time gathered towards the next prediction, s.
    pending_s: f32,
    /// A prediction waits for its measurement.
    predicted: bool,
    /// The history has its first state.
    pub initialised: bool,
}

impl History {
    pub const fn new() -> Self {
        History {
            grow: [[0.0; LEVELS]; RATE_BINS],
            pause: [[0.0; LEVELS]; RATE_BINS],
            phase: [0.0; RATE_BINS],
            rates: [0.0; RATE_BINS],
            marginal: [0.0; LEVELS],
            weight: [0.0; LEVELS],
            gamma: 1.0,
            growth_mm: 0.0,
            since_measure_s: 0.0,
            pending_s: 0.0,
            predicted: false,
            initialised: false,
        }
    }

    fn fill_rates(&mut self) {
        for (b, r) in self.rates.iter_mut().enumerate() {
            *r = rate_of_bin(b);
        }
    }

    /// Nothing known: every state alike.
    pub fn reset_flat(&mut self) {
        self.fill_rates();
        let v = 1.0 / (2 * RATE_BINS * LEVELS) as f32;
        for row in self.grow.iter_mut().chain(self.pause.iter_mut()) {
            *row = [v; LEVELS];
        }
        self.after_reset();
    }

    /// The first look: the bank's thickness marginal `lik` (sums to 1) at
    /// full weight, the rate bins alike, a dry face paused (growth has
    /// just started there with probability `p_start`), ice growing or
    /// paused alike.
    pub fn initialise_from(&mut self, lik: &[f32; LEVELS], p_start: f32) {
        self.fill_rates();
        let v = 1.0 / RATE_BINS as f32;
        for (g, q) in self.grow.iter_mut().zip(self.pause.iter_mut()) {
            for (j, ((gv, qv), &l)) in g.iter_mut().zip(q.iter_mut()).zip(lik).enumerate() {
                let share = if j == 0 { p_start } else { 0.5 };
                *gv = v * l * share;
                *qv = v * l * (1.0 - share);
            }
        }
        self.after_reset();
        self.normalise();
        self.update_marginal();
    }

    /// A dry face (a dark calibration): paused at level 0, a little
    /// probability already growing there.
    pub fn set_dry(&mut self) {
        self.fill_rates();
        *self = History {
            rates: self.rates,
            gamma: self.gamma,
            ..History::new()
        };
        let v = 1.0 / RATE_BINS as f32;
        for (g, p) in self.grow.iter_mut().zip(self.pause.iter_mut()) {
            g[0] = 0.05 * v;
            p[0] = 0.95 * v;
        }
        self.after_reset();
    }

    fn after_reset(&mut self) {
        self.phase = [0.0; RATE_BINS];
        self.growth_mm = 0.0;
        self.since_measure_s = 0.0;
        self.pending_s = 0.0;
        self.predicted = false;
        self.initialised = true;
        self.update_marginal();
    }

    /// The thickness marginal (sums to 1).
    pub fn marginal(&self) -> &[f32; LEVELS] {
        &self.marginal
    }

    /// The output's weight per level (the marginal to `output_weight`,
    /// sums to 1).
    pub fn weight(&self) -> &[f32; LEVELS] {
        &self.weight
    }

    /// Set the exponent of the output's weight.
    pub fn set_output_weight(&mut self, gamma: f32) {
        self.gamma = gamma;
        self.update_marginal();
    }

    /// Gather `dt_s`; true when a prediction is due.
    pub fn gather(&mut self, dt_s: f32, period_s: f32) -> bool {
        self.pending_s += dt_s;
        self.since_measure_s += dt_s;
        !self.predicted && self.pending_s + 1e-4 >= period_s
    }

    /// A prediction waits for its measurement.
    pub fn predicted(&self) -> bool {
        self.predicted
    }

    /// The transitions over the gathered time.
    pub fn predict(&mut self, p: &HistoryParams) {
        let dt_h = self.pending_s / 3600.0;
        self.pending_s = 0.0;
        self.predicted = true;
        if dt_h <= 0.0 {
            return;
        }
        let prob = |per_h: f32| fast_math::one_minus_exp_neg(per_h * dt_h);
        let walk = 0.5 * prob(p.rate_walk_per_h);
        let pause = prob(p.pause_per_h);
        let resume = prob(p.resume_per_h);
        let shed = prob(p.shed_per_h);
        let restart = prob(p.restart_per_h);
        // Growth: whole rows per bin, the phase keeps the rest.
        let mut growth = 0.0f32;
        let mut total = 0.0f32;
        for b in 0..RATE_BINS {
            let g = &mut self.grow[b];
            let s: f32 = g.iter().sum();
            total += s;
            growth += s * self.rates[b] * dt_h;
            let ph = self.phase[b] + self.rates[b] * dt_h / STEP_MM;
            let whole = ph as u32 as f32;
            self.phase[b] = ph - whole;
            let n = (whole as usize).min(LEVELS - 1);
            if n > 0 {
                // The top level keeps what would grow beyond it.
                let top: f32 = g[LEVELS - 1 - n..].iter().sum();
                g.copy_within(0..LEVELS - 1 - n, n);
                for v in g[..n].iter_mut() {
                    *v = 0.0;
                }
                g[LEVELS - 1] = top;
            }
        }
        for b in 0..RATE_BINS {
            total += self.pause[b].iter().sum::<f32>();
        }
        let norm = if total > 0.0 { 1.0 / total } else { 1.0 };
        self.growth_mm += growth * norm;
        // Pause / resume, shed, restart: level by level.
        let restart_each = restart * (total / (2 * RATE_BINS * LEVELS) as f32);
        let mut shed_sum = [[0.0f32; 2]; RATE_BINS];
        for b in 0..RATE_BINS {
            let (g, q) = (&mut self.grow[b], &mut self.pause[b]);
            for (j, (gv, qv)) in g.iter_mut().zip(q.iter_mut()).enumerate() {
                let (a, c) = (*gv, *qv);
                let mut ng = a * (1.0 - pause) + c * resume;
                let mut nq = c * (1.0 - resume) + a * pause;
                if j > 0 {
                    shed_sum[b][0] += ng * shed;
                    shed_sum[b][1] += nq * shed;
                    ng *= 1.0 - shed;
                    nq *= 1.0 - shed;
                }
                *gv = ng * (1.0 - restart) + restart_each;
                *qv = nq * (1.0 - restart) + restart_each;
            }
        }
        for b in 0..RATE_BINS {
            // Shed: a dry face, paused (growth starts again by a resume).
            if let Some(q0) = self.pause[b].get_mut(0) {
                *q0 += shed_sum[b][0] + shed_sum[b][1];
            }
        }
        // The rate walks to the neighbouring bins (both modes).
        for mode in 0..2 {
            let rows = if mode == 0 {
                &mut self.grow
            } else {
                &mut self.pause
            };
            for j in 0..LEVELS {
                let mut prev = 0.0f32;
                for b in 0..RATE_BINS {
                    let here = rows[b][j];
                    let next = if b + 1 < RATE_BINS {
                        rows[b + 1][j]
                    } else {
                        here
                    };
                    let below = if b == 0 { here } else { prev };
                    prev = here;
                    rows[b][j] = here * (1.0 - 2.0 * walk) + walk * (below + next);
                }
            }
        }
    }

    /// The measurement: the bank's thickness marginal `lik` (sums to 1),
    /// tempered by the looks it is worth; `p_rime` the bank's probability
    /// of rime. Then the marginal and the rate.
    pub fn measure(&mut self, lik: &[f32; LEVELS], p_rime: f32, p: &HistoryParams) {
        self.predicted = false;
        let mean_mm = self.mean_mm();
        let mut per_mm = p.looks_per_mm;
        if mean_mm < p.early_mm {
            per_mm += p.early_rime_looks_per_mm * p_rime.clamp(0.0, 1.0);
        }
        let beta = (per_mm * self.growth_mm + p.looks_per_h * self.since_measure_s / 3600.0)
            .clamp(0.0, 1.0);
        self.growth_mm = 0.0;
        self.since_measure_s = 0.0;
        if beta > 0.0 {
            let mut max = 0.0f32;
            for &l in lik {
                max = max.max(l);
            }
            if max > 0.0 {
                let mut factor = [0.0f32; LEVELS];
                for (f, &l) in factor.iter_mut().zip(lik) {
                    let r = l / max;
                    // A level the bank rules out keeps e^−40 of a look.
                    let ln = if r > 1e-17 { fast_math::ln(r) } else { -40.0 };
                    *f = fast_math::exp(beta * ln);
                }
                for row in self.grow.iter_mut().chain(self.pause.iter_mut()) {
                    for (v, f) in row.iter_mut().zip(factor.iter()) {
                        *v *= f;
                    }
                }
            }
        }
        self.normalise();
        self.update_marginal();
    }

    fn mean_mm(&self) -> f32 {
        let mut m = 0.0f32;
        for (j, h) in self.marginal.iter().enumerate() {
            m += h * j as f32 * STEP_MM;
        }
        m
    }

    fn normalise(&mut self) {
        let mut total = 0.0f32;
        for row in self.grow.iter().chain(self.pause.iter()) {
            total += row.iter().sum::<f32>();
        }
        if !(total.is_finite() && total > 0.0) {
            self.reset_flat();
            return;
        }
        let inv = 1.0 / total;
        for row in self.grow.iter_mut().chain(self.pause.iter_mut()) {
            for v in row.iter_mut() {
                *v *= inv;
                if *v < FLOOR {
                    *v = 0.0;
                }
            }
        }
    }

    fn update_marginal(&mut self) {
        let mut m = [0.0f32; LEVELS];
        for row in self.grow.iter().chain(self.pause.iter()) {
            for (a, v) in m.iter_mut().zip(row) {
                *a += v;
            }
        }
        let s: f32 = m.iter().sum();
        if s > 0.0 {
            for a in m.iter_mut() {
                *a /= s;
            }
        }
        self.marginal = m;
        let mut w = m;
        if self.gamma != 1.0 {
            for a in w.iter_mut() {
                *a = if *a > 1e-30 {
                    fast_math::exp(self.gamma * fast_math::ln(*a))
                } else {
                    0.0
                };
            }
            let s: f32 = w.iter().sum();
            if s > 0.0 {
                for a in w.iter_mut() {
                    *a /= s;
                }
            }
        }
        self.weight = w;
    }

    /// The growth rate: moments of r over the growing states (paused ones
    /// count 0), and P(growing).
    pub fn rate(&self) -> Rate {
        let (mut p, mut m1, mut m2, mut total) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for b in 0..RATE_BINS {
            let g: f32 = self.grow[b].iter().sum();
            let q: f32 = self.pause[b].iter().sum();
            let r = self.rates[b];
            p += g;
            m1 += g * r;
            m2 += g * r * r;
            total += g + q;
        }
        if !(total > 0.0) {
            return Rate {
                mean_mm_per_h: 0.0,
                sigma_mm_per_h: 0.0,
                p_accreting: 0.0,
            };
        }
        let inv = 1.0 / total;
        let (m1, m2) = (m1 * inv, m2 * inv);
        Rate {
            mean_mm_per_h: m1,
            sigma_mm_per_h: fast_math::sqrt((m2 - m1 * m1).max(0.0)),
            p_accreting: (p * inv).clamp(0.0, 1.0),
        }
    }
}

/// The rate a history that is wrong would give: the rate bins' prior
/// (log-uniform), growing with probability ½.
pub fn prior_rate() -> Rate {
    let (mut m1, mut m2) = (0.0f32, 0.0f32);
    for b in 0..RATE_BINS {
        let r = rate_of_bin(b);
        m1 += r;
        m2 += r * r;
    }
    let n = 2.0 * RATE_BINS as f32;
    let (m1, m2) = (m1 / n, m2 / n);
    Rate {
        mean_mm_per_h: m1,
        sigma_mm_per_h: fast_math::sqrt((m2 - m1 * m1).max(0.0)),
        p_accreting: 0.5,
    }
}
