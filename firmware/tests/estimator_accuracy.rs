//! Accuracy of the ice estimator on ray-traced accretions the response table
//! was not built from (run 0 of seeds 101–106; the table uses seed 900 001),
//! with frame noise and a persistent offset per run. The goals of the ice
//! characterisation that the estimator meets are asserted here; the figures
//! of every class, met or not, are printed
//! (`cargo test -p fois-firmware --test estimator_accuracy -- --nocapture`)
//! and the larger sweep is `examples/estimator_eval.rs`.
//!
//! The node's gain is calibrated here (1 ± 1 %: the table's physics); the
//! last test runs it with the gain unknown (the bank of gain hypotheses),
//! and `examples/gain_eval.rs` sweeps gains, drifts and priors.
//!
//! Frames come at 1 Hz here (10 Hz in the example): the errors that matter
//! persist for a whole accretion, so the frame rate barely changes the
//! figures, and the test stays fast.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "estimator_eval/mod.rs"]
mod estimator_eval;

use estimator_eval::*;
use fois_firmware::estimator::{EstimatorParams, IcingState};
use fois_sim::IceKind;

const SEEDS: std::ops::RangeInclusive<u64> = 101..=106;

/// √CRLB of rime from 128 accretions of seed 4242 (computed once).
fn crlb() -> &'static [(f64, f64)] {
    static CRLB: std::sync::OnceLock<Vec<(f64, f64)>> = std::sync::OnceLock::new();
    CRLB.get_or_init(|| rime_crlb(128, 4242))
}

/// A calibrated node's gain prior.
const CALIBRATED: Option<(f32, f32)> = Some((1.0, 0.01));

fn class(kind: IceKind, rate: f64, temp_c: f64, max_mm: f64) -> Stats {
    class_with(kind, rate, temp_c, max_mm, 1.0, CALIBRATED)
}

fn class_with(
    kind: IceKind,
    rate: f64,
    temp_c: f64,
    max_mm: f64,
    gain: f64,
    prior: Option<(f32, f32)>,
) -> Stats {
    let mut st = Stats::new();
    for seed in SEEDS {
        let mut run = Run::new(
            seed,
            vec![
                Segment::dry(120.0, temp_c),
                Segment::grow(kind, 0.0, max_mm, rate, temp_c),
            ],
        );
        run.frame_s = 1.0;
        run.led = gain;
        run.gain_prior = prior;
        st.add(&simulate(&run, EstimatorParams::default()), 0.05);
    }
    st
}

fn print(name: &str, st: &Stats, crlb: &[(f64, f64)]) {
    println!("{name}:");
    for d in TARGETS_MM {
        if let Some((bias, rms, sig, n)) = st.at(d) {
            println!(
                "  {d:4.1} mm  bias {bias:+.3}  rms {rms:.3}  mean σ {sig:.3}  √CRLB {:.3}  ({n} runs)",
                crlb_at(crlb, d)
            );
        }
    }
    println!(
        "  |error| ≤ 2σ beyond 0.5 mm: {:.1} % of {} frames; medium right from 1 mm: {:.1} % of {}",
        100.0 * st.calibration(),
        st.calib.0,
        100.0 * st.medium_accuracy(),
        st.medium.0
    );
}

