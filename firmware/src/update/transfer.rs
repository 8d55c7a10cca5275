//! [`FlashUpdater`]: the transfer's state machine over the update (DFU) and
//! boot-state partitions, on embassy-boot.
//!
//! - **Begin** refuses an image that does not fit the slot
//!   ([`Geometry::slot_bytes`]) or is shorter than a trailer, and any begin
//!   while the running image is on trial (embassy-boot's `verify_booted`).
//!   A begin with the digest and length of the transfer in progress resumes
//!   it; any other erases the page(s) holding the session record (one
//!   128 KiB sector on the board) and writes a new record. The image's other
//!   pages are erased when the image first reaches them: never more than
//!   one erase per command, so frames stop for at most one erase.
//! - **Chunk**: at the expected offset only, never past the image's end,
//!   its CRC-32 (ISO-HDLC) checked; the bytes are programmed, then the
//!   progress marks they complete (`session`).
//! - **Verify**: the SHA-512 of the image's bytes against the begin's
//!   digest, the trailer (`ImageTrailer`) at `image_len − TRAILER_LEN` (its
//!   body length, its version against the begin's, its board), the version
//!   rule against the running version, then the signature. Nothing marked.
//! - **Commit** (after a verify in this session): the record is closed and
//!   embassy-boot's `verify_and_mark_updated` checks the signature over the
//!   slot once more and marks the swap; the node resets after its answer.
//! - **Abort** closes the record.
//!
//! A refused piece changes nothing in the flash.

use embassy_boot::{
    AlignedBuffer, BlockingFirmwareState, BlockingFirmwareUpdater, FirmwareUpdaterConfig,
    FirmwareUpdaterError, State,
};
use embedded_storage::nor_flash::NorFlash;
// A chunk's CRC: ISO-HDLC, the frames' own (one table in the image).
use fois_protocol::framing::CRC as CHUNK_CRC;
use fois_protocol::update::{SIGNATURE_LEN, TRAILER_LEN, version_allowed};
use fois_protocol::{
    FirmwareVersion, ImageSignature, ImageState, ImageTrailer, UPDATE_CHUNK_MAX, UpdateBegin,
    UpdateChunk, UpdatePhase, UpdateRefusal, UpdateStatus,
};

use super::key::UpdateKey;
use super::session::{self, GRANULE, Geometry, MAX_STRIDE, SessionHeader};
use super::slots::{Refused, UpdateSlots};

/// What the board tells its updater.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UpdaterConfig {
    /// Bytes of the active slot (the part of the DFU slot the bootloader
    /// copies; the DFU slot is one page larger).
    pub active_len: u32,
    /// The running image's version.
    pub running: FirmwareVersion,
    /// The key images are verified with.
    pub key: UpdateKey,
}

/// A transfer begun.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Session {
    header: SessionHeader,
    /// Every byte below it is written.
    next: u32,
    /// Progress marks set.
    marks: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Idle,
    Receiving(Session),
    Verified(Session, [u8; SIGNATURE_LEN]),
}

/// Bytes hashed per flash read while verifying.
const HASH_BLOCK: usize = 256;

/// The updater over a DFU partition and a boot-state partition (each its
/// own `NorFlash`: a partition of the board's flash, or a RAM flash).
pub struct FlashUpdater<DFU: NorFlash, STATE: NorFlash> {
    dfu: DFU,
    state: STATE,
    key: UpdateKey,
    running: FirmwareVersion,
    /// `None`: the partitions cannot hold a transfer (every begin refused).
    geometry: Option<Geometry>,
    phase: Phase,
    image_state: ImageState,
}

