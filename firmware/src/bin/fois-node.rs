//! The embassy application for the NUCLEO-F446RE. Only this file and its
//! board module touch the HAL; all the logic is `fois_firmware::node::Node`.
//!
//! Tasks: `measure` (the library's `Schedule`: `Hello` at boot and every
//! second until streaming, a frame every frame period, pending saves; feeds
//! the watchdog), `uart_rx` (bytes →
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
    use embassy_stm32::{bind_interrupts, interrupt, peripherals};
    use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
    use embassy_sync::mutex::Mutex;
    use embassy_sync::pipe::Pipe;
    use embassy_sync::signal::Signal;
    use embassy_time::{Instant, Timer};
    use embedded_io_async::{Read, Write};
    use fois_firmware::flash_store::FlashStore;
    use fois_firmware::hal::BoardInfo;
    use fois_firmware::node::Node;
    use fois_firmware::schedule::Schedule;
    use fois_firmware::watchdog::MAX_SLEEP_MS;
    use panic_probe as _;

    use crate::board::{self, BoardAdc, BoardFlash, FeedingDelay, Watchdog};

    bind_interrupts!(struct Irqs {
        USART2 => usart::BufferedInterruptHandler<peripherals::USART2>;
        EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
    });

    type BoardNode = Node<
        BoardAdc,
        Output<'static>,
        Output<'static>,
        Output<'static>,
        FeedingDelay,
        FlashStore<BoardFlash>,
    >;

    static NODE: Mutex<ThreadModeRawMutex, Option<BoardNode>> = Mutex::new(None);
    /// Encoded frames waiting for the UART.
    static TX: Pipe<ThreadModeRawMutex, 1024> = Pipe::new();
    /// Raised by the link and the button after the node took a command: the
    /// measurement loop polls the schedule again at once, so a new stream
    /// period, a `StopStream`'s first `Hello`, a `Reset` and a save come
    /// due from now, not from the wake-up planned before the command.
    static COMMANDED: Signal<ThreadModeRawMutex, ()> = Signal::new();

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
        // Probe the ST-LINK's 8 MHz before embassy's clock setup (which
        // would wait for it for ever), then run on it or on HSI.
        let hse = board::hse_bypass_present();
        let p = embassy_stm32::init(board::clock_config(hse));
        // The watchdog runs from here on; the flash store feeds it before
        // each sector erase, the settle waits in every frame.
        let wdg = Watchdog::start(p.IWDG);
        let reset_reason = board::take_reset_reason();
        defmt::info!(
            "fois-node up, reset reason {=str}, clock {=str}",
            board::reset_reason_name(reset_reason),
            if hse {
                "HSE 8 MHz bypass"
            } else {
                "HSI (HSE missing)"
            }
        );

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
        let flash = BoardFlash::new(Flash::new_blocking(p.FLASH), wdg);
        let storage = match FlashStore::new(flash, BoardFlash::RANGE) {
            Ok(s) => s,
            Err(_) => defmt::panic!("flash store: sectors 6-7 are not two equal pages"),
        };
        let mut node = Node::new(adc, led, alarm, ld2, FeedingDelay { wdg }, storage, info);
        node.set_clock_fallback(!hse);
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

    /// The measurement loop, on the library's `Schedule` (the same one the
    /// virtual node runs): `Hello` at boot and every second until
    /// streaming, frames on a fixed grid, pending saves when due, the
    /// watchdog fed at least every `MAX_SLEEP_MS` (periods go up to 10 min).
    async fn measure(wdg: Watchdog) -> ! {
        let mut schedule = Schedule::new();
        let mut bor_checked = false;
        loop {
            let (wake_ms, reset) = {
                let mut guard = NODE.lock().await;
                let Some(node) = guard.as_mut() else {
                    defmt::panic!("node missing")
                };
                let now = now_ms();
                let streaming = node.is_streaming();
                let due = schedule.poll(now, streaming, node.frame_period_ms());
                if due.hello {
                    node.send_hello(&mut queue);
                }
                if due.frame {
                    // Runs the pending save too, after the frame.
                    node.run_frame(now, &mut queue);
                    if let Some(m) = node.last_measurement() {
                        board::LAST_VDDA_MV.store(m.vdda_mv, core::sync::atomic::Ordering::Relaxed);
                        if !bor_checked {
                            bor_checked = true;
                            if board::ensure_bor_level(m.vdda_mv, wdg) {
                                defmt::info!("brown-out reset level set to 3");
                            }
                        }
                    }
                } else {
                    node.poll_storage(now);
                }
                let streaming = node.is_streaming();
                let mut wake = schedule
                    .next_wake_ms(streaming)
                    .min(now.saturating_add(u64::from(MAX_SLEEP_MS)));
                if let Some(save) = node.save_due_ms() {
                    wake = wake.min(save);
                }
                (wake, node.take_reset_request())
            };
            wdg.pet();
            if reset {
                // Let the Ack leave (1 KiB at 115200 Bd is < 100 ms).
                Timer::after_millis(100).await;
                cortex_m::peripheral::SCB::sys_reset();
            }
            embassy_futures::select::select(
                Timer::at(Instant::from_millis(wake_ms)),
                COMMANDED.wait(),
            )
            .await;
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
                    COMMANDED.signal(());
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
                COMMANDED.signal(());
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
