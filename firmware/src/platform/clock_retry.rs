//! When the board tries the external clock (HSE) again after running on
//! the internal HSI: after a failed HSE probe at boot or a fail-over by the
//! clock security system. HSI can be −8 % in the cold, beyond the link's
//! ≈ 2.9 % budget (`platform::field_link`): without a retry the link would
//! stay dead until a power cycle. A retry costs the board up to
//! [`RETRY_COST_MAX_MS`] of busy waiting (the two HSE probes and the PLL's
//! lock), so the retries back off: the first [`RETRY_FIRST_MS`] after the
//! fallback, then twice as long after each failed one, at most
//! [`RETRY_MAX_MS`] apart. An HSE that returns and holds for
//! [`STABLE_AFTER_MS`] starts the back-off afresh at its next failure; one
//! that flaps (fails again sooner) keeps the longer interval, so a
//! marginal crystal cannot make the node probe every 10 s.

/// The first retry after a fallback, ms.
pub const RETRY_FIRST_MS: u64 = 10_000;
/// The longest interval between retries, ms (10 min).
pub const RETRY_MAX_MS: u64 = 600_000;
/// An HSE that held this long after a retry counts as back for good, ms (1 h).
pub const STABLE_AFTER_MS: u64 = 3_600_000;
/// The most one retry blocks the board, ms: two HSE probes of 100 ms each
/// (bypass, then crystal) and the PLL's lock (≤ 2 ms, bounded by 10 ms).
pub const RETRY_COST_MAX_MS: u64 = 210;

// At the cap a retry's busy time is 0.035 % of the node's time.
const _: () = assert!(RETRY_COST_MAX_MS * 10_000 / RETRY_MAX_MS < 4);

/// The retry policy's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct HseRetry {
    /// When the next retry is due (`None`: on the HSE, nothing to retry).
    next_ms: Option<u64>,
    /// The interval after the next failed retry, ms.
    interval_ms: u64,
    /// When the HSE last came back through a retry.
    restored_ms: Option<u64>,
}

impl HseRetry {
    /// On the HSE, nothing to retry.
    pub const fn new() -> Self {
        HseRetry {
            next_ms: None,
            interval_ms: RETRY_FIRST_MS,
            restored_ms: None,
        }
    }

    /// The node runs on HSI from `now_ms` (no HSE at boot, or the clock
    /// security system switched). Nothing changes if a retry is already
    /// planned.
    pub fn fell_back(&mut self, now_ms: u64) {
        if self.next_ms.is_some() {
            return;
        }
        let flapped = self
            .restored_ms
            .is_some_and(|at| now_ms.saturating_sub(at) < STABLE_AFTER_MS);
        if !flapped {
            self.interval_ms = RETRY_FIRST_MS;
        }
        self.next_ms = Some(now_ms.saturating_add(self.interval_ms));
        self.interval_ms = self.interval_ms.saturating_mul(2).min(RETRY_MAX_MS);
    }

    /// Is a retry due at `now_ms`?
    pub fn due(&self, now_ms: u64) -> bool {
        self.next_ms.is_some_and(|t| now_ms >= t)
    }

    /// When the next retry is due (for the loop's wake-up).
    pub fn next_ms(&self) -> Option<u64> {
        self.next_ms
    }

    /// The retry at `now_ms` failed: the next one comes after the
    /// (doubled, capped) interval.
    pub fn failed(&mut self, now_ms: u64) {
        self.next_ms = Some(now_ms.saturating_add(self.interval_ms));
        self.interval_ms = self.interval_ms.saturating_mul(2).min(RETRY_MAX_MS);
    }

    /// The retry at `now_ms` brought the HSE back.
    pub fn restored(&mut self, now_ms: u64) {
        self.next_ms = None;
        self.restored_ms = Some(now_ms);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The retries of an HSE that never comes back, as times in s.
    fn retries(policy: &mut HseRetry, from_ms: u64, to_ms: u64) -> Vec<u64> {
        let mut at = Vec::new();
        let mut t = from_ms;
        while t < to_ms {
            if policy.due(t) {
                at.push(t / 1_000);
                policy.failed(t);
            }
            t += 1_000;
        }
        at
    }

    #[test]
    fn retries_back_off_from_10_s_to_10_min() {
        let mut p = HseRetry::new();
        assert!(!p.due(u64::MAX), "on the HSE nothing is retried");
        p.fell_back(5_000);
        assert_eq!(p.next_ms(), Some(15_000));
        let at = retries(&mut p, 5_000, 3_600_000);
        // 15, +20, +40, +80, +160, +320, +600 (capped), +600, ...
        assert_eq!(at[..8], [15, 35, 75, 155, 315, 635, 1_235, 1_835]);
        assert_eq!(at.len(), 10);
        // A second fallback report changes nothing while one is planned.
        let next = p.next_ms();
        p.fell_back(3_600_000);
        assert_eq!(p.next_ms(), next);
    }

    #[test]
    fn a_returned_hse_that_holds_starts_afresh_and_a_flapping_one_does_not() {
        let mut p = HseRetry::new();
        p.fell_back(0);
        let _ = retries(&mut p, 0, 200_000); // retries at 10, 30, 70, 150 s
        p.restored(200_000);
        assert!(!p.due(10_000_000));
        // It fails again within the hour: the interval stays long (320 s).
        p.fell_back(300_000);
        assert_eq!(p.next_ms(), Some(300_000 + 320_000));
        p.restored(620_000);
        // Held for more than an hour: the first retry after 10 s again.
        p.fell_back(620_000 + STABLE_AFTER_MS);
        assert_eq!(p.next_ms(), Some(620_000 + STABLE_AFTER_MS + 10_000));
    }
}
