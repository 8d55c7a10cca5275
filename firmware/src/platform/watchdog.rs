//! The independent watchdog's timing on the STM32F446, as numbers the board
//! binary programs and the tests check: the shortest real timeout must
//! outlast the longest time the node can go without feeding it.
//!
//! The IWDG counts the LSI oscillator, which the F446 datasheet gives as
//! 17–47 kHz (32 kHz typical) over voltage and temperature. A timeout picked
//! at the nominal 32 kHz is 32/47 = 68 % of itself on a fast chip, so the
//! prescaler and reload are chosen for the fastest LSI.
//!
//! The longest stall: with one flash bank the CPU stops while a sector is
//! erased (instruction fetches wait). The datasheet's 128 KiB sector erase
//! time t_ERASE128KB is 1 s typ / 2 s max at x32 parallelism, 1.3 / 2.6 s at
//! x16 and 2 / 4 s at x8 (embassy-stm32 0.6 erases at x8; the board erases
//! at x32, or x16 when V_DDA is below 2.7 V). The board feeds the watchdog
//! only in its measure loop, and there only while the schedule shows
//! progress (`Schedule::on_track`), right before and after each erase, and
//! in the boot's bounded wait for a healthy supply (a hung loop must not be
//! kept alive by anything else). Between two feeds the loop sleeps, may try
//! the HSE again (`clock_retry::RETRY_COST_MAX_MS`), may wait for the node
//! behind one command from the link and one button press (the link task
//! yields after each host frame and wakes the loop), each at most a dark
//! calibration, then runs a frame and the save work before an erase.

use crate::calibration::dark::CAL_MAX_MS;
use crate::platform::clock_retry::RETRY_COST_MAX_MS;

/// Slowest LSI, Hz (F446 datasheet, LSI oscillator characteristics).
pub const LSI_MIN_HZ: u32 = 17_000;
/// Typical LSI, Hz.
pub const LSI_TYP_HZ: u32 = 32_000;
/// Fastest LSI, Hz.
pub const LSI_MAX_HZ: u32 = 47_000;

/// IWDG_PR value: divide by 4 × 2^PR = 128.
pub const IWDG_PR: u8 = 5;
/// The LSI divider that [`IWDG_PR`] selects.
pub const IWDG_DIVIDER: u32 = 4 << IWDG_PR;
/// IWDG_RLR value (12 bit): the counter runs RLR + 1 ticks.
pub const IWDG_RELOAD: u16 = 2_999;

/// Worst-case 128 KiB sector erase at x32 parallelism, ms (t_ERASE128KB max).
pub const ERASE_128K_X32_MAX_MS: u32 = 2_000;
/// ... at x16 (V_DDA below 2.7 V), ms.
pub const ERASE_128K_X16_MAX_MS: u32 = 2_600;
/// ... at x8 (what embassy-stm32 0.6 would do), ms.
pub const ERASE_128K_X8_MAX_MS: u32 = 4_000;
/// Worst-case 16 KiB sector erase at x32 (t_ERASE16KB max; the config
/// store's sectors 2 and 3), ms.
pub const ERASE_16K_X32_MAX_MS: u32 = 500;
/// ... at x16, ms.
pub const ERASE_16K_X16_MAX_MS: u32 = 600;
/// Worst-case 64 KiB sector erase at x32 (t_ERASE64KB max; the boot
/// state's sector 4), ms.
pub const ERASE_64K_X32_MAX_MS: u32 = 1_100;
/// ... at x16, ms.
pub const ERASE_64K_X16_MAX_MS: u32 = 1_400;
/// The measure loop's longest sleep between feeds, ms.
pub const MAX_SLEEP_MS: u32 = 500;
/// The longest frame the config rule allows: K = 64 cycles × 2 × 5 ms
/// settle, plus 2 × 65 photo conversions and four others of ≤ 20 µs, ms.
pub const LONGEST_FRAME_MS: u32 = 643;
/// A save's programming and read-back around its erase, ms.
pub const SAVE_WORK_MS: u32 = 50;
/// The most the node can go without a feed, ms: a sleep, an HSE retry,
/// two dark calibrations (a command's and the button's) and a frame with
/// the save work before an erase; or an erase (fed just before, at the
/// worst parallelism the board may use, x16) and the programming after it.
pub const WORST_UNFED_MS: u32 = max(
    MAX_SLEEP_MS + RETRY_COST_MAX_MS as u32 + 2 * CAL_MAX_MS + LONGEST_FRAME_MS + SAVE_WORK_MS,
    ERASE_128K_X16_MAX_MS + SAVE_WORK_MS,
);

const fn max(a: u32, b: u32) -> u32 {
    if a > b { a } else { b }
}

/// The timeout at this LSI frequency, ms (rounded down).
pub const fn timeout_ms(lsi_hz: u32) -> u32 {
    ((IWDG_RELOAD as u64 + 1) * IWDG_DIVIDER as u64 * 1_000 / lsi_hz as u64) as u32
}

/// The shortest real timeout (fastest LSI), ms.
pub const SHORTEST_TIMEOUT_MS: u32 = timeout_ms(LSI_MAX_HZ);
/// The longest real timeout (slowest LSI): how long a hung node may take to
/// reset, ms.
pub const LONGEST_TIMEOUT_MS: u32 = timeout_ms(LSI_MIN_HZ);

const _: () = assert!(IWDG_PR <= 6 && IWDG_RELOAD <= 0x0FFF);
const _: () = assert!(SHORTEST_TIMEOUT_MS >= 8_000);
const _: () = assert!(SHORTEST_TIMEOUT_MS > WORST_UNFED_MS);
// Even an x8 erase (4 s, what embassy-stm32 would do) would not fire it.
const _: () = assert!(ERASE_128K_X8_MAX_MS + SAVE_WORK_MS < SHORTEST_TIMEOUT_MS);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timeouts_over_the_lsi_spread() {
        assert_eq!(IWDG_DIVIDER, 128);
        // 3 000 ticks of 128 LSI periods.
        assert_eq!(SHORTEST_TIMEOUT_MS, 8_170);
        assert_eq!(timeout_ms(LSI_TYP_HZ), 12_000);
        assert_eq!(LONGEST_TIMEOUT_MS, 22_588);
        // 0.5 s + 0.21 s + 2 × 2 s + 0.643 s + 0.05 s.
        assert_eq!(WORST_UNFED_MS, 5_403);
    }
}
