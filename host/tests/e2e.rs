//! End to end over pseudo-terminals: `foisctl virtual-node` ↔ `foisctl
//! monitor` / commands as separate processes, and an in-process lossy link.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use fois_host::csvlog::{HEADER, LogTable};

mod common;
use common::foisctl;
use common::{BIN, NodeProc};

/// `foisctl monitor --port PORT --log LOG --plain EXTRA...` as a child;
/// `piped`: capture its stdout/stderr (else discard them).
fn spawn_monitor(port: &str, log: &Path, extra: &[&str], piped: bool) -> Child {
    let io = || if piped { Stdio::piped() } else { Stdio::null() };
    Command::new(BIN)
        .args([
            "monitor",
            "--port",
            port,
            "--log",
            log.to_str().unwrap(),
            "--plain",
        ])
        .args(extra)
        .stdout(io())
        .stderr(io())
        .spawn()
        .unwrap()
}

/// `foisctl calibrate-gain --port PORT --i1-ua I1 --i2-ua I2`.
fn calibrate_gain(port: &str, i1_ua: &str, i2_ua: &str) -> (i32, String, String) {
    foisctl(&[
        "calibrate-gain",
        "--port",
        port,
        "--i1-ua",
        i1_ua,
        "--i2-ua",
        i2_ua,
    ])
}

fn kinds(t: &LogTable) -> Vec<String> {
    let k = t.col("kind").unwrap();
    t.rows.iter().map(|r| r[k].clone()).collect()
}

