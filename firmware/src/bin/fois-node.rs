//! The embassy application for the NUCLEO-F446RE. Only this file and its
//! board module touch the HAL; all the logic is `fois_firmware::node::Node`.
//!
//! Tasks: `measure` (runs a frame every frame period, feeds the watchdog,
//! sends `Hello` every second until streaming starts), `uart_rx` (bytes →
//! `Node::handle_rx`), `uart_tx` (frame bytes → USART2) and `button` (B1 →
//! `Node::button_pressed`). The node sits in one mutex; frames go to the
//! transmitter through a byte pipe, and a frame that does not fit is dropped
//! whole (the host sees the gap in the sequence numbers) rather than blocking
//! the measurement.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
#[path = "fois-node/board.rs"]
mod board;

#[cfg(target_os = "none")]
mod app {
    use defmt_rtt as _;
    use embassy_executor::Spawner;
    use embassy_stm32::exti::{self, ExtiInput};
    use embassy_stm32::flash::Flash;
    use embassy_stm32::gpio::{Level, Output, Pull, Speed};
    use embassy_stm32::usart::{self, BufferedUart, BufferedUartRx, BufferedUartTx};
    use embassy_stm32::wdg::IndependentWatchdog;
    use embassy_stm32::{bind_interrupts, interrupt, peripherals};
    use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
    use embassy_sync::mutex::Mutex;
    use embassy_sync::pipe::Pipe;
    use embassy_time::{Delay, Duration, Instant, Timer};
    use embedded_io_async::{Read, Write};
    use fois_firmware::hal::BoardInfo;
    use fois_firmware::node::Node;
    use panic_probe as _;

    use crate::board::{self, BoardAdc, FlashStorage};

    bind_interrupts!(struct Irqs {
        USART2 => usart::BufferedInterruptHandler<peripherals::USART2>;
        EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
    });

    type BoardNode =
        Node<BoardAdc, Output<'static>, Output<'static>, Output<'static>, Delay, FlashStorage>;

    static NODE: Mutex<ThreadModeRawMutex, Option<BoardNode>> = Mutex::new(None);
    /// Encoded frames waiting for the UART.
    static TX: Pipe<ThreadModeRawMutex, 1024> = Pipe::new();

    /// Independent watchdog timeout: longer than a flash sector erase (≤ 2 s)
    /// plus the longest frame (K = 64 × 2 × 5 ms = 0.65 s), short enough to
    /// recover a hung node quickly.
    const WATCHDOG_US: u32 = 4_000_000;
    const HELLO_EVERY_MS: u64 = 1_000;

    /// Queue one whole frame for the UART, or drop it whole if there is no room.
    fn queue(frame: &[u8]) {
        if TX.free_capacity() < frame.len() {
            return;
        }
        let mut rest = frame;
        while !rest.is_empty() {
            match TX.try_write(rest) {
                Ok(n) => rest = rest.get(n..).unwrap_or(&[]),
                Err(_) => break,
            }
        }
    }

    fn now_ms() -> u64 {
        Instant::now().as_millis()
    }

    #[embassy_executor::main]
    async fn main(spawner: Spawner) {
        let p = embassy_stm32::init(Default::default());
        let reset_reason = board::take_reset_reason();
        defmt::info!(
            "fois-node up, reset reason {=str}",
            board::reset_reason_name(reset_reason)
        );

        let mut wdg = IndependentWatchdog::new(p.IWDG, WATCHDOG_US);
        wdg.unleash();

        let info = BoardInfo {
            board: board::BOARD_NAME,
            unique_id: board::unique_id(),
            reset_reason,
            cal: board::factory_cal(),
        };
        let adc = BoardAdc::new(p.ADC1, p.PA0, p.PA1, p.PA4);
        let led = Output::new(p.PB0, Level::Low, Speed::Low);
        let alarm = Output::new(p.PA9, Level::Low, Speed::Low);
        let ld2 = Output::new(p.PA5, Level::Low, Speed::Low);
        let storage = FlashStorage::new(Flash::new_blocking(p.FLASH));
        let node = Node::new(adc, led, alarm, ld2, Delay, storage, info);
        *NODE.lock().await = Some(node);

        let mut config = usart::Config::default();
        config.baudrate = fois_protocol::BAUD_RATE;
        let tx_buf = cortex_m::singleton!(: [u8; 512] = [0; 512]);
        let rx_buf = cortex_m::singleton!(: [u8; 256] = [0; 256]);
        let (Some(tx_buf), Some(rx_buf)) = (tx_buf, rx_buf) else {
            defmt::panic!("buffers taken twice")
        };
        let uart = match BufferedUart::new(p.USART2, p.PA3, p.PA2, tx_buf, rx_buf, Irqs, config) {
            Ok(u) => u,
            Err(e) => defmt::panic!("USART2 config: {}", e),
        };
        let (tx, rx) = uart.split();
        let button = ExtiInput::new(p.PC13, p.EXTI13, Pull::None, Irqs);

        spawn(&spawner, uart_tx(tx));
        spawn(&spawner, uart_rx(rx));
        spawn(&spawner, button_task(button));
        measure(wdg).await
    }

