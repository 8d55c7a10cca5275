//! Version 6: a firmware image sent over the node's own link, and the signed
//! image's trailer both sides read.
//!
//! **The signed image** (`foisctl sign` writes it, `foisctl update` sends it):
//!
//! ```text
//! body (the application binary, as linked for the active slot)
//! | trailer (TRAILER_LEN bytes: ImageTrailer::to_bytes)
//! | signature (64 bytes, ed25519)
//! ```
//!
//! The node writes `body | trailer` into its update (DFU) slot; the signed
//! message is the SHA-512 digest of exactly those bytes (what
//! embassy-boot's `verify_and_mark_updated` hashes and verifies against the
//! public key built into the firmware). The trailer is inside the signed
//! bytes, so its version and its downgrade flag cannot be changed without
//! the private key; it lands after the body in the active slot, past the
//! program's last byte, where nothing reads it.
//!
//! **The transfer** (commands of [`crate::Command`]):
//! 1. `UpdateBegin { image_len, version, image_digest }`: `image_len` =
//!    `body + trailer` bytes, `image_digest` = the first 32 bytes of their
//!    SHA-512. A begin with the digest of the transfer in progress resumes it
//!    (the answer's `next_offset` says where); any other erases the slot.
//! 2. `UpdateChunk { offset, crc32, data }` in order, each at most
//!    [`UPDATE_CHUNK_MAX`] bytes, answered with the next offset.
//! 3. `UpdateVerify(signature)`: the node hashes the slot, compares the
//!    digest, reads the trailer, applies the version rule and checks the
//!    signature; nothing is marked.
//! 4. `UpdateCommit`: the verified image becomes the next boot's, on trial;
//!    the node resets after the answer. The new image confirms itself after
//!    its self-test or the bootloader rolls back to the old one.
//!
//! Every refusal is an [`crate::ErrorCode::UpdateRefused`] with its
//! [`UpdateRefusal`]; a refused piece changes nothing.

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

/// The most image bytes one [`UpdateChunk`] carries.
pub const UPDATE_CHUNK_MAX: usize = 256;

/// Bytes of the trailer that follows the body in a signed image.
pub const TRAILER_LEN: usize = 64;

/// Bytes of an ed25519 signature.
pub const SIGNATURE_LEN: usize = 64;

/// The trailer's first bytes.
pub const TRAILER_MAGIC: [u8; 8] = *b"FOIS-IMG";

/// The trailer layout this crate writes and reads.
pub const TRAILER_FORMAT: u16 = 1;

/// Bits of [`ImageTrailer::flags`].
pub mod image_flags {
    /// The image may replace a newer one: a deliberate, signed downgrade.
    pub const DOWNGRADE: u8 = 1 << 0;
}

/// A firmware version, semantic: major, minor, patch (as in
/// [`crate::Hello::firmware_version`]). Compared in that order.
pub type FirmwareVersion = [u8; 3];

/// The signed description of an image, after its body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageTrailer {
    /// Bytes of the body before the trailer.
    pub body_len: u32,
    /// The image's firmware version.
    pub version: FirmwareVersion,
    /// See [`image_flags`].
    pub flags: u8,
    /// The board the image is built for, ASCII, zero-padded (as
    /// [`crate::Hello::board`]).
    pub board: [u8; 16],
}

/// Why a trailer could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TrailerError {
    /// The magic bytes are missing: not a FOIS image (or not its trailer).
    NoMagic,
    /// A trailer layout this build does not know.
    UnknownFormat(u16),
    /// Reserved bytes are not zero.
    Reserved,
}

impl ImageTrailer {
    /// The trailer's bytes: magic, format (u16 LE), body length (u32 LE),
    /// version, flags, board, then zeros to [`TRAILER_LEN`].
    pub fn to_bytes(&self) -> [u8; TRAILER_LEN] {
        let mut out = [0u8; TRAILER_LEN];
        out[..8].copy_from_slice(&TRAILER_MAGIC);
        out[8..10].copy_from_slice(&TRAILER_FORMAT.to_le_bytes());
        out[10..14].copy_from_slice(&self.body_len.to_le_bytes());
        out[14..17].copy_from_slice(&self.version);
        out[17] = self.flags;
        out[18..34].copy_from_slice(&self.board);
        out
    }

