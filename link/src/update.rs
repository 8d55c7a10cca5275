//! The firmware update driver: sends a signed image ([`SignedImage`]) to a
//! connected node over its own link (protocol 6, `fois_protocol::update`)
//! and follows it until the new image confirms itself or rolls back. Used
//! by `foisctl update` and the gateway's roll-out.
//!
//! The steps: handshake (protocol ≥ [`UPDATE_SINCE`]), `GetImageInfo`
//! (the board, the size and the version rule checked on the host first, so
//! a wrong image is refused before 90 KiB cross the link), `UpdateBegin`
//! (the node resumes at its `next_offset` when the digest is that of its
//! transfer in progress), `UpdateChunk`s in order (at most
//! [`UPDATE_CHUNK_MAX`] bytes, CRC-32 ISO-HDLC each, one in flight: the
//! node answers each), `UpdateVerify`, `UpdateCommit`, then the node's
//! `Hello` after its reset and its `ImageConfirmed` (or `ImageRolledBack`)
//! event.
//!
//! Faults: a command without an answer in time, or whose answer arrives
//! garbled, is sent again (a chunk the node already took is answered
//! `OutOfOrder` with the next offset, which counts as taken); after
//! [`UpdateOptions::attempts`] the link counts as down and the driver
//! reopens the port (when it can) and asks `UpdateBegin` again until
//! [`UpdateOptions::resume_timeout`]; a node that resets mid-transfer is
//! picked up the same way. A refusal ends the update with its
//! [`UpdateRefusal`] (after an `UpdateAbort` when the slot's bytes cannot
//! be used again).

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use fois_protocol::update::version_allowed;
use fois_protocol::{
    AckResult, ChunkData, Command, DeviceMsg, ErrorCode, FirmwareVersion, Hello, ImageInfo,
    ImageState, SeqEvent, UPDATE_CHUNK_MAX, UpdateChunk, UpdatePhase, UpdateRefusal, UpdateStatus,
};

use crate::link::{Incoming, Link, LinkError};
use crate::signed_image::{SignedImage, board_text};
use crate::text::hello_text;
pub use crate::update_error::{Step, UpdateError, UpdateEvent, UpdateReport};

/// The first protocol version with the update commands.
pub const UPDATE_SINCE: u16 = 6;

/// Timings and limits of the driver.
#[derive(Debug, Clone, PartialEq)]
pub struct UpdateOptions {
    /// How long one command waits for its answer: the protocol's
    /// `REPLY_TIMEOUT_MS` (an answer can wait behind a frame and an erase).
    pub reply_timeout: Duration,
    /// After a frame the decoder rejected (perhaps the answer, garbled),
    /// send again when no answer came within this.
    pub garbled_wait: Duration,
    /// Sends of one command before the link counts as down.
    pub attempts: u32,
    /// How long a down link (no answers, port gone) is tried again before
    /// the update stops (a later run continues).
    pub resume_timeout: Duration,
    /// From the commit's answer to the node's `Hello` (the bootloader's
    /// swap erases and copies both slots).
    pub boot_timeout: Duration,
    /// From that `Hello` to the new image's confirmation (its self-test).
    pub confirm_timeout: Duration,
    /// While waiting for the confirmation, ask `GetImageInfo` this often
    /// (an event can be lost on the line).
    pub status_poll: Duration,
    /// Resumes allowed in one run (a node that keeps resetting).
    pub max_resumes: u32,
    /// Stop the node's measurement stream for the transfer (it keeps
    /// measuring and driving its alarm; only the frames stay home) and ask
    /// for it again at the end: the 10 Hz stream takes 27 % of a 19 200 Bd
    /// half-duplex line, and the node's time per chunk within the 90 s goal
    /// grows from 26 ms to 86 ms (`update_timing`).
    pub quiet_stream: bool,
}

impl Default for UpdateOptions {
    fn default() -> Self {
        UpdateOptions {
            reply_timeout: Duration::from_millis(fois_protocol::REPLY_TIMEOUT_MS),
            garbled_wait: Duration::from_millis(1_000),
            attempts: 4,
            resume_timeout: Duration::from_secs(60),
            boot_timeout: Duration::from_secs(60),
            confirm_timeout: Duration::from_secs(120),
            status_poll: Duration::from_secs(5),
            max_resumes: 50,
            quiet_stream: true,
        }
    }
}

