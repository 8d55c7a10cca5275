//! Commands from MQTT (`ack`, `calibrate-dark`; a plain word or
//! `{"command": "ack"}`) on a node's command topic, when commands are
//! enabled. Refused, with a `<node>/command/result` saying why: a message
//! larger than any command, a retained message (it would be carried out
//! again at every reconnection: the gateway also deletes it), an unknown
//! word, a command for an offline node, and a command sooner than
//! `[commands] min_interval_ms` after the node's last one (each
//! `calibrate-dark` is a flash save on the board). An empty message (what
//! deletes a retained one) is ignored.
//!
//! **Retained while connected.** A broker hands a message to a client that
//! is already subscribed with the retain flag cleared, even when it was
//! published retained (MQTT 3.1.1, §3.3.1.3): the flag alone cannot tell.
//! So before a command is carried out the gateway subscribes to its topic
//! again: the broker then sends the topic's retained message, if there is
//! one, flagged retained, right after its SUBACK. A command is carried out
//! only when [`RETAINED_GRACE`](super::retained_check::RETAINED_GRACE)
//! after that SUBACK no retained copy of it came (the check itself:
//! [`super::retained_check`]); a copy means it was retained: refused and deleted. This costs a
//! command one round trip and the grace.

use std::time::Instant;

use fois_link::timefmt::unix_ms_now;
use rumqttc::QoS;
use tracing::{info, warn};

use super::retained_check::{CHECK_TIMEOUT, Check, Verdict};
use super::{Action, Gateway};
use crate::command::{MAX_COMMAND_BYTES, NodeCommand, Refusal, command_word};
use crate::payload::CommandResultJson;

