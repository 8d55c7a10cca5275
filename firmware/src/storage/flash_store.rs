//! The node's [`Storage`] on NOR flash: the versioned record of [`super::record`]
//! kept as the one value of a `sequential-storage` map over two flash
//! pages (sectors 2 and 3 of the F446 on the board, a [`RamFlash`] in
//! tests).
//!
//! Why this layout (the field failures it removes):
//! - **Power-fail safe.** A save appends a new item (header and data each
//!   with a CRC) after the old one; the old item stays valid until a newer
//!   one is complete. A page is erased only when the other page holds the
//!   newest value. A cut at any point leaves the old or the new record (the
//!   power-loss test in `tests/storage.rs` cuts at every operation and every
//!   byte of saves, page changes included).
//! - **Wear.** A 16 KiB page holds hundreds of records before it is
//!   erased once, and the two pages are used in turn (figures in
//!   `firmware/README.md`).
//! - **First boot vs. damage.** A range that is entirely erased is *empty*
//!   (defaults, no fault). A range that holds anything but no readable
//!   record is reported as a read failure, so the node raises
//!   `CONFIG_DEFAULTED`: defaults never come back silently. The read itself
//!   may erase: sequential-storage's `fetch_item` repairs an interrupted
//!   page change by erasing a page, so the board reads the store at boot
//!   only with a healthy supply (`storage::supply::boot_read`, else the read
//!   is deferred: `platform::boot::StoreRead::Defer`). If the
//!   damage is beyond sequential-storage's own repair, the next save erases
//!   the range and writes its record. (A cut
//!   in the moment between that erase and the new record leaves erased
//!   flash, which the next boot takes for a first boot: the one window in
//!   which defaults can come back without the flag, and only after the
//!   flag was raised for the damage.)
//!
//! The node is blocking (it runs from one mutex on the board, and in plain
//! loops on the host) while `sequential-storage` is async. [`Blocking`]
//! turns a blocking `NorFlash` into the async trait with futures that are
//! ready at their first poll, so `embassy_futures::block_on` runs each map
//! operation to completion in one call. On the F446 nothing is lost by
//! blocking: flash has one bank, and the CPU stalls on instruction fetches
//! while the controller erases or programs, async or not.
//! ([`embassy_embedded_hal`'s `BlockingAsync`] does the same wrapping but
//! cannot give the flash back, which the power-loss test's reboot needs.)
//!
//! [`embassy_embedded_hal`'s `BlockingAsync`]: https://docs.rs/embassy-embedded-hal

use core::ops::Range;

use embassy_futures::block_on;
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use sequential_storage::cache::Cache;
use sequential_storage::cache::key_pointers::ArrayKeyPointers;
use sequential_storage::cache::page_pointers::ArrayPagePointers;
use sequential_storage::cache::page_states::ArrayPageStates;
use sequential_storage::map::{MapConfig, MapStorage};

use crate::platform::flash_layout::{CONFIG_STORE, OLD_CONFIG_STORE};
use crate::storage::record::MAX_RECORD;
use crate::storage::{Storage, StorageError};

#[cfg(doc)]
use crate::storage::ram_flash::RamFlash;

/// Flash pages (erase units) the store uses: sequential-storage's map needs
/// two, one always kept free to move into.
pub const STORE_PAGES: usize = 2;
/// Bytes in each of the board's two store pages: the STM32F446's flash
/// sectors 2 and 3 are 16 KiB each (RM0390, flash organisation;
/// `platform::flash_layout::CONFIG_STORE`). The virtual node's flash has
/// the same geometry.
pub const BOARD_SECTOR_BYTES: usize = CONFIG_STORE.largest_sector_bytes() as usize;
/// Bytes in each page of the store before the bootloader (sectors 6 and 7,
/// 128 KiB each: `platform::flash_layout::OLD_CONFIG_STORE`), which
/// `storage::migrate` reads once.
pub const OLD_BOARD_SECTOR_BYTES: usize = OLD_CONFIG_STORE.largest_sector_bytes() as usize;
const _: () = assert!(CONFIG_STORE.sectors as usize == STORE_PAGES && CONFIG_STORE.uniform());
const _: () =
    assert!(OLD_CONFIG_STORE.sectors as usize == STORE_PAGES && OLD_CONFIG_STORE.uniform());
