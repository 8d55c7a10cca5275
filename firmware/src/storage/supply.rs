//! Flash writes wait for a healthy supply. The F446 erases and programs at
//! x32 parallelism only from 2.7 V (RM0390 §3.5, program/erase
//! parallelism; the board programs at x32 always), and a write that a
//! sagging supply cuts short is the one a power-loss-safe store can still
//! survive but should not have to: so a save starts only when the last
//! V_DDA (measured through VREFINT just before) is at least
//! [`FLASH_WRITE_MIN_VDDA_MV`] (and plausible: at most 3.6 V) and the programmable voltage detector does
//! not report V_DD below its threshold (PWR_CSR.PVDO, RM0390 §5.2.3: the
//! board sets it to 2.8 V). Otherwise the save is postponed, not failed: it
//! runs at the first poll after the supply has recovered.

//!
//! The boot's read of the store is gated the same way ([`boot_read`]):
//! sequential-storage repairs an interrupted operation while reading, by
//! erasing, and a boot typically follows the power cut that interrupted
//! it. The board waits up to [`BOOT_SUPPLY_WAIT_MAX_MS`] for the supply,
//! then boots with the read deferred (`STORE_SKIPPED`, the defaults, the
//! record left as it is: `platform::boot::StoreRead::Defer`) and resets to
//! read it once the supply has been healthy for a while.

/// The lowest V_DDA at which the node starts a flash write, mV.
pub const FLASH_WRITE_MIN_VDDA_MV: u16 = 2_700;

/// May a flash write start now? `vdda_mv`: V_DDA just measured; `pvd_low`:
/// the PVD reports V_DD below its threshold.
pub fn flash_write_allowed(vdda_mv: u16, pvd_low: bool) -> bool {
    // A VREFINT code of 0 reads as u16::MAX mV: out of range, not healthy.
    !pvd_low && vdda_mv >= FLASH_WRITE_MIN_VDDA_MV && crate::measure::vref::vdda_in_range(vdda_mv)
}

/// How long the boot waits for a healthy supply before it skips the
/// store's read, ms (the watchdog is fed while it waits).
pub const BOOT_SUPPLY_WAIT_MAX_MS: u32 = 10_000;
/// The boot's wait step between two looks at the supply, ms.
pub const BOOT_SUPPLY_STEP_MS: u32 = 100;

/// What the boot does about the store's read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BootRead {
    /// The supply is healthy: read (and let sequential-storage repair).
    Read,
    /// Not yet: look again after [`BOOT_SUPPLY_STEP_MS`].
    Wait,
    /// The supply stayed low for [`BOOT_SUPPLY_WAIT_MAX_MS`]: boot with the
    /// read deferred.
    Skip,
}

/// The boot's read of the store: `vdda_mv` just measured, `pvd_low` from
/// the PVD, `waited_ms` since the boot began to wait.
pub fn boot_read(vdda_mv: u16, pvd_low: bool, waited_ms: u32) -> BootRead {
    if flash_write_allowed(vdda_mv, pvd_low) {
        BootRead::Read
    } else if waited_ms < BOOT_SUPPLY_WAIT_MAX_MS {
        BootRead::Wait
    } else {
        BootRead::Skip
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_boot_reads_the_store_only_on_a_healthy_supply() {
        assert_eq!(boot_read(3_300, false, 0), BootRead::Read);
        // Right after the power cut: 2.5 V, the PVD low.
        assert_eq!(boot_read(2_500, true, 0), BootRead::Wait);
        assert_eq!(boot_read(2_500, false, 9_900), BootRead::Wait);
        assert_eq!(boot_read(3_300, true, 5_000), BootRead::Wait);
        // Recovered within the wait: read.
        assert_eq!(boot_read(3_000, false, 5_000), BootRead::Read);
        // Still low after 10 s: skip (no erase on a sagging supply).
        assert_eq!(boot_read(2_500, false, 10_000), BootRead::Skip);
        assert_eq!(boot_read(0, false, 10_000), BootRead::Skip);
    }

    #[test]
    fn writes_wait_for_a_measured_healthy_supply() {
        assert!(flash_write_allowed(3_300, false));
        assert!(flash_write_allowed(2_700, false));
        assert!(!flash_write_allowed(2_699, false));
        assert!(!flash_write_allowed(3_300, true));
        // A VREFINT reading of 0 gives u16::MAX mV (out of range): the old
        // brown-out check let that pass.
        let broken = crate::measure::vref::vdda_mv(&crate::hal::FactoryCal::TYPICAL, 0);
        assert!(!flash_write_allowed(broken, false));
        assert!(!flash_write_allowed(3_601, false));
        assert!(!flash_write_allowed(0, false));
    }
}
