//! Roll-outs in the state machine: the command on the firmware topic
//! (checked: not retained, a known image name of `[firmware] dir`, a signed
//! image, known nodes, no roll-out running) becomes an
//! [`Action::RollOut`]; the readers' progress and the roll-out's results
//! are published (progress QoS 0; each node's result and the roll-out's
//! retained). The sequencing itself is [`crate::rollout`]'s.

use std::sync::Arc;

use fois_link::signed_image::SignedImage;
use fois_link::timefmt::unix_ms_now;
use fois_link::update::{UpdateEvent, UpdateOptions};
use rumqttc::QoS;
use tracing::{info, warn};

use super::{Action, Gateway};
use crate::config::firmware::image_path;
use crate::payload::{RolloutResultJson, UpdateProgressJson, UpdateResultJson};
use crate::rollout::{NodeOutcome, RolloutCommand, RolloutOutcome};

impl Gateway {
    /// Subscribe to the firmware topic (roll-outs configured).
    pub(super) fn watch_firmware(&mut self) {
        if self.cfg.firmware.is_some() {
            self.subscribe(self.topics.firmware_command(), None);
        }
    }

    fn publish_rollout_result(&mut self, r: RolloutResultJson) {
        let payload = serde_json::to_vec(&r).unwrap_or_default();
        self.publish_now(
            self.topics.firmware_result(),
            payload,
            true,
            QoS::AtLeastOnce,
        );
    }

    fn refuse_rollout(&mut self, image: &str, detail: String) {
        warn!("roll-out of `{image}` refused: {detail}");
        self.publish_rollout_result(RolloutResultJson {
            image: image.to_string(),
            ok: false,
            detail,
            updated: Vec::new(),
            failed: None,
            not_reached: Vec::new(),
            host_unix_ms: unix_ms_now(),
        });
    }

    /// A message on the firmware topic.
    pub(super) fn on_firmware_command(&mut self, payload: &[u8], retained: bool) {
        let Some(fw) = self.cfg.firmware.clone() else {
            return;
        };
        if payload.is_empty() {
            // What deletes a retained message: not a command.
            return;
        }
        let cmd = match RolloutCommand::parse(payload) {
            Ok(c) => c,
            Err(why) => return self.refuse_rollout("?", why),
        };
        if retained {
            self.refuse_rollout(
                &cmd.image,
                "a retained roll-out command is never carried out (it would repeat on every \
                 reconnection); the gateway deleted it"
                    .into(),
            );
            let topic = self.topics.firmware_command();
            self.publish_now(topic, Vec::new(), true, QoS::AtLeastOnce);
            return;
        }
        if let Some(running) = &self.rollout {
            let detail = format!("the roll-out of `{running}` is still running");
            return self.refuse_rollout(&cmd.image, detail);
        }
        let path = match image_path(&fw.dir, &cmd.image) {
            Ok(p) => p,
            Err(why) => return self.refuse_rollout(&cmd.image, why),
        };
        let image = match std::fs::read(&path)
            .map_err(|e| e.to_string())
            .and_then(|b| SignedImage::from_bytes(b).map_err(|e| e.to_string()))
        {
            Ok(i) => i,
            Err(why) => {
                let detail = format!("{}: {why}", path.display());
                return self.refuse_rollout(&cmd.image, detail);
            }
        };
        let order: Vec<usize> = match &cmd.nodes {
            None => (0..self.nodes.len()).collect(),
            Some(names) => {
                let mut order = Vec::new();
                for n in names {
                    match (0..self.nodes.len()).find(|&k| self.node_name(k).as_deref() == Some(n)) {
                        Some(k) if !order.contains(&k) => order.push(k),
                        Some(_) => {}
                        None => {
                            let detail = format!("no node named `{}` here", n.escape_debug());
                            return self.refuse_rollout(&cmd.image, detail);
                        }
                    }
                }
                order
            }
        };
        info!(
            "roll-out of {} ({}) to {} node(s), one at a time",
            cmd.image,
            fois_link::text::version_text(image.version()),
            order.len()
        );
        self.rollout = Some(cmd.image.clone());
        self.out.push(Action::RollOut {
            image: Arc::new(image),
            order,
            opts: UpdateOptions {
                confirm_timeout: fw.confirm_timeout,
                ..UpdateOptions::default()
            },
        });
    }

