//! The host link, one of two variants chosen at build time:
//!
//! - bench (default): the ST-LINK's virtual COM port on USART2, PA2 (TX) /
//!   PA3 (RX), 115 200 Bd 8N1;
//! - field (cargo feature `field-link`): an RS-485/RS-422 transceiver on
//!   USART6, PC6 (TX → DI) / PC7 (RX ← RO, pulled up: the receiver's output
//!   floats while DE/RE̅ is high), DE and RE̅ together on PA8, and the baud
//!   strap on PC8: open (internal pull-up) = 115 200 Bd, tied to GND at
//!   power-up = 19 200 Bd for long cables. The F446's USART has no hardware
//!   driver enable (embassy-stm32 0.6 has `new_with_de` only for newer USART
//!   versions), so the transmit task raises PA8 before a burst and drops it
//!   once the USART reports transmission complete (TC).
//!
//! Either speaks the framed protocol (8N1) or, when the node's link
//! settings say so, Modbus RTU with their parity (8E1, 8N2, 8N1): a byte
//! wakes the receive task at once (`eager_reads`), so the RTU task's
//! silence timing sees each byte's arrival.
//!
//! The rate is never a `Config` field: a wrong value sent over the link
//! would cut the only link to a node on a tower (`fois_firmware::platform::field_link`
//! states each rate's error against the node's clock).

use embassy_stm32::gpio::Output;
use embassy_stm32::usart::{self, BufferedUart, BufferedUartRx, BufferedUartTx};
use embassy_stm32::{Peri, bind_interrupts, peripherals};

/// The link's halves, its driver-enable pin (field link only) and its rate.
pub struct Link {
    /// Transmit half.
    pub tx: BufferedUartTx<'static>,
    /// Receive half.
    pub rx: BufferedUartRx<'static>,
    /// DE and RE̅ of the transceiver (high: driving, receiver off).
    pub de: Option<Output<'static>>,
    /// The rate in use, Bd.
    pub baud: u32,
}

/// The buffers of the link: 512 B out (the 1 KiB pipe in front feeds it),
/// 256 B in.
fn buffers() -> (&'static mut [u8; 512], &'static mut [u8; 256]) {
    let tx = cortex_m::singleton!(: [u8; 512] = [0; 512]);
    let rx = cortex_m::singleton!(: [u8; 256] = [0; 256]);
    match (tx, rx) {
        (Some(tx), Some(rx)) => (tx, rx),
        _ => defmt::panic!("link buffers taken twice"),
    }
}

#[cfg(not(feature = "field-link"))]
bind_interrupts!(struct Irqs {
    USART2 => usart::BufferedInterruptHandler<peripherals::USART2>;
});

/// The UART's settings: the rate, and Modbus RTU's parity and stop bits
/// (`None`: the framed protocol's 8N1).
fn uart_config(baud: u32, modbus: Option<fois_protocol::Parity>) -> usart::Config {
    use embassy_stm32::usart::{DataBits, Parity, StopBits};
    let mut config = usart::Config::default();
    config.baudrate = baud;
    config.data_bits = DataBits::DataBits8;
    if let Some(p) = modbus {
        // 8 data bits + parity: embassy sets the 9-bit word with PCE.
        let (parity, stop) = match p {
            fois_protocol::Parity::Even8E1 => (Parity::ParityEven, StopBits::STOP1),
            fois_protocol::Parity::None8N2 => (Parity::ParityNone, StopBits::STOP2),
            fois_protocol::Parity::None8N1 => (Parity::ParityNone, StopBits::STOP1),
        };
        config.parity = parity;
        config.stop_bits = stop;
        config.eager_reads = Some(1);
    }
    config
}

/// The bench link: USART2 to the ST-LINK's virtual COM port.
#[cfg(not(feature = "field-link"))]
pub fn bench(
    usart: Peri<'static, peripherals::USART2>,
    rx: Peri<'static, peripherals::PA3>,
    tx: Peri<'static, peripherals::PA2>,
    modbus: Option<fois_protocol::Parity>,
) -> Link {
    let config = uart_config(fois_protocol::BAUD_RATE, modbus);
    let (tx_buf, rx_buf) = buffers();
    let uart = match BufferedUart::new(usart, rx, tx, tx_buf, rx_buf, Irqs, config) {
        Ok(u) => u,
        Err(e) => defmt::panic!("USART2 config: {}", e),
    };
    let (tx, rx) = uart.split();
    Link {
        tx,
        rx,
        de: None,
        baud: fois_protocol::BAUD_RATE,
    }
}

#[cfg(feature = "field-link")]
bind_interrupts!(struct Irqs {
    USART6 => usart::BufferedInterruptHandler<peripherals::USART6>;
});

/// The field link: USART6 to an RS-485/RS-422 transceiver, DE on PA8, the
/// rate from the strap on PC8 (read once, at boot).
#[cfg(feature = "field-link")]
pub fn field(
    usart: Peri<'static, peripherals::USART6>,
    rx: Peri<'static, peripherals::PC7>,
    tx: Peri<'static, peripherals::PC6>,
    de: Peri<'static, peripherals::PA8>,
    strap: Peri<'static, peripherals::PC8>,
    modbus: Option<fois_protocol::Parity>,
) -> Link {
    use embassy_stm32::gpio::{Input, Level, Pull, Speed};
    use fois_firmware::platform::field_link::LONG_CABLE_BAUD;

    // DE low first: the transceiver listens while the USART is set up.
    let de = Output::new(de, Level::Low, Speed::Low);
    let baud = {
        let strap = Input::new(strap, Pull::Up);
        // The pull-up (≈ 40 kΩ) charges the pin's few pF in well under 1 µs.
        embassy_time::block_for(embassy_time::Duration::from_micros(10));
        if strap.is_low() {
            LONG_CABLE_BAUD
        } else {
            fois_protocol::BAUD_RATE
        }
    };
    let mut config = uart_config(baud, modbus);
    config.rx_pull = Pull::Up;
    let (tx_buf, rx_buf) = buffers();
    let uart = match BufferedUart::new(usart, rx, tx, tx_buf, rx_buf, Irqs, config) {
        Ok(u) => u,
        Err(e) => defmt::panic!("USART6 config: {}", e),
    };
    let (tx, rx) = uart.split();
    Link {
        tx,
        rx,
        de: Some(de),
        baud,
    }
}
