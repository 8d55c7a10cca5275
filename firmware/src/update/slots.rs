//! What the node needs from its update slots ([`UpdateSlots`]), a node
//! without them ([`NoUpdates`]), how a refusal is told ([`Refused`]) and the
//! running image's version ([`FIRMWARE_VERSION`]).

use fois_protocol::{
    FirmwareVersion, ImageSignature, ImageState, UpdateBegin, UpdateChunk, UpdateRefusal,
    UpdateStatus,
};

/// The crate's version: the image's, sent in `Hello` (unless the update
/// slots say otherwise, `UpdateSlots::running_version`).
pub const FIRMWARE_VERSION: [u8; 3] = [
    parse_u8(env!("CARGO_PKG_VERSION_MAJOR")),
    parse_u8(env!("CARGO_PKG_VERSION_MINOR")),
    parse_u8(env!("CARGO_PKG_VERSION_PATCH")),
];

const fn parse_u8(s: &str) -> u8 {
    let b = s.as_bytes();
    let mut i = 0;
    let mut v: u8 = 0;
    while i < b.len() {
        v = v.wrapping_mul(10).wrapping_add(b[i].wrapping_sub(b'0'));
        i += 1;
    }
    v
}

/// Where a piece of the transfer was refused, as the node answers it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// This node takes no updates (`ErrorCode::UnknownCommand`).
    Unsupported,
    /// Refused with its reason (`ErrorCode::UpdateRefused`); nothing changed.
    Update(UpdateRefusal),
}

impl From<UpdateRefusal> for Refused {
    fn from(r: UpdateRefusal) -> Self {
        Refused::Update(r)
    }
}

/// What the node needs from its update slots. [`FlashUpdater`] implements it
/// over a pair of NOR flash partitions, [`NoUpdates`] for a node without.
/// No method panics on any input.
pub trait UpdateSlots {
    /// The running image's version (what `Hello` and `GetImageInfo` say).
    fn running_version(&self) -> FirmwareVersion;
    /// How the running image booted (read once, when the slots were built).
    fn image_state(&self) -> ImageState;
    /// The largest image the update slot takes (body and trailer), bytes.
    fn slot_bytes(&self) -> u32;
    /// Start a transfer, or resume the one in progress (same digest and
    /// length).
    fn begin(&mut self, begin: &UpdateBegin) -> Result<UpdateStatus, Refused>;
    /// Write one chunk at the expected offset.
    fn chunk(&mut self, chunk: &UpdateChunk) -> Result<UpdateStatus, Refused>;
    /// Where the transfer stands.
    fn status(&self) -> Result<UpdateStatus, Refused>;
    /// Check the whole image for `board` (the node's board name, as
    /// `Hello::board`): digest, trailer, version rule, signature. Nothing is
    /// marked.
    fn verify(
        &mut self,
        signature: &ImageSignature,
        board: &[u8; 16],
    ) -> Result<UpdateStatus, Refused>;
    /// Make the verified image the next boot's, on trial; gives its version.
    /// The node resets after the answer.
    fn commit(&mut self) -> Result<FirmwareVersion, Refused>;
    /// Abandon the transfer.
    fn abort(&mut self) -> Result<UpdateStatus, Refused>;
    /// Mark the running image good (embassy-boot's `mark_booted`): after a
    /// trial that passed its self-test, and after a rollback (so a new
    /// update can begin). Writes flash (the boot-state page's erase).
    fn confirm(&mut self) -> Result<(), Refused>;
}

/// A node without update slots: the transfer's commands are unknown to it,
/// its image is confirmed, its version the crate's.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NoUpdates;

impl UpdateSlots for NoUpdates {
    fn running_version(&self) -> FirmwareVersion {
        FIRMWARE_VERSION
    }
    fn image_state(&self) -> ImageState {
        ImageState::Confirmed
    }
    fn slot_bytes(&self) -> u32 {
        0
    }
    fn begin(&mut self, _: &UpdateBegin) -> Result<UpdateStatus, Refused> {
        Err(Refused::Unsupported)
    }
    fn chunk(&mut self, _: &UpdateChunk) -> Result<UpdateStatus, Refused> {
        Err(Refused::Unsupported)
    }
    fn status(&self) -> Result<UpdateStatus, Refused> {
        Err(Refused::Unsupported)
    }
    fn verify(&mut self, _: &ImageSignature, _: &[u8; 16]) -> Result<UpdateStatus, Refused> {
        Err(Refused::Unsupported)
    }
    fn commit(&mut self) -> Result<FirmwareVersion, Refused> {
        Err(Refused::Unsupported)
    }
    fn abort(&mut self) -> Result<UpdateStatus, Refused> {
        Err(Refused::Unsupported)
    }
    fn confirm(&mut self) -> Result<(), Refused> {
        Ok(())
    }
}
