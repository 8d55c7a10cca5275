//! The estimator's optical gain: learned where the currents tell it (thick
//! rime), kept while a dry face tells nothing, set from a calibration or a
//! kept estimate, compensated for the optoelectronics' temperature; and
//! never "confidently thin" while it is unknown.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use fois_firmware::estimator::{
    Estimator, GAIN_REF_TEMP_C, GAINS, ROWS, STEP_MM, TableEntry, UNKNOWN_GAIN_SD, table,
};
use fois_protocol::Medium;

/// The table's mean currents at `d` mm (linear between rows), µA.
fn mean_at(t: &[TableEntry; ROWS], d: f32) -> [f32; 2] {
    let f = (d / STEP_MM - 1.0).clamp(0.0, (ROWS - 1) as f32);
    let i = f.floor() as usize;
    let j = (i + 1).min(ROWS - 1);
    let w = f - i as f32;
    let at = |k: usize| {
        [
            f32::from(t[k].mu_na[0]) * 1e-3,
            f32::from(t[k].mu_na[1]) * 1e-3,
        ]
    };
    let (a, b) = (at(i), at(j));
    [a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1])]
}

/// Rime's mean curve × `gain`, grown from a dry face at 5 mm/h to `d_end`,
/// 10 Hz frames at −8 °C; `check(d, estimator)` after every second.
fn grow_rime(est: &mut Estimator, gain: f32, d_end: f32, mut check: impl FnMut(f32, &Estimator)) {
    let frames = (d_end / 5.0 * 36_000.0) as usize;
    for n in 0..=frames {
        let d = d_end * n as f32 / frames as f32;
        let x = mean_at(&table::RIME, d).map(|v| v * gain);
        est.step(0.1, Some(x), Some(-8.0));
        if n % 10 == 0 {
            check(d, est);
        }
    }
}

#[test]
fn an_unknown_gain_is_learned_on_thick_rime_and_never_reads_thin() {
    for gain in [0.85f32, 1.15] {
        let mut est = Estimator::default();
        est.set_dry();
        let mut thin = 0;
        grow_rime(&mut est, gain, 10.0, |d, est| {
            let p = est.posterior().expect("an estimate");
            if d >= 4.0 && p.thickness_mm + 2.0 * p.sigma_mm < d / 2.0 {
                thin += 1;
            }
        });
        assert_eq!(thin, 0, "gain {gain}: confidently thin");
        let p = est.posterior().unwrap();
        let g = est.gain().unwrap();
        assert_eq!(p.medium().0, Medium::Rime, "gain {gain}: {p:?}");
        assert!(
            (p.thickness_mm - 10.0).abs() <= 2.0 * p.sigma_mm,
            "gain {gain}: {p:?}"
        );
        assert!(
            (g.gain / gain).ln().abs() < 0.08,
            "gain {gain}: learned {g:?}, weights {:?}",
            est.gain_weights()
        );
        assert!(g.sigma < 0.15, "gain {gain}: {g:?}");
    }
}

#[test]
fn a_dry_face_says_nothing_about_the_gain_and_keeps_what_was_learned() {
    let mut est = Estimator::default();
    est.set_dry();
    let before = est.gain().unwrap();
    for _ in 0..36_000 {
        est.step(0.1, Some([0.02, -0.01]), Some(-8.0));
    }
    // An hour of dry face: the prior, unchanged.
    let after = est.gain().unwrap();
    assert!(
        (after.gain - before.gain).abs() < 1e-4,
        "{before:?} → {after:?}"
    );
    assert!((after.sigma - before.sigma).abs() < 1e-4);
    // Learn on rime at 0.85, shed, an hour dry: the learned gain stays.
    grow_rime(&mut est, 0.85, 10.0, |_, _| {});
    let learned = est.gain().unwrap();
    for _ in 0..36_000 {
        est.step(0.1, Some([0.02, -0.01]), Some(-8.0));
    }
    assert_eq!(est.posterior().unwrap().medium().0, Medium::Dry);
    let kept = est.gain().unwrap();
    assert!(
        (kept.gain / learned.gain).ln().abs() < 0.01,
        "{learned:?} → {kept:?}"
    );
}