#[test]
fn rime_thickness_meets_the_goal_at_5_mm_and_its_sigma_is_honest() {
    let crlb = crlb();
    let st = class(IceKind::Rime, 2.0, -8.0, 11.0);
    print("rime, 2 mm/h, -8 °C", &st, crlb);
    // Goal: RMS ≤ 1.5 √CRLB and |bias| ≤ 0.3 mm for 2–10 mm. Met at 5 mm;
    // missed at 2 mm, and at 10 mm over the 10-seed sweep of the example
    // (these six seeds happen to pass there), see firmware/README.md.
    let (bias, rms, _, n) = st.at(5.0).expect("frames at 5 mm");
    assert_eq!(n, 6);
    let bound = 1.5 * crlb_at(crlb, 5.0);
    assert!(rms <= bound, "5 mm: rms {rms:.3} > 1.5 √CRLB {bound:.3}");
    assert!(bias.abs() <= 0.3, "5 mm: bias {bias:+.3}");
    // Goal: |error| ≤ 2σ in ≥ 90 % of the frames beyond 0.5 mm.
    assert!(st.calibration() >= 0.90, "calibration {}", st.calibration());
    // Goal 95 % (missed); this guards the figure the README states.
    assert!(
        st.medium_accuracy() >= 0.90,
        "medium {}",
        st.medium_accuracy()
    );
}

#[test]
fn glazed_sigma_is_honest() {
    let crlb = crlb();
    let st = class(IceKind::Glazed, 2.0, -5.0, 11.0);
    print("glazed, 2 mm/h, -5 °C (thickness: report only)", &st, crlb);
    assert!(st.calibration() >= 0.90, "calibration {}", st.calibration());
    // Goal 95 % (missed); this guards the figure the README states.
    assert!(
        st.medium_accuracy() >= 0.85,
        "medium {}",
        st.medium_accuracy()
    );
}

#[test]
fn water_at_plus_5_c_is_never_ice_and_water_that_freezes_becomes_glaze() {
    let crlb = crlb();
    let st = class(IceKind::Water, 2.0, 5.0, 3.0);
    print("water, 2 mm/h, +5 °C", &st, crlb);
    assert!(st.water_frames > 30_000);
    assert_eq!(st.water_called_ice, 0, "water at +5 °C called ice");
    assert!(
        st.medium_accuracy() >= 0.95,
        "medium {}",
        st.medium_accuracy()
    );
    assert!(st.calibration() >= 0.90, "calibration {}", st.calibration());

    // The scenario of the hardware-in-loop suite: 0.3 mm of water at +5 °C,
    // the air cools to 0 °C, the film freezes and glaze grows on it while
    // the air falls to −5 °C.
    let mut st = Stats::new();
    // Frames of the frozen film below −1 °C: (all, called ice, called glaze).
    let mut frozen = (0u64, 0u64, 0u64);
    for seed in SEEDS {
        let mut run = freeze_run(seed);
        run.frame_s = 1.0;
        run.gain_prior = CALIBRATED;
        let frames = simulate(&run, EstimatorParams::default());
        for f in &frames {
            let Some(e) = f.est else { continue };
            if f.medium == fois_protocol::Medium::Glazed && f.temp_c <= -1.0 {
                frozen.0 += 1;
                match e.medium().0 {
                    fois_protocol::Medium::Glazed => {
                        frozen.1 += 1;
                        frozen.2 += 1;
                    }
                    fois_protocol::Medium::Rime => frozen.1 += 1,
                    _ => {}
                }
            }
        }
        st.add(&frames, 0.05);
    }
    let ice = frozen.1 as f64 / frozen.0.max(1) as f64;
    let glaze = frozen.2 as f64 / frozen.0.max(1) as f64;
    println!(
        "water that freezes: water frames called ice {} of {}; the frozen film (0.3–1.3 mm) below −1 °C called ice {:.1} %, glaze {:.1} % of {} frames",
        st.water_called_ice,
        st.water_frames,
        100.0 * ice,
        100.0 * glaze,
        frozen.0
    );
    assert_eq!(
        st.water_called_ice, 0,
        "the film called ice while still water"
    );
    // Ice, not water, once the air is below −1 °C (where the water factor
    // is ½ and falls): 97.5 % with these seeds. Glaze or rime: a film under
    // 1.3 mm is too thin to tell (the glaze share is only reported).
    assert!(ice >= 0.95, "frozen film called ice in {ice:.3}");
}