/// The one key of the map.
const RECORD_KEY: u8 = 0;
/// Work buffer: key + the largest record, rounded up to flash words, with room.
const WORK_LEN: usize = 128;
const _: () = assert!(1 + MAX_RECORD + 8 <= WORK_LEN);
/// Bytes checked per read when testing whether the range is erased.
const SCAN_CHUNK: usize = 64;

/// A blocking [`NorFlash`] seen through the async trait sequential-storage
/// takes; every future is ready at its first poll.
#[derive(Debug)]
pub struct Blocking<F>(F);

impl<F> Blocking<F> {
    /// Wrap a flash.
    pub fn new(flash: F) -> Self {
        Blocking(flash)
    }
    /// The flash back.
    pub fn into_inner(self) -> F {
        self.0
    }
    /// The flash.
    pub fn inner_mut(&mut self) -> &mut F {
        &mut self.0
    }
}

impl<F: ErrorType> ErrorType for Blocking<F> {
    type Error = F::Error;
}

impl<F: ReadNorFlash> embedded_storage_async::nor_flash::ReadNorFlash for Blocking<F> {
    const READ_SIZE: usize = F::READ_SIZE;
    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.0.read(offset, bytes)
    }
    fn capacity(&self) -> usize {
        self.0.capacity()
    }
}

impl<F: NorFlash> embedded_storage_async::nor_flash::NorFlash for Blocking<F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;
    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.0.erase(from, to)
    }
    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.0.write(offset, bytes)
    }
}

type StoreCache = Cache<
    ArrayPageStates<STORE_PAGES>,
    ArrayPagePointers<STORE_PAGES>,
    ArrayKeyPointers<u8, 1>,
    u8,
>;

type Map<F> = MapStorage<u8, Blocking<F>, StoreCache>;

fn fresh_cache() -> StoreCache {
    Cache::new(
        ArrayPageStates::new(),
        ArrayPagePointers::new(),
        ArrayKeyPointers::new(),
    )
}

/// The config/baseline record in a sequential-storage map on NOR flash.
pub struct FlashStore<F: NorFlash> {
    /// Always `Some`: taken only inside [`Self::erase_afresh`], which puts
    /// a map back on every path.
    map: Option<Map<F>>,
    range: Range<u32>,
    saves: u32,
}

impl<F: NorFlash> FlashStore<F> {
    /// The store on `range` of `flash` (offsets in the flash's own address
    /// space): exactly [`STORE_PAGES`] erase pages, page-aligned. Anything
    /// else is [`StorageError::Layout`].
    pub fn new(flash: F, range: Range<u32>) -> Result<Self, StorageError> {
        let pages = (range.end.saturating_sub(range.start) as usize) / F::ERASE_SIZE.max(1);
        if pages != STORE_PAGES {
            return Err(StorageError::Layout);
        }
        let config = MapConfig::try_new(range.clone()).map_err(|_| StorageError::Layout)?;
        Ok(FlashStore {
            map: Some(MapStorage::new(Blocking::new(flash), config, fresh_cache())),
            range,
            saves: 0,
        })
    }

    fn map(&mut self) -> &mut Map<F> {
        match self.map.as_mut() {
            Some(map) => map,
            // `erase_afresh` puts the map back before it returns.
            None => unreachable!("the store's map is always present"),
        }
    }

    /// The flash back (e.g. to "reboot" on the same flash in a test).
    pub fn into_flash(self) -> F {
        match self.map {
            Some(map) => map.destroy().0.into_inner(),
            None => unreachable!("the store's map is always present"),
        }
    }

    /// The flash (e.g. to look at its counters).
    pub fn flash_mut(&mut self) -> &mut F {
        self.map().flash().inner_mut()
    }

    /// Erase both pages and start sequential-storage over with an empty
    /// cache: its `erase_all` leaves the cache as it was (the page states
    /// and item positions of before the erase), and a record stored through
    /// that stale cache would land without its page's marker, found by this
    /// store's read-back but by no store made at the next boot.
    fn erase_afresh(&mut self) -> Result<(), StorageError> {
        let erased = block_on(self.map().erase_all()).map_err(|_| StorageError::Write);
        if let Some(map) = self.map.take() {
            let (flash, _stale) = map.destroy();
            // The range `new` accepted (MapConfig::try_new): valid.
            let config = MapConfig::new(self.range.clone());
            self.map = Some(MapStorage::new(flash, config, fresh_cache()));
        }
        erased
    }

