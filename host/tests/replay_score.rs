//! The replay's scoring, as firmware/README.md's replay figures are made: a
//! user's path — `foisctl sim curve` (accretions the response table was not
//! built from), every `*_ua` column multiplied by a gain the node is not
//! told, `foisctl estimate` — then each row scored against the curve's
//! truth as `gain_eval` scores the node at 1 Hz: rows beyond 0.5 mm with
//! |err| ≤ 2σ, RMS at the rows of 2, 5 and 10 mm, rows "confidently thin"
//! (est + 2σ < d/2 at d ≥ 4 mm), the rate at the row one hour into the
//! growth (RMS of ln(est/true), truth within 2σ).
//!
//! The full table (30 accretions per class, 24 classes; minutes):
//!
//! ```text
//! cargo test -p fois-host --test replay_score -- --ignored --nocapture
//! ```
//!
//! `REPLAY_RUNS` (default 30) and `REPLAY_FILTER` (a class name's part) narrow
//! it. The default test run scores one small class and asserts it.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_foisctl");

/// Seeds of the replay's curves (no table, test or scenario uses them).
const RIME_SEED: u64 = 7100;
const GLAZED_SEED: u64 = 7200;

fn foisctl(args: &[&str]) {
    let out = Command::new(BIN).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "foisctl {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// One class of the replay.
#[derive(Debug, Clone)]
struct Class {
    ice: &'static str,
    rate_mm_per_h: f64,
    gain: f64,
    calibrated: bool,
}

impl Class {
    fn name(&self) -> String {
        format!(
            "{} {} mm/h g {:.2} {}",
            self.ice,
            self.rate_mm_per_h,
            self.gain,
            if self.calibrated {
                "calibrated ±2 %"
            } else {
                "unknown"
            }
        )
    }
}

/// What a class measured.
#[derive(Debug, Clone, Default)]
struct Score {
    within: (u64, u64),
    thin: u64,
    err_at: [Vec<f64>; 3],
    rate_ln: Vec<f64>,
    rate_within: (u64, u64),
}

const AT_MM: [f64; 3] = [2.0, 5.0, 10.0];

fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// `sim curve` → scaled by the gain → `foisctl estimate` → scored.
fn score(c: &Class, runs: u64, dir: &Path) -> Score {
    let seed = if c.ice == "rime" {
        RIME_SEED
    } else {
        GLAZED_SEED
    };
    score_seed(c, runs, seed, dir)
}

/// [`score`] on the curves of `seed`.
fn score_seed(c: &Class, runs: u64, seed: u64, dir: &Path) -> Score {
    let curve = dir.join(format!("{}-{runs}-{seed}.csv", c.ice));
    if !curve.exists() {
        foisctl(&[
            "sim",
            "curve",
            "--ice",
            c.ice,
            "--runs",
            &runs.to_string(),
            "--seed",
            &seed.to_string(),
            "--max-mm",
            "11",
            "--step-mm",
            "0.1",
            "--out",
            curve.to_str().unwrap(),
        ]);
    }
    // Every current times the gain the node is not told.
    let scaled = dir.join("scaled.csv");
    {
        let mut rd = csv::Reader::from_path(&curve).unwrap();
        let header = rd.headers().unwrap().clone();
        let mut wr = csv::Writer::from_path(&scaled).unwrap();
        wr.write_record(&header).unwrap();
        for rec in rd.records() {
            let rec = rec.unwrap();
            let row: Vec<String> = rec
                .iter()
                .zip(header.iter())
                .map(|(v, h)| {
                    if h.ends_with("_ua") {
                        format!("{:.6}", v.parse::<f64>().unwrap() * c.gain)
                    } else {
                        v.to_string()
                    }
                })
                .collect();
            wr.write_record(&row).unwrap();
        }
        wr.flush().unwrap();
    }
    let out = dir.join("estimated.csv");
    let rate = c.rate_mm_per_h.to_string();
    let temp = if c.ice == "rime" { "-8" } else { "-5" };
    let mut args = vec![
        "estimate",
        "--input",
        scaled.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--rate-mm-per-h",
        &rate,
        "--temperature-c",
        temp,
    ];
    if c.calibrated {
        args.extend_from_slice(&["--gain", "1", "--gain-sd", "0.02"]);
    }
    foisctl(&args);
    let mut rd = csv::Reader::from_path(&out).unwrap();
    let header = rd.headers().unwrap().clone();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (c_run, c_d, c_est, c_sd, c_rate, c_rate_sd) = (
        col("run"),
        col("thickness_mm"),
        col("est_thickness_mm"),
        col("est_sigma_mm"),
        col("est_rate_mm_per_h"),
        col("est_rate_sigma_mm_per_h"),
    );
    let mut s = Score::default();
    // The row one hour into the growth, per run.
    let hour_mm = c.rate_mm_per_h;
    let mut rate_done: BTreeMap<String, bool> = BTreeMap::new();
    for rec in rd.records() {
        let rec = rec.unwrap();
        let num = |i: usize| rec.get(i).and_then(|v| v.parse::<f64>().ok());
        let (Some(d), Some(est), Some(sd)) = (num(c_d), num(c_est), num(c_sd)) else {
            continue;
        };
        let err = est - d;
        if d > 0.5 {
            s.within.1 += 1;
            if err.abs() <= 2.0 * sd {
                s.within.0 += 1;
            }
        }
        if d >= 4.0 && est + 2.0 * sd < d / 2.0 {
            s.thin += 1;
        }
        for (at, v) in AT_MM.iter().zip(s.err_at.iter_mut()) {
            if (d - at).abs() < 0.05 {
                v.push(err);
            }
        }
        let run = rec.get(c_run).unwrap_or("").to_string();
        if d + 1e-9 >= hour_mm && !rate_done.get(&run).copied().unwrap_or(false) {
            rate_done.insert(run, true);
            if let (Some(r), Some(r_sd)) = (num(c_rate), num(c_rate_sd)) {
                s.rate_ln.push((r.max(1e-3) / c.rate_mm_per_h).ln());
                s.rate_within.1 += 1;
                if (r - c.rate_mm_per_h).abs() <= 2.0 * r_sd {
                    s.rate_within.0 += 1;
                }
            }
        }
    }
    s
}

fn row(c: &Class, s: &Score) -> String {
    format!(
        "| {} | {:.1} % | {:.2} | {:.2} | {:.2} | {} | {:.2} | {:.0} % |",
        c.name(),
        100.0 * s.within.0 as f64 / s.within.1.max(1) as f64,
        rms(&s.err_at[0]),
        rms(&s.err_at[1]),
        rms(&s.err_at[2]),
        s.thin,
        rms(&s.rate_ln),
        100.0 * s.rate_within.0 as f64 / s.rate_within.1.max(1) as f64,
    )
}

fn classes() -> Vec<Class> {
    let mut out = Vec::new();
    for ice in ["rime", "glazed"] {
        for rate_mm_per_h in [2.0, 10.0] {
            for gain in [0.85, 0.92, 1.0, 1.08, 1.15] {
                out.push(Class {
                    ice,
                    rate_mm_per_h,
                    gain,
                    calibrated: false,
                });
            }
            out.push(Class {
                ice,
                rate_mm_per_h,
                gain: 1.0,
                calibrated: true,
            });
        }
    }
    out
}

#[test]
fn a_calibrated_rime_replay_is_scored_and_honest() {
    // Two accretions of rime at 2 mm/h, the gain calibrated: the scorer
    // finds every row, σ is honest and the rate one hour in is the truth's.
    let dir = tempfile::tempdir().unwrap();
    let c = Class {
        ice: "rime",
        rate_mm_per_h: 2.0,
        gain: 1.0,
        calibrated: true,
    };
    let s = score(&c, 2, dir.path());
    println!("{}", row(&c, &s));
    // 2 runs × the rows beyond 0.5 mm up to 11 mm.
    assert_eq!(s.within.1, 2 * 105, "{s:?}");
    assert!(s.within.0 as f64 >= 0.9 * s.within.1 as f64, "{s:?}");
    assert_eq!(s.err_at.iter().map(Vec::len).sum::<usize>(), 6, "{s:?}");
    assert_eq!(s.thin, 0);
    assert_eq!(s.rate_within, (2, 2), "{s:?}");
}

#[test]
fn the_rate_from_rows_180_s_apart_is_not_drawn_low() {
    // Six accretions of rime at 2 mm/h, the gain unknown, rows 180 s apart
    // (curves of a seed the table does not use): one hour in, the rate's
    // RMS of ln(est/true). The change look credited every rate that a large
    // change lay far from a pause for with the same capped ratio, while a
    // small change ruled the fast rates out: the rate drifted low (0.46 on
    // these curves before, 0.27 after; 2026-11-28).
    let dir = tempfile::tempdir().unwrap();
    let c = Class {
        ice: "rime",
        rate_mm_per_h: 2.0,
        gain: 1.0,
        calibrated: false,
    };
    let s = score_seed(&c, 6, 7400, dir.path());
    println!("{}", row(&c, &s));
    let r = rms(&s.rate_ln);
    assert_eq!(s.rate_ln.len(), 6, "{s:?}");
    assert!(r <= 0.36, "rate at 60 min: RMS ln {r:.3}");
    assert_eq!(s.rate_within, (6, 6), "{s:?}");
}

#[test]
#[ignore = "the full replay table: minutes of CPU (run with --ignored)"]
fn replay_table() {
    let runs: u64 = std::env::var("REPLAY_RUNS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(30);
    let filter = std::env::var("REPLAY_FILTER").unwrap_or_default();
    let dir = tempfile::tempdir().unwrap();
    println!(
        "| class (sim curve → foisctl estimate, {runs} accretions) | within 2σ | RMS 2 mm | RMS 5 mm | RMS 10 mm | confidently thin | rate at 60 min: RMS ln | rate within 2σ |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for c in classes().iter().filter(|c| c.name().contains(&filter)) {
        let s = score(c, runs, dir.path());
        println!("{}", row(c, &s));
    }
}