#[test]
fn commands_round_trip_and_monitor_logs_measurements() {
    // Dry for 1000 s of virtual time: calibration works, no alarm.
    let node = NodeProc::start(&["--speed", "20", "--dry-s", "1000", "--seed", "3"]);
    let p = node.path.as_str();

    let (code, out, err) = foisctl(&["config", "get", "--port", p]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("frame_period_ms") && out.contains("100"),
        "{out}"
    );

    let value = |out: &str, key: &str| -> String {
        let line = out.lines().find(|l| l.starts_with(key)).unwrap();
        line.split_whitespace().nth(1).unwrap().to_string()
    };
    let before = value(&out, "onset_frames");
    assert_eq!(
        before,
        fois_protocol::Config::default().onset_frames.to_string()
    );
    let (code, out, err) = foisctl(&[
        "config",
        "set",
        "--port",
        p,
        "onset_frames=12",
        "clear_frames=40",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains(&format!("onset_frames: {before} -> 12")),
        "{out}"
    );
    let (_, out, _) = foisctl(&["config", "get", "--port", p]);
    assert_eq!(value(&out, "onset_frames"), "12");
    assert_eq!(value(&out, "clear_frames"), "40");

    // Refused on the host (range, cross-field, syntax): exit 7, nothing sent.
    for bad in [
        "settle_us=1",
        "clear_rise_na=999999",
        "nokey=3",
        "onset_frames",
    ] {
        let (code, _, err) = foisctl(&["config", "set", "--port", p, bad]);
        assert_eq!(code, 7, "{bad}: {err}");
        assert!(
            err.contains("refused on the host") || err.contains("KEY=VALUE"),
            "{err}"
        );
    }

    let (code, out, err) = foisctl(&["calibrate-dark", "--port", p]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("DarkCalibrated"), "{out}");
    let (code, out, err) = foisctl(&["calibrate-dark", "--force", "--port", p]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("DarkCalibrated"), "{out}");
    // No alarm on a dry face: said so, exit 8 (it answered
    // `AlarmAcknowledged` and exit 0 before).
    let (code, out, err) = foisctl(&["ack", "--port", p]);
    assert_eq!(code, 8, "{out} {err}");
    assert!(out.contains("NoAlarm"), "{out}");
    assert!(err.contains("no alarm to acknowledge"), "{err}");

    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.csv");
    let l = log.to_str().unwrap();
    let (code, out, err) = foisctl(&[
        "monitor",
        "--port",
        p,
        "--log",
        l,
        "--duration",
        "1.5",
        "--plain",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("monitor:"), "{out}");
    let text = std::fs::read_to_string(&log).unwrap();
    assert_eq!(text.lines().next(), Some(HEADER));
    let t = LogTable::read(&log).unwrap();
    let ks = kinds(&t);
    assert_eq!(ks[0], "link_up");
    let (seq, i1, temp) = (
        t.col("seq").unwrap(),
        t.col("i1_ua").unwrap(),
        t.col("temperature_c").unwrap(),
    );
    let meas: Vec<&Vec<String>> = t.rows.iter().filter(|r| r[2] == "measurement").collect();
    // 1.5 s at ×20 and 10 Hz ≈ 300 frames.
    assert!(meas.len() > 150, "{} measurements", meas.len());
    // Measurements and answers share one sequence: no hole in it.
    let seqs: Vec<u32> = t.rows.iter().filter_map(|r| r[seq].parse().ok()).collect();
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "consecutive");
    for r in &meas {
        let i: f64 = r[i1].parse().unwrap();
        assert!(i.abs() < 0.5, "dry face reads ~0 µA, got {i}");
        let c: f64 = r[temp].parse().unwrap();
        assert!((c + 5.0).abs() < 0.1, "air -5 °C, got {c}");
    }
    // The node's ice estimate (protocol 2): a dry face, with a σ.
    let (kind, sigma) = (t.col("est_kind").unwrap(), t.col("est_sigma_mm").unwrap());
    let dry = meas.iter().filter(|r| r[kind] == "dry").count();
    assert_eq!(
        dry,
        meas.len(),
        "every frame of a calibrated dry face reads dry"
    );
    assert!(meas.iter().all(|r| r[sigma].parse::<f64>().is_ok()));
    // A second run appends to the same file, header once.
    let (code, _, _) = foisctl(&[
        "monitor",
        "--port",
        p,
        "--log",
        l,
        "--duration",
        "0.5",
        "--plain",
    ]);
    assert_eq!(code, 0);
    let text = std::fs::read_to_string(&log).unwrap();
    assert_eq!(text.matches("host_time_utc").count(), 1);
    assert_eq!(text.matches(",link_up,").count(), 2);
}

#[test]
fn bad_port_and_bad_input_give_clear_errors() {
    let (code, _, err) = foisctl(&["monitor", "--port", "/dev/does-not-exist"]);
    assert_eq!(code, 3, "{err}");
    assert!(
        err.contains("cannot open serial port /dev/does-not-exist"),
        "{err}"
    );
    let (code, _, err) = foisctl(&["config", "get", "--port", "/dev/does-not-exist"]);
    assert_eq!(code, 3, "{err}");
    let (code, _, err) = foisctl(&["virtual-node", "--ice", "slush"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("slush"), "{err}");
    assert!(!err.contains("panicked"));
}

#[test]
fn node_killed_and_restarted_monitor_reconnects_and_logs_the_gap() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("node");
    let ls = link.to_str().unwrap();
    let log = dir.path().join("log.csv");
    let mut node = NodeProc::start(&["--speed", "10", "--dry-s", "1000", "--link", ls]);
    let mon = spawn_monitor(ls, &log, &["--duration", "4"], true);
    std::thread::sleep(Duration::from_millis(1200));
    node.kill9();
    std::thread::sleep(Duration::from_millis(600));
    let _node2 = NodeProc::start(&["--speed", "10", "--dry-s", "1000", "--link", ls]);
    let out = mon.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("disappeared"), "{stdout}");
    assert!(stdout.contains("reconnected"), "{stdout}");
    let t = LogTable::read(&log).unwrap();
    let ks = kinds(&t);
    let lost = ks
        .iter()
        .position(|k| k == "link_lost")
        .expect("link_lost row");
    let up2 = ks.iter().rposition(|k| k == "link_up").unwrap();
    assert!(up2 > lost, "{ks:?}");
    assert_eq!(
        ks[lost..].iter().filter(|k| *k == "node_restart").count(),
        1,
        "restart recorded once: {ks:?}"
    );
    assert!(ks[..lost].iter().filter(|k| *k == "measurement").count() > 20);
    assert!(ks[up2..].iter().filter(|k| *k == "measurement").count() > 20);
    // The host clock shows the gap: > 0.5 s between the rows around it.
    let ms = t.col("host_unix_ms").unwrap();
    let before: u64 = t.rows[lost - 1][ms].parse().unwrap();
    let after: u64 = t.rows[up2 + 1][ms].parse().unwrap();
    assert!(after - before >= 500, "gap {} ms", after - before);
}