#[test]
fn with_the_gain_unknown_sigma_stays_honest() {
    // The gain the node is not told: 15 % more light than the table's, a
    // new node (unknown prior). Rime's currents at 5 mm are those of 10 mm
    // at 0.86× the gain; σ must say so, never "thin" with confidence.
    let crlb = crlb();
    for (kind, temp) in [(IceKind::Rime, -8.0), (IceKind::Glazed, -5.0)] {
        let st = class_with(kind, 2.0, temp, 11.0, 1.15, None);
        print(&format!("{kind:?}, 2 mm/h, gain 1.15 unknown"), &st, crlb);
        assert!(
            st.calibration() >= 0.95,
            "{kind:?}: calibration {}",
            st.calibration()
        );
        if kind == IceKind::Rime {
            let (_, rms, _, _) = st.at(10.0).expect("frames at 10 mm");
            assert!(rms <= 1.5, "10 mm: rms {rms:.3}");
            let (_, rms, _, _) = st.at(2.0).expect("frames at 2 mm");
            assert!(rms <= 1.0, "2 mm: rms {rms:.3}");
        }
    }
}

#[test]
fn the_icing_rate_is_honest_and_the_icing_period_starts_with_the_growth() {
    // Rime at 2 mm/h from a dry face, a gain of 1.08 the node is not told,
    // 1 Hz: one hour into the growth the rate's truth lies within 2σ and
    // the icing period is on; it started within 15 min of the growth.
    for seed in 101..=103u64 {
        let mut run = Run::new(
            seed,
            vec![
                Segment::dry(60.0, -8.0),
                Segment::grow(IceKind::Rime, 0.0, 2.5, 2.0, -8.0),
            ],
        );
        run.frame_s = 1.0;
        run.led = 1.08;
        let frames = simulate(&run, EstimatorParams::default());
        let on = frames
            .iter()
            .find(|f| f.accreting)
            .map(|f| f.t_s - 60.0)
            .expect("the icing period starts");
        assert!(on <= 900.0, "seed {seed}: the period started after {on} s");
        let f = frames
            .iter()
            .find(|f| f.t_s >= 60.0 + 3600.0)
            .expect("an hour of growth");
        let r = f.est_rate.expect("a rate");
        let (est, sd) = (f64::from(r.mean_mm_per_h), f64::from(r.sigma_mm_per_h));
        println!("seed {seed}: period on after {on:.0} s; rate at 60 min {est:.2} ± {sd:.2} mm/h");
        assert!((est - 2.0).abs() <= 2.0 * sd, "seed {seed}: {est} ± {sd}");
        assert!(sd < 2.0, "seed {seed}: σ {sd} is the prior's");
        assert!(f.accreting, "seed {seed}: not accreting after an hour");
    }
    // A water film at +5 °C is never an icing period.
    let mut run = Run::new(
        101,
        vec![
            Segment::dry(60.0, 5.0),
            Segment::grow(IceKind::Water, 0.0, 1.0, 2.0, 5.0),
        ],
    );
    run.frame_s = 1.0;
    let frames = simulate(&run, EstimatorParams::default());
    assert!(
        frames.iter().all(|f| !f.accreting),
        "water at +5 °C called icing"
    );
}

