//! The estimator with an optical gain it is not told, on ray-traced
//! accretions (seeds the response table does not use):
//!
//! ```text
//! cargo run --release -p fois-firmware --example gain_eval -- [SEEDS] [FRAME_S] [FILTER]
//! ```
//!
//! One line per class (medium, rate, gain, prior; and the growth history's
//! scenarios: paused 2 h at 5 mm, a varying rate, a rate step, shed and
//! regrowth): frames with |err| ≤ 2σ beyond 0.5 mm, RMS error at 2, 5 and
//! 10 mm (while growing, before any shed), frames "confidently thin" (est +
//! 2σ < d/2 at d ≥ 4 mm), the medium right from 1 mm, the gain's RMS error
//! (ln) at 10 mm, the icing rate one hour into the growth (RMS of
//! ln(est/true), truth within 2σ), the icing flag's delays (on after the
//! growth starts, off after it stops), shed → dry. FILTER keeps only the
//! classes whose name contains it (ending in `$`: the one named so).
//! `SEED_BASE` sets the first seed (default 101). `EST_DESIGN=fixed` runs
//! every class with the gain taken as 1 ± 2 %, `EST_DESIGN=folded` with the
//! gain's uncertainty folded into each state's covariance;
//! `EST_HISTORY=off` without the growth history, `EST_HISTORY=nopause`
//! without its pause state; `EST_TRACE=1` prints every 300 s of each run
//! (`EST_TRACE_S` another period, s);
//! `EST_MEDIUM_BINS=1` adds the medium right in 1–2, 2–4 and ≥ 4 mm;
//! `EST_ODDS=1` prints the bank's ln odds of rime against glaze per 0.5 mm
//! of steady growth.
//! Settings: `EST_MEMORY` (gain memory, s), `EST_PERIOD` (update period,
//! s), `EST_SWITCH`, `EST_WITHIN`, and the history's `EST_LOOKS`
//! (looks per mm), `EST_EARLY`, `EST_LOOKS_PER_H`, `EST_WALK`,
//! `EST_HPERIOD`, `EST_GAMMA` (output weight), `EST_ESCAPE`, `EST_RESTART` (the
//! history's restart share per hour), the change
//! look's `EST_CWIN`, `EST_CNOISE`, `EST_CSLOPE`, `EST_CTEMPER` (0: the look as it
//! was first), `EST_RESUME`, `EST_TELL`; the shedding rates `EST_SHED` (the bank's) and
//! `EST_HSHED` (the history's).
// An evaluation tool sharing the accuracy test's harness: a missing estimate
// there is a failed evaluation, as in the tests.
#![allow(clippy::unwrap_used, clippy::expect_used)]
#[path = "../tests/estimator_eval/mod.rs"]
mod eval;

use eval::*;
use fois_firmware::estimator::{ACCRETING_OFF, EstimatorParams};
use fois_protocol::Medium;
use fois_sim::IceKind;

/// How a class's accretion grows.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Shape {
    /// From a dry face to 11 mm at the rate.
    Steady,
    /// To 5 mm, 2 h paused, on to 11 mm.
    Pause,
    /// ln r an Ornstein–Uhlenbeck process (sd 0.5, 1 h) around the rate.
    Varying,
    /// At the rate to 4 mm, then at 5× the rate to 11 mm.
    Step,
    /// To 6 mm, shed, 20 min dry, regrow to 8 mm.
    Shed,
    /// To this thickness, mm, then the ice stays (the icing flag's
    /// clearing per thickness).
    Stop(f64),
}

/// One class of runs.
#[derive(Debug, Clone)]
struct Class {
    name: String,
    kind: IceKind,
    rate_mm_per_h: f64,
    gain: f64,
    gain_end: Option<f64>,
    prior: Option<(f32, f32)>,
    /// A first accretion (grown, shed, dry for an hour) before the measured one.
    learned: bool,
    shape: Shape,
}

