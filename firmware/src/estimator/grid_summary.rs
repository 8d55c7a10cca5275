//! A grid's posterior read out ([`Moments`]): its moments and P(medium)
//! (plain, or weighted per level by the growth history's prediction), the
//! mixture of the bank's grids as the output posterior, and a grid's
//! thickness likelihood for the history's look. Reads the grid filter
//! (`grid.rs`); the estimator (`filter.rs`) reads both.

use super::fast_math;
use super::grid::{Grid, Shared};
use super::history::LEVELS;
use super::posterior::Posterior;
use super::response::STEP_MM;

impl Grid {
    /// The grid's posterior: its filtered optical evidence times the static
    /// knowledge of this frame (prior π, temperature factors). They act at
    /// once (a film at +5 °C is never ice, not after τ) and do not
    /// accumulate from frame to frame. Also returns the normaliser.
    #[inline(never)]
    pub fn summarise(&self, s: &Shared) -> Option<Moments> {
        if !self.initialised {
            return None;
        }
        let dry = self.dry * s.dry_factor;
        let mut total = dry;
        let mut p_medium = [dry, 0.0, 0.0, 0.0];
        let (mut m1, mut m2) = (0.0f32, 0.0f32);
        for (k, cells) in self.cells.iter().enumerate() {
            let ratio = s.row_ratio[k];
            let mut f = s.factor[k] * ratio;
            let (mut pk, mut s1, mut s2) = (0.0f32, 0.0f32, 0.0f32);
            let mut d = STEP_MM;
            for &c in cells.iter() {
                let q = c * f;
                f *= ratio;
                pk += q;
                s1 += q * d;
                s2 += q * d * d;
                d += STEP_MM;
            }
            if let Some(slot) = p_medium.get_mut(k + 1) {
                *slot = pk;
            }
            total += pk;
            m1 += s1;
            m2 += s2;
        }
        if !(total.is_finite() && total > 0.0) {
            return None;
        }
        let inv = 1.0 / total;
        for pm in p_medium.iter_mut() {
            *pm *= inv;
        }
        Some(Moments {
            p_medium,
            m1_mm: m1 * inv,
            m2_mm2: m2 * inv,
        })
    }
}

/// The medium row of water in [`Grid`]'s cells (then glazed, rime).
const WATER_ROW: usize = 0;

/// One medium's row weighted per level by `h`: its plain and weighted
/// mass and the weighted first and second moments of thickness.
#[inline(always)]
fn weighted_row(cells: &[f32], mut f: f32, ratio: f32, h: impl Iterator<Item = f32>) -> [f32; 4] {
    let (mut pk, mut pk_plain, mut s1, mut s2) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    let mut d = STEP_MM;
    for (&c, hj) in cells.iter().zip(h) {
        let q = c * f;
        f *= ratio;
        pk_plain += q;
        let qw = q * hj;
        pk += qw;
        s1 += qw * d;
        s2 += qw * d * d;
        d += STEP_MM;
    }
    [pk, pk_plain, s1, s2]
}

