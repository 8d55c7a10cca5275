//! The change look ([`Change`]): how far the currents moved between two
//! windows of `HistoryParams::change_window_s`, against what a paused state
//! (nothing) and a growing one (the table's μ from the thickness a rate ago
//! to now, times the gain) foresee. An accretion's deviation from the
//! table's mean persists along it, so the level look is tempered; the
//! change between two windows of the same accretion cancels that deviation,
//! so this look counts at full weight: it is what tells the history that
//! the ice has stopped growing. Where the currents hardly move with the
//! thickness (rime beyond ~8 mm, glazed beyond ~4 mm) it tells little, and
//! [`Change::discern`] says so (the icing state "uncertain"). Reads the
//! response table and the history's rate grid; the history reads it.

use super::fast_math;
use super::params::HistoryParams;
use super::response::{ROWS, STEP_MM, table_of};

/// Levels of the growth history: the dry face and the table's rows.
const LEVELS: usize = ROWS + 1;

/// Largest |ln likelihood ratio| one change look gives a state: a jump
/// (a shed, a wiped face) fits neither hypothesis.
const MAX_LN_LR: f32 = 6.0;

/// Most rate bins the look weighs at one level.
const MAX_BINS: usize = 16;

/// Largest ln ratio between two rates at a level from one look (after the
/// temper): a change that fits no rate does not rule one out.
const RATE_SPAN: f32 = 8.0;

/// Largest |ln likelihood ratio| against a pause a rate is credited with
/// among the rates: beyond, a change fits the rates alike (the table's
/// slope is no better known).
const MAX_LN_RATE: f32 = 30.0;

/// Relative drift of the gain between two windows (the temperature model's
/// residual): a change along the currents that is not growth.
const DRIFT: f32 = 0.002;

/// The time over which the change looks must be able to tell growth from
/// a pause, s (the clearing goal's 20 min).
pub(crate) const TELL_WINDOW_S: f32 = 1200.0;

/// The window of currents and the change between the last two.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Change {
    /// Sum of the currents of this window, nA, and their count.
    sum_na: [f32; 2],
    n: u32,
    /// Length of this window so far, s.
    window_s: f32,
    /// Mean of the previous window, nA, its length, s, and its count.
    prev_na: Option<([f32; 2], f32, u32)>,
    /// The change between the last two windows' means, nA, the time
    /// between their centres, h, and the variance of the update noise in
    /// it, nA² (per channel); `None` when no change waits for a look.
    pending: Option<([f32; 2], f32, [f32; 2])>,
    /// The change the look uses (taken from `pending` when the look starts).
    delta_na: [f32; 2],
    delta_h: f32,
    /// The variance of the updates' own noise in that change, nA²: the
    /// measurement noise per update over each window's count (at 1 Hz,
    /// 240 updates a window, it adds 7 % to the change's noise; in a
    /// replay of rows 180 s apart, two a window, it is most of it).
    delta_var_na2: [f32; 2],
    /// This look has a change to weigh.
    active: bool,
    /// Expected information of one window of change, nats, if the ice grew
    /// as the history believes (summed over the look's parts).
    discern_part: f32,
    grow_part: f32,
    /// The growing states' likelihood ratio against a pause, summed with
    /// their weights over the look's parts.
    support_part: f32,
    /// Time since a window's change last supported growth by at least
    /// [`SUPPORT_NATS`], s.
    support_age_s: f32,
    /// Its value at the last completed look (`None`: none yet).
    discern: Option<f32>,
    /// The last two windows' means fell from ice to a dry face's reading
    /// (a shed, a wiped face).
    fell_to_dry: bool,
    /// Updates in a row that fell from the last window's mean to a dry
    /// face's reading.
    fell_run: u16,
}

impl Change {
    pub const fn new() -> Self {
        Change {
            sum_na: [0.0; 2],
            n: 0,
            window_s: 0.0,
            prev_na: None,
            pending: None,
            delta_na: [0.0; 2],
            delta_h: 0.0,
            delta_var_na2: [0.0; 2],
            active: false,
            discern_part: 0.0,
            grow_part: 0.0,
            support_part: 0.0,
            support_age_s: 0.0,
            discern: None,
            fell_to_dry: false,
            fell_run: 0,
        }
    }

