//! The simulated ADC: at the clock's time it asks the environment for the
//! true photocurrents, adds the LED's share when the LED pin is high, and
//! converts through the front end.

use std::sync::Arc;

use fois_firmware::PhotoAdc;

use super::clock::{VirtualClock, VirtualPin};
use super::environment::{Environment, Truth};
use super::frontend::FrontEnd;

/// `fois_firmware::PhotoAdc` on virtual hardware.
#[derive(Debug, Clone)]
pub struct SimAdc {
    /// Shared virtual time.
    pub clock: VirtualClock,
    /// The LED pin (a clone of the one the node drives).
    pub led: VirtualPin,
    /// What the face sees.
    pub env: Arc<Environment>,
    /// Resistors, reference, noise.
    pub frontend: FrontEnd,
    /// Virtual time one conversion of both channels takes, ns.
    pub conversion_ns: u64,
    /// Conversions so far (both channels count as one).
    pub conversions: u64,
}

impl SimAdc {
    /// An ADC on `clock` that sees `led`, in `env`, noise from `seed`.
    pub fn new(clock: VirtualClock, led: VirtualPin, env: Arc<Environment>, seed: u64) -> Self {
        SimAdc {
            clock,
            led,
            env,
            frontend: FrontEnd::new(seed),
            conversion_ns: 1_000,
            conversions: 0,
        }
    }

    /// The conditions now.
    pub fn truth(&self) -> Truth {
        self.env.truth(self.clock.now_ns())
    }

    /// The photocurrents the phototransistors carry now, µA.
    pub fn photocurrents_ua(&self) -> [f64; 2] {
        let t = self.truth();
        let led = if self.led.is_high() {
            t.led_signal_ua
        } else {
            [0.0; 2]
        };
        [t.ambient_ua[0] + led[0], t.ambient_ua[1] + led[1]]
    }
}

impl PhotoAdc for SimAdc {
    fn read_photo(&mut self) -> [u16; 2] {
        let noise = self.truth().adc_noise_lsb;
        let i = self.photocurrents_ua();
        self.conversions += 1;
        let codes = self.frontend.photo_codes(i, noise);
        self.clock.advance_ns(self.conversion_ns);
        codes
    }

    fn read_ntc(&mut self) -> u16 {
        let t = self.truth().air_temp_c;
        self.frontend.ntc_code(t)
    }

    fn read_vrefint(&mut self) -> u16 {
        self.frontend.vrefint_code()
    }

    fn read_internal_temp(&mut self) -> u16 {
        let t = self.truth().air_temp_c;
        self.frontend.internal_temp_code(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::environment::{Cover, Segment, Timeline};
    use embedded_hal::digital::OutputPin;

    #[test]
    fn led_adds_the_curve_current_to_the_ambient() {
        let tl = Timeline::constant(
            Segment::new(10.0, Cover::Dry)
                .ambient([10.0, 5.0])
                .noise(0.0),
        );
        let env = Arc::new(Environment::with_curves(tl, [], [20.0, 0.0]));
        let clock = VirtualClock::new();
        let mut led = VirtualPin::new();
        let mut adc = SimAdc::new(clock.clone(), led.clone(), env, 3);
        adc.frontend.load_ohm = [22_000.0; 2];
        // 10 µA × 22 kΩ = 0.22 V → 273; 5 µA → 137 (rounded 136.5).
        assert_eq!(adc.read_photo(), [273, 137]);
        led.set_high().unwrap();
        // 30 µA → 819.
        assert_eq!(adc.read_photo(), [819, 137]);
        assert_eq!(clock.now_ns(), 2_000);
        assert_eq!(adc.conversions, 2);
    }
}
