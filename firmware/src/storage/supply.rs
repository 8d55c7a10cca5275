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

/// The lowest V_DDA at which the node starts a flash write, mV.
pub const FLASH_WRITE_MIN_VDDA_MV: u16 = 2_700;

/// May a flash write start now? `vdda_mv`: V_DDA just measured; `pvd_low`:
/// the PVD reports V_DD below its threshold.
pub fn flash_write_allowed(vdda_mv: u16, pvd_low: bool) -> bool {
    // A VREFINT code of 0 reads as u16::MAX mV: out of range, not healthy.
    !pvd_low && vdda_mv >= FLASH_WRITE_MIN_VDDA_MV && crate::measure::vref::vdda_in_range(vdda_mv)
}

#[cfg(test)]
mod tests {
    use super::*;

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
