//! A read-only reader of the store of the layout before the bootloader:
//! the newest record in a sequential-storage 8.0.2 map (key `0u8`) as the
//! firmware of that layout wrote it (`storage::flash_store` on sectors 6–7,
//! a flash read in bytes and programmed in 4-byte words). Only
//! `storage::migrate` uses it, once per node.
//!
//! Why not sequential-storage itself: a second `FlashStore` for the old
//! geometry (128 KiB pages, another `NorFlash` type) monomorphises the
//! crate's map code again — 6.8 KB of the application's 128 KiB for a
//! once-in-a-lifetime copy — and its `fetch_item` may erase to repair,
//! which must not happen in what is now the DFU slot. This reader follows
//! `fetch_item`'s search without the repair (sequential-storage 8.0.2,
//! pinned exactly: `src/map.rs`, `src/item.rs`, `src/lib.rs`):
//!
//! - a page's state is its first and last byte: at least 4 of 8 bits zero
//!   is a marker; start and end marked = closed, start only = partly open,
//!   neither = open, end only = an interrupted erase (nothing is read);
//! - the page in use is the first partly open one, else the closed page
//!   before the first open one (no open page: nothing is read);
//! - items follow the page's start marker word: an 8-byte header (data
//!   CRC-32 as adapted by the crate, length u16, CRC-16 of the length),
//!   the data padded to the word; an erased header ends the page, a header
//!   whose length CRC fails is skipped word by word, a data CRC of 0 is an
//!   erased item, a wrong data CRC a corrupted one (skipped);
//! - the newest item with the key in the page in use wins; with none there,
//!   the page before it if that one is closed.
//!
//! Anything it cannot read gives `None`: the migration then moves nothing.
//! The tests compare it with sequential-storage on stores of thousands of
//! saves with power cuts (`tests` below).

use core::ops::Range;

use embedded_storage::nor_flash::ReadNorFlash;

use crate::storage::record::MAX_RECORD;

/// The old flash's word (the largest of its read and write sizes): the
/// board's `BoardFlash` programmed 4 bytes and read 1.
const WORD: u32 = 4;
/// Bytes of a page marker that are read (the old flash's read size).
const MARKER_READ: u32 = 1;
/// Item header bytes (rounded to the word: 8).
const HEADER: u32 = 8;
/// The map's key of the record (`flash_store`'s `RECORD_KEY`).
const KEY: u8 = 0;
/// The largest item data: the key and the largest record.
const MAX_DATA: usize = 1 + MAX_RECORD;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Page {
    Open,
    PartOpen,
    Closed,
}

fn marked<F: ReadNorFlash>(flash: &mut F, at: u32) -> Option<bool> {
    let mut b = [0u8; MARKER_READ as usize];
    flash.read(at, &mut b).ok()?;
    Some(b.iter().map(|x| x.count_zeros()).sum::<u32>() >= 4)
}

fn page_state<F: ReadNorFlash>(flash: &mut F, start: u32, page_bytes: u32) -> Option<Page> {
    let first = marked(flash, start)?;
    let last = marked(flash, start + page_bytes - MARKER_READ)?;
    match (first, last) {
        (true, true) => Some(Page::Closed),
        (true, false) => Some(Page::PartOpen),
        (false, false) => Some(Page::Open),
        (false, true) => None,
    }
}

/// sequential-storage's CRC-16 of an item's length (never 0xFFFF).
fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xffff;
    for &byte in data {
        crc ^= u16::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0x1a2e
            } else {
                crc >> 1
            };
        }
    }
    match crc ^ 0xffff {
        0xffff => 0xfffe,
        other => other,
    }
}

/// sequential-storage's data CRC: CRC-32C from 0xEEEEEEEE, never 0, and
/// never with a first byte of 0x00 or 0xFF.
fn adapted_crc32(data: &[u8]) -> u32 {
    let mut crc: u32 = 0xEEEE_EEEE;
    for &byte in data {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            let low = crc & 1 == 1;
            crc >>= 1;
            if low {
                crc ^= 0x82f6_3b78;
            }
        }
    }
    match !crc {
        0 => 1,
        v if v.to_le_bytes()[0] == 0 || v.to_le_bytes()[0] == 0xFF => v ^ 1,
        v => v,
    }
}

