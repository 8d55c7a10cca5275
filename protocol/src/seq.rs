//! The sequence-gap rule: what a frame's [`DeviceFrame::seq`](crate::DeviceFrame)
//! says about the frames before it. Every host reader uses it (the serial
//! link of `foisctl` and the gateway, the hardware-in-loop observer), so
//! "lost", "restarted" and "duplicate" mean the same everywhere.
//!
//! The node numbers every frame it sends, of any kind, +1 each, wrapping at
//! `u32::MAX`. Seen from the host, the next number `seq` after `last` is
//!
//! | `seq − last` (wrapping) | meaning |
//! | --- | --- |
//! | 1 | in order |
//! | 0 | the same frame again (ignored) |
//! | 2 … 2³¹ − 1 | `seq − last − 1` frames were lost in between |
//! | 2³¹ … 2³² − 1 | the number went back: the node restarted |
//!
//! At 10 frames per second a gap of 2³¹ frames would take 6.8 years, so a
//! jump of half the number space or more is a restart, never a loss.

/// What one frame's sequence number says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeqEvent {
    /// The first frame seen.
    First,
    /// The next frame, as expected.
    InOrder,
    /// This many frames were lost before this one.
    Gap(u64),
    /// The same number again (ignored).
    Duplicate,
    /// The number went backwards: the node restarted.
    Restart,
}

/// Classify `seq` following `last` (see the module's table).
pub const fn classify(last: u32, seq: u32) -> SeqEvent {
    let d = seq.wrapping_sub(last);
    if d == 1 {
        SeqEvent::InOrder
    } else if d == 0 {
        SeqEvent::Duplicate
    } else if d < 1 << 31 {
        SeqEvent::Gap((d - 1) as u64)
    } else {
        SeqEvent::Restart
    }
}

/// Counts lost frames and restarts from a stream of sequence numbers.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SeqTracker {
    last: Option<u32>,
    /// Frames lost so far (the sum of every [`SeqEvent::Gap`]).
    pub lost: u64,
    /// Node restarts seen.
    pub restarts: u64,
    /// Frames seen twice.
    pub duplicates: u64,
}

impl SeqTracker {
    /// A tracker that has seen nothing.
    pub const fn new() -> SeqTracker {
        SeqTracker {
            last: None,
            lost: 0,
            restarts: 0,
            duplicates: 0,
        }
    }

    /// Record one frame's sequence number; what it says.
    pub fn observe(&mut self, seq: u32) -> SeqEvent {
        let ev = match self.last {
            None => SeqEvent::First,
            Some(last) => classify(last, seq),
        };
        match ev {
            SeqEvent::Gap(n) => self.lost += n,
            SeqEvent::Restart => self.restarts += 1,
            SeqEvent::Duplicate => self.duplicates += 1,
            SeqEvent::First | SeqEvent::InOrder => {}
        }
        self.last = Some(seq);
        ev
    }

    /// The last sequence number seen.
    pub const fn last(&self) -> Option<u32> {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_wraps_duplicates_and_restarts() {
        let mut t = SeqTracker::new();
        assert_eq!(t.observe(10), SeqEvent::First);
        assert_eq!(t.observe(11), SeqEvent::InOrder);
        assert_eq!(t.observe(15), SeqEvent::Gap(3));
        assert_eq!(t.observe(15), SeqEvent::Duplicate);
        assert_eq!(t.observe(2), SeqEvent::Restart);
        assert_eq!(t.observe(u32::MAX - 1), SeqEvent::Restart);
        // Across the wrap: MAX-1, (MAX lost), 0.
        assert_eq!(t.observe(0), SeqEvent::Gap(1));
        assert_eq!(t.observe(1), SeqEvent::InOrder);
        assert_eq!((t.lost, t.restarts, t.duplicates), (4, 2, 1));
        assert_eq!(t.last(), Some(1));
    }

    #[test]
    fn half_the_number_space_is_the_border_between_loss_and_restart() {
        assert_eq!(classify(0, (1 << 31) - 1), SeqEvent::Gap((1 << 31) - 2));
        assert_eq!(classify(0, 1 << 31), SeqEvent::Restart);
        assert_eq!(classify(u32::MAX, 0), SeqEvent::InOrder);
        assert_eq!(classify(5, 5), SeqEvent::Duplicate);
        // A node that reset sends Hello with seq 0: a restart from anywhere
        // in the first half of the number space.
        assert_eq!(classify(1_000_000, 0), SeqEvent::Restart);
    }
}