/// Opens the node's port again after it went away (a USB port that
/// re-enumerates).
pub type Reopen<'a, P> = dyn FnMut() -> Result<P, LinkError> + 'a;

/// Send `image` to the node on `link` and follow it until its new image
/// confirms itself. `reopen` (if any) opens the port again after it went
/// away; `on_event` sees progress, retries and resumes.
pub fn update<P: Read + Write>(
    link: &mut Link<P>,
    image: &SignedImage,
    opts: &UpdateOptions,
    reopen: Option<&mut Reopen<'_, P>>,
    on_event: &mut dyn FnMut(UpdateEvent),
) -> Result<UpdateReport, UpdateError> {
    let mut d = Driver {
        link,
        image,
        opts,
        reopen,
        on_event,
        retries: 0,
        resumes: 0,
        offset: 0,
    };
    d.run()
}

/// An answer to one command.
pub(crate) enum Answer {
    Ack(AckResult),
    Refused(UpdateRefusal),
    Error(ErrorCode),
    /// The node reset instead (its boot `Hello`).
    Reset(Hello),
}

/// Why a command got no usable answer.
pub(crate) enum Fail {
    /// No answer after every attempt, or the port went away: try to resume.
    Down(LinkError),
    /// Stop.
    Fatal(UpdateError),
}

impl From<UpdateError> for Fail {
    fn from(e: UpdateError) -> Fail {
        Fail::Fatal(e)
    }
}

pub(crate) struct Driver<'a, 'r, P> {
    pub(crate) link: &'a mut Link<P>,
    pub(crate) image: &'a SignedImage,
    pub(crate) opts: &'a UpdateOptions,
    pub(crate) reopen: Option<&'a mut Reopen<'r, P>>,
    pub(crate) on_event: &'a mut dyn FnMut(UpdateEvent),
    pub(crate) retries: u32,
    pub(crate) resumes: u32,
    /// The node's next offset, as last known.
    pub(crate) offset: u32,
}

impl<P: Read + Write> Driver<'_, '_, P> {
    fn run(&mut self) -> Result<UpdateReport, UpdateError> {
        (self.on_event)(UpdateEvent::Step(Step::Connect));
        let hello = self.link.handshake(self.opts.reply_timeout)?;
        // The handshake keeps the frames it read for the next poll: the
        // driver reads none of them.
        self.link.discard_backlog();
        if hello.protocol_version < UPDATE_SINCE {
            return Err(UpdateError::NodeTooOld {
                node: hello.protocol_version,
                since: UPDATE_SINCE,
            });
        }
        let info = self.image_info(Step::Connect)?;
        let wanted = self.image.version();
        if info.version == wanted && self.image.trailer().flags == 0 {
            // A previous run got this far: follow its trial, or say so.
            match info.state {
                ImageState::Confirmed => {
                    return Ok(self.report(info.version, info.version, true, 0, Duration::ZERO));
                }
                ImageState::Trial => {
                    let running = self.confirm(Some(hello))?;
                    return Ok(self.report(info.version, running, false, 0, Duration::ZERO));
                }
                ImageState::RolledBack { .. } => {}
            }
        }
        self.check_on_host(&hello, &info)?;
        let quieted = self.opts.quiet_stream
            && matches!(
                self.exchange(Command::StopStream, Step::Connect),
                Ok(Answer::Ack(AckResult::Stopped))
            );
        let result = self.send_and_follow(&info);
        if quieted {
            // Best effort: the gateway's reader and a node's boot start the
            // stream again anyway.
            let _ = self.link.send(Command::StartStream {
                frame_period_ms: None,
            });
        }
        result
    }

    fn send_and_follow(&mut self, info: &ImageInfo) -> Result<UpdateReport, UpdateError> {
        let started = Instant::now();
        (self.on_event)(UpdateEvent::Step(Step::Begin));
        let started_at = self.begin_or_resume(Step::Begin)?;
        if started_at > 0 {
            (self.on_event)(UpdateEvent::Resumed { from: started_at });
        }
        self.transfer_and_verify()?;
        let transfer_time = started.elapsed();
        let booted = self.commit()?;
        let running = self.confirm(booted)?;
        Ok(self.report(info.version, running, false, started_at, transfer_time))
    }

