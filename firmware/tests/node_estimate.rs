//! The node streams `MeasurementV5` with the ice estimator's estimate: fed
//! with the baseline-corrected currents of valid frames and the NTC's air
//! temperature; saturated frames only predict; a dark calibration starts the
//! estimator from "dry".
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use fois_firmware::estimator::{Update, table};
use fois_protocol::*;

fn estimate(fs: &[DeviceFrame]) -> (Measurement, Option<IceEstimate>) {
    fs.iter()
        .find_map(|f| match &f.msg {
            DeviceMsg::MeasurementV5(m) => Some((m.measurement.clone(), m.estimate)),
            _ => None,
        })
        .expect("a MeasurementV5")
}

#[test]
fn the_measurement_carries_the_estimate() {
    let (mut node, w) = node();
    // Rime at 5 mm (the table's mean currents) at −8 °C.
    let e = &table::RIME[24];
    w.set(|s| {
        s.signal_na = [f64::from(e.mu_na[0]), f64::from(e.mu_na[1])];
        s.temp_c = -8.0;
    });
    // The node's gain calibrated first (those currents as the target: gain
    // 1): with its gain unknown, 5 mm of rime reads like 10 mm at 0.86× the
    // gain, and the estimate says so with a wide σ (`node_gain.rs`).
    let target = GainTarget {
        i1_na: u32::from(e.mu_na[0]),
        i2_na: u32::from(e.mu_na[1]),
    };
    let fs = command(&mut node, &w, 3, Command::CalibrateGain(target));
    assert!(
        fs.iter().any(|f| matches!(
            f.msg,
            DeviceMsg::Ack(Ack {
                id: 3,
                result: AckResult::GainCalibrated(_)
            })
        )),
        "{fs:?}"
    );
    let (m, est) = estimate(&step(&mut node, &w));
    assert!(m.is_valid());
    let est = est.expect("an estimate from the first valid frame");
    assert_eq!(node.estimator().last_update(), Update::Initialised);
    for _ in 0..300 {
        step(&mut node, &w);
    }
    let (_, est2) = estimate(&step(&mut node, &w));
    let est2 = est2.expect("estimate");
    for e in [est, est2] {
        assert_eq!(e.medium, Medium::Rime, "{e:?}");
        assert!((i32::from(e.thickness_um) - 5_000).abs() < 1_000, "{e:?}");
    }
    assert!(est2.probability_permille > 900, "{est2:?}");

    // Sunlight saturates channel 1: the frame is invalid, the estimator
    // only predicts, and the estimate is still sent.
    // (The estimator updates once a second on the frames gathered.)
    w.set(|s| s.ambient_na = [400_000.0, 0.0]);
    for _ in 0..20 {
        step(&mut node, &w);
    }
    let (m, est3) = estimate(&step(&mut node, &w));
    assert!(!m.is_valid());
    assert_eq!(node.estimator().last_update(), Update::NoCurrents);
    assert_eq!(est3.map(|e| e.medium), Some(Medium::Rime));
}

#[test]
fn a_failed_ntc_gives_the_estimator_no_temperature() {
    // Water optics at 1 mm: at +5 °C water; with the NTC open the node's
    // rule reads the die sensor, but the estimator gets no temperature, so
    // glaze (alike optically) keeps a share.
    let e = &table::WATER[4];
    let run = |ntc_code: Option<u16>| {
        let (mut node, w) = node();
        w.set(|s| {
            s.signal_na = [f64::from(e.mu_na[0]), f64::from(e.mu_na[1])];
            s.temp_c = 5.0;
            s.ntc_code = ntc_code;
        });
        for _ in 0..300 {
            step(&mut node, &w);
        }
        node.estimator().posterior().expect("posterior")
    };
    let ok = run(None);
    let open = run(Some(4095));
    assert_eq!(ok.medium().0, Medium::Water, "{ok:?}");
    assert!(ok.p_medium[2] + ok.p_medium[3] < 1e-3, "{ok:?}");
    assert!(open.p_medium[2] + open.p_medium[3] > 0.1, "{open:?}");
}

#[test]
fn a_dark_calibration_starts_the_estimator_from_dry() {
    let (mut node, w) = node();
    w.set(|s| s.temp_c = -10.0);
    for _ in 0..10 {
        step(&mut node, &w);
    }
    let fs = command(&mut node, &w, 9, Command::CalibrateDark);
    assert!(fs.iter().any(|f| matches!(
        f.msg,
        DeviceMsg::Ack(Ack {
            id: 9,
            result: AckResult::DarkCalibrated(_)
        })
    )));
    for _ in 0..600 {
        step(&mut node, &w);
    }
    let (_, est) = estimate(&step(&mut node, &w));
    let est = est.expect("estimate");
    assert_eq!(est.medium, Medium::Dry, "{est:?}");
    assert!(est.probability_permille >= 990, "{est:?}");
    assert!(est.thickness_um < 20, "{est:?}");
}
