//! A scripted simulated board (feature `sim-board`, `no_std`): the fakes
//! that put the [`Node`] on a desk instead of a NUCLEO board. The firmware's
//! host tests and the QEMU harness (`firmware/qemu-test`) run the node on
//! it; the virtual node (crate `fois-vnode`) converts its physics into ADC
//! codes with the same [`codes`].
//!
//! The board is a set of cells: a clock in ns (advanced by the settle delays
//! and by every photo conversion, as on the real board), the levels of the
//! LED (PB0), the alarm output (PA9) and the indicator (LD2), and a
//! [`Scene`] a test changes between frames (photocurrents, ambient light
//! with flicker, air temperature, V_DDA, load resistors). The fakes hold
//! anything that dereferences to the board (`&SimBoard`, `Rc<SimBoard>`),
//! so one board is shared by the ADC, the pins and the delay.
//!
//! ```
//! use fois_firmware::MemStorage;
//! use fois_firmware::sim_board::{SimBoard, sim_node};
//!
//! let board = SimBoard::new();
//! let mut node = sim_node(&board, MemStorage::new(), "desk");
//! board.set(|s| s.signal_na = [12_000.0, 4_000.0]); // the LED's light on each channel
//! let mut sent = 0;
//! board.run_frame(&mut node, &mut |frame: &[u8]| sent += frame.len());
//! let m = node.last_measurement().expect("a frame ran");
//! assert!((m.i1_na - 12_000).abs() <= 81, "within one ADC step: {}", m.i1_na);
//! assert!(sent > 0 && !board.led.get(), "a frame went out; the LED is off");
//! ```

use core::cell::{Cell, RefCell};
use core::convert::Infallible;
use core::ops::Deref;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{ErrorType, OutputPin};

use rand_core::Rng;
use rand_pcg::Pcg32;

use crate::hal::{BoardInfo, FactoryCal, PhotoAdc};
use crate::node::Node;
use crate::storage::Storage;
use crate::update::{NoUpdates, UpdateSlots};

/// The noise stream's PCG state and stream constants (any fixed values).
const NOISE_STATE: u64 = 0xcafe_f00d_d15e_a5e5;
const NOISE_STREAM: u64 = 0x0a02_bdbf_7bb3_c0a7;

/// Physical quantities → 12-bit ADC codes: the inverse of what the firmware
/// computes from the codes (`measure::photocurrent`, `measure::ntc`, `measure::vref`).
pub mod codes {
    use crate::hal::{ADC_MAX, FactoryCal};
    use crate::measure::ntc::{BETA_K, R_FIXED_OHM, R25_OHM};

    /// 0 °C in kelvin.
    pub const KELVIN_OFFSET: f64 = 273.15;
    /// The NTC's reference temperature (25 °C), K.
    pub const T25_K: f64 = 298.15;
    /// V_DDA at which the factory values were taken, V.
    pub const CAL_VDDA_V: f64 = 3.3;
    /// The factory values' reference temperatures, °C (TS_CAL1, TS_CAL2).
    pub const TS_CAL_C: [f64; 2] = [30.0, 110.0];

    /// A voltage in ADC steps (unrounded) at reference `vdda_v`.
    pub fn lsb(volts: f64, vdda_v: f64) -> f64 {
        volts / vdda_v * f64::from(ADC_MAX)
    }

    /// Round to a code, saturating at 0 and 4095 (NaN reads 0).
    pub fn code(lsb: f64) -> u16 {
        if lsb.is_nan() {
            return 0;
        }
        libm::round(lsb).clamp(0.0, f64::from(ADC_MAX)) as u16
    }

    /// A typical V_CE(sat) of a small NPN phototransistor, V (0.2–0.4 V at
    /// its rated current; the firmware flags saturation against the worst,
    /// `measure::photocurrent::PHOTO_VCE_SAT_MV`).
    pub const VCE_SAT_TYPICAL_V: f64 = 0.25;

    /// The emitter voltage of a phototransistor channel: `current_na`
    /// (negative reads as 0) through `load_ohm`, clipped where the
    /// transistor saturates: its collector is on the 3V3 rail (= V_DDA on
    /// the NUCLEO), so the emitter never rises above `vdda_v − vce_sat_v`.
    pub fn photo_volts(current_na: f64, load_ohm: f64, vdda_v: f64, vce_sat_v: f64) -> f64 {
        let clip_v = (vdda_v - vce_sat_v).max(0.0);
        (current_na.max(0.0) * 1e-9 * load_ohm).min(clip_v)
    }