    fn spawn<S>(
        spawner: &Spawner,
        token: Result<embassy_executor::SpawnToken<S>, embassy_executor::SpawnError>,
    ) {
        match token {
            Ok(t) => spawner.spawn(t),
            Err(e) => defmt::panic!("spawn: {}", e),
        }
    }

    /// The measurement loop: one frame per frame period on a fixed grid,
    /// `Hello` at boot and every second while not streaming, the watchdog fed
    /// at least every `MAX_SLEEP` (frame periods go up to 10 min).
    async fn measure(mut wdg: IndependentWatchdog<'static, peripherals::IWDG>) -> ! {
        const MAX_SLEEP: Duration = Duration::from_millis(500);
        let hello_every = Duration::from_millis(HELLO_EVERY_MS);
        let mut next_frame = Instant::now();
        let mut next_hello = Instant::now();
        let mut booted = false;
        loop {
            let (wake, reset) = {
                let mut guard = NODE.lock().await;
                let Some(node) = guard.as_mut() else {
                    defmt::panic!("node missing")
                };
                let now = Instant::now();
                // Hello at boot and every second until streaming starts.
                if now >= next_hello && (!booted || !node.is_streaming()) {
                    node.send_hello(&mut queue);
                    next_hello = now + hello_every;
                }
                booted = true;
                let period = Duration::from_millis(u64::from(node.frame_period_ms()));
                if now >= next_frame {
                    node.run_frame(now.as_millis(), &mut queue);
                    next_frame += period;
                    if next_frame < now {
                        // Overran (flash erase, long calibration): restart the grid.
                        next_frame = now + period;
                    }
                }
                // A shorter period (StartStream) takes effect at once.
                next_frame = next_frame.min(now + period);
                let mut wake = next_frame.min(now + MAX_SLEEP);
                if !node.is_streaming() {
                    wake = wake.min(next_hello);
                }
                (wake, node.take_reset_request())
            };
            wdg.pet();
            if reset {
                // Let the Ack leave (1 KiB at 115200 Bd is < 100 ms).
                Timer::after_millis(100).await;
                cortex_m::peripheral::SCB::sys_reset();
            }
            Timer::at(wake).await;
        }
    }

    #[embassy_executor::task]
    async fn uart_tx(mut tx: BufferedUartTx<'static>) {
        let mut buf = [0u8; 128];
        loop {
            let n = TX.read(&mut buf).await;
            if let Some(bytes) = buf.get(..n) {
                // A UART error loses bytes: the host's decoder resyncs at the next 0x00.
                let _ = tx.write_all(bytes).await;
            }
        }
    }

    #[embassy_executor::task]
    async fn uart_rx(mut rx: BufferedUartRx<'static>) {
        let mut buf = [0u8; 64];
        loop {
            match rx.read(&mut buf).await {
                Ok(n) => {
                    let mut guard = NODE.lock().await;
                    if let (Some(node), Some(bytes)) = (guard.as_mut(), buf.get(..n)) {
                        node.handle_rx(bytes, now_ms(), &mut queue);
                    }
                }
                // Framing/noise/overrun: the bytes are lost; the decoder resyncs.
                Err(_) => Timer::after_millis(1).await,
            }
        }
    }

    /// B1 (PC13, active low, external pull-up on the Nucleo), debounced.
    #[embassy_executor::task]
    async fn button_task(mut button: ExtiInput<'static, embassy_stm32::mode::Async>) {
        loop {
            button.wait_for_falling_edge().await;
            Timer::after_millis(30).await;
            if button.is_low() {
                let mut guard = NODE.lock().await;
                if let Some(node) = guard.as_mut() {
                    node.button_pressed(now_ms(), &mut queue);
                }
            }
            button.wait_for_high().await;
            Timer::after_millis(30).await;
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("fois-node is firmware: build it with `cargo fw` (thumbv7em-none-eabihf)");
}
