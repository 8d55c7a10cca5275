//! The update's partitions as the application sees them: the DFU slot
//! (sectors 6–7, where an update is downloaded, and where the store was
//! before the bootloader: `storage::migrate` reads it there) and
//! embassy-boot's state (sector 4, the trial boot's mark). Blocking
//! `NorFlash` types, offset 0 at each partition's first byte, which the
//! updater (generic over `NorFlash`, as embassy-boot's
//! `BlockingFirmwareUpdater`) takes. Reads and programming go through
//! embassy-stm32's flash regions (x32); erases through
//! `board::erase_sector`, sector by sector, each with the watchdog fed
//! right before it and the link's burst ended, like the store's.
//!
//! Addresses: `fois_firmware::platform::flash_layout` (one source, also for
//! the bootloader and the two `memory.x`).

use embassy_stm32::flash::{
    BANK1_REGION2, BANK1_REGION3, Bank1Region2, Bank1Region3, Blocking, Error as FlashError,
    FlashRegion,
};
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use fois_firmware::platform::flash_layout::{BOOT_STATE, DFU, Partition, WRITE_BYTES};

use crate::board::erase_partition;
use crate::safety::Watchdog;

/// The DFU slot's sectors, bytes (128 KiB).
const DFU_SECTOR_BYTES: usize = DFU.largest_sector_bytes() as usize;
/// The state's sector, bytes (64 KiB).
const STATE_SECTOR_BYTES: usize = BOOT_STATE.largest_sector_bytes() as usize;

/// `part` lies inside embassy-stm32's flash region `region`.
const fn inside(part: Partition, region: &FlashRegion) -> bool {
    region.offset <= part.offset() && part.offset() + part.bytes() <= region.offset + region.size
}
const _: () = assert!(inside(DFU, &BANK1_REGION3) && DFU.uniform());
const _: () = assert!(inside(BOOT_STATE, &BANK1_REGION2) && BOOT_STATE.uniform());
const _: () = assert!(WRITE_BYTES == 4);

/// One partition of equal sectors of `SECTOR` bytes inside the flash
/// region `R` of embassy-stm32.
pub struct Slot<R, const SECTOR: usize> {
    region: R,
    /// The region's offset from the start of flash.
    region_offset: u32,
    part: Partition,
    wdg: Watchdog,
}

/// The DFU slot: sectors 6–7, two 128 KiB pages at 0x0804_0000.
pub type DfuSlot = Slot<Bank1Region3<'static, Blocking>, DFU_SECTOR_BYTES>;
/// embassy-boot's state: sector 4, one 64 KiB page at 0x0801_0000.
pub type StateSlot = Slot<Bank1Region2<'static, Blocking>, STATE_SECTOR_BYTES>;

impl DfuSlot {
    /// Over embassy-stm32's third flash region (sectors 5–7).
    pub fn new(region: Bank1Region3<'static, Blocking>, wdg: Watchdog) -> Self {
        Slot {
            region,
            region_offset: BANK1_REGION3.offset,
            part: DFU,
            wdg,
        }
    }
}

impl StateSlot {
    /// Over embassy-stm32's second flash region (sector 4).
    // Taken by the updater (feature `updater`).
    #[cfg_attr(not(feature = "updater"), allow(dead_code))]
    pub fn new(region: Bank1Region2<'static, Blocking>, wdg: Watchdog) -> Self {
        Slot {
            region,
            region_offset: BANK1_REGION2.offset,
            part: BOOT_STATE,
            wdg,
        }
    }
}

impl<R, const SECTOR: usize> Slot<R, SECTOR> {
    /// The region's offset of the partition's byte `offset`, if
    /// `offset..offset + len` lies inside the partition.
    fn in_region(&self, offset: u32, len: usize) -> Result<u32, FlashError> {
        let at = self
            .part
            .range_offset(offset, len)
            .ok_or(FlashError::Size)?;
        Ok(at - self.region_offset)
    }
}

impl<R, const SECTOR: usize> ErrorType for Slot<R, SECTOR> {
    type Error = FlashError;
}

impl<R, const SECTOR: usize> ReadNorFlash for Slot<R, SECTOR>
where
    R: ReadNorFlash<Error = FlashError>,
{
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        let at = self.in_region(offset, bytes.len())?;
        self.region.read(at, bytes)
    }

    fn capacity(&self) -> usize {
        self.part.bytes() as usize
    }
}

impl<R, const SECTOR: usize> NorFlash for Slot<R, SECTOR>
where
    R: NorFlash<Error = FlashError>,
{
    const WRITE_SIZE: usize = WRITE_BYTES as usize;
    const ERASE_SIZE: usize = SECTOR;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        erase_partition(self.part, SECTOR as u32, from, to, self.wdg)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        let at = self.in_region(offset, bytes.len())?;
        self.region.write(at, bytes)
    }
}
