//! The firmware transfer's commands carried out on the node's
//! [`UpdateSlots`], and the trial boot run beside the frames: the
//! self-test's inputs (frames, the store, the link), the confirmation or
//! the reset that rolls back, the rollback's report
//! (`crate::update::trial`).
//!
//! Flash work stays short per command, so frames go on during a transfer:
//! a begin erases one page (one 128 KiB sector on the board, the longest
//! gap), a chunk programs at most 256 bytes and its marks (and erases a page
//! when the image first enters it), a verify or a commit hashes the image
//! and checks its signature once (`firmware/README.md` gives its time).

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use fois_protocol::{AckResult, ErrorCode, EventKind, ImageInfo};

use super::Node;
use crate::hal::PhotoAdc;
use crate::storage::Storage;
use crate::update::{Refused, TrialAction, UpdateSlots};

/// The error a refused piece of a transfer is answered with.
pub fn refusal_code(r: Refused) -> ErrorCode {
    match r {
        Refused::Unsupported => ErrorCode::UnknownCommand,
        Refused::Update(reason) => ErrorCode::UpdateRefused(reason),
    }
}

impl<A, L, AL, IND, D, S, U> Node<A, L, AL, IND, D, S, U>
where
    A: PhotoAdc,
    L: OutputPin,
    AL: OutputPin,
    IND: OutputPin,
    D: DelayNs,
    S: Storage,
    U: UpdateSlots,
{
    /// Which image runs, how it booted, the largest image the slot takes.
    pub fn image_info(&self) -> ImageInfo {
        ImageInfo {
            version: self.updates.running_version(),
            state: self.updates.image_state(),
            slot_bytes: self.updates.slot_bytes(),
        }
    }

    /// The update slots (tests, the virtual node).
    pub fn updates(&self) -> &U {
        &self.updates
    }

    /// The host link answered a request the node cannot see as a command
    /// (the board's Modbus server answering a read): the trial's link
    /// check. Commands (framed, or a Modbus write) count by themselves.
    pub fn link_answered(&mut self) {
        self.trial.link_answered();
    }

    /// True while the running image is on trial and not yet confirmed.
    pub fn on_trial(&self) -> bool {
        self.trial.pending()
    }

    /// `Command::UpdateCommit`: the verified image boots next; whatever
    /// waits to be saved is saved, and the node asks for its reset.
    pub(super) fn commit_update(&mut self, now_ms: u64) -> Result<AckResult, ErrorCode> {
        let version = self.updates.commit().map_err(refusal_code)?;
        if self.pending_save.is_some() {
            self.save(now_ms);
        }
        self.reset_request = true;
        Ok(AckResult::UpdateCommitted { version })
    }

    /// After each frame: the trial's step. Gives the event to report
    /// (image confirmed, rolled back); a trial past its deadline asks for
    /// the reset that rolls back.
    pub(super) fn trial_after_frame(
        &mut self,
        now_ms: u64,
        plausible: bool,
        streamed: bool,
    ) -> Option<EventKind> {
        if !self.trial.pending()
            && self.updates.image_state() == fois_protocol::ImageState::Confirmed
        {
            return None;
        }
        self.trial.frame(now_ms, plausible, streamed);
        let action = self.trial.step(now_ms, self.frame_period_ms());
        match action {
            TrialAction::None => None,
            // Confirmed only once the boot state says so; a failed write is
            // tried again after the next frame.
            TrialAction::Confirm => match self.updates.confirm() {
                Ok(()) => self.trial.done(action),
                Err(_) => None,
            },
            // Reported even if the mark fails (the next boot reports again).
            TrialAction::ReportRollback => {
                let _ = self.updates.confirm();
                self.trial.done(action)
            }
            TrialAction::Rollback => {
                if self.pending_save.is_some() {
                    self.save(now_ms);
                }
                self.reset_request = true;
                self.trial.done(action)
            }
        }
    }
}
