//! The ice estimator's behaviour on the table's own mean curves and on bad
//! input: what it says on a dry face, on rime, on water at +5 °C, after a
//! shed, with a failed NTC, across gaps, invalid frames and outliers, and
//! that no input makes it panic or report nonsense; and its optical gain:
//! learned where the currents tell it, honest where they do not, set from a
//! calibration, compensated for temperature.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use fois_firmware::estimator::{
    Estimator, EstimatorParams, Posterior, ROWS, STEP_MM, TableEntry, Update, table,
};
use fois_protocol::Medium;
use proptest::prelude::*;

/// The table's mean currents of row `i`, µA.
fn mean_ua(t: &[TableEntry; ROWS], i: usize) -> [f32; 2] {
    [
        f32::from(t[i].mu_na[0]) * 1e-3,
        f32::from(t[i].mu_na[1]) * 1e-3,
    ]
}

/// Row of thickness `d` mm.
fn row(d: f32) -> usize {
    ((d / STEP_MM).round() as usize).clamp(1, ROWS) - 1
}

/// An estimator whose gain was calibrated (1 ± 1 %): the table's physics
/// without the gain's ambiguity.
fn calibrated() -> Estimator {
    let mut est = Estimator::default();
    est.set_gain_prior(1.0, 0.01);
    est
}

/// `n` frames at 10 Hz of the same currents and temperature.
fn hold(est: &mut Estimator, n: usize, x: Option<[f32; 2]>, t: Option<f32>) -> Posterior {
    for _ in 0..n {
        est.step(0.1, x, t);
    }
    est.posterior().expect("an estimate")
}

#[test]
fn no_estimate_until_a_valid_frame_and_bad_currents_are_not_measurements() {
    let mut est = Estimator::default();
    for x in [
        None,
        Some([f32::NAN, 1.0]),
        Some([1.0, f32::INFINITY]),
        Some([f32::NEG_INFINITY, 0.0]),
        Some([2.0e4, 0.0]), // beyond any front end
    ] {
        assert_eq!(est.step(0.1, x, Some(-5.0)), None, "{x:?}");
        assert_eq!(est.last_update(), Update::Waiting);
    }
    // A frame that fits no state (−40 µA: a baseline taken with ice on the
    // face) does not start the filter either.
    assert_eq!(est.step(0.1, Some([-40.0, -40.0]), Some(-5.0)), None);
    assert_eq!(est.last_update(), Update::Waiting);
    let e = est
        .step(0.1, Some([0.0, 0.0]), Some(-5.0))
        .expect("estimate");
    assert_eq!(est.last_update(), Update::Initialised);
    assert_eq!(e.medium, Medium::Dry);
}

#[test]
fn a_dry_face_is_dry() {
    let mut est = Estimator::default();
    for t in [-10.0, 0.0, 5.0] {
        // From boot: dry, but thick clear ice (it reads ~0.3 µA at 15 mm)
        // keeps a few per cent in the cold.
        est.reset();
        let p = hold(&mut est, 300, Some([0.03, -0.02]), Some(t));
        assert_eq!(p.medium().0, Medium::Dry, "{t} °C: {p:?}");
        assert!(p.p_medium[0] > 0.95, "{t} °C: {p:?}");
        // After a dark calibration (the face is known clean): dry, 0 mm.
        est.set_dry();
        let p = hold(&mut est, 3000, Some([0.03, -0.02]), Some(t));
        assert_eq!(p.medium().0, Medium::Dry, "{t} °C: {p:?}");
        assert!(p.p_medium[0] > 0.99, "{t} °C: {p:?}");
        assert!(p.thickness_mm < 0.01 && p.sigma_mm < 0.05, "{t} °C: {p:?}");
    }
}

/// The table's mean currents at `d` mm (linear between rows), µA.
fn mean_at(t: &[TableEntry; ROWS], d: f32) -> [f32; 2] {
    let f = (d / STEP_MM - 1.0).clamp(0.0, (ROWS - 1) as f32);
    let (i, w) = (f as usize, f.fract());
    let (a, b) = (mean_ua(t, i), mean_ua(t, (i + 1).min(ROWS - 1)));
    if d < STEP_MM {
        return [a[0] * d / STEP_MM, a[1] * d / STEP_MM];
    }
    [a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1])]
}

