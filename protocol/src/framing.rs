//! Framing (the wire-format rules of ARCHITECTURE.md): postcard payload, CRC-32 (little-endian) appended,
//! COBS-encoded, terminated by one 0x00.
//!
//! ```text
//! | COBS( postcard(message) | CRC-32/ISO-HDLC(postcard bytes), 4 B LE ) | 0x00 |
//! ```
//!
//! The decoder works byte by byte in a fixed buffer: it never allocates and
//! never panics. A frame that fails COBS, its CRC, postcard, or is longer than
//! the buffer is skipped and counted; decoding resumes after the next 0x00.

use postcard::experimental::max_size::MaxSize;
use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::messages::{DeviceFrame, HostFrame};

/// The CRC used on every frame: CRC-32/ISO-HDLC (the zlib/Ethernet CRC).
pub const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Bytes of CRC appended to each payload.
pub const CRC_LEN: usize = 4;

const fn max(a: usize, b: usize) -> usize {
    if a > b { a } else { b }
}

/// The largest postcard payload of any message, either direction (computed
/// from the types by postcard's `MaxSize`).
pub const MAX_PAYLOAD: usize = max(DeviceFrame::POSTCARD_MAX_SIZE, HostFrame::POSTCARD_MAX_SIZE);

/// The largest frame on the wire: COBS of payload + CRC, plus the 0x00.
/// Buffers of this size hold any frame of this protocol version.
pub const MAX_FRAME: usize = cobs::max_encoding_length(MAX_PAYLOAD + CRC_LEN) + 1;

/// Why a message could not be framed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The output buffer is smaller than the frame (use [`MAX_FRAME`]).
    BufferTooSmall,
}

/// Frame `msg` into `out`; returns the frame's length, 0x00 included.
pub fn encode<T: Serialize>(msg: &T, out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut scratch = [0u8; MAX_PAYLOAD + CRC_LEN];
    let payload_len = postcard::to_slice(msg, &mut scratch[..MAX_PAYLOAD])
        .map_err(|_| EncodeError::BufferTooSmall)?
        .len();
    let crc = CRC.checksum(&scratch[..payload_len]).to_le_bytes();
    let total = payload_len + CRC_LEN;
    scratch
        .get_mut(payload_len..total)
        .ok_or(EncodeError::BufferTooSmall)?
        .copy_from_slice(&crc);
    let n = cobs::try_encode(&scratch[..total], out).map_err(|_| EncodeError::BufferTooSmall)?;
    *out.get_mut(n).ok_or(EncodeError::BufferTooSmall)? = 0;
    Ok(n + 1)
}

/// Frame `msg` into a new vector (host side).
#[cfg(any(feature = "std", test))]
pub fn encode_to_vec<T: Serialize>(msg: &T) -> Vec<u8> {
    let mut out = vec![0u8; MAX_FRAME];
    // MAX_FRAME bounds every message of this crate; a foreign type that does
    // not fit yields an empty frame rather than a panic.
    let n = encode(msg, &mut out).unwrap_or(0);
    out.truncate(n);
    out
}

/// Why a received frame was skipped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// Not valid COBS, or too short to hold a CRC.
    Garbled,
    /// The CRC does not match: bytes were corrupted.
    Crc,
    /// Longer than the decoder's buffer: dropped up to the next 0x00.
    Oversized,
    /// CRC good but not a message of this version (unknown variant, trailing bytes).
    Malformed,
}

/// Counts kept by a [`FrameDecoder`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DecodeStats {
    /// Frames decoded.
    pub frames: u32,
    /// Frames skipped as [`FrameError::Garbled`].
    pub garbled: u32,
    /// Frames skipped as [`FrameError::Crc`].
    pub crc_failed: u32,
    /// Frames skipped as [`FrameError::Oversized`].
    pub oversized: u32,
    /// Frames skipped as [`FrameError::Malformed`].
    pub malformed: u32,
}

impl DecodeStats {
    /// Every skipped frame, whatever the reason.
    pub fn rejected(&self) -> u32 {
        self.garbled
            .saturating_add(self.crc_failed)
            .saturating_add(self.oversized)
            .saturating_add(self.malformed)
    }
}

/// A streaming decoder with a fixed buffer of `N` bytes (default
/// [`MAX_FRAME`]). Feed it bytes as they arrive.
pub struct FrameDecoder<const N: usize = MAX_FRAME> {
    buf: [u8; N],
    len: usize,
    discarding: bool,
    stats: DecodeStats,
}

