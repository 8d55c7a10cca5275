//! The dark-calibration scenarios with their numbers: calibrated at a noisy
//! site (8 LSB, 5 µA of ambient, −10 °C) to within its standard error of
//! the true dry currents, a cloud edge in bright sun refused as a `Step`, a
//! wet face refused as `NotDry`. The files are in `hil/scenarios/`; this
//! asserts more than their `[expect]` tables can say.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use fois_hil::Outcome;
use fois_protocol::{AckResult, Baseline, CalibrationRefusal, ErrorCode};
use fois_vnode::Environment;

/// Run one shipped scenario file (its own expectations must hold too);
/// also the true dry-face currents of its environment, nA.
fn run(file: &str) -> (Outcome, [f64; 2]) {
    let (o, sc) = common::run_file(file);
    let env = Environment::new(sc.timeline.clone(), sc.sensor, sc.seed);
    let dry = env.truth(0).led_signal_ua.map(|ua| ua * 1e3);
    (o, dry)
}

fn answers(o: &Outcome) -> Vec<Result<AckResult, ErrorCode>> {
    o.replies.iter().map(|r| r.result.clone()).collect()
}

fn baseline(r: &Result<AckResult, ErrorCode>) -> Baseline {
    match r {
        Ok(AckResult::DarkCalibrated(b)) => *b,
        other => panic!("not calibrated: {other:?}"),
    }
}

#[test]
fn a_noisy_site_calibrates_to_the_true_dry_face() {
    let (o, dry) = run("calibration-noisy-site.toml");
    let a = answers(&o);
    assert_eq!(a.len(), 2, "{a:?}");
    for r in &a {
        let b = baseline(r);
        // Within 3 standard errors (3 × 50 nA) of the truth, both channels.
        assert!(
            (f64::from(b.i1_na) - dry[0]).abs() <= 150.0,
            "{b:?} vs {dry:?}"
        );
        assert!(
            (f64::from(b.i2_na) - dry[1]).abs() <= 150.0,
            "{b:?} vs {dry:?}"
        );
    }
    assert_eq!(o.false_alarms(), 0);
}

#[test]
fn a_cloud_edge_in_bright_sun_is_refused_as_a_step() {
    let (o, dry) = run("calibration-cloud.toml");
    let a = answers(&o);
    assert_eq!(a.len(), 3, "{a:?}");
    assert_eq!(
        a[0],
        Err(ErrorCode::CalibrationRefused(CalibrationRefusal::Step))
    );
    // In the steady shade and in the steady sun: calibrated, to the truth.
    for r in &a[1..] {
        let b = baseline(r);
        assert!(
            (f64::from(b.i1_na) - dry[0]).abs() <= 150.0,
            "{b:?} vs {dry:?}"
        );
    }
}

#[test]
fn a_wet_face_is_refused_until_it_has_dried() {
    let (o, _) = run("calibration-wet.toml");
    let a = answers(&o);
    assert_eq!(a.len(), 3, "{a:?}");
    assert_eq!(a[0], Err(ErrorCode::NotDry));
    assert_eq!(a[1], Err(ErrorCode::NotDry));
    baseline(&a[2]);
}
