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
    assert_eq!(client.read(1, 3, 24, 1), Err(2));
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
    // `max_clients = 2`: of 3 clients connected at once, one is closed at
    // once (its first read gets no answer); the two others get all theirs.
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
