//! The tracer's random streams: PCG32 (`rand_pcg::Pcg32`, XSH RR on a 64-bit LCG), bit for
//! bit, plus a block scan for the bubble walk.
//!
//! The bubble walk of dense ice (rime) draws once per 0.1 mm layer and ray and only acts on
//! the draws below P_B: about 380 000 draws per accretion for 80 000 bubbles. Drawn one by
//! one, each draw waits for the previous LCG step and every bubble is a mispredicted branch.
//! [`Pcg32Stream::draws_until_below`] computes four states at once by LCG jump-ahead
//! (s_k = Mᵏ·s + c·(1 + M + … + Mᵏ⁻¹)) and tests four outputs together. The outputs, and the
//! state after the scan, are exactly those of drawing one by one (tested against
//! `rand_pcg::Pcg32`), so the random-stream layout of the model is unchanged.

/// The PCG multiplier (`rand_pcg`'s `MULTIPLIER`, PCG's default for 64-bit state).
const MUL: u64 = 6_364_136_223_846_793_005;

/// Mᵏ for k = 0..=8.
const MUL_POW: [u64; 9] = {
    let mut p = [1u64; 9];
    let mut k = 1;
    while k < 9 {
        p[k] = p[k - 1].wrapping_mul(MUL);
        k += 1;
    }
    p
};

/// 1 + M + … + Mᵏ⁻¹ for k = 0..=8: the increment's factor after k steps
/// (state after k steps = Mᵏ·s + c·(1 + M + … + Mᵏ⁻¹)).
const INC_SUM: [u64; 9] = {
    let mut s = [0u64; 9];
    let mut k = 1;
    while k < 9 {
        s[k] = s[k - 1].wrapping_add(MUL_POW[k - 1]);
        k += 1;
    }
    s
};

/// Outputs computed per refill of a [`Pcg32Stream`].
const BLOCK: usize = 32;
/// Independent LCG lanes of a refill.
const LANES: usize = 8;

/// One PCG32 stream, identical to `rand_pcg::Pcg32::new(state, stream)`, computed a block
/// of outputs at a time.
#[derive(Clone, Debug)]
pub(crate) struct Pcg32Stream {
    buf: [u32; BLOCK],
    /// The next output is `buf[pos]`; `pos == BLOCK`: refill first.
    pos: usize,
    /// The LCG state of the first output after the buffer.
    state: u64,
    /// The increment c (odd).
    inc: u64,
}

/// XSH RR output of one LCG state (`rand_pcg`'s `Lcg64Xsh32::try_next_u32`).
#[inline(always)]
fn output(state: u64) -> u32 {
    const ROTATE: u32 = 59; // 64 - 5
    const XSHIFT: u32 = 18; // (5 + 32) / 2
    const SPARE: u32 = 27; // 64 - 32 - 5
    let rot = (state >> ROTATE) as u32;
    let xsh = (((state >> XSHIFT) ^ state) >> SPARE) as u32;
    xsh.rotate_right(rot)
}

impl Pcg32Stream {
    /// The stream `rand_pcg::Pcg32::new(state, stream)`.
    #[inline]
    pub(crate) fn new(state: u64, stream: u64) -> Self {
        let inc = (stream << 1) | 1;
        let s = state.wrapping_add(inc).wrapping_mul(MUL).wrapping_add(inc);
        Pcg32Stream {
            buf: [0; BLOCK],
            pos: BLOCK,
            state: s,
            inc,
        }
    }

    /// The next `BLOCK` outputs: `LANES` LCGs, lane k starting k steps ahead and moving
    /// `LANES` steps at a time, so that no step waits for the one before.
    #[inline(never)]
    fn refill(&mut self) {
        let s = self.state;
        let mut lane = [0u64; LANES];
        for (k, l) in lane.iter_mut().enumerate() {
            *l = s
                .wrapping_mul(MUL_POW[k])
                .wrapping_add(self.inc.wrapping_mul(INC_SUM[k]));
        }
        let (mul_l, inc_l) = (MUL_POW[LANES], self.inc.wrapping_mul(INC_SUM[LANES]));
        for chunk in self.buf.chunks_exact_mut(LANES) {
            for (o, l) in chunk.iter_mut().zip(lane.iter_mut()) {
                *o = output(*l);
                *l = l.wrapping_mul(mul_l).wrapping_add(inc_l);
            }
        }
        self.state = lane[0];
        self.pos = 0;
    }

    /// The next 32-bit output.
    #[inline(always)]
    pub(crate) fn next_u32(&mut self) -> u32 {
        if self.pos == BLOCK {
            self.refill();
        }
        let x = self.buf[self.pos];
        self.pos += 1;
        x
    }

    /// Two outputs combined low word first, like `rand_core`'s `next_u64_via_u32`.
    #[inline]
    pub(crate) fn next_u64(&mut self) -> u64 {
        let x = u64::from(self.next_u32());
        let y = u64::from(self.next_u32());
        (y << 32) | x
    }

    /// Draw until a draw is below `threshold`, at most `max` draws. Returns the number of
    /// draws at or above the threshold before it (that draw is consumed too), or `max` if
    /// none of `max` draws is below (all `max` consumed). The same as calling
    /// [`Self::next_u32`] in a loop.
    #[inline]
    pub(crate) fn draws_until_below(&mut self, threshold: u32, max: u32) -> u32 {
        let mut n = 0u32;
        while n < max {
            if self.pos == BLOCK {
                self.refill();
            }
            let avail = (BLOCK - self.pos).min((max - n) as usize);
            let window = &self.buf[self.pos..self.pos + avail];
            if let Some(t) = window.iter().position(|&x| x < threshold) {
                self.pos += t + 1;
                return n + t as u32;
            }
            self.pos += avail;
            n += avail as u32;
        }
        max
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_core::Rng;
    use rand_pcg::Pcg32;

    #[test]
    fn outputs_equal_rand_pcg() {
        for (state, stream) in [(0u64, 0u64), (1, 2), (0xDEAD_BEEF, 77), (u64::MAX, u64::MAX)] {
            let mut a = Pcg32::new(state, stream);
            let mut b = Pcg32Stream::new(state, stream);
            for _ in 0..1000 {
                assert_eq!(a.next_u32(), b.next_u32());
            }
            for _ in 0..100 {
                assert_eq!(a.next_u64(), b.next_u64());
            }
        }
    }

    #[test]
    fn scan_equals_drawing_one_by_one() {
        let mut checked = 0;
        for stream in 0..40u64 {
            for (thr, max) in [
                (0u32, 7u32),
                (1 << 20, 50),
                (900_000_000, 1000),
                (2_000_000_000, 3),
                (u32::MAX, 9),
                (3_000_000_000, 0),
            ] {
                let key = 0x1234_5678 ^ stream.wrapping_mul(0x9E37_79B9);
                let mut a = Pcg32::new(key, stream);
                let mut b = Pcg32Stream::new(key, stream);
                for _ in 0..200 {
                    // Reference: one draw at a time.
                    let mut want = max;
                    for n in 0..max {
                        if a.next_u32() < thr {
                            want = n;
                            break;
                        }
                    }
                    assert_eq!(b.draws_until_below(thr, max), want);
                    // The streams stay in step.
                    assert_eq!(a.next_u32(), b.next_u32());
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 40 * 6 * 200);
    }
}