impl<const N: usize> Default for FrameDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameDecoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        FrameDecoder {
            buf: [0; N],
            len: 0,
            discarding: false,
            stats: DecodeStats {
                frames: 0,
                garbled: 0,
                crc_failed: 0,
                oversized: 0,
                malformed: 0,
            },
        }
    }

    /// Counts so far.
    pub fn stats(&self) -> DecodeStats {
        self.stats
    }

    /// Forget a partly received frame (e.g. after a reconnect).
    pub fn reset(&mut self) {
        self.len = 0;
        self.discarding = false;
    }

    /// Feed one byte. Returns `Some` when a 0x00 ends a non-empty frame: the
    /// message, or why it was skipped. Empty frames (0x00 0x00) are ignored,
    /// so a sender may put a 0x00 first to flush a receiver's partial frame.
    pub fn push<T: DeserializeOwned>(&mut self, byte: u8) -> Option<Result<T, FrameError>> {
        if byte != 0 {
            if self.discarding {
                return None;
            }
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => self.discarding = true,
            }
            return None;
        }
        // End of a frame.
        let len = core::mem::replace(&mut self.len, 0);
        if core::mem::replace(&mut self.discarding, false) {
            self.stats.oversized = self.stats.oversized.wrapping_add(1);
            return Some(Err(FrameError::Oversized));
        }
        if len == 0 {
            return None;
        }
        let result = self.decode_buffer::<T>(len);
        let counter = match result {
            Ok(_) => &mut self.stats.frames,
            Err(FrameError::Garbled) => &mut self.stats.garbled,
            Err(FrameError::Crc) => &mut self.stats.crc_failed,
            Err(FrameError::Oversized) => &mut self.stats.oversized,
            Err(FrameError::Malformed) => &mut self.stats.malformed,
        };
        *counter = counter.wrapping_add(1);
        Some(result)
    }

    /// Feed many bytes; `on_frame` sees every completed frame in order.
    pub fn feed<T: DeserializeOwned>(
        &mut self,
        bytes: &[u8],
        mut on_frame: impl FnMut(Result<T, FrameError>),
    ) {
        for &b in bytes {
            if let Some(r) = self.push::<T>(b) {
                on_frame(r);
            }
        }
    }

    fn decode_buffer<T: DeserializeOwned>(&mut self, len: usize) -> Result<T, FrameError> {
        let encoded = self.buf.get_mut(..len).ok_or(FrameError::Garbled)?;
        let n = cobs::decode_in_place(encoded).map_err(|_| FrameError::Garbled)?;
        if n <= CRC_LEN {
            return Err(FrameError::Garbled);
        }
        let decoded = encoded.get(..n).ok_or(FrameError::Garbled)?;
        let (payload, crc_bytes) = decoded.split_at(n - CRC_LEN);
        let mut crc = [0u8; CRC_LEN];
        crc.copy_from_slice(crc_bytes);
        if CRC.checksum(payload) != u32::from_le_bytes(crc) {
            return Err(FrameError::Crc);
        }
        match postcard::take_from_bytes::<T>(payload) {
            Ok((msg, [])) => Ok(msg),
            _ => Err(FrameError::Malformed),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::{Command, DeviceMsg, ErrorCode, ErrorReply};

    fn frame(seq: u32) -> DeviceFrame {
        DeviceFrame {
            seq,
            msg: DeviceMsg::Error(ErrorReply {
                id: Some(7),
                code: ErrorCode::Garbled,
            }),
        }
    }

    #[test]
    fn round_trip_and_delimiter() {
        let mut out = [0u8; MAX_FRAME];
        let n = encode(&frame(3), &mut out).unwrap();
        assert_eq!(out[n - 1], 0);
        assert!(!out[..n - 1].contains(&0), "COBS leaves no zero inside");
        let mut dec = FrameDecoder::<MAX_FRAME>::new();
        let mut got = Vec::new();
        dec.feed::<DeviceFrame>(&out[..n], |r| got.push(r));
        assert_eq!(got, vec![Ok(frame(3))]);
        assert_eq!(dec.stats().frames, 1);
    }

    #[test]
    fn small_buffer_is_an_error_not_a_panic() {
        let mut out = [0u8; 4];
        assert_eq!(
            encode(&frame(1), &mut out),
            Err(EncodeError::BufferTooSmall)
        );
    }

    #[test]
    fn empty_frames_are_ignored_and_oversize_resyncs() {
        let mut dec = FrameDecoder::<16>::new();
        let mut got = Vec::new();
        dec.feed::<HostFrame>(&[0, 0, 0], |r| got.push(r));
        assert!(got.is_empty());
        let long = [0x55u8; 40];
        dec.feed::<HostFrame>(&long, |r| got.push(r));
        dec.feed::<HostFrame>(&[0], |r| got.push(r));
        assert_eq!(got, vec![Err(FrameError::Oversized)]);
        let good = encode_to_vec(&HostFrame {
            id: 1,
            cmd: Command::GetInfo,
        });
        dec.feed::<HostFrame>(&good, |r| got.push(r));
        assert_eq!(got.len(), 2);
        assert_eq!(
            got[1],
            Ok(HostFrame {
                id: 1,
                cmd: Command::GetInfo
            })
        );
        assert_eq!(dec.stats().oversized, 1);
    }

    #[test]
    fn crc_failure_and_wrong_type_are_counted() {
        let mut bytes = encode_to_vec(&frame(9));
        bytes[2] ^= 0x01;
        let mut dec = FrameDecoder::<MAX_FRAME>::new();
        let mut got = Vec::new();
        dec.feed::<DeviceFrame>(&bytes, |r| got.push(r));
        assert!(matches!(
            got[0],
            Err(FrameError::Crc) | Err(FrameError::Garbled)
        ));
        // A valid frame of another type: CRC passes, postcard refuses.
        let host = encode_to_vec(&HostFrame {
            id: 300,
            cmd: Command::Reset,
        });
        got.clear();
        dec.feed::<DeviceFrame>(&host, |r| got.push(r));
        assert_eq!(got, vec![Err(FrameError::Malformed)]);
        assert_eq!(dec.stats().rejected(), 2);
    }
}
