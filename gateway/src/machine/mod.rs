//! The gateway's state machine, free of network IO: it takes what happens
//! (a node reader's report, the broker connecting or going away, a packet
//! id going out, a PUBACK, a message on a command topic, a tick) and answers
//! with [`Action`]s (publish, subscribe, hand a command to a node) that the
//! service ([`crate::service`]) carries out with rumqttc — as rumqttc itself
//! keeps its `MqttState` apart from its `EventLoop`. Its tests need no
//! broker. Its only IO is the disk queue it owns.
//!
//! What it publishes: events and rate-limited measurements are appended to
//! the queue and published (QoS 1) from it in order ([`Gateway::pump`]); a
//! record leaves the queue when its PUBACK arrives ([`crate::inflight`]).
//! Retained messages (availability, info, state, discovery) are not queued:
//! they are published from memory again after every (re)connection, since a
//! broker without persistence forgets them. It also keeps every node's
//! latest state in the shared [`Fleet`] for other front ends.

pub mod claim;
mod commands;
mod homeassistant;
pub mod journal;
mod nodes;
pub mod owner;
mod retained_check;
mod rollout;
#[cfg(test)]
mod tests;

use std::collections::{HashMap, VecDeque};
use std::time::{Duration, Instant};

use fois_link::timefmt::unix_ms_now;
use rumqttc::QoS;
use tracing::{error, info, warn};

use crate::command::NodeCommand;
use crate::config::GatewayConfig;
use crate::inflight::{InFlight, WINDOW};
use crate::payload::{InfoJson, StateJson, StatusJson};
use crate::queue::{Queue, Record};
use crate::snapshot::Fleet;
use crate::state_filter::StateFilter;
use crate::topics::Topics;

/// Wait before reconnecting to the broker.
pub const RECONNECT_DELAY: Duration = Duration::from_secs(1);

/// What the service is to do.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Publish a message.
    Publish {
        /// Topic.
        topic: String,
        /// Payload.
        payload: Vec<u8>,
        /// QoS (records: at least once).
        qos: QoS,
        /// Retained.
        retain: bool,
    },
    /// Subscribe (QoS 1) to a node's command topic or the owner topic.
    Subscribe {
        /// The topic.
        topic: String,
        /// The node whose command topic it is (`None`: the owner topic).
        node: Option<usize>,
    },
    /// Hand a command to a node's reader.
    Command {
        /// The node.
        node: usize,
        /// The command.
        command: NodeCommand,
    },
    /// Start a roll-out ([`crate::rollout::run_rollout`]): update these
    /// nodes, in order, one at a time, with this image.
    RollOut {
        /// The signed image.
        image: std::sync::Arc<fois_link::signed_image::SignedImage>,
        /// The nodes, in order.
        order: Vec<usize>,
        /// The driver's options.
        opts: fois_link::update::UpdateOptions,
    },
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
    /// Records the queue lost, ever (its bound, a full or vanished disk).
    pub records_dropped: u64,
    /// Broker connections made.
    pub broker_connects: u64,
    /// Frames lost on the serial links.
    pub frames_lost: u64,
}

/// What the MQTT side keeps of a node beside its record in the [`Fleet`]
/// (name, port, hello, key, link, latest reading and frames lost live
/// there, once).
#[derive(Default)]
pub(crate) struct MqttNode {
    last_state: Option<StateJson>,
    /// When the state is published, with which (held) values.
    state_filter: StateFilter,
    last_meas_uptime: Option<u64>,
    has_estimate: bool,
    has_gain: bool,
    has_icing: bool,
    /// Frames received since the gateway started.
    frames: u64,
    /// Stale discovery configs emptied (once per node and run).
    stale_cleared: bool,
    subscribed: bool,
    /// When the last command was handed to the node (rate limit).
    last_command: Option<Instant>,
    /// A command from MQTT waiting to be known as not retained.
    check: Option<retained_check::Check>,
}

