//! Modbus RTU framing by silence (Modbus over serial line V1.02, §2.5.1.1):
//! a frame is the bytes between two silences of at least 3.5 character
//! times; a gap of more than 1.5 characters inside a frame makes it
//! incomplete (discarded, with whatever follows until the next 3.5-character
//! silence). Above 19 200 Bd both are fixed at 750 µs and 1.75 ms.
//!
//! [`SilenceFramer`] is fed each received byte with the time it arrived and
//! polled with the time now; it never panics and never holds more than
//! [`MAX_ADU`] bytes (a longer frame is discarded whole).

use fois_protocol::Parity;

/// The longest RTU frame: address, PDU of 253, CRC (§2.5.1.1).
pub const MAX_ADU: usize = 256;

/// One frame's bytes.
pub type Adu = heapless::Vec<u8, MAX_ADU>;

/// The inter-character (t1.5) and inter-frame (t3.5) times, µs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Silences {
    /// A gap longer than this inside a frame breaks it, µs.
    pub t15_us: u32,
    /// A gap at least this long ends a frame, µs.
    pub t35_us: u32,
}

impl Silences {
    /// The silences at `baud` with `parity`'s character length: 1.5 and
    /// 3.5 characters, rounded up; above 19 200 Bd the fixed 750 µs and
    /// 1 750 µs.
    pub const fn at(baud: u32, parity: Parity) -> Silences {
        if baud > 19_200 || baud == 0 {
            return Silences {
                t15_us: 750,
                t35_us: 1_750,
            };
        }
        let bits = parity.bits_per_char() as u64;
        let baud = baud as u64;
        Silences {
            t15_us: (bits * 1_500_000).div_ceil(baud) as u32,
            t35_us: (bits * 3_500_000).div_ceil(baud) as u32,
        }
    }
}

/// The receive side of an RTU link.
#[derive(Debug, Clone)]
pub struct SilenceFramer {
    silences: Silences,
    buf: Adu,
    /// When the last byte came, µs.
    last_us: Option<u64>,
    /// The frame being received is broken (a 1.5-character gap, too long):
    /// dropped at the next 3.5-character silence.
    broken: bool,
    /// Frames dropped as broken or too long.
    dropped: u32,
}

impl SilenceFramer {
    /// A framer for these silences.
    pub const fn new(silences: Silences) -> Self {
        SilenceFramer {
            silences,
            buf: heapless::Vec::new(),
            last_us: None,
            broken: false,
            dropped: 0,
        }
    }

    /// Its silences.
    pub fn silences(&self) -> Silences {
        self.silences
    }

    /// Frames dropped so far (broken by a gap or too long).
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// A byte received at `now_us`. Returns the frame that a silence of
    /// 3.5 characters before it ended (if [`poll`](Self::poll) did not
    /// take it yet).
    pub fn push(&mut self, byte: u8, now_us: u64) -> Option<Adu> {
        let done = self.poll(now_us);
        if let Some(last) = self.last_us
            && now_us.saturating_sub(last) > u64::from(self.silences.t15_us)
        {
            self.broken = true;
        }
        if self.buf.push(byte).is_err() {
            self.broken = true;
        }
        self.last_us = Some(now_us);
        done
    }

    /// The frame that ended, if the line has been silent for 3.5
    /// characters at `now_us`; a broken one is dropped.
    pub fn poll(&mut self, now_us: u64) -> Option<Adu> {
        let last = self.last_us?;
        if now_us.saturating_sub(last) < u64::from(self.silences.t35_us) {
            return None;
        }
        self.last_us = None;
        let frame = core::mem::take(&mut self.buf);
        if core::mem::take(&mut self.broken) {
            self.dropped = self.dropped.saturating_add(1);
            return None;
        }
        Some(frame)
    }

    /// When [`poll`](Self::poll) will give the frame being received, µs
    /// (`None`: nothing received).
    pub fn deadline_us(&self) -> Option<u64> {
        self.last_us
            .map(|t| t.saturating_add(u64::from(self.silences.t35_us)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_silences_at_the_field_rates() {
        // 19 200 Bd 8E1: 11 bits = 573 µs a character; 1.5 → 860 µs,
        // 3.5 → 2 006 µs.
        let s = Silences::at(19_200, Parity::Even8E1);
        assert_eq!((s.t15_us, s.t35_us), (860, 2_006));
        // 8N1 at 9 600: 10 bits = 1 042 µs; 3.5 → 3 646 µs.
        assert_eq!(Silences::at(9_600, Parity::None8N1).t35_us, 3_646);
        // Above 19 200 Bd: fixed.
        let s = Silences::at(115_200, Parity::Even8E1);
        assert_eq!((s.t15_us, s.t35_us), (750, 1_750));
    }

    fn feed(f: &mut SilenceFramer, bytes: &[u8], t0: u64, step_us: u64) -> u64 {
        let mut t = t0;
        for &b in bytes {
            assert_eq!(f.push(b, t), None);
            t += step_us;
        }
        t - step_us
    }

    #[test]
    fn a_frame_ends_at_three_and_a_half_characters_of_silence() {
        let s = Silences::at(19_200, Parity::Even8E1);
        let mut f = SilenceFramer::new(s);
        let last = feed(&mut f, &[1, 3, 0, 0, 0, 1, 0x84, 0x0A], 1_000, 573);
        assert_eq!(f.deadline_us(), Some(last + 2_006));
        assert_eq!(f.poll(last + 2_005), None);
        let frame = f.poll(last + 2_006).unwrap();
        assert_eq!(&frame[..], &[1, 3, 0, 0, 0, 1, 0x84, 0x0A]);
        assert_eq!(f.poll(last + 10_000), None, "given once");
    }

    #[test]
    fn a_gap_of_more_than_one_and_a_half_characters_drops_the_frame() {
        let mut f = SilenceFramer::new(Silences::at(19_200, Parity::Even8E1));
        let t = feed(&mut f, &[1, 3, 0], 0, 573);
        // 861 µs after the last byte: broken, but not yet the frame's end.
        let t = feed(&mut f, &[0, 0, 1], t + 861, 573);
        assert_eq!(f.poll(t + 2_006), None);
        assert_eq!(f.dropped(), 1);
        // The next frame after the silence is whole again.
        feed(&mut f, &[7], t + 5_000, 573);
        assert_eq!(f.poll(t + 8_000).as_deref(), Some(&[7u8][..]));
    }

    #[test]
    fn two_frames_back_to_back_are_one_and_too_long_is_dropped() {
        let mut f = SilenceFramer::new(Silences::at(115_200, Parity::Even8E1));
        let t = feed(&mut f, &[1; 16], 0, 96);
        assert_eq!(f.poll(t + 1_750).map(|a| a.len()), Some(16));
        let t = feed(&mut f, &[2; 300], t + 5_000, 96);
        assert_eq!(f.poll(t + 1_750), None);
        assert_eq!(f.dropped(), 1);
    }

    #[test]
    fn a_byte_after_the_silence_hands_over_the_frame_before_it() {
        let mut f = SilenceFramer::new(Silences::at(115_200, Parity::Even8E1));
        feed(&mut f, &[1, 2], 0, 96);
        assert_eq!(f.push(9, 96 + 1_750).as_deref(), Some(&[1u8, 2][..]));
        assert_eq!(f.poll(96 + 3_500).as_deref(), Some(&[9u8][..]));
    }
}
