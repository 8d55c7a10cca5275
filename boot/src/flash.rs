//! The bootloader's flash: one `NorFlash` per partition of
//! `flash_layout` (offset 0 = the partition's first byte), read from the
//! memory map and erased and programmed through the PAC, and the
//! independent watchdog that guards the swap.
//!
//! **Parallelism x16.** The bootloader measures no supply, so it erases and
//! programs at x16, which RM0390 §3.5 allows from 2.1 V (x32 needs 2.7 V):
//! a 128 KiB sector erases in ≤ 2.6 s (t_ERASE128KB at x16), a 128 KiB page
//! programs in 65 536 half-words of ≤ 100 µs (≤ 6.6 s, 1 s typical). The
//! application, which knows V_DDA, uses x32 where it may.
//!
//! **Watchdog.** Whether or not the reset that led here stopped the IWDG,
//! the bootloader starts it (a second start is harmless) and feeds it right
//! before every erase and every programmed chunk, so the longest stretch
//! unfed is one erase (2.6 s) against a timeout of ≥ 5.5 s. It keeps running
//! into the application: an image that hangs before it feeds the watchdog
//! itself is reset, and embassy-boot then rolls it back (the trial boot was
//! not marked good). The application's `Watchdog::start_first` sets its own
//! prescaler and reload (the IWDG accepts new ones while running).
//!
//! **Caches.** The flash's instruction and data caches are off from reset
//! and the bootloader does not turn them on, so a read after an erase or a
//! program sees the flash, never a stale line.

use embassy_stm32::pac;
use embassy_stm32::pac::flash::vals::Psize;
use embassy_stm32::pac::iwdg::vals::{Key, Pr};
use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

use crate::flash_controller;
use crate::flash_layout::{FLASH_BASE, Partition, WRITE_BYTES};

/// IWDG prescaler: LSI / 64 (PR = 4).
const IWDG_PR: u8 = 4;
/// IWDG reload: 4 096 ticks. At the fastest LSI (47 kHz) 4 096 × 64 /
/// 47 000 = 5.58 s; at the slowest (17 kHz) 15.4 s.
const IWDG_RELOAD: u16 = 4_095;
/// t_ERASE128KB at x16, maximum, ms (the longest stretch unfed).
const ERASE_128K_X16_MAX_MS: u32 = 2_600;
const _: () = assert!(4_096 * 64 * 1_000 / 47_000 > ERASE_128K_X16_MAX_MS * 2);

/// Start the independent watchdog (or keep it running) and feed it.
pub fn watchdog_start() {
    let iwdg = pac::IWDG;
    iwdg.kr().write(|w| w.set_key(Key::START));
    iwdg.kr().write(|w| w.set_key(Key::ENABLE));
    iwdg.pr().write(|w| w.set_pr(Pr::from_bits(IWDG_PR)));
    iwdg.rlr().write(|w| w.set_rl(IWDG_RELOAD));
    watchdog_feed();
}

/// Feed the independent watchdog.
pub fn watchdog_feed() {
    pac::IWDG.kr().write(|w| w.set_key(Key::RESET));
}

/// Why a flash operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlashError {
    /// Outside the partition.
    OutOfBounds,
    /// Not on a word (program) or sector (erase) boundary.
    NotAligned,
    /// The controller reported an error (SR: PGSERR, PGPERR, PGAERR,
    /// WRPERR, OPERR) or a programmed word did not read back.
    Failed,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            FlashError::NotAligned => NorFlashErrorKind::NotAligned,
            FlashError::Failed => NorFlashErrorKind::Other,
        }
    }
}

/// One partition of equal sectors of `SECTOR` bytes.
pub struct PartitionFlash<const SECTOR: usize> {
    part: Partition,
}

impl<const SECTOR: usize> PartitionFlash<SECTOR> {
    /// The partition `part`, whose sectors are all `SECTOR` bytes.
    pub const fn new(part: Partition) -> Self {
        assert!(part.uniform() && part.largest_sector_bytes() as usize == SECTOR);
        PartitionFlash { part }
    }

    fn check(&self, offset: u32, len: usize) -> Result<u32, FlashError> {
        let at = self
            .part
            .range_offset(offset, len)
            .ok_or(FlashError::OutOfBounds)?;
        Ok(FLASH_BASE + at)
    }
}

fn erase_sector(snb: u8) -> Result<(), FlashError> {
    watchdog_feed();
    flash_controller::unlock();
    flash_controller::start_sector_erase(snb, Psize::PSIZE16);
    // The CPU stalls on its next instruction fetch until the erase ends.
    let done = flash_controller::finish().map_err(|_| FlashError::Failed);
    watchdog_feed();
    done
}

fn program(address: u32, bytes: &[u8]) -> Result<(), FlashError> {
    watchdog_feed();
    flash_controller::unlock();
    flash_controller::start_programming(Psize::PSIZE16);
    let mut at = address;
    let mut result = Ok(());
    for pair in bytes.chunks_exact(2) {
        let half = u16::from_le_bytes([pair[0], pair[1]]);
        // SAFETY: `at` is inside a partition of the flash (checked by the
        // caller), half-word aligned, and the controller is in PG mode at x16.
        unsafe { core::ptr::write_volatile(at as *mut u16, half) };
        if flash_controller::wait_idle().is_err() {
            result = Err(FlashError::Failed);
            break;
        }
        // SAFETY: the same flash address, now programmed.
        if unsafe { core::ptr::read_volatile(at as *const u16) } != half {
            result = Err(FlashError::Failed);
            break;
        }
        at += 2;
    }
    let locked = flash_controller::finish().map_err(|_| FlashError::Failed);
    result.and(locked)
}

impl<const SECTOR: usize> ErrorType for PartitionFlash<SECTOR> {
    type Error = FlashError;
}

impl<const SECTOR: usize> ReadNorFlash for PartitionFlash<SECTOR> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        let address = self.check(offset, bytes.len())?;
        debug_assert!(address >= FLASH_BASE);
        // SAFETY: a range inside the memory-mapped flash (checked), which
        // is always readable.
        let src = unsafe { core::slice::from_raw_parts(address as *const u8, bytes.len()) };
        bytes.copy_from_slice(src);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.part.bytes() as usize
    }
}

impl<const SECTOR: usize> NorFlash for PartitionFlash<SECTOR> {
    const WRITE_SIZE: usize = WRITE_BYTES as usize;
    const ERASE_SIZE: usize = SECTOR;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        let sector = SECTOR as u32;
        if !from.is_multiple_of(sector) || !to.is_multiple_of(sector) {
            return Err(FlashError::NotAligned);
        }
        if from > to || to > self.part.bytes() {
            return Err(FlashError::OutOfBounds);
        }
        let mut at = from;
        while at < to {
            let snb = self.part.sector_at(at).ok_or(FlashError::OutOfBounds)?;
            erase_sector(snb)?;
            at += sector;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        if !offset.is_multiple_of(WRITE_BYTES) || !bytes.len().is_multiple_of(WRITE_BYTES as usize)
        {
            return Err(FlashError::NotAligned);
        }
        let address = self.check(offset, bytes.len())?;
        program(address, bytes)
    }
}