/// The state machine.
pub struct Gateway {
    cfg: GatewayConfig,
    topics: Topics,
    nodes: Vec<MqttNode>,
    /// Every node's record: the truth, shared with the other front ends.
    fleet: Fleet,
    queue: Queue,
    connected: bool,
    /// The broker failure last logged (a repeat of it is not logged again).
    logged_down_reason: Option<String>,
    flight: InFlight,
    send_cursor: u64,
    started: Instant,
    last_status: Instant,
    sum: GatewaySummary,
    out: Vec<Action>,
    instance: claim::Instance,
    conflict: Option<String>,
    reannounce_at: Option<Instant>,
    /// The goodbye (`offline`) was published: an `offline` on the
    /// availability topic is ours ([`owner`]).
    said_goodbye: bool,
    /// When a phantom `offline` was last logged ([`owner`]).
    phantom_logged: Option<Instant>,
    /// Subscriptions handed to the client, in order (`Outgoing::Subscribe`
    /// gives their packet ids in the same order), and by packet id.
    sub_fifo: VecDeque<Option<usize>>,
    sub_pkids: HashMap<u16, Option<usize>>,
    /// The rate limit of the nodes' lines in the log.
    journal: journal::Limiter,
    /// The image of the roll-out running, if one is.
    rollout: Option<String>,
}

impl Gateway {
    /// A gateway over an opened queue, not connected yet, keeping its
    /// nodes' records in `fleet` ([`Fleet::of`] this config).
    pub fn new(cfg: GatewayConfig, queue: Queue, fleet: Fleet, now: Instant) -> Gateway {
        let topics = Topics::new(&cfg.topic_prefix, &cfg.name, cfg.command_topic.as_deref());
        let nodes = cfg.nodes.iter().map(|_| MqttNode::default()).collect();
        let send_cursor = queue.acked();
        Gateway {
            cfg,
            topics,
            nodes,
            queue,
            fleet,
            connected: false,
            logged_down_reason: None,
            flight: InFlight::default(),
            send_cursor,
            started: now,
            last_status: now,
            sum: GatewaySummary::default(),
            out: Vec::new(),
            instance: claim::Instance::this_process(),
            conflict: None,
            reannounce_at: None,
            said_goodbye: false,
            phantom_logged: None,
            sub_fifo: VecDeque::new(),
            sub_pkids: HashMap::new(),
            journal: journal::Limiter::default(),
            rollout: None,
        }
    }

    /// Who this gateway says it is in its name claim (tests set their own).
    pub fn set_instance(&mut self, instance: claim::Instance) {
        self.instance = instance;
    }

    /// The actions decided since the last call, in order.
    pub fn actions(&mut self) -> Vec<Action> {
        std::mem::take(&mut self.out)
    }

    /// The shared per-node snapshots.
    pub fn fleet(&self) -> Fleet {
        self.fleet.clone()
    }

    /// The topics.
    pub fn topics(&self) -> &Topics {
        &self.topics
    }

