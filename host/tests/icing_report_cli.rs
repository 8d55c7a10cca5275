//! `foisctl icing-report` as a user runs it: on the fleet gateway's daily
//! files (the fixture its test writes: a compressed day and today's file,
//! an icing night across midnight), in each output format, with the
//! figure; bad input named with its exit code.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;
use std::process::Command;

fn foisctl(args: &[&str]) -> (Option<i32>, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_foisctl"))
        .args(args)
        .output()
        .expect("run foisctl");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// The gateway's files (gateway/src/season_log/tests.rs writes and checks them).
fn gateway_files() -> Vec<String> {
    let dir =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../gateway/tests/fixtures/daily-log/ridge");
    // Today's file first: the report orders files by their content.
    ["ridge-2026-03-02.csv", "ridge-2026-03-01.csv.gz"]
        .iter()
        .map(|n| dir.join(n).display().to_string())
        .collect()
}

#[test]
fn the_report_runs_on_the_gateways_daily_files() {
    let files = gateway_files();
    let mut args = vec!["icing-report", "--json", "--log"];
    args.extend(files.iter().map(String::as_str));
    let (code, out, err) = foisctl(&args);
    assert_eq!(code, Some(0), "{err}");
    let r: serde_json::Value = serde_json::from_str(&out).unwrap();
    // 12:00 to 04:00 the next day, a row a minute.
    assert_eq!(r["measurements"], 16 * 60);
    assert_eq!(r["events"].as_array().unwrap().len(), 1);
    let e = &r["events"][0];
    // 20:00 UTC on 2026-03-01 (rime from then at 2 mm/h), shed 02:00.
    // Derived icing starts when the 20-minute growth reaches 0.2 mm/h: the
    // 20:03 mean (0.100 mm) against 19:43 (dry), seen at 20:04.
    assert_eq!(
        e["start_ms"],
        1_772_323_200_000u64 + 20 * 3_600_000 + 4 * 60_000
    );
    assert_eq!(
        e["end_ms"],
        1_772_323_200_000u64 + 86_400_000 + 2 * 3_600_000
    );
    // Ice on the sensor from 0.3 mm (20:09) to 02:00.
    assert!(
        (e["instrumental_h"].as_f64().unwrap() - 5.85).abs() < 1e-9,
        "{e}"
    );
    let met = e["meteorological_h"].as_f64().unwrap();
    // No est_accreting in these rows: derived from the growth (3 h of it,
    // the 20-minute window's lag).
    assert!((3.0..3.5).contains(&met), "{e}");
    assert_eq!(e["peak_thickness_mm"], 6.0);
    assert_eq!(e["peak_sigma_mm"], 0.4);
    assert_eq!(e["medium"], "rime");
    assert_eq!(r["meteorological_source"]["node"], 0);
    assert!((r["covered_h"].as_f64().unwrap() - (16.0 - 1.0 / 60.0)).abs() < 1e-9);

    // The table and the events as CSV.
    let mut args = vec!["icing-report", "--log"];
    args.extend(files.iter().map(String::as_str));
    let (code, out, _) = foisctl(&args);
    assert_eq!(code, Some(0));
    assert!(
        out.contains("derived from the thickness series' growth"),
        "{out}"
    );
    assert!(
        out.contains("2026-03-01 20:04:00  2026-03-02 02:00:00"),
        "{out}"
    );
    assert!(out.contains("2026-03     "), "{out}");
    args.push("--csv");
    let (_, csv, _) = foisctl(&args);
    assert_eq!(csv.lines().count(), 2, "{csv}");
    assert!(
        csv.lines()
            .nth(1)
            .unwrap()
            .contains(",5.8500,6.0000,0.4000,"),
        "{csv}"
    );

    // The figure.
    let tmp = tempfile::tempdir().unwrap();
    let png = tmp.path().join("icing.png");
    let png_s = png.display().to_string();
    let mut args = vec!["icing-report", "--plot", png_s.as_str(), "--log"];
    args.extend(files.iter().map(String::as_str));
    let (code, _, err) = foisctl(&args);
    assert_eq!(code, Some(0), "{err}");
    assert!(std::fs::metadata(&png).unwrap().len() > 10_000);
}

#[test]
fn bad_input_is_named_with_its_exit_code() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nope.csv").display().to_string();
    let (code, _, err) = foisctl(&["icing-report", "--log", &missing]);
    assert_eq!(code, Some(1));
    assert!(err.contains("nope.csv"), "{err}");
    // A CSV that is not a log: the file, the line and its columns named.
    let other = tmp.path().join("other.csv");
    std::fs::write(&other, "not,a,log\n1,2,3\n").unwrap();
    let (code, _, err) = foisctl(&["icing-report", "--log", &other.display().to_string()]);
    assert_eq!(code, Some(1));
    assert!(
        err.contains("other.csv, line 1: no column `host_unix_ms`"),
        "{err}"
    );
    assert!(err.contains("(columns: not, a, log)"), "{err}");
    let files = gateway_files();
    let (code, _, err) = foisctl(&["icing-report", "--plot", "x.pdf", "--log", &files[0]]);
    assert_eq!(code, Some(2), "{err}");
    let (code, _, _) = foisctl(&["icing-report"]);
    assert_eq!(code, Some(2));
    let (code, _, _) = foisctl(&["icing-report", "--log", &files[0], "--csv", "--json"]);
    assert_eq!(code, Some(2));
    let (code, _, _) = foisctl(&["icing-report", "--log", &files[0], "--ice-on-mm", "-1"]);
    assert_eq!(code, Some(2));
}