    /// Read a trailer (the inverse of [`ImageTrailer::to_bytes`]).
    pub fn parse(bytes: &[u8; TRAILER_LEN]) -> Result<Self, TrailerError> {
        let (magic, rest) = bytes.split_at(8);
        if magic != TRAILER_MAGIC {
            return Err(TrailerError::NoMagic);
        }
        let format = u16::from_le_bytes([rest[0], rest[1]]);
        if format != TRAILER_FORMAT {
            return Err(TrailerError::UnknownFormat(format));
        }
        if bytes[34..].iter().any(|&b| b != 0) {
            return Err(TrailerError::Reserved);
        }
        let mut version = [0u8; 3];
        version.copy_from_slice(&bytes[14..17]);
        let mut board = [0u8; 16];
        board.copy_from_slice(&bytes[18..34]);
        Ok(ImageTrailer {
            body_len: u32::from_le_bytes([bytes[10], bytes[11], bytes[12], bytes[13]]),
            version,
            flags: bytes[17],
            board,
        })
    }

    /// True when the image says it is a deliberate downgrade.
    pub fn allows_downgrade(&self) -> bool {
        self.flags & image_flags::DOWNGRADE != 0
    }
}

/// The version rule: an image replaces the running one when it is newer, or
/// when it is older or equal and says it is a deliberate downgrade (the same
/// version again counts as a downgrade: re-flashing is deliberate too).
pub fn version_allowed(running: FirmwareVersion, trailer: &ImageTrailer) -> bool {
    trailer.version > running || trailer.allows_downgrade()
}

/// Version 6: start or resume a transfer ([`crate::Command::UpdateBegin`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UpdateBegin {
    /// Bytes to write: the body and its trailer (not the signature).
    pub image_len: u32,
    /// The image's version (from its trailer), for the node's log and refusal.
    pub version: FirmwareVersion,
    /// The first 32 bytes of the SHA-512 of the `image_len` bytes.
    pub image_digest: [u8; 32],
}

/// Version 6: one piece of the image ([`crate::Command::UpdateChunk`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UpdateChunk {
    /// Where in the image these bytes go (the node's `next_offset`).
    pub offset: u32,
    /// CRC-32 (ISO-HDLC, as the frames') of `data`.
    pub crc32: u32,
    /// At most [`UPDATE_CHUNK_MAX`] bytes.
    pub data: ChunkData,
}

/// Up to [`UPDATE_CHUNK_MAX`] bytes, on the wire as postcard bytes (a varint
/// length, then the bytes).
#[derive(Clone, PartialEq, Eq)]
pub struct ChunkData {
    len: u16,
    bytes: [u8; UPDATE_CHUNK_MAX],
}

impl ChunkData {
    /// The bytes, or `None` when there are more than [`UPDATE_CHUNK_MAX`].
    pub fn new(data: &[u8]) -> Option<Self> {
        let mut bytes = [0u8; UPDATE_CHUNK_MAX];
        bytes.get_mut(..data.len())?.copy_from_slice(data);
        Some(ChunkData {
            len: data.len() as u16,
            bytes,
        })
    }

    /// The bytes carried.
    pub fn as_slice(&self) -> &[u8] {
        self.bytes.get(..usize::from(self.len)).unwrap_or(&[])
    }
}

impl core::fmt::Debug for ChunkData {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "ChunkData({} B)", self.len)
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for ChunkData {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(f, "ChunkData({=u16} B)", self.len)
    }
}

impl Serialize for ChunkData {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(self.as_slice())
    }
}

impl<'de> Deserialize<'de> for ChunkData {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Bytes;
        impl serde::de::Visitor<'_> for Bytes {
            type Value = ChunkData;
            fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                write!(f, "at most {UPDATE_CHUNK_MAX} bytes")
            }
            fn visit_bytes<E: serde::de::Error>(self, v: &[u8]) -> Result<ChunkData, E> {
                ChunkData::new(v).ok_or_else(|| E::invalid_length(v.len(), &self))
            }
        }
        d.deserialize_bytes(Bytes)
    }
}

