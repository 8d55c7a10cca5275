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
//! the bank). It reads the response table's dimensions, the change look
//! (`change.rs`) and `fast_math`; its transitions are in `history/predict.rs`,
//! the icing rate's readout in `history/rate.rs`.
//!
//! States: level j ∈ 0..=[`ROWS`] (0 the dry face, j the bank's row j − 1),
//! rate bin b (log-spaced [`RATE_MIN_MM_PER_H`] … [`RATE_MAX_MM_PER_H`]),
//! growing or paused. Growing states move up by r·Δt (whole rows, a phase
//! per rate bin: no numerical diffusion); the rate walks to a neighbouring
//! bin; growth pauses and resumes (a dry face is the paused level 0, so the
//! onset of an event is a resume); any ice sheds to the dry face; a small
//! share of the probability restarts anywhere (what the model does not
//! know: a rate beyond the grid, melting, a face cleaned).

use super::change::{Change, TELL_WINDOW_S};
use super::fast_math;
use super::params::HistoryParams;
use super::response::{ROWS, STEP_MM};

mod predict;
mod rate;

pub use rate::{RATE_BINS, RATE_MAX_MM_PER_H, RATE_MIN_MM_PER_H, Rate, prior_rate, rate_of_bin};

/// Levels of the history: the dry face and the bank's rows.
pub const LEVELS: usize = ROWS + 1;

/// Parts of the change look, a share of the levels each (every rate bin):
/// 19 parts of 4 levels keep its part within the worst second's budget.
const CHANGE_PARTS: usize = 19;

/// The stage of the change look's first part.
const CHANGE_FIRST: u8 = 6;

/// The stage after the change look's last part (the levels' sums).
const SUMS: u8 = CHANGE_FIRST + CHANGE_PARTS as u8;

/// The stage at which the prediction and the change look are done and
/// the level look waits.
pub const READY_TO_LOOK: u8 = SUMS + 3;

/// The stages of the look applied: the factor, the normalisation, the
/// marginal.
const LOOKED: u8 = READY_TO_LOOK + 1;
const APPLIED: u8 = READY_TO_LOOK + 2;
const NORMALISED: u8 = READY_TO_LOOK + 3;

