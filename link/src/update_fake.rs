//! A scripted node that follows the update protocol (feature `fixtures`):
//! it takes `UpdateBegin`/`UpdateChunk`/`UpdateVerify`/`UpdateCommit` as
//! the node's updater does (offsets, CRCs, the digest, the trailer, the
//! board, the version rule; the signature through a caller's check), boots
//! the new image after a commit and confirms or rolls it back, and injects
//! faults at chosen offsets: a lost command, a lost or garbled answer, a
//! cut port, a power cut. It streams a measurement now and then, as a node
//! does. For the driver's tests and the gateway's roll-out tests; the
//! end-to-end test runs against the virtual node.
//!
//! [`FakeNode::port`] gives a `Read + Write` port; a cut makes it fail
//! (`BrokenPipe`) and a new `port()` is the port reopened.

use std::collections::{HashSet, VecDeque};
use std::io::{self, Read, Write};
use std::sync::{Arc, Mutex, MutexGuard};

use fois_protocol::update::TRAILER_LEN;
use fois_protocol::update::version_allowed;
use fois_protocol::{
    Ack, AckResult, Command, DeviceFrame, DeviceMsg, ErrorCode, ErrorReply, Event, EventKind,
    FirmwareVersion, FrameDecoder, Hello, HostFrame, ImageInfo, ImageState, ImageTrailer,
    ResetReason, UpdateBegin, UpdatePhase, UpdateRefusal, UpdateStatus, encode_to_vec,
};

use crate::signed_image::sha512;

/// The node's signature check: `(digest, signature)` → valid.
pub type SignatureCheck = Box<dyn Fn(&[u8; 64], &[u8; 64]) -> bool + Send>;

/// What the new image does on its trial boot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrialOutcome {
    /// Passes its self-test: `ImageConfirmed`.
    Confirm,
    /// Fails: the bootloader puts the old image back (`ImageRolledBack`).
    RollBack,
    /// Stays on trial (never confirms within the test).
    Silent,
}

/// Faults and answers to script.
#[derive(Debug, Clone)]
pub struct Script {
    /// Chunk offsets whose command is lost on the line (once each).
    pub lose_command_at: HashSet<u32>,
    /// Chunk offsets whose answer is lost (the chunk is written; once each).
    pub lose_answer_at: HashSet<u32>,
    /// Chunk offsets whose answer arrives with a flipped bit (once each).
    pub garble_answer_at: HashSet<u32>,
    /// The port goes away when a chunk at or past this offset arrives
    /// (once; the chunk is not taken).
    pub cut_port_at: Option<u32>,
    /// The node loses power when a chunk at or past this offset arrives
    /// (once): it boots again, keeps the bytes written and forgets the
    /// transfer until the next begin.
    pub power_cut_at: Option<u32>,
    /// Refuse every begin with this.
    pub refuse_begin: Option<UpdateRefusal>,
    /// Refuse the verify with this (before its own checks).
    pub refuse_verify: Option<UpdateRefusal>,
    /// The new image's trial.
    pub trial: TrialOutcome,
    /// A measurement frame after every this many answers (0: none).
    pub stream_every: u32,
}

impl Default for Script {
    fn default() -> Self {
        Script {
            lose_command_at: HashSet::new(),
            lose_answer_at: HashSet::new(),
            garble_answer_at: HashSet::new(),
            cut_port_at: None,
            power_cut_at: None,
            refuse_begin: None,
            refuse_verify: None,
            trial: TrialOutcome::Confirm,
            stream_every: 5,
        }
    }
}

/// Counts of what crossed the fake link.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Traffic {
    /// Bytes the host wrote.
    pub host_bytes: u64,
    /// Bytes of the node's answers (streamed frames not counted).
    pub answer_bytes: u64,
    /// Commands answered.
    pub answers: u64,
    /// Chunks written to the slot.
    pub chunks_written: u64,
}

struct Transfer {
    begin: UpdateBegin,
    next_offset: u32,
    verified: bool,
}

struct State {
    hello: Hello,
    info: ImageInfo,
    seq: u32,
    generation: u64,
    decoder: Box<FrameDecoder>,
    out: VecDeque<u8>,
    slot: Vec<u8>,
    transfer: Option<Transfer>,
    /// Bytes kept after a power cut and the begin they belong to.
    kept: Option<(UpdateBegin, u32)>,
    script: Script,
    traffic: Traffic,
    verify_signature: SignatureCheck,
    pending_version: Option<FirmwareVersion>,
    streaming: bool,
}

