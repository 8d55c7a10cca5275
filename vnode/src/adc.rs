//! The simulated ADC: at the clock's time it asks the environment for the
//! true photocurrents, adds the LED's share when the LED pin is high, and
//! converts through the front end.

use std::sync::Arc;

use fois_firmware::PhotoAdc;

use super::clock::{VirtualClock, VirtualPin};
use super::environment::{Environment, NtcWiring, Truth};
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
        let t = self.truth();
        match t.ntc {
            NtcWiring::Connected => self.frontend.ntc_code(t.air_temp_c),
            NtcWiring::Open => fois_firmware::hal::ADC_MAX,
            NtcWiring::Short => 0,
        }
    }

    fn read_vrefint(&mut self) -> u16 {
        self.frontend.vrefint_code()
    }

    fn read_internal_temp(&mut self) -> u16 {
        // The die sits with the optoelectronics: it reads their temperature
        // (air + the enclosure's self-heating), the one that sets the gain.
        let t = self.truth().optics_temp_c;
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

    #[test]
    fn the_ntc_wiring_of_the_segment_sets_its_code() {
        let tl = Timeline::new(vec![
            Segment::new(1.0, Cover::Dry).temp(0.0),
            Segment::new(1.0, Cover::Dry).temp(0.0).ntc(NtcWiring::Open),
            Segment::new(1.0, Cover::Dry)
                .temp(0.0)
                .ntc(NtcWiring::Short),
        ]);
        let env = Arc::new(Environment::with_curves(tl, [], [0.0, 0.0]));
        let clock = VirtualClock::new();
        let mut adc = SimAdc::new(clock.clone(), VirtualPin::new(), env, 3);
        // 0 °C: 33.6 kΩ against 10 kΩ → 3156.
        assert_eq!(adc.read_ntc(), 3156);
        clock.advance_to_ns(1_500_000_000);
        assert_eq!(adc.read_ntc(), 4095);
        clock.advance_to_ns(2_500_000_000);
        assert_eq!(adc.read_ntc(), 0);
    }

    #[test]
    fn the_internal_sensor_reads_the_optics_temperature() {
        // Air at −10 °C, the enclosure 4 K warmer: the die reads −6 °C.
        let tl = Timeline::constant(
            Segment::new(1.0, Cover::Dry)
                .temp(-10.0)
                .optics_above_air(4.0),
        );
        let env = Arc::new(Environment::with_curves(tl, [], [0.0, 0.0]));
        let mut adc = SimAdc::new(VirtualClock::new(), VirtualPin::new(), env, 3);
        let code = adc.read_internal_temp();
        assert_eq!(code, adc.frontend.internal_temp_code(-6.0));
        assert_ne!(code, adc.frontend.internal_temp_code(-10.0));
        // The firmware's conversion reads it back within a step of the
        // 12-bit code (~0.4 K).
        let centi = fois_firmware::measure::vref::internal_temp_centi_c(
            &fois_firmware::FactoryCal::TYPICAL,
            code,
            3_300,
        );
        assert!((i32::from(centi) + 600).abs() <= 40, "{centi}");
    }
}
