//! What the node readers report: a node connected (named after its unique
//! id when the config gives no name), lost, unreachable; its frames —
//! sequence gaps and restarts as gateway events, measurements into the
//! retained state (when it changed), the rate-limited measurement records
//! and the shared snapshot, events as records; the answers to commands.

use std::time::{Duration, Instant};

use fois_link::reading::{EventReading, Reading};
use fois_link::text::hello_text;
use fois_protocol::{DeviceMsg, SeqEvent};
use rumqttc::QoS;
use tracing::{info, warn};

use super::Gateway;
use super::journal::{self, Level, Line};
use crate::payload::{EventJson, LinkEventJson, MeasurementJson, StateJson};
use crate::reader::{NodeMsg, NodeUpdate};

impl Gateway {
    /// Write `line` about node `k` to the log unless its rate limit
    /// holds it back.
    fn journal(&mut self, k: usize, line: Line, now: Instant) {
        self.report_suppressed(now);
        if !self.journal.admit(k, line.kind, now) {
            return;
        }
        match line.level {
            Level::Info => info!("{}", line.text),
            Level::Warn => warn!("{}", line.text),
        }
    }

    /// Say how many lines the rate limit left out, for each window that
    /// has ended.
    pub(super) fn report_suppressed(&mut self, now: Instant) {
        for (k, kind, n) in self.journal.lifted(now) {
            let name = self.node_name(k).unwrap_or_else(|| self.node_port(k));
            warn!(
                "node {name}: {n} more `{kind}` line(s) were left out of the log in the last {} s \
                 (at most {} per node and kind per {} s are written; every event still went \
                 to MQTT)",
                journal::WINDOW.as_secs(),
                journal::LINES_PER_WINDOW,
                journal::WINDOW.as_secs()
            );
        }
    }

    fn link_event(
        &mut self,
        k: usize,
        kind: &'static str,
        detail: String,
        seq: Option<u32>,
        frames_lost: Option<u64>,
        t_ms: u64,
    ) {
        let Some(name) = self.node_name(k) else {
            return;
        };
        let mut e = LinkEventJson::new(&name, kind, detail, t_ms);
        e.seq = seq;
        e.frames_lost = frames_lost;
        let payload = serde_json::to_vec(&e).unwrap_or_default();
        self.queue_record(self.topics.event(&name), payload);
    }

    /// A report of a node reader.
    pub fn on_node(&mut self, m: NodeMsg, now: Instant) {
        let k = m.node;
        if k >= self.nodes.len() {
            return;
        }
        let t = m.host_unix_ms;
        match m.update {
            NodeUpdate::Up(h) => {
                let port = self.node_port(k);
                let named = self.node_name(k).is_none();
                let name = self.fleet.connected(k, &h).unwrap_or_default();
                if named {
                    info!(
                        "node on {port} has no name in the config: named {name} after its unique id"
                    );
                }
                info!("node {name} on {port}: connected ({})", hello_text(&h));
                self.link_event(
                    k,
                    "link_up",
                    format!("port={port} {}", hello_text(&h)),
                    None,
                    None,
                    t,
                );
                self.announce_node(k);
            }
            NodeUpdate::Down(reason) => {
                let name = self.node_name(k).unwrap_or_default();
                let line = Line {
                    kind: "link_lost",
                    level: Level::Warn,
                    text: format!(
                        "node {name} on {}: link lost ({reason}); reconnecting",
                        self.node_port(k)
                    ),
                };
                self.journal(k, line, now);
                self.fleet.update(k, |n| n.link_up = false);
                self.link_event(k, "link_lost", reason, None, None, t);
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
                warn!(
                    "node on {}: cannot connect ({reason}); retrying",
                    self.node_port(k)
                );
            }
            NodeUpdate::Rejected => {}
            NodeUpdate::CommandResult {
                command,
                ok,
                detail,
            } => {
                let name = self.node_name(k).unwrap_or_default();
                info!(
                    "command {} for {name}: {} ({detail})",
                    command.name(),
                    if ok { "done" } else { "failed" }
                );
                self.publish_command_result(&name, command.name(), ok, detail, t);
            }
            NodeUpdate::Frame(f, ev) => self.on_frame(k, f, ev, t, now),
            NodeUpdate::Update(e) => self.on_update_event(k, e, t),
            NodeUpdate::UpdateDone { ok, detail } => self.on_update_done(k, ok, detail, t),
            NodeUpdate::RolloutEnd(o) => self.on_rollout_end(o, t),
        }
    }

