//! The MQTT side: one task owns the node states, the disk queue and the
//! `rumqttc` client; a second task drives the client's event loop and
//! forwards its events. Events and rate-limited measurements are appended to
//! the queue and published (QoS 1) from it in order; a record leaves the
//! queue when its PUBACK arrives. Retained messages (availability, info,
//! state, discovery) are not queued: they are re-published from memory after
//! every (re)connection, since a broker without persistence forgets them.
//!
//! Matching PUBACKs to records: the event loop reports every publish it
//! sends as `Outgoing::Publish(pkid)`, in the order the requests were made;
//! a FIFO of "which record was that" turns the packet id into a record
//! index. At most [`WINDOW`] records are unacknowledged at once, fewer than
//! the client's packet-id space ([`INFLIGHT`]), so a packet id is never
//! reused while in flight. On a lost connection everything unacknowledged
//! is simply sent again from the queue after the reconnect (clean session:
//! the client's own replay buffer is discarded first, so nothing is sent
//! twice by the gateway itself).

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use fois_protocol::{DeviceMsg, Hello};
use rumqttc::{
    AsyncClient, ConnectionError, Event, EventLoop, Incoming, LastWill, MqttOptions, Outgoing, QoS,
    TlsConfiguration, Transport,
};
use tokio::sync::mpsc;

use crate::link::SeqEvent;
use crate::text::hello_text;
use crate::timefmt::{iso_utc, unix_ms_now};

use super::config::{BrokerConfig, GatewayConfig, NodeSpec, TlsConfig};
use super::discovery;
use super::node::{NodeCommand, NodeMsg, NodeUpdate};
use super::payload::{
    CommandResultJson, EventJson, InfoJson, LinkEventJson, MeasurementJson, StateJson, StatusJson,
    unique_id_hex,
};
use super::queue::{Queue, QueueLimits, Record};
use super::topics::Topics;

/// Records published and not yet acknowledged, at most.
pub const WINDOW: usize = 512;
/// The client's packet-id space (> [`WINDOW`]: see the module doc).
pub const INFLIGHT: u16 = 1024;
/// Wait before reconnecting to the broker.
pub const RECONNECT_DELAY: Duration = Duration::from_secs(1);
/// The publisher's housekeeping period (queue flush, state, status).
pub const TICK: Duration = Duration::from_millis(100);
/// A thickness change below this never re-publishes the state.
pub const THICKNESS_STEP_MM: f64 = 0.01;

/// Where log lines go.
#[derive(Debug, Clone, Copy)]
pub struct Log {
    /// Print nothing.
    pub quiet: bool,
}

impl Log {
    /// One line with the host time.
    pub fn say(&self, msg: &str) {
        if !self.quiet {
            println!("{} {msg}", iso_utc(unix_ms_now()));
        }
    }
}

/// Totals at the end of a run.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GatewaySummary {
    /// Frames received from all nodes.
    pub frames: u64,
    /// Records appended to the queue.
    pub records_queued: u64,
    /// Records acknowledged by the broker.
    pub records_acked: u64,
    /// Records left in the queue at exit.
    pub records_pending: u64,
    /// Records dropped by the queue's bound (ever).
    pub records_dropped: u64,
    /// Broker connections made.
    pub broker_connects: u64,
    /// Frames lost on the serial links.
    pub frames_lost: u64,
    /// Records the disk queue could not take (published live instead).
    pub records_unqueued: u64,
}

struct NodeSlot {
    spec: NodeSpec,
    name: Option<String>,
    hello: Option<Hello>,
    online: bool,
    last_state: Option<StateJson>,
    published_state: Option<(StateJson, Instant)>,
    last_meas_uptime: Option<u64>,
    has_estimate: bool,
    subscribed: bool,
    lost: u64,
    cmd_tx: std::sync::mpsc::Sender<NodeCommand>,
}

/// What the broker task reports.
#[derive(Debug)]
pub enum BrokerEvent {
    /// An MQTT event.
    Mqtt(Event),
    /// The connection failed or was lost.
    Down(String),
}

