//! A tiny simulated board for the node tests: a virtual clock advanced by the
//! delay and by each ADC conversion, an LED the ADC can see, and a scene
//! (photocurrents, ambient light with a 100 Hz flicker, air temperature).
#![allow(dead_code)]

use std::cell::{Cell, RefCell};
use std::convert::Infallible;
use std::rc::Rc;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{ErrorType, OutputPin};
use fois_firmware::hal::{BoardInfo, FactoryCal, MemStorage, PhotoAdc, Storage};
use fois_firmware::node::Node;
use fois_protocol::{DeviceFrame, FrameDecoder, HostFrame, encode_to_vec};

/// What the simulated optics and air do.
#[derive(Debug, Clone)]
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
    /// Air temperature, °C.
    pub temp_c: f64,
    /// Override of the NTC code (open/short).
    pub ntc_code: Option<u16>,
    /// Supply, mV.
    pub vdda_mv: f64,
    /// Load resistors, Ω.
    pub load_ohm: [f64; 2],
    /// Time one `read_photo` takes, ns.
    pub conversion_ns: u64,
    /// V_CE(sat) of the phototransistors, mV: the emitter (ADC input) never
    /// rises above V_DDA minus this (the clip of strong light).
    pub vce_sat_mv: f64,
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
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
            vce_sat_mv: 250.0,
        }
    }
}

#[derive(Clone, Default)]
pub struct World {
    pub t_ns: Rc<Cell<u64>>,
    pub led: Rc<Cell<bool>>,
    pub alarm: Rc<Cell<bool>>,
    pub indicator: Rc<Cell<bool>>,
    pub scene: Rc<RefCell<Scene>>,
    pub led_toggles: Rc<Cell<u32>>,
}

impl World {
    pub fn now_ms(&self) -> u64 {
        self.t_ns.get() / 1_000_000
    }
    pub fn advance_ms(&self, ms: u64) {
        self.t_ns.set(self.t_ns.get() + ms * 1_000_000);
    }
    pub fn set(&self, f: impl FnOnce(&mut Scene)) {
        f(&mut self.scene.borrow_mut());
    }
}

pub struct SimAdc(pub World);

fn to_code(volts: f64, vdda_mv: f64) -> u16 {
    (volts / (vdda_mv / 1000.0) * 4095.0)
        .round()
        .clamp(0.0, 4095.0) as u16
}

impl PhotoAdc for SimAdc {
    fn read_photo(&mut self) -> [u16; 2] {
        let w = &self.0;
        let s = w.scene.borrow();
        let t = w.t_ns.get() as f64 * 1e-9;
        let mut out = [0u16; 2];
        #[allow(clippy::needless_range_loop)]
        for ch in 0..2 {
            let flicker = s.flicker_na[ch]
                * (2.0 * std::f64::consts::PI * s.flicker_hz * t + s.flicker_phase).sin();
            let led = if w.led.get() {
                s.signal_na[ch] + s.signal_ramp_na_per_s[ch] * t
            } else {
                0.0
            };
            let i_na = (s.ambient_na[ch] + flicker + led).max(0.0);
            let clip_v = (s.vdda_mv - s.vce_sat_mv) / 1000.0;
            let v = (i_na * 1e-9 * s.load_ohm[ch]).min(clip_v);
            out[ch] = to_code(v, s.vdda_mv);
        }
        w.t_ns.set(w.t_ns.get() + s.conversion_ns);
        out
    }
    fn read_ntc(&mut self) -> u16 {
        let s = self.0.scene.borrow();
        if let Some(c) = s.ntc_code {
            return c;
        }
        let r = 10_000.0 * ((1.0 / (s.temp_c + 273.15) - 1.0 / 298.15) * 3950.0).exp();
        (4095.0 * r / (r + 10_000.0)).round() as u16
    }
    fn read_vrefint(&mut self) -> u16 {
        let s = self.0.scene.borrow();
        let vref = 3.3 * f64::from(FactoryCal::TYPICAL.vrefint_cal) / 4095.0;
        to_code(vref, s.vdda_mv)
    }
    fn read_internal_temp(&mut self) -> u16 {
        let s = self.0.scene.borrow();
        let c = FactoryCal::TYPICAL;
        let code33 =
            f64::from(c.ts_cal1) + (s.temp_c - 30.0) * f64::from(c.ts_cal2 - c.ts_cal1) / 80.0;
        (code33 * 3300.0 / s.vdda_mv).round() as u16
    }
}