    fn on_frame(
        &mut self,
        k: usize,
        f: fois_protocol::DeviceFrame,
        ev: SeqEvent,
        t: u64,
        now: Instant,
    ) {
        self.sum.frames += 1;
        self.nodes[k].frames += 1;
        match ev {
            SeqEvent::Gap(n) => {
                self.sum.frames_lost += n;
                self.fleet.update(k, |s| s.frames_lost += n);
                self.link_event(
                    k,
                    "frames_lost",
                    format!("{n} frame(s) missing before seq {}", f.seq),
                    Some(f.seq),
                    Some(n),
                    t,
                );
            }
            SeqEvent::Restart => {
                self.nodes[k].last_meas_uptime = None;
                let detail = match &f.msg {
                    DeviceMsg::Hello(h) => format!("reset reason {:?}", h.reset_reason),
                    _ => "sequence number went back".into(),
                };
                let name = self.node_name(k).unwrap_or_default();
                warn!("node {name} restarted ({detail}) at seq {}", f.seq);
                self.link_event(k, "node_restart", detail, Some(f.seq), None, t);
                if let DeviceMsg::Hello(h) = &f.msg {
                    let h = h.clone();
                    self.fleet.update(k, |n| n.hello = Some(h));
                    self.announce_node(k);
                }
            }
            SeqEvent::First | SeqEvent::InOrder | SeqEvent::Duplicate => {}
        }
        let Some(name) = self.node_name(k) else {
            return;
        };
        if let Some(reading) = Reading::of(&f.msg) {
            self.on_reading(k, &name, f.seq, reading, t, now);
        } else if let DeviceMsg::Event(e) = &f.msg {
            let r = EventReading::new(e);
            let estimate = self
                .fleet
                .read(k, |n| n.reading.as_ref().and_then(|x| x.estimate))
                .flatten();
            self.journal(k, journal::event_line(&name, &r, estimate.as_ref()), now);
            let payload =
                serde_json::to_vec(&EventJson::new(&name, f.seq, &r, t)).unwrap_or_default();
            self.queue_record(self.topics.event(&name), payload);
        }
    }

    fn on_reading(&mut self, k: usize, name: &str, seq: u32, r: Reading, t: u64, now: Instant) {
        let lost = self.fleet.read(k, |n| n.frames_lost).unwrap_or(0);
        let frames = (self.nodes[k].frames, lost);
        let was_acked = self
            .fleet
            .read(k, |n| n.reading.as_ref().map(|x| x.alarm_acked))
            .flatten();
        if r.alarm_acked && was_acked == Some(false) {
            self.journal(k, journal::acknowledged_line(name, &r), now);
        }
        let state = StateJson::new(name, seq, &r, frames, t);
        self.nodes[k].last_state = Some(state.clone());
        self.new_entities(k, &r);
        let interval = Duration::from_millis(self.cfg.state_interval_ms);
        if let Some(s) = self.nodes[k].state_filter.offer(state, now, interval) {
            self.publish_state(s);
        }
        let interval = if self.connected {
            self.cfg.measurement_interval_ms
        } else {
            self.cfg.offline_measurement_interval_ms
        };
        let take = match self.nodes[k].last_meas_uptime {
            None => true,
            Some(last) => r.uptime_ms < last || r.uptime_ms - last >= interval,
        };
        if take {
            self.nodes[k].last_meas_uptime = Some(r.uptime_ms);
            let payload =
                serde_json::to_vec(&MeasurementJson::new(name, seq, &r, t)).unwrap_or_default();
            self.queue_record(self.topics.measurement(name), payload);
        }
        self.fleet.update(k, |s| {
            s.reading = Some(r);
            s.seq = Some(seq);
            s.received = Some(now);
            s.received_unix_ms = Some(t);
        });
    }
}
