//! The environment: thickness across segments, light, LED drift and the
//! optical gain, with numbers.

use super::*;
use fois_sim::CurvePoint;

/// A straight-line curve: I1 = 2·d + 0.5, I2 = d.
pub(crate) fn line_curve() -> Curve {
    Curve {
        points: (0..=150)
            .map(|i| {
                let d = f64::from(i) * 0.1;
                CurvePoint {
                    thickness_mm: d,
                    i1_ua: 2.0 * d + 0.5,
                    i2_ua: d,
                    ..CurvePoint::default()
                }
            })
            .collect(),
    }
}

#[test]
fn thickness_accumulates_across_segments_and_water_freezes_in_place() {
    let tl = Timeline::new(vec![
        Segment::new(100.0, Cover::Dry),
        Segment::new(3600.0, Cover::Water).rate(2.0).temp(5.0),
        Segment::new(3600.0, Cover::Glazed)
            .rate(1.0)
            .temp_ramp(5.0, -5.0),
        Segment::new(10.0, Cover::Dry),
        Segment::new(10.0, Cover::Rime).rate(3600.0 * 100.0),
    ]);
    let env = Environment::with_curves(
        tl,
        [(Cover::Water, line_curve()), (Cover::Glazed, line_curve())],
        [0.5, 0.0],
    );
    let s = 1_000_000_000u64;
    let t = env.truth(50 * s);
    assert_eq!(
        (t.cover, t.thickness_mm, t.led_signal_ua),
        (Cover::Dry, 0.0, [0.5, 0.0])
    );
    let t = env.truth((100 + 1800) * s);
    assert!((t.thickness_mm - 1.0).abs() < 1e-9);
    assert!((t.led_signal_ua[0] - 2.5).abs() < 1e-9);
    assert_eq!(t.air_temp_c, 5.0);
    // The water film (2 mm) freezes and keeps growing at 1 mm/h.
    let t = env.truth((100 + 3600 + 1800) * s);
    assert_eq!(t.cover, Cover::Glazed);
    assert!((t.thickness_mm - 2.5).abs() < 1e-9);
    assert!(t.air_temp_c.abs() < 1e-9, "halfway down the ramp");
    // Dry resets; a medium without a curve reads as dry; clamp at 15 mm.
    let t = env.truth((100 + 7200 + 5) * s);
    assert_eq!(t.thickness_mm, 0.0);
    let t = env.truth((100 + 7200 + 10 + 5) * s);
    assert_eq!(t.thickness_mm, MAX_THICKNESS_MM);
    assert_eq!(t.led_signal_ua, [0.5, 0.0]);
    // After the end the last segment holds.
    assert_eq!(env.truth(1_000_000 * s).segment, 4);
}

#[test]
fn ambient_flicker_and_led_drift() {
    let tl = Timeline::constant(
        Segment::new(100.0, Cover::Glazed)
            .thickness(5.0)
            .ambient([10.0, 1.0])
            .flicker([4.0, 4.0])
            .led_ramp(1.0, 0.7),
    );
    let env = Environment::with_curves(tl, [(Cover::Glazed, line_curve())], [0.0; 2]);
    // 2.5 ms into a 100 Hz period: sin = 1.
    let t = env.truth(2_500_000);
    assert!((t.ambient_ua[0] - 14.0).abs() < 1e-6);
    assert_eq!(t.ambient_ua[1], 5.0);
    let t = env.truth(7_500_000);
    assert!((t.ambient_ua[0] - 6.0).abs() < 1e-6);
    assert_eq!(t.ambient_ua[1], 0.0, "never negative");
    let t = env.truth(100_000_000_000);
    assert!((t.led_factor - 0.7).abs() < 1e-12);
    assert!((t.led_signal_ua[0] - 0.7 * 10.5).abs() < 1e-9);
}

#[test]
fn the_optical_gain_follows_led_temperature_and_fouling() {
    // κ = −0.6 %/K, air −25 → −5 °C over 100 s with the optics 3 K
    // above it, face transmission 1.0 → 0.8, LED 0.9, 10 µA of sun.
    let tl = Timeline::constant(
        Segment::new(100.0, Cover::Rime)
            .thickness(5.0)
            .temp_ramp(-25.0, -5.0)
            .gain_tempco(-0.006)
            .optics_above_air(3.0)
            .transmission_ramp(1.0, 0.8)
            .led(0.9)
            .ambient([10.0, 0.0]),
    );
    let env = Environment::with_curves(tl, [(Cover::Rime, line_curve())], [0.0; 2]);
    let t = env.truth(0);
    assert_eq!((t.air_temp_c, t.optics_temp_c), (-25.0, -22.0));
    // exp(−0.006 × (−22 − 25)) = exp(0.282) = 1.325 78; × 0.9 = 1.193 20.
    assert!((t.gain.temperature_factor - 1.325_779).abs() < 1e-6);
    assert!((t.gain.signal_gain() - 1.193_201).abs() < 1e-6);
    // The curve reads 10.5 µA at 5 mm.
    assert!((t.led_signal_ua[0] - 12.528_609).abs() < 1e-5);
    assert_eq!(t.ambient_ua, [10.0, 0.0]);
    // Halfway: optics at −12 °C, exp(0.222) = 1.248 57; t = 0.9, so the
    // signal loses 0.81 and the sun 0.9.
    let t = env.truth(50_000_000_000);
    assert!((t.gain.face_transmission - 0.9).abs() < 1e-12);
    assert!((t.gain.signal_gain() - 0.910_209).abs() < 1e-6);
    assert!((t.led_signal_ua[0] - 9.557_190).abs() < 1e-5);
    assert!((t.ambient_ua[0] - 9.0).abs() < 1e-12);
    // The defaults leave everything as it was: gain = LED factor.
    let plain = Environment::with_curves(
        Timeline::constant(Segment::new(10.0, Cover::Rime).thickness(5.0).temp(-40.0)),
        [(Cover::Rime, line_curve())],
        [0.0; 2],
    );
    let t = plain.truth(0);
    assert_eq!((t.optics_temp_c, t.gain.signal_gain()), (-40.0, 1.0));
    assert_eq!(t.led_signal_ua[0], 10.5);
}

#[test]
fn a_target_reads_over_the_dry_face_times_the_gain_whatever_the_cover() {
    let tl = Timeline::new(vec![
        Segment::new(10.0, Cover::Dry),
        Segment::new(10.0, Cover::Rime)
            .rate(3600.0)
            .led(0.8)
            .target([25.2, 9.56]),
        Segment::new(f64::INFINITY, Cover::Rime).rate(3600.0),
    ]);
    let env = Environment::with_curves(tl, [(Cover::Rime, line_curve())], [0.6, 0.2]);
    let dry = env.truth(5_000_000_000).led_signal_ua;
    assert!((dry[0] - 0.6).abs() < 1e-12 && (dry[1] - 0.2).abs() < 1e-12);
    // The target on: (dry + target) × 0.8, the rime under it not seen.
    let on = env.truth(15_000_000_000);
    assert!((on.led_signal_ua[0] - 0.8 * 25.8).abs() < 1e-9, "{on:?}");
    assert!((on.led_signal_ua[1] - 0.8 * 9.76).abs() < 1e-9, "{on:?}");
    // Taken off: the rime's curve again.
    let off = env.truth(25_000_000_000);
    assert!((off.led_signal_ua[0] - on.led_signal_ua[0]).abs() > 1e-3);
}
