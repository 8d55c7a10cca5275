//! The runtime wiring: the network runtime ([`crate::net_runtime`], its
//! own thread) drives rumqttc's event loop, forwarding its events, and
//! serves Modbus TCP; one thread per node reads its serial port
//! ([`crate::reader`]); the loop here, on the main current-thread runtime,
//! feeds all of it to the state machine ([`crate::machine::Gateway`]),
//! which owns the disk queue, and carries out the actions it returns with
//! the `AsyncClient`. A stalled disk blocks this loop only.
//! With `[log] dir`, the nodes' rows go to the daily logs' own thread
//! ([`crate::season_log`]).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use rumqttc::{AsyncClient, ConnectionError, Event, EventLoop, Incoming, Outgoing};
use tokio::sync::mpsc;
use tracing::{info, warn};

use fois_link::timefmt::unix_ms_now;

use crate::command::{FrontEndCommand, NodeCommand};
use crate::config::GatewayConfig;
use crate::machine::{Action, Gateway, GatewaySummary, RECONNECT_DELAY};
use crate::mqtt::{describe, mqtt_options};
use crate::net_runtime::NetRuntime;
use crate::queue::{Queue, QueueLimits};
use crate::reader::{NodeMsg, NodeUpdate, ReaderTimings, Sink, spawn_serial_reader};
use crate::rollout::{NodeOutcome, PICKUP_TIMEOUT, UpdateSlot, run_rollout, update_text};
use crate::season_log::{SeasonLog, rows_of};
use crate::snapshot::Fleet;
use crate::topics::Topics;

/// The housekeeping period (queue flush, state, status, stop).
pub const TICK: Duration = Duration::from_millis(100);
/// After a stop, the broker has this long for the last acknowledgements.
pub const LAST_ACKS: Duration = Duration::from_secs(3);

/// What the broker task reports.
#[derive(Debug)]
enum BrokerEvent {
    /// An MQTT event.
    Mqtt(Event),
    /// The connection failed or was lost.
    Down(String),
}

/// Drive the event loop; after a failure wait for `resume` (the gateway
/// has stopped sending), discard the client's own replay buffer (the queue
/// sends again what was not acknowledged), wait [`RECONNECT_DELAY`],
/// reconnect.
async fn broker_task(
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

/// The run stopped because another gateway of the same name runs (exit
/// code 3); the totals so far.
#[derive(Debug)]
pub struct NameConflict {
    /// Why (who the other one is).
    pub why: String,
    /// The totals at the stop.
    pub summary: GatewaySummary,
}

impl std::fmt::Display for NameConflict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.why)
    }
}

impl std::error::Error for NameConflict {}

/// How a run ends.
#[derive(Debug, Clone, Copy)]
pub struct RunLimits<'a> {
    /// Set by Ctrl-C / SIGTERM.
    pub stop: &'a AtomicBool,
    /// Stop after this long (None: until `stop`).
    pub duration: Option<Duration>,
    /// Log a status line this often.
    pub status_every: Duration,
}

/// The gateway before it runs: its config, the shared snapshots, the
/// command channel for other front ends.
pub struct Service {
    cfg: GatewayConfig,
    fleet: Fleet,
    commands_tx: mpsc::UnboundedSender<FrontEndCommand>,
    commands_rx: mpsc::UnboundedReceiver<FrontEndCommand>,
}

impl Service {
    /// A gateway of this config.
    pub fn new(cfg: GatewayConfig) -> Service {
        let (commands_tx, commands_rx) = mpsc::unbounded_channel();
        Service {
            fleet: Fleet::of(&cfg),
            cfg,
            commands_tx,
            commands_rx,
        }
    }

    /// Every node's latest state, filled in while the gateway runs (a
    /// shared handle: clone it into another front end before
    /// [`Service::run`]).
    pub fn fleet(&self) -> Fleet {
        self.fleet.clone()
    }

    /// A sender of commands to nodes (they go through the same checks as
    /// MQTT's: online, rate limit).
    pub fn commands(&self) -> mpsc::UnboundedSender<FrontEndCommand> {
        self.commands_tx.clone()
    }

    /// Run until `limits.stop` or `limits.duration`; the totals.
    pub fn run(self, limits: RunLimits<'_>) -> anyhow::Result<GatewaySummary> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .context("cannot start the async runtime")?;
        rt.block_on(self.run_async(limits))
    }