    /// Forget the windows (a reset, a dark calibration, a face cleaned).
    pub fn clear(&mut self) {
        *self = Change::new();
    }

    /// `dt_s` of time and, when the bank measured, the currents `x_na`;
    /// `noise_na` the standard deviation of one update's currents.
    pub fn gather(
        &mut self,
        dt_s: f32,
        x_na: Option<[f32; 2]>,
        noise_na: [f32; 2],
        p: &HistoryParams,
    ) {
        self.window_s += dt_s;
        self.support_age_s = (self.support_age_s + dt_s).min(SUPPORT_AGE_MAX_S);
        if let Some(x) = x_na {
            self.sum_na[0] += x[0];
            self.sum_na[1] += x[1];
            self.n += 1;
            // A fall is seen at once, within the window: updates in a row
            // that read as a dry face, against the last window's mean.
            let change_na = p.change_noise_ua * 1000.0;
            let fell = self
                .prev_na
                .is_some_and(|(prev, _, _)| fell_to_dry(prev, x, noise_na, change_na));
            self.fell_run = if fell {
                self.fell_run.saturating_add(1)
            } else {
                0
            };
        }
        if self.window_s + 1e-4 < p.change_window_s {
            return;
        }
        let now = if self.n > 0 {
            let inv = 1.0 / self.n as f32;
            Some([self.sum_na[0] * inv, self.sum_na[1] * inv])
        } else {
            None
        };
        self.fell_to_dry = false;
        if let (Some(m), Some((prev, prev_s, prev_n))) = (now, self.prev_na) {
            self.fell_to_dry = fell_to_dry(prev, m, noise_na, p.change_noise_ua * 1000.0);
            let dt_h = 0.5 * (prev_s + self.window_s) / 3600.0;
            let inv_n = 1.0 / prev_n.max(1) as f32 + 1.0 / self.n.max(1) as f32;
            self.pending = Some((
                [m[0] - prev[0], m[1] - prev[1]],
                dt_h,
                noise_na.map(|s| s * s * inv_n),
            ));
        }
        self.prev_na = now.map(|m| (m, self.window_s, self.n));
        self.sum_na = [0.0; 2];
        self.n = 0;
        self.window_s = 0.0;
    }

    /// Start a look: the pending change, if any, is weighed by the next
    /// [`Self::weigh`] parts (true: there is one).
    pub fn start(&mut self) -> bool {
        self.active = false;
        self.discern_part = 0.0;
        self.grow_part = 0.0;
        self.support_part = 0.0;
        if let Some((d, h, v)) = self.pending.take() {
            self.delta_na = d;
            self.delta_h = h;
            self.delta_var_na2 = v;
            self.active = true;
        }
        self.active
    }

    /// End a look: the expected information of the growing states.
    pub fn end(&mut self) {
        if self.active {
            self.discern = Some(if self.grow_part > 0.0 {
                self.discern_part / self.grow_part
            } else {
                0.0
            });
            if self.grow_part > 0.0
                && self.support_part > fast_math::exp(SUPPORT_NATS) * self.grow_part
            {
                self.support_age_s = 0.0;
            }
        }
        self.active = false;
    }

    /// Expected information one window of change gives about growth as the
    /// history believes it, nats (`None` before the first change look).
    pub fn discern(&self) -> Option<f32> {
        self.discern
    }

    /// Time since a window's change last supported growth against a pause
    /// by at least [`SUPPORT_NATS`] (the growing states' likelihood ratio,
    /// weighed by their probabilities), s.
    pub fn support_age_s(&self) -> f32 {
        self.support_age_s
    }

    /// The currents fell from ice to a dry face's reading: a shed is seen
    /// (the last window's mean against the one before, until the next
    /// window ends; or [`FALL_UPDATES`] updates in a row against the last
    /// window's mean).
    pub fn fell_to_dry(&self) -> bool {
        self.fell_to_dry || self.fell_run >= FALL_UPDATES
    }

