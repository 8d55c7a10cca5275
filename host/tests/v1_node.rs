//! A protocol-version-1 node (it streams `Measurement`, not `MeasurementV2`,
//! and sends no ice estimate): `foisctl monitor` still connects, shows it and
//! logs it, with the estimate fields empty; `foisctl estimate` then gives its
//! log the estimate on the host. A fleet is never upgraded at once.
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::{Read, Write};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use fois_host::csvlog::LogTable;
use fois_protocol::{
    Ack, AckResult, Baseline, Command as HostCmd, DetectorState, DeviceFrame, DeviceMsg,
    FrameDecoder, Hello, HostFrame, Measurement, ResetReason, encode_to_vec,
};
use serialport::SerialPort;

const BIN: &str = env!("CARGO_BIN_EXE_foisctl");

/// The version-1 node: answers `GetInfo` with a version-1 `Hello`, and on
/// `StartStream` streams `Measurement` frames (rime-like currents rising
/// from 0 to ~25 µA, -5 °C) every 10 ms of real time until `stop`.
fn v1_node(mut master: serialport::TTYPort, stop: Arc<AtomicBool>) {
    let hello = Hello {
        protocol_version: 1,
        firmware_version: [0, 9, 0],
        board: Hello::board_from_str("nucleo-f446re"),
        unique_id: [3; 12],
        reset_reason: ResetReason::PowerOn,
    };
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    let mut seq = 0u32;
    let mut streaming = false;
    let mut uptime_ms = 0u64;
    let mut buf = [0u8; 256];
    let send = |master: &mut serialport::TTYPort, seq: &mut u32, msg: DeviceMsg| {
        let _ = master.write_all(&encode_to_vec(&DeviceFrame { seq: *seq, msg }));
        *seq += 1;
    };
    while !stop.load(Ordering::Relaxed) {
        let n = master.read(&mut buf).unwrap_or(0);
        let mut cmds = Vec::new();
        dec.feed::<HostFrame>(&buf[..n], |r| {
            if let Ok(f) = r {
                cmds.push(f);
            }
        });
        for f in cmds {
            let result = match f.cmd {
                HostCmd::GetInfo => AckResult::Info(hello.clone()),
                HostCmd::StartStream { .. } => {
                    streaming = true;
                    AckResult::Streaming {
                        frame_period_ms: 100,
                    }
                }
                // The version-1 commands; a newer variant is not answered
                // (a real version-1 node could not decode it).
                HostCmd::AckAlarm => AckResult::AlarmAcknowledged,
                HostCmd::CalibrateDark => AckResult::DarkCalibrated(Baseline {
                    i1_na: 600,
                    i2_na: 200,
                }),
                _ => continue,
            };
            send(
                &mut master,
                &mut seq,
                DeviceMsg::Ack(Ack { id: f.id, result }),
            );
        }
        if streaming {
            uptime_ms += 100;
            let i1_na = (uptime_ms / 20).min(25_000) as i32;
            let m = Measurement {
                uptime_ms,
                i1_na,
                i2_na: i1_na / 3,
                ambient1_na: 50,
                ambient2_na: 40,
                temperature_centi_c: -500,
                vdda_mv: 3300,
                flags: 0,
                state: DetectorState::Dry,
            };
            send(&mut master, &mut seq, DeviceMsg::Measurement(m));
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn a_version_1_node_is_monitored_and_logged_with_empty_estimate_fields() {
    let (mut master, slave) = serialport::TTYPort::pair().unwrap();
    master.set_timeout(Duration::from_millis(5)).unwrap();
    let path = slave.name().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let node = std::thread::spawn(move || v1_node(master, s2));

    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("v1.csv");
    let out = Command::new(BIN)
        .args(["monitor", "--port", &path, "--plain", "--duration", "2.5"])
        .args(["--log", log.to_str().unwrap()])
        .output()
        .unwrap();
    stop.store(true, Ordering::Relaxed);
    node.join().unwrap();
    drop(slave);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stdout.contains("protocol 1"), "{stdout}");
    // The status line: currents, state, and no estimate.
    let status = stdout.lines().find(|l| l.starts_with("I1")).unwrap();
    assert!(
        status.contains("state Dry") && status.contains("est —"),
        "{status}"
    );

    let t = LogTable::read(&log).unwrap();
    let c = |n: &str| t.col(n).unwrap();
    let (kind, i1, temp) = (c("kind"), c("i1_ua"), c("temperature_c"));
    let meas: Vec<&Vec<String>> = t.rows.iter().filter(|r| r[kind] == "measurement").collect();
    assert!(meas.len() >= 50, "{} measurements", meas.len());
    for r in &meas {
        for col in ["est_thickness_mm", "est_sigma_mm", "est_kind", "est_p"] {
            assert_eq!(r[c(col)], "", "{col} of a v1 node");
        }
        assert_eq!(r[temp], "-5.00");
    }
    // Every frame's currents arrive (5 nA per 100 ms of uptime).
    let first: f64 = meas[0][i1].parse().unwrap();
    let last: f64 = meas[meas.len() - 1][i1].parse().unwrap();
    assert!(last > first, "{first} -> {last}");

    // The host gives a v1 node's log the estimate.
    let est = dir.path().join("v1_est.csv");
    let out = Command::new(BIN)
        .args(["estimate", "--input", log.to_str().unwrap()])
        .args(["--out", est.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let t = LogTable::read(&est).unwrap();
    let k = t.col("est_kind").unwrap();
    let kind = t.col("kind").unwrap();
    let n = t
        .rows
        .iter()
        .filter(|r| r[kind] == "measurement" && !r[k].is_empty())
        .count();
    assert_eq!(n, meas.len());
}

#[test]
fn a_version_1_node_gets_the_old_dark_calibration_and_acknowledgement() {
    let (mut master, slave) = serialport::TTYPort::pair().unwrap();
    master.set_timeout(Duration::from_millis(5)).unwrap();
    let path = slave.name().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let node = std::thread::spawn(move || v1_node(master, s2));
    let run = |args: &[&str]| {
        let out = Command::new(BIN)
            .args(args)
            .args(["--port", &path, "--timeout-ms", "1500"])
            .output()
            .unwrap();
        (
            out.status.code().unwrap_or(-1),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    // Answered only because the old commands were sent.
    let (code, out, err) = run(&["ack"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("AlarmAcknowledged"), "{out}");
    let (code, out, err) = run(&["calibrate-dark"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("DarkCalibrated i1_ua=0.600"), "{out}");
    // A forced calibration needs version 4: refused on the host.
    let (code, _, err) = run(&["calibrate-dark", "--force"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("protocol version 1") && err.contains("version 4"),
        "{err}"
    );
    stop.store(true, Ordering::Relaxed);
    node.join().unwrap();
    drop(slave);
}
