//! Helpers of the gateway tests and the load benchmark: a real Mosquitto
//! broker on a free loopback port, an MQTT subscriber that records every
//! message, virtual nodes on pseudo-terminals, `fois-gateway` child
//! processes, test certificates, and the seq bookkeeping that says whether
//! every frame arrived.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

pub mod ha_snapshot;
pub mod home_assistant;
pub mod pki;
pub mod pymodbus;
pub mod vnode;
#[allow(unused_imports)] // the load benchmark serves its nodes itself
pub use vnode::{NodeProc, Scene};

/// The gateway binary.
pub const BIN: &str = env!("CARGO_BIN_EXE_fois-gateway");

/// Where Debian puts the broker.
pub const MOSQUITTO_PATHS: [&str; 3] = [
    "/usr/sbin/mosquitto",
    "/usr/bin/mosquitto",
    "/usr/local/sbin/mosquitto",
];

/// The broker binary; panics with the install command when it is missing
/// (these tests fail, they never skip).
pub fn mosquitto_bin() -> PathBuf {
    MOSQUITTO_PATHS
        .iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
        .unwrap_or_else(|| {
            panic!(
                "mosquitto is not installed (looked in {MOSQUITTO_PATHS:?}): the gateway tests \
                 need a real broker; install it with `apt-get install mosquitto mosquitto-clients` \
                 (`cargo xtask ci` does)"
            )
        })
}

/// A tool of mosquitto-clients (`mosquitto_passwd`, `mosquitto_sub`);
/// panics with the install command when missing.
pub fn mosquitto_tool(name: &str) -> PathBuf {
    ["/usr/bin", "/usr/local/bin", "/usr/sbin"]
        .iter()
        .map(|d| Path::new(d).join(name))
        .find(|p| p.exists())
        .unwrap_or_else(|| {
            panic!(
                "{name} is not installed: install `mosquitto mosquitto-clients` \
                 (apt-get install mosquitto mosquitto-clients)"
            )
        })
}

/// A free TCP port on 127.0.0.1 (bound, then released).
pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free loopback port")
}

/// A Mosquitto broker, killed on drop.
pub struct Broker {
    child: Option<Child>,
    /// The plain listener (anonymous unless the config says otherwise).
    pub port: u16,
    /// Its directory (config, log, persistence).
    pub dir: PathBuf,
    conf: PathBuf,
}

impl Broker {
    /// Start with `extra` config lines after a plain listener on a free
    /// port (`{port}` in `extra` is replaced by it, `{dir}` by the
    /// broker's directory). No persistence unless `extra` says so.
    pub fn start(dir: &Path, extra: &str) -> Broker {
        let bin = mosquitto_bin();
        for _attempt in 0..5 {
            let port = free_port();
            let conf = dir.join("mosquitto.conf");
            let body = extra
                .replace("{port}", &port.to_string())
                .replace("{dir}", &dir.display().to_string());
            let has_listener = body.contains("listener ");
            // As root, mosquitto drops to the `mosquitto` user, which cannot
            // read the test's private files (TLS keys): stay who we are.
            // SAFETY: geteuid has no preconditions.
            let body = if unsafe { libc::geteuid() } == 0 {
                format!("user root\n{body}")
            } else {
                body
            };
            let text = format!(
                "{}{}\nmax_queued_messages 1000000\nmax_inflight_messages 100\n",
                if has_listener {
                    String::new()
                } else {
                    format!("listener {port} 127.0.0.1\nallow_anonymous true\n")
                },
                body
            );
            std::fs::write(&conf, text).unwrap();
            let mut b = Broker {
                child: None,
                port,
                dir: dir.to_path_buf(),
                conf,
            };
            if b.spawn(&bin) {
                return b;
            }
        }
        panic!("mosquitto did not start: {}", broker_log(dir));
    }