    /// The change look on the growing states at the levels `levels` (0 the
    /// dry face; `grow[b][j]` the state of rate bin b at level j, the bins'
    /// rates `rates_mm_per_h`). Two things at each level: growing against
    /// paused — every growing state there times the level's likelihood
    /// ratio (its rates' ratios against a pause, each capped at e^±6,
    /// weighed by their probabilities there) — and the rates among
    /// themselves, by their ratios against the best rate there, tempered
    /// (`HistoryParams::change_rate_temper`; at 0 each rate takes its own
    /// capped ratio, the look as it was first). Before, each state took its own capped ratio: a
    /// large change gave every rate fast enough the same e⁶ while a small
    /// one ruled the fast rates out, and the rates drifted low (a replay
    /// of rows 180 s apart: RMS ln 0.57 one hour into 2 mm/h of rime).
    /// `gain` the bank's gain, `p_rime` its probability of rime (glazed the
    /// rest).
    #[inline(never)]
    pub fn weigh(
        &mut self,
        grow: &mut [[f32; LEVELS]],
        rates_mm_per_h: &[f32],
        levels: core::ops::Range<usize>,
        gain: f32,
        p_rime: f32,
        p: &HistoryParams,
    ) {
        if !self.active {
            return;
        }
        let s0 = p.change_noise_ua * 1000.0;
        let v_update = self.delta_var_na2;
        let (s0_2, eps2, k2) = (s0 * s0, DRIFT * DRIFT, {
            let k = p.change_slope_sd;
            k * k
        });
        let d = self.delta_na;
        let p_rime = p_rime.clamp(0.0, 1.0);
        let window_h = p.change_window_s / 3600.0;
        let temper = p.change_rate_temper;
        let media = [(1usize, 1.0 - p_rime), (2usize, p_rime)];
        for j in levels {
            let at = j as f32;
            // The table now, and the change's noise there, per medium.
            let mut now = [[0.0f32; 2]; 2];
            let mut inv_v0 = [[0.0f32; 2]; 2];
            for ((n, iv), &(k, _)) in now.iter_mut().zip(inv_v0.iter_mut()).zip(&media) {
                *n = mu_at(k, at);
                for c in 0..2 {
                    let m = gain * n[c];
                    iv[c] = 1.0 / (s0_2 + v_update[c] + eps2 * m * m);
                }
            }
            let (mut sum_g, mut sum_gl) = (0.0f32, 0.0f32);
            let mut lns = [f32::NEG_INFINITY; MAX_BINS];
            let mut lrs = [0.0f32; MAX_BINS];
            let mut ln_best = f32::NEG_INFINITY;
            for (((row, &rate), ln_out), lr_out) in grow
                .iter()
                .zip(rates_mm_per_h)
                .zip(lns.iter_mut())
                .zip(lrs.iter_mut())
            {
                let g = match row.get(j) {
                    Some(&g) if g > 0.0 => g,
                    _ => continue,
                };
                let rows = rate * self.delta_h / STEP_MM;
                let look_rows = rate * window_h / STEP_MM;
                let (mut lr, mut ln_mean, mut info) = (0.0f32, 0.0f32, 0.0f32);
                for ((&(k, w), now), inv_v0) in media.iter().zip(&now).zip(&inv_v0) {
                    if w < 0.02 {
                        continue;
                    }
                    let before = mu_at(k, at - rows);
                    // What the next window would show: from the dry face
                    // the table ahead; on ice, as the last one (the slope
                    // varies slowly there).
                    let ahead = if j == 0 {
                        mu_at(k, look_rows)
                    } else {
                        let s = look_rows / rows.max(1e-6);
                        [
                            now[0] + s * (now[0] - before[0]),
                            now[1] + s * (now[1] - before[1]),
                        ]
                    };
                    let (mut ln, mut inf) = (0.0f32, 0.0f32);
                    let mut var_ratio = 1.0f32;
                    for c in 0..2 {
                        let u = gain * (now[c] - before[c]);
                        // v / v0 of the growing state, and 1 / v.
                        let ratio = 1.0 + k2 * u * u * inv_v0[c];
                        let inv_v = inv_v0[c] / ratio;
                        var_ratio *= ratio;
                        ln += d[c] * d[c] * inv_v0[c] - (d[c] - u) * (d[c] - u) * inv_v;
                        let f = gain * (ahead[c] - now[c]);
                        let ratio_f = 1.0 + k2 * f * f * inv_v0[c];
                        inf += f * f * inv_v0[c] / ratio_f;
                    }
                    let ln = 0.5 * (ln - fast_math::ln(var_ratio));
                    lr += w * fast_math::exp(ln.clamp(-MAX_LN_LR, MAX_LN_LR));
                    ln_mean += w * ln.clamp(-MAX_LN_RATE, MAX_LN_RATE);
                    info += w * 0.5 * inf;
                }
                self.discern_part += g * info;
                self.grow_part += g;
                self.support_part += g * lr;
                sum_g += g;
                sum_gl += g * lr;
                *ln_out = ln_mean;
                *lr_out = lr;
                ln_best = ln_best.max(ln_mean);
            }
            if sum_g <= 0.0 {
                continue;
            }
            if temper <= 0.0 {
                for (row, lr) in grow.iter_mut().zip(lrs) {
                    if let Some(g) = row.get_mut(j) {
                        *g *= lr;
                    }
                }
                continue;
            }
            // The rates' shares: tempered, bounded, against the best.
            let mut sum_gs = 0.0f32;
            for (row, ln) in grow.iter().zip(lns.iter_mut()) {
                let g = row.get(j).copied().unwrap_or(0.0);
                *ln = if g > 0.0 {
                    fast_math::exp((temper * (*ln - ln_best)).max(-RATE_SPAN))
                } else {
                    0.0
                };
                sum_gs += g * *ln;
            }
            if sum_gs > 0.0 {
                // The growing states' sum becomes sum_g × the level's ratio.
                let f = sum_gl / sum_gs;
                for (row, share) in grow.iter_mut().zip(lns) {
                    if let Some(g) = row.get_mut(j) {
                        *g *= share * f;
                    }
                }
            }
        }
    }
}