    fn report(
        &self,
        from: FirmwareVersion,
        running: FirmwareVersion,
        already_running: bool,
        started_at: u32,
        transfer_time: Duration,
    ) -> UpdateReport {
        UpdateReport {
            from_version: from,
            running,
            already_running,
            started_at,
            retries: self.retries,
            resumes: self.resumes,
            transfer_time,
        }
    }

    fn total(&self) -> u32 {
        self.image.image_len()
    }

    /// The checks the node would make at its verify, made before the
    /// transfer: the board, the size, the version rule.
    fn check_on_host(&self, hello: &Hello, info: &ImageInfo) -> Result<(), UpdateError> {
        let refuse = |refusal| UpdateError::Refused {
            step: Step::Connect,
            refusal,
            by_host: true,
        };
        if board_text(&self.image.trailer().board) != hello.board_name() {
            return Err(refuse(UpdateRefusal::WrongBoard));
        }
        if self.total() > info.slot_bytes {
            return Err(refuse(UpdateRefusal::BadLength {
                max_bytes: info.slot_bytes,
            }));
        }
        if !version_allowed(info.version, self.image.trailer()) {
            return Err(refuse(UpdateRefusal::OlderVersion {
                running: info.version,
                image: self.image.version(),
            }));
        }
        Ok(())
    }

    fn image_info(&mut self, step: Step) -> Result<ImageInfo, UpdateError> {
        match self.exchange(Command::GetImageInfo, step) {
            Ok(Answer::Ack(AckResult::ImageInfo(i))) => Ok(i),
            Ok(a) => Err(self.unexpected(step, a)),
            Err(Fail::Fatal(e)) => Err(e),
            Err(Fail::Down(e)) => Err(UpdateError::Link(e)),
        }
    }

    fn unexpected(&self, step: Step, a: Answer) -> UpdateError {
        match a {
            Answer::Refused(refusal) => UpdateError::Refused {
                step,
                refusal,
                by_host: false,
            },
            Answer::Error(code) => UpdateError::NodeError { step, code },
            Answer::Ack(r) => UpdateError::Unexpected {
                step,
                answer: format!("{r:?}"),
            },
            Answer::Reset(h) => UpdateError::Unexpected {
                step,
                answer: format!("the node reset ({})", hello_text(&h)),
            },
        }
    }

    /// `UpdateBegin` until it is answered (the link may be down: reopen,
    /// try again until the resume timeout); sets and returns the offset.
    fn begin_or_resume(&mut self, step: Step) -> Result<u32, UpdateError> {
        let start = Instant::now();
        let begin = Command::UpdateBegin(self.image.begin());
        loop {
            match self.exchange(begin.clone(), step) {
                Ok(Answer::Ack(AckResult::UpdateStatus(s))) => {
                    self.accept_status(&s, step)?;
                    return Ok(self.offset);
                }
                // A node that reset answers the next begin.
                Ok(Answer::Reset(_)) => continue,
                Ok(a) => return Err(self.unexpected(step, a)),
                Err(Fail::Fatal(e)) => return Err(e),
                Err(Fail::Down(e)) => {
                    if start.elapsed() >= self.opts.resume_timeout {
                        return Err(self.down(step, start, &e));
                    }
                    self.reconnect(start, step, &e)?;
                }
            }
        }
    }

    fn down(&self, step: Step, since: Instant, cause: &LinkError) -> UpdateError {
        UpdateError::LinkDown {
            step,
            offset: self.offset,
            total: self.total(),
            waited_ms: since.elapsed().as_millis() as u64,
            cause: cause.to_string(),
        }
    }

    /// After a lost port: reopen it (when the caller can) until the resume
    /// timeout. After a silent link: nothing to do but ask again.
    pub(crate) fn reconnect(
        &mut self,
        since: Instant,
        step: Step,
        cause: &LinkError,
    ) -> Result<(), UpdateError> {
        if !matches!(cause, LinkError::Lost(..)) {
            return Ok(());
        }
        let Some(reopen) = self.reopen.as_mut() else {
            return Err(self.down(step, since, cause));
        };
        loop {
            match reopen() {
                Ok(port) => {
                    *self.link.port_mut() = port;
                    self.link.reset_decoder();
                    return Ok(());
                }
                Err(e) if since.elapsed() >= self.opts.resume_timeout => {
                    return Err(self.down(step, since, &e));
                }
                Err(_) => std::thread::sleep(Duration::from_millis(500)),
            }
        }
    }

