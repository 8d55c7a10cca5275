//! The STM32F446RE's 512 KiB of flash, partitioned for the bootloader
//! (`boot/`, embassy-boot), the config store, embassy-boot's state, the
//! running image (active slot) and the update's download slot (DFU). The
//! one source of these addresses: the board binary, the bootloader and the
//! node's migration use them; the two `memory.x` files (the app's in
//! `firmware/`, the bootloader's in `boot/`) repeat them for the linker, and
//! a test (`tests/flash_layout.rs`) checks that they agree.
//!
//! | sectors | bytes | at | part |
//! |---|---|---|---|
//! | 0–1 | 2 × 16 KiB | 0x0800_0000 | bootloader (≤ 24 KiB used) |
//! | 2–3 | 2 × 16 KiB | 0x0800_8000 | config store (sequential-storage, two equal pages) |
//! | 4 | 64 KiB | 0x0801_0000 | boot state (embassy-boot: magic + swap progress) |
//! | 5 | 128 KiB | 0x0802_0000 | active slot: the application image (≤ 128 KiB) |
//! | 6–7 | 2 × 128 KiB | 0x0804_0000 | DFU slot: the downloaded image + one page for the swap |
//!
//! Before the bootloader, the application ran from sector 0 and the config
//! store was sectors 6–7 ([`OLD_CONFIG_STORE`], now the DFU slot):
//! `storage::migrate` copies its newest record over once.
//!
//! Why this split: the F446's sectors (RM0390 §3.3, flash organisation:
//! 4 × 16, 64, 3 × 128 KiB) leave one way to hold a 128 KiB image twice —
//! the active slot in sector 5 and the DFU slot in sectors 6–7, because
//! embassy-boot's swap wants the DFU slot one erase page (here 128 KiB)
//! larger than the active one. The 16 KiB sectors hold the bootloader and
//! the store (sequential-storage needs two equal pages); the 64 KiB sector
//! is the only one left for the boot state.

/// Where flash starts (memory-mapped, RM0390 §2.3).
pub const FLASH_BASE: u32 = 0x0800_0000;
/// The F446RE's flash, bytes.
pub const FLASH_BYTES: u32 = 512 * 1024;
/// The sectors' sizes, KiB (RM0390 §3.3, flash module organisation).
pub const SECTOR_KIB: [u32; 8] = [16, 16, 16, 16, 64, 128, 128, 128];
/// Programming unit of the board's flash code, bytes (x32 parallelism).
pub const WRITE_BYTES: u32 = 4;

/// Offset (from [`FLASH_BASE`]) of sector `n`'s first byte; past the last
/// sector: the flash's size.
pub const fn sector_offset(n: u8) -> u32 {
    let mut at = 0;
    let mut i = 0;
    while i < n as usize && i < SECTOR_KIB.len() {
        at += SECTOR_KIB[i] * 1024;
        i += 1;
    }
    at
}

/// Bytes of sector `n` (0 past the last sector).
pub const fn sector_bytes(n: u8) -> u32 {
    if (n as usize) < SECTOR_KIB.len() {
        SECTOR_KIB[n as usize] * 1024
    } else {
        0
    }
}

/// A run of whole sectors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Partition {
    /// Its first sector's number (SNB).
    pub first_sector: u8,
    /// How many sectors.
    pub sectors: u8,
}

impl Partition {
    /// Offset of its first byte from [`FLASH_BASE`].
    pub const fn offset(&self) -> u32 {
        sector_offset(self.first_sector)
    }
    /// Its first byte's address.
    pub const fn start(&self) -> u32 {
        FLASH_BASE + self.offset()
    }
    /// Its size, bytes.
    pub const fn bytes(&self) -> u32 {
        sector_offset(self.first_sector + self.sectors) - self.offset()
    }
    /// The address just past it.
    pub const fn end(&self) -> u32 {
        self.start() + self.bytes()
    }
    /// The largest of its sectors, bytes (its erase unit if all are equal).
    pub const fn largest_sector_bytes(&self) -> u32 {
        let mut largest = 0;
        let mut i = 0;
        while i < self.sectors {
            let b = sector_bytes(self.first_sector + i);
            if b > largest {
                largest = b;
            }
            i += 1;
        }
        largest
    }
    /// True if all its sectors have one size (a `NorFlash` with one erase size).
    pub const fn uniform(&self) -> bool {
        let first = sector_bytes(self.first_sector);
        let mut i = 0;
        while i < self.sectors {
            if sector_bytes(self.first_sector + i) != first {
                return false;
            }
            i += 1;
        }
        true
    }
    /// The bytes `offset..offset + len` (from the partition's start), if
    /// they lie inside it: their offset from [`FLASH_BASE`] (`None` if they
    /// run past its end or overflow).
    pub fn range_offset(&self, offset: u32, len: usize) -> Option<u32> {
        let end = offset.checked_add(u32::try_from(len).ok()?)?;
        if end > self.bytes() {
            return None;
        }
        Some(self.offset() + offset)
    }
    /// The sector holding `offset` (from the partition's start), if inside.
    pub const fn sector_at(&self, offset: u32) -> Option<u8> {
        let mut i = 0;
        while i < self.sectors {
            let s = self.first_sector + i;
            let from = sector_offset(s) - self.offset();
            if offset >= from && offset < from + sector_bytes(s) {
                return Some(s);
            }
            i += 1;
        }
        None
    }
}

