//! The embassy application for the NUCLEO-F446RE. Only this file and its
//! board modules (`board`, `safety`, `link`) touch the HAL; all the logic is
//! `fois_firmware::node::Node` and the library's pure modules.
//!
//! Boot: the watchdog first, the HSE probe, `embassy_stm32::init`, the
//! backup registers (panic record, the rule's state), the flash store
//! (skipped after panic resets in a row), the node, the link. Tasks:
//! `measure` (the library's `Schedule`: `Hello` at boot and every second
//! until streaming, a frame every frame period, pending saves; the only
//! place besides the flash erase that feeds the watchdog), `uart_rx` (bytes
//! → `Node::handle_rx`, one host frame at a time, yielding between them),
//! `uart_tx` (frame bytes → the link; on the field link with the
//! transceiver's driver enable around each burst) and `button` (B1 →
//! `Node::button_pressed`). The node sits in one mutex; frames go to the
//! transmitter through a byte pipe, and a frame that does not fit is dropped
//! whole (the host sees the gap in the sequence numbers) rather than
//! blocking the measurement.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
#[path = "fois-node/board.rs"]
mod board;
#[cfg(target_os = "none")]
#[path = "fois-node/link.rs"]
mod link;
#[cfg(target_os = "none")]
#[path = "fois-node/safety.rs"]
mod safety;

#[cfg(target_os = "none")]
mod app {
    use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

    use defmt_rtt as _;
    use embassy_executor::Spawner;
    use embassy_stm32::exti::{self, ExtiInput};
    use embassy_stm32::flash::Flash;
    use embassy_stm32::gpio::{Level, Output, Pull, Speed};
    use embassy_stm32::usart::{BufferedUartRx, BufferedUartTx};
    use embassy_stm32::{bind_interrupts, interrupt};
    use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
    use embassy_sync::mutex::Mutex;
    use embassy_sync::pipe::Pipe;
    use embassy_sync::signal::Signal;
    use embassy_time::{Delay, Instant, Timer};
    use embedded_io_async::{Read, Write};
    use fois_firmware::hal::BoardInfo;
    use fois_firmware::node::Node;
    use fois_firmware::platform::boot::{self, RuleSnapshot, SkippableStorage};
    use fois_firmware::platform::field_link;
    use fois_firmware::platform::schedule::Schedule;
    use fois_firmware::platform::watchdog::MAX_SLEEP_MS;
    use fois_firmware::storage::flash_store::FlashStore;
    use fois_protocol::ResetReason;

    use crate::board::{self, BoardAdc, BoardFlash};
    use crate::link;
    use crate::safety::{self, Watchdog};

    bind_interrupts!(struct Irqs {
        EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
    });

    type BoardNode = Node<
        BoardAdc,
        Output<'static>,
        Output<'static>,
        Output<'static>,
        Delay,
        SkippableStorage<FlashStore<BoardFlash>>,
    >;

    static NODE: Mutex<ThreadModeRawMutex, Option<BoardNode>> = Mutex::new(None);
    /// Encoded frames waiting for the UART.
    static TX: Pipe<ThreadModeRawMutex, 1024> = Pipe::new();
    /// Raised by the link and the button after the node took a command: the
    /// measurement loop polls the schedule again at once, so a new stream
    /// period, a `StopStream`'s first `Hello`, a `Reset` and a save come
    /// due from now, not from the wake-up planned before the command.
    static COMMANDED: Signal<ThreadModeRawMutex, ()> = Signal::new();
    /// When the last byte came in, µs of uptime (wrapping), and whether one
    /// has: the field link's transmitter waits for a quiet line.
    static LAST_RX_US: AtomicU32 = AtomicU32::new(0);
    static RX_SEEN: AtomicBool = AtomicBool::new(false);

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

    fn now_us32() -> u32 {
        Instant::now().as_micros() as u32
    }