impl Gateway {
    /// `<node>/command/result`: what became of a command from MQTT (QoS 0,
    /// not retained, not queued: it answers whoever is listening now).
    pub(super) fn publish_command_result(
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

    fn refuse_command(&mut self, name: &str, shown: &str, detail: String) {
        warn!("command `{shown}` for {name} refused: {detail}");
        self.publish_command_result(name, shown, false, detail, unix_ms_now());
    }

    /// Delete a retained message on `topic` (an empty retained message).
    fn clear_retained(&mut self, topic: &str) {
        self.publish_now(topic.to_string(), Vec::new(), true, QoS::AtLeastOnce);
    }

    /// A message arrived on a subscribed topic.
    pub fn on_incoming(&mut self, topic: &str, payload: &[u8], retained: bool, now: Instant) {
        if topic == self.topics.owner() {
            self.on_claim(payload, now);
            return;
        }
        if topic == self.topics.gateway_availability() {
            self.on_own_availability(payload, now);
            return;
        }
        if self.cfg.firmware.is_some() && topic == self.topics.firmware_command() {
            self.on_firmware_command(payload, retained);
            return;
        }
        if self.cfg.command_topic.is_none() {
            return;
        }
        let Some(k) = (0..self.nodes.len()).find(|&k| {
            self.node_name(k)
                .and_then(|name| self.topics.command(&name))
                .is_some_and(|t| t == topic)
        }) else {
            warn!("ignored a message on {topic}: not a command topic");
            return;
        };
        let name = self.node_name(k).unwrap_or_default();
        if payload.is_empty() {
            // An empty message deletes a retained one: not a command.
            return;
        }
        if payload.len() > MAX_COMMAND_BYTES {
            self.refuse_command(
                &name,
                "?",
                format!(
                    "a {}-byte message was skipped: a command is at most {MAX_COMMAND_BYTES} bytes",
                    payload.len()
                ),
            );
            if retained {
                self.clear_retained(topic);
            }
            return;
        }
        let text = String::from_utf8_lossy(payload).to_string();
        let word = command_word(&text);
        let shown: String = word.trim().chars().take(40).collect();
        if shown.is_empty() {
            return;
        }
        if retained {
            // The copy a check's subscription brought: that command was
            // retained too, it is refused once, here.
            if self.nodes[k]
                .check
                .as_ref()
                .is_some_and(|c| c.payload == payload)
            {
                self.nodes[k].check = None;
            }
            self.refuse_command(
                &name,
                &shown,
                "a retained command is never carried out (it would repeat on every \
                 reconnection); the gateway deleted it"
                    .into(),
            );
            self.clear_retained(topic);
            return;
        }
        let Some(cmd) = NodeCommand::parse(&word) else {
            self.refuse_command(
                &name,
                &shown,
                "unknown command: use ack or calibrate-dark".into(),
            );
            return;
        };
        if self.nodes[k].check.is_some() {
            self.refuse_command(
                &name,
                &shown,
                "the node's previous command is still being checked".into(),
            );
            return;
        }
        self.nodes[k].check = Some(Check::new(cmd, shown, payload.to_vec(), now));
        self.subscribe(topic.to_string(), Some(k));
    }

    /// The checking subscription of node `k` was confirmed.
    pub(super) fn check_subscribed(&mut self, k: usize, now: Instant) {
        if let Some(c) = self.nodes.get_mut(k).and_then(|n| n.check.as_mut()) {
            c.subscribed(now);
        }
    }

    /// Carry out the commands no retained copy came for; refuse those
    /// whose check got no SUBACK.
    pub(super) fn finish_checks(&mut self, now: Instant) {
        for k in 0..self.nodes.len() {
            let verdict = match &self.nodes[k].check {
                Some(c) => c.verdict(now),
                None => continue,
            };
            if verdict == Verdict::Waiting {
                continue;
            }
            let Some(c) = self.nodes[k].check.take() else {
                continue;
            };
            if verdict == Verdict::Passed {
                // Its refusal is published and logged there.
                let _ = self.request_command(k, &c.shown, c.command, "MQTT", now);
            } else {
                let name = self.node_name(k).unwrap_or_default();
                self.refuse_command(
                    &name,
                    &c.shown,
                    format!(
                        "the broker did not confirm the check for a retained copy within {} s",
                        CHECK_TIMEOUT.as_secs()
                    ),
                );
            }
        }
    }

    /// The connection is gone: commands being checked cannot be checked.
    pub(super) fn drop_checks(&mut self) {
        for k in 0..self.nodes.len() {
            if let Some(c) = self.nodes[k].check.take() {
                warn!(
                    "command `{}` for {} dropped: the broker connection was lost before it \
                     could be checked",
                    c.shown,
                    self.node_name(k).as_deref().unwrap_or("?")
                );
            }
        }
    }

    /// A command from another front end (see
    /// [`crate::command::FrontEndCommand`]): the same checks as MQTT's.
    pub fn front_end_command(
        &mut self,
        node: usize,
        cmd: NodeCommand,
        now: Instant,
    ) -> Result<(), Refusal> {
        if node >= self.nodes.len() {
            return Err(Refusal::Offline);
        }
        self.request_command(node, cmd.name(), cmd, "a front end", now)
    }

    /// Hand `cmd` to node `k` unless it is offline or its last command was
    /// too recent (then answer why).
    fn request_command(
        &mut self,
        k: usize,
        shown: &str,
        cmd: NodeCommand,
        from: &str,
        now: Instant,
    ) -> Result<(), Refusal> {
        let name = self.node_name(k).unwrap_or_default();
        if !self.online(k) {
            self.refuse_command(&name, shown, "the node is offline".into());
            return Err(Refusal::Offline);
        }
        let min = self.cfg.command_min_interval;
        if let Some(last) = self.nodes[k].last_command {
            let since = now.saturating_duration_since(last);
            if since < min {
                self.refuse_command(
                    &name,
                    shown,
                    format!(
                        "rate limit: one command per {:.1} s per node, the last was {:.1} s ago",
                        min.as_secs_f64(),
                        since.as_secs_f64()
                    ),
                );
                return Err(Refusal::RateLimit);
            }
        }
        self.nodes[k].last_command = Some(now);
        info!("command {} for {name} from {from}", cmd.name());
        self.out.push(Action::Command {
            node: k,
            command: cmd,
        });
        Ok(())
    }
}
