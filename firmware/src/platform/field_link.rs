//! The link's numbers: baud rates, the divider the USART gets and the error
//! it leaves, the receiver's tolerance against the clock the node runs on,
//! and the field link's turn-taking on a two-wire RS-485 pair.
//!
//! The board has two link variants (cargo feature `field-link`,
//! `firmware/README.md`, "Wiring a field node"): the ST-LINK's virtual COM
//! port on USART2 (bench) and an RS-485/RS-422 transceiver on USART6 whose
//! driver enable a GPIO raises around each transmission. Both run 8N1 at
//! 16× oversampling from a 16 MHz peripheral clock.
//!
//! The rate is not a `Config` field: a wrong value set over the link would
//! cut the only link to a node on a tower. The bench link runs at
//! [`fois_protocol::BAUD_RATE`]; the field link at the same 115 200 Bd, or
//! at [`LONG_CABLE_BAUD`] when its strap pin is tied to GND at power-up.

/// The long-cable rate of the field link, Bd.
pub const LONG_CABLE_BAUD: u32 = 19_200;
/// The USARTs' kernel clock: PCLK1 (USART2) and PCLK2 (USART6) both run at
/// SYSCLK = 16 MHz, from the PLL on HSE or from HSI alike.
pub const USART_CLOCK_HZ: u32 = 16_000_000;
/// Bits on the wire per byte: start, 8 data, stop.
pub const BITS_PER_BYTE: u32 = 10;

/// The receiver's tolerance to the total clock deviation with 16×
/// oversampling, 3-sample majority (ONEBIT = 0), 8-bit words and a
/// fractional divider (RM0390 §25.4.5, "USART receiver tolerance to clock
/// deviation"), ppm: 3.33 %.
pub const RX_TOLERANCE_PPM: u32 = 33_300;
/// HSI after factory trim at 25 °C, ± ppm (STM32F446 datasheet, HSI
/// oscillator characteristics: ±1 %).
pub const HSI_25C_PPM: u32 = 10_000;
/// HSI over −40…105 °C, the larger side, ppm (datasheet: −8 % / +4.5 %).
pub const HSI_FULL_RANGE_PPM: u32 = 80_000;
/// An 8 MHz crystal or the ST-LINK's MCO (itself from a crystal), ± ppm
/// (a typical crystal's tolerance plus drift, with room).
pub const HSE_PPM: u32 = 100;
/// What the far end may contribute: a USB-RS-485 adapter's own baud error
/// (an FT232R at 115 200 Bd: +0.16 %) and the transceivers' asymmetry
/// (tens of ns on an 8.7 µs bit), ppm.
pub const FAR_END_AND_LINE_PPM: u32 = 3_000;

/// The BRR value for `baud` (USARTDIV × 16, rounded to nearest, as
/// embassy-stm32 computes it with 16× oversampling).
pub const fn brr(clock_hz: u32, baud: u32) -> u32 {
    (clock_hz + baud / 2) / baud
}

/// The rate the USART really runs at with that divider, Bd.
pub const fn actual_baud(clock_hz: u32, brr: u32) -> u32 {
    (clock_hz + brr / 2) / brr
}

/// The divider's error, ppm (signed: + is fast).
pub const fn quantisation_ppm(clock_hz: u32, baud: u32) -> i32 {
    let b = brr(clock_hz, baud) as i64;
    // actual/desired − 1 = clock / (brr · baud) − 1.
    let num = clock_hz as i64 * 1_000_000;
    let den = b * baud as i64;
    ((num + den / 2) / den - 1_000_000) as i32
}

/// The clock deviation left for the node's own oscillator at `baud`, ppm:
/// the tolerance minus the divider's error and the far end's share.
pub const fn clock_budget_ppm(baud: u32) -> i32 {
    RX_TOLERANCE_PPM as i32
        - quantisation_ppm(USART_CLOCK_HZ, baud).abs()
        - FAR_END_AND_LINE_PPM as i32
}