    /// The service could not start the roll-out: say why.
    pub fn rollout_failed_to_start(&mut self, why: &str) {
        if let Some(image) = self.rollout.take() {
            self.refuse_rollout(&image, why.to_string());
        }
    }

    /// A reader's update event: `<node>/update/progress`.
    pub(super) fn on_update_event(&mut self, k: usize, e: UpdateEvent, t: u64) {
        let name = self.node_name(k).unwrap_or_default();
        let image = self.rollout.clone().unwrap_or_default();
        let (event, step, done, total) = match e {
            UpdateEvent::Step(s) => {
                info!("node {name}: update {}", s.name());
                ("step", Some(s.name()), None, None)
            }
            UpdateEvent::Progress { done, total } => ("progress", None, Some(done), Some(total)),
            UpdateEvent::Retry { step, offset } => ("retry", Some(step.name()), Some(offset), None),
            UpdateEvent::Resumed { from } => ("resumed", None, Some(from), None),
        };
        let p = UpdateProgressJson {
            node: &name,
            image: &image,
            event,
            step,
            done,
            total,
            host_unix_ms: t,
        };
        let payload = serde_json::to_vec(&p).unwrap_or_default();
        self.publish_now(
            self.topics.update_progress(&name),
            payload,
            false,
            QoS::AtMostOnce,
        );
    }

    /// A node's update ended: `<node>/update/result` (retained).
    pub(super) fn on_update_done(&mut self, k: usize, ok: bool, detail: String, t: u64) {
        let name = self.node_name(k).unwrap_or_default();
        let image = self.rollout.clone().unwrap_or_default();
        if ok {
            info!("node {name}: {detail}");
        } else {
            warn!("node {name}: update to {image} failed: {detail}");
        }
        let r = UpdateResultJson {
            node: &name,
            image: &image,
            ok,
            detail,
            host_unix_ms: t,
        };
        let payload = serde_json::to_vec(&r).unwrap_or_default();
        self.publish_now(
            self.topics.update_result(&name),
            payload,
            true,
            QoS::AtLeastOnce,
        );
    }

    /// The roll-out ended: `<gw>/firmware/result` (retained).
    pub(super) fn on_rollout_end(&mut self, o: RolloutOutcome, t: u64) {
        let image = self.rollout.take().unwrap_or_default();
        let name = |k: usize| self.node_name(k).unwrap_or_else(|| format!("node {k}"));
        let updated: Vec<String> = o
            .results
            .iter()
            .filter(|(_, r)| matches!(r, NodeOutcome::Updated(_)))
            .map(|(k, _)| name(*k))
            .collect();
        let failed = o.results.iter().find_map(|(k, r)| match r {
            NodeOutcome::Failed(why) => Some((name(*k), why.clone())),
            NodeOutcome::Updated(_) => None,
        });
        let not_reached: Vec<String> = o.not_reached.iter().map(|&k| name(k)).collect();
        let detail = match &failed {
            None => format!("{} node(s) updated", updated.len()),
            Some((n, why)) => format!(
                "stopped at {n} ({why}); {} updated before it, {} not reached",
                updated.len(),
                not_reached.len()
            ),
        };
        info!("roll-out of {image}: {detail}");
        self.publish_rollout_result(RolloutResultJson {
            image,
            ok: o.ok(),
            detail,
            updated,
            failed: failed.map(|(n, _)| n),
            not_reached,
            host_unix_ms: t,
        });
    }
}