/// What one class measured.
#[derive(Debug, Clone, Default)]
struct Score {
    within: (u64, u64),
    thin: u64,
    err2: [Vec<f64>; 3],
    gain_err10: Vec<f64>,
    /// ln(est/true) of the rate 60 min into the growth, and whether the
    /// truth was within 2σ.
    rate_ln_err: Vec<f64>,
    rate_within: (u64, u64),
    /// Seconds from the growth's start to the icing flag (NaN: never).
    flag_on_s: Vec<f64>,
    /// Seconds from the growth's end to the flag's clearing (NaN: never).
    flag_off_s: Vec<f64>,
    /// Seconds from the growth's end to "not accreting" (P(accreting) ≤
    /// the off threshold; NaN: never — "uncertain" at most).
    not_acc_s: Vec<f64>,
    /// Seconds from a resumed growth to the flag (NaN: never).
    resume_on_s: Vec<f64>,
    /// Frames of growth, and those flagged accreting.
    grow_flagged: (u64, u64),
    /// Seconds from the shed to the medium "dry" (NaN: never).
    shed_dry_s: Vec<f64>,
    /// Frames with ice ≥ 1 mm, and those whose medium is right.
    medium: (u64, u64),
    /// The same in 1–2 mm, 2–4 mm and from 4 mm (`EST_MEDIUM_BINS`).
    medium_bins: [(u64, u64); 3],
}

const AT_MM: [f64; 3] = [2.0, 5.0, 10.0];

fn classes() -> Vec<Class> {
    let mut out = Vec::new();
    for (kind, kname) in [(IceKind::Rime, "rime"), (IceKind::Glazed, "glazed")] {
        for rate in [2.0, 10.0] {
            let base = |gain: f64, prior, tag: String| Class {
                name: format!("{kname} {rate} mm/h {tag}"),
                kind,
                rate_mm_per_h: rate,
                gain,
                gain_end: None,
                prior,
                learned: false,
                shape: Shape::Steady,
            };
            for g in [0.85, 0.92, 1.0, 1.08, 1.15] {
                out.push(base(g, None, format!("g {g:.2}")));
            }
            for g in [0.85, 1.0, 1.15] {
                out.push(base(
                    g,
                    Some((g as f32, 0.02)),
                    format!("g {g:.2} calibrated ±2 %"),
                ));
            }
        }
    }
    let scenario = |name: &str, kind, rate, gain: f64, shape| Class {
        name: name.into(),
        kind,
        rate_mm_per_h: rate,
        gain,
        gain_end: None,
        prior: None,
        learned: false,
        shape,
    };
    for (kind, kname) in [(IceKind::Rime, "rime"), (IceKind::Glazed, "glazed")] {
        for rate in [2.0, 10.0] {
            for at in [3.0, 6.0] {
                out.push(scenario(
                    &format!("{kname} {rate} mm/h g 1.08 stops at {at} mm"),
                    kind,
                    rate,
                    1.08,
                    Shape::Stop(at),
                ));
            }
        }
    }
    out.push(scenario(
        "rime 2 mm/h g 1.08 paused 2 h at 5 mm",
        IceKind::Rime,
        2.0,
        1.08,
        Shape::Pause,
    ));
    out.push(scenario(
        "rime 2 mm/h g 0.92 paused 2 h at 5 mm",
        IceKind::Rime,
        2.0,
        0.92,
        Shape::Pause,
    ));
    out.push(scenario(
        "rime varying around 2 mm/h g 1.08",
        IceKind::Rime,
        2.0,
        1.08,
        Shape::Varying,
    ));
    out.push(scenario(
        "rime varying around 5 mm/h g 0.92",
        IceKind::Rime,
        5.0,
        0.92,
        Shape::Varying,
    ));
    out.push(scenario(
        "rime step 2→10 mm/h at 4 mm g 1.08",
        IceKind::Rime,
        2.0,
        1.08,
        Shape::Step,
    ));
    out.push(scenario(
        "rime 2 mm/h g 0.92 shed at 6 mm, regrow",
        IceKind::Rime,
        2.0,
        0.92,
        Shape::Shed,
    ));
    out.push(scenario(
        "glazed 10 mm/h g 1.08 shed at 6 mm, regrow",
        IceKind::Glazed,
        10.0,
        1.08,
        Shape::Shed,
    ));
    out
}

