//! The virtual node's flash: the board's two 16 KiB store sectors in RAM
//! (the firmware's [`RamFlash`]), with the board's stall: while the F446
//! erases or programs its one flash bank the CPU stops, so each operation
//! moves the virtual clock on by the datasheet's worst-case time. A save
//! that erases a sector holds the node for 0.5 s of virtual time, as on the
//! board (x32 parallelism, V_DDA ≥ 2.7 V), and the frame schedule, the
//! `Hello` cadence and the host's command timeout see it.

use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use fois_firmware::platform::watchdog::ERASE_16K_X32_MAX_MS;
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

/// The board's store flash on a virtual clock.
#[derive(Debug)]
pub struct VirtualFlash {
    flash: BoardRamFlash,
    clock: Option<VirtualClock>,
}

impl VirtualFlash {
    /// Over `image` ([`FLASH_BYTES`] bytes; 0xFF = erased), stalling
    /// `clock` (none: no stall, e.g. before the node exists).
    pub fn new(image: Vec<u8>, clock: Option<VirtualClock>) -> Self {
        VirtualFlash {
            flash: RamFlash::new(image),
            clock,
        }
    }

    /// Stall `clock` from now on (or nothing).
    pub fn set_clock(&mut self, clock: Option<VirtualClock>) {
        self.clock = clock;
    }

    /// The RAM flash (contents, counters, power cuts).
    pub fn ram(&mut self) -> &mut BoardRamFlash {
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

impl ErrorType for VirtualFlash {
    type Error = RamFlashError;
}

impl ReadNorFlash for VirtualFlash {
    const READ_SIZE: usize = BoardRamFlash::READ_SIZE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.flash.read(offset, bytes)
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl NorFlash for VirtualFlash {
    const WRITE_SIZE: usize = BoardRamFlash::WRITE_SIZE;
    const ERASE_SIZE: usize = BoardRamFlash::ERASE_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let pages = u64::from(to.saturating_sub(from)) / BOARD_SECTOR_BYTES as u64;
        self.stall_ns(pages * u64::from(ERASE_16K_X32_MAX_MS) * 1_000_000);
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
}
