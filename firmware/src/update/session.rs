//! The transfer's session record: what a begin said (length, version,
//! digest) and how far the image is written, kept in the update (DFU) slot
//! so a transfer resumes after a power cut.
//!
//! **Where**: at the end of the part of the DFU slot the bootloader copies
//! into the active slot (its first `active_len` bytes), after the largest
//! image ([`Geometry::slot_bytes`]). The bootloader's swap carries it into
//! the active slot (past the program's last byte, where nothing reads it)
//! and its revert carries it back, so after a rollback the record still
//! names the image that failed. It is written right after the erase of the
//! page(s) that hold it, at each new begin.
//!
//! **Layout** (`stride` = the flash's program unit, at least 4 bytes):
//! ```text
//! header   HEADER_LEN bytes: magic, image_len (u32 LE), version, digest (32),
//!          CRC-32 of the bytes before it; the rest 0xFF
//! closed   one stride: programmed (zeros) when the session is committed or
//!          aborted
//! marks    one stride per GRANULE bytes of image: mark g programmed (zeros)
//!          after every byte of [0, min((g + 1) × GRANULE, image_len)) is
//! ```
//! **Vouching**: after a cut the node resumes at the end of the last mark of
//! an unbroken run from mark 0. A chunk cut mid-programming has no mark yet
//! (marks are programmed after the bytes they cover), and a mark cut
//! mid-programming is not all zeros: neither is vouched for. The bytes after
//! the vouched offset may hold part of the same image; they are programmed
//! again with the same bytes (NOR programming only clears bits, so the
//! result is those bytes: the F4 allows a word to be programmed again,
//! RM0390 §3.5.2 as `storage::ram_flash` models it).

use embedded_storage::nor_flash::NorFlash;
use fois_protocol::FirmwareVersion;
// CRC-32 ISO-HDLC: the frames' own (one table in the image).
use fois_protocol::framing::CRC;

/// Image bytes one progress mark covers (the protocol's chunk size).
pub const GRANULE: u32 = fois_protocol::UPDATE_CHUNK_MAX as u32;

/// Bytes of the record's header.
pub const HEADER_LEN: usize = 64;

/// The header's first bytes.
pub const SESSION_MAGIC: [u8; 8] = *b"FOIS-UPD";

/// The largest program unit the record supports (bytes).
pub const MAX_STRIDE: usize = 32;

/// What a begin said.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SessionHeader {
    /// Bytes of the image (body and trailer).
    pub image_len: u32,
    /// The version the begin named.
    pub version: FirmwareVersion,
    /// The first 32 bytes of the image's SHA-512.
    pub digest: [u8; 32],
}

impl SessionHeader {
    /// The header's bytes.
    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let mut out = [0xFFu8; HEADER_LEN];
        let mut body = [0u8; 48];
        body[..8].copy_from_slice(&SESSION_MAGIC);
        body[8..12].copy_from_slice(&self.image_len.to_le_bytes());
        body[12..15].copy_from_slice(&self.version);
        body[15] = 0;
        body[16..48].copy_from_slice(&self.digest);
        out[..48].copy_from_slice(&body);
        out[48..52].copy_from_slice(&CRC.checksum(&body).to_le_bytes());
        out
    }

    /// Read a header (`None`: erased, torn or foreign bytes).
    pub fn parse(bytes: &[u8; HEADER_LEN]) -> Option<Self> {
        let (body, rest) = bytes.split_at(48);
        let crc = u32::from_le_bytes(rest.get(..4)?.try_into().ok()?);
        if body.get(..8)? != SESSION_MAGIC || CRC.checksum(body) != crc {
            return None;
        }
        Some(SessionHeader {
            image_len: u32::from_le_bytes(body.get(8..12)?.try_into().ok()?),
            version: body.get(12..15)?.try_into().ok()?,
            digest: body.get(16..48)?.try_into().ok()?,
        })
    }
}