/// A calibrated node's dry face, then `kind`'s mean curve growing at 5 mm/h up to `d`, then
/// one more minute at `d`; 10 Hz frames at `t` °C.
fn grow(t_c: f32, curve: &[TableEntry; ROWS], d: f32) -> Estimator {
    let mut est = calibrated();
    est.set_dry();
    let frames = (d / 5.0 * 36_000.0) as usize;
    for n in 0..frames {
        let dn = d * n as f32 / frames as f32;
        est.step(0.1, Some(mean_at(curve, dn)), Some(t_c));
    }
    hold(&mut est, 600, Some(mean_at(curve, d)), Some(t_c));
    est
}

#[test]
fn rime_on_its_mean_curve_is_rime_at_its_thickness() {
    // At 2 mm the mean reading sits amid the widest spread of rime and of
    // glaze (the tilted surface still reflects): rime is only the more
    // likely. Its mean currents are also those of 10 mm (29.2/11.8 against
    // 29.2/11.2 µA): only the history tells them apart, and the gain
    // hypotheses a few per cent above 1 lose it — σ is wide and says so.
    // From 5 mm rime is certain and σ is about the Cramér–Rao bound (0.27,
    // 0.63 mm) widened by the gain uncertainty.
    for (d, min_p, max_sigma) in [(2.0, 0.5, 4.5), (5.0, 0.9, 0.8), (10.0, 0.9, 1.6)] {
        let est = grow(-8.0, &table::RIME, d);
        let p = est.posterior().expect("estimate");
        let (m, prob) = p.medium();
        assert_eq!(m, Medium::Rime, "{d} mm: {p:?}");
        assert!(prob > min_p, "{d} mm: {p:?}");
        let err = p.thickness_mm - d;
        assert!(err.abs() <= 2.0 * p.sigma_mm, "{d} mm: {p:?}");
        assert!(p.sigma_mm < max_sigma, "{d} mm: {p:?}");
    }
}

#[test]
fn water_at_plus_5_c_is_never_ice_and_cold_glaze_is_not_water() {
    // A film growing to 3 mm at +5 °C, on the water curve and on the glazed
    // curve (the optics of the two are alike, thesis §5.2.3).
    for (name, t) in [("water", &table::WATER), ("glazed", &table::GLAZED)] {
        let mut est = Estimator::default();
        est.set_dry();
        for i in 0..row(3.0) {
            for _ in 0..300 {
                let e = est
                    .step(0.1, Some(mean_ua(t, i)), Some(5.0))
                    .expect("estimate");
                assert!(
                    !matches!(e.medium, Medium::Glazed | Medium::Rime),
                    "{name} at {:.1} mm, +5 °C: {e:?}",
                    (i + 1) as f32 * STEP_MM
                );
            }
        }
    }
    // The same optics at −5 °C: ice, not water.
    let est = grow(-5.0, &table::WATER, 1.0);
    let p = est.posterior().expect("estimate");
    assert!(
        matches!(p.medium().0, Medium::Glazed | Medium::Rime),
        "{p:?}"
    );
    assert!(p.p_medium[1] < 0.01, "{p:?}");
}

#[test]
fn a_failed_ntc_gives_no_temperature_evidence() {
    // Water optics at 1 mm: with +5 °C water is certain; with no NTC the
    // optics still favour water, but glaze (same optics) keeps a share.
    let x = Some(mean_ua(&table::WATER, row(1.0)));
    let mut warm = Estimator::default();
    let warm = hold(&mut warm, 600, x, Some(5.0));
    let mut blind = Estimator::default();
    let blind = hold(&mut blind, 600, x, None);
    assert_eq!(warm.medium().0, Medium::Water);
    assert!(warm.p_medium[2] + warm.p_medium[3] < 1e-3, "{warm:?}");
    // Without a temperature, water and glaze (alike optically) share.
    assert!(
        blind.p_medium[1] < 0.9 * warm.p_medium[1],
        "{blind:?} vs {warm:?}"
    );
    assert!(blind.p_medium[2] + blind.p_medium[3] > 0.1, "{blind:?}");
}

