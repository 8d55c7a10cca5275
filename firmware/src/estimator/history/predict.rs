//! The growth history's prediction (`History`'s transitions over the
//! gathered time): growth by whole rows per rate bin, pause and resume,
//! shed (taken at once when the change look saw the currents fall) and
//! the model's restart, the rate's walk to its neighbouring bins. The
//! history (`history.rs`) runs them as parts of its update.

use super::{History, LEVELS, RATE_BINS};
use crate::estimator::fast_math;
use crate::estimator::params::HistoryParams;
use crate::estimator::response::STEP_MM;

/// The shed rate once the change look has seen the currents fall to a
/// dry face's reading, per hour (a prediction every 10 s sheds 63 %: a
/// fall that fits no growth is a shed).
const SHED_SEEN_PER_H: f32 = 360.0;

/// The share of `HistoryParams::shed_per_h` that acts while no fall is
/// seen (a shed the windows missed: a gap in the frames).
const SHED_UNSEEN: f32 = 0.05;

impl History {
    /// Growth over the gathered time: whole rows per bin, the phase keeps
    /// the rest; the transition probabilities of the later parts.
    pub(super) fn predict_growth(&mut self, p: &HistoryParams) {
        let dt_h = self.pending_s / 3600.0;
        self.pending_s = 0.0;
        self.stage = 1;
        let prob = |per_h: f32| {
            if dt_h > 0.0 {
                fast_math::one_minus_exp_neg(per_h * dt_h)
            } else {
                0.0
            }
        };
        self.walk = 0.5 * prob(p.rate_walk_per_h);
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
        let restart = prob(p.restart_per_h);
        // A shed is a jump of the currents to a dry face's reading: seen
        // by the change look's windows, it is taken within a window; unseen,
        // the ice stays (thick clear ice reads almost like a dry face, and
        // at `shed_per_h` alone the looks at it had shed glaze at 10 mm/h
        // and gain 0.85 within the hour in most accretions).
        let shed = if self.change.fell_to_dry() {
            prob(SHED_SEEN_PER_H)
        } else {
            SHED_UNSEEN * prob(p.shed_per_h)
        };
        self.switch = [
            prob(p.pause_per_h),
            prob(p.resume_per_h),
            shed,
            restart,
            restart * (total / (2 * RATE_BINS * LEVELS) as f32),
            prob(p.resume_ice_per_h),
        ];
    }

    /// Pause / resume, shed, restart, level by level, over half `half` of
    /// the rate bins.
    pub(super) fn predict_switches(&mut self, half: usize) {
        self.stage = 2 + half as u8;
        let [pause, resume_dry, shed, restart, restart_each, resume_ice] = self.switch;
        let bins = if half == 0 {
            0..RATE_BINS / 2
        } else {
            RATE_BINS / 2..RATE_BINS
        };
        for b in bins {
            let (g, q) = (&mut self.grow[b], &mut self.pause[b]);
            let mut shed_sum = 0.0f32;
            for (j, (gv, qv)) in g.iter_mut().zip(q.iter_mut()).enumerate() {
                let (a, c) = (*gv, *qv);
                let resume = if j == 0 { resume_dry } else { resume_ice };
                let mut ng = a * (1.0 - pause) + c * resume;
                let mut nq = c * (1.0 - resume) + a * pause;
                if j > 0 {
                    shed_sum += (ng + nq) * shed;
                    ng *= 1.0 - shed;
                    nq *= 1.0 - shed;
                }
                *gv = ng * (1.0 - restart) + restart_each;
                *qv = nq * (1.0 - restart) + restart_each;
            }
            // Shed: a dry face, paused (growth starts again by a resume).
            q[0] += shed_sum;
        }
    }

    /// The rate walks to the neighbouring bins (`mode` 0 growing, 1
    /// paused); after the paused ones, the prediction's marginal.
    pub(super) fn predict_rate(&mut self, mode: usize) {
        self.stage = 4 + mode as u8;
        let walk = self.walk;
        let keep = 1.0 - 2.0 * walk;
        let rows = if mode == 0 {
            &mut self.grow
        } else {
            &mut self.pause
        };
        let mut prev = rows[0];
        for b in 0..RATE_BINS {
            let cur = rows[b];
            let next = match rows.get(b + 1) {
                Some(n) => *n,
                None => cur,
            };
            let below = if b == 0 { cur } else { prev };
            for (((o, c), lo), hi) in rows[b].iter_mut().zip(&cur).zip(&below).zip(&next) {
                *o = c * keep + walk * (lo + hi);
            }
            prev = cur;
        }
    }
}