/// A level's probability below this (relative to the sum) is set to zero.
const FLOOR: f32 = 1e-20;

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
    /// How well the prediction foresaw the bank's last look against the
    /// flat escape: the weight of the history's rate in the output.
    credibility: f32,
    /// Expected growth since the last measurement, mm.
    growth_mm: f32,
    /// Time since the last measurement, s.
    since_measure_s: f32,
    /// Time gathered towards the next prediction, s.
    pending_s: f32,
    /// Where the update stands: 0 gathering, 1 growth, pause and shed
    /// predicted, 2 the rate walk too (the measurement is next).
    stage: u8,
    /// Probability of a step to each neighbouring rate bin over the
    /// prediction (for its later parts).
    walk: f32,
    /// Pause, resume, shed, restart probabilities and the restart's share
    /// per state, over the prediction.
    switch: [f32; 6],
    /// The look's factor per level.
    factor: [f32; LEVELS],
    /// The levels' sums being gathered over parts.
    scratch: [f32; LEVELS],
    /// The change look (the currents' windows).
    change: Change,
    /// The change look weighed a change this update.
    changed: bool,
    /// The bank's gain and P(rime) for the change look.
    gain: f32,
    p_rime: f32,
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
            credibility: 1.0,
            growth_mm: 0.0,
            since_measure_s: 0.0,
            pending_s: 0.0,
            stage: 0,
            walk: 0.0,
            switch: [0.0; 6],
            factor: [1.0; LEVELS],
            scratch: [0.0; LEVELS],
            change: Change::new(),
            changed: false,
            gain: 1.0,
            p_rime: 0.5,
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
        self.stage = 0;
        self.scratch = [0.0; LEVELS];
        self.change.clear();
        self.initialised = true;
        self.update_marginal();
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
        self.stage == 0 && self.pending_s + 1e-4 >= period_s
    }

    /// The update's stage: 0 gathering, else the part done last (see
    /// [`Self::advance`]).
    pub fn stage(&self) -> u8 {
        self.stage
    }

    /// The next part of the update; at 10 Hz one part per second, so that
    /// no second carries more than one (the budget's worst second). The
    /// prediction: 1 growth; 2, 3 pause, resume, shed and restarts (half
    /// the rate bins each); 4, 5 the rate walk (growing, paused); 6 the
    /// change look's start, 7–25 the change look (a nineteenth of the
    /// levels each, every rate bin); 26, 27 the levels' sums (then the
    /// levels restored to their masses before the change look); 28 the
    /// prediction's marginal ([`READY_TO_LOOK`]: the caller looks with
    /// [`Self::look`]). The look applied: 30 every state times its level's
    /// factor, 31 normalised, 0 the marginal. Returns the stage reached.
    pub fn advance(&mut self, p: &HistoryParams) -> u8 {
        match self.stage {
            0 => self.predict_growth(p),
            1 => self.predict_switches(0),
            2 => self.predict_switches(1),
            3 => self.predict_rate(0),
            4 => self.predict_rate(1),
            5 => {
                self.changed = self.change.start();
                if self.changed {
                    // Each level's mass before the change look: it moves
                    // probability between growing, paused and the rates
                    // within a level, never between levels.
                    self.factor = [0.0; LEVELS];
                    for row in self.grow.iter().chain(self.pause.iter()) {
                        for (a, v) in self.factor.iter_mut().zip(row) {
                            *a += v;
                        }
                    }
                }
                self.stage = CHANGE_FIRST;
            }
            CHANGE_FIRST..SUMS => {
                let part = usize::from(self.stage - CHANGE_FIRST);
                let per = LEVELS.div_ceil(CHANGE_PARTS);
                let first = (part * per).min(LEVELS);
                let last = ((part + 1) * per).min(LEVELS);
                self.change.weigh(
                    &mut self.grow,
                    &self.rates,
                    first..last,
                    self.gain,
                    self.p_rime,
                    p,
                );
                if part + 1 == CHANGE_PARTS {
                    self.change.end();
                }
                self.stage += 1;
            }
            SUMS => {
                self.sum_levels(0);
                self.stage = SUMS + 1;
            }
            s if s == SUMS + 1 => {
                self.sum_levels(1);
                if self.changed {
                    self.changed = false;
                    self.restore_levels();
                }
                self.stage = SUMS + 2;
            }
            s if s == SUMS + 2 => {
                let m = self.scratch;
                let s: f32 = m.iter().sum();
                self.scratch = [0.0; LEVELS];
                let inv = if s > 0.0 { 1.0 / s } else { 0.0 };
                self.set_marginal(m.map(|a| a * inv));
                self.stage = READY_TO_LOOK;
            }
            LOOKED => self.apply_factor(),
            APPLIED => self.normalise_applied(),
            NORMALISED => {
                let m = self.scratch;
                self.scratch = [0.0; LEVELS];
                self.set_marginal(m);
                self.stage = 0;
            }
            _ => {}
        }
        self.stage
    }

    /// The currents of an update (`None`: the bank did not measure), their
    /// noise (standard deviation, nA) and the update's time, for the change
    /// look's windows; `gain` and `p_rime` the bank's, for its next look.
    pub fn gather_currents(
        &mut self,
        dt_s: f32,
        x_na: Option<[f32; 2]>,
        noise_na: [f32; 2],
        gain: f32,
        p_rime: f32,
        p: &HistoryParams,
    ) {
        self.change.gather(dt_s, x_na, noise_na, p);
        self.gain = gain;
        self.p_rime = p_rime;
    }

    /// Expected information of the change looks of 20 min about
    /// growth as the history believes it, nats (`None`: no change look yet).
    pub fn discern_nats(&self, p: &HistoryParams) -> Option<f32> {
        self.change
            .discern()
            .map(|d| d * TELL_WINDOW_S / p.change_window_s)
    }

    /// Time since a change look last supported growth against a pause, s
    /// (`Change::support_age_s`).
    pub fn support_age_s(&self) -> f32 {
        self.change.support_age_s()
    }

    /// After the change look: every level back to its mass before it
    /// (held in `factor`; the scratch holds the masses after it, and then
    /// the ones before).
    fn restore_levels(&mut self) {
        let mut ratio = [1.0f32; LEVELS];
        for ((r, &before), &after) in ratio.iter_mut().zip(&self.factor).zip(&self.scratch) {
            if after > 0.0 {
                *r = before / after;
            }
        }
        for row in self.grow.iter_mut().chain(self.pause.iter_mut()) {
            for (v, r) in row.iter_mut().zip(&ratio) {
                *v *= r;
            }
        }
        self.scratch = self.factor;
    }

    /// Add the levels of the growing (`mode` 0) or paused states to the
    /// scratch.
    fn sum_levels(&mut self, mode: usize) {
        let rows = if mode == 0 { &self.grow } else { &self.pause };
        for row in rows.iter() {
            for (a, v) in self.scratch.iter_mut().zip(row) {
                *a += v;
            }
        }
    }

    /// The look (at [`READY_TO_LOOK`], → [`LOOKED`]): the bank's thickness likelihood `lik` (sums to
    /// 1), tempered by the looks it is worth; `p_rime` the bank's
    /// probability of rime (the early trust). Also how well the
    /// prediction foresaw it (the history's credibility).
    pub fn look(&mut self, lik: &[f32; LEVELS], p_rime: f32, p: &HistoryParams) {
        self.stage = LOOKED;
        let mut o = 0.0f32;
        for (l, m) in lik.iter().zip(self.marginal.iter()) {
            o += l * m;
        }
        let a = (1.0 - p.escape) * o;
        let b = p.escape / LEVELS as f32;
        self.credibility = if a + b > 0.0 { a / (a + b) } else { 0.0 };
        let mean_mm = self.mean_mm();
        let mut per_mm = p.looks_per_mm;
        if mean_mm < p.early_mm {
            per_mm += p.early_rime_looks_per_mm * p_rime.clamp(0.0, 1.0);
        }
        let beta = (per_mm * self.growth_mm + p.looks_per_h * self.since_measure_s / 3600.0)
            .clamp(0.0, 1.0);
        self.growth_mm = 0.0;
        self.since_measure_s = 0.0;
        let mut max = 0.0f32;
        for &l in lik {
            max = max.max(l);
        }
        if beta <= 0.0 || max <= 0.0 {
            self.factor = [1.0; LEVELS];
            return;
        }
        for (f, &l) in self.factor.iter_mut().zip(lik) {
            let r = l / max;
            // A level the bank rules out keeps e^−40 of a look.
            let ln = if r > 1e-17 { fast_math::ln(r) } else { -40.0 };
            *f = fast_math::exp(beta * ln);
        }
    }

    /// The look applied ([`LOOKED`] → [`APPLIED`]): every state times its level's
    /// factor, the levels' sums in the scratch.
    fn apply_factor(&mut self) {
        self.stage = APPLIED;
        let mut m = [0.0f32; LEVELS];
        for row in self.grow.iter_mut().chain(self.pause.iter_mut()) {
            for ((v, f), a) in row.iter_mut().zip(self.factor.iter()).zip(m.iter_mut()) {
                *v *= f;
                *a += *v;
            }
        }
        self.scratch = m;
    }

    /// Normalised ([`APPLIED`] → [`NORMALISED`]); the scratch holds the marginal.
    fn normalise_applied(&mut self) {
        self.stage = NORMALISED;
        let total: f32 = self.scratch.iter().sum();
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
        for a in self.scratch.iter_mut() {
            *a *= inv;
        }
    }

    /// All the parts left, at once (slow updates).
    pub fn finish(&mut self, p: &HistoryParams) {
        while self.stage != 0 && self.stage != READY_TO_LOOK {
            self.advance(p);
        }
    }

    /// No look this time (no currents): the growth and the time wait for
    /// the next one.
    pub fn skip_measure(&mut self) {
        self.stage = 0;
        self.scratch = [0.0; LEVELS];
    }

    /// The weight of the history's rate in the output (against its prior).
    pub fn credibility(&self) -> f32 {
        self.credibility
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
        self.set_marginal(m);
    }

    /// The marginal `m` (sums to 1), and the output's weight from it.
    fn set_marginal(&mut self, m: [f32; LEVELS]) {
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
        rate::from_bins(
            self.grow
                .iter()
                .zip(&self.pause)
                .zip(&self.rates)
                .map(|((g, q), &r)| (g.iter().sum(), q.iter().sum(), r)),
        )
    }
}