#[test]
fn logger_killed_with_sigkill_keeps_all_but_the_last_second() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.csv");
    let node = NodeProc::start(&["--speed", "10", "--dry-s", "1000"]);
    let mut mon = spawn_monitor(&node.path, &log, &[], false);
    std::thread::sleep(Duration::from_millis(2500));
    let killed_at = fois_link::timefmt::unix_ms_now();
    mon.kill().unwrap(); // SIGKILL: no flush, no destructor
    mon.wait().unwrap();
    let t = LogTable::read(&log).unwrap();
    let ms = t.col("host_unix_ms").unwrap();
    let last: u64 = t
        .rows
        .iter()
        .map(|r| r[ms].parse::<u64>().unwrap())
        .max()
        .unwrap();
    assert!(
        killed_at - last <= 1000,
        "lost {} ms of rows",
        killed_at - last
    );
    // Every frame older than that is there: the sequence has no hole.
    let seq = t.col("seq").unwrap();
    // Every frame (measurements and answers) has a sequence number.
    let seqs: Vec<u32> = t.rows.iter().filter_map(|r| r[seq].parse().ok()).collect();
    assert!(seqs.len() > 100);
    let holes: Vec<&[u32]> = seqs.windows(2).filter(|w| w[1] != w[0] + 1).collect();
    assert!(holes.is_empty(), "{holes:?}");
    drop(node);
}

/// Write all of `bytes` to the pty's master side. Its 1 ms timeout makes a
/// write fail while the monitor is slow to read (a loaded machine): the
/// frame must then wait, not vanish, or the wire loses frames the test did
/// not mean to lose.
fn wire_write(master: &mut serialport::TTYPort, mut bytes: &[u8]) {
    use std::io::{ErrorKind, Write};
    let start = Instant::now();
    while !bytes.is_empty() && start.elapsed() < Duration::from_secs(5) {
        match master.write(bytes) {
            Ok(n) => bytes = &bytes[n..],
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                ) => {}
            Err(_) => return,
        }
    }
}

/// In process: a virtual node behind a pty whose "wire" drops frames 100..110
/// and injects garbage; the monitor counts both and logs a gap row.
#[test]
fn lossy_wire_gap_and_garbage_are_counted_not_fatal() {
    use fois_host::monitor::{MonitorOptions, run};
    use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};
    use serialport::SerialPort;
    use std::io::Read;

    let (mut master, slave) = serialport::TTYPort::pair().unwrap();
    master.set_timeout(Duration::from_millis(1)).unwrap();
    let path = slave.name().unwrap();
    let tl = Timeline::constant(Segment::new(0.0, Cover::Dry).noise(0.5));
    let env = Arc::new(Environment::with_curves(tl, [], [0.0, 0.0]));
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let wire = std::thread::spawn(move || {
        let mut node = VirtualNode::new(env, NodeOptions::default());
        let mut buf = [0u8; 256];
        let mut sent = 0u32;
        let start = Instant::now();
        while !s2.load(Ordering::Relaxed) && start.elapsed() < Duration::from_secs(10) {
            let mut out: Vec<Vec<u8>> = Vec::new();
            if let Ok(n) = master.read(&mut buf) {
                node.handle_rx(&buf[..n], &mut |b: &[u8]| out.push(b.to_vec()));
            }
            if node.node().is_streaming() {
                node.step_frame(&mut |b: &[u8]| out.push(b.to_vec()));
            } else {
                node.advance_to(node.clock().now_ns() + 10_000_000, &mut |b: &[u8]| {
                    out.push(b.to_vec())
                });
            }
            for f in out {
                let seq = node.node().next_seq();
                let _ = seq;
                sent += 1;
                if (100..110).contains(&sent) {
                    continue; // lost on the wire
                }
                if sent == 150 {
                    // Garbage: random bytes, a corrupted frame, an oversized run.
                    wire_write(&mut master, &[0x13, 0x37, 0xff, 0x00]);
                    let mut bad = f.clone();
                    bad[3] ^= 0x55;
                    wire_write(&mut master, &bad);
                    wire_write(&mut master, &[0x42; 600]);
                    wire_write(&mut master, &[0x00]);
                }
                wire_write(&mut master, &f);
            }
            std::thread::sleep(Duration::from_micros(500));
        }
    });
    let dir = tempfile::tempdir().unwrap();
    let log: PathBuf = dir.path().join("log.csv");
    let mut opts = MonitorOptions::new(path);
    opts.log = Some(log.clone());
    opts.quiet = true;
    opts.duration = Some(Duration::from_millis(1500));
    let never = AtomicBool::new(false);
    let sum = run(&opts, &never).unwrap();
    stop.store(true, Ordering::Relaxed);
    wire.join().unwrap();
    drop(slave);
    assert_eq!(sum.lost, 10, "{sum:?}");
    assert_eq!(sum.rejected, 3, "{sum:?}");
    assert!(sum.measurements > 200, "{sum:?}");
    let t = LogTable::read(Path::new(&log)).unwrap();
    let gaps: Vec<&Vec<String>> = t.rows.iter().filter(|r| r[2] == "gap").collect();
    assert_eq!(gaps.len(), 1);
    assert_eq!(gaps[0][t.col("frames_lost").unwrap()], "10");
    assert_eq!(t.rows.iter().filter(|r| r[2] == "rejected").count(), 3);
}