/// The scripted node (cheap to clone: every clone is the same node).
#[derive(Clone)]
pub struct FakeNode {
    state: Arc<Mutex<State>>,
}

/// A port to a [`FakeNode`].
pub struct FakePort {
    state: Arc<Mutex<State>>,
    generation: u64,
}

impl FakeNode {
    /// A protocol-6 node on `board` running `version`, confirmed, with an
    /// update slot of `slot_bytes`; signatures accepted by
    /// `verify_signature(digest, signature)`.
    pub fn new(
        board: &str,
        version: FirmwareVersion,
        slot_bytes: u32,
        script: Script,
        verify_signature: SignatureCheck,
    ) -> FakeNode {
        let hello = Hello {
            protocol_version: 6,
            firmware_version: version,
            board: Hello::board_from_str(board),
            unique_id: [0x5A; 12],
            reset_reason: ResetReason::PowerOn,
        };
        let state = State {
            hello,
            info: ImageInfo {
                version,
                state: ImageState::Confirmed,
                slot_bytes,
            },
            seq: 100,
            generation: 0,
            decoder: Box::default(),
            out: VecDeque::new(),
            slot: vec![0xFF; slot_bytes as usize],
            transfer: None,
            kept: None,
            script,
            traffic: Traffic::default(),
            verify_signature,
            pending_version: None,
            streaming: true,
        };
        FakeNode {
            state: Arc::new(Mutex::new(state)),
        }
    }

    /// Set the protocol version its hello says.
    pub fn set_protocol_version(&self, v: u16) {
        self.lock().hello.protocol_version = v;
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A port to the node (after a cut: the port reopened).
    pub fn port(&self) -> FakePort {
        FakePort {
            state: self.state.clone(),
            generation: self.lock().generation,
        }
    }

    /// The version it runs and its boot state.
    pub fn image_info(&self) -> ImageInfo {
        self.lock().info
    }

    /// What crossed the link.
    pub fn traffic(&self) -> Traffic {
        self.lock().traffic
    }
}

impl Read for FakePort {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        if s.generation != self.generation {
            return Err(io::ErrorKind::BrokenPipe.into());
        }
        if s.out.is_empty() {
            drop(s);
            std::thread::sleep(std::time::Duration::from_micros(200));
            return Err(io::ErrorKind::TimedOut.into());
        }
        let n = buf.len().min(s.out.len());
        for (dst, src) in buf.iter_mut().zip(s.out.drain(..n)) {
            *dst = src;
        }
        Ok(n)
    }
}