impl<DFU: NorFlash, STATE: NorFlash> FlashUpdater<DFU, STATE> {
    /// The updater: reads the boot state (on trial, rolled back — then the
    /// failed image's version from its trailer in the DFU slot — or
    /// confirmed) and the session record (a transfer cut by a reset or a
    /// power cut resumes at the offset the record vouches for).
    pub fn new(dfu: DFU, state: STATE, config: UpdaterConfig) -> Self {
        let geometry = if STATE::WRITE_SIZE <= MAX_STRIDE {
            Geometry::new::<DFU>(config.active_len, dfu.capacity())
        } else {
            None
        };
        let mut u = FlashUpdater {
            dfu,
            state,
            key: config.key,
            running: config.running,
            geometry,
            phase: Phase::Idle,
            image_state: ImageState::Confirmed,
        };
        let boot = u.boot_state();
        let stored = match u.geometry {
            Some(g) => session::read(&mut u.dfu, &g).ok().flatten(),
            None => None,
        };
        u.image_state = match boot {
            Some(State::Swap) => ImageState::Trial,
            // Rolled back when the DFU slot holds another version than
            // the one running. (A cut in `mark_booted` after it invalidated
            // the swap's progress leaves the new image running with the
            // revert magic: embassy-boot's revert then copies nothing. That
            // image is confirmed.)
            Some(State::Revert) => match stored.map(|s| u.failed_version(&s.header)) {
                Some(failed) if failed != u.running => ImageState::RolledBack { failed },
                _ => ImageState::Confirmed,
            },
            _ => ImageState::Confirmed,
        };
        if let Some(s) = stored
            && !s.closed
            && u.image_state != ImageState::Trial
        {
            u.phase = Phase::Receiving(Session {
                header: s.header,
                next: Geometry::vouched(s.marks, s.header.image_len),
                marks: s.marks,
            });
        }
        u
    }

    /// The partitions back (the virtual node's restart, tests).
    pub fn into_parts(self) -> (DFU, STATE) {
        (self.dfu, self.state)
    }

    /// The boot state as embassy-boot keeps it (`None`: unreadable).
    fn boot_state(&mut self) -> Option<State> {
        let mut aligned = AlignedBuffer([0u8; MAX_STRIDE]);
        let word = aligned.0.get_mut(..STATE::WRITE_SIZE)?;
        BlockingFirmwareState::new(&mut self.state, word)
            .get_state()
            .ok()
    }

    /// The version in the trailer of the image the record describes (after
    /// a rollback: the image that failed), else the begin's.
    fn failed_version(&mut self, header: &SessionHeader) -> FirmwareVersion {
        let mut t = [0u8; TRAILER_LEN];
        let at = header.image_len.saturating_sub(TRAILER_LEN as u32);
        match self
            .dfu
            .read(at, &mut t)
            .ok()
            .map(|()| ImageTrailer::parse(&t))
        {
            Some(Ok(trailer)) => trailer.version,
            _ => header.version,
        }
    }

    fn session(&self) -> Option<Session> {
        match self.phase {
            Phase::Idle => None,
            Phase::Receiving(s) | Phase::Verified(s, _) => Some(s),
        }
    }

    fn status_now(&self) -> UpdateStatus {
        match self.phase {
            Phase::Idle => UpdateStatus {
                phase: UpdatePhase::Idle,
                image_len: 0,
                next_offset: 0,
            },
            Phase::Receiving(s) => UpdateStatus {
                phase: UpdatePhase::Receiving,
                image_len: s.header.image_len,
                next_offset: s.next,
            },
            Phase::Verified(s, _) => UpdateStatus {
                phase: UpdatePhase::Verified,
                image_len: s.header.image_len,
                next_offset: s.next,
            },
        }
    }

    /// Start or resume a transfer.
    pub fn begin_transfer(&mut self, begin: &UpdateBegin) -> Result<UpdateStatus, UpdateRefusal> {
        let Some(g) = self.geometry else {
            return Err(UpdateRefusal::BadLength { max_bytes: 0 });
        };
        match self.boot_state() {
            Some(State::Boot | State::Revert | State::DfuDetach) => {}
            Some(State::Swap) => return Err(UpdateRefusal::OnTrial),
            None => return Err(UpdateRefusal::FlashFailed),
        }
        if begin.image_len > g.slot_bytes() || (begin.image_len as usize) < TRAILER_LEN {
            return Err(UpdateRefusal::BadLength {
                max_bytes: g.slot_bytes(),
            });
        }
        if let Some(s) = self.session()
            && s.header.digest == begin.image_digest
            && s.header.image_len == begin.image_len
        {
            return Ok(self.status_now());
        }
        let header = SessionHeader {
            image_len: begin.image_len,
            version: begin.version,
            digest: begin.image_digest,
        };
        // From here the old transfer is gone, whatever happens.
        self.phase = Phase::Idle;
        session::start(&mut self.dfu, &g, &header).map_err(|_| UpdateRefusal::FlashFailed)?;
        self.phase = Phase::Receiving(Session {
            header,
            next: 0,
            marks: 0,
        });
        Ok(self.status_now())
    }

