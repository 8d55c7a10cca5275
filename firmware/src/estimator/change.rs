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

/// Largest |ln likelihood ratio| one change look gives a state: a jump
/// (a shed, a wiped face) fits neither hypothesis.
const MAX_LN_LR: f32 = 6.0;

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
    /// Mean of the previous window, nA, and its length, s.
    prev_na: Option<([f32; 2], f32)>,
    /// The change between the last two windows' means, nA, and the time
    /// between their centres, h; `None` when no change waits for a look.
    pending: Option<([f32; 2], f32)>,
    /// The change the look uses (taken from `pending` when the look starts).
    delta_na: [f32; 2],
    delta_h: f32,
    /// This look has a change to weigh.
    active: bool,
    /// Expected information of one window of change, nats, if the ice grew
    /// as the history believes (summed over the look's parts).
    discern_part: f32,
    grow_part: f32,
    /// Its value at the last completed look (`None`: none yet).
    discern: Option<f32>,
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
            active: false,
            discern_part: 0.0,
            grow_part: 0.0,
            discern: None,
        }
    }

    /// Forget the windows (a reset, a dark calibration, a face cleaned).
    pub fn clear(&mut self) {
        *self = Change::new();
    }

    /// `dt_s` of time and, when the bank measured, the currents `x_na`.
    pub fn gather(&mut self, dt_s: f32, x_na: Option<[f32; 2]>, p: &HistoryParams) {
        self.window_s += dt_s;
        if let Some(x) = x_na {
            self.sum_na[0] += x[0];
            self.sum_na[1] += x[1];
            self.n += 1;
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
        if let (Some(m), Some((prev, prev_s))) = (now, self.prev_na) {
            let dt_h = 0.5 * (prev_s + self.window_s) / 3600.0;
            self.pending = Some(([m[0] - prev[0], m[1] - prev[1]], dt_h));
        }
        self.prev_na = now.map(|m| (m, self.window_s));
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
        if let Some((d, h)) = self.pending.take() {
            self.delta_na = d;
            self.delta_h = h;
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
        }
        self.active = false;
    }

    /// Expected information one window of change gives about growth as the
    /// history believes it, nats (`None` before the first change look).
    pub fn discern(&self) -> Option<f32> {
        self.discern
    }

    /// The change look on the growing states of rate `rate_mm_per_h` at
    /// the levels `grow` (one per level from level `first`; 0 the dry
    /// face): each times its likelihood ratio against a paused state at
    /// its level. `gain` the
    /// bank's gain, `p_rime` its probability of rime (glazed the rest).
    #[inline(never)]
    pub fn weigh(
        &mut self,
        grow: &mut [f32],
        first: usize,
        rate_mm_per_h: f32,
        gain: f32,
        p_rime: f32,
        p: &HistoryParams,
    ) {
        if !self.active {
            return;
        }
        let rows = rate_mm_per_h * self.delta_h / STEP_MM;
        let look_rows = rate_mm_per_h * p.change_window_s / 3600.0 / STEP_MM;
        let s0 = p.change_noise_ua * 1000.0;
        let (s0_2, eps2, k2) = (s0 * s0, DRIFT * DRIFT, {
            let k = p.change_slope_sd;
            k * k
        });
        let d = self.delta_na;
        let p_rime = p_rime.clamp(0.0, 1.0);
        for (j, g) in grow.iter_mut().enumerate() {
            let j = j + first;
            if *g <= 0.0 {
                continue;
            }
            let at = j as f32;
            let mut lr = 0.0f32;
            let mut info = 0.0f32;
            for (k, w) in [(1usize, 1.0 - p_rime), (2usize, p_rime)] {
                if w < 0.02 {
                    continue;
                }
                let now = mu_at(k, at);
                let before = mu_at(k, at - rows);
                // What the next window would show: from the dry face the
                // table ahead; on ice, as the last one (the slope varies
                // slowly there).
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
                    let m = gain * now[c];
                    let inv_v0 = 1.0 / (s0_2 + eps2 * m * m);
                    // v / v0 of the growing state, and 1 / v.
                    let ratio = 1.0 + k2 * u * u * inv_v0;
                    let inv_v = inv_v0 / ratio;
                    var_ratio *= ratio;
                    ln += d[c] * d[c] * inv_v0 - (d[c] - u) * (d[c] - u) * inv_v;
                    let f = gain * (ahead[c] - now[c]);
                    let ratio_f = 1.0 + k2 * f * f * inv_v0;
                    inf += f * f * inv_v0 / ratio_f;
                }
                let ln = 0.5 * (ln - fast_math::ln(var_ratio));
                lr += w * fast_math::exp(ln.clamp(-MAX_LN_LR, MAX_LN_LR));
                info += w * 0.5 * inf;
            }
            self.discern_part += *g * info;
            self.grow_part += *g;
            *g *= lr;
        }
    }
}

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
