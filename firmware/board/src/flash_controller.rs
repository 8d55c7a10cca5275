//! The F446's flash controller, register by register (RM0390 §3.5–§3.8):
//! the steps that both the application (`board.rs`, `slots.rs`) and the
//! bootloader (`boot/src/flash.rs`, which includes this file by its path,
//! as it does the flash layout) take to erase a sector or program the
//! flash through the PAC. What differs between the two stays with them:
//! the parallelism (the application knows V_DDA, the bootloader does not),
//! the watchdog, the caches.

use embassy_stm32::pac;
use embassy_stm32::pac::flash::vals::Psize;

/// An error the controller reported in SR after an operation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerError {
    /// PGSERR: the programming sequence was wrong.
    Sequence,
    /// PGPERR: the data's width did not match PSIZE.
    Parallelism,
    /// PGAERR: the data was not aligned to PSIZE.
    Alignment,
    /// WRPERR: the address is write-protected.
    Protected,
    /// OPERR: the operation failed (the part signals it only with ERRIE).
    Operation,
}

/// Wait until the controller is idle, unlock its CR (the two keys) and
/// clear the error flags an earlier operation left (write 1 to clear).
pub fn unlock() {
    let flash = pac::FLASH;
    while flash.sr().read().bsy() {}
    if flash.cr().read().lock() {
        flash.keyr().write_value(0x4567_0123);
        flash.keyr().write_value(0xCDEF_89AB);
    }
    flash.sr().write(|w| {
        w.set_eop(true);
        w.set_operr(true);
        w.set_wrperr(true);
        w.set_pgaerr(true);
        w.set_pgperr(true);
        w.set_pgserr(true);
    });
}

/// Start erasing sector `snb` at parallelism `psize` (after [`unlock`]).
/// The CPU stalls on its next fetch from the flash until the erase ends
/// (one bank).
pub fn start_sector_erase(snb: u8, psize: Psize) {
    let flash = pac::FLASH;
    flash.cr().write(|w| {
        w.set_ser(true);
        w.set_snb(snb);
        w.set_psize(psize);
    });
    flash.cr().modify(|w| w.set_strt(true));
}

/// Set the controller to program at parallelism `psize` (after
/// [`unlock`]); then each write to the flash's address space programs it.
pub fn start_programming(psize: Psize) {
    pac::FLASH.cr().write(|w| {
        w.set_pg(true);
        w.set_psize(psize);
    });
}

/// Wait until the controller is idle and say what it reported.
pub fn wait_idle() -> Result<(), ControllerError> {
    let flash = pac::FLASH;
    while flash.sr().read().bsy() {}
    let sr = flash.sr().read();
    if sr.pgserr() {
        Err(ControllerError::Sequence)
    } else if sr.pgperr() {
        Err(ControllerError::Parallelism)
    } else if sr.pgaerr() {
        Err(ControllerError::Alignment)
    } else if sr.wrperr() {
        Err(ControllerError::Protected)
    } else if sr.operr() {
        Err(ControllerError::Operation)
    } else {
        Ok(())
    }
}

/// Wait for the controller, leave erase or programming mode (SER, PG,
/// STRT cleared) and lock it; what it reported.
pub fn finish() -> Result<(), ControllerError> {
    let reported = wait_idle();
    pac::FLASH.cr().write(|w| w.set_lock(true));
    reported
}
