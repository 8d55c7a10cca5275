//! `foisctl sim ...` end to end: the real binary on small runs.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;
use std::process::{Command, Output};

fn foisctl(args: &[&str]) -> Output {
    foisctl_env(args, &[])
}

/// `foisctl` with these environment variables set.
fn foisctl_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_foisctl"))
        .args(args)
        .envs(env.iter().copied())
        .output()
        .expect("run foisctl")
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fois_sim_cli_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// The header line and every record of a CSV file, as text.
fn records(path: &PathBuf) -> (String, Vec<csv::StringRecord>) {
    let mut rd = csv::Reader::from_path(path).unwrap();
    let header = rd.headers().unwrap().iter().collect::<Vec<_>>().join(",");
    let data = rd.records().map(Result::unwrap).collect();
    (header, data)
}

fn rows(path: &PathBuf) -> (String, Vec<Vec<f64>>) {
    let (header, recs) = records(path);
    let data = recs
        .iter()
        .map(|r| r.iter().map(|v| v.parse::<f64>().unwrap()).collect())
        .collect();
    (header, data)
}

#[test]
fn curve_writes_its_header_and_values() {
    let out = tmp("curve.csv");
    let png = tmp("curve.png");
    // Two rime accretions of seed 4, 0–3 mm in 0.5 mm steps.
    let small_rime = |extra: &[&str]| {
        let mut v = vec![
            "sim",
            "curve",
            "--ice",
            "rime",
            "--runs",
            "2",
            "--max-mm",
            "3",
            "--step-mm",
            "0.5",
            "--seed",
            "4",
        ];
        v.extend_from_slice(extra);
        foisctl(&v)
    };
    let o = small_rime(&[
        "--out",
        out.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (h, d) = rows(&out);
    assert_eq!(
        h,
        "run,thickness_mm,i1_ua,i2_ua,i1_refl_ua,i1_scat_ua,i2_refl_ua,i2_scat_ua"
    );
    assert_eq!(d.len(), 2 * 7);
    assert_eq!(d[0][0], 0.0);
    assert_eq!(d[7][0], 1.0);
    assert_eq!(d[6][1], 3.0);
    // Sensor B: dry face reads 0; rime at 3 mm gives tens of µA on I1.
    assert_eq!(d[0][2], 0.0);
    assert!(d[6][2] > 10.0 && d[6][2] < 40.0, "{:?}", d[6]);
    for r in &d {
        assert!((r[2] - r[4] - r[5]).abs() < 2e-6 && (r[3] - r[6] - r[7]).abs() < 2e-6);
    }
    let png_bytes = std::fs::read(&png).unwrap();
    assert_eq!(&png_bytes[1..4], b"PNG");
    // Same seed → same file.
    let out2 = tmp("curve2.csv");
    let o = small_rime(&["--threads", "1", "--out", out2.to_str().unwrap()]);
    assert!(o.status.success());
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&out2).unwrap());
}

