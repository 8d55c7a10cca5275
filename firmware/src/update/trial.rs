//! The trial boot: a new image confirms itself only after a self-test
//! within a deadline, else it asks for a reset and the bootloader rolls
//! back to the previous image; after a rollback the old image reports it
//! once and confirms itself so a new update can begin.
//!
//! **The self-test** (all three, counted from the first frame):
//! - [`TRIAL_FRAMES`] frames measured with plausible values (no flag of
//!   `flags::INVALID_MASK`: nothing saturated);
//! - the config store read at boot (a record or an empty store; a store
//!   that cannot be read or decoded fails the test);
//! - the link: a host command decoded and answered (framed or Modbus), or
//!   [`TRIAL_FRAMES`] measurement frames streamed out.
//!
//! **The deadline**: [`trial_deadline_ms`] after the first frame —
//! [`TRIAL_GRACE_MS`] plus [`TRIAL_FRAMES`] + 2 frame periods. The grace
//! covers what can delay a healthy node's first command after a reset: the
//! boot read's supply gate (≤ 10 s), a store repair erase (≤ 5 s) and the
//! host's (or the gateway's) reconnect after the commit's reset; the frame
//! periods let a node measuring every 10 min still finish its frames. A
//! hang or a panic on trial ends earlier, in a watchdog or panic reset,
//! which the bootloader rolls back the same way.

use fois_protocol::{EventKind, FirmwareVersion, ImageState};

/// Plausible frames a trial needs (and streamed frames that prove the link
/// when no command comes).
pub const TRIAL_FRAMES: u8 = 3;

/// The deadline's fixed part, ms.
pub const TRIAL_GRACE_MS: u64 = 60_000;

/// How long a trial may take from its first frame, ms, at a frame period of
/// `frame_period_ms`.
pub const fn trial_deadline_ms(frame_period_ms: u32) -> u64 {
    TRIAL_GRACE_MS + (TRIAL_FRAMES as u64 + 2) * frame_period_ms as u64
}

/// What the node does now about its trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrialAction {
    /// Nothing.
    None,
    /// Mark the image booted (embassy-boot's `mark_booted`) and report
    /// [`EventKind::ImageConfirmed`].
    Confirm,
    /// The deadline passed without the self-test: reset, the bootloader
    /// rolls back.
    Rollback,
    /// After a rollback: report [`EventKind::ImageRolledBack`] and mark the
    /// old image booted so a new update can begin.
    ReportRollback,
}

/// The trial's progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Trial {
    state: ImageState,
    running: FirmwareVersion,
    store_ok: bool,
    frames_ok: u8,
    frames_out: u8,
    link_ok: bool,
    started_ms: Option<u64>,
    /// The action was taken (or there is none to take).
    done: bool,
}

impl Trial {
    /// A trial for an image that booted in `state`, running `running`;
    /// `store_ok`: the config store was read at boot.
    pub fn new(state: ImageState, running: FirmwareVersion, store_ok: bool) -> Self {
        Trial {
            state,
            running,
            store_ok,
            frames_ok: 0,
            frames_out: 0,
            link_ok: false,
            started_ms: None,
            done: state == ImageState::Confirmed,
        }
    }

    /// A frame was measured (`plausible`: no invalid flag; `streamed`: its
    /// measurement went out on the link).
    pub fn frame(&mut self, now_ms: u64, plausible: bool, streamed: bool) {
        self.started_ms.get_or_insert(now_ms);
        if plausible {
            self.frames_ok = self.frames_ok.saturating_add(1);
        }
        if streamed {
            self.frames_out = self.frames_out.saturating_add(1);
        }
    }

    /// A host command was decoded and answered.
    pub fn link_answered(&mut self) {
        self.link_ok = true;
    }

    /// True once the self-test passed.
    pub fn passed(&self) -> bool {
        self.store_ok
            && self.frames_ok >= TRIAL_FRAMES
            && (self.link_ok || self.frames_out >= TRIAL_FRAMES)
    }

    /// True while the image is on trial and has not confirmed.
    pub fn pending(&self) -> bool {
        self.state == ImageState::Trial && !self.done
    }