/// Whether the currents fell from `prev_na` to `now_na` (two windows'
/// means, nA) as a shed makes them fall: `now_na` within
/// [`DRY_READING_SD`] noise deviations `noise_na` of a dry face's zero in
/// both channels, `prev_na` beyond it in one, the fall larger than
/// [`FALL_CHANGE_SD`] deviations of the change's noise `change_na`, and at
/// most [`FALL_KEEPS`] of the currents' sum left. Thick
/// clear ice also reads near zero, but it gets there slowly: its windows
/// never fall by that much (glaze at 10 mm/h beyond 8 mm: ~0.05 µA a
/// window).
fn fell_to_dry(prev_na: [f32; 2], now_na: [f32; 2], noise_na: [f32; 2], change_na: f32) -> bool {
    let near_zero = |x: [f32; 2]| {
        x[0].abs() <= DRY_READING_SD * noise_na[0] && x[1].abs() <= DRY_READING_SD * noise_na[1]
    };
    let d = [prev_na[0] - now_na[0], prev_na[1] - now_na[1]];
    let fall2 = d[0] * d[0] + d[1] * d[1];
    let limit = FALL_CHANGE_SD * change_na;
    let (sum_prev, sum_now) = (prev_na[0] + prev_na[1], now_na[0] + now_na[1]);
    near_zero(now_na)
        && !near_zero(prev_na)
        && fall2 > 2.0 * limit * limit
        && sum_now <= FALL_KEEPS * sum_prev
}

/// At most this share of the currents' sum is left after a fall: a shed
/// takes the whole layer (thick glaze growing 0.7 mm in a window at
/// 10 mm/h keeps ~80 %).
const FALL_KEEPS: f32 = 0.3;