impl Grid {
    /// The grid's posterior (as [`Self::summarise`]) weighted per level by
    /// `h` (the history's prediction; level 0 the dry face, level i + 1 row
    /// i), and `w` · its unweighted P(medium) added to `p_medium_plain`.
    /// Returns the weighted moments and the ratio of the weighted
    /// normaliser to the plain one.
    #[inline(never)]
    pub fn summarise_weighted(
        &self,
        s: &Shared,
        h: &[f32; LEVELS],
        w: f32,
        p_medium_plain: &mut [f32; 4],
    ) -> Option<(Moments, f32)> {
        if !self.initialised {
            return None;
        }
        let (h0, h_rows) = h.split_first()?;
        let dry = self.dry * s.dry_factor;
        let mut total = dry;
        let mut total_w = dry * h0;
        let mut p_medium = [dry * h0, 0.0, 0.0, 0.0];
        let mut plain_medium = [dry, 0.0, 0.0, 0.0];
        let (mut m1, mut m2) = (0.0f32, 0.0f32);
        for (k, cells) in self.cells.iter().enumerate() {
            let ratio = s.row_ratio[k];
            let f = s.factor[k] * ratio;
            // A water film is not an accretion: the history (ice growth)
            // does not weigh its thickness; it weighs as the dry face does.
            let [pk, pk_plain, s1, s2] = if k == WATER_ROW {
                weighted_row(cells, f, ratio, core::iter::repeat(*h0))
            } else {
                weighted_row(cells, f, ratio, h_rows.iter().copied())
            };
            if let Some(slot) = p_medium.get_mut(k + 1) {
                *slot = pk;
            }
            if let Some(slot) = plain_medium.get_mut(k + 1) {
                *slot = pk_plain;
            }
            total += pk_plain;
            total_w += pk;
            m1 += s1;
            m2 += s2;
        }
        if !(total.is_finite() && total > 0.0 && total_w.is_finite() && total_w > 0.0) {
            return None;
        }
        let inv = 1.0 / total;
        for (a, b) in p_medium_plain.iter_mut().zip(plain_medium) {
            *a += w * b * inv;
        }
        let inv_w = 1.0 / total_w;
        for pm in p_medium.iter_mut() {
            *pm *= inv_w;
        }
        Some((
            Moments {
                p_medium,
                m1_mm: m1 * inv_w,
                m2_mm2: m2 * inv_w,
            },
            total_w * inv,
        ))
    }

    /// The grid's thickness likelihood (the filtered evidence times the
    /// temperature's factor, without the prior, which would count once per
    /// look of the history), normalised, times `w`, added to `lik`.
    #[inline(never)]
    pub fn add_likelihood(&self, s: &Shared, w: f32, lik: &mut [f32; LEVELS]) {
        if !self.initialised {
            return;
        }
        let mut plain = [0.0f32; LEVELS];
        let (p0, rows) = plain.split_at_mut(1);
        if let Some(p) = p0.first_mut() {
            *p = self.dry;
        }
        let mut total = self.dry;
        for (k, cells) in self.cells.iter().enumerate() {
            let t = s.temp_factor[k];
            for (pl, &c) in rows.iter_mut().zip(cells) {
                let v = c * t;
                *pl += v;
                total += v;
            }
        }
        if total.is_finite() && total > 0.0 {
            let a = w / total;
            for (l, p) in lik.iter_mut().zip(plain) {
                *l += a * p;
            }
        }
    }
}

/// A grid's posterior moments: P(medium), E[d], E[d²].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Moments {
    pub p_medium: [f32; 4],
    pub m1_mm: f32,
    pub m2_mm2: f32,
}

impl Moments {
    /// The mixture of several grids' moments with `weights` (summing to 1),
    /// as the output posterior (the 0.1 mm grid adds its ±0.05 mm).
    pub fn mixture(parts: impl Iterator<Item = (f32, Moments)>) -> Option<Posterior> {
        let (mut w_sum, mut p, mut m1, mut m2) = (0.0f32, [0.0f32; 4], 0.0f32, 0.0f32);
        for (w, m) in parts {
            w_sum += w;
            for (a, b) in p.iter_mut().zip(m.p_medium) {
                *a += w * b;
            }
            m1 += w * m.m1_mm;
            m2 += w * m.m2_mm2;
        }
        if !(w_sum.is_finite() && w_sum > 0.0) {
            return None;
        }
        let inv = 1.0 / w_sum;
        for a in p.iter_mut() {
            *a *= inv;
        }
        let (m1, m2) = (m1 * inv, m2 * inv);
        let var = (m2 - m1 * m1).max(0.0) + (1.0 - p[0]) * STEP_MM * STEP_MM / 12.0;
        Some(Posterior {
            thickness_mm: m1,
            sigma_mm: fast_math::sqrt(var),
            p_medium: p,
        })
    }
}
