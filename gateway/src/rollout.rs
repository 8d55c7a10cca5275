//! Firmware roll-outs: a command names a signed image of the `[firmware]
//! dir`; the gateway updates the nodes it serves one at a time, each by
//! its own reader (which pauses its stream, runs `fois_link::update` on
//! its link and then reconnects: [`UpdateSlot`]), and stops at the first
//! node that fails.
//!
//! The command, on `<prefix>/<gateway>/firmware/command` (not retained):
//! `{"command": "update", "image": "fois-0.7.0.fois"}`, optionally with
//! `"nodes": ["mast-1", "mast-2"]` (default: every configured node, in
//! config order). Progress goes to `<node>/update/progress` (QoS 0), each
//! node's result to `<node>/update/result` (retained), the roll-out's to
//! `<prefix>/<gateway>/firmware/result` (retained).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use fois_link::signed_image::SignedImage;
use fois_link::update::{UpdateOptions, UpdateReport};

/// The longest roll-out command read, bytes.
pub const MAX_ROLLOUT_COMMAND_BYTES: usize = 4096;

/// How long a node's reader has to take its job (it is connected and
/// streaming: it looks at the slot between frames) before the node counts
/// as offline.
pub const PICKUP_TIMEOUT: Duration = Duration::from_secs(30);

/// A roll-out command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RolloutCommand {
    /// The image's file name in the firmware directory.
    pub image: String,
    /// The nodes by name, in order (`None`: every node, config order).
    pub nodes: Option<Vec<String>>,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct CommandJson {
    command: String,
    image: String,
    #[serde(default)]
    nodes: Option<Vec<String>>,
}

impl RolloutCommand {
    /// Parse `{"command": "update", "image": NAME[, "nodes": [...]]}`.
    pub fn parse(payload: &[u8]) -> Result<RolloutCommand, String> {
        if payload.len() > MAX_ROLLOUT_COMMAND_BYTES {
            return Err(format!(
                "a {}-byte message: a roll-out command is at most {MAX_ROLLOUT_COMMAND_BYTES} bytes",
                payload.len()
            ));
        }
        let c: CommandJson = serde_json::from_slice(payload).map_err(|e| {
            format!(
                "not a roll-out command ({e}): send {{\"command\": \"update\", \"image\": \
                 \"NAME.fois\"}}"
            )
        })?;
        if c.command.trim() != "update" {
            return Err(format!(
                "unknown command `{}`: the firmware topic takes `update`",
                c.command.escape_debug()
            ));
        }
        if c.nodes.as_ref().is_some_and(|n| n.is_empty()) {
            return Err("`nodes` is empty: leave it out to update every node".into());
        }
        Ok(RolloutCommand {
            image: c.image,
            nodes: c.nodes,
        })
    }
}

/// One node's update, handed to its reader.
pub struct UpdateJob {
    /// The image.
    pub image: Arc<SignedImage>,
    /// The driver's options.
    pub opts: UpdateOptions,
    /// Where the reader says how it ended.
    pub done: mpsc::Sender<Result<UpdateReport, String>>,
}

/// A node reader's mailbox for an update (one job at a time).
#[derive(Clone, Default)]
pub struct UpdateSlot(Arc<Mutex<Option<UpdateJob>>>);

impl UpdateSlot {
    fn lock(&self) -> MutexGuard<'_, Option<UpdateJob>> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Leave a job for the reader.
    pub fn put(&self, job: UpdateJob) {
        *self.lock() = Some(job);
    }

    /// The job waiting, if any (the reader takes it).
    pub fn take(&self) -> Option<UpdateJob> {
        self.lock().take()
    }
}

/// What became of one node.
#[derive(Debug, Clone, PartialEq)]
pub enum NodeOutcome {
    /// It runs the image, confirmed.
    Updated(UpdateReport),
    /// It failed (the roll-out stopped here): why.
    Failed(String),
}

/// A roll-out's end: the nodes in order with their outcome; the nodes not
/// reached (after a failure) are in `not_reached`.
#[derive(Debug, Clone, PartialEq)]
pub struct RolloutOutcome {
    /// The nodes tried, in order.
    pub results: Vec<(usize, NodeOutcome)>,
    /// The nodes left alone after the first failure.
    pub not_reached: Vec<usize>,
}

impl RolloutOutcome {
    /// Every node updated.
    pub fn ok(&self) -> bool {
        self.not_reached.is_empty()
            && self
                .results
                .iter()
                .all(|(_, o)| matches!(o, NodeOutcome::Updated(_)))
    }
}

/// Update `order`'s nodes one at a time through their readers' `slots`;
/// stop at the first failure. `on_result` sees each node's outcome as it
/// comes. A reader that does not take its job within `pickup` (the node
/// is offline) fails the node; so does `stop` before it took it.
pub fn run_rollout(
    order: &[usize],
    image: &Arc<SignedImage>,
    opts: &UpdateOptions,
    slots: &[UpdateSlot],
    pickup: Duration,
    stop: &AtomicBool,
    on_result: &mut dyn FnMut(usize, &NodeOutcome),
) -> RolloutOutcome {
    let mut results = Vec::new();
    for (i, &k) in order.iter().enumerate() {
        let outcome = update_one(k, image, opts, slots, pickup, stop);
        on_result(k, &outcome);
        let failed = matches!(outcome, NodeOutcome::Failed(_));
        results.push((k, outcome));
        if failed {
            return RolloutOutcome {
                results,
                not_reached: order[i + 1..].to_vec(),
            };
        }
    }
    RolloutOutcome {
        results,
        not_reached: Vec::new(),
    }
}

fn update_one(
    k: usize,
    image: &Arc<SignedImage>,
    opts: &UpdateOptions,
    slots: &[UpdateSlot],
    pickup: Duration,
    stop: &AtomicBool,
) -> NodeOutcome {
    let Some(slot) = slots.get(k) else {
        return NodeOutcome::Failed("no such node".into());
    };
    let (tx, rx) = mpsc::channel();
    slot.put(UpdateJob {
        image: image.clone(),
        opts: opts.clone(),
        done: tx,
    });
    let start = Instant::now();
    loop {
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(Ok(report)) => return NodeOutcome::Updated(report),
            Ok(Err(why)) => return NodeOutcome::Failed(why),
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                return NodeOutcome::Failed("the node's reader stopped".into());
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                if stop.load(Ordering::Relaxed) && slot.take().is_some() {
                    return NodeOutcome::Failed("the gateway is stopping".into());
                }
                // Still in the slot after the pickup time: take it back.
                if start.elapsed() >= pickup && slot.take().is_some() {
                    return NodeOutcome::Failed(format!(
                        "the node is offline (its reader did not take the update within {} s)",
                        pickup.as_secs()
                    ));
                }
            }
        }
    }
}

/// One line for a finished update.
pub fn update_text(r: &UpdateReport) -> String {
    let v = fois_link::text::version_text;
    if r.already_running {
        format!("runs {} already, confirmed", v(r.running))
    } else {
        format!(
            "updated {} -> {}, confirmed (transfer {:.1} s, {} resent, {} resumed)",
            v(r.from_version),
            v(r.running),
            r.transfer_time.as_secs_f64(),
            r.retries,
            r.resumes
        )
    }
}

#[cfg(test)]
mod tests;