/// Build the client options (credentials, will, TLS).
pub fn mqtt_options(b: &BrokerConfig, topics: &Topics) -> anyhow::Result<MqttOptions> {
    let mut o = MqttOptions::new(b.client_id.clone(), b.host.clone(), b.port);
    o.set_keep_alive(b.keep_alive);
    o.set_clean_session(true);
    o.set_inflight(INFLIGHT);
    o.set_max_packet_size(64 * 1024, 1024 * 1024);
    o.set_last_will(LastWill::new(
        topics.gateway_availability(),
        "offline",
        QoS::AtLeastOnce,
        true,
    ));
    if let Some(u) = &b.username {
        let pw = b.password.as_ref().map(|p| p.expose()).unwrap_or("");
        o.set_credentials(u.clone(), pw);
    }
    if let Some(t) = &b.tls {
        let cfg = rustls_config(t)?;
        o.set_transport(Transport::tls_with_config(TlsConfiguration::Rustls(
            Arc::new(cfg),
        )));
    }
    Ok(o)
}

/// A rustls client config (ring provider) from PEM files.
pub fn rustls_config(t: &TlsConfig) -> anyhow::Result<rustls::ClientConfig> {
    use rustls::pki_types::pem::PemObject;
    use rustls::pki_types::{CertificateDer, PrivateKeyDer};
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let mut roots = rustls::RootCertStore::empty();
    let ca = &t.ca_file;
    for cert in CertificateDer::pem_file_iter(ca)
        .with_context(|| format!("cannot read the CA file {}", ca.display()))?
    {
        let cert = cert.with_context(|| format!("the CA file {} is not PEM", ca.display()))?;
        roots
            .add(cert)
            .with_context(|| format!("a certificate in {} is not usable", ca.display()))?;
    }
    if roots.is_empty() {
        anyhow::bail!("the CA file {} holds no certificate", ca.display());
    }
    let builder = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .context("TLS set-up")?
        .with_root_certificates(roots);
    Ok(match &t.client_auth {
        None => builder.with_no_client_auth(),
        Some((cert, key)) => {
            let certs = CertificateDer::pem_file_iter(cert)
                .with_context(|| format!("cannot read the client certificate {}", cert.display()))?
                .collect::<Result<Vec<_>, _>>()
                .with_context(|| format!("the client certificate {} is not PEM", cert.display()))?;
            if certs.is_empty() {
                anyhow::bail!("{} holds no certificate", cert.display());
            }
            let key = PrivateKeyDer::from_pem_file(key)
                .with_context(|| format!("cannot read the client key {}", key.display()))?;
            builder
                .with_client_auth_cert(certs, key)
                .context("the client certificate and key do not match")?
        }
    })
}

/// Words for a connection error (no secrets: the client never puts the
/// password in its errors).
pub fn describe(e: &ConnectionError) -> String {
    match e {
        ConnectionError::ConnectionRefused(code) => format!("the broker refused: {code:?}"),
        ConnectionError::Io(io) => format!("{io}"),
        other => other.to_string(),
    }
}

/// Drive the event loop; after a failure wait for `resume` (the publisher
/// has stopped sending), discard the client's own replay buffer, wait
/// [`RECONNECT_DELAY`], reconnect.
pub async fn broker_task(
    mut el: EventLoop,
    tx: mpsc::UnboundedSender<BrokerEvent>,
    mut resume: mpsc::UnboundedReceiver<()>,
) {
    loop {
        match el.poll().await {
            Ok(ev) => {
                if tx.send(BrokerEvent::Mqtt(ev)).is_err() {
                    return;
                }
            }
            Err(ConnectionError::RequestsDone) => return,
            Err(e) => {
                if tx.send(BrokerEvent::Down(describe(&e))).is_err() {
                    return;
                }
                if resume.recv().await.is_none() {
                    return;
                }
                el.clean();
                el.pending.clear();
                tokio::time::sleep(RECONNECT_DELAY).await;
            }
        }
    }
}

/// Records in flight: in send order, with their acknowledgement.
#[derive(Debug, Default)]
pub struct InFlight {
    fifo: VecDeque<Option<u64>>,
    pkids: HashMap<u16, u64>,
    sent: VecDeque<(u64, bool)>,
}

impl InFlight {
    /// A request was handed to the client: a record, or `None` for anything
    /// else that produces an `Outgoing::Publish`.
    pub fn requested(&mut self, record: Option<u64>) {
        self.fifo.push_back(record);
        if let Some(i) = record {
            self.sent.push_back((i, false));
        }
    }

    /// The event loop sent a publish with this packet id.
    pub fn outgoing(&mut self, pkid: u16) {
        if let Some(Some(i)) = self.fifo.pop_front()
            && pkid != 0
        {
            self.pkids.insert(pkid, i);
        }
    }