    #[embassy_executor::main]
    async fn main(spawner: Spawner) {
        // First the watchdog: everything after it may hang only until it
        // fires (embassy's clock setup waits without a bound).
        let wdg = Watchdog::start_first();
        // Probe the ST-LINK's 8 MHz (or a crystal at X3) before embassy's
        // clock setup, which would wait for it for ever; then run on it or
        // on HSI.
        let hse = safety::probe_hse();
        let p = embassy_stm32::init(safety::clock_config(hse));
        if hse.is_some() {
            safety::enable_css();
        }
        safety::enable_pvd();
        let reset_reason = board::take_reset_reason();
        let power_on = reset_reason == ResetReason::PowerOn;
        let plan = boot::plan_boot(safety::panic_words(), power_on);
        safety::set_panic_words(plan.words);
        let bor_ok = safety::bor_level_set();
        defmt::info!(
            "fois-node up, reset reason {=str}, clock {=str}, BOR {=bool}, store {=str}",
            board::reset_reason_name(reset_reason),
            match hse {
                Some(safety::HseSource::Bypass) => "HSE 8 MHz (ST-LINK MCO)",
                Some(safety::HseSource::Crystal) => "HSE 8 MHz (crystal)",
                None => "HSI (HSE missing)",
            },
            bor_ok,
            if plan.skip_store { "skipped" } else { "flash" }
        );

        let info = BoardInfo {
            board: board::BOARD_NAME,
            unique_id: board::unique_id(),
            reset_reason,
            cal: board::factory_cal(),
        };
        let mut adc = BoardAdc::new(p.ADC1, p.PA0, p.PA1, p.PA4);
        if let Some(cycles) = adc.measure_photo_pair_cycles() {
            // The conversion part of the settle gap Δ (firmware/README.md,
            // Measurement): ≈ 19 µs expected at 16 MHz.
            defmt::info!("photo pair: {=u32} cycles ({=u32} µs)", cycles, cycles / 16);
        }
        let led = Output::new(p.PB0, Level::Low, Speed::Low);
        let alarm = Output::new(p.PA9, Level::Low, Speed::Low);
        let ld2 = Output::new(p.PA5, Level::Low, Speed::Low);
        let store = if plan.skip_store {
            None
        } else {
            let flash = BoardFlash::new(Flash::new_blocking(p.FLASH), wdg);
            match FlashStore::new(flash, BoardFlash::RANGE) {
                Ok(s) => Some(s),
                Err(_) => defmt::panic!("flash store: sectors 6-7 are not two equal pages"),
            }
        };
        // Built and moved in within a block that ends before the first
        // await: a node whose storage lived across one (even moved out)
        // would sit in this task's future as well as in NODE (14 KiB of
        // static RAM twice with the growth history).
        {
            let mut node = Node::new(adc, led, alarm, ld2, Delay, SkippableStorage(store), info);
            node.set_clock_fallback(hse.is_none());
            node.set_boot_faults(!bor_ok, plan.skip_store);
            if let Some((line, resets)) = plan.panic_reset {
                node.report_panic_reset(line, resets);
            }
            // After a watchdog, software, pin or panic reset: the alarm (and its
            // acknowledgement) as before the reset, at once.
            node.resume_rule(RuleSnapshot::resume(safety::rule_words(), power_on));
            match NODE.try_lock() {
                Ok(mut slot) => *slot = Some(node),
                Err(_) => defmt::panic!("the node's mutex is taken before the node exists"),
            }
        }

        #[cfg(not(feature = "field-link"))]
        let link = link::bench(p.USART2, p.PA3, p.PA2);
        #[cfg(feature = "field-link")]
        let link = link::field(p.USART6, p.PC7, p.PC6, p.PA8, p.PC8);
        defmt::info!("link at {=u32} Bd", link.baud);
        let button = ExtiInput::new(p.PC13, p.EXTI13, Pull::None, Irqs);

        spawn(&spawner, uart_tx(link.tx, link.de, link.baud));
        spawn(&spawner, uart_rx(link.rx));
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
    /// It also keeps the rule's state in the backup registers, tells the
    /// node about the supply and the clock, and ends a row of panic resets
    /// once the node has run for `boot::HEALTHY_AFTER_MS`.
    async fn measure(wdg: Watchdog) -> ! {
        let mut schedule = Schedule::new();
        let mut kept = None;
        let mut healthy = false;
        loop {
            let (wake_ms, reset) = {
                let mut guard = NODE.lock().await;
                let Some(node) = guard.as_mut() else {
                    defmt::panic!("node missing")
                };
                let now = now_ms();
                node.set_supply_low(safety::supply_low());
                if safety::clock_failed() {
                    node.set_clock_fallback(true);
                }
                let streaming = node.is_streaming();
                let due = schedule.poll(now, streaming, node.frame_period_ms());
                if due.hello {
                    node.send_hello(&mut queue);
                }
                if due.frame {
                    // Runs the pending save too, after the frame.
                    node.run_frame(now, &mut queue);
                    if let Some(m) = node.last_measurement() {
                        board::LAST_VDDA_MV.store(m.vdda_mv, Ordering::Relaxed);
                    }
                } else {
                    node.poll_storage(now);
                }
                let snapshot = node.rule_snapshot();
                if kept != Some(snapshot) {
                    safety::set_rule_words(snapshot.encode());
                    kept = Some(snapshot);
                }
                if !healthy && now >= boot::HEALTHY_AFTER_MS {
                    healthy = true;
                    safety::set_panic_words(boot::healthy(safety::panic_words()));
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
                // Let the Ack leave (1 KiB at 19 200 Bd is < 0.6 s).
                Timer::after_millis(600).await;
                cortex_m::peripheral::SCB::sys_reset();
            }
            embassy_futures::select::select(
                Timer::at(Instant::from_millis(wake_ms)),
                COMMANDED.wait(),
            )
            .await;
        }
    }

    /// Frames to the link. On the field link (`de` present): wait for a
    /// quiet line (two-wire RS-485 is half duplex), raise DE, send what is
    /// queued, wait for transmission complete, drop DE.
    #[embassy_executor::task]
    async fn uart_tx(mut tx: BufferedUartTx<'static>, mut de: Option<Output<'static>>, baud: u32) {
        let mut buf = [0u8; 128];
        loop {
            let n = TX.read(&mut buf).await;
            if let Some(de) = de.as_mut() {
                loop {
                    let quiet = RX_SEEN
                        .load(Ordering::Relaxed)
                        .then(|| now_us32().wrapping_sub(LAST_RX_US.load(Ordering::Relaxed)));
                    if field_link::line_free(quiet, baud) {
                        break;
                    }
                    Timer::after_micros(u64::from(field_link::byte_time_us(baud))).await;
                }
                de.set_high();
                embassy_time::block_for(embassy_time::Duration::from_micros(u64::from(
                    field_link::DE_LEAD_US,
                )));
            }
            // A UART error loses bytes: the host's decoder resyncs at the next 0x00.
            if let Some(bytes) = buf.get(..n) {
                let _ = tx.write_all(bytes).await;
            }
            if let Some(de) = de.as_mut() {
                // Whatever else is queued goes in the same burst.
                while let Ok(n) = TX.try_read(&mut buf) {
                    if let Some(bytes) = buf.get(..n) {
                        let _ = tx.write_all(bytes).await;
                    }
                }
                // TC: the last stop bit has left the shift register.
                let _ = tx.flush().await;
                de.set_low();
            }
        }
    }

    /// Bytes from the link to the node, one host frame (up to its 0x00) at
    /// a time, yielding between frames: a host that floods commands (a dark
    /// calibration takes up to 2 s) cannot starve the measurement loop,
    /// which alone feeds the watchdog.
    #[embassy_executor::task]
    async fn uart_rx(mut rx: BufferedUartRx<'static>) {
        let mut buf = [0u8; 64];
        loop {
            match rx.read(&mut buf).await {
                Ok(n) => {
                    LAST_RX_US.store(now_us32(), Ordering::Relaxed);
                    RX_SEEN.store(true, Ordering::Relaxed);
                    let bytes = buf.get(..n).unwrap_or(&[]);
                    for piece in bytes.split_inclusive(|b| *b == 0) {
                        {
                            let mut guard = NODE.lock().await;
                            if let Some(node) = guard.as_mut() {
                                node.handle_rx(piece, now_ms(), &mut queue);
                            }
                        }
                        COMMANDED.signal(());
                        embassy_futures::yield_now().await;
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
