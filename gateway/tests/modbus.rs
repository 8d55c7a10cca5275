//! The gateway's Modbus TCP server polled by an independent client
//! (pymodbus, in the virtualenv `cargo xtask tools` makes): the gateway
//! runs in a thread of the test (`service::Service`, so the test reads the
//! same node snapshots the server answers from) with virtual nodes on
//! pseudo-terminals, and no broker (the gateway keeps retrying it; Modbus
//! does not need it).
// A test crate: unwrap and expect are assertions here (helpers included).
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod support;

use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use fois_gateway::config::file::{FileConfig, Overrides};
use fois_gateway::machine::GatewaySummary;
use fois_gateway::modbus::status;
use fois_gateway::service::{RunLimits, Service};
use fois_gateway::snapshot::{Fleet, NodeSnapshot};
use fois_vnode::Cover;
use support::pymodbus::{self, Client};
use support::*;

/// The gateway with `[modbus]` `extra` and these nodes, in a thread.
struct Gateway {
    fleet: Fleet,
    stop: &'static AtomicBool,
    run: Option<JoinHandle<anyhow::Result<GatewaySummary>>>,
    port: u16,
    _dir: tempfile::TempDir,
}

impl Gateway {
    fn start(nodes: &[(&str, &str)], modbus: &str) -> Gateway {
        let dir = tempfile::tempdir().unwrap();
        let port = free_port();
        let extra = format!("[modbus]\nenabled = true\nlisten = \"127.0.0.1:{port}\"\n{modbus}\n");
        // Nothing listens on the broker port: the gateway retries it.
        let cfg = FileConfig::parse(&gateway_toml(
            free_port(),
            &dir.path().join("q"),
            nodes,
            &extra,
        ))
        .unwrap()
        .resolve(&Overrides::default())
        .unwrap();
        let service = Service::new(cfg);
        let fleet = service.fleet();
        let stop: &'static AtomicBool = Box::leak(Box::new(AtomicBool::new(false)));
        let run = std::thread::spawn(move || {
            service.run(RunLimits {
                stop,
                duration: None,
                status_every: Duration::from_secs(3600),
            })
        });
        Gateway {
            fleet,
            stop,
            run: Some(run),
            port,
            _dir: dir,
        }
    }

