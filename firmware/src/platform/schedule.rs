//! When the node sends `Hello` and runs its frames: one pure type, driven
//! by the board binary with embassy's clock and by the virtual node with
//! virtual time (integer milliseconds, no embassy types).
//!
//! - `Hello` on the first poll (boot) and every [`HELLO_EVERY_MS`] while the
//!   node is not streaming.
//! - The first frame on the first poll too; then frames on a fixed grid of
//!   the frame period (a frame that starts late does not shift the ones
//!   after it).
//! - A new frame period applies at once: the grid restarts at the last
//!   frame, so the next frame comes one new period after it (at once if
//!   that is already past).
//! - Overrun (a frame or a flash erase that kept the node busy past one or
//!   more grid slots): the missed slots are dropped, not caught up in a
//!   burst, and the grid restarts one period after the late frame; each
//!   dropped slot is counted.

/// `Hello` cadence while not streaming, ms.
pub const HELLO_EVERY_MS: u64 = 1_000;

/// What to do now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Due {
    /// Send `Hello`.
    pub hello: bool,
    /// Run a frame.
    pub frame: bool,
}

/// The frame grid and the `Hello` cadence.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Schedule {
    /// When the next frame is due; `None` before the first poll.
    next_frame_ms: Option<u64>,
    /// When the last frame was due (the grid's origin after a period change).
    last_frame_ms: Option<u64>,
    next_hello_ms: Option<u64>,
    period_ms: u32,
    skipped: u32,
}

impl Default for Schedule {
    fn default() -> Self {
        Self::new()
    }
}

impl Schedule {
    /// Nothing sent yet: the first poll sends `Hello` and runs a frame.
    pub const fn new() -> Self {
        Schedule {
            next_frame_ms: None,
            last_frame_ms: None,
            next_hello_ms: None,
            period_ms: 0,
            skipped: 0,
        }
    }

    /// What is due at `now_ms`, for a node that is `streaming` with frame
    /// period `period_ms` (the node's `frame_period_ms()`, at least 1 ms).
    /// Call it, do what it says, then sleep until [`Self::next_wake_ms`].
    pub fn poll(&mut self, now_ms: u64, streaming: bool, period_ms: u32) -> Due {
        let period = period_ms.max(1);
        let mut due = Due::default();

        // Hello: at boot, then every second until streaming starts.
        match self.next_hello_ms {
            None => {
                due.hello = true;
                self.next_hello_ms = Some(now_ms.saturating_add(HELLO_EVERY_MS));
            }
            Some(t) if !streaming && now_ms >= t => {
                due.hello = true;
                self.next_hello_ms = Some(now_ms.saturating_add(HELLO_EVERY_MS));
            }
            // While streaming the cadence restarts: after a StopStream the
            // next Hello comes at once.
            Some(_) if streaming => self.next_hello_ms = Some(now_ms),
            Some(_) => {}
        }

        // A new period: restart the grid at the last frame.
        if period != self.period_ms {
            if let Some(last) = self.last_frame_ms {
                self.next_frame_ms = Some(last.saturating_add(u64::from(period)).max(now_ms));
            }
            self.period_ms = period;
        }

        let next = self.next_frame_ms.unwrap_or(now_ms);
        if now_ms >= next {
            due.frame = true;
            self.last_frame_ms = Some(next);
            let step = u64::from(period);
            let mut following = next.saturating_add(step);
            if following <= now_ms {
                // Overrun: drop the missed slots, restart the grid from now.
                let missed = (now_ms - next) / step;
                self.skipped = self.skipped.saturating_add(missed as u32);
                following = now_ms.saturating_add(step);
                self.last_frame_ms = Some(now_ms);
            }
            self.next_frame_ms = Some(following);
        }
        due
    }

    /// When something is next due (the next frame, or the next `Hello` while
    /// not streaming), ms.
    pub fn next_wake_ms(&self, streaming: bool) -> u64 {
        let frame = self.next_frame_ms.unwrap_or(0);
        match self.next_hello_ms {
            Some(h) if !streaming => frame.min(h),
            _ => frame,
        }
    }

    /// The measure loop has proved progress: right after [`Self::poll`] at
    /// `now_ms`, the last frame ran at most one period ago and the next is
    /// due at most one period ahead (`period_ms` as passed to `poll`).
    /// False before the first poll and whenever the clock went backwards or
    /// jumped (a wrapped timer: the next frame would lie years away, and
    /// the loop would feed the watchdog for ever without a frame). The
    /// board feeds the watchdog only while this holds.
    pub fn on_track(&self, now_ms: u64, period_ms: u32) -> bool {
        let period = u64::from(period_ms.max(1));
        match (self.last_frame_ms, self.next_frame_ms) {
            (Some(last), Some(next)) => {
                now_ms.checked_sub(last).is_some_and(|ago| ago <= period)
                    && next
                        .checked_sub(now_ms)
                        .is_some_and(|ahead| ahead <= period)
            }
            _ => false,
        }
    }