    fn accept_status(&mut self, s: &UpdateStatus, step: Step) -> Result<(), UpdateError> {
        if s.next_offset > self.total()
            || (s.phase != UpdatePhase::Idle && s.image_len != self.total())
        {
            return Err(UpdateError::Unexpected {
                step,
                answer: format!("{s:?} for an image of {} bytes", self.total()),
            });
        }
        self.offset = s.next_offset;
        let total = self.total();
        (self.on_event)(UpdateEvent::Progress {
            done: self.offset,
            total,
        });
        Ok(())
    }

    /// Pick the transfer up again after a drop or a reset.
    fn resume(&mut self, step: Step) -> Result<(), UpdateError> {
        self.resumes += 1;
        if self.resumes > self.opts.max_resumes {
            return Err(UpdateError::LinkDown {
                step,
                offset: self.offset,
                total: self.total(),
                waited_ms: 0,
                cause: format!("{} resumes in one run", self.opts.max_resumes),
            });
        }
        let from = self.begin_or_resume(step)?;
        (self.on_event)(UpdateEvent::Resumed { from });
        Ok(())
    }

    fn transfer_and_verify(&mut self) -> Result<(), UpdateError> {
        (self.on_event)(UpdateEvent::Step(Step::Transfer));
        loop {
            while self.offset < self.total() {
                match self.send_chunk() {
                    Ok(()) => {}
                    Err(Fail::Fatal(e)) => return Err(e),
                    Err(Fail::Down(e)) => {
                        let since = Instant::now();
                        self.reconnect(since, Step::Transfer, &e)?;
                        self.resume(Step::Transfer)?;
                    }
                }
            }
            (self.on_event)(UpdateEvent::Step(Step::Verify));
            let verify = Command::UpdateVerify(self.image.signature());
            match self.exchange(verify, Step::Verify) {
                Ok(Answer::Ack(AckResult::UpdateStatus(s))) if s.phase == UpdatePhase::Verified => {
                    return Ok(());
                }
                Ok(Answer::Refused(UpdateRefusal::Incomplete { next_offset }))
                    if next_offset < self.total() =>
                {
                    self.offset = next_offset;
                    self.resume(Step::Verify)?;
                }
                Ok(Answer::Refused(UpdateRefusal::NoTransfer)) | Ok(Answer::Reset(_)) => {
                    self.resume(Step::Verify)?;
                }
                Ok(Answer::Refused(refusal)) => {
                    // The slot's bytes are no use: a later run starts afresh.
                    let _ = self.exchange(Command::UpdateAbort, Step::Verify);
                    return Err(UpdateError::Refused {
                        step: Step::Verify,
                        refusal,
                        by_host: false,
                    });
                }
                Ok(a) => return Err(self.unexpected(Step::Verify, a)),
                Err(Fail::Fatal(e)) => return Err(e),
                Err(Fail::Down(e)) => {
                    let since = Instant::now();
                    self.reconnect(since, Step::Verify, &e)?;
                    self.resume(Step::Verify)?;
                }
            }
        }
    }

    /// One chunk at the node's next offset; moves the offset on.
    fn send_chunk(&mut self) -> Result<(), Fail> {
        let start = self.offset as usize;
        let bytes = self.image.signed_bytes();
        let end = (start + UPDATE_CHUNK_MAX).min(bytes.len());
        let data = &bytes[start..end];
        let chunk = UpdateChunk {
            offset: self.offset,
            crc32: fois_protocol::framing::CRC.checksum(data),
            data: ChunkData::new(data).ok_or(Fail::Fatal(UpdateError::Unexpected {
                step: Step::Transfer,
                answer: "a chunk longer than the protocol allows".into(),
            }))?,
        };
        match self.exchange(Command::UpdateChunk(chunk), Step::Transfer)? {
            Answer::Ack(AckResult::UpdateStatus(s)) => Ok(self.accept_status(&s, Step::Transfer)?),
            // A resent chunk the node had taken: its next offset is ours.
            Answer::Refused(UpdateRefusal::OutOfOrder { expected_offset })
                if expected_offset <= self.total() && expected_offset != self.offset =>
            {
                // Counted as a resume: a node that kept moving its offset
                // would otherwise hold the driver for ever.
                self.resumes += 1;
                if self.resumes > self.opts.max_resumes {
                    return Err(Fail::Fatal(UpdateError::Refused {
                        step: Step::Transfer,
                        refusal: UpdateRefusal::OutOfOrder { expected_offset },
                        by_host: false,
                    }));
                }
                self.offset = expected_offset;
                (self.on_event)(UpdateEvent::Resumed {
                    from: expected_offset,
                });
                Ok(())
            }
            // The node lost the transfer (it reset): begin again (it resumes).
            Answer::Refused(UpdateRefusal::NoTransfer) | Answer::Reset(_) => {
                self.resume(Step::Transfer)?;
                Ok(())
            }
            a => Err(Fail::Fatal(self.unexpected(Step::Transfer, a))),
        }
    }