    /// The code of a phototransistor channel: [`photo_volts`] at reference
    /// `vdda_v`.
    pub fn photo_code(current_na: f64, load_ohm: f64, vdda_v: f64, vce_sat_v: f64) -> u16 {
        code(lsb(
            photo_volts(current_na, load_ohm, vdda_v, vce_sat_v),
            vdda_v,
        ))
    }

    /// NTC resistance at `temp_c`, Ω (beta equation; the firmware inverts it).
    pub fn ntc_ohm(temp_c: f64) -> f64 {
        let t_k = temp_c + KELVIN_OFFSET;
        f64::from(R25_OHM) * libm::exp(f64::from(BETA_K) * (1.0 / t_k - 1.0 / T25_K))
    }

    /// The NTC divider's code at `temp_c` (NTC to GND, the fixed resistor to
    /// 3V3; ratiometric, so independent of V_DDA).
    pub fn ntc_code(temp_c: f64) -> u16 {
        let r = ntc_ohm(temp_c);
        code(f64::from(ADC_MAX) * r / (r + f64::from(R_FIXED_OHM)))
    }

    /// VREFINT's code at supply `vdda_v`: VREFINT_CAL · 3.3 V / V_DDA.
    pub fn vrefint_code(cal: &FactoryCal, vdda_v: f64) -> u16 {
        code(f64::from(cal.vrefint_cal) * CAL_VDDA_V / vdda_v)
    }

    /// The internal temperature sensor's code at die temperature `temp_c`
    /// and supply `vdda_v` (linear between TS_CAL1 and TS_CAL2, taken at 3.3 V).
    pub fn internal_temp_code(cal: &FactoryCal, temp_c: f64, vdda_v: f64) -> u16 {
        let (c1, c2) = (f64::from(cal.ts_cal1), f64::from(cal.ts_cal2));
        let [t1, t2] = TS_CAL_C;
        let at_cal = c1 + (temp_c - t1) * (c2 - c1) / (t2 - t1);
        code(at_cal * CAL_VDDA_V / vdda_v)
    }
}

/// What the simulated optics and air do; change it between frames.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Photocurrent the LED causes on each channel, nA.
    pub signal_na: [f64; 2],
    /// Change of the LED photocurrent per second, nA/s (a film coming and going).
    pub signal_ramp_na_per_s: [f64; 2],
    /// Ambient DC photocurrent, nA.
    pub ambient_na: [f64; 2],
    /// Ambient flicker amplitude, nA (sinusoid).
    pub flicker_na: [f64; 2],
    /// Flicker frequency, Hz (mains: 100 Hz).
    pub flicker_hz: f64,
    /// Flicker phase, rad.
    pub flicker_phase: f64,
    /// Air temperature, °C (NTC and internal sensor).
    pub temp_c: f64,
    /// Override of the NTC code (open: ≥ 4085, short: ≤ 10).
    pub ntc_code: Option<u16>,
    /// Supply, mV.
    pub vdda_mv: f64,
    /// Load resistors, Ω.
    pub load_ohm: [f64; 2],
    /// Time one photo conversion (both channels) takes, ns.
    pub conversion_ns: u64,
    /// V_CE(sat) of the phototransistors, mV: the emitter (the ADC input)
    /// clips at `vdda_mv` minus this in strong light.
    pub vce_sat_mv: f64,
    /// ADC noise, rms LSB per photo conversion (Gaussian, from the board's
    /// seeded stream: [`SimBoard::seed_noise`]).
    pub noise_lsb: f64,
    /// A change at a board time, ns: from then on the LED's photocurrent
    /// and the ambient light are higher by these, nA (a drop landing, a
    /// cloud edge). `None`: no change.
    pub step_at_ns: Option<u64>,
    /// The LED photocurrent's change at `step_at_ns`, nA.
    pub signal_step_na: [f64; 2],
    /// The ambient light's change at `step_at_ns`, nA.
    pub ambient_step_na: [f64; 2],
}

impl Scene {
    /// Dark and still: no light, 10 °C, 3.3 V, 10 kΩ loads, 15 µs
    /// conversions, phototransistors clipping 0.25 V below V_DDA.
    pub const DEFAULT: Scene = Scene {
        signal_na: [0.0; 2],
        signal_ramp_na_per_s: [0.0; 2],
        ambient_na: [0.0; 2],
        flicker_na: [0.0; 2],
        flicker_hz: 100.0,
        flicker_phase: 0.0,
        temp_c: 10.0,
        ntc_code: None,
        vdda_mv: 3300.0,
        load_ohm: [10_000.0; 2],
        conversion_ns: 15_000,
        vce_sat_mv: codes::VCE_SAT_TYPICAL_V * 1000.0,
        noise_lsb: 0.0,
        step_at_ns: None,
        signal_step_na: [0.0; 2],
        ambient_step_na: [0.0; 2],
    };
}