#[test]
fn the_prior_is_set_by_a_calibration_and_forgotten_on_request() {
    let mut est = Estimator::default();
    assert_eq!(est.gain_prior(), (1.0, UNKNOWN_GAIN_SD));
    est.set_gain_prior(0.85, 0.02);
    let (g, sd) = est.gain_prior();
    assert!((g - 0.85).abs() < 1e-5 && (sd - 0.02).abs() < 1e-6);
    // The hypotheses sit around it, ±3 steps of its sd.
    let h = est.gain_hypotheses();
    assert_eq!(h.len(), GAINS);
    assert!((h[GAINS / 2] - 0.85).abs() < 1e-4, "{h:?}");
    assert!((h[GAINS - 1] / h[0]).ln() > 0.11 && (h[GAINS - 1] / h[0]).ln() < 0.13);
    est.set_dry();
    let e = est.gain().unwrap();
    assert!((e.gain - 0.85).abs() < 0.01, "{e:?}");
    assert!(e.sigma < 0.03, "{e:?}");
    // Nonsense leaves the gain unknown.
    for (g, sd) in [(f32::NAN, 0.02), (0.0, 0.02), (50.0, 0.02), (-1.0, 0.1)] {
        est.set_gain_prior(g, sd);
        assert_eq!(est.gain_prior(), (1.0, UNKNOWN_GAIN_SD), "{g} {sd}");
    }
    est.set_gain_prior(0.9, f32::NAN);
    assert!((est.gain_prior().1 - UNKNOWN_GAIN_SD).abs() < 1e-6);
    est.set_gain_prior(0.9, 0.02);
    est.reset_gain();
    assert_eq!(est.gain_prior(), (1.0, UNKNOWN_GAIN_SD));
    // The unknown prior's hypotheses span 0.63 … 1.58.
    let h = est.gain_hypotheses();
    assert!(
        (h[0] - 0.632).abs() < 0.005 && (h[GAINS - 1] - 1.582).abs() < 0.01,
        "{h:?}"
    );
}

#[test]
fn the_temperature_model_compensates_the_gain() {
    // −0.6 %/K: at −25 °C the optics give exp(0.3) = 1.35 × the light of 25 °C.
    let mut cold = Estimator::default();
    cold.set_gain_prior(1.0, 0.01);
    cold.set_temperature_model(-6_000, 1_000);
    cold.set_optics_temp_c(Some(-25.0));
    assert!((cold.compensation() - 0.3f32.exp()).abs() < 1e-4);
    let mut warm = Estimator::default();
    warm.set_gain_prior(1.0, 0.01);
    warm.set_optics_temp_c(Some(GAIN_REF_TEMP_C));
    assert_eq!(warm.compensation(), 1.0);
    let x = mean_at(&table::RIME, 5.0);
    let c = cold.compensation();
    for _ in 0..600 {
        cold.step(0.1, Some(x.map(|v| v * c)), Some(-8.0));
        warm.step(0.1, Some(x), Some(-8.0));
    }
    let (pc, pw) = (cold.posterior().unwrap(), warm.posterior().unwrap());
    assert!(
        (pc.thickness_mm - pw.thickness_mm).abs() < 0.02,
        "{pc:?} {pw:?}"
    );
    assert!((pc.thickness_mm - 5.0).abs() < 0.5, "{pc:?}");
    // The reported gain is the one at the optics' temperature now.
    let g = cold.gain().unwrap();
    assert!((g.gain / c - 1.0).abs() < 0.02, "{g:?}");
    // An absurd coefficient is clamped to ±5 %/K; a missing temperature
    // keeps the last one.
    cold.set_temperature_model(i32::MIN, u32::MAX);
    cold.set_optics_temp_c(None);
    assert!((cold.compensation() - 2.5f32.exp()).abs() < 0.01);
    cold.set_optics_temp_c(Some(f32::NAN));
    assert!(cold.compensation().is_finite());
}

#[test]
fn a_gain_beyond_the_hypotheses_is_followed() {
    // Half the light (a face badly fouled, an LED failing): beyond the
    // unknown prior's hypotheses (0.63 … 1.58) and the plausible band (the
    // node raises GAIN_OUT_OF_BAND). On thick rime the bank moves out to
    // it; on the way, before it has, a few per cent of the seconds read
    // thin with confidence (outside the band that is not promised).
    let mut est = Estimator::default();
    est.set_dry();
    let mut thin = 0;
    grow_rime(&mut est, 0.5, 10.0, |d, est| {
        let p = est.posterior().expect("an estimate");
        if d >= 4.0 && p.thickness_mm + 2.0 * p.sigma_mm < d / 2.0 {
            thin += 1;
        }
    });
    // 4320 s from 4 mm to 10 mm.
    assert!(thin < 130, "{thin} s confidently thin");
    let g = est.gain().unwrap();
    assert!(
        (g.gain / 0.5).ln().abs() < 0.1,
        "{g:?} prior {:?} weights {:?} {:?}",
        est.gain_prior(),
        est.gain_weights(),
        est.posterior()
    );
    assert!(
        est.gain_hypotheses()[0] < 0.5,
        "{:?}",
        est.gain_hypotheses()
    );
    let p = est.posterior().unwrap();
    assert!((p.thickness_mm - 10.0).abs() <= 2.0 * p.sigma_mm, "{p:?}");
}
