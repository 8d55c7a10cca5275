//! Ambient light: a DC level plus a mains flicker must barely move I1/I2.
//!
//! Bound (derivation in `fois_firmware::measure::photocurrent`): each LED-on sample is
//! compared with the mean of the LED-off samples one settle-plus-conversion
//! time Δ before and after it, which cancels the linear part of the ambient
//! change; what is left of a flicker A·sin(2πft) is at most A·(2πfΔ)²/2, plus
//! one ADC step of quantisation. With Δ = 200 µs settle + 19 µs for the
//! board's photo pair (two conversions of 8.5 µs with the converter kept on,
//! and the register work) and f = 100 Hz that is 0.95 % of A: for A = 25 µA
//! (a 50 µA ambient modulated ±50 %), ≤ 237 nA + 81 nA = 318 nA, under a
//! third of the 1 µA onset rise.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use fois_protocol::{DeviceMsg, Measurement};

/// One photo pair (`read_photo`) on the board, µs: 2 × (56 + 12) ADC cycles
/// at 8 MHz plus the register work (`firmware/README.md`, the board binary;
/// the board logs its own figure at boot).
const BOARD_PAIR_US: f64 = 19.0;

fn measure(w: &World, node: &mut SimNode) -> Measurement {
    let fs = step(node, w);
    fs.into_iter()
        .find_map(|f| match f.msg {
            DeviceMsg::MeasurementV5(m) => Some(m.measurement),
            _ => None,
        })
        .expect("streaming")
}

/// The bound stated above, nA, for flicker amplitude `a_na` at `f_hz`.
fn bound_na(a_na: f64, f_hz: f64, settle_us: f64, conversion_us: f64) -> f64 {
    let delta = (settle_us + conversion_us) * 1e-6;
    let wd = 2.0 * std::f64::consts::PI * f_hz * delta;
    a_na * wd * wd / 2.0 + 80.6
}

fn worst_error(f_hz: f64, amplitude: f64) -> (f64, [i32; 2]) {
    let signal = [5_000.0, 1_500.0];
    let (mut n0, w) = node();
    w.set(|s| {
        s.signal_na = signal;
        s.conversion_ns = (BOARD_PAIR_US * 1_000.0) as u64;
    });
    let dark = measure(&w, &mut n0);
    let mut worst: f64 = 0.0;
    let reference = [dark.i1_na, dark.i2_na];
    for k in 0..64 {
        let (mut node, w) = node();
        let phase = k as f64 * std::f64::consts::TAU / 64.0;
        w.set(|s| {
            s.signal_na = signal;
            s.ambient_na = [50_000.0, 50_000.0];
            s.flicker_na = [amplitude, amplitude];
            s.flicker_hz = f_hz;
            s.flicker_phase = phase;
            s.conversion_ns = (BOARD_PAIR_US * 1_000.0) as u64;
        });
        // Several frames: the frame start moves against the flicker too.
        for _ in 0..3 {
            let m = measure(&w, &mut node);
            assert!(m.is_valid());
            assert!((m.ambient1_na as f64 - 50_000.0).abs() < amplitude + 100.0);
            for (i, r) in [m.i1_na, m.i2_na].into_iter().zip(reference) {
                worst = worst.max(f64::from(i - r).abs());
            }
        }
    }
    (worst, reference)
}

#[test]
fn dc_ambient_does_not_move_the_currents() {
    let (mut n0, w) = node();
    w.set(|s| s.signal_na = [5_000.0, 1_500.0]);
    let dark = measure(&w, &mut n0);
    for dc in [1_000.0, 50_000.0, 200_000.0, 300_000.0] {
        let (mut node, w) = node();
        w.set(|s| {
            s.signal_na = [5_000.0, 1_500.0];
            s.ambient_na = [dc, dc];
        });
        let m = measure(&w, &mut node);
        assert!((m.i1_na - dark.i1_na).abs() <= 81, "DC {dc}: {m:?}");
        assert!((m.i2_na - dark.i2_na).abs() <= 81, "DC {dc}: {m:?}");
        assert!(
            (f64::from(m.ambient1_na) - dc).abs() <= 81.0,
            "DC {dc}: {m:?}"
        );
    }
}

#[test]
fn mains_flicker_stays_under_the_stated_bound() {
    for f in [100.0, 120.0] {
        let amplitude = 25_000.0;
        let (worst, _) = worst_error(f, amplitude);
        let bound = bound_na(amplitude, f, 200.0, BOARD_PAIR_US);
        println!(
            "ambient 50 µA DC + {amplitude} nA at {f} Hz: worst |ΔI| = {worst:.0} nA, bound {bound:.0} nA"
        );
        assert!(worst <= bound, "{f} Hz: {worst} nA > {bound} nA");
        assert!(worst < 1_000.0 / 3.0, "must stay well under the onset rise");
    }
}

#[test]
fn a_plain_difference_would_not_meet_it() {
    // Sanity of the bound: the first-order term A·2πfΔ that the bracketing
    // cancels is 14× larger than what is left.
    let a: f64 = 25_000.0;
    let first_order = a * 2.0 * std::f64::consts::PI * 100.0 * (200.0 + BOARD_PAIR_US) * 1e-6;
    assert!(first_order > 3_000.0);
    assert!(bound_na(a, 100.0, 200.0, BOARD_PAIR_US) < first_order / 10.0);
}