    /// A PUBACK arrived; returns the new acknowledged offset (every record
    /// below it is acknowledged) when it moved.
    pub fn acked(&mut self, pkid: u16) -> Option<u64> {
        let i = self.pkids.remove(&pkid)?;
        if let Ok(k) = self.sent.binary_search_by_key(&i, |s| s.0) {
            self.sent[k].1 = true;
        }
        let mut upto = None;
        while let Some(&(i, true)) = self.sent.front() {
            upto = Some(i + 1);
            self.sent.pop_front();
        }
        upto
    }

    /// Records sent and not acknowledged.
    pub fn unacked(&self) -> usize {
        self.sent.len()
    }

    /// The connection is gone: forget everything in flight.
    pub fn clear(&mut self) {
        *self = InFlight::default();
    }
}

/// The publisher's state.
pub struct Gateway {
    cfg: GatewayConfig,
    topics: Topics,
    nodes: Vec<NodeSlot>,
    queue: Queue,
    client: AsyncClient,
    resume: mpsc::UnboundedSender<()>,
    connected: bool,
    down_said: Option<String>,
    flight: InFlight,
    send_cursor: u64,
    log: Log,
    started: Instant,
    last_status: Instant,
    queue_error_said: Option<Instant>,
    sum: GatewaySummary,
}

impl Gateway {
    /// A publisher over a started client.
    pub fn new(
        cfg: GatewayConfig,
        queue: Queue,
        client: AsyncClient,
        resume: mpsc::UnboundedSender<()>,
        cmd_txs: Vec<std::sync::mpsc::Sender<NodeCommand>>,
        log: Log,
    ) -> Gateway {
        let topics = Topics::new(&cfg.topic_prefix, &cfg.name, cfg.command_topic.as_deref());
        let nodes = cfg
            .nodes
            .iter()
            .cloned()
            .zip(cmd_txs)
            .map(|(spec, cmd_tx)| NodeSlot {
                name: spec.name.clone(),
                spec,
                hello: None,
                online: false,
                last_state: None,
                published_state: None,
                last_meas_uptime: None,
                has_estimate: false,
                subscribed: false,
                lost: 0,
                cmd_tx,
            })
            .collect();
        let send_cursor = queue.acked();
        Gateway {
            cfg,
            topics,
            nodes,
            queue,
            client,
            resume,
            connected: false,
            down_said: None,
            flight: InFlight::default(),
            send_cursor,
            log,
            started: Instant::now(),
            last_status: Instant::now(),
            queue_error_said: None,
            sum: GatewaySummary::default(),
        }
    }

    /// The topics.
    pub fn topics(&self) -> &Topics {
        &self.topics
    }

    /// True while connected to the broker.
    pub fn connected(&self) -> bool {
        self.connected
    }

    /// Records sent and not yet acknowledged.
    pub fn unacked(&self) -> usize {
        self.flight.unacked()
    }

    /// Records in the queue.
    pub fn pending(&self) -> u64 {
        self.queue.pending()
    }

    fn publish_now(&mut self, topic: String, payload: Vec<u8>, retain: bool, qos: QoS) {
        if !self.connected {
            return;
        }
        if self.client.try_publish(topic, qos, retain, payload).is_ok() {
            self.flight.requested(None);
        }
    }

    /// `<node>/command/result`: what became of a command from MQTT (QoS 0,
    /// not retained, not queued: it answers whoever is listening now).
    fn publish_command_result(
        &mut self,
        name: &str,
        command: &str,
        ok: bool,
        detail: String,
        host_unix_ms: u64,
    ) {
        let r = CommandResultJson {
            node: name,
            command,
            ok,
            detail,
            host_unix_ms,
        };
        let payload = serde_json::to_vec(&r).unwrap_or_default();
        self.publish_now(
            self.topics.command_result(name),
            payload,
            false,
            QoS::AtMostOnce,
        );
    }

    fn queue_record(&mut self, topic: String, payload: Vec<u8>) -> anyhow::Result<()> {
        let rec = Record { topic, payload };
        match self.queue.push(rec.clone()) {
            Ok(_) => self.sum.records_queued += 1,
            Err(e) => {
                // Disk full or gone: keep the fleet visible. Publish live
                // (not stored: lost if the broker is away too) and say so,
                // at most once a minute.
                self.sum.records_unqueued += 1;
                if self
                    .queue_error_said
                    .is_none_or(|t| t.elapsed() >= Duration::from_secs(60))
                {
                    self.queue_error_said = Some(Instant::now());
                    self.log.say(&format!(
                        "the disk queue failed ({e:#}); publishing without it ({} record(s) so far)",
                        self.sum.records_unqueued
                    ));
                }
                self.publish_now(rec.topic, rec.payload, false, QoS::AtLeastOnce);
            }
        }
        Ok(())
    }