#[test]
fn sensor_a_shows_the_dry_offset() {
    let out = tmp("a.csv");
    let o = foisctl(&[
        "sim",
        "curve",
        "--ice",
        "glazed",
        "--sensor",
        "a",
        "--max-mm",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    let (_, d) = rows(&out);
    assert!((d[0][2] - 13.0).abs() < 1.0, "{:?}", d[0]);
}

/// `foisctl sim CMD` over 20 rime accretions, 0–5 mm, into `out`.
fn small_mc(cmd: &str, out: &std::path::Path) -> Output {
    foisctl(&[
        "sim",
        cmd,
        "--ice",
        "rime",
        "--runs",
        "20",
        "--max-mm",
        "5",
        "--out",
        out.to_str().unwrap(),
    ])
}

#[test]
fn analytic_montecarlo_and_crlb_write_their_headers() {
    let a = tmp("an.csv");
    let o = foisctl(&[
        "sim",
        "analytic",
        "--geometry",
        "thesis-ch3",
        "--out",
        a.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (h, d) = rows(&a);
    assert_eq!(h, "thickness_mm,i1_ua,i2_ua");
    assert_eq!(d.len(), 151);
    assert!(d.iter().any(|r| r[1] > 5.0));

    let m = tmp("mc.csv");
    let o = small_mc("montecarlo", &m);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (h, d) = rows(&m);
    assert_eq!(
        h,
        "thickness_mm,mean_i1_ua,mean_i2_ua,var_i1,var_i2,cov_i1_i2"
    );
    assert_eq!(d.len(), 51);
    for r in &d[1..] {
        assert!(r[3] >= 0.0 && r[4] >= 0.0 && r[5] * r[5] <= r[3] * r[4] * (1.0 + 1e-9) + 1e-12);
    }

    let c = tmp("crlb.csv");
    let o = small_mc("crlb", &c);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (h, vals) = records(&c);
    assert_eq!(h, "thickness_mm,crlb_std_mm,crlb_no_dsigma_std_mm");
    assert_eq!(vals.len(), 51);
    assert_eq!(&vals[0][1], "NaN"); // dry face: Σ singular
    let v: f64 = vals[40][1].parse().unwrap();
    assert!(v > 0.0 && v < 5.0, "{v}");
}

#[test]
fn crlb_with_an_unknown_gain_adds_its_bound_beside_the_known_one() {
    let c = tmp("crlb_gain.csv");
    let png = tmp("crlb_gain.png");
    let o = foisctl(&[
        "sim",
        "crlb",
        "--ice",
        "rime",
        "--runs",
        "40",
        "--max-mm",
        "8",
        "--gain-sd",
        "0.1",
        "--out",
        c.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (h, vals) = records(&c);
    assert_eq!(
        h,
        "thickness_mm,crlb_std_mm,crlb_no_dsigma_std_mm,crlb_gain_std_mm,crlb_gain_no_dsigma_std_mm"
    );
    assert_eq!(vals.len(), 81);
    assert_eq!(&vals[0][3], "NaN"); // dry face
    let at = |i: usize, k: usize| vals[i][k].parse::<f64>().unwrap();
    // The unknown gain never lowers the bound, and at 6 mm (I1 and I2 rising in proportion)
    // it raises it several times.
    for i in 10..81 {
        assert!(at(i, 3) >= at(i, 1) * (1.0 - 1e-5), "{i}: {vals:?}");
        assert!(at(i, 4) >= at(i, 2) * (1.0 - 1e-5), "{i}");
    }
    assert!(at(60, 3) > 2.0 * at(60, 1), "{:?}", vals[60]);
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
    // The same run without the flag: the known-gain columns are the same numbers.
    let k = tmp("crlb_known.csv");
    let o = foisctl(&[
        "sim",
        "crlb",
        "--ice",
        "rime",
        "--runs",
        "40",
        "--max-mm",
        "8",
        "--out",
        k.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    let (h, known) = records(&k);
    assert_eq!(h, "thickness_mm,crlb_std_mm,crlb_no_dsigma_std_mm");
    for (a, b) in known.iter().zip(&vals) {
        assert_eq!(&a[1], &b[1]);
    }
    let bad = foisctl(&[
        "sim",
        "crlb",
        "--runs",
        "2",
        "--gain-sd",
        "-1",
        "--out",
        k.to_str().unwrap(),
    ]);
    assert_eq!(bad.status.code(), Some(2));
}

#[test]
fn bad_input_exits_with_an_error_not_a_panic() {
    let out = tmp("bad.csv");
    let o = out.to_str().unwrap();
    let curve = |extra: &[&'static str]| {
        let mut v = vec!["sim", "curve", "--ice", "rime", "--out", o];
        v.extend_from_slice(extra);
        v
    };
    // (arguments, exit code): 2 for a bad command line, 1 for an I/O failure.
    for (args, code) in [
        (curve(&["--step-mm", "0"]), 2),
        (curve(&["--step-mm", "-0.1"]), 2),
        (curve(&["--runs", "-3"]), 2),
        (curve(&["--runs", "0"]), 2),
        (vec!["sim", "curve", "--ice", "snow", "--out", o], 2),
        (curve(&["--max-mm", "nan"]), 2),
        (curve(&["--max-mm", "101"]), 2),
        (curve(&["--max-mm", "15", "--step-mm", "0.0001"]), 2),
        (curve(&["--diffuse-deg", "61"]), 2),
        (curve(&["--threads", "0"]), 2),
        (curve(&["--sensor", "c"]), 2),
        (curve(&["--geometry", "thesis-ch4"]), 2),
        (
            vec![
                "sim",
                "curve",
                "--ice",
                "rime",
                "--out",
                "/nonexistent/dir/x.csv",
            ],
            1,
        ),
        (vec!["sim", "montecarlo", "--runs", "1", "--out", o], 2),
        (
            vec![
                "sim",
                "crlb",
                "--runs",
                "10",
                "--fit-half-width-mm",
                "0",
                "--out",
                o,
            ],
            2,
        ),
        (vec!["sim", "analytic", "--ice", "rime", "--out", o], 2),
        (vec!["sim", "bench", "--runs", "0"], 2),
        (vec!["sim", "bench", "--threads", "0"], 2),
        (vec!["sim", "gallery", "--runs", "1"], 2),
    ] {
        let r = foisctl(&args);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(code), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(!err.trim().is_empty(), "{args:?}: no message");
    }
}

#[test]
fn help_explains_units_and_defaults() {
    let o = foisctl(&["sim", "curve", "--help"]);
    assert!(o.status.success());
    let h = String::from_utf8_lossy(&o.stdout);
    for want in [
        "--step-mm",
        "mm",
        "default: 0.1",
        "--geometry",
        "thesis-ch5",
        "--seed",
        "run,thickness_mm",
    ] {
        assert!(h.contains(want), "missing {want:?} in\n{h}");
    }
    let o = foisctl(&["sim", "--help"]);
    let h = String::from_utf8_lossy(&o.stdout);
    for sub in [
        "curve",
        "analytic",
        "montecarlo",
        "crlb",
        "bench",
        "gallery",
    ] {
        assert!(h.contains(sub), "{sub}");
    }
}

#[test]
fn bench_reports_ray_evaluations_per_thread_for_each_medium() {
    let o = foisctl(&["sim", "bench", "--runs", "4", "--threads", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    for medium in ["rime", "glazed", "water"] {
        let head = format!("{medium} ice, thesis-ch5: 2553 rays × 151 thicknesses = 385503");
        assert!(out.contains(&head), "{out}");
    }
    // Three media, each with its one-thread and per-thread figures.
    assert_eq!(out.matches(" per thread").count(), 3, "{out}");
    let rates: Vec<f64> = out
        .lines()
        .filter_map(|l| l.trim().strip_prefix("1 thread:"))
        .map(|l| l.split_whitespace().next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(rates.len(), 3);
    assert!(rates.iter().all(|&r| r.is_finite() && r > 0.0), "{rates:?}");
    let o = foisctl(&["sim", "bench", "--runs", "2", "--ice", "water"]);
    assert!(o.status.success());
    assert_eq!(
        String::from_utf8_lossy(&o.stdout).matches(" ice, ").count(),
        1
    );
}

/// `FOIS_SIM_ISA` caps the vector kernels' tier, `sim bench` names the one it ran, the
/// output does not depend on it, and a misspelt tier is reported and ignored.
#[test]
fn the_kernel_tier_is_named_capped_and_does_not_change_the_output() {
    let run = |isa: &str, out: &PathBuf| {
        let args = [
            "sim",
            "montecarlo",
            "--ice",
            "glazed",
            "--runs",
            "3",
            "--out",
        ];
        let out = out.to_str().unwrap();
        foisctl_env(&[&args[..], &[out]].concat(), &[("FOIS_SIM_ISA", isa)])
    };
    let (base, best) = (tmp("tier_baseline.csv"), tmp("tier_best.csv"));
    assert!(run("baseline", &base).status.success());
    let o = run("avx3", &best);
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("FOIS_SIM_ISA=avx3: not one of avx512, avx2, baseline; ignored"),
        "{err}"
    );
    assert_eq!(std::fs::read(&base).unwrap(), std::fs::read(&best).unwrap());
    let o = foisctl_env(
        &["sim", "bench", "--runs", "1", "--ice", "water"],
        &[("FOIS_SIM_ISA", "baseline")],
    );
    assert!(o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("vector kernels: baseline ("), "{out}");
}

#[test]
fn table_writes_the_firmwares_checked_in_table() {
    let out = tmp("table.rs");
    let o = foisctl(&[
        "sim",
        "table",
        "--out",
        out.to_str().unwrap(),
        "--threads",
        "2",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("3 media × 75 rows, seed 900001, 321 accretions"),
        "{stdout}"
    );
    let checked_in =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware/src/estimator/table.rs");
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        std::fs::read_to_string(checked_in).unwrap(),
        "`foisctl sim table` and the firmware's stale-table test must write the same file"
    );
    assert!(!tmp("table.rs.partial").exists());
    // A directory that does not exist: a clear error, nothing written.
    let o = foisctl(&["sim", "table", "--out", "/nonexistent-dir/table.rs"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("does not exist"));
}