/// The newest item with the key in the page `start..start + page_bytes`:
/// its record bytes copied into `out`, their length.
fn newest_in_page<F: ReadNorFlash>(
    flash: &mut F,
    start: u32,
    page_bytes: u32,
    out: &mut [u8; MAX_RECORD],
) -> Option<Option<usize>> {
    let end = start + page_bytes - WORD;
    let mut at = start + WORD;
    let mut found = None;
    let mut data = [0u8; MAX_DATA + WORD as usize];
    while at + HEADER <= end {
        let mut h = [0u8; HEADER as usize];
        flash.read(at, &mut h).ok()?;
        if h.iter().all(|&b| b == 0xFF) {
            break;
        }
        let length = u16::from_le_bytes([h[4], h[5]]);
        if crc16(&h[4..6]) != u16::from_le_bytes([h[6], h[7]]) {
            at += WORD;
            continue;
        }
        let padded = u32::from(length).next_multiple_of(WORD);
        let next = at + HEADER + padded;
        if next > end {
            // A length beyond the page: sequential-storage skips a word.
            at += WORD;
            continue;
        }
        let crc = u32::from_le_bytes([h[0], h[1], h[2], h[3]]);
        let len = usize::from(length);
        if crc != 0 {
            // sequential-storage fails the whole fetch on an item larger
            // than its buffer; none of the old store's items was.
            let buf = data.get_mut(..padded as usize)?;
            flash.read(at + HEADER, buf).ok()?;
            let item = buf.get(..len)?;
            if adapted_crc32(item) == crc && item.first() == Some(&KEY) {
                let record = item.get(1..)?;
                out.get_mut(..record.len())?.copy_from_slice(record);
                found = Some(record.len());
            }
        }
        at = next;
    }
    Some(found)
}

/// The newest record of the old store on `range` of `flash` (pages of
/// `page_bytes`), copied into `out`; its length. `None`: no record, or a
/// store sequential-storage would have to repair first.
pub fn newest_record<F: ReadNorFlash>(
    flash: &mut F,
    range: Range<u32>,
    page_bytes: u32,
    out: &mut [u8; MAX_RECORD],
) -> Option<usize> {
    if page_bytes < 2 * WORD + HEADER {
        return None;
    }
    let pages = (range.end.checked_sub(range.start)? / page_bytes) as usize;
    if pages != 2 {
        return None; // the old store had two pages
    }
    let page_start = |p: usize| range.start + p as u32 * page_bytes;
    // Page states are read as sequential-storage reads them: in page order,
    // and only as far as it looks (a damaged page it never reaches does not
    // matter).
    let state = |flash: &mut F, p: usize| page_state(flash, page_start(p), page_bytes);
    let previous = |p: usize| (p + pages - 1) % pages;
    let mut in_use = None;
    for p in 0..pages {
        if state(flash, p)? == Page::PartOpen {
            in_use = Some(p);
            break;
        }
    }
    let in_use = match in_use {
        Some(p) => p,
        None => {
            let mut open = None;
            for p in 0..pages {
                if state(flash, p)? == Page::Open {
                    open = Some(p);
                    break;
                }
            }
            let before = previous(open?);
            if state(flash, before)? != Page::Closed {
                return None; // all open: nothing stored
            }
            before
        }
    };
    let mut page = in_use;
    for _ in 0..pages {
        if let Some(n) = newest_in_page(flash, page_start(page), page_bytes, out)? {
            return Some(n);
        }
        page = previous(page);
        if state(flash, page)? != Page::Closed {
            return None;
        }
    }
    None
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)]
mod tests {
    use rand_core::Rng;
    use rand_pcg::Pcg32;

    use super::*;
    use crate::storage::Storage;
    use crate::storage::flash_store::FlashStore;
    use crate::storage::ram_flash::{PowerCut, RamFlash};