/// The bootloader (`boot/`): sectors 0–1.
pub const BOOTLOADER: Partition = Partition {
    first_sector: 0,
    sectors: 2,
};
/// The bootloader's budget, bytes (`cargo xtask size` checks it): a quarter
/// of its partition left free for a later fix.
pub const BOOTLOADER_BUDGET_BYTES: u32 = 24 * 1024;
/// The config store (`storage::flash_store`): sectors 2–3.
pub const CONFIG_STORE: Partition = Partition {
    first_sector: 2,
    sectors: 2,
};
/// embassy-boot's state (magic, swap and revert progress): sector 4.
pub const BOOT_STATE: Partition = Partition {
    first_sector: 4,
    sectors: 1,
};
/// The running application image: sector 5.
pub const ACTIVE: Partition = Partition {
    first_sector: 5,
    sectors: 1,
};
/// The update's download slot: sectors 6–7.
pub const DFU: Partition = Partition {
    first_sector: 6,
    sectors: 2,
};
/// Where the config store was before the bootloader (the application then
/// started at sector 0): sectors 6–7, the same flash as [`DFU`] now.
pub const OLD_CONFIG_STORE: Partition = Partition {
    first_sector: 6,
    sectors: 2,
};

/// The swap's page: the larger erase unit of the active and DFU slots.
pub const SWAP_PAGE_BYTES: u32 = {
    let a = ACTIVE.largest_sector_bytes();
    let d = DFU.largest_sector_bytes();
    if a > d { a } else { d }
};
/// Words embassy-boot's state needs: magic, progress validity, and two
/// progress words (swap, revert) per swap page of the active slot.
pub const BOOT_STATE_WORDS: u32 = 2 + 4 * (ACTIVE.bytes() / SWAP_PAGE_BYTES);

// The partitions tile the flash in order, with no gap and no overlap.
const _: () = assert!(BOOTLOADER.first_sector == 0);
const _: () = assert!(CONFIG_STORE.first_sector == BOOTLOADER.first_sector + BOOTLOADER.sectors);
const _: () = assert!(BOOT_STATE.first_sector == CONFIG_STORE.first_sector + CONFIG_STORE.sectors);
const _: () = assert!(ACTIVE.first_sector == BOOT_STATE.first_sector + BOOT_STATE.sectors);
const _: () = assert!(DFU.first_sector == ACTIVE.first_sector + ACTIVE.sectors);
const _: () = assert!(DFU.end() == FLASH_BASE + FLASH_BYTES);
const _: () = assert!(DFU.first_sector as usize + DFU.sectors as usize == SECTOR_KIB.len());
// The bootloader fits its partition; the store has two equal pages.
const _: () = assert!(BOOTLOADER_BUDGET_BYTES <= BOOTLOADER.bytes());
const _: () = assert!(CONFIG_STORE.sectors == 2 && CONFIG_STORE.uniform());
// embassy-boot (boot_loader.rs, `assert_partitions`): whole pages, the DFU
// slot at least one page larger than the active slot, enough state words.
const _: () = assert!(ACTIVE.uniform() && DFU.uniform());
const _: () = assert!(ACTIVE.bytes().is_multiple_of(SWAP_PAGE_BYTES));
const _: () = assert!(DFU.bytes().is_multiple_of(SWAP_PAGE_BYTES));
const _: () = assert!(DFU.bytes() >= ACTIVE.bytes() + SWAP_PAGE_BYTES);
const _: () = assert!(BOOT_STATE_WORDS * WRITE_BYTES <= BOOT_STATE.bytes());
// The project's budget: the application image stays ≤ 128 KiB.
const _: () = assert!(ACTIVE.bytes() == 128 * 1024);
// The old store is where the DFU slot is (the migration reads it there).
const _: () = assert!(OLD_CONFIG_STORE.start() == DFU.start() && OLD_CONFIG_STORE.uniform());

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_range_is_inside_a_partition_or_refused() {
        let p = DFU;
        assert_eq!(p.range_offset(0, 256), Some(p.offset()));
        assert_eq!(
            p.range_offset(p.bytes() - 4, 4),
            Some(p.offset() + p.bytes() - 4)
        );
        assert_eq!(p.range_offset(p.bytes() - 4, 5), None);
        assert_eq!(p.range_offset(u32::MAX, 1), None);
        assert_eq!(p.range_offset(p.bytes(), 0), Some(p.offset() + p.bytes()));
    }

    #[test]
    fn addresses_of_the_partitions() {
        assert_eq!(
            (BOOTLOADER.start(), BOOTLOADER.bytes()),
            (0x0800_0000, 32 * 1024)
        );
        assert_eq!(
            (CONFIG_STORE.start(), CONFIG_STORE.bytes()),
            (0x0800_8000, 32 * 1024)
        );
        assert_eq!(
            (BOOT_STATE.start(), BOOT_STATE.bytes()),
            (0x0801_0000, 64 * 1024)
        );
        assert_eq!((ACTIVE.start(), ACTIVE.bytes()), (0x0802_0000, 128 * 1024));
        assert_eq!((DFU.start(), DFU.bytes()), (0x0804_0000, 256 * 1024));
        assert_eq!(SWAP_PAGE_BYTES, 128 * 1024);
        assert_eq!(BOOT_STATE_WORDS, 6);
    }

    #[test]
    fn sectors_by_offset() {
        assert_eq!(CONFIG_STORE.sector_at(0), Some(2));
        assert_eq!(CONFIG_STORE.sector_at(16 * 1024 - 1), Some(2));
        assert_eq!(CONFIG_STORE.sector_at(16 * 1024), Some(3));
        assert_eq!(CONFIG_STORE.sector_at(32 * 1024), None);
        assert_eq!(DFU.sector_at(128 * 1024), Some(7));
        assert_eq!(BOOT_STATE.sector_at(0), Some(4));
        assert_eq!(sector_offset(8), FLASH_BYTES);
        assert_eq!(sector_bytes(8), 0);
        assert!(
            !Partition {
                first_sector: 3,
                sectors: 2
            }
            .uniform()
        );
    }
}