#[test]
fn ctrl_c_stops_the_monitor_cleanly() {
    let node = NodeProc::start(&["--speed", "10", "--dry-s", "1000"]);
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.csv");
    let mon = spawn_monitor(&node.path, &log, &[], true);
    std::thread::sleep(Duration::from_millis(1000));
    // SAFETY: plain kill(2) on our own child.
    let rc = unsafe { libc::kill(mon.id() as libc::pid_t, libc::SIGINT) };
    assert_eq!(rc, 0);
    let out = mon.wait_with_output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let summary = stdout.lines().last().unwrap();
    assert!(summary.starts_with("monitor: "), "{summary}");
    // The summary's row count is what the file holds (closed cleanly).
    let t = LogTable::read(&log).unwrap();
    assert!(
        summary.contains(&format!("{} rows appended", t.rows.len())),
        "{summary} vs {}",
        t.rows.len()
    );
}

/// A log made in process from the virtual node (no pty): 10 s dry, then
/// rime at 36 mm/h for 5 min of virtual time (0..3 mm).
fn make_rime_log(path: &Path) -> usize {
    use fois_host::csvlog::{CsvLog, Row};
    use fois_protocol::{DeviceFrame, FrameDecoder};
    use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

    let tl = Timeline::new(vec![
        Segment::new(10.0, Cover::Dry),
        Segment::new(f64::INFINITY, Cover::Rime).rate(36.0),
    ]);
    let env = Arc::new(Environment::new(tl, fois_sim::SensorKind::B, 1));
    let mut node = VirtualNode::new(env, NodeOptions::default());
    let mut bytes = Vec::new();
    node.run_until_s(310.0, &mut |b: &[u8]| bytes.extend_from_slice(b));
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    let mut log = CsvLog::open(path).unwrap();
    let mut n = 0;
    dec.feed::<DeviceFrame>(&bytes, |r| {
        let f = r.unwrap();
        if matches!(
            f.msg,
            fois_protocol::DeviceMsg::Measurement(_)
                | fois_protocol::DeviceMsg::MeasurementV2(_)
                | fois_protocol::DeviceMsg::MeasurementV3(_)
                | fois_protocol::DeviceMsg::MeasurementV5(_)
        ) {
            n += 1;
        }
        log.write(&Row::device(f.seq, &f.msg)).unwrap();
    });
    log.close().unwrap();
    assert!(node.alarm_on());
    n
}