    /// Records saved (successfully) through this store since it was made.
    pub fn saves(&self) -> u32 {
        self.saves
    }

    /// True if every byte of the range reads 0xFF (never written, or erased).
    fn range_is_erased(&mut self) -> Result<bool, StorageError> {
        let mut chunk = [0u8; SCAN_CHUNK];
        let range = self.range.clone();
        let mut at = range.start;
        let flash = self.map().flash().inner_mut();
        while at < range.end {
            let n = (range.end - at).min(SCAN_CHUNK as u32) as usize;
            let part = chunk.get_mut(..n).ok_or(StorageError::Read)?;
            flash.read(at, part).map_err(|_| StorageError::Read)?;
            if part.iter().any(|&b| b != 0xFF) {
                return Ok(false);
            }
            at += n as u32;
        }
        Ok(true)
    }
}

impl<F: NorFlash> Storage for FlashStore<F> {
    /// The newest record: `Ok(0)` when the range is erased (first boot),
    /// [`StorageError::Read`] when it holds something but no record.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, StorageError> {
        // Look before sequential-storage repairs (and maybe erases) anything.
        let erased = self.range_is_erased()?;
        let mut work = [0u8; WORK_LEN];
        let found = block_on(self.map().fetch_item::<&[u8]>(&mut work, &RECORD_KEY));
        match found {
            Ok(Some(bytes)) => {
                let dst = buf.get_mut(..bytes.len()).ok_or(StorageError::Read)?;
                dst.copy_from_slice(bytes);
                Ok(bytes.len())
            }
            Ok(None) if erased => Ok(0),
            Ok(None) | Err(_) => Err(StorageError::Read),
        }
    }

    /// Append `data` as the newest record, then read it back.
    fn write(&mut self, data: &[u8]) -> Result<(), StorageError> {
        if data.len() > MAX_RECORD {
            return Err(StorageError::TooLarge);
        }
        let mut work = [0u8; WORK_LEN];
        match block_on(self.map().store_item(&mut work, &RECORD_KEY, &data)) {
            Ok(()) => {}
            // The flash itself failed (or the power went): nothing more to try.
            Err(sequential_storage::Error::Storage { .. }) => return Err(StorageError::Write),
            // The store is in a state sequential-storage cannot repair (e.g.
            // another program's data whose bytes pass for an item header):
            // the record in it was already unreadable (the node booted with
            // CONFIG_DEFAULTED), so start the store afresh with this record.
            Err(_) => {
                self.erase_afresh()?;
                block_on(self.map().store_item(&mut work, &RECORD_KEY, &data))
                    .map_err(|_| StorageError::Write)?;
            }
        }
        self.read_back(data)
    }

    /// Erase both pages and write `data` as the only record, never parsing
    /// what the pages held (the store after a skipped read at boot). A cut
    /// between the erase and the record leaves erased flash: the defaults,
    /// which the node was running anyway.
    fn overwrite(&mut self, data: &[u8]) -> Result<(), StorageError> {
        if data.len() > MAX_RECORD {
            return Err(StorageError::TooLarge);
        }
        let mut work = [0u8; WORK_LEN];
        self.erase_afresh()?;
        block_on(self.map().store_item(&mut work, &RECORD_KEY, &data))
            .map_err(|_| StorageError::Write)?;
        self.read_back(data)
    }
}

impl<F: NorFlash> FlashStore<F> {
    /// Read the record back after a save: it must be `data`.
    fn read_back(&mut self, data: &[u8]) -> Result<(), StorageError> {
        let mut work = [0u8; WORK_LEN];
        let back = block_on(self.map().fetch_item::<&[u8]>(&mut work, &RECORD_KEY))
            .map_err(|_| StorageError::Read)?;
        if back != Some(data) {
            return Err(StorageError::Write);
        }
        self.saves = self.saves.saturating_add(1);
        Ok(())
    }
}
