//! Accuracy of the ice estimator on ray-traced accretions (seeds the response
//! table does not use): `cargo run --release -p fois-firmware --example estimator_eval`
//! (`EST_PRIOR_SD=0.02`: a node whose gain is calibrated to 1 ± 2 %).
// An evaluation tool sharing the accuracy test's harness: a missing estimate
// there is a failed evaluation, as in the tests.
#![allow(clippy::unwrap_used, clippy::expect_used)]
#[path = "../tests/estimator_eval/mod.rs"]
mod eval;

use eval::*;
use fois_firmware::estimator::EstimatorParams;
use fois_sim::IceKind;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("trace") {
        return trace(&args);
    }
    if args.get(1).map(String::as_str) == Some("trace-freeze") {
        let seed = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(101);
        let mut run = freeze_run(seed);
        run.frame_s = 1.0;
        for f in simulate(&run, params_from_env()).iter().step_by(120) {
            if let Some(e) = f.est {
                println!(
                    "t {:6.0} {:?} d {:5.2} T {:5.1} x ({:6.2},{:6.2}) est {:5.2} ± {:5.2} p {:.3} {:.3} {:.3} {:.3}",
                    f.t_s,
                    f.medium,
                    f.thickness_mm,
                    f.temp_c,
                    f.currents_ua[0],
                    f.currents_ua[1],
                    e.thickness_mm,
                    e.sigma_mm,
                    e.p_medium[0],
                    e.p_medium[1],
                    e.p_medium[2],
                    e.p_medium[3]
                );
            }
        }
        return;
    }
    let seeds: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(8);
    let frame_s: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0.1);
    let params = params_from_env();
    let crlb = rime_crlb(256, 4242);
    let classes: Vec<(&str, IceKind, f64, f64, f64)> = vec![
        ("rime 0.5 mm/h, -8 °C", IceKind::Rime, 0.5, -8.0, 1.0),
        ("rime 2 mm/h, -8 °C", IceKind::Rime, 2.0, -8.0, 1.0),
        ("rime 10 mm/h, -8 °C", IceKind::Rime, 10.0, -8.0, 1.0),
        ("glazed 2 mm/h, -5 °C", IceKind::Glazed, 2.0, -5.0, 1.0),
        ("glazed 10 mm/h, -5 °C", IceKind::Glazed, 10.0, -5.0, 1.0),
        ("water 2 mm/h, +5 °C", IceKind::Water, 2.0, 5.0, 1.0),
        (
            "rime 2 mm/h, -8 °C, LED -30 %",
            IceKind::Rime,
            2.0,
            -8.0,
            0.7,
        ),
    ];
    for (name, kind, rate, temp, led) in classes {
        let mut st = Stats::new();
        let t0 = std::time::Instant::now();
        for s in 0..seeds {
            let seed = 101 + s;
            let max = if kind == IceKind::Water { 3.0 } else { 11.0 };
            let mut run = Run::new(
                seed,
                vec![
                    Segment::dry(60.0, temp),
                    Segment::grow(kind, 0.0, max, rate, temp),
                ],
            );
            run.led = led;
            run.frame_s = frame_s;
            run.gain_prior = gain_prior_from_env();
            let frames = simulate(&run, params);
            st.add(&frames, 0.05);
        }
        println!(
            "== {name}: {seeds} seeds, {:.1} s",
            t0.elapsed().as_secs_f64()
        );
        for d in TARGETS_MM {
            if let Some((bias, rms, sig, n)) = st.at(d) {
                println!(
                    "  {d:5.1} mm: bias {bias:+.3} rms {rms:.3} mean σ {sig:.3} (n {n})  √CRLB {:.3}",
                    crlb_at(&crlb, d)
                );
            }
        }
        println!(
            "  |err| ≤ 2σ beyond 0.5 mm: {:.1} %   medium right ≥ 1 mm: {:.1} %   water called ice: {}/{}",
            100.0 * st.calibration(),
            100.0 * st.medium_accuracy(),
            st.water_called_ice,
            st.water_frames
        );
    }
}

/// `trace KIND RATE TEMP SEED [LED]`: one run, every 60 s of virtual time.
#[allow(dead_code)]
pub fn trace(args: &[String]) {
    let kind = match args.get(2).map_or("rime", String::as_str) {
        "rime" => IceKind::Rime,
        "glazed" => IceKind::Glazed,
        _ => IceKind::Water,
    };
    let rate: f64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(2.0);
    let temp: f64 = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(-8.0);
    let seed: u64 = args.get(5).and_then(|s| s.parse().ok()).unwrap_or(101);
    let led: f64 = args.get(6).and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let max = if kind == IceKind::Water { 3.0 } else { 11.0 };
    let mut run = Run::new(
        seed,
        vec![
            Segment::dry(60.0, temp),
            Segment::grow(kind, 0.0, max, rate, temp),
        ],
    );
    run.led = led;
    run.frame_s = 1.0;
    let frames = simulate(&run, params_from_env());
    for f in frames.iter().step_by(60) {
        if let Some(e) = f.est {
            println!(
                "t {:6.0} d {:6.2} x ({:6.2},{:6.2}) est {:6.2} ± {:5.2}  p dry {:.3} water {:.3} glazed {:.3} rime {:.3}",
                f.t_s,
                f.thickness_mm,
                f.currents_ua[0],
                f.currents_ua[1],
                e.thickness_mm,
                e.sigma_mm,
                e.p_medium[0],
                e.p_medium[1],
                e.p_medium[2],
                e.p_medium[3]
            );
        }
    }
}

/// Defaults, with overrides from `EST_GAIN`, `EST_NOISE`, `EST_TAU`, `EST_GROWTH` (tuning).
/// `EST_PRIOR_SD=S`: the node's gain calibrated to 1 ± S (unset: unknown).
fn gain_prior_from_env() -> Option<(f32, f32)> {
    let sd = std::env::var("EST_PRIOR_SD").ok()?.parse::<f32>().ok()?;
    Some((1.0, sd))
}

fn params_from_env() -> EstimatorParams {
    let mut p = EstimatorParams::default();
    let get = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f32>().ok());
    if let Some(v) = get("EST_GAIN") {
        p.gain_sd = v;
    }
    if let Some(v) = get("EST_NOISE") {
        p.noise_ua = [v, v];
    }
    if let Some(v) = get("EST_TAU") {
        p.forget_time_s = v;
    }
    if let Some(v) = get("EST_GROWTH") {
        p.max_growth_mm_per_h = v;
    }
    p
}