impl Write for FakePort {
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        if s.generation != self.generation {
            return Err(io::ErrorKind::BrokenPipe.into());
        }
        s.traffic.host_bytes += bytes.len() as u64;
        let mut frames = Vec::new();
        s.decoder.feed::<HostFrame>(bytes, |r| frames.push(r));
        for f in frames {
            match f {
                Ok(frame) => s.command(frame),
                Err(_) => s.send(DeviceMsg::Error(ErrorReply {
                    id: None,
                    code: ErrorCode::Garbled,
                })),
            }
        }
        Ok(bytes.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl State {
    fn send(&mut self, msg: DeviceMsg) {
        let frame = encode_to_vec(&DeviceFrame { seq: self.seq, msg });
        self.seq = self.seq.wrapping_add(1);
        self.out.extend(frame);
    }

    fn answer(&mut self, id: u16, result: Result<AckResult, ErrorCode>, fault: Fault) {
        let msg = match result {
            Ok(result) => DeviceMsg::Ack(Ack { id, result }),
            Err(code) => DeviceMsg::Error(ErrorReply { id: Some(id), code }),
        };
        let mut frame = encode_to_vec(&DeviceFrame { seq: self.seq, msg });
        self.seq = self.seq.wrapping_add(1);
        self.traffic.answers += 1;
        self.traffic.answer_bytes += frame.len() as u64;
        match fault {
            Fault::None => self.out.extend(frame),
            Fault::Lose => {}
            Fault::Garble => {
                if let Some(b) = frame.get_mut(3) {
                    *b ^= 0x10;
                }
                self.out.extend(frame);
            }
        }
        let every = u64::from(self.script.stream_every);
        if self.streaming && every > 0 && self.traffic.answers.is_multiple_of(every) {
            self.send(DeviceMsg::Measurement(crate::fixtures::iced_measurement()));
        }
    }

    fn status(&self) -> UpdateStatus {
        match &self.transfer {
            None => UpdateStatus {
                phase: UpdatePhase::Idle,
                image_len: 0,
                next_offset: 0,
            },
            Some(t) => UpdateStatus {
                phase: if t.verified {
                    UpdatePhase::Verified
                } else {
                    UpdatePhase::Receiving
                },
                image_len: t.begin.image_len,
                next_offset: t.next_offset,
            },
        }
    }

    /// Boot (after a power cut or a commit): a new hello, its sequence
    /// numbers from 0.
    fn boot(&mut self, reason: ResetReason) {
        self.seq = 0;
        self.streaming = true;
        self.hello.reset_reason = reason;
        self.hello.firmware_version = self.info.version;
        let hello = self.hello.clone();
        self.send(DeviceMsg::Hello(hello));
    }

    fn event(&mut self, kind: EventKind) {
        self.send(DeviceMsg::Event(Event {
            uptime_ms: 1_000,
            kind,
            i1_na: 0,
            i2_na: 0,
            rise1_na: 0,
            temperature_centi_c: -500,
            frames: 0,
        }));
    }

    fn command(&mut self, frame: HostFrame) {
        let id = frame.id;
        let refuse = |r| Err(ErrorCode::UpdateRefused(r));
        match frame.cmd {
            Command::GetInfo => {
                let h = self.hello.clone();
                self.answer(id, Ok(AckResult::Info(h)), Fault::None)
            }
            Command::GetImageInfo => {
                self.answer(id, Ok(AckResult::ImageInfo(self.info)), Fault::None)
            }
            Command::GetUpdateStatus => {
                let s = self.status();
                self.answer(id, Ok(AckResult::UpdateStatus(s)), Fault::None)
            }
            Command::UpdateBegin(b) => {
                let r = self.begin(b);
                self.answer(id, r, Fault::None)
            }
            Command::UpdateChunk(c) => self.chunk(id, c),
            Command::UpdateVerify(sig) => {
                let r = self.verify(&sig.to_bytes());
                self.answer(id, r, Fault::None)
            }
            Command::UpdateCommit => match self.transfer.as_ref().map(|t| (t.verified, t.begin)) {
                Some((true, b)) => {
                    self.answer(
                        id,
                        Ok(AckResult::UpdateCommitted { version: b.version }),
                        Fault::None,
                    );
                    self.commit_and_boot(b.version);
                }
                Some((false, _)) => {
                    self.answer(id, refuse(UpdateRefusal::NotVerified), Fault::None)
                }
                None => self.answer(id, refuse(UpdateRefusal::NoTransfer), Fault::None),
            },
            Command::StopStream => {
                self.streaming = false;
                self.answer(id, Ok(AckResult::Stopped), Fault::None)
            }
            Command::StartStream { .. } => {
                self.streaming = true;
                let r = AckResult::Streaming {
                    frame_period_ms: 100,
                };
                self.answer(id, Ok(r), Fault::None)
            }
            Command::UpdateAbort => {
                self.transfer = None;
                self.kept = None;
                let s = self.status();
                self.answer(id, Ok(AckResult::UpdateStatus(s)), Fault::None)
            }
            _ => self.answer(id, Err(ErrorCode::UnknownCommand), Fault::None),
        }
    }

    fn begin(&mut self, b: UpdateBegin) -> Result<AckResult, ErrorCode> {
        let refuse = |r| Err(ErrorCode::UpdateRefused(r));
        if let Some(r) = self.script.refuse_begin {
            return refuse(r);
        }
        if self.info.state == ImageState::Trial {
            return refuse(UpdateRefusal::OnTrial);
        }
        if b.image_len > self.info.slot_bytes || (b.image_len as usize) <= TRAILER_LEN {
            return refuse(UpdateRefusal::BadLength {
                max_bytes: self.info.slot_bytes,
            });
        }
        let same = |other: &UpdateBegin| other.image_digest == b.image_digest;
        if !self.transfer.as_ref().is_some_and(|t| same(&t.begin)) {
            let next_offset = match self.kept.take() {
                Some((k, n)) if same(&k) => n,
                _ => {
                    self.slot.fill(0xFF);
                    0
                }
            };
            self.transfer = Some(Transfer {
                begin: b,
                next_offset,
                verified: false,
            });
        }
        Ok(AckResult::UpdateStatus(self.status()))
    }

    fn chunk(&mut self, id: u16, c: fois_protocol::UpdateChunk) {
        let refuse = |r| Err(ErrorCode::UpdateRefused(r));
        if self.script.lose_command_at.remove(&c.offset) {
            return;
        }
        if self.script.cut_port_at.is_some_and(|at| c.offset >= at) {
            self.script.cut_port_at = None;
            self.generation += 1;
            self.out.clear();
            return;
        }
        if self.script.power_cut_at.is_some_and(|at| c.offset >= at) {
            self.script.power_cut_at = None;
            self.out.clear();
            self.kept = self.transfer.take().map(|t| (t.begin, t.next_offset));
            self.boot(ResetReason::PowerOn);
            return;
        }
        let Some(t) = self.transfer.as_mut() else {
            return self.answer(id, refuse(UpdateRefusal::NoTransfer), Fault::None);
        };
        let data = c.data.as_slice();
        let end = c.offset as usize + data.len();
        if c.offset != t.next_offset || end > t.begin.image_len as usize {
            let expected_offset = t.next_offset;
            return self.answer(
                id,
                refuse(UpdateRefusal::OutOfOrder { expected_offset }),
                Fault::None,
            );
        }
        if fois_protocol::framing::CRC.checksum(data) != c.crc32 {
            return self.answer(id, refuse(UpdateRefusal::ChunkCrc), Fault::None);
        }
        self.slot[c.offset as usize..end].copy_from_slice(data);
        t.next_offset = end as u32;
        self.traffic.chunks_written += 1;
        let fault = if self.script.lose_answer_at.remove(&c.offset) {
            Fault::Lose
        } else if self.script.garble_answer_at.remove(&c.offset) {
            Fault::Garble
        } else {
            Fault::None
        };
        let s = self.status();
        self.answer(id, Ok(AckResult::UpdateStatus(s)), fault)
    }

    fn verify(&mut self, signature: &[u8; 64]) -> Result<AckResult, ErrorCode> {
        let refuse = |r| Err(ErrorCode::UpdateRefused(r));
        let Some(t) = self.transfer.as_ref() else {
            return refuse(UpdateRefusal::NoTransfer);
        };
        if let Some(r) = self.script.refuse_verify {
            return refuse(r);
        }
        let len = t.begin.image_len as usize;
        if t.next_offset as usize != len {
            return refuse(UpdateRefusal::Incomplete {
                next_offset: t.next_offset,
            });
        }
        let digest = sha512(&self.slot[..len]);
        if digest[..32] != t.begin.image_digest {
            return refuse(UpdateRefusal::DigestMismatch);
        }
        let mut raw = [0u8; TRAILER_LEN];
        raw.copy_from_slice(&self.slot[len - TRAILER_LEN..len]);
        let trailer = match ImageTrailer::parse(&raw) {
            Ok(tr) if tr.body_len as usize == len - TRAILER_LEN => tr,
            _ => return refuse(UpdateRefusal::BadTrailer),
        };
        if trailer.board != self.hello.board {
            return refuse(UpdateRefusal::WrongBoard);
        }
        if !(self.verify_signature)(&digest, signature) {
            return refuse(UpdateRefusal::BadSignature);
        }
        if !version_allowed(self.info.version, &trailer) {
            return refuse(UpdateRefusal::OlderVersion {
                running: self.info.version,
                image: trailer.version,
            });
        }
        if let Some(t) = self.transfer.as_mut() {
            t.verified = true;
        }
        Ok(AckResult::UpdateStatus(self.status()))
    }

    fn commit_and_boot(&mut self, version: FirmwareVersion) {
        let old = self.info.version;
        self.transfer = None;
        self.kept = None;
        self.pending_version = Some(version);
        self.info.version = version;
        self.info.state = ImageState::Trial;
        self.boot(ResetReason::Software);
        match self.script.trial {
            TrialOutcome::Confirm => {
                self.info.state = ImageState::Confirmed;
                self.event(EventKind::ImageConfirmed { version });
            }
            TrialOutcome::RollBack => {
                self.info.version = old;
                self.info.state = ImageState::RolledBack { failed: version };
                self.boot(ResetReason::IndependentWatchdog);
                self.event(EventKind::ImageRolledBack {
                    failed: version,
                    running: old,
                });
            }
            TrialOutcome::Silent => {}
        }
    }
}

#[derive(Clone, Copy)]
enum Fault {
    None,
    Lose,
    Garble,
}
