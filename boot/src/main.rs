//! The bootloader of the FOIS node (NUCLEO-F446RE): embassy-boot in sectors
//! 0–1. At every reset it reads embassy-boot's state (sector 4): after an
//! update was committed it swaps the DFU slot (sectors 6–7) into the active
//! slot (sector 5), keeping the old image in the DFU slot; if the image it
//! swapped in was not marked good by the next reset, it swaps the old one
//! back (rollback). Every step is power-fail safe: the progress is kept in
//! the state sector and a reset resumes it. Then it jumps to the active
//! slot (`firmware/board/memory.x`).
//!
//! HardFault and panic reset the chip (a retry: a swap resumes where it
//! stopped); a flash error in the swap does too. The independent watchdog
//! runs from here on (`flash.rs`). No log unless built with `defmt`.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
#[allow(dead_code)] // the shared layout names more than the bootloader uses
#[path = "../../firmware/src/platform/flash_layout.rs"]
mod flash_layout;

#[cfg(target_os = "none")]
#[path = "../../firmware/board/src/flash_controller.rs"]
mod flash_controller;

#[cfg(target_os = "none")]
mod flash;

#[cfg(target_os = "none")]
mod app {
    use cortex_m_rt::{ExceptionFrame, entry, exception};
    #[cfg(feature = "defmt")]
    use defmt_rtt as _;
    use embassy_boot_stm32::{BootLoader, BootLoaderConfig};
    // The chip's interrupt vectors (cortex-m-rt's `device` table).
    use embassy_stm32 as _;

    use crate::flash::{PartitionFlash, watchdog_start};
    use crate::flash_layout::{ACTIVE, BOOT_STATE, DFU, SWAP_PAGE_BYTES};

    /// The swap's copy buffer: a whole number of chunks per 128 KiB page.
    const COPY_CHUNK: usize = 2048;
    const _: () = assert!((SWAP_PAGE_BYTES as usize).is_multiple_of(COPY_CHUNK));

    const ACTIVE_SECTOR: usize = ACTIVE.largest_sector_bytes() as usize;
    const DFU_SECTOR: usize = DFU.largest_sector_bytes() as usize;
    const STATE_SECTOR: usize = BOOT_STATE.largest_sector_bytes() as usize;

    #[entry]
    fn main() -> ! {
        watchdog_start();
        let config = BootLoaderConfig {
            active: PartitionFlash::<ACTIVE_SECTOR>::new(ACTIVE),
            dfu: PartitionFlash::<DFU_SECTOR>::new(DFU),
            state: PartitionFlash::<STATE_SECTOR>::new(BOOT_STATE),
        };
        match BootLoader::try_prepare::<_, _, _, COPY_CHUNK>(config) {
            // SAFETY: the active slot holds an image linked for its address
            // (firmware/memory.x); `load` sets VTOR, the stack pointer and
            // jumps to its reset vector.
            Ok(loader) => unsafe { loader.load(ACTIVE.start()) },
            // A flash error mid-swap: reset and resume from the progress
            // kept in the state sector.
            Err(_) => cortex_m::peripheral::SCB::sys_reset(),
        }
    }

    #[exception]
    unsafe fn HardFault(_frame: &ExceptionFrame) -> ! {
        cortex_m::peripheral::SCB::sys_reset()
    }

    #[panic_handler]
    fn panic(_info: &core::panic::PanicInfo) -> ! {
        cortex_m::peripheral::SCB::sys_reset()
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "fois-boot is the board's bootloader: build it with `cargo boot` (thumbv7em-none-eabihf)"
    );
}
