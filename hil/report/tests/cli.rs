//! `hil-report`'s command line: help, and the exit code of mistakes.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::process::Command;

fn hil_report(args: &[&str]) -> (Option<i32>, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_hil-report"))
        .args(args)
        .output()
        .expect("run hil-report");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn help_prints_usage_instead_of_opening_a_file() {
    let (code, out, err) = hil_report(&["--help"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("Usage: hil-report"), "{out}");
    assert!(out.contains("FILE_OR_DIR"), "{out}");
    assert!(out.contains("Exit codes"), "{out}");
}

#[test]
fn bad_flags_and_missing_files_exit_2() {
    let (code, _, err) = hil_report(&["--bogus"]);
    assert_eq!(code, Some(2), "{err}");
    let (code, _, err) = hil_report(&["no-such-dir/none.toml"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("none.toml"), "{err}");
}
