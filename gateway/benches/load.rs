//! Load figure of `fois-gateway`: how many nodes at 10 Hz one gateway
//! carries with no loss, its CPU (% of one core) and memory.
//!
//! ```sh
//! cargo bench -p fois-gateway --bench load                    # 50, 100, 200, 400 nodes, 20 s each
//! FOIS_GW_BENCH_NODES=200,600 FOIS_GW_BENCH_SECONDS=30 cargo bench -p fois-gateway --bench load
//! ```
//!
//! For each fleet size N: a real Mosquitto broker on a free loopback port;
//! N virtual nodes (the firmware's own `Node` on simulated hardware, one
//! shared ray-traced environment, real time, 10 frames/s each) served on N
//! pseudo-terminals by one feeder thread of this process; the real
//! `fois-gateway` binary as a child process reading the N ptys and
//! publishing every measurement (`measurement_interval_ms = 0`, QoS 1
//! through its disk queue); an MQTT subscriber (QoS 1) in this process.
//! After all nodes are online, a measuring window: every measurement frame
//! the nodes write in it is looked for at the subscriber (by node and seq);
//! the gateway's CPU time and RSS come from /proc. Not a timed unit test:
//! it prints a table.

// The gateway tests' helpers: test code, where a failed setup panics with
// its reason (unwrap and expect are assertions there).
#[allow(clippy::unwrap_used, clippy::expect_used)]
#[path = "../tests/support/mod.rs"]
mod support;

use std::collections::HashSet;
use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use fois_protocol::{DeviceFrame, DeviceMsg, FrameDecoder, MAX_FRAME};
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};
use serialport::SerialPort;
use support::*;

struct Fed {
    node: VirtualNode,
    master: serialport::TTYPort,
    _slave: serialport::TTYPort,
    path: String,
    decoder: Box<FrameDecoder<MAX_FRAME>>,
}

/// Per node: measurement seqs written during the window.
type Written = Arc<Mutex<Vec<Vec<u32>>>>;