#[test]
fn a_shed_layer_reads_dry_within_seconds() {
    let mut est = Estimator::default();
    hold(&mut est, 300, Some([0.0, 0.0]), Some(-8.0));
    let iced = hold(
        &mut est,
        6000,
        Some(mean_ua(&table::RIME, row(5.0))),
        Some(-8.0),
    );
    assert_eq!(iced.medium().0, Medium::Rime);
    // The layer falls off: the face reads ~0 again.
    let mut frames = 0;
    while est
        .step(0.1, Some([0.02, 0.01]), Some(-8.0))
        .is_some_and(|e| e.medium != Medium::Dry || e.probability_permille < 950)
    {
        frames += 1;
        assert!(frames < 600, "not dry after 60 s: {:?}", est.posterior());
    }
    let p = est.posterior().expect("estimate");
    assert!(p.thickness_mm < 0.3, "{p:?}");
    println!("dry again after {frames} frames at 10 Hz");
}

#[test]
fn a_node_reset_with_ice_on_the_face_has_an_estimate_at_once() {
    // With its gain known (kept in the flash store across the reset).
    let mut est = calibrated();
    let e = est
        .step(0.0, Some(mean_ua(&table::RIME, row(5.0))), Some(-8.0))
        .expect("estimate");
    assert_eq!(est.last_update(), Update::Initialised);
    assert_eq!(e.medium, Medium::Rime);
    assert!((i32::from(e.thickness_um) - 5_000).abs() < 1_000, "{e:?}");
}

#[test]
fn invalid_frames_predict_and_widen_the_estimate() {
    let mut est = calibrated();
    let before = hold(
        &mut est,
        600,
        Some(mean_ua(&table::RIME, row(5.0))),
        Some(-8.0),
    );
    // 10 minutes of saturated frames: no currents.
    let after = hold(&mut est, 6000, None, Some(-8.0));
    assert_eq!(est.last_update(), Update::NoCurrents);
    assert!(
        after.sigma_mm > 2.0 * before.sigma_mm,
        "{before:?} → {after:?}"
    );
    assert!(after.sigma_mm.is_finite());
    // And the currents come back: the estimate settles again.
    let again = hold(
        &mut est,
        600,
        Some(mean_ua(&table::RIME, row(5.0))),
        Some(-8.0),
    );
    assert!((again.thickness_mm - 5.0).abs() < 0.5, "{again:?}");
    assert!(again.sigma_mm < 1.5 * before.sigma_mm, "{again:?}");
}

#[test]
fn an_outlier_is_skipped_and_leaves_the_estimate_alone() {
    let mut est = calibrated();
    let x = Some(mean_ua(&table::RIME, row(5.0)));
    let before = hold(&mut est, 600, x, Some(-8.0));
    // One spike among two seconds' frames: the robust mean drops it.
    for n in 0..20 {
        let spike = (n == 14).then_some([-30.0, 45.0]);
        est.step(0.1, spike.or(x), Some(-8.0));
    }
    assert_eq!(est.last_update(), Update::Measured);
    let after = est.posterior().expect("estimate");
    assert!(
        (after.thickness_mm - before.thickness_mm).abs() < 0.01,
        "{after:?}"
    );
    // Two whole seconds of currents no state explains: skipped.
    for _ in 0..20 {
        est.step(0.1, Some([-30.0, 45.0]), Some(-8.0));
    }
    assert_eq!(est.last_update(), Update::Outlier);
    let after = est.posterior().expect("estimate");
    assert_eq!(after.medium().0, Medium::Rime);
    assert!(
        (after.thickness_mm - before.thickness_mm).abs() < 0.1,
        "{after:?}"
    );
}

