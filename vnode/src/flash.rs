//! The virtual node's flash: the board's two 16 KiB store sectors in RAM
//! (the firmware's [`RamFlash`]), with the board's stall: while the F446
//! erases or programs its one flash bank the CPU stops, so each operation
//! moves the virtual clock on by the datasheet's worst-case time. A save
//! that erases a sector holds the node for 0.5 s of virtual time, as on the
//! board (x32 parallelism, V_DDA ≥ 2.7 V), and the frame schedule, the
//! `Hello` cadence and the host's command timeout see it.
//!
//! The update's partitions (`crate::update_slots`) are the same model at
//! their own sector sizes ([`StallingFlash`]): a 64 KiB boot-state sector
//! and 128 KiB slot sectors, each erase stalling by its sector's time.

use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use fois_firmware::platform::watchdog::{
    ERASE_16K_X32_MAX_MS, ERASE_64K_X32_MAX_MS, ERASE_128K_X32_MAX_MS,
};
use fois_firmware::storage::flash_store::{BOARD_SECTOR_BYTES, STORE_PAGES};
use fois_firmware::storage::ram_flash::{RamFlash, RamFlashError};

use crate::VirtualClock;

/// The RAM flash under [`VirtualFlash`].
pub type BoardRamFlash = RamFlash<Vec<u8>, BOARD_SECTOR_BYTES, STORE_PAGES>;

// The stall per page is the 16 KiB sector's erase time.
const _: () = assert!(BOARD_SECTOR_BYTES == 16 * 1024);

/// Bytes of the virtual flash (and of a state file).
pub const FLASH_BYTES: usize = BOARD_SECTOR_BYTES * STORE_PAGES;

/// Worst-case programming time of one 32-bit word at x32, ns (RM0390 /
/// datasheet t_PROG: 16 µs typ, 100 µs max).
pub const PROGRAM_WORD_MAX_NS: u64 = 100_000;

/// Worst-case erase time of one of the F446's sectors of `sector_bytes`
/// at x32 (16, 64 or 128 KiB; the datasheet's t_ERASE max), ns.
pub const fn erase_max_ns(sector_bytes: usize) -> u64 {
    let ms = if sector_bytes <= 16 * 1024 {
        ERASE_16K_X32_MAX_MS
    } else if sector_bytes <= 64 * 1024 {
        ERASE_64K_X32_MAX_MS
    } else {
        ERASE_128K_X32_MAX_MS
    };
    ms as u64 * 1_000_000
}

/// `PAGES` flash sectors of `PAGE` bytes in RAM on a virtual clock.
#[derive(Debug)]
pub struct StallingFlash<const PAGE: usize, const PAGES: usize> {
    flash: RamFlash<Vec<u8>, PAGE, PAGES>,
    clock: Option<VirtualClock>,
}

/// The board's store flash on a virtual clock.
pub type VirtualFlash = StallingFlash<BOARD_SECTOR_BYTES, STORE_PAGES>;

impl<const PAGE: usize, const PAGES: usize> StallingFlash<PAGE, PAGES> {
    /// Over `image` (`PAGE × PAGES` bytes; 0xFF = erased), stalling
    /// `clock` (none: no stall, e.g. before the node exists).
    pub fn new(image: Vec<u8>, clock: Option<VirtualClock>) -> Self {
        StallingFlash {
            flash: RamFlash::new(image),
            clock,
        }
    }

    /// Stall `clock` from now on (or nothing).
    pub fn set_clock(&mut self, clock: Option<VirtualClock>) {
        self.clock = clock;
    }

    /// The RAM flash (contents, counters, power cuts).
    pub fn ram(&mut self) -> &mut RamFlash<Vec<u8>, PAGE, PAGES> {
        &mut self.flash
    }

    /// The contents.
    pub fn bytes(&self) -> &[u8] {
        self.flash.bytes()
    }

    fn stall_ns(&self, ns: u64) {
        if let Some(c) = &self.clock {
            c.advance_ns(ns);
        }
    }
}

impl<const PAGE: usize, const PAGES: usize> ErrorType for StallingFlash<PAGE, PAGES> {
    type Error = RamFlashError;
}

impl<const PAGE: usize, const PAGES: usize> ReadNorFlash for StallingFlash<PAGE, PAGES> {
    const READ_SIZE: usize = RamFlash::<Vec<u8>, PAGE, PAGES>::READ_SIZE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.flash.read(offset, bytes)
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<const PAGE: usize, const PAGES: usize> NorFlash for StallingFlash<PAGE, PAGES> {
    const WRITE_SIZE: usize = RamFlash::<Vec<u8>, PAGE, PAGES>::WRITE_SIZE;
    const ERASE_SIZE: usize = RamFlash::<Vec<u8>, PAGE, PAGES>::ERASE_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let pages = u64::from(to.saturating_sub(from)) / PAGE as u64;
        self.stall_ns(pages * erase_max_ns(PAGE));
        self.flash.erase(from, to)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let words = bytes.len().div_ceil(4) as u64;
        self.stall_ns(words * PROGRAM_WORD_MAX_NS);
        self.flash.write(offset, bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erases_and_writes_stall_the_clock_by_the_datasheet_maximum() {
        let clock = VirtualClock::new();
        let mut f = VirtualFlash::new(vec![0xFF; FLASH_BYTES], Some(clock.clone()));
        f.write(0, &[0u8; 48]).unwrap();
        // 12 words × 100 µs.
        assert_eq!(clock.now_ns(), 1_200_000);
        f.erase(0, BOARD_SECTOR_BYTES as u32).unwrap();
        assert_eq!(clock.now_ns(), 1_200_000 + 500_000_000);
        assert!(f.bytes()[..48].iter().all(|&b| b == 0xFF));
        let mut g = VirtualFlash::new(vec![0xFF; FLASH_BYTES], None);
        g.erase(0, FLASH_BYTES as u32).unwrap();
        assert_eq!(g.ram().counters().erases, 2);
    }

    #[test]
    fn a_slot_sector_erase_stalls_by_its_own_size() {
        let clock = VirtualClock::new();
        let mut f =
            StallingFlash::<{ 128 * 1024 }, 2>::new(vec![0xFF; 256 * 1024], Some(clock.clone()));
        f.erase(0, 256 * 1024).unwrap();
        assert_eq!(clock.now_ns(), 4_000_000_000);
        let mut s =
            StallingFlash::<{ 64 * 1024 }, 1>::new(vec![0xFF; 64 * 1024], Some(clock.clone()));
        s.erase(0, 64 * 1024).unwrap();
        assert_eq!(clock.now_ns(), 5_100_000_000);
    }
}
