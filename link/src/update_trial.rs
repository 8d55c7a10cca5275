//! After the commit: the update driver ([`crate::update`]) waits for the
//! node to boot the new image (its `Hello`, or its answer to `GetInfo`
//! once a restart was seen) and then for the new image's verdict on its
//! trial: `ImageConfirmed`, or `ImageRolledBack` (also read from
//! `GetImageInfo`, asked now and then: an event can be lost on the line).

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use fois_protocol::{
    Ack, AckResult, Command, DeviceMsg, EventKind, FirmwareVersion, Hello, ImageState, SeqEvent,
};

use crate::link::Incoming;
use crate::update::Driver;
use crate::update_error::{Step, UpdateError, UpdateEvent};

impl<P: Read + Write> Driver<'_, '_, P> {
    /// Wait for the node's boot, then for its verdict on the new image.
    /// Returns the version it runs, confirmed.
    pub(crate) fn confirm(
        &mut self,
        booted: Option<Hello>,
    ) -> Result<FirmwareVersion, UpdateError> {
        let wanted = self.image.version();
        let booted = match booted {
            Some(h) => h,
            None => {
                (self.on_event)(UpdateEvent::Step(Step::Reboot));
                self.wait_boot()?
            }
        };
        (self.on_event)(UpdateEvent::Step(Step::Confirm));
        let start = Instant::now();
        let mut running = booted.firmware_version;
        let mut state = if running == wanted {
            ImageState::Trial
        } else {
            ImageState::RolledBack { failed: wanted }
        };
        let mut last_poll = Instant::now();
        let mut asked: Option<u16> = None;
        while start.elapsed() < self.opts.confirm_timeout {
            if last_poll.elapsed() >= self.opts.status_poll {
                last_poll = Instant::now();
                asked = self.link.send(Command::GetImageInfo).ok();
            }
            let frames = match self.link.poll() {
                Ok(f) => f,
                Err(e) => {
                    self.reconnect(start, Step::Confirm, &e)?;
                    continue;
                }
            };
            for inc in frames {
                let Incoming::Frame(f, _) = inc else { continue };
                match f.msg {
                    DeviceMsg::Event(ev) => match ev.kind {
                        EventKind::ImageConfirmed { version } if version == wanted => {
                            return Ok(version);
                        }
                        EventKind::ImageRolledBack { failed, running } => {
                            return Err(UpdateError::RolledBack { failed, running });
                        }
                        _ => {}
                    },
                    DeviceMsg::Hello(h) => running = h.firmware_version,
                    DeviceMsg::Ack(a) if Some(a.id) == asked => {
                        if let AckResult::ImageInfo(i) = a.result {
                            running = i.version;
                            state = i.state;
                            match i.state {
                                ImageState::Confirmed if i.version == wanted => return Ok(wanted),
                                ImageState::RolledBack { failed } => {
                                    return Err(UpdateError::RolledBack {
                                        failed,
                                        running: i.version,
                                    });
                                }
                                // The old image, confirmed: the commit did
                                // not take (a reset before it).
                                ImageState::Confirmed => {
                                    return Err(UpdateError::NotConfirmed {
                                        running: i.version,
                                        expected: wanted,
                                        state: i.state,
                                        waited_ms: start.elapsed().as_millis() as u64,
                                    });
                                }
                                _ => {}
                            }
                        }
                    }
                    _ => {}
                }
            }
        }
        Err(UpdateError::NotConfirmed {
            running,
            expected: wanted,
            state,
            waited_ms: start.elapsed().as_millis() as u64,
        })
    }

    /// The node's `Hello` after the commit: its boot hello, or (after a
    /// restart was seen, or the port was reopened) the answer to `GetInfo`.
    fn wait_boot(&mut self) -> Result<Hello, UpdateError> {
        let start = Instant::now();
        let ask_after = self.opts.reply_timeout.min(Duration::from_secs(3));
        let mut asked_at: Option<Instant> = None;
        let mut ids: Vec<u16> = Vec::new();
        let mut restarted = false;
        while start.elapsed() < self.opts.boot_timeout {
            if start.elapsed() >= ask_after && asked_at.is_none_or(|t| t.elapsed() >= ask_after) {
                asked_at = Some(Instant::now());
                if let Ok(id) = self.link.send(Command::GetInfo) {
                    ids.push(id);
                }
            }
            let frames = match self.link.poll() {
                Ok(f) => f,
                Err(e) => {
                    self.reconnect(start, Step::Reboot, &e)?;
                    restarted = true;
                    continue;
                }
            };
            let mut frames = frames.into_iter();
            while let Some(inc) = frames.next() {
                let Incoming::Frame(f, seq) = inc else {
                    continue;
                };
                if seq == SeqEvent::Restart {
                    restarted = true;
                }
                let hello = match f.msg {
                    DeviceMsg::Hello(h) if restarted => Some(h),
                    DeviceMsg::Ack(Ack {
                        id,
                        result: AckResult::Info(h),
                    }) if restarted && ids.contains(&id) => Some(h),
                    _ => None,
                };
                if let Some(h) = hello {
                    // Its first events (a confirmation) may be in this batch.
                    self.link.keep(frames);
                    return Ok(h);
                }
            }
        }
        Err(UpdateError::NoBoot {
            waited_ms: start.elapsed().as_millis() as u64,
        })
    }
}