fn params_from_env() -> EstimatorParams {
    let mut p = EstimatorParams::default();
    let get = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f32>().ok());
    if let Some(v) = get("EST_MEMORY") {
        p.gain_memory_s = v;
    }
    if let Some(v) = get("EST_SWITCH") {
        p.switch_per_h = v;
    }
    if let Some(v) = get("EST_WITHIN") {
        p.gain_within_min = v;
    }
    if std::env::var("EST_DESIGN").as_deref() == Ok("folded") {
        p.gain_within_min = 0.2;
    }
    if let Some(v) = get("EST_PERIOD") {
        p.update_period_s = v;
    }
    match std::env::var("EST_HISTORY").as_deref() {
        Ok("off") => p.history.enabled = false,
        Ok("nopause") => p.history.pause_per_h = 0.0,
        _ => {}
    }
    if let Some(v) = get("EST_LOOKS") {
        p.history.looks_per_mm = v;
    }
    if let Some(v) = get("EST_EARLY") {
        p.history.early_rime_looks_per_mm = v;
    }
    if let Some(v) = get("EST_LOOKS_PER_H") {
        p.history.looks_per_h = v;
    }
    if let Some(v) = get("EST_WALK") {
        p.history.rate_walk_per_h = v;
    }
    if let Some(v) = get("EST_HPERIOD") {
        p.history.period_s = v;
    }
    if let Some(v) = get("EST_GAMMA") {
        p.history.output_weight = v;
    }
    if let Some(v) = get("EST_RESTART") {
        p.history.restart_per_h = v;
    }
    if let Some(v) = get("EST_ESCAPE") {
        p.history.escape = v;
    }
    if let Some(v) = get("EST_CWIN") {
        p.history.change_window_s = v;
    }
    if let Some(v) = get("EST_CNOISE") {
        p.history.change_noise_ua = v;
    }
    if let Some(v) = get("EST_CSLOPE") {
        p.history.change_slope_sd = v;
    }
    if let Some(v) = get("EST_CTEMPER") {
        p.history.change_rate_temper = v;
    }
    if let Some(v) = get("EST_RESUME") {
        p.history.resume_ice_per_h = v;
    }
    if let Some(v) = get("EST_TELL") {
        p.history.tell_nats = v;
    }
    if let Some(v) = get("EST_SHED") {
        p.shed_per_h = v;
    }
    if let Some(v) = get("EST_HSHED") {
        p.history.shed_per_h = v;
    }
    p
}