    /// Wait until node `k`'s snapshot satisfies `ok`.
    fn wait(
        &self,
        k: usize,
        what: &str,
        within: Duration,
        ok: impl Fn(&NodeSnapshot) -> bool,
    ) -> NodeSnapshot {
        let t0 = Instant::now();
        loop {
            let n = self.fleet.node(k).unwrap();
            if ok(&n) {
                return n;
            }
            assert!(
                t0.elapsed() < within,
                "{what}: not within {within:?}: {n:?}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn stop(&mut self) -> GatewaySummary {
        self.stop.store(true, Ordering::Relaxed);
        self.run.take().unwrap().join().unwrap().unwrap()
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// A node with its alarm on (rime at 30 mm/h from 2 s, speed 10).
fn iced_node() -> NodeProc {
    NodeProc::start(Scene::film(Cover::Rime, 30.0, -5.0, 2.0, 10.0, 1))
}

fn u32_at(r: &[u16], a: usize) -> u32 {
    (u32::from(r[a]) << 16) | u32::from(r[a + 1])
}

fn i32_at(r: &[u16], a: usize) -> i32 {
    u32_at(r, a) as i32
}

/// Registers 1–22 say what the snapshot's reading says, in the table's
/// scales (µA ×1000, °C ×100, mm ×1000, fractions ×1000, gains ×10⁶).
fn assert_matches(r: &[u16], n: &NodeSnapshot) {
    let m = n.reading.as_ref().unwrap();
    assert_eq!(r.len(), 24);
    let scaled = |x: f64, k: f64| (x * k).round() as i64;
    assert_eq!(r[1], 2, "ice");
    assert_eq!(r[2], m.flags & fois_protocol::flags::FAULT_MASK, "faults");
    assert_eq!(
        i64::from(i32_at(r, 3)),
        scaled(m.i1_ua, 1000.0),
        "i1 {}",
        m.i1_ua
    );
    assert_eq!(
        i64::from(i32_at(r, 5)),
        scaled(m.i2_ua, 1000.0),
        "i2 {}",
        m.i2_ua
    );
    assert_eq!(
        i64::from(r[7] as i16),
        scaled(m.temperature_c, 100.0),
        "{}",
        m.temperature_c
    );
    let e = m.estimate.as_ref().expect("the node sends an ice estimate");
    assert_eq!(
        i64::from(r[8]),
        scaled(e.thickness_mm, 1000.0),
        "{}",
        e.thickness_mm
    );
    assert_eq!(i64::from(r[9]), scaled(e.thickness_sigma_mm, 1000.0));
    assert_eq!(
        r[10],
        fois_gateway::modbus::medium_code(e.medium),
        "{:?}",
        e.medium
    );
    assert_eq!(i64::from(r[11]), scaled(e.medium_probability, 1000.0));
    match m.gain.as_ref() {
        Some(g) => {
            assert_eq!(
                i64::from(u32_at(r, 12)),
                scaled(g.gain, 1e6),
                "gain {}",
                g.gain
            );
            assert_eq!(i64::from(u32_at(r, 14)), scaled(g.gain_sigma, 1e6));
        }
        None => assert_eq!((u32_at(r, 12), u32_at(r, 14)), (u32::MAX, u32::MAX)),
    }
    assert_eq!(Some(u32_at(r, 18)), n.seq, "seq");
    assert_eq!(r[20], m.vdda_mv);
    assert_eq!(u64::from(u32_at(r, 21)), n.frames_lost);
    assert_eq!(r[23], 0);
}

#[test]
fn scada_reads_fresh_values_then_a_stale_node_and_bad_requests_get_exceptions_and_50_clients_poll_at_once()
 {
    let node = iced_node();
    let mut gw = Gateway::start(
        &[(&node.path, "n1"), ("/dev/does-not-exist", "n2")],
        "stale_after_s = 3\n",
    );
    let client = Client::new(gw.port);
    gw.wait(0, "the alarm", Duration::from_secs(30), |n| {
        n.reading
            .as_ref()
            .is_some_and(|m| m.alarm && m.estimate.is_some())
    });

    // Fresh: link up, alarm, measurement present, not stale, young data.
    let r = client.read(1, 4, 0, 24).unwrap();
    let want = status::ALARM | status::ICE | status::LINK_UP | status::DATA | status::ESTIMATE;
    assert_eq!(r[0] & (want | status::STALE), want, "status {:#06x}", r[0]);
    assert!(u32_at(&r, 16) < 1500, "data age {} ms", u32_at(&r, 16));
    let h = client.read(1, 3, 0, 24).unwrap();
    assert_eq!(
        h[0] & (want | status::STALE),
        want,
        "FC 03 reads the same table"
    );
    // The missing node: configured, never heard from: stale, link down, no values.
    let r2 = client.read(2, 4, 0, 24).unwrap();
    assert_eq!(r2[0], status::STALE);
    assert_eq!((r2[1], r2[7], u32_at(&r2, 16)), (0xFFFF, 0x8000, u32::MAX));

    // The node goes away: its data ages, the stale bit comes after 3 s.
    let t_kill = Instant::now();
    let mut node = node;
    node.kill9();
    let w = client.run("watch", &["1".into(), "5".into(), "0.25".into()]);
    let samples: Vec<(f64, Vec<u16>)> = w["samples"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| (s["t"].as_f64().unwrap(), pymodbus::answer(s).unwrap()))
        .collect();
    println!(
        "stale node: {} samples over {:.1} s (the first {:.2} s after the kill); ages (ms) {:?}",
        samples.len(),
        samples.last().unwrap().0,
        t_kill.elapsed().as_secs_f64() - samples.last().unwrap().0,
        samples
            .iter()
            .map(|(_, r)| u32_at(r, 16))
            .collect::<Vec<_>>()
    );
    assert!(samples.len() >= 12, "{samples:?}");
    for (k, (t, r)) in samples.iter().enumerate() {
        let age = u32_at(r, 16);
        assert_eq!(
            r[0] & status::STALE != 0,
            age > 3000,
            "sample {k} at {t:.2} s: age {age} ms, status {:#06x}",
            r[0]
        );
        if k > 0 {
            // The age rises with the time between the samples (±150 ms).
            let (t0, r0) = &samples[k - 1];
            let expect = (t - t0) * 1000.0;
            let rose = f64::from(age) - f64::from(u32_at(r0, 16));
            assert!(
                (rose - expect).abs() < 150.0,
                "sample {k}: rose {rose} ms in {expect} ms"
            );
        }
    }
    assert_eq!(
        samples[0].1[0] & status::STALE,
        0,
        "fresh right after the kill"
    );
    let (_, last) = samples.last().unwrap();
    assert_ne!(last[0] & status::STALE, 0);
    assert_eq!(last[0] & status::LINK_UP, 0, "the link is down");
    assert_ne!(last[0] & status::DATA, 0, "the last values stay");
    // The frozen snapshot, register by register in its scales.
    let snap = gw.fleet.node(0).unwrap();
    assert!(!snap.link_up);
    let r = client.read(1, 3, 0, 24).unwrap();
    assert_matches(&r, &snap);

    // Registers that do not exist, a unit no node has, writes while read-only.
    assert_eq!(
        client.read(1, 4, 20, 10),
        Err(2),
        "20..29 crosses the end (23)"
    );
    assert_eq!(client.read(1, 3, 27, 1), Err(2));
    assert_eq!(client.read(1, 4, 1000, 2), Err(2));
    assert_eq!(client.read(9, 4, 0, 1), Err(0x0A), "no node has unit 9");
    assert_eq!(
        client.write(1, 23, 1, 6),
        Err(1),
        "read-only: illegal function"
    );
    assert_eq!(client.write(1, 23, 1, 16), Err(1));

    // 50 clients connected at once (a barrier), each then reading all 24
    // registers of both units 40 times.
    let p = client.run("poll", &["1,2".into(), "50".into(), "40".into()]);
    println!("50 clients: {p}");
    assert_eq!(p["failures"], serde_json::json!([]), "{p}");
    assert_eq!(p["answers"], 4000, "{p}");
    assert!(p["seconds"].as_f64().unwrap() < 20.0, "{p}");

    let sum = gw.stop();
    assert_eq!(sum.broker_connects, 0);
}

#[test]
fn with_commands_on_writing_1_to_the_ack_register_acknowledges_the_nodes_alarm() {
    let node = iced_node();
    let mut gw = Gateway::start(&[(&node.path, "n1")], "commands = true\nmax_clients = 2\n");
    let client = Client::new(gw.port);
    gw.wait(0, "the alarm", Duration::from_secs(30), |n| {
        n.reading.as_ref().is_some_and(|m| m.alarm)
    });
    let r = client.read(1, 4, 0, 1).unwrap();
    assert_eq!(r[0] & (status::ALARM | status::ALARM_ACKED), status::ALARM);
    // `max_clients = 2`: of 3 clients connected at once, the third evicts
    // one of the two silent before it (whose first read gets no answer);
    // the two others get all theirs.
    let p = client.run("poll", &["1".into(), "3".into(), "5".into()]);
    assert_eq!(
        (p["answers"].as_u64(), p["failed"].as_u64()),
        (Some(10), Some(1)),
        "{p}"
    );
    assert_eq!(
        client.write(1, 22, 1, 6),
        Err(2),
        "only alarm_ack is writable"
    );
    assert_eq!(client.write(1, 23, 2, 6), Err(3), "only 1 acknowledges");
    assert_eq!(client.write(2, 23, 1, 6), Err(0x0A), "no unit 2");
    let t0 = Instant::now();
    assert_eq!(client.write(1, 23, 1, 6), Ok(()));
    gw.wait(0, "the acknowledgement", Duration::from_secs(10), |n| {
        n.reading.as_ref().is_some_and(|m| m.alarm_acked)
    });
    println!(
        "acknowledged {:.2} s after the write was sent",
        t0.elapsed().as_secs_f64()
    );
    let r = client.read(1, 4, 0, 1).unwrap();
    assert_eq!(
        r[0] & (status::ALARM | status::ALARM_ACKED),
        status::ALARM | status::ALARM_ACKED,
        "the output stays on while ice remains, acknowledged"
    );
    gw.stop();
}

/// A raw Modbus TCP connection (std::net), for what a well-behaved client
/// library never sends.
struct Raw(std::net::TcpStream);

impl Raw {
    /// Connect to the gateway's server (retried while it starts).
    fn connect(port: u16) -> Raw {
        let t0 = Instant::now();
        loop {
            match std::net::TcpStream::connect(("127.0.0.1", port)) {
                Ok(s) => return Raw(s),
                Err(e) => assert!(t0.elapsed() < Duration::from_secs(10), "connect: {e}"),
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    fn send(&mut self, bytes: &[u8]) {
        use std::io::Write;
        self.0.write_all(bytes).unwrap();
    }

    /// Send `pdu` to `unit` as transaction `tid`.
    fn request(&mut self, tid: u16, unit: u8, pdu: &[u8]) {
        let mut adu = tid.to_be_bytes().to_vec();
        adu.extend([0, 0]);
        adu.extend(u16::try_from(pdu.len() + 1).unwrap().to_be_bytes());
        adu.push(unit);
        adu.extend(pdu);
        self.send(&adu);
    }

    /// The next answer's (transaction, unit, PDU); `None` when nothing
    /// comes within `within` (the connection stays open).
    fn answer(&mut self, within: Duration) -> Option<(u16, u8, Vec<u8>)> {
        use std::io::Read;
        self.0.set_read_timeout(Some(within)).unwrap();
        let mut h = [0u8; 7];
        match self.0.read_exact(&mut h) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return None,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => return None,
            Err(e) => panic!("the connection ended: {e}"),
        }
        let mut pdu = vec![0u8; usize::from(u16::from_be_bytes([h[4], h[5]])) - 1];
        self.0.read_exact(&mut pdu).unwrap();
        Some((u16::from_be_bytes([h[0], h[1]]), h[6], pdu))
    }

    /// How long until the server closes the connection (from `t0`), or
    /// `None` when it is still open `within` after `t0`.
    fn closed_after(&mut self, t0: Instant, within: Duration) -> Option<Duration> {
        use std::io::Read;
        let left = within
            .saturating_sub(t0.elapsed())
            .max(Duration::from_millis(1));
        self.0.set_read_timeout(Some(left)).unwrap();
        let mut b = [0u8; 64];
        match self.0.read(&mut b) {
            Ok(0) => Some(t0.elapsed()),
            Ok(n) => panic!("an answer of {n} bytes: {:02x?}", &b[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => Some(t0.elapsed()),
            Err(_) => None,
        }
    }
}

/// A read of 24 input registers from address 0.
const READ_ALL: [u8; 5] = [0x04, 0, 0, 0, 24];

#[test]
fn half_frames_huge_lengths_and_silence_are_closed_within_their_bounds() {
    let gw = Gateway::start(&[("/dev/does-not-exist", "n1")], "idle_timeout_s = 3\n");
    let silent = Raw::connect(gw.port);
    let t0 = Instant::now();
    let mut half_header = Raw::connect(gw.port);
    half_header.send(&[0, 1, 0, 0]);
    let mut half_pdu = Raw::connect(gw.port);
    half_pdu.send(&[0, 1, 0, 0, 0, 6, 1, 0x04, 0]);
    let mut huge = Raw::connect(gw.port);
    huge.send(&[0, 1, 0, 0, 0xFF, 0xFF, 1, 0x04]);
    // Each watched in its own thread from t0, while a master polling every
    // second stays connected past the idle bound.
    let watch = |mut c: Raw| std::thread::spawn(move || c.closed_after(t0, Duration::from_secs(6)));
    let [huge, half_header, half_pdu, silent] = [huge, half_header, half_pdu, silent].map(watch);
    let mut polling = Raw::connect(gw.port);
    for k in 0..5u16 {
        polling.request(k, 1, &READ_ALL);
        let (tid, unit, pdu) = polling.answer(Duration::from_secs(2)).unwrap();
        assert_eq!((tid, unit, pdu[..2].to_vec()), (k, 1, vec![4, 48]));
        std::thread::sleep(Duration::from_millis(900));
    }
    let [huge_s, header_s, pdu_s, silent_s] =
        [huge, half_header, half_pdu, silent].map(|t| t.join().unwrap());
    println!(
        "closed after: MBAP length 65535 {huge_s:?}, half header {header_s:?}, half PDU \
         {pdu_s:?}, silent {silent_s:?}"
    );
    assert!(
        huge_s.unwrap() < Duration::from_millis(500),
        "length 65535: closed at once"
    );
    for (what, s) in [("half header", header_s), ("half PDU", pdu_s)] {
        let s = s.unwrap().as_secs_f64();
        assert!((1.9..2.6).contains(&s), "{what}: {s} s (frame timeout 2 s)");
    }
    let s = silent_s.unwrap().as_secs_f64();
    assert!((2.9..3.6).contains(&s), "silent: {s} s (idle timeout 3 s)");
    // The polling master was never closed.
    polling.request(9, 1, &READ_ALL);
    assert_eq!(polling.answer(Duration::from_secs(2)).unwrap().0, 9);
}

#[test]
fn silent_connections_at_max_clients_do_not_lock_out_a_new_master() {
    let gw = Gateway::start(&[("/dev/does-not-exist", "n1")], "max_clients = 3\n");
    let mut first = Raw::connect(gw.port);
    first.request(1, 1, &READ_ALL);
    assert!(first.answer(Duration::from_secs(2)).is_some());
    // Two silent connections take the other places.
    let mut silent: Vec<Raw> = (0..2).map(|_| Raw::connect(gw.port)).collect();
    std::thread::sleep(Duration::from_millis(200));
    let t0 = Instant::now();
    let mut master = Raw::connect(gw.port);
    master.request(7, 1, &READ_ALL);
    let (tid, unit, pdu) = master.answer(Duration::from_secs(2)).unwrap();
    assert_eq!((tid, unit, pdu.len()), (7, 1, 2 + 48));
    // The earliest silent connection made room, not `first`, which
    // connected before it but asked something.
    assert!(silent[0].closed_after(t0, Duration::from_secs(1)).is_some());
    let t1 = Instant::now();
    assert_eq!(silent[1].closed_after(t1, Duration::from_millis(200)), None);
    first.request(2, 1, &READ_ALL);
    assert_eq!(first.answer(Duration::from_secs(2)).unwrap().0, 2);
    // A request on a place is answered on it.
    silent[1].request(8, 1, &READ_ALL);
    assert_eq!(silent[1].answer(Duration::from_secs(2)).unwrap().0, 8);
}

#[test]
fn sixty_four_silent_connections_do_not_lock_out_a_65th_master_at_the_defaults() {
    let gw = Gateway::start(&[("/dev/does-not-exist", "n1")], "");
    let mut silent: Vec<Raw> = (0..64).map(|_| Raw::connect(gw.port)).collect();
    std::thread::sleep(Duration::from_millis(300));
    let t0 = Instant::now();
    let mut master = Raw::connect(gw.port);
    master.request(65, 1, &READ_ALL);
    let (tid, unit, pdu) = master.answer(Duration::from_secs(2)).unwrap();
    println!(
        "the 65th master answered {:?} after connecting",
        t0.elapsed()
    );
    assert_eq!((tid, unit, pdu.len()), (65, 1, 2 + 48));
    // The first silent one made room; the others keep their places.
    assert!(silent[0].closed_after(t0, Duration::from_secs(1)).is_some());
    let t1 = Instant::now();
    assert_eq!(
        silent[63].closed_after(t1, Duration::from_millis(200)),
        None
    );
    silent[63].request(9, 1, &READ_ALL);
    assert_eq!(silent[63].answer(Duration::from_secs(2)).unwrap().0, 9);
}

#[test]
fn broadcasts_are_never_answered_and_malformed_requests_get_exceptions_not_a_closed_connection() {
    let gw = Gateway::start(&[("/dev/does-not-exist", "n1")], "commands = true\n");
    let mut c = Raw::connect(gw.port);
    let quiet = Duration::from_millis(400);
    // Unit 0: a read, a write, a function the gateway lacks: no answer.
    c.request(1, 0, &READ_ALL);
    c.request(2, 0, &[0x06, 0, 23, 0, 1]);
    c.request(3, 0, &[0x2B, 0x0E, 1, 0]);
    assert_eq!(c.answer(quiet), None);
    let mut fc16_124 = vec![0x10, 0, 23, 0, 124, 248];
    fc16_124.extend([0u8; 248]);
    let cases: [(&str, Vec<u8>, [u8; 2]); 7] = [
        (
            "an exception code as a function",
            vec![0x81, 0, 0, 0, 1],
            [0x81, 1],
        ),
        ("function 0xC3", vec![0xC3], [0xC3, 1]),
        ("a truncated FC 03", vec![0x03, 0, 0, 0], [0x83, 3]),
        (
            "FC 04 with a trailing byte",
            vec![0x04, 0, 0, 0, 1, 0],
            [0x84, 3],
        ),
        (
            "FC 06 with a trailing byte",
            vec![0x06, 0, 23, 0, 1, 0],
            [0x86, 3],
        ),
        ("FC 16 of 124 registers", fc16_124, [0x90, 3]),
        (
            "FC 16 byte count 3 for 1 register",
            vec![0x10, 0, 23, 0, 1, 3, 0, 1, 0],
            [0x90, 3],
        ),
    ];
    for (k, (what, pdu, want)) in cases.iter().enumerate() {
        let tid = 100 + u16::try_from(k).unwrap();
        c.request(tid, 1, pdu);
        let got = c.answer(Duration::from_secs(2));
        assert_eq!(got, Some((tid, 1, want.to_vec())), "{what}");
    }
    // The connection still serves.
    c.request(200, 1, &READ_ALL);
    let (tid, _, pdu) = c.answer(Duration::from_secs(2)).unwrap();
    assert_eq!((tid, pdu.len()), (200, 50));
}
