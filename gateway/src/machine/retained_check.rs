//! The check a command from MQTT waits through before it is carried out
//! (see [`super::commands`]): the gateway subscribes to the command's topic
//! again, and the command passes when [`RETAINED_GRACE`] after that
//! subscription's SUBACK no retained copy of it came; it is refused when no
//! SUBACK comes within [`CHECK_TIMEOUT`].

use std::time::{Duration, Instant};

use crate::command::NodeCommand;

/// After the SUBACK of the checking subscription, a retained copy has this
/// long to arrive (it follows the SUBACK on the same connection at once).
pub const RETAINED_GRACE: Duration = Duration::from_millis(200);

/// A command whose SUBACK does not come within this is refused.
pub const CHECK_TIMEOUT: Duration = Duration::from_secs(10);

/// A command from MQTT being checked for a retained copy.
#[derive(Debug, Clone)]
pub(crate) struct Check {
    /// The command, parsed.
    pub command: NodeCommand,
    /// The word as it came (at most 40 characters), for logs and answers.
    pub shown: String,
    /// The message as it came (a retained copy is recognised by it).
    pub payload: Vec<u8>,
    started: Instant,
    subacked: Option<Instant>,
}

/// Where a check stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Verdict {
    /// Still waiting (for the SUBACK, or through the grace after it).
    Waiting,
    /// No retained copy came: carry the command out.
    Passed,
    /// No SUBACK within [`CHECK_TIMEOUT`]: refuse it.
    TimedOut,
}

impl Check {
    /// A check that starts `now` (its subscription handed to the client).
    pub fn new(command: NodeCommand, shown: String, payload: Vec<u8>, now: Instant) -> Check {
        Check {
            command,
            shown,
            payload,
            started: now,
            subacked: None,
        }
    }

    /// The checking subscription was confirmed `now` (the first SUBACK
    /// counts).
    pub fn subscribed(&mut self, now: Instant) {
        if self.subacked.is_none() {
            self.subacked = Some(now);
        }
    }

    /// Where the check stands at `now`.
    pub fn verdict(&self, now: Instant) -> Verdict {
        if self.subacked.is_some_and(|t| now >= t + RETAINED_GRACE) {
            Verdict::Passed
        } else if now >= self.started + CHECK_TIMEOUT {
            Verdict::TimedOut
        } else {
            Verdict::Waiting
        }
    }
}