/// Serve every node on its pty in real time until `stop`; while `window`
/// is set, record the seq of every measurement frame written in full.
fn feed(
    mut nodes: Vec<Fed>,
    window: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    written: Written,
) -> (u64, u64) {
    let t0 = Instant::now();
    let mut buf = [0u8; 512];
    let (mut frames, mut incomplete) = (0u64, 0u64);
    while !stop.load(Ordering::Relaxed) {
        let now_ns = t0.elapsed().as_nanos() as u64;
        let in_window = window.load(Ordering::Relaxed);
        for (k, f) in nodes.iter_mut().enumerate() {
            let Fed {
                node,
                master,
                decoder,
                ..
            } = f;
            let mut out: Vec<u8> = Vec::new();
            if let Ok(n) = master.read(&mut buf)
                && n > 0
            {
                node.handle_rx(&buf[..n], &mut |b: &[u8]| out.extend_from_slice(b));
            }
            node.advance_to(now_ns, &mut |b: &[u8]| out.extend_from_slice(b));
            if out.is_empty() {
                continue;
            }
            let mut off = 0;
            while off < out.len() {
                match master.write(&out[off..]) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => off += n,
                }
            }
            frames += 1;
            if off < out.len() {
                incomplete += 1;
            }
            if in_window {
                let mut seqs = vec![];
                decoder.feed::<DeviceFrame>(&out[..off], |r| {
                    if let Ok(DeviceFrame {
                        seq,
                        msg:
                            DeviceMsg::Measurement(_)
                            | DeviceMsg::MeasurementV2(_)
                            | DeviceMsg::MeasurementV3(_),
                    }) = r
                    {
                        seqs.push(seq);
                    }
                });
                // A frame cut short ends with no delimiter: drop its rest.
                if off < out.len() {
                    decoder.reset();
                }
                // A poisoned lock still holds the seqs recorded so far.
                written.lock().unwrap_or_else(|e| e.into_inner())[k].extend(seqs);
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    (frames, incomplete)
}

fn proc_cpu_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // Fields after the command name (which may contain spaces).
    let rest = stat.rsplit_once(')').map(|x| x.1).unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let utime: u64 = f.get(11).and_then(|s| s.parse().ok()).unwrap_or(0);
    let stime: u64 = f.get(12).and_then(|s| s.parse().ok()).unwrap_or(0);
    utime + stime
}

fn proc_status_kib(pid: u32, key: &str) -> u64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .unwrap_or_default()
        .lines()
        .find(|l| l.starts_with(key))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

fn threads_of(pid: u32) -> u64 {
    proc_status_kib(pid, "Threads:")
}

struct Row {
    nodes: usize,
    window_s: f64,
    written: usize,
    received: usize,
    lost: usize,
    duplicates: usize,
    gw_cpu_pct: f64,
    broker_cpu_pct: f64,
    rss_mib: f64,
    hwm_mib: f64,
    incomplete: u64,
}

fn run(env: &Arc<Environment>, n: usize, window_s: f64) -> anyhow::Result<Row> {
    let dir = tempfile::tempdir()?;
    let broker = Broker::start(dir.path(), "");
    let broker_pid = std::fs::read_dir("/proc")
        .ok()
        .and_then(|_| {
            // The broker's pid: the newest mosquitto child with our config.
            let conf = dir.path().join("mosquitto.conf").display().to_string();
            std::fs::read_dir("/proc")
                .ok()?
                .filter_map(|e| e.ok())
                .find_map(|e| {
                    let pid: u32 = e.file_name().to_str()?.parse().ok()?;
                    let cmd = std::fs::read_to_string(format!("/proc/{pid}/cmdline")).ok()?;
                    cmd.contains(&conf).then_some(pid)
                })
        })
        .unwrap_or(0);
    let sub = Subscriber::start(
        broker.port,
        "bench-sub",
        &["fois/gw/+/measurement"],
        SubOptions::default(),
    );
    let mut fed = Vec::new();
    for k in 0..n {
        let (mut master, slave) = serialport::TTYPort::pair().context("open a pty pair")?;
        master.set_timeout(Duration::ZERO)?;
        let path = slave.name().context("the pty has no name")?;
        let node = VirtualNode::new(
            env.clone(),
            NodeOptions {
                seed: k as u64 + 1,
                ..NodeOptions::default()
            },
        );
        fed.push(Fed {
            node,
            master,
            _slave: slave,
            path,
            decoder: Box::default(),
        });
    }
    let names: Vec<String> = (0..n).map(|k| format!("n{k}")).collect();
    let nodes: Vec<(&str, &str)> = fed
        .iter()
        .zip(&names)
        .map(|(f, name)| (f.path.as_str(), name.as_str()))
        .collect();
    let cfg = dir.path().join("gw.toml");
    std::fs::write(
        &cfg,
        gateway_toml(
            broker.port,
            &dir.path().join("q"),
            &nodes,
            "[homeassistant]\nenabled = false\n",
        ),
    )?;
    let window = Arc::new(AtomicBool::new(false));
    let stop = Arc::new(AtomicBool::new(false));
    let written: Written = Arc::new(Mutex::new(vec![Vec::new(); n]));
    let (w2, s2, wr2) = (window.clone(), stop.clone(), written.clone());
    let feeder = std::thread::spawn(move || feed(fed, w2, s2, wr2));
    let mut gw = GatewayProc::start(&cfg, &[], &dir.path().join("gw.out"));
    // All nodes online.
    let t0 = Instant::now();
    while gw.output().matches(": connected (").count() < n {
        anyhow::ensure!(
            t0.elapsed() < Duration::from_secs(60),
            "only {} of {n} nodes connected",
            gw.output().matches(": connected (").count()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_secs(2));
    let pid = gw.pid();
    let hz = 100.0; // USER_HZ on Linux
    let (c0, b0, w0) = (
        proc_cpu_ticks(pid),
        proc_cpu_ticks(broker_pid),
        Instant::now(),
    );
    window.store(true, Ordering::Relaxed);
    std::thread::sleep(Duration::from_secs_f64(window_s));
    window.store(false, Ordering::Relaxed);
    let (c1, b1, secs) = (
        proc_cpu_ticks(pid),
        proc_cpu_ticks(broker_pid),
        w0.elapsed().as_secs_f64(),
    );
    let rss = proc_status_kib(pid, "VmRSS:") as f64 / 1024.0;
    let hwm = proc_status_kib(pid, "VmHWM:") as f64 / 1024.0;
    let threads = threads_of(pid);
    // Let the last frames through, then stop everything.
    std::thread::sleep(Duration::from_secs(2));
    sub.settle(Duration::from_millis(800), Duration::from_secs(30));
    stop.store(true, Ordering::Relaxed);
    let (_frames, incomplete) = feeder
        .join()
        .map_err(|_| anyhow::anyhow!("the feeder thread panicked"))?;
    let _ = gw.interrupt();
    let msgs = sub.messages();
    let written = written.lock().unwrap_or_else(|e| e.into_inner());
    let (mut total_w, mut total_r, mut lost, mut dups) = (0, 0, 0, 0);
    for (k, name) in names.iter().enumerate() {
        let r = NodeRecords::of(&msgs, name);
        let got: HashSet<u32> = r.measurements.keys().copied().collect();
        total_w += written[k].len();
        let found = written[k].iter().filter(|s| got.contains(s)).count();
        total_r += found;
        lost += written[k].len() - found;
        dups += r.duplicates();
    }
    eprintln!("  {n} nodes: gateway {threads} threads");
    Ok(Row {
        nodes: n,
        window_s: secs,
        written: total_w,
        received: total_r,
        lost,
        duplicates: dups,
        gw_cpu_pct: (c1 - c0) as f64 / hz / secs * 100.0,
        broker_cpu_pct: (b1.saturating_sub(b0)) as f64 / hz / secs * 100.0,
        rss_mib: rss,
        hwm_mib: hwm,
        incomplete,
    })
}

fn main() -> anyhow::Result<()> {
    let counts: Vec<usize> = std::env::var("FOIS_GW_BENCH_NODES")
        .unwrap_or_else(|_| "50,100,200,400".into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let window_s: f64 = std::env::var("FOIS_GW_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20.0);
    eprintln!("ray-tracing the shared environment ...");
    let env = Arc::new(Environment::new(
        Timeline::new(vec![Segment::new(f64::INFINITY, Cover::Dry).temp(-5.0)]),
        fois_sim::SensorKind::B,
        1,
    ));
    println!(
        "| nodes | window s | measurements sent | received | lost | duplicates | msg/s | gateway CPU % of one core | broker CPU % | gateway RSS MiB (peak) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for n in counts {
        let r = run(&env, n, window_s)?;
        println!(
            "| {} | {:.1} | {} | {} | {} | {} | {:.0} | {:.1} | {:.1} | {:.1} ({:.1}) |",
            r.nodes,
            r.window_s,
            r.written,
            r.received,
            r.lost,
            r.duplicates,
            r.received as f64 / r.window_s,
            r.gw_cpu_pct,
            r.broker_cpu_pct,
            r.rss_mib,
            r.hwm_mib
        );
        if r.incomplete > 0 {
            println!(
                "  ({} writes to a pty were cut short: the gateway did not read in time)",
                r.incomplete
            );
        }
        let _ = std::io::stdout().flush();
    }
    Ok(())
}
