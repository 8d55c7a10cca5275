//! Virtual time (ns) shared by the delay, the ADC and the runner, and output
//! pins whose level anyone holding a clone can read.

use std::convert::Infallible;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// A virtual clock in nanoseconds. Clones share the same time.
#[derive(Debug, Clone, Default)]
pub struct VirtualClock(Arc<AtomicU64>);

impl VirtualClock {
    /// A clock at t = 0.
    pub fn new() -> Self {
        Self::default()
    }

    /// Now, ns.
    pub fn now_ns(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }

    /// Now, ms (truncated).
    pub fn now_ms(&self) -> u64 {
        self.now_ns() / 1_000_000
    }

    /// Now, s.
    pub fn now_s(&self) -> f64 {
        self.now_ns() as f64 * 1e-9
    }

    /// Move time forward by `ns`.
    pub fn advance_ns(&self, ns: u64) {
        self.0.fetch_add(ns, Ordering::Relaxed);
    }

    /// Move time forward to `t_ns` (never backwards).
    pub fn advance_to_ns(&self, t_ns: u64) {
        self.0.fetch_max(t_ns, Ordering::Relaxed);
    }
}

/// `embedded_hal::delay::DelayNs` that advances the virtual clock instead
/// of waiting.
#[derive(Debug, Clone)]
pub struct VirtualDelay {
    clock: VirtualClock,
}

impl VirtualDelay {
    /// A delay on `clock`.
    pub fn new(clock: VirtualClock) -> Self {
        VirtualDelay { clock }
    }
}

impl embedded_hal::delay::DelayNs for VirtualDelay {
    fn delay_ns(&mut self, ns: u32) {
        self.clock.advance_ns(u64::from(ns));
    }
}

/// Most edges a pin remembers (oldest dropped first).
pub const PIN_EDGE_HISTORY: usize = 4096;

#[derive(Debug, Default)]
struct PinShared {
    high: AtomicBool,
    rising: AtomicU64,
    edges: Mutex<std::collections::VecDeque<(u64, bool)>>,
}

/// An output pin (`embedded_hal::digital::OutputPin`). Clones share the
/// level, so the ADC can see the LED and a test can see the alarm output.
/// With a clock, level changes are recorded with their virtual time.
#[derive(Debug, Clone, Default)]
pub struct VirtualPin {
    shared: Arc<PinShared>,
    clock: Option<VirtualClock>,
}

impl VirtualPin {
    /// A pin, low, that does not record edges.
    pub fn new() -> Self {
        Self::default()
    }

    /// A pin, low, recording its edges at the times of `clock`.
    pub fn with_clock(clock: VirtualClock) -> Self {
        VirtualPin {
            shared: Arc::default(),
            clock: Some(clock),
        }
    }

    /// Current level.
    pub fn is_high(&self) -> bool {
        self.shared.high.load(Ordering::Relaxed)
    }

    /// Low → high transitions so far.
    pub fn rising_edges(&self) -> u64 {
        self.shared.rising.load(Ordering::Relaxed)
    }

    /// Recorded level changes: (virtual time ns, new level), oldest first.
    pub fn edges(&self) -> Vec<(u64, bool)> {
        self.shared
            .edges
            .lock()
            .map(|e| e.iter().copied().collect())
            .unwrap_or_default()
    }

    fn set(&self, high: bool) {
        let was = self.shared.high.swap(high, Ordering::Relaxed);
        if was == high {
            return;
        }
        if high {
            self.shared.rising.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(c) = &self.clock
            && let Ok(mut e) = self.shared.edges.lock()
        {
            if e.len() >= PIN_EDGE_HISTORY {
                e.pop_front();
            }
            e.push_back((c.now_ns(), high));
        }
    }
}

impl embedded_hal::digital::ErrorType for VirtualPin {
    type Error = Infallible;
}

impl embedded_hal::digital::OutputPin for VirtualPin {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.set(false);
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        self.set(true);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::delay::DelayNs;
    use embedded_hal::digital::OutputPin;

    #[test]
    fn delay_advances_the_shared_clock_and_pins_record_edges() {
        let clock = VirtualClock::new();
        let mut d = VirtualDelay::new(clock.clone());
        d.delay_us(200);
        d.delay_ms(3);
        assert_eq!(clock.now_ns(), 3_200_000);
        clock.advance_to_ns(1_000);
        assert_eq!(clock.now_ns(), 3_200_000, "never backwards");
        let mut pin = VirtualPin::with_clock(clock.clone());
        let view = pin.clone();
        pin.set_high().unwrap();
        d.delay_ns(5);
        pin.set_high().unwrap();
        pin.set_low().unwrap();
        assert!(!view.is_high());
        assert_eq!(view.rising_edges(), 1);
        assert_eq!(view.edges(), vec![(3_200_000, true), (3_200_005, false)]);
    }
}