    /// Send queued records while connected and the window allows.
    pub fn pump(&mut self) -> anyhow::Result<()> {
        while self.connected && self.flight.unacked() < WINDOW {
            let Some((i, rec)) = self.queue.get(self.send_cursor)? else {
                break;
            };
            if self
                .client
                .try_publish(rec.topic, QoS::AtLeastOnce, false, rec.payload)
                .is_err()
            {
                break;
            }
            self.flight.requested(Some(i));
            self.send_cursor = i + 1;
        }
        Ok(())
    }

    fn node_name(&self, k: usize) -> Option<&str> {
        self.nodes.get(k).and_then(|n| n.name.as_deref())
    }

    fn announce_node(&mut self, k: usize) {
        let Some(slot) = self.nodes.get(k) else {
            return;
        };
        let Some(name) = slot.name.clone() else {
            return;
        };
        let online = slot.online;
        let port = slot.spec.port.clone();
        let hello = slot.hello.clone();
        let with_thickness = slot.has_estimate;
        let state = slot.last_state.clone();
        self.publish_now(
            self.topics.availability(&name),
            if online { "online" } else { "offline" }.into(),
            true,
            QoS::AtMostOnce,
        );
        if let Some(h) = &hello {
            let info = serde_json::to_vec(&InfoJson::new(&name, &port, h)).unwrap_or_default();
            self.publish_now(self.topics.info(&name), info, true, QoS::AtMostOnce);
            if let Some(prefix) = self.cfg.homeassistant_prefix.clone() {
                for (t, p) in discovery::node_configs(
                    &prefix,
                    &self.topics,
                    &self.cfg.name,
                    &name,
                    h,
                    with_thickness,
                ) {
                    self.publish_now(t, p, true, QoS::AtMostOnce);
                }
            }
        }
        if let Some(s) = state {
            self.publish_state(k, s);
        }
        if let Some(t) = self.topics.command(&name)
            && self.connected
            && !self.nodes[k].subscribed
            && self.client.try_subscribe(t, QoS::AtLeastOnce).is_ok()
        {
            self.nodes[k].subscribed = true;
        }
    }

    fn publish_state(&mut self, k: usize, s: StateJson) {
        let payload = serde_json::to_vec(&s).unwrap_or_default();
        let topic = self.topics.state(&s.node);
        self.publish_now(topic, payload, true, QoS::AtMostOnce);
        if self.connected {
            self.nodes[k].published_state = Some((s, Instant::now()));
        }
    }

    fn publish_status(&mut self) {
        let s = StatusJson {
            gateway: self.cfg.name.clone(),
            nodes: self.nodes.len(),
            nodes_online: self.nodes.iter().filter(|n| n.online).count(),
            records_acked: self.sum.records_acked,
            queue_records: self.queue.pending(),
            queue_bytes: self.queue.bytes(),
            queue_dropped: self.queue.dropped(),
            uptime_s: self.started.elapsed().as_secs(),
            host_unix_ms: unix_ms_now(),
        };
        let payload = serde_json::to_vec(&s).unwrap_or_default();
        self.publish_now(self.topics.gateway_status(), payload, true, QoS::AtMostOnce);
    }

