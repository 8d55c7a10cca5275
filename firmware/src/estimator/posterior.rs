//! What the estimator reports: the [`Posterior`] (thickness ± σ, the
//! probability of each medium) and what its last step did ([`Update`]).

use fois_protocol::{IceEstimate, Medium};

/// What the estimator's last step did with its frame.
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

/// `x` rounded into a `u16` (0 for NaN and below, saturating above).
pub(super) fn to_u16(x: f32) -> u16 {
    if x.is_nan() || x <= 0.0 {
        0
    } else if x >= 65_535.0 {
        u16::MAX
    } else {
        (x + 0.5) as u16
    }
}