/// One byte on the wire, µs (rounded up).
pub const fn byte_time_us(baud: u32) -> u32 {
    (BITS_PER_BYTE * 1_000_000).div_ceil(baud)
}

/// Bytes of silence on the line before the node takes it (two-wire RS-485
/// is half duplex: a frame sent while the host talks destroys both).
pub const IDLE_BYTES_BEFORE_TX: u32 = 3;
/// How long the driver enable leads the first start bit, µs: the
/// transceiver's driver enable time (t_ZH, t_ZL ≤ 2.5 µs for the 3.3 V
/// parts the wiring table names) with room.
pub const DE_LEAD_US: u32 = 10;

/// The longest an answer waits for the line and the driver on the field
/// link, ms: the quiet bytes at the slowest rate and the DE lead, rounded
/// up (1.57 ms → 2 ms).
pub const TURNAROUND_MAX_MS: u32 =
    (IDLE_BYTES_BEFORE_TX * byte_time_us(LONG_CABLE_BAUD) + DE_LEAD_US).div_ceil(1_000);

/// May the node start transmitting now? `quiet_us`: time since the last
/// byte was received (`None`: nothing received yet).
pub const fn line_free(quiet_us: Option<u32>, baud: u32) -> bool {
    match quiet_us {
        None => true,
        Some(q) => q >= IDLE_BYTES_BEFORE_TX * byte_time_us(baud),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dividers_and_their_error_at_16_mhz() {
        // RM0390's own table (fPCLK = 16 MHz, 16× oversampling): 115.2 kBd
        // → 8.6875 (BRR 139): 115 108 Bd, −0.08 %; 19.2 kBd → 52.0625
        // (BRR 833): 19 208 Bd, +0.04 %.
        assert_eq!(brr(USART_CLOCK_HZ, 115_200), 139);
        assert_eq!(actual_baud(USART_CLOCK_HZ, 139), 115_108);
        assert_eq!(quantisation_ppm(USART_CLOCK_HZ, 115_200), -799);
        assert_eq!(brr(USART_CLOCK_HZ, LONG_CABLE_BAUD), 833);
        assert_eq!(actual_baud(USART_CLOCK_HZ, 833), 19_208);
        assert_eq!(quantisation_ppm(USART_CLOCK_HZ, LONG_CABLE_BAUD), 400);
        assert_eq!(fois_protocol::BAUD_RATE, 115_200);
    }

    #[test]
    fn the_clock_budget_holds_on_hse_and_hsi_at_room_temperature_only() {
        for baud in [fois_protocol::BAUD_RATE, LONG_CABLE_BAUD] {
            let budget = clock_budget_ppm(baud);
            // 3.33 % − 0.08 % (or 0.04 %) − 0.3 % ≈ 2.95 %.
            assert!((29_000..=30_000).contains(&budget), "{baud}: {budget}");
            assert!(HSE_PPM as i32 <= budget);
            assert!(HSI_25C_PPM as i32 <= budget);
            // Over the full temperature range the HSI alone can take 8 %.
            assert!(HSI_FULL_RANGE_PPM as i32 > budget);
        }
    }

    #[test]
    fn the_node_waits_for_a_quiet_line() {
        // 115 200 Bd: 87 µs a byte, three of them = 261 µs.
        assert_eq!(byte_time_us(115_200), 87);
        assert!(line_free(None, 115_200));
        assert!(!line_free(Some(260), 115_200));
        assert!(line_free(Some(261), 115_200));
        // 19 200 Bd: 521 µs a byte, 1.56 ms.
        assert_eq!(byte_time_us(LONG_CABLE_BAUD), 521);
        assert!(!line_free(Some(1_500), LONG_CABLE_BAUD));
        assert!(line_free(Some(1_563), LONG_CABLE_BAUD));
        assert_eq!(TURNAROUND_MAX_MS, 2);
    }
}
