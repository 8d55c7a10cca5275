//! `fois-gateway`'s command line without a broker: every kind of bad flag
//! or config exits 2 with the reason before anything is opened;
//! `--check-config` says what is wrong (or OK) and opens no port;
//! `--help` and `--version` exit 0.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod support;

use std::path::Path;
use std::process::Command;

use support::BIN;

fn gateway(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(BIN).args(args).output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

#[test]
fn bad_flags_exit_2_with_the_reason() {
    // A valid command line (one node) plus `extra`: clap refuses the flag
    // before the node's port or any file is opened.
    let gw = |extra: &[&'static str]| [&["--node", "/dev/does-not-exist"][..], extra].concat();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--node", "/dev/x=a/b"], "not usable in topics"),
        (vec!["--node", "/dev/x="], "not usable in topics"),
        (vec!["--node", "=tower-3"], "give PATH or PATH=NAME"),
        (gw(&["--name", "farm 7"]), "not usable in topics"),
        (gw(&["--name", ""]), "not usable in topics"),
        (gw(&["--broker", "host:notaport"]), "not a port number"),
        (gw(&["--broker", "host:0"]), "not a port number"),
        (gw(&["--broker", "host:65536"]), "not a port number"),
        (gw(&["--broker", ":1883"]), "host is empty"),
        (gw(&["--measurement-interval-ms=-1"]), "invalid value"),
        (
            gw(&["--measurement-interval-ms", "86400001"]),
            "0..=86400000",
        ),
        (
            gw(&["--offline-measurement-interval-ms", "x"]),
            "invalid value",
        ),
        (gw(&["--queue-max-bytes", "65535"]), "65536.."),
        (gw(&["--status-interval-s", "0.05"]), "0.1..=86400"),
        (gw(&["--status-interval-s", "nan"]), "not a finite number"),
        (gw(&["--duration=-1"]), "must be >= 0"),
        (gw(&["--client-cert", "gw.pem"]), "--client-key"),
        (gw(&["--log-time", "sometimes"]), "invalid value"),
        (
            gw(&["--check-config", "--print-config"]),
            "cannot be used with",
        ),
        (gw(&["--bogus"]), "unexpected argument"),
    ];
    for (args, needle) in cases {
        let (code, _, err) = gateway(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: `{needle}` not in {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

#[test]
fn bad_configs_exit_2_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let node = "[[node]]\nport = \"/dev/x\"\n";
    let missing = dir.path().join("nope.toml").display().to_string();
    let bad_key = write(
        dir.path(),
        "bad.toml",
        &format!("[broker]\nprot = 1883\n{node}"),
    );
    let bad_name = write(dir.path(), "name.toml", &format!("{node}name = \"a/b\"\n"));
    let sys = write(
        dir.path(),
        "sys.toml",
        &format!("topic_prefix = \"$SYS/fois\"\n{node}"),
    );
    let modbus_addr = write(
        dir.path(),
        "modbus.toml",
        &format!("[modbus]\nenabled = true\nlisten = \"localhost\"\n{node}"),
    );
    let modbus_unit = write(
        dir.path(),
        "unit.toml",
        &format!("[modbus]\nenabled = true\n{node}[[node]]\nport = \"/dev/y\"\nmodbus_unit = 1\n"),
    );
    let cases: [(Option<&str>, &str); 7] = [
        (None, "no nodes"),
        (Some(&missing), "cannot read the config"),
        (Some(&bad_key), "unknown field `prot`"),
        (Some(&bad_name), "not usable in topics"),
        (Some(&sys), "starts with `$`"),
        (
            Some(&modbus_addr),
            "[modbus] listen `localhost` is not an address and port",
        ),
        (Some(&modbus_unit), "nodes 1 and 2 both have Modbus unit 1"),
    ];
    for (config, needle) in cases {
        for check in [false, true] {
            let mut args = vec![];
            if let Some(c) = config {
                args.extend(["--config", c]);
            }
            if check {
                args.push("--check-config");
            }
            let (code, _, err) = gateway(&args);
            assert_eq!(code, Some(2), "{args:?}: {err}");
            assert!(err.contains(needle), "{args:?}: `{needle}` not in {err}");
            assert!(!err.contains("panicked"), "{err}");
        }
    }
}

#[test]
fn a_bad_value_is_named_by_key_and_line_and_what_the_start_refuses_check_config_refuses() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().display();
    let head = format!("name = \"gw\"\n[queue]\ndir = \"{d}/q\"\n");
    let link = dir.path().join("by-id-link");
    std::os::unix::fs::symlink("/dev/null", &link).unwrap();
    let cases: Vec<(String, String)> = vec![
        (
            "[broker]\nport = 70000\n[[node]]\nport = \"/dev/x\"\n".into(),
            "line 5, column 8, key `broker.port`: invalid value: integer `70000`, expected u16"
                .into(),
        ),
        (
            "[modbus]\nenabled = true\n[[node]]\nport = \"/dev/x\"\nmodbus_unit = 300\n".into(),
            "line 8, column 15, key `node[0].modbus_unit`: invalid value: integer `300`, \
             expected u8"
                .into(),
        ),
        (
            "[broker]\nport = 1883\nport = 1884\n[[node]]\nport = \"/dev/x\"\n".into(),
            "line 6, column 1, key `broker.port`: duplicate key (first at line 5)".into(),
        ),
        (
            "[broker]\nkeep_alive_s = \"5\"\n[[node]]\nport = \"/dev/x\"\n".into(),
            "line 5, column 16, key `broker.keep_alive_s`: invalid type: string \"5\", \
             expected u64"
                .into(),
        ),
        (
            "[modbus]\nenabled = true\nidle_timeout_s = 0.5\n[[node]]\nport = \"/dev/x\"\n".into(),
            "line 6, key `modbus.idle_timeout_s`: [modbus] idle_timeout_s must be within \
             1..=86400 (not 0.5)"
                .into(),
        ),
        (
            "[broker]\nport = 1883\n[modbus]\nenabled = true\nlisten = \"0.0.0.0:1883\"\n\
             [[node]]\nport = \"/dev/x\"\n"
                .into(),
            "line 8, key `modbus.listen`: [modbus] listen 0.0.0.0:1883 is the broker's own \
             address and port (127.0.0.1:1883)"
                .into(),
        ),
        (
            format!(
                "[[node]]\nport = \"/dev/null\"\nname = \"a\"\n[[node]]\nport = \"{}\"\n\
                 name = \"b\"\n",
                link.display()
            ),
            format!(
                "line 8, key `node[1].port`: one serial port listed twice: /dev/null and {} are \
                 both /dev/null",
                link.display()
            ),
        ),
        (
            "[[node]]\nport = \"/dev/x\"\nname = \"Tower\"\n[[node]]\nport = \"/dev/y\"\n\
             name = \"tower\"\n"
                .into(),
            "line 9, key `node[1].name`: the node names `Tower` and `tower` differ only in case"
                .into(),
        ),
    ];
    for (k, (body, want)) in cases.iter().enumerate() {
        let cfg = write(dir.path(), &format!("c{k}.toml"), &format!("{head}{body}"));
        for check in [true, false] {
            let mut args = vec!["--config", cfg.as_str(), "--duration", "1"];
            if check {
                args.push("--check-config");
            }
            let (code, out, err) = gateway(&args);
            assert_eq!(code, Some(2), "{args:?}: {out}{err}");
            assert!(
                err.contains(want.as_str()),
                "{args:?}: `{want}` not in {err}"
            );
        }
    }
    // Modbus on an address that is not this machine's: refused by the
    // check (2) as by the start (1), each naming the address.
    let far = write(
        dir.path(),
        "far.toml",
        &format!(
            "{head}[broker]\nport = {}\n[modbus]\nenabled = true\nlisten = \"192.0.2.7:5020\"\n\
             [[node]]\nport = \"/dev/x\"\n",
            support::free_port()
        ),
    );
    let (code, _, err) = gateway(&["--config", &far, "--check-config"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("key `modbus.listen`: the gateway cannot listen on 192.0.2.7"),
        "{err}"
    );
    let (code, _, err) = gateway(&["--config", &far, "--duration", "1"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(
        err.contains("cannot listen for Modbus TCP on 192.0.2.7:5020"),
        "{err}"
    );
}

#[test]
fn check_config_validates_certificates_and_opens_nothing() {
    let dir = tempfile::tempdir().unwrap();
    support::pki::make_pki(dir.path());
    let d = dir.path().display();
    // The ports do not exist: --check-config never opens them.
    let nodes = "[[node]]\nport = \"/dev/does-not-exist-1\"\nname = \"a\"\n\
                 [[node]]\nport = \"/dev/does-not-exist-2\"\n";
    let good = write(
        dir.path(),
        "good.toml",
        &format!(
            "name = \"farm-7\"\n[broker]\nhost = \"broker.example\"\n[broker.tls]\n\
             ca_file = \"{d}/ca.pem\"\nclient_cert_file = \"{d}/client.pem\"\n\
             client_key_file = \"{d}/client.key\"\n[queue]\ndir = \"{d}/q\"\n{nodes}"
        ),
    );
    let (code, out, err) = gateway(&["--config", &good, "--check-config"]);
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(
        out.contains("config OK: gateway farm-7, 2 node(s), broker broker.example:8883 (TLS)"),
        "{out}"
    );
    assert!(
        out.contains("Home Assistant discovery on (for Home Assistant 2024.1 and later)"),
        "{out}"
    );
    assert!(out.contains("Modbus TCP off"), "{out}");
    assert!(!dir.path().join("q").exists(), "the queue was not created");
    // The ports do not exist: a warning each (by name, else by position),
    // still exit 0 (a USB adapter may be plugged in later).
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning: ")).collect();
    assert_eq!(warnings.len(), 2, "{err}");
    assert!(
        warnings[0].starts_with(
            "warning: node a: the serial port /dev/does-not-exist-1 does not exist. Not an error \
             (a USB adapter may be plugged in later; the gateway starts and tries to open it \
             every 500 ms)"
        ),
        "{err}"
    );
    assert!(
        warnings[1].starts_with("warning: node 2: the serial port /dev/does-not-exist-2 does not"),
        "{err}"
    );
    // A port that exists (here a plain file standing for it): no warning.
    let present = write(dir.path(), "ttyFOIS0", "");
    let present_cfg = write(
        dir.path(),
        "present.toml",
        &format!(
            "[queue]\ndir = \"{d}/q3\"\n[log]\ndir = \"{d}/logs\"\ndays_kept = 30\n[[node]]\nport = \"{present}\"\n"
        ),
    );
    let (code, out, err) = gateway(&["--config", &present_cfg, "--check-config"]);
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(out.contains("config OK"), "{out}");
    assert!(
        out.contains(&format!(", daily logs in {d}/logs (30 day(s) kept)")),
        "{out}"
    );
    assert!(!err.contains("warning"), "{err}");
    // Modbus on a port another program holds: --check-config does not
    // listen, so it is OK; the run stops at once with exit 1 and the reason.
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let modbus = write(
        dir.path(),
        "modbus.toml",
        &format!(
            "[broker]\nport = {}\n[queue]\ndir = \"{d}/q2\"\n[modbus]\nenabled = true\n\
             listen = \"127.0.0.1:{port}\"\n{nodes}",
            support::free_port()
        ),
    );
    let (code, out, err) = gateway(&["--config", &modbus, "--check-config"]);
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(
        out.contains(&format!(
            "Modbus TCP on 127.0.0.1:{port} (unit(s) 1,2, read-only, stale after 10 s, at most 64 clients)"
        )),
        "{out}"
    );
    let (code, out, err) = gateway(&["--config", &modbus, "--duration", "10"]);
    assert_eq!(code, Some(1), "{out}{err}");
    assert!(
        err.contains(&format!(
            "cannot listen for Modbus TCP on 127.0.0.1:{port}: Address already in use"
        )),
        "{err}"
    );
    assert!(!dir.path().join("q2").exists(), "stopped before the queue");
    drop(taken);
    // The server's key with the client's certificate: they do not match.
    let mismatched = write(
        dir.path(),
        "mismatch.toml",
        &std::fs::read_to_string(&good)
            .unwrap()
            .replace("client.key", "server.key"),
    );
    let (code, _, err) = gateway(&["--config", &mismatched, "--check-config"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("do not match"), "{err}");
    // A CA file that is not PEM.
    std::fs::write(dir.path().join("ca.pem"), "not a certificate").unwrap();
    let (code, _, err) = gateway(&["--config", &good, "--check-config"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("holds no certificate"), "{err}");
}

#[test]
fn help_and_version_are_not_errors() {
    for args in [&["--help"][..], &["--version"]] {
        let (code, out, err) = gateway(args);
        assert_eq!(code, Some(0), "{args:?}: {err}");
        assert!(out.contains("fois-gateway"), "{out}");
    }
    let (_, help, _) = gateway(&["--help"]);
    for needle in [
        "--check-config",
        "RUST_LOG",
        "Exit codes",
        "--log-time",
        "--log-to",
    ] {
        assert!(help.contains(needle), "`{needle}` not in --help:\n{help}");
    }
}

/// `fois-gateway` with one node that does not exist and a broker at
/// `broker`, for `secs`; (exit code, stdout + stderr).
fn short_run(
    dir: &Path,
    broker: &str,
    secs: &str,
    extra: &[&str],
    env: &[(&str, &str)],
) -> (Option<i32>, String) {
    let q = dir.join("q").display().to_string();
    let mut cmd = Command::new(BIN);
    cmd.args([
        "--node",
        "/dev/does-not-exist=a",
        "--broker",
        broker,
        "--queue-dir",
        &q,
        "--duration",
        secs,
    ])
    .args(extra)
    .env_remove("RUST_LOG")
    .env_remove("JOURNAL_STREAM");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap();
    let mut text = String::from_utf8_lossy(&out.stdout).into_owned();
    text.push_str(&String::from_utf8_lossy(&out.stderr));
    (out.status.code(), text)
}

/// A loopback port nothing listens on.
fn closed_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().port()
}

#[test]
fn a_run_that_never_reaches_the_broker_fails_with_its_summary() {
    let dir = tempfile::tempdir().unwrap();
    let broker = format!("127.0.0.1:{}", closed_port());
    let (code, out) = short_run(dir.path(), &broker, "1.5", &[], &[]);
    assert_eq!(code, Some(1), "{out}");
    assert!(
        out.contains("the broker was never reached in 1.5 s"),
        "{out}"
    );
    assert!(
        out.contains("0 broker connection(s)"),
        "the summary:\n{out}"
    );
    assert!(out.contains("Connection refused"), "{out}");
}

#[test]
fn log_lines_have_levels_no_timestamps_off_a_terminal_and_follow_rust_log() {
    let dir = tempfile::tempdir().unwrap();
    let broker = format!("127.0.0.1:{}", closed_port());
    // stdout is a pipe here: no timestamps (journald stamps lines itself).
    let (_, out) = short_run(dir.path(), &broker, "0.5", &[], &[]);
    let line = out
        .lines()
        .find(|l| l.contains("node on /dev/does-not-exist: cannot connect"))
        .unwrap_or_else(|| panic!("{out}"));
    assert!(line.trim_start().starts_with("WARN"), "{line}");
    let gw = out
        .lines()
        .find(|l| l.contains("gateway vm") || l.contains(": 1 node(s)"))
        .unwrap();
    assert!(gw.trim_start().starts_with("INFO"), "{gw}");
    // Asked for: an RFC 3339 timestamp first.
    let (_, out) = short_run(dir.path(), &broker, "0.5", &["--log-time", "always"], &[]);
    let first = out.lines().next().unwrap();
    assert!(
        first.len() > 20 && first.as_bytes()[4] == b'-' && first.contains('T'),
        "{first}"
    );
    // RUST_LOG=error: neither INFO nor WARN lines.
    let (_, out) = short_run(dir.path(), &broker, "0.5", &[], &[("RUST_LOG", "error")]);
    assert!(!out.contains(" INFO ") && !out.contains("WARN"), "{out}");
    assert!(
        out.contains("0 broker connection(s)"),
        "the summary stays:\n{out}"
    );
}

#[test]
fn a_server_that_is_not_an_mqtt_broker_is_named_as_such() {
    // A TCP server that answers every connection with a PUBACK packet.
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    std::thread::spawn(move || {
        for s in l.incoming() {
            let Ok(mut s) = s else { return };
            let _ = std::io::Write::write_all(&mut s, &[0x40, 0x02, 0x00, 0x01]);
            std::thread::sleep(std::time::Duration::from_millis(200));
        }
    });
    let dir = tempfile::tempdir().unwrap();
    let (code, out) = short_run(dir.path(), &format!("127.0.0.1:{port}"), "1.5", &[], &[]);
    assert_eq!(code, Some(1), "{out}");
    assert!(out.contains("did not answer as an MQTT broker"), "{out}");
    assert!(out.contains("PUBACK instead of CONNACK"), "{out}");
    assert!(!out.contains("Expected ConnAck"), "{out}");
}

#[test]
fn without_a_reachable_journal_logs_stay_on_stdout() {
    // This machine runs no journald: under a JOURNAL_STREAM (as systemd
    // sets it) the gateway falls back to its stdout lines, and says so only
    // when the journal was asked for explicitly.
    let dir = tempfile::tempdir().unwrap();
    let broker = format!("127.0.0.1:{}", closed_port());
    let (_, out) = short_run(
        dir.path(),
        &broker,
        "0.5",
        &[],
        &[("JOURNAL_STREAM", "8:1234")],
    );
    assert!(
        out.contains("WARN") && out.contains("cannot connect"),
        "{out}"
    );
    assert!(!out.contains("journal"), "{out}");
    let (_, out) = short_run(dir.path(), &broker, "0.5", &["--log-to", "journald"], &[]);
    assert!(
        out.contains("the systemd journal cannot be reached"),
        "{out}"
    );
    assert!(out.contains("cannot connect"), "{out}");
}
