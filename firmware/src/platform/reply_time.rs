//! How long the node may take to answer a command, worst case: the figure
//! behind the host's command timeout (`fois_protocol::REPLY_TIMEOUT_MS`).
//!
//! On the board the node sits in one mutex. A command whose last byte
//! arrives just as the measure loop takes it waits for
//! - the longest frame the config rule allows ([`LONGEST_FRAME_MS`]),
//! - a save that comes due after that frame and must erase a 128 KiB
//!   sector first (x16 worst case, [`ERASE_128K_X16_MAX_MS`]: the board
//!   erases at x32 from the first frame on at V_DDA ≥ 2.7 V, x16 below),
//!   plus the item's programming and read-back ([`SAVE_PROGRAM_MAX_MS`]).
//!
//! Then it runs itself: a dark calibration averages for at most
//! [`CAL_MAX_MS`] before its `Ack` (any other command answers at once),
//! which then queues behind at most a full transmit pipe drained at the
//! slowest link rate ([`TX_QUEUE_MAX_MS`]), and on the field link waits for
//! a quiet line and the driver enable ([`TURNAROUND_MAX_MS`]). (The save a command causes is
//! deferred and coalesced: it never delays the command's own answer.)
//!
//! A commanded `Reset` waits until its `Ack` has left: the board resets
//! once the transmit pipe and the UART's buffer are empty and the USART
//! reported transmission complete, or after [`drain_ms`] of everything
//! that can be queued at the link's rate ([`RESET_DRAIN_BYTES`]) as a
//! bound — not after a fixed time, which at 19 200 Bd could cut the `Ack`.

use crate::calibration::dark::CAL_MAX_MS;
use crate::platform::field_link::TURNAROUND_MAX_MS;
use crate::platform::watchdog::{ERASE_128K_X16_MAX_MS, LONGEST_FRAME_MS};

/// Programming one record item and reading it back, ms (a ~50-byte item
/// at ≤ 100 µs per 32-bit word, RM0390 t_PROG, with room).
pub const SAVE_PROGRAM_MAX_MS: u32 = 50;
/// The board's transmit pipe, bytes.
pub const TX_PIPE_BYTES: u32 = 1_024;
/// The slowest link rate the board offers, Bd (the field link's long-cable
/// rate).
pub const SLOWEST_BAUD: u32 = crate::platform::field_link::LONG_CABLE_BAUD;
/// The transmit pipe drained at [`SLOWEST_BAUD`], 10 bits a byte, ms
/// (rounded up: 534 ms; 89 ms at 115 200 Bd).
pub const TX_QUEUE_MAX_MS: u32 = (TX_PIPE_BYTES * 10 * 1_000).div_ceil(SLOWEST_BAUD);
/// The UART driver's own transmit buffer on the board, bytes.
pub const UART_TX_BUFFER_BYTES: u32 = 512;
/// Everything that can wait for the wire when a `Reset` is acknowledged:
/// the pipe and the UART's buffer, bytes.
pub const RESET_DRAIN_BYTES: u32 = TX_PIPE_BYTES + UART_TX_BUFFER_BYTES;
/// Added to a drain time for the turnaround and the scheduling, ms.
pub const DRAIN_MARGIN_MS: u32 = 50;

/// How long `bytes` take to leave at `baud` (10 bits a byte, rounded up),
/// plus the field link's turnaround and [`DRAIN_MARGIN_MS`], ms.
pub const fn drain_ms(bytes: u32, baud: u32) -> u32 {
    let wire = (bytes as u64 * 10 * 1_000).div_ceil(if baud == 0 { 1 } else { baud as u64 });
    wire as u32 + TURNAROUND_MAX_MS + DRAIN_MARGIN_MS
}

/// The worst time from a command's last byte to the first byte of its
/// answer, ms (5 829 ms).
pub const WORST_REPLY_MS: u32 = LONGEST_FRAME_MS
    + ERASE_128K_X16_MAX_MS
    + SAVE_PROGRAM_MAX_MS
    + CAL_MAX_MS
    + TX_QUEUE_MAX_MS
    + TURNAROUND_MAX_MS;

// The host waits longer than the node can take, with 2 s for the host's own
// latency (USB-serial, scheduling).
const _: () = assert!(WORST_REPLY_MS as u64 + 2_000 <= fois_protocol::REPLY_TIMEOUT_MS);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_worst_reply_and_the_host_timeout() {
        assert_eq!(TX_QUEUE_MAX_MS, 534);
        assert_eq!(WORST_REPLY_MS, 643 + 2_600 + 50 + 2_000 + 534 + 2);
        // 5.829 s: longer than the host's former 3 s timeout, 2.17 s inside
        // the 8 s it waits now.
        assert_eq!(WORST_REPLY_MS, 5_829);
        assert_eq!(fois_protocol::REPLY_TIMEOUT_MS, 8_000);
    }

    #[test]
    fn a_commanded_reset_waits_for_everything_queued_to_leave() {
        // A full pipe and UART buffer at 19 200 Bd take 800 ms: the former
        // fixed 600 ms wait cut them.
        assert_eq!(RESET_DRAIN_BYTES, 1_536);
        assert_eq!(drain_ms(RESET_DRAIN_BYTES, 19_200), 800 + 2 + 50);
        assert!(drain_ms(RESET_DRAIN_BYTES, 19_200) > 600);
        // 134 ms at 115 200 Bd; one 20-byte Ack alone: 11 + 52 ms.
        assert_eq!(drain_ms(RESET_DRAIN_BYTES, 115_200), 134 + 52);
        assert_eq!(drain_ms(20, 19_200), 11 + 52);
        assert_eq!(drain_ms(20, 0), 200_000 + 52, "no division by zero");
        // Well inside the watchdog's shortest timeout.
        assert!(
            drain_ms(RESET_DRAIN_BYTES, 19_200) < crate::platform::watchdog::SHORTEST_TIMEOUT_MS
        );
    }

    #[test]
    fn on_a_failed_over_clock_the_worst_reply_still_fits() {
        // After the clock security system switched to HSI the node's
        // milliseconds are HSI's: at its slowest (−8 % over −40…105 °C,
        // field_link::HSI_FULL_RANGE_PPM) the worst case takes 5 829 / 0.92
        // = 6 336 ms of the host's time, 1.66 s inside its timeout.
        let slow = 1.0 - f64::from(crate::platform::field_link::HSI_FULL_RANGE_PPM) * 1e-6;
        let real_ms = f64::from(WORST_REPLY_MS) / slow;
        assert!((6_335.0..6_337.0).contains(&real_ms), "{real_ms}");
        assert!(real_ms + 1_500.0 < fois_protocol::REPLY_TIMEOUT_MS as f64);
    }
}