    /// `UpdateCommit`; the node's boot hello when it came instead of the
    /// answer (lost on the line).
    fn commit(&mut self) -> Result<Option<Hello>, UpdateError> {
        (self.on_event)(UpdateEvent::Step(Step::Commit));
        match self.exchange(Command::UpdateCommit, Step::Commit) {
            Ok(Answer::Ack(AckResult::UpdateCommitted { .. })) => Ok(None),
            Ok(Answer::Reset(h)) => Ok(Some(h)),
            Ok(a) => Err(self.unexpected(Step::Commit, a)),
            Err(Fail::Fatal(e)) => Err(e),
            Err(Fail::Down(e)) => Err(self.down(Step::Commit, Instant::now(), &e)),
        }
    }

    /// Send `cmd` and wait for its answer; send it again (up to
    /// `attempts`) when none comes in time or a garbled frame arrived
    /// instead. An answer to any of the sends counts.
    pub(crate) fn exchange(&mut self, cmd: Command, step: Step) -> Result<Answer, Fail> {
        let mut ids = Vec::new();
        let mut last = None;
        for attempt in 0..self.opts.attempts.max(1) {
            if attempt > 0 {
                self.retries += 1;
                (self.on_event)(UpdateEvent::Retry {
                    step,
                    offset: self.offset,
                });
            }
            let id = self.link.send(cmd.clone()).map_err(Fail::Down)?;
            ids.push(id);
            match self.wait(&ids)? {
                Some(a) => return Ok(a),
                None => last = Some(self.opts.reply_timeout),
            }
        }
        Err(Fail::Down(LinkError::Timeout {
            port: self.link.name().to_string(),
            waited_ms: last.unwrap_or_default().as_millis() as u64,
            hint: format!("; {} sends without an answer", self.opts.attempts.max(1)),
        }))
    }

    /// The answer to one of `ids`, or `None` when it is time to send again.
    fn wait(&mut self, ids: &[u16]) -> Result<Option<Answer>, Fail> {
        let start = Instant::now();
        let mut deadline = start + self.opts.reply_timeout;
        while Instant::now() < deadline {
            let mut frames = self.link.poll().map_err(Fail::Down)?.into_iter();
            while let Some(inc) = frames.next() {
                let (frame, seq) = match inc {
                    Incoming::Frame(f, seq) => (f, seq),
                    Incoming::Rejected(_) => {
                        deadline = deadline.min(Instant::now() + self.opts.garbled_wait);
                        continue;
                    }
                };
                let answer = match frame.msg {
                    DeviceMsg::Ack(a) if ids.contains(&a.id) => Some(Answer::Ack(a.result)),
                    DeviceMsg::Error(e) if e.id.is_some_and(|id| ids.contains(&id)) => {
                        Some(match e.code {
                            ErrorCode::UpdateRefused(r) => Answer::Refused(r),
                            code => Answer::Error(code),
                        })
                    }
                    // The node could not read a frame (ours, garbled): resend.
                    DeviceMsg::Error(e) if e.id.is_none() => {
                        self.link.keep(frames);
                        return Ok(None);
                    }
                    // A boot hello (its sequence number started again),
                    // not the hello a node repeats until it streams.
                    DeviceMsg::Hello(h) if seq == SeqEvent::Restart => Some(Answer::Reset(h)),
                    _ => None,
                };
                if answer.is_some() {
                    self.link.keep(frames);
                    return Ok(answer);
                }
            }
        }
        Ok(None)
    }
}