    async fn run_async(self, limits: RunLimits<'_>) -> anyhow::Result<GatewaySummary> {
        let Service {
            cfg,
            fleet,
            commands_tx,
            commands_rx: mut front_rx,
        } = self;
        let net = NetRuntime::start()?;
        // Modbus first: a taken port stops the start before anything else
        // is opened.
        let modbus = match &cfg.modbus {
            Some(m) => {
                let listener = crate::modbus::server::bind(m)?;
                info!("{}", m.describe());
                let units = crate::modbus::server::ModbusUnits::new(
                    m.clone(),
                    fleet.clone(),
                    commands_tx,
                    cfg.command_min_interval,
                );
                Some(net.spawn(crate::modbus::server::serve(listener, Arc::new(units))))
            }
            None => {
                drop(commands_tx);
                None
            }
        };
        let limits_q = QueueLimits::for_max_bytes(cfg.queue_max_bytes);
        let (queue, rec) = Queue::open(&cfg.queue_dir, limits_q)?;
        info!(
            "gateway {}: {} node(s), broker {}, queue {}{}",
            cfg.name,
            cfg.nodes.len(),
            cfg.broker.describe(),
            cfg.queue_dir.display(),
            if rec.pending > 0 {
                format!(" ({} record(s) from the last run to send)", rec.pending)
            } else {
                String::new()
            }
        );
        let topics = Topics::new(&cfg.topic_prefix, &cfg.name, cfg.command_topic.as_deref());
        let opts = mqtt_options(&cfg.broker, &topics)?;
        let (client, eventloop) = AsyncClient::new(opts, 1 << 16);
        let (ev_tx, mut ev_rx) = mpsc::unbounded_channel();
        let (resume_tx, resume_rx) = mpsc::unbounded_channel();
        let broker = net.spawn(broker_task(eventloop, ev_tx, resume_rx));

        let (node_tx, mut node_rx) = mpsc::channel::<NodeMsg>(8192);
        let readers_stop = Arc::new(AtomicBool::new(false));
        let timings = ReaderTimings {
            silence_timeout: cfg.silence_timeout,
            ..Default::default()
        };
        let mut cmd_txs = Vec::new();
        let mut threads = Vec::new();
        let slots: Vec<UpdateSlot> = cfg.nodes.iter().map(|_| UpdateSlot::default()).collect();
        for (k, spec) in cfg.nodes.iter().enumerate() {
            let (ctx, crx) = std::sync::mpsc::channel();
            cmd_txs.push(ctx);
            threads.push(
                spawn_serial_reader(
                    k,
                    spec.clone(),
                    node_tx.clone(),
                    crx,
                    slots[k].clone(),
                    timings,
                    readers_stop.clone(),
                )
                .context("cannot start a node reader thread")?,
            );
        }
        // The roll-out reports like a reader, while one runs: a weak
        // sender, so the readers' end still closes the channel.
        let rollout_tx = node_tx.downgrade();
        drop(node_tx);

        // The daily logs: a thread of their own, off the runtime.
        let mut season = cfg.log.as_ref().map(SeasonLog::start).transpose()?;
        let log_fleet = fleet.clone();
        let started = Instant::now();
        let mut gw = Gateway::new(cfg, queue, fleet, started);
        let mut io = Io {
            client,
            resume: resume_tx,
            cmd_txs,
            rollouts: RolloutIo {
                slots,
                tx: rollout_tx,
                stop: readers_stop.clone(),
            },
        };
        let mut tick = tokio::time::interval(TICK);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut stopping: Option<Instant> = None;
        let mut readers_done = false;
        loop {
            tokio::select! {
                biased;
                ev = ev_rx.recv() => match ev {
                    Some(ev) => io.broker_event(&mut gw, ev),
                    None => break,
                },
                m = node_rx.recv(), if !readers_done => match m {
                    Some(m) => {
                        on_node(&mut gw, season.as_mut(), &log_fleet, m);
                        for _ in 0..256 {
                            match node_rx.try_recv() {
                                Ok(m) => on_node(&mut gw, season.as_mut(), &log_fleet, m),
                                Err(_) => break,
                            }
                        }
                    }
                    None => readers_done = true,
                },
                Some(c) = front_rx.recv() => {
                    // A waiter that gave up has answered its client already.
                    if !c.reply.as_ref().is_some_and(|r| r.is_closed()) {
                        let r = gw.front_end_command(c.node, c.command, Instant::now());
                        if let Some(reply) = c.reply {
                            let _ = reply.send(r);
                        }
                    }
                }
                _ = tick.tick() => {
                    let now = Instant::now();
                    gw.tick(now, limits.status_every);
                    let want_stop = limits.stop.load(Ordering::Relaxed)
                        || limits.duration.is_some_and(|d| started.elapsed() >= d);
                    if want_stop && stopping.is_none() {
                        stopping = Some(now);
                        readers_stop.store(true, Ordering::Relaxed);
                    }
                    if let Some(at) = stopping {
                        // Drain the readers, then give the broker a moment
                        // for the last acknowledgements.
                        let flushed = gw.unacked() == 0 && gw.pending() == 0;
                        if readers_done && (flushed || !gw.connected() || at.elapsed() >= LAST_ACKS) {
                            break;
                        }
                    }
                }
            }
            gw.pump();
            io.carry_out(&mut gw);
            if gw.conflict().is_some() {
                readers_stop.store(true, Ordering::Relaxed);
                break;
            }
        }
        if let Some(m) = modbus {
            m.abort();
        }
        for t in threads {
            let _ = t.join();
        }
        if let Some(s) = season.take() {
            s.stop();
        }
        let conflict = gw.conflict().map(str::to_string);
        if let Some(why) = conflict {
            // No goodbye: the other gateway's nodes are not ours to mark
            // offline. A clean DISCONNECT: no last will either (waited
            // for: a connection dropped without it publishes the will).
            let _ = io.client.try_disconnect();
            until_broker_closes(&mut ev_rx, |_| {}).await;
            broker.abort();
            let sum = gw.finish();
            return Err(NameConflict { why, summary: sum }.into());
        }
        if gw.connected() {
            gw.goodbye(Instant::now());
            io.carry_out(&mut gw);
            let _ = io.client.try_disconnect();
            // Let the event loop send the goodbye and the DISCONNECT (a
            // connection dropped before the DISCONNECT went out publishes
            // the last will).
            until_broker_closes(&mut ev_rx, |ev| io.broker_event(&mut gw, ev)).await;
        }
        broker.abort();
        Ok(gw.finish())
    }
}

