//! The bootloader's swap (embassy-boot's `prepare_boot`, the code
//! `boot/` runs on the board) on RAM flashes of the board's geometry: the
//! active slot one 128 KiB page, the DFU slot two, the state one 64 KiB
//! sector, programmed in 4-byte words (`RamFlash`), with the bootloader's
//! copy buffer of 2 KiB. An update is asked for (the state's swap magic, as
//! the application's updater writes it), the swap runs, the new image is in
//! the active slot and the old one in the DFU slot; not marked booted, the
//! next `prepare_boot` rolls back. The SysTick ticks of the swap and of the
//! rollback are kept for `main`, which turns them into instructions.

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m_semihosting::hprintln;

use embassy_boot::{AlignedBuffer, BlockingFirmwareState, BootLoader, BootLoaderConfig, State};
use embedded_storage::nor_flash::NorFlash;
use fois_firmware::storage::ram_flash::RamFlash;

use crate::{TestResult, ticks};

const PAGE: usize = 128 * 1024;
const STATE: usize = 64 * 1024;
/// The bootloader's copy buffer (`boot/src/main.rs`, `COPY_CHUNK`).
const CHUNK: usize = 2048;

/// SysTick ticks of the swap (one 128 KiB page) and of the rollback.
pub static SWAP_TICKS: AtomicU32 = AtomicU32::new(0);
/// See [`SWAP_TICKS`].
pub static REVERT_TICKS: AtomicU32 = AtomicU32::new(0);

static mut MEM: [u8; 3 * PAGE + STATE] = [0; 3 * PAGE + STATE];

/// The byte of image `tag` at `i`.
fn image_byte(tag: u8, i: usize) -> u8 {
    (i as u8).wrapping_mul(31) ^ tag
}

pub fn t_bootloader_swap_and_rollback() -> TestResult {
    // SAFETY: the only reference to MEM, taken once in this test.
    let mem: &'static mut [u8; 3 * PAGE + STATE] = unsafe { &mut *core::ptr::addr_of_mut!(MEM) };
    let (active_mem, rest) = mem.split_at_mut(PAGE);
    let (dfu_mem, state_mem) = rest.split_at_mut(2 * PAGE);
    let mut active: RamFlash<&mut [u8], PAGE, 1> = RamFlash::new(active_mem);
    let mut dfu: RamFlash<&mut [u8], PAGE, 2> = RamFlash::new(dfu_mem);
    let mut state: RamFlash<&mut [u8], STATE, 1> = RamFlash::new(state_mem);
    check!(active.erase(0, PAGE as u32).is_ok(), "    erase active");
    check!(dfu.erase(0, 2 * PAGE as u32).is_ok(), "    erase dfu");
    check!(state.erase(0, STATE as u32).is_ok(), "    erase state");
    // The running image (tag 0xA1) and a downloaded one (tag 0x5E).
    for (i, b) in active.bytes_mut().iter_mut().enumerate() {
        *b = image_byte(0xA1, i);
    }
    for (i, b) in dfu.bytes_mut().iter_mut().take(PAGE).enumerate() {
        *b = image_byte(0x5E, i);
    }
    // The application asks for the swap (embassy-boot's updater does this).
    let mut word = [0u8; 4];
    check!(
        BlockingFirmwareState::new(&mut state, &mut word)
            .mark_updated()
            .is_ok(),
        "    mark updated"
    );
    let mut buf = AlignedBuffer([0u8; CHUNK]);
    let t0 = ticks();
    let swapped = BootLoader::new(BootLoaderConfig {
        active: &mut active,
        dfu: &mut dfu,
        state: &mut state,
    })
    .prepare_boot(&mut buf.0);
    SWAP_TICKS.store(
        u32::try_from(ticks() - t0).unwrap_or(u32::MAX),
        Ordering::Relaxed,
    );
    check!(swapped == Ok(State::Swap), "    swap: {:?}", swapped);
    let new_in = active
        .bytes()
        .iter()
        .enumerate()
        .all(|(i, &b)| b == image_byte(0x5E, i));
    check!(new_in, "    the new image is active");
    let old_kept = dfu
        .bytes()
        .iter()
        .skip(PAGE)
        .enumerate()
        .all(|(i, &b)| b == image_byte(0xA1, i));
    check!(
        old_kept,
        "    the old image is in the DFU slot's second page"
    );
    // Not marked booted: the next reset rolls back.
    let t0 = ticks();
    let reverted = BootLoader::new(BootLoaderConfig {
        active: &mut active,
        dfu: &mut dfu,
        state: &mut state,
    })
    .prepare_boot(&mut buf.0);
    REVERT_TICKS.store(
        u32::try_from(ticks() - t0).unwrap_or(u32::MAX),
        Ordering::Relaxed,
    );
    check!(reverted == Ok(State::Swap), "    rollback: {:?}", reverted);
    let old_back = active
        .bytes()
        .iter()
        .enumerate()
        .all(|(i, &b)| b == image_byte(0xA1, i));
    check!(old_back, "    the old image is active again");
    // And the state says so (the application reports the rollback).
    let again = BootLoader::new(BootLoaderConfig {
        active: &mut active,
        dfu: &mut dfu,
        state: &mut state,
    })
    .prepare_boot(&mut buf.0);
    check!(
        again == Ok(State::Revert),
        "    after the rollback: {:?}",
        again
    );
    Ok(())
}