    /// Write one chunk.
    pub fn write_chunk(&mut self, chunk: &UpdateChunk) -> Result<UpdateStatus, UpdateRefusal> {
        let (Some(g), Some(mut s)) = (self.geometry, self.session()) else {
            return Err(UpdateRefusal::NoTransfer);
        };
        let data = chunk.data.as_slice();
        let out_of_order = UpdateRefusal::OutOfOrder {
            expected_offset: s.next,
        };
        if chunk.offset != s.next {
            return Err(out_of_order);
        }
        let end = match chunk.offset.checked_add(data.len() as u32) {
            Some(end) if end <= s.header.image_len => end,
            _ => return Err(out_of_order),
        };
        if CHUNK_CRC.checksum(data) != chunk.crc32 {
            return Err(UpdateRefusal::ChunkCrc);
        }
        if data.is_empty() {
            return Ok(self.status_now());
        }
        self.program(&g, chunk.offset, data)
            .map_err(|_| UpdateRefusal::FlashFailed)?;
        let complete = if end == s.header.image_len {
            Geometry::marks_for(end)
        } else {
            end / GRANULE
        };
        while s.marks < complete {
            session::set_word(&mut self.dfu, &g, g.mark_at(s.marks))
                .map_err(|_| UpdateRefusal::FlashFailed)?;
            s.marks += 1;
        }
        s.next = end;
        self.phase = Phase::Receiving(s);
        Ok(self.status_now())
    }

    /// Erase the pages `data` enters first (before the record's) and
    /// program it in whole program units (0xFF around it leaves the bytes
    /// there as they are).
    fn program(&mut self, g: &Geometry, offset: u32, data: &[u8]) -> Result<(), DFU::Error> {
        let end = offset + data.len() as u32;
        let mut page = offset.div_ceil(g.page) * g.page;
        while page < end && page < g.record_page() {
            self.dfu.erase(page, page + g.page)?;
            page += g.page;
        }
        let unit = DFU::WRITE_SIZE.max(1) as u32;
        let start = offset / unit * unit;
        let stop = end.div_ceil(unit) * unit;
        let mut buf = [0xFFu8; UPDATE_CHUNK_MAX + 2 * MAX_STRIDE];
        let lead = (offset - start) as usize;
        if let Some(dst) = buf.get_mut(lead..lead + data.len()) {
            dst.copy_from_slice(data);
        }
        match buf.get(..(stop - start) as usize) {
            Some(bytes) => self.dfu.write(start, bytes),
            None => Ok(()),
        }
    }

    /// The SHA-512 of the image's bytes.
    fn hash(&mut self, image_len: u32) -> Result<[u8; 64], DFU::Error> {
        let mut sha = salty::Sha512::new();
        let mut buf = [0u8; HASH_BLOCK];
        let mut at = 0u32;
        while at < image_len {
            let n = (image_len - at).min(HASH_BLOCK as u32) as usize;
            let part = buf.get_mut(..n).unwrap_or(&mut []);
            self.dfu.read(at, part)?;
            sha.update(part);
            at += n as u32;
        }
        Ok(sha.finalize())
    }

    /// Check the whole image for `board`.
    pub fn verify_image(
        &mut self,
        signature: &ImageSignature,
        board: &[u8; 16],
    ) -> Result<UpdateStatus, UpdateRefusal> {
        let Some(s) = self.session() else {
            return Err(UpdateRefusal::NoTransfer);
        };
        let len = s.header.image_len;
        if s.next < len {
            return Err(UpdateRefusal::Incomplete {
                next_offset: s.next,
            });
        }
        let digest = self.hash(len).map_err(|_| UpdateRefusal::FlashFailed)?;
        if digest.get(..32) != Some(&s.header.digest[..]) {
            return Err(UpdateRefusal::DigestMismatch);
        }
        let mut t = [0u8; TRAILER_LEN];
        self.dfu
            .read(len - TRAILER_LEN as u32, &mut t)
            .map_err(|_| UpdateRefusal::FlashFailed)?;
        let trailer = ImageTrailer::parse(&t).map_err(|_| UpdateRefusal::BadTrailer)?;
        if trailer.body_len as usize + TRAILER_LEN != len as usize
            || trailer.version != s.header.version
        {
            return Err(UpdateRefusal::BadTrailer);
        }
        if &trailer.board != board {
            return Err(UpdateRefusal::WrongBoard);
        }
        if !version_allowed(self.running, &trailer) {
            return Err(UpdateRefusal::OlderVersion {
                running: self.running,
                image: trailer.version,
            });
        }
        if !self.key.verifies(&digest, signature) {
            return Err(UpdateRefusal::BadSignature);
        }
        self.phase = Phase::Verified(s, signature.to_bytes());
        Ok(self.status_now())
    }

