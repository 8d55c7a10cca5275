//! The icing rate as the node reports it ([`Rate`]): the growth rate's
//! moments over the history's growing states and P(accreting), the rate
//! bins' grid, and the rate a history that is wrong would give (the
//! output widens towards it).

use crate::estimator::fast_math;

/// Rate bins of the history.
pub const RATE_BINS: usize = 8;

/// Slowest and fastest growth rate the history models, mm/h: a rate beyond
/// the top is out of model (the output falls back to the bank's, wide).
pub const RATE_MIN_MM_PER_H: f32 = 0.3;
/// See [`RATE_MIN_MM_PER_H`].
pub const RATE_MAX_MM_PER_H: f32 = 13.0;

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

/// The growth rate from the rate bins' (growing mass, paused mass, rate
/// in mm/h): the moments of r over the growing states (paused ones count
/// 0), and P(growing).
pub(super) fn from_bins(bins: impl Iterator<Item = (f32, f32, f32)>) -> Rate {
    let (mut p, mut m1, mut m2, mut total) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    for (g, q, r) in bins {
        p += g;
        m1 += g * r;
        m2 += g * r * r;
        total += g + q;
    }
    if total.is_nan() || total <= 0.0 {
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