    /// An event from the broker task.
    pub fn on_broker(&mut self, ev: BrokerEvent) -> anyhow::Result<()> {
        match ev {
            BrokerEvent::Down(reason) => {
                if self.connected || self.down_said.as_deref() != Some(reason.as_str()) {
                    self.log.say(&format!(
                        "broker {}:{} {}: {reason}; {} record(s) wait in the disk queue, retrying every {} s",
                        self.cfg.broker.host,
                        self.cfg.broker.port,
                        if self.connected { "lost" } else { "unreachable" },
                        self.queue.pending(),
                        RECONNECT_DELAY.as_secs()
                    ));
                }
                self.down_said = Some(reason);
                self.connected = false;
                self.flight.clear();
                self.send_cursor = self.queue.acked();
                for n in &mut self.nodes {
                    n.subscribed = false;
                }
                let _ = self.resume.send(());
            }
            BrokerEvent::Mqtt(Event::Incoming(Incoming::ConnAck(_))) => {
                self.connected = true;
                self.down_said = None;
                self.sum.broker_connects += 1;
                self.flight.clear();
                self.send_cursor = self.queue.acked();
                self.log.say(&format!(
                    "connected to the broker {}:{}{}{}",
                    self.cfg.broker.host,
                    self.cfg.broker.port,
                    if self.cfg.broker.tls.is_some() {
                        " (TLS)"
                    } else {
                        ""
                    },
                    match self.queue.pending() {
                        0 => String::new(),
                        n => format!("; sending {n} queued record(s)"),
                    }
                ));
                self.publish_now(
                    self.topics.gateway_availability(),
                    b"online".to_vec(),
                    true,
                    QoS::AtLeastOnce,
                );
                if let Some(prefix) = self.cfg.homeassistant_prefix.clone() {
                    let (t, p) = discovery::gateway_config(&prefix, &self.topics, &self.cfg.name);
                    self.publish_now(t, p, true, QoS::AtMostOnce);
                }
                for k in 0..self.nodes.len() {
                    self.announce_node(k);
                }
                self.publish_status();
            }
            BrokerEvent::Mqtt(Event::Outgoing(Outgoing::Publish(pkid))) => {
                self.flight.outgoing(pkid);
            }
            BrokerEvent::Mqtt(Event::Outgoing(Outgoing::AwaitAck(pkid))) => {
                // Cannot happen while WINDOW < INFLIGHT; say so if it does.
                self.log.say(&format!(
                    "internal: packet id {pkid} collided; records may be sent twice"
                ));
                self.flight.outgoing(pkid);
            }
            BrokerEvent::Mqtt(Event::Incoming(Incoming::PubAck(p))) => {
                if let Some(upto) = self.flight.acked(p.pkid) {
                    let before = self.queue.acked();
                    self.queue.ack_through(upto);
                    self.sum.records_acked += self.queue.acked().saturating_sub(before);
                }
            }
            BrokerEvent::Mqtt(Event::Incoming(Incoming::Publish(p))) => {
                self.on_command(&p.topic, &p.payload, p.retain);
            }
            BrokerEvent::Mqtt(_) => {}
        }
        Ok(())
    }

    fn on_command(&mut self, topic: &str, payload: &[u8], retained: bool) {
        if self.cfg.command_topic.is_none() {
            return;
        }
        let Some(k) = self.nodes.iter().position(|n| {
            n.name
                .as_deref()
                .and_then(|name| self.topics.command(name))
                .is_some_and(|t| t == topic)
        }) else {
            self.log.say(&format!(
                "ignored a message on {topic}: not a command topic"
            ));
            return;
        };
        let name = self.nodes[k].name.clone().unwrap_or_default();
        let text = String::from_utf8_lossy(payload).to_string();
        // `{"command": "ack"}` or plain `ack`.
        let word = serde_json::from_str::<serde_json::Value>(&text)
            .ok()
            .and_then(|v| {
                v.get("command")
                    .and_then(|c| c.as_str())
                    .map(str::to_string)
            })
            .unwrap_or_else(|| text.clone());
        let shown: String = word.trim().chars().take(40).collect();
        if shown.is_empty() {
            // An empty message deletes a retained one: not a command.
            return;
        }
        let refuse = |me: &mut Gateway, detail: String| {
            me.log
                .say(&format!("command `{shown}` for {name} refused: {detail}"));
            me.publish_command_result(&name, &shown, false, detail, unix_ms_now());
        };
        if retained {
            refuse(
                self,
                "a retained command is never carried out (it would repeat on every reconnect)"
                    .into(),
            );
            return;
        }
        let Some(cmd) = NodeCommand::parse(&word) else {
            refuse(self, "unknown command: use ack or calibrate-dark".into());
            return;
        };
        if !self.nodes[k].online {
            refuse(self, "the node is offline".into());
            return;
        }
        self.log
            .say(&format!("command {} for {name} from MQTT", cmd.name()));
        if self.nodes[k].cmd_tx.send(cmd).is_err() {
            refuse(self, "the node's reader has stopped".into());
        }
    }

    fn resolve_name(&mut self, k: usize, h: &Hello) {
        if self.nodes[k].name.is_some() {
            return;
        }
        let mut name = unique_id_hex(h);
        if self
            .nodes
            .iter()
            .any(|n| n.name.as_deref() == Some(name.as_str()))
        {
            // Two nodes with one id (virtual nodes share theirs): keep the
            // config position, stable across restarts.
            name = format!("{name}-{k}");
        }
        self.log.say(&format!(
            "node on {} has no name in the config: named {name} after its unique id",
            self.nodes[k].spec.port
        ));
        self.nodes[k].name = Some(name);
    }