impl MaxSize for ChunkData {
    // A varint length of at most 256 (2 bytes) and the bytes.
    const POSTCARD_MAX_SIZE: usize = 2 + UPDATE_CHUNK_MAX;
}

/// Version 6: an ed25519 signature, in two halves (serde's arrays end at 32).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ImageSignature {
    /// Bytes 0..32 of the signature (R).
    pub r: [u8; 32],
    /// Bytes 32..64 (S).
    pub s: [u8; 32],
}

impl ImageSignature {
    /// From the 64 signature bytes.
    pub fn from_bytes(bytes: &[u8; SIGNATURE_LEN]) -> Self {
        let mut r = [0u8; 32];
        let mut s = [0u8; 32];
        r.copy_from_slice(&bytes[..32]);
        s.copy_from_slice(&bytes[32..]);
        ImageSignature { r, s }
    }

    /// The 64 signature bytes.
    pub fn to_bytes(&self) -> [u8; SIGNATURE_LEN] {
        let mut out = [0u8; SIGNATURE_LEN];
        out[..32].copy_from_slice(&self.r);
        out[32..].copy_from_slice(&self.s);
        out
    }
}

/// Version 6: where a transfer stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UpdatePhase {
    /// No transfer (none begun, or aborted, or committed and reset).
    Idle,
    /// Receiving chunks.
    Receiving,
    /// Every byte is in, the digest, trailer, version and signature checked:
    /// ready to commit.
    Verified,
}

/// Version 6: the answer to the transfer's commands
/// ([`crate::AckResult::UpdateStatus`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UpdateStatus {
    /// The phase.
    pub phase: UpdatePhase,
    /// The transfer's image length, bytes (0 when idle).
    pub image_len: u32,
    /// The next offset the node expects: every byte below it is written
    /// (after a power cut, the highest contiguous offset it can vouch for).
    pub next_offset: u32,
}

/// Version 6: which image runs and how it booted ([`crate::AckResult::ImageInfo`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ImageInfo {
    /// The running image's version.
    pub version: FirmwareVersion,
    /// Its boot state.
    pub state: ImageState,
    /// The largest image the update slot takes (body and trailer), bytes.
    pub slot_bytes: u32,
}

/// Version 6: how the running image booted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ImageState {
    /// Confirmed: it passed its self-test (or was flashed by a probe).
    Confirmed,
    /// On trial: a new image that has not yet passed its self-test; a reset
    /// before it does rolls back to the previous image.
    Trial,
    /// The previous image, back after a new one failed its trial.
    RolledBack {
        /// The version that failed.
        failed: FirmwareVersion,
    },
}

/// Version 6: why a piece of a transfer was refused
/// ([`crate::ErrorCode::UpdateRefused`]). Nothing changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UpdateRefusal {
    /// A chunk, verify or commit without a transfer begun.
    NoTransfer,
    /// The image does not fit the update slot (or is shorter than a trailer).
    BadLength {
        /// The largest image the slot takes, bytes.
        max_bytes: u32,
    },
    /// A chunk not at the offset the node expects (or past the image's end).
    OutOfOrder {
        /// Where the next chunk must start.
        expected_offset: u32,
    },
    /// A chunk whose CRC-32 does not match its bytes.
    ChunkCrc,
    /// Verify before every byte is in.
    Incomplete {
        /// The next offset the node expects.
        next_offset: u32,
    },
    /// The bytes in the slot do not hash to the begin's digest.
    DigestMismatch,
    /// No valid trailer at the image's end (or its body length disagrees).
    BadTrailer,
    /// The image is for another board.
    WrongBoard,
    /// The signature does not verify with the node's public key.
    BadSignature,
    /// The image is not newer and does not say it is a deliberate downgrade.
    OlderVersion {
        /// The running version.
        running: FirmwareVersion,
        /// The image's version.
        image: FirmwareVersion,
    },
    /// Commit before a successful verify.
    NotVerified,
    /// The running image is itself on trial: it must confirm (pass its
    /// self-test) before it accepts another.
    OnTrial,
    /// Erasing or programming the slot failed.
    FlashFailed,
    /// The node is in a state that cannot take an update now (its flash
    /// store skipped, a dark calibration running, ...).
    Busy,
}