    /// What sequential-storage reads (on a copy of the flash) and whether
    /// it changed the flash to do so (a repair).
    fn reference<const P: usize>(bytes: &[u8]) -> (Option<Vec<u8>>, bool) {
        let mut st = FlashStore::new(
            RamFlash::<Vec<u8>, P, 2>::new(bytes.to_vec()),
            0..(2 * P) as u32,
        )
        .unwrap();
        let mut buf = [0u8; MAX_RECORD];
        let got = st.read(&mut buf);
        let changed = st.into_flash().bytes() != bytes;
        match got {
            Ok(n) if n > 0 => (Some(buf[..n].to_vec()), changed),
            _ => (None, changed),
        }
    }

    fn ours<const P: usize>(bytes: &[u8]) -> Option<Vec<u8>> {
        let mut f = RamFlash::<Vec<u8>, P, 2>::new(bytes.to_vec());
        let mut out = [0u8; MAX_RECORD];
        newest_record(&mut f, 0..(2 * P) as u32, P as u32, &mut out).map(|n| out[..n].to_vec())
    }

    /// Saves of random lengths with power cuts at random bytes, each cut
    /// followed by a reboot; after every step the reader agrees with
    /// sequential-storage wherever that needs no repair, and never reads
    /// something sequential-storage would not.
    fn agree_over_saves<const P: usize>(seed: u64, saves: u32) -> (u32, u32) {
        let mut rng = Pcg32::new(seed, 0x0a02_bdbf_7bb3_c0a7);
        let mut flash = RamFlash::<Vec<u8>, P, 2>::new(vec![0xFF; 2 * P]);
        let (mut compared, mut repaired) = (0, 0);
        for k in 0..saves {
            let len = 10 + (rng.next_u32() % 50) as usize;
            let record: Vec<u8> = (0..len).map(|i| (k as usize * 7 + i) as u8).collect();
            if rng.next_u32().is_multiple_of(4) {
                flash.cut_power(PowerCut::AfterBytes(rng.next_u32() % 80));
            }
            let mut st = FlashStore::new(flash, 0..(2 * P) as u32).unwrap();
            let _ = st.write(&record);
            flash = st.into_flash();
            flash.power_on();
            let (want, changed) = reference::<P>(flash.bytes());
            let got = ours::<P>(flash.bytes());
            if changed {
                repaired += 1;
                if let Some(g) = &got {
                    assert_eq!(
                        Some(g),
                        want.as_ref(),
                        "save {k}: read what needed a repair"
                    );
                }
            } else {
                compared += 1;
                assert_eq!(got, want, "save {k}");
            }
        }
        (compared, repaired)
    }

    #[test]
    fn agrees_with_sequential_storage_across_page_changes_and_cuts() {
        let mut repairs = 0;
        for seed in 1..=20 {
            let (compared, repaired) = agree_over_saves::<256>(seed, 300);
            assert!(compared > 200, "seed {seed}: {compared}");
            repairs += repaired;
        }
        let (compared, repaired) = agree_over_saves::<1024>(21, 1_000);
        assert!(compared > 800, "{compared}");
        // The cuts left states sequential-storage had to repair, too.
        assert!(repairs + repaired > 0);
        println!("states needing a repair: {}", repairs + repaired);
    }

    #[test]
    fn the_crcs_are_sequential_storages() {
        // Never the values that mean "erased" or "half written".
        for data in [&b""[..], b"\x00", b"\xff\xff\xff\xff", b"FOIS"] {
            let c = adapted_crc32(data);
            assert_ne!(c, 0);
            assert!(c.to_le_bytes()[0] != 0 && c.to_le_bytes()[0] != 0xFF);
        }
        assert_ne!(crc16(&[0xFF, 0xFF]), 0xFFFF);
    }

    #[test]
    fn nothing_from_an_erased_or_foreign_region() {
        assert_eq!(ours::<256>(&[0xFF; 512]), None);
        assert_eq!(ours::<256>(&[0x00; 512]), None);
        let noise: Vec<u8> = (0..512u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect();
        assert_eq!(ours::<256>(&noise), None);
    }
}