    fn link_event(
        &mut self,
        k: usize,
        kind: &'static str,
        detail: String,
        seq: Option<u32>,
        frames_lost: Option<u64>,
        t_ms: u64,
    ) -> anyhow::Result<()> {
        let Some(name) = self.node_name(k).map(str::to_string) else {
            return Ok(());
        };
        let mut e = LinkEventJson::new(&name, kind, detail, t_ms);
        e.seq = seq;
        e.frames_lost = frames_lost;
        let payload = serde_json::to_vec(&e).unwrap_or_default();
        self.queue_record(self.topics.event(&name), payload)
    }

    /// A report of a node reader.
    pub fn on_node(&mut self, m: NodeMsg) -> anyhow::Result<()> {
        let k = m.node;
        if k >= self.nodes.len() {
            return Ok(());
        }
        let t = m.host_unix_ms;
        match m.update {
            NodeUpdate::Up(h) => {
                self.resolve_name(k, &h);
                let name = self.node_name(k).unwrap_or_default().to_string();
                self.log.say(&format!(
                    "node {name} on {}: connected ({})",
                    self.nodes[k].spec.port,
                    hello_text(&h)
                ));
                self.nodes[k].hello = Some(h.clone());
                self.nodes[k].online = true;
                self.link_event(
                    k,
                    "link_up",
                    format!("port={} {}", self.nodes[k].spec.port, hello_text(&h)),
                    None,
                    None,
                    t,
                )?;
                self.announce_node(k);
            }
            NodeUpdate::Down(reason) => {
                let name = self.node_name(k).unwrap_or_default().to_string();
                self.log.say(&format!(
                    "node {name} on {}: link lost ({reason}); reconnecting",
                    self.nodes[k].spec.port
                ));
                self.nodes[k].online = false;
                self.link_event(k, "link_lost", reason, None, None, t)?;
                if !name.is_empty() {
                    self.publish_now(
                        self.topics.availability(&name),
                        b"offline".to_vec(),
                        true,
                        QoS::AtMostOnce,
                    );
                }
            }
            NodeUpdate::Unreachable(reason) => {
                self.log.say(&format!(
                    "node on {}: cannot connect ({reason}); retrying",
                    self.nodes[k].spec.port
                ));
            }
            NodeUpdate::Rejected => {}
            NodeUpdate::CommandResult {
                command,
                ok,
                detail,
            } => {
                let name = self.node_name(k).unwrap_or_default().to_string();
                self.log.say(&format!(
                    "command {} for {name}: {} ({detail})",
                    command.name(),
                    if ok { "done" } else { "failed" }
                ));
                self.publish_command_result(&name, command.name(), ok, detail, t);
            }
            NodeUpdate::Frame(f, ev) => {
                self.sum.frames += 1;
                match ev {
                    SeqEvent::Gap(n) => {
                        self.nodes[k].lost += n;
                        self.sum.frames_lost += n;
                        self.link_event(
                            k,
                            "frames_lost",
                            format!("{n} frame(s) missing before seq {}", f.seq),
                            Some(f.seq),
                            Some(n),
                            t,
                        )?;
                    }
                    SeqEvent::Restart => {
                        self.nodes[k].last_meas_uptime = None;
                        let detail = match &f.msg {
                            DeviceMsg::Hello(h) => format!("reset reason {:?}", h.reset_reason),
                            _ => "sequence number went back".into(),
                        };
                        let name = self.node_name(k).unwrap_or_default().to_string();
                        self.log.say(&format!(
                            "node {name} restarted ({detail}) at seq {}",
                            f.seq
                        ));
                        self.link_event(k, "node_restart", detail, Some(f.seq), None, t)?;
                        if let DeviceMsg::Hello(h) = &f.msg {
                            self.nodes[k].hello = Some(h.clone());
                            self.announce_node(k);
                        }
                    }
                    _ => {}
                }
                let Some(name) = self.node_name(k).map(str::to_string) else {
                    return Ok(());
                };
                if let Some((meas, est)) = f.msg.measurement() {
                    let lost = self.nodes[k].lost;
                    let state = StateJson::new(&name, f.seq, meas, est, lost, t);
                    if est.is_some() && !self.nodes[k].has_estimate {
                        self.nodes[k].has_estimate = true;
                        self.announce_node(k);
                    }
                    let due = match &self.nodes[k].published_state {
                        None => true,
                        Some((p, at)) => {
                            p.differs_discretely(&state)
                                || (state.thickness_moved(p, THICKNESS_STEP_MM)
                                    && at.elapsed()
                                        >= Duration::from_millis(self.cfg.state_interval_ms))
                        }
                    };
                    self.nodes[k].last_state = Some(state.clone());
                    if due {
                        self.publish_state(k, state);
                    }
                    let interval = if self.connected {
                        self.cfg.measurement_interval_ms
                    } else {
                        self.cfg.offline_measurement_interval_ms
                    };
                    let take = match self.nodes[k].last_meas_uptime {
                        None => true,
                        Some(last) => meas.uptime_ms < last || meas.uptime_ms - last >= interval,
                    };
                    if take {
                        self.nodes[k].last_meas_uptime = Some(meas.uptime_ms);
                        let j = MeasurementJson::new(&name, f.seq, meas, est, t);
                        let payload = serde_json::to_vec(&j).unwrap_or_default();
                        self.queue_record(self.topics.measurement(&name), payload)?;
                    }
                } else if let DeviceMsg::Event(e) = &f.msg {
                    let j = EventJson::new(&name, f.seq, e, t);
                    let payload = serde_json::to_vec(&j).unwrap_or_default();
                    self.queue_record(self.topics.event(&name), payload)?;
                }
            }
        }
        Ok(())
    }