#[test]
fn plot_and_compare_read_a_log() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("rime.csv");
    let n = make_rime_log(&log);
    assert!(n > 3000, "{n}");
    let l = log.to_str().unwrap();
    let png = dir.path().join("plot.png");
    let (code, out, err) = foisctl(&["plot", "--log", l, "--out", png.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains(&format!("{n} measurements drawn")), "{out}");
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let (code, out, err) = foisctl(&[
        "plot",
        "--log",
        l,
        "--out",
        png.to_str().unwrap(),
        "--time",
        "node",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains(&format!("{n} measurements drawn")), "{out}");

    let cmp_png = dir.path().join("cmp.png");
    let (code, out, err) = foisctl(&[
        "compare",
        "--log",
        l,
        "--ice",
        "rime",
        "--rate-mm-per-h",
        "36",
        "--start-s",
        "10",
        "--runs",
        "20",
        "--plot",
        cmp_png.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    // Samples from 10 s on: 300 s × 10 Hz (± the edges).
    let first = out.lines().next().unwrap();
    let samples: usize = first.split_whitespace().next().unwrap().parse().unwrap();
    assert!((2990..=3010).contains(&samples), "{first}");
    assert!(first.contains("thickness 0.00..3.0"), "{first}");
    for ch in ["I1", "I2"] {
        let line = out.lines().find(|l| l.starts_with(ch)).unwrap();
        let pct: f64 = line
            .split("µA, ")
            .nth(2)
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!((0.0..=100.0).contains(&pct), "{line}");
    }
    assert!(!out.contains("uA"), "µA in every text: {out}");
    let verdict = out.lines().find(|l| l.starts_with("verdict: ")).unwrap();
    assert!(
        verdict.starts_with("verdict: AGREES") || verdict.starts_with("verdict: DIFFERS"),
        "{verdict}"
    );
    assert!(verdict.contains("% needed"), "{verdict}");
    assert_eq!(&std::fs::read(&cmp_png).unwrap()[..4], b"\x89PNG");

    // Clear errors: missing column, unreadable file.
    let (code, _, err) = foisctl(&[
        "compare",
        "--log",
        l,
        "--ice",
        "rime",
        "--thickness-col",
        "laser_mm",
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("no column `laser_mm`"), "{err}");
    let (code, _, err) = foisctl(&["plot", "--log", "/nonexistent.csv", "--out", "/tmp/x.png"]);
    assert_eq!(code, 1);
    assert!(err.contains("cannot read log /nonexistent.csv"), "{err}");
}

#[test]
fn demo_runs_a_scenario_file_water_then_freezing() {
    let file = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenarios/water-then-freeze.toml"
    );
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("demo.csv");
    let (code, out, err) = foisctl(&[
        "demo",
        "--scenario",
        file,
        "--speed",
        "400",
        "--duration",
        "4",
        "--plain",
        "--log",
        log.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let wet = out.find("event WetOnset").expect("water at +5 °C is wet");
    let ice = out.find("event IceOnset").expect("then it freezes");
    assert!(wet < ice);
    assert!(out.contains("alarm output ON"), "{out}");
    // Wet and ice events in the log, with the temperature of the moment.
    let t = LogTable::read(&log).unwrap();
    let (detail, temp) = (t.col("detail").unwrap(), t.col("temperature_c").unwrap());
    let ice_row = t
        .rows
        .iter()
        .find(|r| r[detail].starts_with("IceOnset"))
        .unwrap();
    let c: f64 = ice_row[temp].parse().unwrap();
    let freeze = f64::from(fois_protocol::Config::default().freeze_limit_centi_c) / 100.0;
    assert!(
        c <= freeze && c > freeze - 0.5,
        "froze at {c} °C, limit {freeze}"
    );

    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[[segment]]\nduration_s = 5\ncover = \"slush\"\n").unwrap();
    let (code, _, err) = foisctl(&["virtual-node", "--scenario", bad.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("slush") && err.contains("segment 1"), "{err}");
}

#[test]
fn node_refusal_exits_6_and_other_protocol_version_exits_5() {
    // Sun strong enough to saturate both channels: dark calibration refused.
    let node = NodeProc::start(&["--speed", "10", "--dry-s", "1000", "--ambient", "400"]);
    let (code, _, err) = foisctl(&["calibrate-dark", "--port", &node.path]);
    assert_eq!(code, 6, "{err}");
    assert!(err.contains("CalibrationRefused(Saturated)"), "{err}");
    drop(node);

    // A "node" that speaks a protocol version newer than this host's: its Hello (frozen shape) is
    // readable, the version is refused.
    use fois_protocol::{
        DeviceFrame, DeviceMsg, Hello, PROTOCOL_VERSION, ResetReason, encode_to_vec,
    };
    use serialport::SerialPort;
    use std::io::Write;
    let (mut master, slave) = serialport::TTYPort::pair().unwrap();
    master.set_timeout(Duration::from_millis(100)).unwrap();
    let path = slave.name().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let talker = std::thread::spawn(move || {
        let hello = encode_to_vec(&DeviceFrame {
            seq: 0,
            msg: DeviceMsg::Hello(Hello {
                protocol_version: PROTOCOL_VERSION + 1,
                firmware_version: [9, 0, 0],
                board: Hello::board_from_str("future"),
                unique_id: [1; 12],
                reset_reason: ResetReason::PowerOn,
            }),
        });
        while !s2.load(Ordering::Relaxed) {
            let _ = master.write_all(&hello);
            std::thread::sleep(Duration::from_millis(100));
        }
    });
    let (code, _, err) = foisctl(&["monitor", "--port", &path]);
    stop.store(true, Ordering::Relaxed);
    talker.join().unwrap();
    drop(slave);
    assert_eq!(code, 5, "{err}");
    assert!(
        err.contains(&format!("speaks protocol version {}", PROTOCOL_VERSION + 1)),
        "{err}"
    );
}

#[test]
fn virtual_node_state_file_keeps_the_config_across_restarts() {
    let dir = tempfile::tempdir().unwrap();
    let state = dir.path().join("flash.bin");
    let st = state.to_str().unwrap();
    let mut node = NodeProc::start(&["--speed", "10", "--dry-s", "1000", "--state", st]);
    let (code, _, err) = foisctl(&["config", "set", "--port", &node.path, "onset_frames=17"]);
    assert_eq!(code, 0, "{err}");
    // The node saves a change once no other came for 1 s of its time
    // (0.1 s at --speed 10); wait well past that before pulling the plug.
    std::thread::sleep(std::time::Duration::from_millis(600));
    node.kill9();
    assert!(std::fs::metadata(&state).unwrap().len() > 0);
    let node = NodeProc::start(&["--speed", "10", "--dry-s", "1000", "--state", st]);
    let (code, out, err) = foisctl(&["config", "get", "--port", &node.path]);
    assert_eq!(code, 0, "{err}");
    let line = out.lines().find(|l| l.starts_with("onset_frames")).unwrap();
    assert_eq!(line.split_whitespace().nth(1), Some("17"), "{line}");
}

/// Mean of column `col` over the measurement rows of a log.
fn mean_of(t: &LogTable, col: &str) -> f64 {
    let (kind, c) = (t.col("kind").unwrap(), t.col(col).unwrap());
    let v: Vec<f64> = t
        .rows
        .iter()
        .filter(|r| r[kind] == "measurement")
        .filter_map(|r| r[c].parse().ok())
        .collect();
    assert!(!v.is_empty(), "no {col}");
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn calibrate_gain_and_reset_gain_as_a_user_runs_them() {
    // A steady reference on the face: 5 mm of rime that does not grow.
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("target.toml");
    std::fs::write(
        &scenario,
        "[[segment]]\nduration_s = \"inf\"\ncover = \"rime\"\nthickness_mm = 5.0\nair_temp_c = -8.0\n",
    )
    .unwrap();
    let node = NodeProc::start(&["--speed", "10", "--scenario", scenario.to_str().unwrap()]);
    let p = node.path.as_str();
    let log = dir.path().join("log.csv");
    let monitor = |log: &Path| {
        let (code, _, err) = foisctl(&[
            "monitor",
            "--port",
            p,
            "--log",
            log.to_str().unwrap(),
            "--duration",
            "1",
            "--plain",
        ]);
        assert_eq!(code, 0, "{err}");
        LogTable::read(log).unwrap()
    };
    // A new node: its gain unknown, wide.
    let t = monitor(&log);
    let (i1, i2) = (mean_of(&t, "i1_ua"), mean_of(&t, "i2_ua"));
    assert!(i1 > 5.0 && i2 > 2.0, "{i1} {i2}");
    // (5 mm of rime tells a new node its gain within ~10 % at once.)
    let new_sigma = mean_of(&t, "est_gain_sigma");
    assert!(new_sigma > 0.05, "σ {new_sigma}");

    // The target's currents at gain 1 are 0.9× what the face reads: gain 1.11.
    let (t1, t2) = (format!("{:.3}", i1 / 1.11), format!("{:.3}", i2 / 1.11));
    let (code, out, err) = calibrate_gain(p, &t1, &t2);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("GainCalibrated"), "{out}");
    let log2 = dir.path().join("log2.csv");
    let t = monitor(&log2);
    let (g, s) = (mean_of(&t, "est_gain"), mean_of(&t, "est_gain_sigma"));
    assert!((g - 1.11).abs() < 0.025, "gain {g}");
    assert!(s < 0.03, "σ {s}");

    // A target of another shape (channel 2 four times too large): refused,
    // exit 6, the reason said, the gain unchanged.
    let wrong = format!("{:.3}", 4.0 * i2 / 1.11);
    let (code, _, err) = calibrate_gain(p, &t1, &wrong);
    assert_eq!(code, 6, "{err}");
    assert!(
        err.contains("implied gain is outside the plausible range"),
        "{err}"
    );
    // Bad target values never reach the node: usage errors.
    for bad in ["0", "-3", "nan", "x"] {
        let (code, _, err) = calibrate_gain(p, bad, "8");
        assert_eq!(code, 2, "{bad}: {err}");
    }
    let log3 = dir.path().join("log3.csv");
    let t = monitor(&log3);
    assert!((mean_of(&t, "est_gain") - 1.11).abs() < 0.02);

    // Forgotten: wide again.
    let (code, out, err) = foisctl(&["reset-gain", "--port", p]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("GainReset"), "{out}");
    let log4 = dir.path().join("log4.csv");
    let t = monitor(&log4);
    assert!(mean_of(&t, "est_gain_sigma") > 0.06);
    assert!(
        (mean_of(&t, "est_gain") - 1.0).abs() < 0.1,
        "the face's own gain"
    );
}

#[test]
fn the_gain_calibration_is_practised_with_a_target_on_the_virtual_face() {
    // A target of 25.2 / 9.56 µA at gain 1 on a face whose LED gives 0.8 of
    // its nominal output: the node must find gain 0.8 (the brief's practice
    // in host/README.md).
    let node = NodeProc::start(&[
        "--speed",
        "20",
        "--dry-s",
        "3",
        "--target",
        "25.2,9.56",
        "--led-factor",
        "0.8",
        "--seed",
        "5",
    ]);
    let p = node.path.as_str();
    // Wait until the target is on (virtual 3 s = 0.15 s real, with room).
    std::thread::sleep(Duration::from_millis(800));
    let (code, out, err) = calibrate_gain(p, "25.2", "9.56");
    assert_eq!(code, 0, "{err}");
    let g: f64 = out
        .split("gain ")
        .nth(1)
        .and_then(|t| t.split_whitespace().next())
        .unwrap()
        .parse()
        .unwrap();
    assert!((g - 0.8).abs() < 0.02, "{out}");
    // The wrong target values (channel 2 four times too large): refused,
    // with what to do.
    let (code, _, err) = calibrate_gain(p, "25.2", "38.24");
    assert_eq!(code, 6, "{err}");
    assert!(
        err.contains("what to do:") && err.contains("--i1-ua/--i2-ua"),
        "{err}"
    );
}

#[test]
fn a_gain_calibration_without_a_target_says_to_put_one_on() {
    // A dry face, no target: the currents are those of the dark baseline.
    let node = NodeProc::start(&["--speed", "20", "--dry-s", "1000", "--seed", "6"]);
    let p = node.path.as_str();
    std::thread::sleep(Duration::from_millis(300));
    let (code, _, err) = calibrate_gain(p, "25.2", "9.56");
    assert_eq!(code, 6, "{err}");
    // The node sees the currents jump about a zero mean (`Step`): the
    // advice for a gain calibration is to put the target on.
    assert!(err.contains("CalibrationRefused(Step)"), "{err}");
    assert!(
        err.contains("what to do: no target on the face? Put the reference target on"),
        "{err}"
    );
}
