//! Every bad command line exits with code 2 (clap refuses it before any
//! port, file or simulation is touched), with a message and no panic.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::process::Command;

fn foisctl(args: &[&str]) -> (Option<i32>, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_foisctl"))
        .args(args)
        .output()
        .expect("run foisctl");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// `a` then `b`.
fn cat(a: &[&'static str], b: &[&'static str]) -> Vec<&'static str> {
    [a, b].concat()
}

#[test]
fn usage_errors_exit_2() {
    let with_port = |extra: &[&'static str]| cat(extra, &["--port", "/dev/does-not-exist"]);
    // A valid compare command line plus `extra`.
    let compare = |extra: &[&'static str]| {
        cat(
            &[
                "compare",
                "--log",
                "x.csv",
                "--ice",
                "rime",
                "--rate-mm-per-h",
                "1",
            ],
            extra,
        )
    };
    let vnode = |extra: &[&'static str]| cat(&["virtual-node"], extra);
    let cases: Vec<Vec<&str>> = vec![
        vec![],
        vec!["no-such-command"],
        vec!["monitor"],
        with_port(&["monitor", "--duration", "-1"]),
        with_port(&["monitor", "--duration", "nan"]),
        with_port(&["monitor", "--baud", "0"]),
        with_port(&["monitor", "--bogus"]),
        with_port(&["config", "get", "--timeout-ms", "0"]),
        with_port(&["config", "set"]),
        with_port(&["calibrate-dark", "--timeout-ms", "-5"]),
        with_port(&["ack", "--baud", "fast"]),
        vnode(&["--ice", "slush"]),
        vnode(&["--target", "-1,2"]),
        vnode(&["--target", "20,abc"]),
        vnode(&["--target", "1,2,3"]),
        vnode(&["--target", "20,8", "--ice", "rime"]),
        with_port(&["calibrate-dark", "--force", "yes"]),
        with_port(&["ack", "--force"]),
        vnode(&["--speed", "0"]),
        vnode(&["--speed", "20000"]),
        vnode(&["--duration", "-1"]),
        vnode(&["--dry-s", "-1"]),
        vnode(&["--temp-c", "-61"]),
        vnode(&["--rate-mm-per-h", "1001"]),
        vnode(&["--ambient", "1,-2"]),
        vnode(&["--flicker", "-1"]),
        vnode(&["--led-factor", "11"]),
        vnode(&["--noise-lsb", "-0.5"]),
        vnode(&["--sensor", "c"]),
        vnode(&["--seed", "-1"]),
        vnode(&["--scenario", "x.toml", "--ice", "rime"]),
        vec!["demo", "--duration", "-3"],
        vec!["demo", "--speed", "-1"],
        vec![
            "compare",
            "--log",
            "x.csv",
            "--ice",
            "snow",
            "--rate-mm-per-h",
            "1",
        ],
        vec!["compare", "--log", "x.csv", "--ice", "rime"],
        compare(&["--rate-mm-per-h", "0"]),
        compare(&["--runs", "0"]),
        compare(&["--k-sigma", "0"]),
        compare(&["--noise-ua", "-1"]),
        compare(&["--start-s", "-1"]),
        compare(&["--thickness-col", "d"]),
        vec!["plot", "--log", "x.csv", "--out", "x.png", "--time", "wall"],
        vec!["bench-decode", "--frames", "0"],
    ];
    for args in cases {
        let (code, err) = foisctl(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(!err.trim().is_empty(), "{args:?}: no message");
    }
}

/// A negative number where only a positive one makes sense is refused by
/// name ("must be > 0, got -2"), not mistaken for an unknown flag.
#[test]
fn negative_numbers_are_refused_by_name() {
    let base = ["compare", "--log", "x.csv", "--ice", "rime"];
    for (extra, needs) in [
        (&["--rate-mm-per-h", "-2"][..], "must be > 0, got -2"),
        (
            &["--rate-mm-per-h", "1", "--noise-ua", "-1"],
            "must be >= 0",
        ),
        (&["--rate-mm-per-h", "1", "--start-s", "-1"], "must be >= 0"),
    ] {
        let args = cat(&base, extra);
        let (code, err) = foisctl(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(needs), "{args:?}: {err}");
        assert!(!err.contains("unexpected argument"), "{args:?}: {err}");
    }
    for args in [
        &["virtual-node", "--flicker", "-1"][..],
        &["demo", "--duration", "-3"],
        &["monitor", "--port", "/dev/null", "--duration", "-1"],
    ] {
        let (code, err) = foisctl(args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(!err.contains("unexpected argument"), "{args:?}: {err}");
    }
}

/// A figure's format comes from its extension; PDF and others are refused
/// in words (exit 2) before the log is read.
#[test]
fn a_figure_format_other_than_png_or_svg_is_refused_in_words() {
    let (code, err) = foisctl(&["plot", "--log", "x.csv", "--out", "x.pdf"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("PDF is not supported") && err.contains(".svg"),
        "{err}"
    );
    let (code, err) = foisctl(&["plot", "--log", "x.csv", "--out", "/no/such/dir/x.png"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("does not exist") && !err.contains("Os {"),
        "{err}"
    );
}

#[test]
fn help_is_not_an_error() {
    for args in [
        &["--help"][..],
        &["monitor", "--help"],
        &["sim", "gallery", "--help"],
        &["--version"],
    ] {
        let (code, err) = foisctl(args);
        assert_eq!(code, Some(0), "{args:?}: {err}");
    }
}