    /// What to do at `now_ms` with frames every `frame_period_ms`.
    pub fn step(&self, now_ms: u64, frame_period_ms: u32) -> TrialAction {
        if self.done {
            return TrialAction::None;
        }
        match self.state {
            ImageState::Confirmed => TrialAction::None,
            ImageState::RolledBack { .. } => {
                if self.started_ms.is_some() {
                    TrialAction::ReportRollback
                } else {
                    TrialAction::None
                }
            }
            ImageState::Trial => {
                let Some(start) = self.started_ms else {
                    return TrialAction::None;
                };
                if self.passed() {
                    TrialAction::Confirm
                } else if now_ms.saturating_sub(start) >= trial_deadline_ms(frame_period_ms) {
                    TrialAction::Rollback
                } else {
                    TrialAction::None
                }
            }
        }
    }

    /// The action was carried out: the event it reports, if any (a
    /// rollback request reports nothing: the old image will).
    pub fn done(&mut self, action: TrialAction) -> Option<EventKind> {
        match action {
            TrialAction::None => None,
            TrialAction::Confirm => {
                self.done = true;
                self.state = ImageState::Confirmed;
                Some(EventKind::ImageConfirmed {
                    version: self.running,
                })
            }
            TrialAction::Rollback => {
                self.done = true;
                None
            }
            TrialAction::ReportRollback => {
                self.done = true;
                match self.state {
                    ImageState::RolledBack { failed } => Some(EventKind::ImageRolledBack {
                        failed,
                        running: self.running,
                    }),
                    _ => None,
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V: FirmwareVersion = [0, 2, 0];

    #[test]
    fn a_trial_confirms_after_frames_store_and_link() {
        let mut t = Trial::new(ImageState::Trial, V, true);
        assert!(t.pending());
        assert_eq!(t.step(0, 1_000), TrialAction::None, "no frame yet");
        for i in 0..3 {
            t.frame(1_000 * i, true, false);
        }
        assert_eq!(t.step(3_000, 1_000), TrialAction::None, "no link yet");
        t.link_answered();
        assert_eq!(t.step(3_000, 1_000), TrialAction::Confirm);
        assert_eq!(
            t.done(TrialAction::Confirm),
            Some(EventKind::ImageConfirmed { version: V })
        );
        assert!(!t.pending());
        assert_eq!(t.step(4_000, 1_000), TrialAction::None);
    }

    #[test]
    fn streamed_frames_prove_the_link_too() {
        let mut t = Trial::new(ImageState::Trial, V, true);
        for i in 0..3 {
            t.frame(1_000 * i, true, true);
        }
        assert_eq!(t.step(2_000, 1_000), TrialAction::Confirm);
    }

    #[test]
    fn a_failed_self_test_rolls_back_at_the_deadline() {
        // Saturated frames: the test never passes.
        let mut t = Trial::new(ImageState::Trial, V, true);
        t.link_answered();
        let deadline = trial_deadline_ms(1_000);
        assert_eq!(deadline, 65_000);
        let mut now = 5_000;
        t.frame(now, false, true);
        while now < 5_000 + deadline - 1_000 {
            now += 1_000;
            t.frame(now, false, true);
            assert_eq!(t.step(now, 1_000), TrialAction::None, "at {now} ms");
        }
        now += 1_000;
        assert_eq!(t.step(now, 1_000), TrialAction::Rollback);
        // An unreadable store fails it as well.
        let mut t = Trial::new(ImageState::Trial, V, false);
        t.link_answered();
        for i in 0..10 {
            t.frame(i * 1_000, true, true);
        }
        assert_eq!(t.step(9_000, 1_000), TrialAction::None);
        assert_eq!(t.step(65_000, 1_000), TrialAction::Rollback);
    }

    #[test]
    fn a_rollback_is_reported_once_with_the_first_frame() {
        let failed = [0, 3, 0];
        let mut t = Trial::new(ImageState::RolledBack { failed }, V, true);
        assert_eq!(t.step(0, 1_000), TrialAction::None);
        t.frame(10, true, false);
        assert_eq!(t.step(10, 1_000), TrialAction::ReportRollback);
        assert_eq!(
            t.done(TrialAction::ReportRollback),
            Some(EventKind::ImageRolledBack { failed, running: V })
        );
        assert_eq!(t.step(20, 1_000), TrialAction::None);
        // A confirmed image has no trial.
        let t = Trial::new(ImageState::Confirmed, V, false);
        assert_eq!(t.step(1_000_000, 1_000), TrialAction::None);
    }
}