    /// Mark the verified image for the next boot (on trial).
    pub fn commit_image(&mut self) -> Result<FirmwareVersion, UpdateRefusal> {
        let (s, signature) = match self.phase {
            Phase::Idle => return Err(UpdateRefusal::NoTransfer),
            Phase::Receiving(_) => return Err(UpdateRefusal::NotVerified),
            Phase::Verified(s, sig) => (s, sig),
        };
        let (Some(g), Some(key)) = (self.geometry, self.key.bytes().copied()) else {
            return Err(UpdateRefusal::BadSignature);
        };
        // Closed first: a cut before the mark leaves no half-committed state.
        session::set_word(&mut self.dfu, &g, g.closed_at())
            .map_err(|_| UpdateRefusal::FlashFailed)?;
        self.phase = Phase::Idle;
        let mut aligned = AlignedBuffer([0u8; MAX_STRIDE]);
        let word = aligned
            .0
            .get_mut(..STATE::WRITE_SIZE)
            .ok_or(UpdateRefusal::FlashFailed)?;
        let config = FirmwareUpdaterConfig {
            dfu: &mut self.dfu,
            state: &mut self.state,
        };
        BlockingFirmwareUpdater::new(config, word)
            .verify_and_mark_updated(&key, &signature, s.header.image_len)
            .map_err(|e| match e {
                FirmwareUpdaterError::Signature(_) => UpdateRefusal::BadSignature,
                FirmwareUpdaterError::BadState => UpdateRefusal::OnTrial,
                FirmwareUpdaterError::Flash(_) => UpdateRefusal::FlashFailed,
            })?;
        Ok(s.header.version)
    }

    /// Abandon the transfer (the slot is never booted).
    pub fn abort_transfer(&mut self) -> Result<UpdateStatus, UpdateRefusal> {
        if let (Some(g), Some(_)) = (self.geometry, self.session()) {
            session::set_word(&mut self.dfu, &g, g.closed_at())
                .map_err(|_| UpdateRefusal::FlashFailed)?;
            self.phase = Phase::Idle;
        }
        Ok(self.status_now())
    }

    /// Mark the running image good.
    pub fn mark_booted(&mut self) -> Result<(), UpdateRefusal> {
        let mut aligned = AlignedBuffer([0u8; MAX_STRIDE]);
        let word = aligned
            .0
            .get_mut(..STATE::WRITE_SIZE)
            .ok_or(UpdateRefusal::FlashFailed)?;
        BlockingFirmwareState::new(&mut self.state, word)
            .mark_booted()
            .map_err(|_| UpdateRefusal::FlashFailed)?;
        if self.image_state == ImageState::Trial {
            self.image_state = ImageState::Confirmed;
        }
        Ok(())
    }
}

impl<DFU: NorFlash, STATE: NorFlash> UpdateSlots for FlashUpdater<DFU, STATE> {
    fn running_version(&self) -> FirmwareVersion {
        self.running
    }
    fn image_state(&self) -> ImageState {
        self.image_state
    }
    fn slot_bytes(&self) -> u32 {
        self.geometry.map_or(0, |g| g.slot_bytes())
    }
    fn begin(&mut self, begin: &UpdateBegin) -> Result<UpdateStatus, Refused> {
        Ok(self.begin_transfer(begin)?)
    }
    fn chunk(&mut self, chunk: &UpdateChunk) -> Result<UpdateStatus, Refused> {
        Ok(self.write_chunk(chunk)?)
    }
    fn status(&self) -> Result<UpdateStatus, Refused> {
        Ok(self.status_now())
    }
    fn verify(
        &mut self,
        signature: &ImageSignature,
        board: &[u8; 16],
    ) -> Result<UpdateStatus, Refused> {
        Ok(self.verify_image(signature, board)?)
    }
    fn commit(&mut self) -> Result<FirmwareVersion, Refused> {
        Ok(self.commit_image()?)
    }
    fn abort(&mut self) -> Result<UpdateStatus, Refused> {
        Ok(self.abort_transfer()?)
    }
    fn confirm(&mut self) -> Result<(), Refused> {
        Ok(self.mark_booted()?)
    }
}