    fn spawn(&mut self, bin: &Path) -> bool {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.dir.join("mosquitto.log"))
            .unwrap();
        let mut child = Command::new(bin)
            .arg("-c")
            .arg(&self.conf)
            .stdout(Stdio::from(log.try_clone().unwrap()))
            .stderr(Stdio::from(log))
            .spawn()
            .expect("spawn mosquitto");
        let t0 = Instant::now();
        while t0.elapsed() < Duration::from_secs(10) {
            if TcpStream::connect(("127.0.0.1", self.port)).is_ok() {
                self.child = Some(child);
                return true;
            }
            if let Ok(Some(_)) = child.try_wait() {
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill();
        let _ = child.wait();
        false
    }

    /// Stop it (SIGTERM: a broker with persistence saves its sessions).
    pub fn stop(&mut self) {
        if let Some(mut c) = self.child.take() {
            // SAFETY: signalling our own child process.
            unsafe {
                libc::kill(c.id() as i32, libc::SIGTERM);
            }
            let _ = c.wait();
        }
    }

    /// Start it again on the same port.
    pub fn restart(&mut self) {
        let bin = mosquitto_bin();
        let t0 = Instant::now();
        // The port may sit in TIME_WAIT for a moment.
        while !self.spawn(&bin) {
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "mosquitto did not restart: {}",
                broker_log(&self.dir)
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

fn broker_log(dir: &Path) -> String {
    std::fs::read_to_string(dir.join("mosquitto.log")).unwrap_or_default()
}

impl Drop for Broker {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// One message a subscriber got.
#[derive(Debug, Clone)]
pub struct Msg {
    /// Topic.
    pub topic: String,
    /// Payload.
    pub payload: Vec<u8>,
    /// Delivered as retained.
    pub retain: bool,
    /// When it arrived.
    pub at: Instant,
}

impl Msg {
    /// The payload as JSON (panics with the text if it is not).
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.payload).unwrap_or_else(|e| {
            panic!(
                "{} is not JSON ({e}): {}",
                self.topic,
                String::from_utf8_lossy(&self.payload)
            )
        })
    }

    /// The payload as text.
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.payload).into_owned()
    }
}

/// How a subscriber connects.
#[derive(Debug, Clone, Default)]
pub struct SubOptions {
    /// Keep the session across disconnects (and broker restarts with
    /// persistence): the broker queues what arrives meanwhile.
    pub persistent: bool,
    /// User name and password.
    pub credentials: Option<(String, String)>,
}

/// An MQTT subscriber (rumqttc) recording every message, QoS 1.
pub struct Subscriber {
    msgs: Arc<Mutex<Vec<Msg>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
    /// A client to publish with (commands).
    pub client: rumqttc::Client,
}

impl Subscriber {
    /// Connect to `port`, subscribe to `filters`, return once subscribed.
    pub fn start(port: u16, id: &str, filters: &[&str], o: SubOptions) -> Subscriber {
        let mut opts = rumqttc::MqttOptions::new(id, "127.0.0.1", port);
        opts.set_keep_alive(Duration::from_secs(5));
        opts.set_clean_session(!o.persistent);
        opts.set_max_packet_size(1 << 20, 1 << 20);
        opts.set_inflight(200);
        if let Some((u, p)) = &o.credentials {
            opts.set_credentials(u.clone(), p.clone());
        }
        let (client, mut conn) = rumqttc::Client::new(opts, 10_000);
        let msgs = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let filters: Vec<String> = filters.iter().map(|s| s.to_string()).collect();
        let (m2, s2, c2) = (msgs.clone(), stop.clone(), client.clone());
        let thread = std::thread::spawn(move || {
            for ev in conn.iter() {
                if s2.load(Ordering::Relaxed) {
                    break;
                }
                match ev {
                    Ok(rumqttc::Event::Incoming(rumqttc::Packet::ConnAck(_))) => {
                        for f in &filters {
                            let _ = c2.try_subscribe(f.clone(), rumqttc::QoS::AtLeastOnce);
                        }
                    }
                    Ok(rumqttc::Event::Incoming(rumqttc::Packet::SubAck(_))) => {
                        let _ = ready_tx.send(());
                    }
                    Ok(rumqttc::Event::Incoming(rumqttc::Packet::Publish(p))) => {
                        m2.lock().unwrap().push(Msg {
                            topic: p.topic.clone(),
                            payload: p.payload.to_vec(),
                            retain: p.retain,
                            at: Instant::now(),
                        });
                    }
                    Ok(_) => {}
                    Err(_) => std::thread::sleep(Duration::from_millis(100)),
                }
            }
        });
        ready_rx
            .recv_timeout(Duration::from_secs(10))
            .expect("the subscriber connected and subscribed");
        Subscriber {
            msgs,
            stop,
            thread: Some(thread),
            client,
        }
    }