    /// The config.
    pub fn config(&self) -> &GatewayConfig {
        &self.cfg
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

    /// The totals so far.
    pub fn summary(&self) -> &GatewaySummary {
        &self.sum
    }

    /// Publish now (while connected): not queued, not a record.
    fn publish_now(&mut self, topic: String, payload: Vec<u8>, retain: bool, qos: QoS) {
        if !self.connected {
            return;
        }
        self.flight.requested(None);
        self.out.push(Action::Publish {
            topic,
            payload,
            qos,
            retain,
        });
    }

    fn queue_record(&mut self, topic: String, payload: Vec<u8>) {
        self.queue.push(Record { topic, payload });
        self.sum.records_queued += 1;
    }

    /// Send queued records while connected and the window allows.
    pub fn pump(&mut self) {
        while self.connected && self.flight.unacked() < WINDOW {
            let Some((i, rec)) = self.queue.get(self.send_cursor) else {
                break;
            };
            self.flight.requested(Some(i));
            self.send_cursor = i + 1;
            self.out.push(Action::Publish {
                topic: rec.topic,
                payload: rec.payload,
                qos: QoS::AtLeastOnce,
                retain: false,
            });
        }
    }

    /// The service could not hand `actions` (the tail of what
    /// [`Gateway::actions`] returned, in order) to the client: take them
    /// back, so records are sent again and subscriptions are made again.
    pub fn unsent(&mut self, actions: &[Action]) {
        for a in actions.iter().rev() {
            match a {
                Action::Publish { .. } => {
                    if let Some(i) = self.flight.unrequest_last() {
                        self.send_cursor = self.send_cursor.min(i);
                    }
                }
                Action::Subscribe { node, .. } => {
                    self.sub_fifo.pop_back();
                    if let Some(n) = node.and_then(|k| self.nodes.get_mut(k)) {
                        n.subscribed = false;
                    }
                }
                Action::RollOut { .. } => {
                    self.rollout_failed_to_start("the node readers have stopped")
                }
                Action::Command { node, command } => {
                    let name = self.node_name(*node).unwrap_or_default();
                    self.publish_command_result(
                        &name,
                        command.name(),
                        false,
                        "the node's reader has stopped".into(),
                        unix_ms_now(),
                    );
                }
            }
        }
    }

    fn node_name(&self, k: usize) -> Option<String> {
        self.fleet.read(k, |n| n.name.clone()).flatten()
    }

    fn node_port(&self, k: usize) -> String {
        self.fleet.read(k, |n| n.port.clone()).unwrap_or_default()
    }

    fn online(&self, k: usize) -> bool {
        self.fleet.read(k, |n| n.link_up).unwrap_or(false)
    }

    fn nodes_online(&self) -> usize {
        (0..self.nodes.len()).filter(|&k| self.online(k)).count()
    }

    /// Availability, info, discovery, state and the command subscription
    /// of node `k` (retained: again after every reconnection).
    fn announce_node(&mut self, k: usize) {
        let Some((Some(name), online, port, hello)) = self.fleet.read(k, |n| {
            (n.name.clone(), n.link_up, n.port.clone(), n.hello.clone())
        }) else {
            return;
        };
        let state = self.nodes[k].last_state.clone();
        self.publish_now(
            self.topics.availability(&name),
            if online { "online" } else { "offline" }.into(),
            true,
            QoS::AtMostOnce,
        );
        if let Some(h) = &hello {
            let info = serde_json::to_vec(&InfoJson::new(&name, &port, h)).unwrap_or_default();
            self.publish_now(self.topics.info(&name), info, true, QoS::AtMostOnce);
            self.announce_discovery(k);
        }
        if let Some(s) = state {
            let s = self.nodes[k].state_filter.force(s, Instant::now());
            self.publish_state(s);
        }
        if let Some(topic) = self.topics.command(&name)
            && self.connected
            && !self.nodes[k].subscribed
        {
            self.nodes[k].subscribed = true;
            self.subscribe(topic, Some(k));
        }
    }

    /// Subscribe (QoS 1) to `topic`, a command topic of node `node` or the
    /// owner topic (`None`).
    fn subscribe(&mut self, topic: String, node: Option<usize>) {
        self.sub_fifo.push_back(node);
        self.out.push(Action::Subscribe { topic, node });
    }

    /// The event loop sent a SUBSCRIBE with this packet id.
    pub fn on_outgoing_subscribe(&mut self, pkid: u16) {
        if let Some(node) = self.sub_fifo.pop_front() {
            self.sub_pkids.insert(pkid, node);
        }
    }

    /// The broker confirmed a subscription.
    pub fn on_suback(&mut self, pkid: u16, now: Instant) {
        if let Some(Some(k)) = self.sub_pkids.remove(&pkid) {
            self.check_subscribed(k, now);
        }
    }

    fn publish_state(&mut self, s: StateJson) {
        let payload = serde_json::to_vec(&s).unwrap_or_default();
        let topic = self.topics.state(&s.node);
        self.publish_now(topic, payload, true, QoS::AtMostOnce);
    }

    fn publish_status(&mut self, now: Instant) {
        let s = StatusJson {
            gateway: self.cfg.name.clone(),
            nodes: self.nodes.len(),
            nodes_online: self.nodes_online(),
            records_acked: self.sum.records_acked,
            queue_records: self.queue.pending(),
            queue_bytes: self.queue.bytes(),
            queue_dropped: self.queue.dropped(),
            uptime_s: now.saturating_duration_since(self.started).as_secs(),
            host_unix_ms: unix_ms_now(),
        };
        let payload = serde_json::to_vec(&s).unwrap_or_default();
        self.publish_now(self.topics.gateway_status(), payload, true, QoS::AtMostOnce);
    }

    /// The broker accepted the connection (CONNACK): announce everything,
    /// send the queue from its acknowledged offset.
    pub fn on_connected(&mut self, now: Instant) {
        self.connected = true;
        self.logged_down_reason = None;
        self.sum.broker_connects += 1;
        self.flight.clear();
        self.send_cursor = self.queue.acked();
        info!(
            "connected to the broker {}{}",
            self.cfg.broker.describe(),
            match self.queue.pending() {
                0 => String::new(),
                n => format!("; sending {n} queued record(s)"),
            }
        );
        self.claim_name();
        self.announce_all(now);
        self.watch_availability();
        self.watch_firmware();
    }

    /// Every retained message: availability, discovery, each node's.
    fn announce_all(&mut self, now: Instant) {
        self.publish_now(
            self.topics.gateway_availability(),
            b"online".to_vec(),
            true,
            QoS::AtLeastOnce,
        );
        if let Some(d) = self.discovery() {
            let (t, p) = d.gateway_config();
            self.publish_now(t, p, true, QoS::AtMostOnce);
        }
        for k in 0..self.nodes.len() {
            self.announce_node(k);
        }
        self.publish_status(now);
    }

    /// The connection failed or was lost: forget what is in flight (it is
    /// sent again from the queue after the reconnect).
    pub fn on_disconnected(&mut self, reason: &str) {
        if self.connected || self.logged_down_reason.as_deref() != Some(reason) {
            warn!(
                "broker {} {}: {reason}; {} record(s) wait in the disk queue, retrying every {} s",
                self.cfg.broker.describe(),
                if self.connected {
                    "lost"
                } else {
                    "unreachable"
                },
                self.queue.pending(),
                RECONNECT_DELAY.as_secs()
            );
        }
        self.logged_down_reason = Some(reason.to_string());
        self.connected = false;
        self.flight.clear();
        self.send_cursor = self.queue.acked();
        for n in &mut self.nodes {
            n.subscribed = false;
        }
        self.sub_fifo.clear();
        self.sub_pkids.clear();
        self.drop_checks();
    }

    /// The event loop sent a publish with this packet id (0 for QoS 0).
    pub fn on_outgoing_publish(&mut self, pkid: u16) {
        self.flight.outgoing(pkid);
    }

    /// A PUBACK arrived.
    pub fn on_puback(&mut self, pkid: u16) {
        if let Some(upto) = self.flight.acked(pkid) {
            let before = self.queue.acked();
            self.queue.ack_through(upto);
            self.sum.records_acked += self.queue.acked().saturating_sub(before);
        }
    }

    /// Housekeeping: flush the queue, publish the status when due, publish
    /// the retained messages again after a name conflict.
    pub fn tick(&mut self, now: Instant, status_every: Duration) {
        self.queue.tick();
        self.finish_checks(now);
        self.report_suppressed(now);
        if self.reannounce_at.is_some_and(|at| now >= at) {
            self.reannounce_at = None;
            self.announce_all(now);
        }
        if now.saturating_duration_since(self.last_status) >= status_every {
            self.last_status = now;
            self.publish_status(now);
            let online = self.nodes_online();
            info!(
                "status: {online}/{} node(s) online, {} frame(s) received, {} record(s) acknowledged, {} queued, {} lost by the queue{}; broker {}",
                self.nodes.len(),
                self.sum.frames,
                self.sum.records_acked,
                self.queue.pending(),
                self.queue.dropped(),
                match self.queue.failing() {
                    Some(why) => format!(" (disk failing: {why})"),
                    None => String::new(),
                },
                if self.connected {
                    "connected"
                } else {
                    "unreachable"
                }
            );
        }
    }

    /// Clean exit: nodes offline, the final status (no node online: the
    /// readers have stopped), the gateway offline (all retained).
    pub fn goodbye(&mut self, now: Instant) {
        for k in 0..self.nodes.len() {
            self.fleet.update(k, |n| n.link_up = false);
            if let Some(name) = self.node_name(k) {
                self.publish_now(
                    self.topics.availability(&name),
                    b"offline".to_vec(),
                    true,
                    QoS::AtMostOnce,
                );
            }
        }
        self.publish_status(now);
        self.said_goodbye = true;
        self.publish_now(
            self.topics.gateway_availability(),
            b"offline".to_vec(),
            true,
            QoS::AtLeastOnce,
        );
    }

    /// Close the queue; the totals (also when closing fails: the error is
    /// logged, the totals say what happened).
    pub fn finish(self) -> GatewaySummary {
        let mut sum = self.sum;
        sum.records_pending = self.queue.pending();
        sum.records_dropped = self.queue.dropped();
        if let Err(e) = self.queue.close() {
            error!("the disk queue could not be closed cleanly: {e:#}");
        }
        sum
    }
}