#[test]
fn the_icing_period_ends_within_20_min_of_the_growth_stopping() {
    // Rime and glazed at 2 and 10 mm/h grow from a dry face to 3 mm (a
    // gain of 1.08 the node is not told, 1 Hz), then the ice stays: the
    // icing period starts within 10 min of the growth and ends within
    // 20 min of its end, to "not accreting" (P(accreting) ≤ 0.3; where the
    // currents still move with the thickness, the change looks tell). Rime
    // that stops at 11 mm (0.25 µA/mm: the slow rates' hypotheses move the
    // currents by less than the noise of one window) leaves the period
    // within 20 min too, to "uncertain" at least, never "accreting": no
    // window supports growth after the stop (16.6 min; 29.3 min when the
    // period waited for P(accreting) or for the node to lose its tell).
    for (kind, temp, rate, stop_mm) in [
        (IceKind::Rime, -8.0, 2.0, 3.0),
        (IceKind::Rime, -8.0, 10.0, 3.0),
        (IceKind::Glazed, -5.0, 2.0, 3.0),
        (IceKind::Glazed, -5.0, 10.0, 3.0),
        (IceKind::Rime, -8.0, 10.0, 11.0),
    ] {
        let seed = 104;
        let mut run = Run::new(
            seed,
            vec![
                Segment::dry(60.0, temp),
                Segment::grow(kind, 0.0, stop_mm, rate, temp),
                Segment::pause(kind, 1800.0, temp),
            ],
        );
        run.frame_s = 1.0;
        run.led = 1.08;
        let stop_s = 60.0 + stop_mm / rate * 3600.0;
        let frames = simulate(&run, EstimatorParams::default());
        let on = frames
            .iter()
            .find(|f| f.accreting)
            .map(|f| f.t_s - 60.0)
            .expect("the icing period starts");
        let cleared = |f: &&FrameRecord| {
            if stop_mm < 10.0 {
                f.icing == Some(IcingState::NotAccreting)
            } else {
                f.icing != Some(IcingState::Accreting)
            }
        };
        let off = frames
            .iter()
            .filter(|f| f.t_s >= stop_s)
            .find(cleared)
            .map(|f| f.t_s - stop_s);
        println!("{kind:?} {rate} mm/h to {stop_mm} mm: on after {on:.0} s, off after {off:?} s");
        assert!(on <= 600.0, "{kind:?} {rate} mm/h: on after {on} s");
        let off = off.expect("the period ends");
        assert!(off <= 1200.0, "{kind:?} {rate} mm/h: off after {off} s");
        // And it stays off while the ice stays.
        let late = frames.iter().filter(|f| f.t_s > stop_s + off);
        assert!(
            late.clone().all(|f| !f.accreting),
            "{kind:?} {rate} mm/h: the period came back"
        );
    }
}

#[test]
fn a_rate_beyond_the_history_s_grid_widens_sigma() {
    // 20 mm/h is beyond the growth history's 13 mm/h (out of model): the
    // history falls behind, the output falls back to the bank's: σ honest,
    // never confidently thin.
    let (mut n, mut ok, mut thin) = (0u64, 0u64, 0u64);
    for seed in 101..=103u64 {
        let mut run = Run::new(
            seed,
            vec![
                Segment::dry(60.0, -8.0),
                Segment::grow(IceKind::Rime, 0.0, 10.0, 20.0, -8.0),
            ],
        );
        run.frame_s = 1.0;
        run.gain_prior = CALIBRATED;
        for f in simulate(&run, EstimatorParams::default()) {
            let Some(e) = f.est else { continue };
            let (est, sd) = (f64::from(e.thickness_mm), f64::from(e.sigma_mm));
            if f.thickness_mm > 0.5 {
                n += 1;
                ok += u64::from((est - f.thickness_mm).abs() <= 2.0 * sd);
            }
            if confidently_thin(est, sd, f.thickness_mm) {
                thin += 1;
            }
        }
    }
    let share = ok as f64 / n as f64;
    println!(
        "20 mm/h: within 2σ {:.1} % of {n} frames, confidently thin {thin}",
        100.0 * share
    );
    assert_eq!(thin, 0);
    assert!(share >= 0.90, "within 2σ {share}");
}

