//! The estimator's output: the posterior (the bank's grids, each weighted
//! by the growth history's prediction; which ice, from the bank alone), the
//! icing rate and P(accreting) (the history's, widened towards its prior as
//! far as the bank's evidence falls outside what it foresaw), and the icing
//! period and state. Reads the estimator (`filter.rs`), which reads nothing
//! of it but calls `Estimator::summarise` after every update.

use fois_protocol::IcingEstimate;

use super::fast_math;
use super::filter::Estimator;
use super::gain_bank::GAINS;
use super::grid_summary::Moments;
use super::history::{self, LEVELS, Rate};
use super::posterior::to_u16;

/// P(accreting) above which an icing period starts.
pub const ACCRETING_ON: f32 = 0.7;

/// P(accreting) below which an icing period ends.
pub const ACCRETING_OFF: f32 = 0.3;

/// The icing period ends when no change look has supported growth for
/// this long, s: with the last supporting window ending at most one
/// window (240 s) and an update (~35 s) after growth stops, the period
/// ends within 20 min of the stop.
const SUPPORT_S: f32 = 900.0;

/// How long after P(accreting) was last at [`ACCRETING_OFF`] its rise
/// counts as evidence of growth on its own, s (the clearing goal's 20 min).
const RISE_S: f32 = 1200.0;

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

impl Estimator {
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

    /// Glaze against rime (diagnostics): the bank's ln(P(rime) / P(glazed))
    /// of the last summary (0 while either is 0).
    pub fn rime_odds(&self) -> f32 {
        let (r, g) = (self.bank_p_rime, self.bank_p_glazed);
        if r > 0.0 && g > 0.0 {
            fast_math::ln(r / g)
        } else {
            0.0
        }
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

    /// The output posterior: the weighted mixture of the grids', each
    /// weighted by the history's thickness marginal (mixed with a flat
    /// share, the history's `escape`); the bank's own marginal is kept for
    /// the history's next measurement, and the rate is the history's,
    /// widened towards its prior as far as the bank's evidence falls
    /// outside what the history foresaw.
    pub(super) fn summarise(&mut self) {
        let shared = self.shared();
        let hp = self.params.history;
        let use_history = hp.enabled && self.history.initialised;
        let mut h = [1.0 / LEVELS as f32; LEVELS];
        if use_history {
            let flat = hp.escape / LEVELS as f32;
            for (a, m) in h.iter_mut().zip(self.history.weight()) {
                *a = (1.0 - hp.escape) * m + flat;
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
        // Thickness, and a dry face against ice, from the product with the
        // history: thick clear ice reads almost like a dry face, and the
        // history holds it as ice unless the change look saw the currents
        // fall (a shed). Which medium the ice is, from the bank alone: the
        // history weighs thickness, not medium (weighted, rime's broad
        // branch lost to glaze's narrow one between 1 and 3 mm — medium
        // right 78 % of glazed frames instead of 93 %).
        let post = Moments::mixture(parts.iter().filter_map(|m| *m)).map(|mut p| {
            let s: f32 = p_medium.iter().sum();
            let p_dry = p.p_medium[0];
            let s_ice = s - p_medium[0];
            if s_ice > 0.0 {
                for (a, b) in p.p_medium.iter_mut().zip(p_medium).skip(1) {
                    *a = b / s_ice * (1.0 - p_dry);
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
        let s: f32 = p_medium.iter().sum();
        let inv = if s > 0.0 { 1.0 / s } else { 0.0 };
        self.bank_p_rime = p_medium[3] * inv;
        self.bank_p_glazed = p_medium[2] * inv;
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
        // A rise of P(accreting) from the off threshold within the clearing
        // time is the change looks' own evidence of growth (the prior alone
        // never lifts it above its stationary 0.6 on ice): the period
        // starts on it even where the node could not tell a later stop
        // (growth resumed on thick ice), and ends the clearing time after
        // that rise unless the node can tell by then.
        let rose = self.since_low_s < RISE_S;
        // And growth must have shown in the currents lately: where the
        // slow rates and a pause read alike (thick ice), P(accreting)
        // falls slowly after a stop, but no window supports growth.
        let supported = self.history.support_age_s() < SUPPORT_S;
        let decided = (self.can_tell || rose) && supported;
        if let Some(r) = self.rate {
            if r.p_accreting <= ACCRETING_OFF {
                self.since_low_s = 0.0;
            }
            if r.p_accreting >= ACCRETING_ON && decided {
                self.accreting = true;
            } else if r.p_accreting <= ACCRETING_OFF || !decided {
                self.accreting = false;
            }
        } else {
            self.accreting = false;
        }
    }
}