fn score(c: &Class, seed: u64, frame_s: f64, params: EstimatorParams) -> Score {
    let temp = if c.kind == IceKind::Rime { -8.0 } else { -5.0 };
    let mut segments = vec![Segment::dry(60.0, temp)];
    if c.learned {
        segments.push(Segment::grow(c.kind, 0.0, 11.0, c.rate_mm_per_h, temp));
        segments.push(Segment::dry(3600.0, temp));
    }
    let skip_s: f64 = segments.iter().map(|s| s.duration_s).sum();
    let r = c.rate_mm_per_h;
    let (top_mm, stop_mm) = match c.shape {
        Shape::Steady | Shape::Varying => {
            let mut g = Segment::grow(c.kind, 0.0, 11.0, r, temp);
            if c.shape == Shape::Varying {
                g.rate_sd_ln = 0.5;
                // As long as the mean rate needs for 11 mm (the thickness
                // ends where the process takes it).
            }
            segments.push(g);
            (11.0, 11.0)
        }
        Shape::Pause => {
            segments.push(Segment::grow(c.kind, 0.0, 5.0, r, temp));
            segments.push(Segment::pause(c.kind, 7200.0, temp));
            segments.push(Segment::grow(c.kind, 5.0, 11.0, r, temp));
            (11.0, 11.0)
        }
        Shape::Step => {
            segments.push(Segment::grow(c.kind, 0.0, 4.0, r, temp));
            segments.push(Segment::grow(c.kind, 4.0, 11.0, 5.0 * r, temp));
            (11.0, 11.0)
        }
        Shape::Stop(at) => {
            segments.push(Segment::grow(c.kind, 0.0, at, r, temp));
            (at, at)
        }
        Shape::Shed => {
            segments.push(Segment::grow(c.kind, 0.0, 6.0, r, temp));
            segments.push(Segment::dry(1200.0, temp));
            segments.push(Segment::grow(c.kind, 0.0, 8.0, r, temp));
            (8.0, 8.0)
        }
    };
    let _ = top_mm;
    // 40 min with the ice staying after the growth stops.
    segments.push(Segment::pause(c.kind, 2400.0, temp));
    let mut growth_end_s: f64 = segments.iter().map(|s| s.duration_s).sum::<f64>() - 2400.0;
    // Paused growth: the clearing at the pause, the flag again after the
    // resume.
    let resume_s: Option<f64> = (c.shape == Shape::Pause).then(|| {
        growth_end_s = segments.iter().take(2).map(|s| s.duration_s).sum();
        growth_end_s + 7200.0
    });
    let shed_at_s: Option<f64> =
        (c.shape == Shape::Shed).then(|| segments.iter().take(3).map(|s| s.duration_s).sum());
    let _ = stop_mm;
    let mut run = Run::new(seed, segments);
    run.led = c.gain;
    run.led_end = c.gain_end;
    run.gain_prior = match std::env::var("EST_DESIGN").as_deref() {
        Ok("fixed") | Ok("folded") => Some((1.0, 0.001)),
        _ => c.prior,
    };
    run.frame_s = frame_s;
    let frames = simulate(&run, params);
    let mut s = Score::default();
    let (mut on, mut off, mut dry) = (f64::NAN, f64::NAN, f64::NAN);
    let mut not_acc = f64::NAN;
    let mut resumed_on = f64::NAN;
    let mut rate_done = false;
    if std::env::var("EST_TRACE").is_ok() {
        let every_s: u64 = std::env::var("EST_TRACE_S")
            .ok()
            .and_then(|v| v.parse().ok())
            .filter(|&v| v > 0)
            .unwrap_or(300);
        for f in frames
            .iter()
            .filter(|f| (f.t_s as u64).is_multiple_of(every_s))
        {
            if let (Some(p), r) = (f.est, f.est_rate) {
                println!(
                    "t {:6.0} d {:5.2} est {:5.2} ± {:4.2} {:?} {:.2} | rate {:5.2} true {:5.2} | {:?} acc {}",
                    f.t_s,
                    f.thickness_mm,
                    p.thickness_mm,
                    p.sigma_mm,
                    p.medium().0,
                    p.medium().1,
                    r.map_or(f32::NAN, |r| r.mean_mm_per_h),
                    f.rate_mm_per_h,
                    r.map(|r| (r.sigma_mm_per_h, r.p_accreting)),
                    f.accreting
                );
            }
        }
    }
    if std::env::var("EST_ODDS").is_ok() && c.shape == Shape::Steady {
        // Per 0.5 mm of the first growth: the bank's ln odds of rime
        // against glaze, averaged (`EST_ODDS`).
        let mut bins = [(0.0f64, 0u32); 12];
        for f in frames
            .iter()
            .filter(|f| f.t_s >= skip_s && f.rate_mm_per_h > 0.0)
        {
            let b = (f.thickness_mm / 0.5) as usize;
            if let Some(v) = bins.get_mut(b) {
                v.0 += f64::from(f.rime_odds);
                v.1 += 1;
            }
        }
        let cells: Vec<String> = bins
            .iter()
            .map(|v| format!("{:+.1}", v.0 / f64::from(v.1.max(1))))
            .collect();
        println!("odds {seed}: {}", cells.join(" "));
    }
    for f in frames.iter().filter(|f| f.t_s >= skip_s) {
        if on.is_nan() && f.accreting {
            on = f.t_s - skip_s;
        }
        if let Some(t0) = resume_s
            && f.t_s >= t0
            && resumed_on.is_nan()
            && f.accreting
        {
            resumed_on = f.t_s - t0;
        }
        if f.rate_mm_per_h > 0.0 && f.thickness_mm > 0.0 {
            s.grow_flagged.1 += 1;
            if f.accreting {
                s.grow_flagged.0 += 1;
            }
        }
        if f.t_s >= growth_end_s && off.is_nan() && !f.accreting {
            off = f.t_s - growth_end_s;
        }
        if f.t_s >= growth_end_s
            && not_acc.is_nan()
            && f.est_rate.is_some_and(|r| r.p_accreting <= ACCRETING_OFF)
        {
            not_acc = f.t_s - growth_end_s;
        }
        if let (Some(t0), Some(p)) = (shed_at_s, f.est)
            && f.t_s >= t0
            && dry.is_nan()
            && p.medium().0 == Medium::Dry
        {
            dry = f.t_s - t0;
        }
        if !rate_done && f.t_s - skip_s >= 3600.0 {
            rate_done = true;
            if let Some(r) = f.est_rate
                && f.rate_mm_per_h > 0.0
            {
                let est = f64::from(r.mean_mm_per_h).max(1e-3);
                s.rate_ln_err.push((est / f.rate_mm_per_h).ln());
                s.rate_within.1 += 1;
                if (est - f.rate_mm_per_h).abs() <= 2.0 * f64::from(r.sigma_mm_per_h) {
                    s.rate_within.0 += 1;
                }
            }
        }
        if f.medium == Medium::Dry {
            continue;
        }
        let est = f.est.expect("an estimate");
        let d = f.thickness_mm;
        let err = f64::from(est.thickness_mm) - d;
        let sigma = f64::from(est.sigma_mm);
        if d >= 0.5 {
            s.within.1 += 1;
            if err.abs() <= 2.0 * sigma {
                s.within.0 += 1;
            }
        }
        if d >= 1.0 {
            let right = u64::from(est.medium().0 == f.medium);
            s.medium.0 += 1;
            s.medium.1 += right;
            let bin = if d < 2.0 {
                0
            } else if d < 4.0 {
                1
            } else {
                2
            };
            s.medium_bins[bin].0 += 1;
            s.medium_bins[bin].1 += right;
        }
        if confidently_thin(f64::from(est.thickness_mm), sigma, d) {
            s.thin += 1;
        }
        // RMS at 2, 5, 10 mm: the first growth only (a regrowth or a
        // pause would count twice).
        if f.rate_mm_per_h > 0.0 && shed_at_s.is_none_or(|t0| f.t_s < t0) {
            for (at, v) in AT_MM.iter().zip(s.err2.iter_mut()) {
                if (d - at).abs() <= 0.05 {
                    v.push(err);
                }
            }
        }
        if (d - 10.0).abs() <= 0.05
            && let Some(g) = f.est_gain
        {
            s.gain_err10.push((f64::from(g.gain) / f.gain).ln());
        }
    }
    s.flag_on_s.push(on);
    if resume_s.is_some() {
        s.resume_on_s.push(resumed_on);
    }
    s.flag_off_s.push(off);
    s.not_acc_s.push(not_acc);
    if shed_at_s.is_some() {
        s.shed_dry_s.push(dry);
    }
    s
}