    /// Housekeeping: flush the queue, publish the status when due.
    pub fn tick(&mut self, status_every: Duration) -> anyhow::Result<()> {
        if let Err(e) = self.queue.tick()
            && self
                .queue_error_said
                .is_none_or(|t| t.elapsed() >= Duration::from_secs(60))
        {
            self.queue_error_said = Some(Instant::now());
            self.log
                .say(&format!("the disk queue cannot be written: {e:#}"));
        }
        if self.last_status.elapsed() >= status_every {
            self.last_status = Instant::now();
            self.publish_status();
            let online = self.nodes.iter().filter(|n| n.online).count();
            self.log.say(&format!(
                "status: {online}/{} node(s) online, {} frame(s) received, {} record(s) acknowledged, {} queued, {} dropped by the queue bound; broker {}",
                self.nodes.len(),
                self.sum.frames,
                self.sum.records_acked,
                self.queue.pending(),
                self.queue.dropped(),
                if self.connected { "connected" } else { "unreachable" }
            ));
        }
        Ok(())
    }

    /// Clean exit: nodes and gateway offline (retained).
    pub fn say_goodbye(&mut self) {
        for k in 0..self.nodes.len() {
            if let Some(name) = self.node_name(k).map(str::to_string) {
                self.publish_now(
                    self.topics.availability(&name),
                    b"offline".to_vec(),
                    true,
                    QoS::AtMostOnce,
                );
            }
        }
        self.publish_status();
        self.publish_now(
            self.topics.gateway_availability(),
            b"offline".to_vec(),
            true,
            QoS::AtLeastOnce,
        );
    }

    /// Ask the client to disconnect.
    pub fn disconnect(&mut self) {
        let _ = self.client.try_disconnect();
    }

    /// Close the queue; the totals.
    pub fn finish(self) -> anyhow::Result<GatewaySummary> {
        let mut sum = self.sum;
        sum.records_pending = self.queue.pending();
        sum.records_dropped = self.queue.dropped();
        self.queue.close()?;
        Ok(sum)
    }
}

/// Run the gateway until `stop` (or `duration`).
pub fn run(
    cfg: GatewayConfig,
    stop: &'static AtomicBool,
    duration: Option<Duration>,
    status_every: Duration,
    log: Log,
) -> anyhow::Result<GatewaySummary> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    rt.block_on(run_async(cfg, stop, duration, status_every, log))
}

