//! The queue's losses told in the log, once per episode: a warning when it
//! starts dropping measurements (its bound reached, or a failing disk's
//! memory full), at most one more per [`DROP_LOG_INTERVAL`] while it goes
//! on (with the count since the last line), and a line when it has dropped
//! nothing for [`DROP_EPISODE_END`]. The count itself is
//! [`super::Queue::dropped`].

use std::time::{Duration, Instant};

/// At most one "still dropping" line per this long.
pub const DROP_LOG_INTERVAL: Duration = Duration::from_secs(60);
/// An episode ends after this long without a drop.
pub const DROP_EPISODE_END: Duration = Duration::from_secs(60);

/// What to log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DropLine {
    /// The queue started dropping: `dropped` records so far.
    Started {
        /// Records dropped since the last look.
        dropped: u64,
    },
    /// Still dropping: `since` more since the last line, `episode` in all.
    Continuing {
        /// Since the last line.
        since: u64,
        /// Since the episode began.
        episode: u64,
    },
    /// No drop for [`DROP_EPISODE_END`]: the episode lost `episode`.
    Ended {
        /// Records the episode lost.
        episode: u64,
    },
}

#[derive(Debug)]
struct Episode {
    first_total: u64,
    last_drop: Instant,
    last_line: Instant,
    logged_total: u64,
}

/// The state between looks at the queue's drop counter.
#[derive(Debug)]
pub struct DropLog {
    seen: u64,
    episode: Option<Episode>,
}

impl DropLog {
    /// Start from a counter of `dropped` (earlier runs' losses are not
    /// told again).
    pub fn new(dropped: u64) -> DropLog {
        DropLog {
            seen: dropped,
            episode: None,
        }
    }

    /// The counter is `dropped` at `now`: the line to log, if one is due.
    pub fn observe(&mut self, dropped: u64, now: Instant) -> Option<DropLine> {
        let new = dropped.saturating_sub(self.seen);
        let before = self.seen;
        self.seen = self.seen.max(dropped);
        match &mut self.episode {
            None if new > 0 => {
                self.episode = Some(Episode {
                    first_total: before,
                    last_drop: now,
                    last_line: now,
                    logged_total: dropped,
                });
                Some(DropLine::Started { dropped: new })
            }
            None => None,
            Some(e) if new > 0 => {
                e.last_drop = now;
                if now.saturating_duration_since(e.last_line) < DROP_LOG_INTERVAL {
                    return None;
                }
                let since = dropped - e.logged_total;
                e.last_line = now;
                e.logged_total = dropped;
                Some(DropLine::Continuing {
                    since,
                    episode: dropped - e.first_total,
                })
            }
            Some(e) if now.saturating_duration_since(e.last_drop) >= DROP_EPISODE_END => {
                let episode = self.seen - e.first_total;
                self.episode = None;
                Some(DropLine::Ended { episode })
            }
            Some(_) => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_warning_per_episode_then_one_a_minute_then_its_end() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let mut l = DropLog::new(7);
        assert_eq!(l.observe(7, at(0)), None, "earlier runs' losses");
        // Looked at every 100 ms: 10 drops per look for 150 s.
        let mut lines = Vec::new();
        let mut total = 7;
        for k in 1..=1_500u64 {
            total += 10;
            lines.extend(l.observe(total, at(k * 100)).map(|x| (k * 100, x)));
        }
        // Then none for 70 s.
        for k in 1_501..=2_200u64 {
            lines.extend(l.observe(total, at(k * 100)).map(|x| (k * 100, x)));
        }
        assert_eq!(
            lines,
            [
                (100, DropLine::Started { dropped: 10 }),
                (
                    60_100,
                    DropLine::Continuing {
                        since: 6_000,
                        episode: 6_010
                    }
                ),
                (
                    120_100,
                    DropLine::Continuing {
                        since: 6_000,
                        episode: 12_010
                    }
                ),
                (210_000, DropLine::Ended { episode: 15_000 }),
            ]
        );
        // A new episode is told at once.
        assert_eq!(
            l.observe(total + 1, at(220_000)),
            Some(DropLine::Started { dropped: 1 })
        );
    }
}
