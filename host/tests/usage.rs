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

#[test]
fn usage_errors_exit_2() {
    let p = ["--port", "/dev/does-not-exist"];
    let with_port = |extra: &[&'static str]| {
        let mut v = extra.to_vec();
        v.extend_from_slice(&p);
        v
    };
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
        vec!["virtual-node", "--ice", "slush"],
        vec!["virtual-node", "--speed", "0"],
        vec!["virtual-node", "--speed", "20000"],
        vec!["virtual-node", "--duration", "-1"],
        vec!["virtual-node", "--dry-s", "-1"],
        vec!["virtual-node", "--temp-c", "-61"],
        vec!["virtual-node", "--rate-mm-per-h", "1001"],
        vec!["virtual-node", "--ambient", "1,-2"],
        vec!["virtual-node", "--flicker", "-1"],
        vec!["virtual-node", "--led-factor", "11"],
        vec!["virtual-node", "--noise-lsb", "-0.5"],
        vec!["virtual-node", "--sensor", "c"],
        vec!["virtual-node", "--seed", "-1"],
        vec!["virtual-node", "--scenario", "x.toml", "--ice", "rime"],
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
        vec![
            "compare",
            "--log",
            "x.csv",
            "--ice",
            "rime",
            "--rate-mm-per-h",
            "0",
        ],
        vec![
            "compare",
            "--log",
            "x.csv",
            "--ice",
            "rime",
            "--rate-mm-per-h",
            "1",
            "--runs",
            "0",
        ],
        vec![
            "compare",
            "--log",
            "x.csv",
            "--ice",
            "rime",
            "--rate-mm-per-h",
            "1",
            "--k-sigma",
            "0",
        ],
        vec![
            "compare",
            "--log",
            "x.csv",
            "--ice",
            "rime",
            "--rate-mm-per-h",
            "1",
            "--noise-ua",
            "-1",
        ],
        vec![
            "compare",
            "--log",
            "x.csv",
            "--ice",
            "rime",
            "--rate-mm-per-h",
            "1",
            "--start-s",
            "-1",
        ],
        vec![
            "compare",
            "--log",
            "x.csv",
            "--ice",
            "rime",
            "--thickness-col",
            "d",
            "--rate-mm-per-h",
            "1",
        ],
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