/// A window's change supports growth when the growing states' likelihood
/// ratio against a pause is at least e^this, nats.
const SUPPORT_NATS: f32 = 0.5;

/// The support's age saturates here, s (a day).
const SUPPORT_AGE_MAX_S: f32 = 86_400.0;

/// Updates in a row that must read as a fall before it is seen (a spike,
/// a frame's glitch, is not a shed).
const FALL_UPDATES: u16 = 5;

/// A window's mean within this many deviations of the update noise of zero
/// reads like a dry face.
const DRY_READING_SD: f32 = 3.0;

/// A fall between two windows' means larger than this many deviations of
/// the change's noise is a jump, not growth.
const FALL_CHANGE_SD: f32 = 4.0;

/// The table's mean of medium `k` at level `at` (rows from the dry face,
/// fractional; below 0 the dry face), nA, linearly between rows.
#[inline(never)]
fn mu_at(k: usize, at: f32) -> [f32; 2] {
    if at <= 0.0 {
        return [0.0; 2];
    }
    let t = table_of(k);
    let i = at as usize;
    let f = at - i as f32;
    let row = |l: usize| -> [f32; 2] {
        match l.checked_sub(1).and_then(|r| t.get(r.min(ROWS - 1))) {
            Some(e) => [f32::from(e.mu_na[0]), f32::from(e.mu_na[1])],
            None => [0.0; 2],
        }
    };
    let (a, b) = (row(i), row(i + 1));
    [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])]
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOISE_NA: [f32; 2] = [150.0; 2];
    const CHANGE_NA: f32 = 50.0;

    #[test]
    fn a_shed_falls_to_a_dry_face_and_thick_glaze_growing_does_not() {
        // Rime at 5 mm (22 / 14 µA) to a dry face's 20 / 10 nA: a shed.
        assert!(fell_to_dry(
            [22_000.0, 14_000.0],
            [20.0, 10.0],
            NOISE_NA,
            CHANGE_NA
        ));
        // Glaze at 10 mm, 0.85 of the table's gain (380 / 480 nA), shed.
        assert!(fell_to_dry(
            [380.0, 480.0],
            [5.0, -8.0],
            NOISE_NA,
            CHANGE_NA
        ));
        // Glaze growing 6.4 → 7.0 mm in a window at 10 mm/h, an accretion
        // reading low (0.6 of the mean): 520 / 990 → 440 / 800 nA, within
        // 3σ of zero after, but 83 % of the sum left.
        assert!(!fell_to_dry(
            [520.0, 990.0],
            [440.0, 800.0],
            NOISE_NA,
            CHANGE_NA
        ));
        // Already near zero before: no fall (thick glaze that reads low).
        assert!(!fell_to_dry(
            [300.0, 200.0],
            [20.0, 10.0],
            NOISE_NA,
            CHANGE_NA
        ));
        // A fall that does not reach a dry face's reading: not a shed.
        assert!(!fell_to_dry(
            [22_000.0, 14_000.0],
            [2_000.0, 900.0],
            NOISE_NA,
            CHANGE_NA
        ));
    }

    #[test]
    fn a_fall_is_seen_after_five_updates_in_a_row_not_one() {
        let p = HistoryParams::default();
        let mut c = Change::new();
        // A window of rime at 22 / 14 µA, one update a second.
        for _ in 0..240 {
            c.gather(1.0, Some([22_000.0, 14_000.0]), NOISE_NA, &p);
        }
        assert!(!c.fell_to_dry());
        // One spike to zero, then rime again: no fall.
        c.gather(1.0, Some([0.0, 0.0]), NOISE_NA, &p);
        c.gather(1.0, Some([22_000.0, 14_000.0]), NOISE_NA, &p);
        assert!(!c.fell_to_dry());
        // The layer falls off: seen at the fifth update.
        for k in 1..=5 {
            assert!(!c.fell_to_dry(), "seen after {k} updates");
            c.gather(1.0, Some([10.0, 5.0]), NOISE_NA, &p);
        }
        assert!(c.fell_to_dry());
    }
}