/// Where the record and the image go in a DFU slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Geometry {
    /// Bytes of the active slot (the part of the DFU slot the swap copies).
    pub active_len: u32,
    /// The flash's erase unit.
    pub page: u32,
    /// The record's program unit (the flash's, at least 4).
    pub stride: u32,
}

impl Geometry {
    /// The geometry for a DFU flash `F` and an active slot of `active_len`
    /// bytes; `None` when it cannot hold a record (an active slot that is
    /// not whole pages, a program unit over [`MAX_STRIDE`] or not a power
    /// of two, or a DFU slot not one page larger than the active slot).
    pub fn new<F: NorFlash>(active_len: u32, dfu_capacity: usize) -> Option<Self> {
        let page = u32::try_from(F::ERASE_SIZE).ok()?;
        let stride = F::WRITE_SIZE.max(4);
        if stride > MAX_STRIDE || !stride.is_power_of_two() || page == 0 {
            return None;
        }
        let g = Geometry {
            active_len,
            page,
            stride: stride as u32,
        };
        let dfu = u32::try_from(dfu_capacity).ok()?;
        let fits = active_len > 0
            && active_len.is_multiple_of(page)
            && page.is_multiple_of(g.stride)
            && dfu >= active_len.checked_add(page)?
            && g.record_len() < active_len;
        fits.then_some(g)
    }

    /// Progress marks the record holds (enough for the whole active slot).
    pub fn marks(&self) -> u32 {
        self.active_len.div_ceil(GRANULE)
    }

    /// Bytes of the record: header, closed word, marks.
    pub fn record_len(&self) -> u32 {
        HEADER_LEN as u32 + self.stride + self.marks() * self.stride
    }

    /// Where the record starts (a multiple of the stride).
    pub fn record_at(&self) -> u32 {
        (self.active_len - self.record_len()) & !(self.stride - 1)
    }

    /// The largest image (body and trailer): every byte before the record.
    pub fn slot_bytes(&self) -> u32 {
        self.record_at()
    }

    /// The first page that holds part of the record (erased at each begin;
    /// the pages before it are erased when the image first reaches them).
    pub fn record_page(&self) -> u32 {
        self.record_at() / self.page * self.page
    }

    /// Where the closed word is.
    pub fn closed_at(&self) -> u32 {
        self.record_at() + HEADER_LEN as u32
    }

    /// Where mark `g` is.
    pub fn mark_at(&self, g: u32) -> u32 {
        self.closed_at() + self.stride + g * self.stride
    }

    /// Marks a complete image of `image_len` bytes has.
    pub fn marks_for(image_len: u32) -> u32 {
        image_len.div_ceil(GRANULE)
    }

    /// The image bytes below mark `count` (the vouched offset when the first
    /// `count` marks are set).
    pub fn vouched(count: u32, image_len: u32) -> u32 {
        count.saturating_mul(GRANULE).min(image_len)
    }
}

/// A record as read from the flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StoredSession {
    /// What the begin said.
    pub header: SessionHeader,
    /// Committed or aborted.
    pub closed: bool,
    /// Marks set in an unbroken run from the first.
    pub marks: u32,
}

/// True when `n` bytes at `at` are all zeros (a programmed word; a torn or
/// erased one is not).
fn programmed<F: NorFlash>(flash: &mut F, at: u32, n: u32) -> Result<bool, F::Error> {
    let mut buf = [0xFFu8; MAX_STRIDE];
    let word = buf.get_mut(..n as usize).unwrap_or(&mut []);
    flash.read(at, word)?;
    Ok(!word.is_empty() && word.iter().all(|&b| b == 0))
}