/// Wait, at most 500 ms, until the broker closes the connection after our
/// DISCONNECT (then it publishes no last will); other events go to `on`.
async fn until_broker_closes(
    ev_rx: &mut mpsc::UnboundedReceiver<BrokerEvent>,
    mut on: impl FnMut(BrokerEvent),
) {
    let wait = tokio::time::sleep(Duration::from_millis(500));
    tokio::pin!(wait);
    loop {
        tokio::select! {
            _ = &mut wait => break,
            ev = ev_rx.recv() => match ev {
                Some(BrokerEvent::Down(_)) | None => break,
                Some(ev) => on(ev),
            }
        }
    }
}

/// A node report to the machine, and its rows to the daily log (under
/// the node's name, known once it has connected).
fn on_node(gw: &mut Gateway, season: Option<&mut SeasonLog>, fleet: &Fleet, m: NodeMsg) {
    let rows = season.as_ref().map(|_| rows_of(&m));
    let k = m.node;
    gw.on_node(m, Instant::now());
    if let (Some(s), Some(rows)) = (season, rows)
        && let Some(name) = fleet.read(k, |n| n.name.clone()).flatten()
    {
        s.record(&name, rows);
    }
}

/// The IO side: the MQTT client, the broker task's resume signal, the
/// node readers' command channels and update slots.
struct Io {
    client: AsyncClient,
    resume: mpsc::UnboundedSender<()>,
    cmd_txs: Vec<std::sync::mpsc::Sender<NodeCommand>>,
    rollouts: RolloutIo,
}

/// What a roll-out needs: the readers' update slots, the channel of the
/// readers' reports, the readers' stop flag.
struct RolloutIo {
    slots: Vec<UpdateSlot>,
    tx: mpsc::WeakSender<NodeMsg>,
    stop: Arc<AtomicBool>,
}