#[test]
fn thick_clear_glaze_at_a_low_gain_stays_ice() {
    // Glaze at 10 mm/h to 11 mm on a face of gain 0.85 the node is not
    // told, then 40 min with the ice staying: beyond ~8 mm thick clear ice
    // returns ~0.3 µA, near a dry face's reading. The currents never fell
    // as a shed makes them fall, so the node keeps the ice: from 8 mm on it
    // names glaze in ≥ 95 % of the frames and is never confidently thin.
    // (Shed by the prior's 0.1/h alone, without the fall, the history took
    // the dry face in two of these four runs: glaze named in 9 816 of
    // 13 920 frames from 8 mm, 5 of 3 480 in seed 9302.)
    let (mut n, mut glazed, mut thin) = (0u64, 0u64, 0u64);
    for seed in 9301..=9304u64 {
        let mut run = Run::new(
            seed,
            vec![
                Segment::dry(60.0, -5.0),
                Segment::grow(IceKind::Glazed, 0.0, 11.0, 10.0, -5.0),
                Segment::pause(IceKind::Glazed, 2400.0, -5.0),
            ],
        );
        run.frame_s = 1.0;
        run.led = 0.85;
        let (mut ns, mut gs) = (0u64, 0u64);
        for f in simulate(&run, EstimatorParams::default())
            .iter()
            .filter(|f| f.thickness_mm >= 8.0)
        {
            let p = f.est.expect("an estimate");
            ns += 1;
            gs += u64::from(p.medium().0 == fois_protocol::Medium::Glazed);
            if confidently_thin(
                f64::from(p.thickness_mm),
                f64::from(p.sigma_mm),
                f.thickness_mm,
            ) {
                thin += 1;
            }
        }
        println!("seed {seed}: glazed named in {gs} of {ns} frames from 8 mm");
        n += ns;
        glazed += gs;
    }
    println!("glazed named in {glazed} of {n} frames from 8 mm, {thin} confidently thin");
    assert!(glazed as f64 >= 0.95 * n as f64, "{glazed} of {n}");
    assert_eq!(thin, 0);
}

#[test]
fn the_icing_period_comes_back_when_growth_resumes_on_thick_rime() {
    // Rime at 2 mm/h to 5 mm on a face of gain 0.92 the node is not told,
    // a 2 h pause, then growth again for an hour. With the gain unknown,
    // 5 mm of rime reads like 10 mm, where growth barely moves the
    // currents: the node could not tell a stop there within 20 min, but
    // P(accreting) rising from below the off threshold is the change
    // looks' own evidence, and the period comes back on it: within 9.3–
    // 13.3 min on these seeds (the goal is 10); waiting for the node to
    // tell, 9.3–21.4 min.
    for seed in 9311..=9314u64 {
        let mut run = Run::new(
            seed,
            vec![
                Segment::dry(60.0, -8.0),
                Segment::grow(IceKind::Rime, 0.0, 5.0, 2.0, -8.0),
                Segment::pause(IceKind::Rime, 7200.0, -8.0),
                Segment::grow(IceKind::Rime, 5.0, 7.0, 2.0, -8.0),
            ],
        );
        run.frame_s = 1.0;
        run.led = 0.92;
        let resume_s = 60.0 + 2.5 * 3600.0 + 7200.0;
        let frames = simulate(&run, EstimatorParams::default());
        let back = frames
            .iter()
            .filter(|f| f.t_s >= resume_s)
            .find(|f| f.accreting)
            .map(|f| (f.t_s - resume_s) / 60.0);
        println!("seed {seed}: the period back after {back:?} min");
        let back = back.expect("the period comes back");
        assert!(back <= 15.0, "seed {seed}: back after {back} min");
    }
}

#[test]
fn confidently_thin_is_the_goals_definition() {
    // 1.0 + 2·0.4 = 1.8 mm below half of 5 mm: thin with confidence.
    assert!(confidently_thin(1.0, 0.4, 5.0));
    // 1.0 + 2·0.8 = 2.6 mm reaches beyond half of 5 mm: honest.
    assert!(!confidently_thin(1.0, 0.8, 5.0));
    // Below 4 mm the goal does not count.
    assert!(!confidently_thin(0.0, 0.0, 3.9));
    assert!(confidently_thin(0.0, 0.0, 4.0));
}