impl UpdateRefusal {
    /// A short sentence for users.
    pub const fn describe(self) -> &'static str {
        match self {
            UpdateRefusal::NoTransfer => "no transfer begun",
            UpdateRefusal::BadLength { .. } => "the image does not fit the update slot",
            UpdateRefusal::OutOfOrder { .. } => "a chunk not at the expected offset",
            UpdateRefusal::ChunkCrc => "a chunk's CRC does not match its bytes",
            UpdateRefusal::Incomplete { .. } => "not every byte of the image is in",
            UpdateRefusal::DigestMismatch => "the image's bytes do not match its digest",
            UpdateRefusal::BadTrailer => "no valid image trailer",
            UpdateRefusal::WrongBoard => "the image is for another board",
            UpdateRefusal::BadSignature => "the signature does not verify with the node's key",
            UpdateRefusal::OlderVersion { .. } => {
                "the image is not newer and is not a signed downgrade"
            }
            UpdateRefusal::NotVerified => "commit before a successful verify",
            UpdateRefusal::OnTrial => "the running image is on trial and must confirm first",
            UpdateRefusal::FlashFailed => "erasing or programming the update slot failed",
            UpdateRefusal::Busy => "the node cannot take an update now",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trailer() -> ImageTrailer {
        ImageTrailer {
            body_len: 92_160,
            version: [0, 7, 0],
            flags: 0,
            board: *b"NUCLEO-F446RE\0\0\0",
        }
    }

    #[test]
    fn a_trailer_reads_back_and_refuses_foreign_bytes() {
        let bytes = trailer().to_bytes();
        assert_eq!(&bytes[..8], b"FOIS-IMG");
        assert_eq!(ImageTrailer::parse(&bytes), Ok(trailer()));
        let mut bad = bytes;
        bad[0] ^= 1;
        assert_eq!(ImageTrailer::parse(&bad), Err(TrailerError::NoMagic));
        let mut bad = bytes;
        bad[8] = 2;
        assert_eq!(
            ImageTrailer::parse(&bad),
            Err(TrailerError::UnknownFormat(2))
        );
        let mut bad = bytes;
        bad[63] = 1;
        assert_eq!(ImageTrailer::parse(&bad), Err(TrailerError::Reserved));
    }

    #[test]
    fn only_newer_images_or_signed_downgrades_pass_the_version_rule() {
        let t = trailer();
        assert!(version_allowed([0, 6, 9], &t));
        assert!(!version_allowed([0, 7, 0], &t));
        assert!(!version_allowed([1, 0, 0], &t));
        let down = ImageTrailer {
            flags: image_flags::DOWNGRADE,
            ..t
        };
        assert!(version_allowed([1, 0, 0], &down));
        assert!(version_allowed([0, 7, 0], &down));
    }

    #[test]
    fn chunk_data_keeps_at_most_the_chunk_size() {
        assert_eq!(
            ChunkData::new(&[7; 256]).map(|c| c.as_slice().len()),
            Some(256)
        );
        assert!(ChunkData::new(&[7; 257]).is_none());
        let c = ChunkData::new(&[1, 2, 3]).unwrap();
        let bytes = postcard::to_allocvec(&c).unwrap();
        assert_eq!(bytes, [3, 1, 2, 3]);
        let back: ChunkData = postcard::from_bytes(&bytes).unwrap();
        assert_eq!(back, c);
        let too_long = postcard::to_allocvec(&[0u8; 257][..]).unwrap();
        assert!(postcard::from_bytes::<ChunkData>(&too_long).is_err());
        let full = postcard::to_allocvec(&ChunkData::new(&[9; 256]).unwrap()).unwrap();
        assert_eq!(full.len(), ChunkData::POSTCARD_MAX_SIZE);
    }
}