/// Worst (largest) of the times, NaN counted as never: "—".
fn worst_min(v: &[f64]) -> String {
    if v.is_empty() {
        return "".into();
    }
    if v.iter().any(|x| x.is_nan()) {
        let n = v.iter().filter(|x| x.is_nan()).count();
        return format!("never in {n}");
    }
    let m = v.iter().copied().fold(0.0, f64::max);
    format!("{:.1}", m / 60.0)
}

fn median_min(v: &[f64]) -> String {
    let mut w: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    if w.is_empty() {
        return "".into();
    }
    w.sort_by(f64::total_cmp);
    format!("{:.1}", w[w.len() / 2] / 60.0)
}

fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let seeds: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(30);
    let frame_s: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0.1);
    let filter = args.get(3).cloned().unwrap_or_default();
    let params = params_from_env();
    println!(
        "{seeds} accretions per class, frames every {frame_s} s, gain memory {} s, update every {} s",
        params.gain_memory_s, params.update_period_s
    );
    let seed_base: u64 = std::env::var("SEED_BASE")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(101);
    println!(
        "seeds {seed_base}…{}, history {}",
        seed_base + seeds - 1,
        if !params.history.enabled {
            "off"
        } else if params.history.pause_per_h == 0.0 {
            "without the pause state"
        } else {
            "on"
        }
    );
    println!(
        "| class | within 2σ | RMS 2 mm | RMS 5 mm | RMS 10 mm | confidently thin | medium right ≥ 1 mm | gain RMS at 10 mm | rate at 60 min: RMS ln(est/true) | rate within 2σ | icing flag on, median / worst min | off after stop, median / worst min | not accreting after stop, median / worst min | on after resume, worst min | growth flagged | shed → dry, worst min |"
    );
    println!(
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    // FILTER ending in `$`: that class only.
    let keep = |name: &str| match filter.strip_suffix('$') {
        Some(exact) => name == exact,
        None => name.contains(&filter),
    };
    for c in classes().into_iter().filter(|c| keep(&c.name)) {
        let scores: Vec<Score> = std::thread::scope(|sc| {
            let handles: Vec<_> = (0..2u64)
                .map(|part| {
                    let c = &c;
                    sc.spawn(move || {
                        (0..seeds)
                            .filter(|s| s % 2 == part)
                            .map(|s| score(c, seed_base + s, frame_s, params))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().expect("a worker"))
                .collect()
        });
        let mut all = Score::default();
        for s in scores {
            all.within.0 += s.within.0;
            all.within.1 += s.within.1;
            all.thin += s.thin;
            for (a, b) in all.err2.iter_mut().zip(s.err2) {
                a.extend(b);
            }
            all.gain_err10.extend(s.gain_err10);
            all.rate_ln_err.extend(s.rate_ln_err);
            all.rate_within.0 += s.rate_within.0;
            all.rate_within.1 += s.rate_within.1;
            all.flag_on_s.extend(s.flag_on_s);
            all.flag_off_s.extend(s.flag_off_s);
            all.not_acc_s.extend(s.not_acc_s);
            all.resume_on_s.extend(s.resume_on_s);
            all.grow_flagged.0 += s.grow_flagged.0;
            all.grow_flagged.1 += s.grow_flagged.1;
            all.shed_dry_s.extend(s.shed_dry_s);
            all.medium.0 += s.medium.0;
            all.medium.1 += s.medium.1;
            for (a, b) in all.medium_bins.iter_mut().zip(s.medium_bins) {
                a.0 += b.0;
                a.1 += b.1;
            }
        }
        println!(
            "| {} | {:.1} % | {:.2} | {:.2} | {:.2} | {} | {:.1} % | {:.3} | {:.2} | {:.0} % | {} / {} | {} / {} | {} / {} | {} | {:.0} % | {} |",
            c.name,
            100.0 * all.within.0 as f64 / all.within.1.max(1) as f64,
            rms(&all.err2[0]),
            rms(&all.err2[1]),
            rms(&all.err2[2]),
            all.thin,
            100.0 * all.medium.1 as f64 / all.medium.0.max(1) as f64,
            rms(&all.gain_err10),
            rms(&all.rate_ln_err),
            100.0 * all.rate_within.0 as f64 / all.rate_within.1.max(1) as f64,
            median_min(&all.flag_on_s),
            worst_min(&all.flag_on_s),
            median_min(&all.flag_off_s),
            worst_min(&all.flag_off_s),
            median_min(&all.not_acc_s),
            worst_min(&all.not_acc_s),
            worst_min(&all.resume_on_s),
            100.0 * all.grow_flagged.0 as f64 / all.grow_flagged.1.max(1) as f64,
            worst_min(&all.shed_dry_s),
        );
        if std::env::var("EST_MEDIUM_BINS").is_ok() {
            let pct = |b: (u64, u64)| 100.0 * b.1 as f64 / b.0.max(1) as f64;
            println!(
                "  medium right: 1–2 mm {:.1} %, 2–4 mm {:.1} %, from 4 mm {:.1} %",
                pct(all.medium_bins[0]),
                pct(all.medium_bins[1]),
                pct(all.medium_bins[2]),
            );
        }
    }
}