impl Default for Scene {
    fn default() -> Self {
        Scene::DEFAULT
    }
}

/// The board: its clock, output levels and scene.
#[derive(Debug)]
pub struct SimBoard {
    /// Board time, ns.
    pub t_ns: Cell<u64>,
    /// LED (PB0) level.
    pub led: Cell<bool>,
    /// Alarm output (PA9) level.
    pub alarm: Cell<bool>,
    /// Indicator (LD2) level.
    pub indicator: Cell<bool>,
    /// Times the LED was switched on.
    pub led_toggles: Cell<u32>,
    /// The optics and the air.
    pub scene: RefCell<Scene>,
    /// The ADC noise stream.
    noise: RefCell<Pcg32>,
}

impl Default for SimBoard {
    fn default() -> Self {
        Self::new()
    }
}

impl SimBoard {
    /// A board at t = 0 in [`Scene::DEFAULT`].
    pub fn new() -> Self {
        SimBoard {
            t_ns: Cell::new(0),
            led: Cell::new(false),
            alarm: Cell::new(false),
            indicator: Cell::new(false),
            led_toggles: Cell::new(0),
            scene: RefCell::new(Scene::DEFAULT),
            noise: RefCell::new(Pcg32::new(NOISE_STATE, NOISE_STREAM)),
        }
    }

    /// Restart the ADC noise stream from `seed` (the same seed gives the
    /// same draws).
    pub fn seed_noise(&self, seed: u64) {
        *self.noise.borrow_mut() = Pcg32::new(NOISE_STATE ^ seed, NOISE_STREAM);
    }

    /// One standard normal draw (Box–Muller).
    fn gaussian(&self) -> f64 {
        let mut rng = self.noise.borrow_mut();
        let u1 = ((rng.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
        let u2 = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        libm::sqrt(-2.0 * libm::log(u1)) * libm::cos(2.0 * core::f64::consts::PI * u2)
    }

    /// Board time, ms.
    pub fn now_ms(&self) -> u64 {
        self.t_ns.get() / 1_000_000
    }

    /// Move the clock forward.
    pub fn advance_ms(&self, ms: u64) {
        self.t_ns.set(self.t_ns.get() + ms * 1_000_000);
    }

    /// Change the scene.
    pub fn set(&self, f: impl FnOnce(&mut Scene)) {
        f(&mut self.scene.borrow_mut());
    }

    /// Run one frame of `node` now, then move the clock to the end of its
    /// frame period (or of the frame, if that took longer): as the board's
    /// ticker runs the node.
    pub fn run_frame<B, S, U>(&self, node: &mut SimNode<B, S, U>, tx: &mut impl FnMut(&[u8]))
    where
        B: Deref<Target = SimBoard>,
        S: Storage,
        U: UpdateSlots,
    {
        let start = self.t_ns.get();
        node.run_frame(self.now_ms(), tx);
        let period_ns = u64::from(node.frame_period_ms()) * 1_000_000;
        let took = self.t_ns.get() - start;
        self.t_ns.set(start + period_ns.max(took));
    }
}

/// The ADC: ambient + flicker (+ the LED's signal while the LED is on),
/// through the load resistors, clipped at V_DDA − V_CE(sat),
/// at the board's time. Each photo conversion
/// advances the clock by [`Scene::conversion_ns`].
#[derive(Debug, Clone)]
pub struct BoardAdc<B>(pub B);

impl<B: Deref<Target = SimBoard>> PhotoAdc for BoardAdc<B> {
    fn read_photo(&mut self) -> [u16; 2] {
        let board = &*self.0;
        let s = board.scene.borrow();
        let t_s = board.t_ns.get() as f64 * 1e-9;
        let phase = 2.0 * core::f64::consts::PI * s.flicker_hz * t_s + s.flicker_phase;
        let wave = libm::sin(phase);
        let led_on = board.led.get();
        let stepped = s.step_at_ns.is_some_and(|t| board.t_ns.get() >= t);
        let codes = [0, 1].map(|ch| {
            let flicker = s.flicker_na[ch] * wave;
            let (signal_step, ambient_step) = if stepped {
                (s.signal_step_na[ch], s.ambient_step_na[ch])
            } else {
                (0.0, 0.0)
            };
            let led = if led_on {
                s.signal_na[ch] + signal_step + s.signal_ramp_na_per_s[ch] * t_s
            } else {
                0.0
            };
            let i_na = s.ambient_na[ch] + ambient_step + flicker + led;
            let vdda_v = s.vdda_mv / 1000.0;
            let volts = codes::photo_volts(i_na, s.load_ohm[ch], vdda_v, s.vce_sat_mv / 1000.0);
            let noise = if s.noise_lsb > 0.0 {
                s.noise_lsb * board.gaussian()
            } else {
                0.0
            };
            codes::code(codes::lsb(volts, vdda_v) + noise)
        });
        board.t_ns.set(board.t_ns.get() + s.conversion_ns);
        codes
    }

    fn read_ntc(&mut self) -> u16 {
        let s = self.0.scene.borrow();
        s.ntc_code.unwrap_or_else(|| codes::ntc_code(s.temp_c))
    }

    fn read_vrefint(&mut self) -> u16 {
        let s = self.0.scene.borrow();
        codes::vrefint_code(&FactoryCal::TYPICAL, s.vdda_mv / 1000.0)
    }

    fn read_internal_temp(&mut self) -> u16 {
        let s = self.0.scene.borrow();
        codes::internal_temp_code(&FactoryCal::TYPICAL, s.temp_c, s.vdda_mv / 1000.0)
    }
}

/// Which output a [`BoardPin`] drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Line {
    /// LED (PB0); switching it on counts in [`SimBoard::led_toggles`].
    Led,
    /// Alarm output (PA9).
    Alarm,
    /// Indicator (LD2, PA5).
    Indicator,
}

/// An output pin of the board.
#[derive(Debug, Clone)]
pub struct BoardPin<B> {
    board: B,
    line: Line,
}

impl<B: Deref<Target = SimBoard>> BoardPin<B> {
    /// The pin of `line` on `board`.
    pub fn new(board: B, line: Line) -> Self {
        BoardPin { board, line }
    }