pub struct Pin(pub Rc<Cell<bool>>, pub Option<Rc<Cell<u32>>>);
impl ErrorType for Pin {
    type Error = Infallible;
}
impl OutputPin for Pin {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.0.set(false);
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        if let Some(t) = &self.1 {
            t.set(t.get() + 1);
        }
        self.0.set(true);
        Ok(())
    }
}

pub struct Delay(pub Rc<Cell<u64>>);
impl DelayNs for Delay {
    fn delay_ns(&mut self, ns: u32) {
        self.0.set(self.0.get() + u64::from(ns));
    }
}

pub type SimNode = NodeOn<MemStorage>;
/// The simulated node on storage `S`.
pub type NodeOn<S> = Node<SimAdc, Pin, Pin, Pin, Delay, S>;

/// A node on a fresh world with this storage.
pub fn node_with(storage: MemStorage) -> (SimNode, World) {
    node_on(storage)
}

/// A node on a fresh world with any storage.
pub fn node_on<S: Storage>(storage: S) -> (NodeOn<S>, World) {
    let w = World::default();
    let node = Node::new(
        SimAdc(w.clone()),
        Pin(w.led.clone(), Some(w.led_toggles.clone())),
        Pin(w.alarm.clone(), None),
        Pin(w.indicator.clone(), None),
        Delay(w.t_ns.clone()),
        storage,
        BoardInfo::simulated("sim"),
    );
    (node, w)
}

pub fn node() -> (SimNode, World) {
    node_with(MemStorage::new())
}

/// Decode everything a call sent.
pub fn frames(bytes: &[u8]) -> Vec<DeviceFrame> {
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    let mut out = Vec::new();
    dec.feed::<DeviceFrame>(bytes, |r| out.push(r.expect("node sent a bad frame")));
    out
}

/// Run frames until the node has saved what it had pending (at most 30 s of
/// frames); returns the frames sent.
pub fn run_until_saved<S: Storage>(node: &mut NodeOn<S>, w: &World) -> Vec<DeviceFrame> {
    let mut out = Vec::new();
    for _ in 0..300 {
        if !node.save_pending() {
            break;
        }
        out.extend(step(node, w));
    }
    assert!(!node.save_pending(), "the save never came");
    out
}

/// Run one frame and return the frames it sent; the clock then moves to the
/// end of the frame period.
pub fn step<S: Storage>(node: &mut NodeOn<S>, w: &World) -> Vec<DeviceFrame> {
    let start = w.t_ns.get();
    let mut bytes = Vec::new();
    node.run_frame(w.now_ms(), &mut |b| bytes.extend_from_slice(b));
    let period_ns = u64::from(node.frame_period_ms()) * 1_000_000;
    w.t_ns.set(start + period_ns.max(w.t_ns.get() - start));
    frames(&bytes)
}

/// Send one command; return the frames answered.
pub fn command<S: Storage>(
    node: &mut NodeOn<S>,
    w: &World,
    id: u16,
    cmd: fois_protocol::Command,
) -> Vec<DeviceFrame> {
    let mut bytes = Vec::new();
    let wire = encode_to_vec(&HostFrame { id, cmd });
    node.handle_rx(&wire, w.now_ms(), &mut |b| bytes.extend_from_slice(b));
    frames(&bytes)
}
