//! A log line at most once per interval, with the count of the events it
//! stands for (a flood of connections or writes must not flood the log).

use std::time::{Duration, Instant};

/// Rate limit of one kind of log line.
#[derive(Debug)]
pub struct LogLimit {
    interval: Duration,
    last: Option<Instant>,
    unlogged: u64,
}

impl LogLimit {
    /// At most one line per `interval`.
    pub const fn new(interval: Duration) -> LogLimit {
        LogLimit {
            interval,
            last: None,
            unlogged: 0,
        }
    }

    /// An event at `now`: `Some(n)`: log it now, for the `n` events (this
    /// one included) since the last line; `None`: counted, not logged.
    pub fn event(&mut self, now: Instant) -> Option<u64> {
        self.unlogged += 1;
        let due = self
            .last
            .is_none_or(|t| now.saturating_duration_since(t) >= self.interval);
        due.then(|| {
            self.last = Some(now);
            std::mem::take(&mut self.unlogged)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_line_per_interval_with_the_count_it_stands_for() {
        let t0 = Instant::now();
        let mut l = LogLimit::new(Duration::from_secs(10));
        // 100 events per second for 25 s.
        let logged: Vec<(u64, u64)> = (0..2_500u64)
            .filter_map(|k| {
                l.event(t0 + Duration::from_millis(k * 10))
                    .map(|n| (k / 100, n))
            })
            .collect();
        assert_eq!(logged, [(0, 1), (10, 1_000), (20, 1_000)]);
    }
}