    /// Everything so far.
    pub fn messages(&self) -> Vec<Msg> {
        self.msgs.lock().unwrap().clone()
    }

    /// Messages so far on `topic`.
    pub fn on(&self, topic: &str) -> Vec<Msg> {
        self.messages()
            .into_iter()
            .filter(|m| m.topic == topic)
            .collect()
    }

    /// Count of messages so far.
    pub fn count(&self) -> usize {
        self.msgs.lock().unwrap().len()
    }

    /// Wait until `pred` holds on the messages (panics after `timeout`).
    pub fn wait_for(&self, what: &str, timeout: Duration, pred: impl Fn(&[Msg]) -> bool) {
        let t0 = Instant::now();
        loop {
            if pred(&self.msgs.lock().unwrap()) {
                return;
            }
            assert!(t0.elapsed() < timeout, "timed out waiting for {what}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Wait until no message arrived for `quiet` (at most `timeout`).
    pub fn settle(&self, quiet: Duration, timeout: Duration) {
        let t0 = Instant::now();
        let mut n = self.count();
        let mut since = Instant::now();
        while t0.elapsed() < timeout {
            std::thread::sleep(Duration::from_millis(50));
            let m = self.count();
            if m != n {
                n = m;
                since = Instant::now();
            } else if since.elapsed() >= quiet {
                return;
            }
        }
    }

    /// Publish (commands).
    pub fn publish(&self, topic: &str, payload: &str, retain: bool) {
        self.client
            .publish(topic, rumqttc::QoS::AtLeastOnce, retain, payload.as_bytes())
            .unwrap();
    }
}

impl Drop for Subscriber {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.client.try_disconnect();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A `fois-gateway`, its stdout and stderr in a file; killed on drop.
pub struct GatewayProc {
    child: Option<Child>,
    /// Its output file.
    pub out: PathBuf,
}

impl GatewayProc {
    /// `fois-gateway --config CONFIG ARGS...`.
    pub fn start(config: &Path, args: &[&str], out: &Path) -> GatewayProc {
        let f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(out)
            .unwrap();
        // Its log lines in the output file, whatever the environment (a CI
        // run under systemd has JOURNAL_STREAM and maybe a RUST_LOG).
        let child = Command::new(BIN)
            .env_remove("JOURNAL_STREAM")
            .env_remove("RUST_LOG")
            .arg("--config")
            .arg(config)
            .args(["--status-interval-s", "1"])
            .args(args)
            .stdout(Stdio::from(f.try_clone().unwrap()))
            .stderr(Stdio::from(f))
            .spawn()
            .expect("spawn gateway");
        GatewayProc {
            child: Some(child),
            out: out.to_path_buf(),
        }
    }

    /// Process id.
    pub fn pid(&self) -> u32 {
        self.child.as_ref().map_or(0, |c| c.id())
    }

    /// Ctrl-C, then wait; the exit code.
    pub fn interrupt(&mut self) -> i32 {
        let Some(mut c) = self.child.take() else {
            return -1;
        };
        // SAFETY: signalling our own child process.
        unsafe {
            libc::kill(c.id() as i32, libc::SIGINT);
        }
        let t0 = Instant::now();
        loop {
            if let Ok(Some(st)) = c.try_wait() {
                return st.code().unwrap_or(-1);
            }
            if t0.elapsed() > Duration::from_secs(15) {
                let _ = c.kill();
                let _ = c.wait();
                panic!(
                    "the gateway did not stop within 15 s of Ctrl-C:\n{}",
                    self.output()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Wait until it exits by itself; its exit code (panics after `timeout`).
    pub fn wait_exit(&mut self, timeout: Duration) -> i32 {
        let Some(c) = self.child.as_mut() else {
            return -1;
        };
        let t0 = Instant::now();
        loop {
            if let Ok(Some(st)) = c.try_wait() {
                self.child = None;
                return st.code().unwrap_or(-1);
            }
            assert!(
                t0.elapsed() < timeout,
                "the gateway did not exit within {timeout:?}:\n{}",
                self.output()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// SIGKILL.
    pub fn kill9(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    /// Everything it printed so far.
    pub fn output(&self) -> String {
        std::fs::read_to_string(&self.out).unwrap_or_default()
    }

    /// Wait until its output contains `needle`.
    pub fn wait_output(&self, needle: &str, timeout: Duration) {
        let t0 = Instant::now();
        while !self.output().contains(needle) {
            assert!(
                t0.elapsed() < timeout,
                "the gateway did not print {needle:?} within {timeout:?}:\n{}",
                self.output()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for GatewayProc {
    fn drop(&mut self) {
        self.kill9();
    }
}

/// A gateway config: broker port, queue dir, the nodes as (port, name),
/// and extra TOML appended.
pub fn gateway_toml(broker_port: u16, queue: &Path, nodes: &[(&str, &str)], extra: &str) -> String {
    let mut s = format!(
        "name = \"gw\"\n[broker]\nhost = \"127.0.0.1\"\nport = {broker_port}\nkeep_alive_s = 2\n\
         [publish]\nmeasurement_interval_ms = 0\noffline_measurement_interval_ms = 0\n\
         [queue]\ndir = \"{}\"\n",
        queue.display()
    );
    s.push_str(extra);
    s.push('\n');
    for (port, name) in nodes {
        s.push_str(&format!("[[node]]\nport = \"{port}\"\nname = \"{name}\"\n"));
    }
    s
}

/// Write [`gateway_toml`] to `dir/<file>.toml` (queue in `dir/q`); its path.
pub fn gateway_config(
    dir: &Path,
    file: &str,
    broker_port: u16,
    nodes: &[(&str, &str)],
    extra: &str,
) -> PathBuf {
    let path = dir.join(format!("{file}.toml"));
    let text = gateway_toml(broker_port, &dir.join("q"), nodes, extra);
    std::fs::write(&path, text).unwrap();
    path
}

/// What one node's published records say.
#[derive(Debug, Default, Clone)]
pub struct NodeRecords {
    /// Measurement seq -> copies received.
    pub measurements: BTreeMap<u32, usize>,
    /// Node event seq -> (kind, copies).
    pub events: BTreeMap<u32, (String, usize)>,
    /// Gateway events (kind, detail).
    pub gateway_events: Vec<(String, String)>,
    /// host_unix_ms of every node record.
    pub host_ms: Vec<u64>,
}

impl NodeRecords {
    /// Collect node `name`'s measurements and events under `fois/gw`.
    pub fn of(msgs: &[Msg], name: &str) -> NodeRecords {
        let mut r = NodeRecords::default();
        let mt = format!("fois/gw/{name}/measurement");
        let et = format!("fois/gw/{name}/event");
        for m in msgs {
            if m.topic == mt {
                let v = m.json();
                let seq = v["seq"].as_u64().expect("seq") as u32;
                *r.measurements.entry(seq).or_default() += 1;
                r.host_ms.push(v["host_unix_ms"].as_u64().unwrap());
            } else if m.topic == et {
                let v = m.json();
                let kind = v["kind"].as_str().unwrap_or("").to_string();
                if v["source"] == "node" {
                    let seq = v["seq"].as_u64().expect("seq") as u32;
                    let e = r.events.entry(seq).or_insert((kind, 0));
                    e.1 += 1;
                    r.host_ms.push(v["host_unix_ms"].as_u64().unwrap());
                } else {
                    r.gateway_events
                        .push((kind, v["detail"].as_str().unwrap_or("").to_string()));
                }
            }
        }
        r
    }

    /// Every seq of a node record (measurement or event), sorted.
    pub fn seqs(&self) -> Vec<u32> {
        let mut v: Vec<u32> = self
            .measurements
            .keys()
            .chain(self.events.keys())
            .copied()
            .collect();
        v.sort_unstable();
        v.dedup();
        v
    }

    /// Seqs missing between the first and the last record.
    pub fn holes(&self) -> Vec<u32> {
        let s = self.seqs();
        let mut out = vec![];
        for w in s.windows(2) {
            out.extend(w[0] + 1..w[1]);
        }
        out
    }

    /// Records received more than once.
    pub fn duplicates(&self) -> usize {
        self.measurements.values().map(|c| c - 1).sum::<usize>()
            + self.events.values().map(|(_, c)| c - 1).sum::<usize>()
    }

    /// Distinct records.
    pub fn distinct(&self) -> usize {
        self.measurements.len() + self.events.len()
    }
}
