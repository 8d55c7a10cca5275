//! The node's optical gain: streamed with every `MeasurementV5`, set by a
//! calibration against a target (`CalibrateGain`), kept in the flash store
//! across a reset, forgotten on `ResetGain`, returned to the calibration by
//! a dark calibration; `GAIN_OUT_OF_BAND` when it leaves the configured band;
//! the temperature model from the config.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::*;
use fois_firmware::estimator::UNKNOWN_GAIN_SD;
use fois_firmware::storage::MemStorage;
use fois_protocol::*;

/// A reference target: its currents at gain 1, nA.
const TARGET: GainTarget = GainTarget {
    i1_na: 20_000,
    i2_na: 8_000,
};

fn ack(fs: &[DeviceFrame], id: u16) -> Result<AckResult, ErrorCode> {
    fs.iter()
        .find_map(|f| match &f.msg {
            DeviceMsg::Ack(a) if a.id == id => Some(Ok(a.result.clone())),
            DeviceMsg::Error(e) if e.id == Some(id) => Some(Err(e.code)),
            _ => None,
        })
        .expect("an answer")
}

fn streamed_gain(fs: &[DeviceFrame]) -> (u16, Option<GainEstimate>) {
    fs.iter()
        .find_map(|f| match &f.msg {
            DeviceMsg::MeasurementV5(m) => Some((m.measurement.flags, m.gain)),
            _ => None,
        })
        .expect("a MeasurementV5")
}

/// A node whose face shows the target at `gain` × its currents.
fn on_target(storage: MemStorage, gain: f64) -> (SimNode, World) {
    let (node, w) = node_with(storage);
    w.set(|s| {
        s.signal_na = [
            f64::from(TARGET.i1_na) * gain,
            f64::from(TARGET.i2_na) * gain,
        ];
        s.temp_c = -5.0;
    });
    (node, w)
}

#[test]
fn a_calibrated_gain_is_streamed_kept_across_a_reset_and_forgotten_on_request() {
    let (mut node, w) = on_target(MemStorage::new(), 0.85);
    // Before: the unknown prior, streamed from the first frame (a dry face
    // tells nothing about the gain).
    let target = w.scene.borrow().signal_na;
    w.set(|s| s.signal_na = [0.0, 0.0]);
    let (_, g) = streamed_gain(&step(&mut node, &w));
    w.set(|s| s.signal_na = target);
    let g = g.expect("a gain estimate");
    assert!(
        (g.sigma() / g.gain() - f64::from(UNKNOWN_GAIN_SD)).abs() < 0.05,
        "{g:?}"
    );
    let r = ack(
        &command(&mut node, &w, 1, Command::CalibrateGain(TARGET)),
        1,
    );
    let Ok(AckResult::GainCalibrated(c)) = r else {
        panic!("{r:?}")
    };
    assert!((c.gain() - 0.85).abs() < 0.005, "{c:?}");
    assert!((c.sigma() / c.gain() - 0.02).abs() < 1e-3, "{c:?}");
    let (_, g) = streamed_gain(&step(&mut node, &w));
    let g = g.unwrap();
    assert!((g.gain() - 0.85).abs() < 0.01, "{g:?}");
    assert!(g.sigma() < 0.03, "{g:?}");
    // Saved, and the prior of the next boot (widened by 1 %).
    run_until_saved(&mut node, &w);
    let storage = node.into_parts().5;
    let (mut node, w) = on_target(storage, 0.85);
    assert_eq!(node.gain_kept(), Some(c));
    let (_, g) = streamed_gain(&step(&mut node, &w));
    let g = g.unwrap();
    assert!((g.gain() - 0.85).abs() < 0.01, "{g:?}");
    assert!(g.sigma() / g.gain() < 0.035, "{g:?}");
    // Forgotten on request, and that is saved too.
    let r = ack(&command(&mut node, &w, 2, Command::ResetGain), 2);
    assert_eq!(r, Ok(AckResult::GainReset));
    let (_, g) = streamed_gain(&step(&mut node, &w));
    let g = g.unwrap();
    assert!(g.sigma() / g.gain() > 0.2, "{g:?}");
    run_until_saved(&mut node, &w);
    let (node, _) = on_target(node.into_parts().5, 0.85);
    assert_eq!(node.gain_kept(), None);
}