#[test]
fn currents_out_of_reach_bring_their_states_back() {
    // Rime at 5 mm, then suddenly the currents of rime at 12 mm (no
    // transition reaches that in 0.1 s): the filter follows within minutes.
    let mut est = Estimator::default();
    hold(
        &mut est,
        600,
        Some(mean_ua(&table::RIME, row(5.0))),
        Some(-8.0),
    );
    let p = hold(
        &mut est,
        3000,
        Some(mean_ua(&table::RIME, row(12.0))),
        Some(-8.0),
    );
    assert_eq!(p.medium().0, Medium::Rime);
    assert!((p.thickness_mm - 12.0).abs() < 2.0 * p.sigma_mm, "{p:?}");
}

#[test]
fn long_zero_and_nonsense_frame_periods() {
    let mut est = Estimator::default();
    let x = Some(mean_ua(&table::RIME, row(5.0)));
    for dt in [0.0, 600.0, 1e9, -5.0, f32::NAN, f32::INFINITY, 0.02] {
        let e = est.step(dt, x, Some(-8.0)).expect("estimate");
        assert!(e.probability_permille <= 1000);
        let p = est.posterior().expect("posterior");
        assert!(
            p.thickness_mm.is_finite() && p.sigma_mm.is_finite(),
            "{dt}: {p:?}"
        );
    }
}

#[test]
fn settings_out_of_range_take_their_defaults() {
    let bad = EstimatorParams {
        forget_time_s: f32::NAN,
        max_growth_mm_per_h: -1.0,
        noise_ua: [0.0, f32::INFINITY],
        gain_sd: 7.0,
        temp_scale_c: 0.0,
        ..EstimatorParams::default()
    };
    let d = EstimatorParams::default();
    let s = bad.sanitized();
    assert_eq!(s.forget_time_s, d.forget_time_s);
    assert_eq!(s.max_growth_mm_per_h, d.max_growth_mm_per_h);
    assert_eq!(s.noise_ua, d.noise_ua);
    assert_eq!(s.gain_sd, d.gain_sd);
    assert_eq!(s.temp_scale_c, d.temp_scale_c);
    let est = Estimator::new(bad);
    assert_eq!(*est.params(), s);
}

#[test]
fn estimates_saturate_and_permille_is_bounded() {
    let p = Posterior {
        thickness_mm: 99.0,
        sigma_mm: f32::NAN,
        p_medium: [0.0, 0.0, 0.0, 1.2],
    };
    let e = p.ice_estimate();
    assert_eq!(e.thickness_um, 65_535);
    assert_eq!(e.sigma_um, 0);
    assert_eq!(e.medium, Medium::Rime);
    assert_eq!(e.probability_permille, 1000);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Any sequence of frames — NaN, ±∞, huge, negative currents and
    /// temperatures, odd frame periods — never panics, and every estimate is
    /// a probability distribution with a finite mean and σ.
    #[test]
    fn no_input_breaks_the_estimator(
        frames in proptest::collection::vec(
            (
                prop_oneof![Just(0.1f32), Just(0.0), Just(-1.0), Just(f32::NAN), 0.0f32..10_000.0],
                proptest::option::of((
                    prop_oneof![Just(f32::NAN), Just(f32::INFINITY), -100.0f32..100.0, 0.0f32..40.0],
                    prop_oneof![Just(f32::NEG_INFINITY), -100.0f32..100.0, 0.0f32..20.0],
                )),
                proptest::option::of(prop_oneof![Just(f32::NAN), -60.0f32..60.0]),
            ),
            1..40,
        )
    ) {
        let mut est = Estimator::default();
        for (dt, x, t) in frames {
            let e = est.step(dt, x.map(|(a, b)| [a, b]), t);
            if let Some(e) = e {
                prop_assert!(e.probability_permille <= 1000);
                let p = est.posterior().expect("posterior with an estimate");
                let sum: f32 = p.p_medium.iter().sum();
                prop_assert!((sum - 1.0).abs() < 1e-3, "{:?}", p);
                prop_assert!(p.p_medium.iter().all(|q| (0.0..=1.0001).contains(q)));
                prop_assert!(p.thickness_mm.is_finite() && p.thickness_mm >= 0.0 && p.thickness_mm <= 15.1);
                prop_assert!(p.sigma_mm.is_finite() && p.sigma_mm >= 0.0);
            }
        }
    }
}