async fn run_async(
    cfg: GatewayConfig,
    stop: &'static AtomicBool,
    duration: Option<Duration>,
    status_every: Duration,
    log: Log,
) -> anyhow::Result<GatewaySummary> {
    let limits = QueueLimits::for_max_bytes(cfg.queue_max_bytes);
    let (queue, rec) = Queue::open(&cfg.queue_dir, limits)?;
    log.say(&format!(
        "gateway {}: {} node(s), broker {}:{}{}, queue {}{}",
        cfg.name,
        cfg.nodes.len(),
        cfg.broker.host,
        cfg.broker.port,
        if cfg.broker.tls.is_some() {
            " (TLS)"
        } else {
            ""
        },
        cfg.queue_dir.display(),
        if rec.pending > 0 {
            format!(" ({} record(s) from the last run to send)", rec.pending)
        } else {
            String::new()
        }
    ));
    let topics = Topics::new(&cfg.topic_prefix, &cfg.name, cfg.command_topic.as_deref());
    let opts = mqtt_options(&cfg.broker, &topics)?;
    let (client, eventloop) = AsyncClient::new(opts, 1 << 16);
    let (ev_tx, mut ev_rx) = mpsc::unbounded_channel();
    let (resume_tx, resume_rx) = mpsc::unbounded_channel();
    let broker = tokio::spawn(broker_task(eventloop, ev_tx, resume_rx));

    let (node_tx, mut node_rx) = mpsc::channel::<NodeMsg>(8192);
    let readers_stop = Arc::new(AtomicBool::new(false));
    let timings = super::node::ReaderTimings {
        silence_timeout: cfg.silence_timeout,
        ..Default::default()
    };
    let mut cmd_txs = Vec::new();
    let mut threads = Vec::new();
    for (k, spec) in cfg.nodes.iter().enumerate() {
        let (ctx, crx) = std::sync::mpsc::channel();
        cmd_txs.push(ctx);
        threads.push(
            super::node::spawn_serial_reader(
                k,
                spec.clone(),
                node_tx.clone(),
                crx,
                timings,
                readers_stop.clone(),
            )
            .context("cannot start a node reader thread")?,
        );
    }
    drop(node_tx);

    let mut gw = Gateway::new(cfg, queue, client, resume_tx, cmd_txs, log);
    let started = Instant::now();
    let mut tick = tokio::time::interval(TICK);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut stopping: Option<Instant> = None;
    let mut readers_done = false;
    loop {
        tokio::select! {
            biased;
            ev = ev_rx.recv() => match ev {
                Some(ev) => gw.on_broker(ev)?,
                None => break,
            },
            m = node_rx.recv(), if !readers_done => match m {
                Some(m) => {
                    gw.on_node(m)?;
                    for _ in 0..256 {
                        match node_rx.try_recv() {
                            Ok(m) => gw.on_node(m)?,
                            Err(_) => break,
                        }
                    }
                }
                None => readers_done = true,
            },
            _ = tick.tick() => {
                gw.tick(status_every)?;
                let want_stop = stop.load(Ordering::Relaxed)
                    || duration.is_some_and(|d| started.elapsed() >= d);
                if want_stop && stopping.is_none() {
                    stopping = Some(Instant::now());
                    readers_stop.store(true, Ordering::Relaxed);
                }
                if let Some(at) = stopping {
                    // Drain the readers, then give the broker 3 s for the
                    // last acknowledgements.
                    let flushed = gw.unacked() == 0 && gw.pending() == 0;
                    if readers_done && (flushed || !gw.connected() || at.elapsed() >= Duration::from_secs(3)) {
                        break;
                    }
                }
            }
        }
        gw.pump()?;
    }
    for t in threads {
        let _ = t.join();
    }
    if gw.connected() {
        gw.say_goodbye();
        gw.disconnect();
        // Let the event loop send the goodbye and the DISCONNECT.
        let wait = tokio::time::sleep(Duration::from_millis(500));
        tokio::pin!(wait);
        loop {
            tokio::select! {
                _ = &mut wait => break,
                ev = ev_rx.recv() => match ev {
                    Some(BrokerEvent::Mqtt(Event::Outgoing(Outgoing::Disconnect))) | None => break,
                    Some(ev) => { let _ = gw.on_broker(ev); }
                }
            }
        }
    }
    broker.abort();
    let sum = gw.finish()?;
    Ok(sum)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_flight_maps_packet_ids_to_records_and_acks_in_order() {
        let mut f = InFlight::default();
        f.requested(Some(10));
        f.requested(None); // a retained message between records
        f.requested(Some(11));
        f.requested(Some(12));
        f.outgoing(1);
        f.outgoing(0); // QoS 0: no packet id
        f.outgoing(2);
        f.outgoing(3);
        assert_eq!(f.unacked(), 3);
        // Out of order: 12 first: the offset may not move past 10.
        assert_eq!(f.acked(3), None);
        assert_eq!(f.acked(1), Some(11));
        assert_eq!(f.acked(2), Some(13));
        assert_eq!(f.unacked(), 0);
        // An unknown packet id (the QoS 1 availability) changes nothing.
        assert_eq!(f.acked(77), None);
    }
}