#[test]
fn a_calibration_that_cannot_be_trusted_is_refused_and_changes_nothing() {
    let (mut node, w) = on_target(MemStorage::new(), 0.85);
    let tiny = GainTarget {
        i1_na: 300,
        i2_na: 200,
    };
    let refused = |r| Err(ErrorCode::CalibrationRefused(r));
    let r = ack(&command(&mut node, &w, 1, Command::CalibrateGain(tiny)), 1);
    assert_eq!(r, refused(CalibrationRefusal::InvalidTarget));
    // The wrong target on the face: 5 × what it should read.
    w.set(|s| s.signal_na = [100_000.0, 40_000.0]);
    let r = ack(
        &command(&mut node, &w, 2, Command::CalibrateGain(TARGET)),
        2,
    );
    assert_eq!(r, refused(CalibrationRefusal::ImplausibleGain));
    // Sunlight saturates a channel.
    w.set(|s| s.ambient_na = [400_000.0, 0.0]);
    let r = ack(
        &command(&mut node, &w, 3, Command::CalibrateGain(TARGET)),
        3,
    );
    assert_eq!(r, refused(CalibrationRefusal::Saturated));
    assert_eq!(node.gain_kept(), None);
    assert!(!node.save_pending());
}

#[test]
fn a_gain_out_of_its_band_raises_the_maintenance_flag() {
    // A face so fouled it gives 45 % of the light.
    let (mut node, w) = on_target(MemStorage::new(), 0.45);
    let (flags_before, _) = streamed_gain(&step(&mut node, &w));
    assert_eq!(flags_before & flags::GAIN_OUT_OF_BAND, 0);
    let r = ack(
        &command(&mut node, &w, 1, Command::CalibrateGain(TARGET)),
        1,
    );
    assert!(matches!(r, Ok(AckResult::GainCalibrated(_))), "{r:?}");
    let fs = step(&mut node, &w);
    let (f, _) = streamed_gain(&fs);
    assert_ne!(f & flags::GAIN_OUT_OF_BAND, 0);
    assert!(fs.iter().any(|f| matches!(
        f.msg,
        DeviceMsg::Event(Event {
            kind: EventKind::FaultRaised(b),
            ..
        }) if b & flags::GAIN_OUT_OF_BAND != 0
    )));
    // The face cleaned and calibrated again: cleared.
    w.set(|s| s.signal_na = [f64::from(TARGET.i1_na), f64::from(TARGET.i2_na)]);
    ack(
        &command(&mut node, &w, 2, Command::CalibrateGain(TARGET)),
        2,
    )
    .unwrap();
    let (f, _) = streamed_gain(&step(&mut node, &w));
    assert_eq!(f & flags::GAIN_OUT_OF_BAND, 0);
}

#[test]
fn a_dark_calibration_returns_the_gain_to_the_calibration() {
    let (mut node, w) = on_target(MemStorage::new(), 1.1);
    ack(
        &command(&mut node, &w, 1, Command::CalibrateGain(TARGET)),
        1,
    )
    .unwrap();
    // The face cleaned and dry: a dark calibration.
    w.set(|s| s.signal_na = [0.0, 0.0]);
    for _ in 0..10 {
        step(&mut node, &w);
    }
    let r = ack(&command(&mut node, &w, 2, Command::CalibrateDark), 2);
    assert!(matches!(r, Ok(AckResult::DarkCalibrated(_))), "{r:?}");
    let (_, g) = streamed_gain(&step(&mut node, &w));
    let g = g.unwrap();
    assert!((g.gain() - 1.1).abs() < 0.02, "{g:?}");
    assert!(g.sigma() / g.gain() < 0.03, "{g:?}");
    // Without a calibration, it returns to unknown.
    let (mut node, w) = on_target(MemStorage::new(), 0.0);
    for _ in 0..10 {
        step(&mut node, &w);
    }
    ack(&command(&mut node, &w, 3, Command::CalibrateDark), 3).unwrap();
    let (_, g) = streamed_gain(&step(&mut node, &w));
    assert!(g.unwrap().sigma() > 0.2);
}