/// Read the record (`Ok(None)`: none, or a torn header).
pub fn read<F: NorFlash>(flash: &mut F, g: &Geometry) -> Result<Option<StoredSession>, F::Error> {
    let mut bytes = [0u8; HEADER_LEN];
    flash.read(g.record_at(), &mut bytes)?;
    let Some(header) = SessionHeader::parse(&bytes) else {
        return Ok(None);
    };
    if header.image_len > g.slot_bytes() {
        return Ok(None);
    }
    let closed = programmed(flash, g.closed_at(), g.stride)?;
    let mut marks = 0;
    while marks < Geometry::marks_for(header.image_len)
        && programmed(flash, g.mark_at(marks), g.stride)?
    {
        marks += 1;
    }
    Ok(Some(StoredSession {
        header,
        closed,
        marks,
    }))
}

/// Erase the record's page(s) and write a new header (the begin of a new
/// transfer).
pub fn start<F: NorFlash>(
    flash: &mut F,
    g: &Geometry,
    header: &SessionHeader,
) -> Result<(), F::Error> {
    flash.erase(g.record_page(), g.active_len)?;
    flash.write(g.record_at(), &header.to_bytes())
}

/// Program one stride of zeros at `at` (a mark, or the closed word).
pub fn set_word<F: NorFlash>(flash: &mut F, g: &Geometry, at: u32) -> Result<(), F::Error> {
    let zeros = [0u8; MAX_STRIDE];
    flash.write(at, zeros.get(..g.stride as usize).unwrap_or(&[]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::storage::ram_flash::RamFlash;

    type Dfu = RamFlash<Vec<u8>, 4096, 16>;

    #[test]
    fn the_board_layout_leaves_most_of_the_slot_to_the_image() {
        // 128 KiB sectors, the F4's 4-byte program unit.
        type Board = RamFlash<Vec<u8>, 131_072, 2>;
        let g = Geometry::new::<Board>(131_072, 262_144).unwrap();
        assert_eq!(g.marks(), 512);
        assert_eq!(g.record_len(), 64 + 4 + 512 * 4);
        assert_eq!(g.slot_bytes(), 131_072 - 2_116);
        assert_eq!(g.record_page(), 0);
        // A DFU slot no page larger than the active one cannot swap.
        assert!(Geometry::new::<Board>(131_072, 131_072).is_none());
    }

    #[test]
    fn a_header_reads_back_and_a_torn_one_does_not() {
        let h = SessionHeader {
            image_len: 9_000,
            version: [0, 2, 0],
            digest: [7; 32],
        };
        let bytes = h.to_bytes();
        assert_eq!(SessionHeader::parse(&bytes), Some(h));
        let mut torn = bytes;
        torn[40] = 0xFF;
        assert_eq!(SessionHeader::parse(&torn), None);
        assert_eq!(SessionHeader::parse(&[0xFF; HEADER_LEN]), None);
    }

    #[test]
    fn marks_vouch_for_an_unbroken_run_only() {
        let mut f = Dfu::new(vec![0xFF; 65_536]);
        let g = Geometry::new::<Dfu>(32_768, 65_536).unwrap();
        let h = SessionHeader {
            image_len: 1_000,
            version: [0, 2, 0],
            digest: [1; 32],
        };
        start(&mut f, &g, &h).unwrap();
        set_word(&mut f, &g, g.mark_at(0)).unwrap();
        set_word(&mut f, &g, g.mark_at(2)).unwrap();
        let s = read(&mut f, &g).unwrap().unwrap();
        assert_eq!((s.marks, s.closed), (1, false));
        assert_eq!(Geometry::vouched(s.marks, h.image_len), 256);
        set_word(&mut f, &g, g.mark_at(1)).unwrap();
        set_word(&mut f, &g, g.mark_at(3)).unwrap();
        let s = read(&mut f, &g).unwrap().unwrap();
        assert_eq!(Geometry::vouched(s.marks, h.image_len), 1_000);
        // A torn mark (some bits still set) is not vouched for.
        f.bytes_mut()[g.mark_at(3) as usize] = 0x10;
        let s = read(&mut f, &g).unwrap().unwrap();
        assert_eq!(Geometry::vouched(s.marks, h.image_len), 768);
    }
}