impl RolloutIo {
    /// Run a roll-out on a thread of its own; it reports each node's end
    /// and its own like a reader. `Err` when it cannot start.
    fn start(
        &self,
        image: Arc<fois_link::signed_image::SignedImage>,
        order: Vec<usize>,
        opts: fois_link::update::UpdateOptions,
    ) -> Result<(), String> {
        let mut tx = self
            .tx
            .upgrade()
            .ok_or_else(|| "the node readers have stopped".to_string())?;
        let slots = self.slots.clone();
        let stop = self.stop.clone();
        std::thread::Builder::new()
            .name("rollout".into())
            .spawn(move || {
                let mut last = order.first().copied().unwrap_or(0);
                let outcome = run_rollout(
                    &order,
                    &image,
                    &opts,
                    &slots,
                    PICKUP_TIMEOUT,
                    &stop,
                    &mut |k, o| {
                        last = k;
                        let (ok, detail) = match o {
                            NodeOutcome::Updated(r) => (true, update_text(r)),
                            NodeOutcome::Failed(why) => (false, why.clone()),
                        };
                        let update = NodeUpdate::UpdateDone { ok, detail };
                        let _ = Sink::send(
                            &mut tx,
                            NodeMsg {
                                node: k,
                                host_unix_ms: unix_ms_now(),
                                update,
                            },
                        );
                    },
                );
                let update = NodeUpdate::RolloutEnd(outcome);
                let _ = Sink::send(
                    &mut tx,
                    NodeMsg {
                        node: last,
                        host_unix_ms: unix_ms_now(),
                        update,
                    },
                );
            })
            .map(|_| ())
            .map_err(|e| format!("cannot start the roll-out thread: {e}"))
    }
}

impl Io {
    fn broker_event(&mut self, gw: &mut Gateway, ev: BrokerEvent) {
        match ev {
            BrokerEvent::Down(reason) => {
                gw.on_disconnected(&reason);
                // Requests made before the gateway learnt of the loss are
                // dropped with the client's replay buffer.
                let _ = self.resume.send(());
            }
            BrokerEvent::Mqtt(Event::Incoming(Incoming::ConnAck(_))) => {
                gw.on_connected(Instant::now())
            }
            BrokerEvent::Mqtt(Event::Outgoing(Outgoing::Publish(pkid))) => {
                gw.on_outgoing_publish(pkid)
            }
            BrokerEvent::Mqtt(Event::Outgoing(Outgoing::AwaitAck(pkid))) => {
                // Cannot happen while WINDOW < INFLIGHT; say so if it does.
                warn!("internal: packet id {pkid} collided; records may be sent twice");
                gw.on_outgoing_publish(pkid);
            }
            BrokerEvent::Mqtt(Event::Incoming(Incoming::PubAck(p))) => gw.on_puback(p.pkid),
            BrokerEvent::Mqtt(Event::Outgoing(Outgoing::Subscribe(pkid))) => {
                gw.on_outgoing_subscribe(pkid)
            }
            BrokerEvent::Mqtt(Event::Incoming(Incoming::SubAck(s))) => {
                gw.on_suback(s.pkid, Instant::now())
            }
            BrokerEvent::Mqtt(Event::Incoming(Incoming::Publish(p))) => {
                gw.on_incoming(&p.topic, &p.payload, p.retain, Instant::now())
            }
            BrokerEvent::Mqtt(_) => {}
        }
    }

    /// Hand the gateway's actions to the client and the readers. Once the
    /// client's request channel refuses one, the publishes and
    /// subscriptions after it go back to the gateway (in order: its packet
    /// bookkeeping follows the order of requests); commands still go out.
    fn carry_out(&mut self, gw: &mut Gateway) {
        let mut unsent = Vec::new();
        for a in gw.actions() {
            let sent = match &a {
                Action::RollOut { image, order, opts } => {
                    if let Err(why) =
                        self.rollouts
                            .start(image.clone(), order.clone(), opts.clone())
                    {
                        gw.rollout_failed_to_start(&why);
                    }
                    continue;
                }
                Action::Command { node, command } => {
                    let delivered = self
                        .cmd_txs
                        .get(*node)
                        .is_some_and(|tx| tx.send(*command).is_ok());
                    if !delivered {
                        gw.unsent(std::slice::from_ref(&a));
                    }
                    continue;
                }
                _ if !unsent.is_empty() => false,
                Action::Publish {
                    topic,
                    payload,
                    qos,
                    retain,
                } => self
                    .client
                    .try_publish(topic.clone(), *qos, *retain, payload.clone())
                    .is_ok(),
                Action::Subscribe { topic, .. } => self
                    .client
                    .try_subscribe(topic.clone(), rumqttc::QoS::AtLeastOnce)
                    .is_ok(),
            };
            if !sent {
                unsent.push(a);
            }
        }
        if !unsent.is_empty() {
            gw.unsent(&unsent);
        }
    }
}

#[cfg(test)]
mod tests;