    /// Grid slots dropped because the node was busy past them.
    pub fn skipped_frames(&self) -> u32 {
        self.skipped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Drive the schedule from `from` to `to` ms in 1 ms steps; returns the
    /// times of frames and of Hellos.
    fn run(
        s: &mut Schedule,
        from: u64,
        to: u64,
        streaming: impl Fn(u64) -> bool,
        period: impl Fn(u64) -> u32,
    ) -> (Vec<u64>, Vec<u64>) {
        let (mut frames, mut hellos) = (Vec::new(), Vec::new());
        for t in from..to {
            let d = s.poll(t, streaming(t), period(t));
            if d.frame {
                frames.push(t);
            }
            if d.hello {
                hellos.push(t);
            }
        }
        (frames, hellos)
    }

    #[test]
    fn hello_at_boot_and_every_second_until_streaming() {
        let mut s = Schedule::new();
        // Not streaming for 3.5 s, then streaming.
        let (frames, hellos) = run(&mut s, 0, 5_000, |t| t >= 3_500, |_| 100);
        assert_eq!(hellos, vec![0, 1_000, 2_000, 3_000]);
        assert_eq!(frames.len(), 50);
        assert_eq!(frames[..3], [0, 100, 200]);
        // Streaming from boot: one Hello only.
        let mut s = Schedule::new();
        let (_, hellos) = run(&mut s, 0, 5_000, |_| true, |_| 100);
        assert_eq!(hellos, vec![0]);
        // Stops streaming at 2.05 s: Hello at once, then every second.
        let (_, hellos) = run(&mut s, 5_000, 7_500, |t| t < 6_050, |_| 100);
        assert_eq!(hellos, vec![6_050, 7_050]);
    }

    #[test]
    fn first_frame_at_boot_then_a_fixed_grid() {
        let mut s = Schedule::new();
        assert_eq!(
            s.poll(7, true, 250),
            Due {
                hello: true,
                frame: true
            }
        );
        assert_eq!(s.next_wake_ms(true), 257);
        // Polled late (a command held the node for 30 ms): the grid holds.
        assert!(!s.poll(256, true, 250).frame);
        assert!(s.poll(287, true, 250).frame);
        assert_eq!(s.next_wake_ms(true), 507);
        assert_eq!(s.skipped_frames(), 0);
    }

    #[test]
    fn a_new_period_applies_at_once() {
        let mut s = Schedule::new();
        let (frames, _) = run(&mut s, 0, 1_000, |_| true, |_| 1_000);
        assert_eq!(frames, vec![0]);
        // At 1 000 ms... the 1 s frame runs; at 1 300 the host asks for 100 ms:
        // the next frame is due at once (1 000 + 100 is past).
        let (frames, _) = run(
            &mut s,
            1_000,
            1_650,
            |_| true,
            |t| if t < 1_300 { 1_000 } else { 100 },
        );
        assert_eq!(frames, vec![1_000, 1_300, 1_400, 1_500, 1_600]);
        // Longer again (500 ms) at 1 650: one new period after the last frame.
        let (frames, _) = run(&mut s, 1_650, 3_000, |_| true, |_| 500);
        assert_eq!(frames, vec![2_100, 2_600]);
    }

    #[test]
    fn overrun_drops_missed_slots_and_restarts_the_grid() {
        let mut s = Schedule::new();
        assert!(s.poll(0, true, 100).frame);
        // A flash erase keeps the node busy until 2 345 ms.
        assert!(s.poll(2_345, true, 100).frame);
        assert_eq!(
            s.skipped_frames(),
            22,
            "slots 100..=2 300 minus the one run"
        );
        assert_eq!(s.next_wake_ms(true), 2_445);
        assert!(!s.poll(2_444, true, 100).frame);
        assert!(s.poll(2_445, true, 100).frame);
        // Less than a period late: the grid holds, nothing dropped.
        assert!(s.poll(2_590, true, 100).frame);
        assert_eq!(s.next_wake_ms(true), 2_645);
        assert_eq!(s.skipped_frames(), 22);
    }

    #[test]
    fn progress_holds_on_a_running_grid_and_fails_when_time_jumps() {
        let mut s = Schedule::new();
        assert!(!s.on_track(0, 100), "nothing ran yet");
        for t in 0..1_000 {
            s.poll(t, true, 100);
            assert!(s.on_track(t, 100), "{t}");
        }
        // Overrun by an erase: still on track after the late frame.
        s.poll(3_000, true, 100);
        assert!(s.on_track(3_000, 100));
        // A new, shorter period: on track with it after the poll.
        s.poll(3_010, true, 10);
        assert!(s.on_track(3_010, 10));
        // The clock went backwards: not on track, whatever the poll says.
        s.poll(5, true, 10);
        assert!(!s.on_track(5, 10));
        // Or jumped far ahead without a poll.
        let mut s = Schedule::new();
        s.poll(0, true, 100);
        assert!(!s.on_track(10_000, 100));
    }

    #[test]
    fn wakes_for_hello_only_while_not_streaming() {
        let mut s = Schedule::new();
        s.poll(0, false, 10_000);
        assert_eq!(s.next_wake_ms(false), 1_000);
        assert_eq!(s.next_wake_ms(true), 10_000);
    }
}
