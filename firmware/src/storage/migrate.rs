//! The store's move to the bootloader's flash layout: before the
//! bootloader, the store was sectors 6–7 of the F446 (two 128 KiB pages);
//! now it is sectors 2–3 (two 16 KiB pages), and sectors 6–7 are the
//! update's DFU slot (`platform::flash_layout`). A node updated from the
//! old layout keeps its config, link settings, baseline and learned gain:
//! at boot, while the new store holds no valid record and the old region
//! holds one, the old region's newest record is copied, byte for byte
//! (its layout version 1–4 is read and upgraded by the node's usual load,
//! `storage::record::decode`), into the new store; once it reads back
//! there, the old region is erased, so the copy happens once.
//!
//! Power cuts: the old region is only read (by `storage::old_store`, a
//! read-only reader of sequential-storage's format: no repair may erase in
//! it) until the new record is complete and read back; a cut anywhere before leaves the old record
//! where it was and the next boot copies again (the new store's partial
//! item is overwritten: `Storage::overwrite`). A cut during the old
//! region's erase leaves a valid new record, so the next boot does nothing.
//!
//! The old region is read only when the new store holds no valid record,
//! and copied only from a valid record (magic, CRC, a layout this firmware
//! reads, a config that passes its rule): an update's image downloaded
//! into the DFU slot is never taken for a store, never erased here.
//!
//! Call it before the node reads its store, before anything may erase the
//! DFU slot, and only where the boot reads the store at all
//! (`platform::boot::StoreRead::Read`: a healthy supply, no boot loop).

use core::ops::Range;

use embedded_storage::nor_flash::NorFlash;

use crate::storage::old_store;
use crate::storage::record::{self, MAX_RECORD};
use crate::storage::{Storage, StorageError};

/// What [`migrate`] found and did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Migration {
    /// The new store holds a valid record: nothing was read of the old
    /// region (every boot after the first).
    NotNeeded,
    /// The old region holds no valid record (a node that never had the old
    /// layout, an erased region, or an update's image): nothing copied.
    NothingToMove,
    /// The old region's newest record (of this layout version) is now the
    /// new store's record; `old_erased`: the old region was erased after
    /// (false if that erase failed: the copy stands, the erase is retried
    /// by no one, and the next update erases the slot anyway).
    Moved {
        /// The record's layout version (1–4).
        layout: u16,
        /// The old region was erased after the copy.
        old_erased: bool,
    },
}

/// The layout version of a valid record in `bytes`, `None` if they hold none.
fn valid_layout(bytes: &[u8]) -> Option<u16> {
    record::decode(bytes).ok()?;
    let v = bytes.get(4..6)?;
    Some(u16::from_le_bytes([*v.first()?, *v.get(1)?]))
}

/// Move the old store's newest record from `old_range` of `old` (the old
/// layout's two pages) into `new`, if `new` holds no valid record (see the
/// module's text). An error: the new store could not be written (the old
/// record stays; the next boot tries again) or the old range does not
/// suit a store ([`StorageError::Layout`]).
pub fn migrate<N, O>(
    new: &mut N,
    old: &mut O,
    old_range: Range<u32>,
) -> Result<Migration, StorageError>
where
    N: Storage,
    O: NorFlash,
{
    let mut buf = [0xFFu8; MAX_RECORD];
    if let Ok(n) = new.read(&mut buf)
        && valid_layout(buf.get(..n).unwrap_or(&[])).is_some()
    {
        return Ok(Migration::NotNeeded);
    }
    let mut record = [0xFFu8; MAX_RECORD];
    let Some(n) =
        old_store::newest_record(old, old_range.clone(), O::ERASE_SIZE as u32, &mut record)
    else {
        return Ok(Migration::NothingToMove);
    };
    let bytes = record.get(..n).unwrap_or(&[]);
    let Some(layout) = valid_layout(bytes) else {
        return Ok(Migration::NothingToMove);
    };
    new.overwrite(bytes)?;
    let old_erased = old.erase(old_range.start, old_range.end).is_ok();
    Ok(Migration::Moved { layout, old_erased })
}