#[test]
fn the_config_sets_the_temperature_model() {
    // −0.6 %/K, the optics at −5 °C: the node expects exp(0.18) = 1.197 ×
    // the light of 25 °C; a target calibrated at −5 °C reading 1.197 × its
    // currents is gain 1 at 25 °C, reported as 1.197 now.
    let (mut node, w) = on_target(MemStorage::new(), 0.18f64.exp());
    let cfg = Config {
        gain_tempco_ppm_per_k: -6_000,
        gain_tempco_sd_ppm_per_k: 500,
        ..node.config().clone()
    };
    let r = ack(&command(&mut node, &w, 1, Command::SetConfigV3(cfg)), 1);
    assert!(matches!(r, Ok(AckResult::ConfigV3(_))), "{r:?}");
    step(&mut node, &w);
    let r = ack(
        &command(&mut node, &w, 2, Command::CalibrateGain(TARGET)),
        2,
    );
    let Ok(AckResult::GainCalibrated(c)) = r else {
        panic!("{r:?}")
    };
    assert!((c.gain() - 1.0).abs() < 0.01, "{c:?}");
    let (_, g) = streamed_gain(&step(&mut node, &w));
    assert!((g.unwrap().gain() - 0.18f64.exp()).abs() < 0.02, "{g:?}");
    // An absurd coefficient is refused by the config's own check.
    let bad = Config {
        gain_tempco_ppm_per_k: i32::MAX,
        ..node.config().clone()
    };
    let r = ack(&command(&mut node, &w, 3, Command::SetConfigV3(bad)), 3);
    assert!(matches!(r, Err(ErrorCode::InvalidConfig(_))), "{r:?}");
}

#[test]
fn a_learned_gain_is_kept_hourly_and_is_the_prior_after_a_reset() {
    // 10 mm of rime at 0.85× the table's light, −8 °C, the gain unknown.
    let e = &fois_firmware::estimator::table::RIME[49];
    let (mut node, w) = node();
    w.set(|s| {
        s.signal_na = [0.85 * f64::from(e.mu_na[0]), 0.85 * f64::from(e.mu_na[1])];
        s.temp_c = -8.0;
    });
    let period_ms = u64::from(node.frame_period_ms());
    let mut saved_at = None;
    for n in 0..(3_700_000 / period_ms) {
        step(&mut node, &w);
        if saved_at.is_none() && node.gain_kept().is_some() {
            saved_at = Some(n * period_ms);
        }
    }
    // Considered once the first hour is over, not before.
    let at = saved_at.expect("the learned gain kept");
    assert!(
        (3_600_000..3_600_000 + 2 * period_ms).contains(&at),
        "{at} ms"
    );
    let kept = node.gain_kept().unwrap();
    assert!((kept.gain() / 0.85).ln().abs() < 0.08, "{kept:?}");
    run_until_saved(&mut node, &w);
    let (mut node, w2) = node_with(node.into_parts().5);
    w2.set(|s| s.temp_c = -8.0);
    assert_eq!(node.gain_kept(), Some(kept));
    let (_, g) = streamed_gain(&step(&mut node, &w2));
    let g = g.unwrap();
    assert!(
        (g.gain() / kept.gain()).ln().abs() < 0.01,
        "{g:?} vs {kept:?}"
    );
    let kept_sd = kept.sigma() / kept.gain();
    assert!(g.sigma() / g.gain() > kept_sd, "widened: {g:?} vs {kept:?}");
}