    fn cell(&self) -> &Cell<bool> {
        match self.line {
            Line::Led => &self.board.led,
            Line::Alarm => &self.board.alarm,
            Line::Indicator => &self.board.indicator,
        }
    }
}

impl<B> ErrorType for BoardPin<B> {
    type Error = Infallible;
}

impl<B: Deref<Target = SimBoard>> OutputPin for BoardPin<B> {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.cell().set(false);
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Infallible> {
        if self.line == Line::Led {
            let t = &self.board.led_toggles;
            t.set(t.get().wrapping_add(1));
        }
        self.cell().set(true);
        Ok(())
    }
}

/// The settle delay: advances the board's clock instead of waiting.
#[derive(Debug, Clone)]
pub struct BoardDelay<B>(pub B);

impl<B: Deref<Target = SimBoard>> DelayNs for BoardDelay<B> {
    fn delay_ns(&mut self, ns: u32) {
        let t = &self.0.t_ns;
        t.set(t.get() + u64::from(ns));
    }
}

/// The node on a simulated board `B` with storage `S` (and update slots
/// `U`, none by default).
pub type SimNode<B, S, U = NoUpdates> =
    Node<BoardAdc<B>, BoardPin<B>, BoardPin<B>, BoardPin<B>, BoardDelay<B>, S, U>;

/// A node on `board` (typical factory calibration, power-on reset) named
/// `name` in its `Hello`.
pub fn sim_node<B, S>(board: B, storage: S, name: &'static str) -> SimNode<B, S>
where
    B: Deref<Target = SimBoard> + Clone,
    S: Storage,
{
    sim_node_with_updates(board, storage, name, NoUpdates)
}

/// A node as [`sim_node`] with the update slots `updates`.
pub fn sim_node_with_updates<B, S, U>(
    board: B,
    storage: S,
    name: &'static str,
    updates: U,
) -> SimNode<B, S, U>
where
    B: Deref<Target = SimBoard> + Clone,
    S: Storage,
    U: UpdateSlots,
{
    Node::new_with_updates(
        BoardAdc(board.clone()),
        BoardPin::new(board.clone(), Line::Led),
        BoardPin::new(board.clone(), Line::Alarm),
        BoardPin::new(board.clone(), Line::Indicator),
        BoardDelay(board),
        storage,
        BoardInfo::simulated(name),
        updates,
    )
}
