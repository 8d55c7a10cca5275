//! The node's clock across the wrap of the board's timer.
//!
//! embassy-stm32 0.6's time driver counts a 16-bit timer and a 32-bit
//! period counter: `((period as u64) << 15) + counter`, 47 bits of ticks.
//! At embassy-time's default 1 MHz tick that wraps after 2^47 µs =
//! 4.46 years of uptime (embassy's "136 years" assumes a 32.768 kHz tick),
//! and `Instant::now()` starts again at 0. Everything in the library runs
//! on a `u64` of milliseconds that must only go forward (`Schedule`, the
//! saves, the rule's timers), so:
//!
//! - [`Uptime`] extends the raw tick with an explicit epoch (one more
//!   `2^47` each time the raw value goes backwards): the milliseconds it
//!   gives never go back and wrap only after 584 million years;
//! - the board resets itself [`RESET_BEFORE_WRAP_TICKS`] before the raw
//!   wrap ([`reset_before_wrap`]), in a quiet moment and with the rule's
//!   state and acknowledgement kept in the backup registers: an embassy
//!   timer armed across the wrap would wait for a tick value the counter
//!   never reaches (`Timer::after` adds to the raw `Instant`), and a task
//!   behind it would hang.

/// Bits of the board's raw tick (embassy-stm32's 16-bit time driver).
pub const TICK_BITS: u32 = 47;
/// The raw tick wraps here.
pub const WRAP_TICKS: u64 = 1 << TICK_BITS;
/// Ticks per millisecond (embassy-time's default 1 MHz tick).
pub const TICKS_PER_MS: u64 = 1_000;
/// How long before the raw wrap the board resets itself, ticks (one day:
/// far more than any timer the board arms, at most a 10 s wait).
pub const RESET_BEFORE_WRAP_TICKS: u64 = 24 * 3_600 * 1_000 * TICKS_PER_MS;

/// Raw ticks → milliseconds that never go backwards.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Uptime {
    last_raw: u64,
    epochs: u64,
}

impl Uptime {
    /// At boot (the raw tick starts at 0).
    pub const fn new() -> Self {
        Uptime {
            last_raw: 0,
            epochs: 0,
        }
    }

    /// Milliseconds since boot for this raw tick (`Instant::as_ticks()`;
    /// bits above [`TICK_BITS`] are ignored). Call it at least once per
    /// wrap period (the measure loop runs at least every 0.5 s).
    pub fn now_ms(&mut self, raw_ticks: u64) -> u64 {
        let raw = raw_ticks & (WRAP_TICKS - 1);
        if raw < self.last_raw {
            self.epochs = self.epochs.wrapping_add(1);
        }
        self.last_raw = raw;
        let ticks = u128::from(self.epochs) * u128::from(WRAP_TICKS) + u128::from(raw);
        u64::try_from(ticks / u128::from(TICKS_PER_MS)).unwrap_or(u64::MAX)
    }
}

/// The raw tick is within [`RESET_BEFORE_WRAP_TICKS`] of the wrap: the
/// board resets itself now (after 4.46 years minus a day of uptime).
pub const fn reset_before_wrap(raw_ticks: u64) -> bool {
    raw_ticks & (WRAP_TICKS - 1) >= WRAP_TICKS - RESET_BEFORE_WRAP_TICKS
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::platform::schedule::Schedule;

    #[test]
    fn the_wrap_is_after_four_and_a_half_years() {
        let years = WRAP_TICKS as f64 / 1e6 / (365.25 * 86_400.0);
        assert!((4.45..4.47).contains(&years), "{years}");
        assert!(!reset_before_wrap(0));
        assert!(!reset_before_wrap(WRAP_TICKS - RESET_BEFORE_WRAP_TICKS - 1));
        assert!(reset_before_wrap(WRAP_TICKS - RESET_BEFORE_WRAP_TICKS));
        assert!(reset_before_wrap(WRAP_TICKS - 1));
    }

    #[test]
    fn milliseconds_go_on_across_the_wrap() {
        let mut up = Uptime::new();
        let before = WRAP_TICKS - 1_500_000; // 1.5 s before the wrap
        let t0 = up.now_ms(before);
        assert_eq!(t0, before / 1_000);
        // The raw tick wraps to 0.5 s: 2 s later, not 140 737 s earlier.
        assert_eq!(up.now_ms(500_000), t0 + 2_000);
        assert_eq!(up.now_ms(1_500_000), t0 + 3_000);
        // A second wrap.
        assert_eq!(
            up.now_ms(WRAP_TICKS - 1_000),
            (2 * WRAP_TICKS - 1_000) / 1_000
        );
        assert_eq!(up.now_ms(0), 2 * WRAP_TICKS / 1_000);
    }

    /// A node streaming at 100 ms across the wrap: on the raw clock the
    /// schedule stops (the next frame lies 4.46 years ahead) and its
    /// progress check fails; on `Uptime` the frames go on, every 100 ms.
    #[test]
    fn frames_go_on_across_the_wrap_on_uptime_and_stop_on_the_raw_clock() {
        let start = WRAP_TICKS - 2_000_000;
        let ticks = (0..5_000u64).map(|ms| (start + ms * 1_000) & (WRAP_TICKS - 1));

        let mut up = Uptime::new();
        let mut s = Schedule::new();
        let mut frames = 0;
        for t in ticks.clone() {
            let now = up.now_ms(t);
            if s.poll(now, true, 100).frame {
                frames += 1;
            }
            assert!(s.on_track(now, 100), "at {now}");
        }
        assert_eq!(frames, 50);

        let mut s = Schedule::new();
        let mut frames = 0;
        let mut off_track = 0;
        for t in ticks {
            let now = t / TICKS_PER_MS;
            if s.poll(now, true, 100).frame {
                frames += 1;
            }
            if !s.on_track(now, 100) {
                off_track += 1;
            }
        }
        assert_eq!(frames, 20, "only the 2 s before the wrap");
        assert_eq!(off_track, 3_000, "every poll after the wrap");
    }
}
