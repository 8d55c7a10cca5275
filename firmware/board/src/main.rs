//! The embassy application for the NUCLEO-F446RE. Only this file and its
//! board modules (`board`, `safety`, `link`, `rtu`) touch the HAL; all the logic is
//! `fois_firmware::node::Node` and the library's pure modules.
//!
//! Boot: the watchdog first; the reset's cause and the rule's state from
//! the backup registers, and at once the alarm, LD2 and (field link) DE/RE̅
//! driven from them; the HSE probe, `embassy_stm32::init`, the boot plan
//! (panic record, booting marker); the ADC; the flash store's read, only
//! on a healthy supply and not after unhealthy resets in a row; the node,
//! the link. Tasks: `measure` (the library's `Schedule` on a wrap-safe
//! `Uptime`: `Hello` at boot and every second until streaming, a frame
//! every frame period, pending saves, the HSE retries; it feeds the
//! watchdog only while the schedule shows progress, and besides it only
//! the flash erase and the bounded boot wait do), `uart_rx` (bytes →
//! `Node::handle_rx`, one host frame at a time, yielding between them),
//! `uart_tx` (frame bytes → the link; on the field link with the
//! transceiver's driver enable around each burst; on a higher-priority
//! executor, so DE drops at transmission complete even while the
//! measure loop runs a frame or a calibration) and `button` (B1 →
//! `Node::button_pressed`); on Modbus RTU (the node's link settings) the
//! `rtu` module's task replaces `uart_rx` and `uart_tx`, on the same
//! higher-priority executor. The node sits in one mutex; frames go to the
//! transmitter through a byte pipe, and a frame that does not fit is dropped
//! whole (the host sees the gap in the sequence numbers) rather than
//! blocking the measurement.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
mod board;
#[cfg(target_os = "none")]
#[allow(dead_code)] // shared with the bootloader, which also programs through it
mod flash_controller;
#[cfg(target_os = "none")]
mod link;
#[cfg(target_os = "none")]
mod rtu;
#[cfg(target_os = "none")]
mod safety;
#[cfg(target_os = "none")]
mod slots;

#[cfg(target_os = "none")]
mod app {
    use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

    use defmt_rtt as _;
    use embassy_executor::{InterruptExecutor, Spawner};
    use embassy_stm32::exti::{self, ExtiInput};
    use embassy_stm32::flash::Flash;
    use embassy_stm32::gpio::{Level, Output, Pull, Speed};
    use embassy_stm32::interrupt::{InterruptExt, Priority};
    use embassy_stm32::usart::{BufferedUartRx, BufferedUartTx};
    use embassy_stm32::{bind_interrupts, interrupt};
    use embassy_sync::blocking_mutex::raw::{CriticalSectionRawMutex, ThreadModeRawMutex};
    use embassy_sync::mutex::Mutex;
    use embassy_sync::pipe::Pipe;
    use embassy_sync::signal::Signal;
    use embassy_time::{Delay, Instant, Timer};
    use embedded_io_async::{Read, Write};
    use fois_firmware::hal::{BoardInfo, PhotoAdc};
    use fois_firmware::measure::vref;
    use fois_firmware::node::Node;
    use fois_firmware::platform::boot::{self, RuleSnapshot, SkippableStorage, StoreRead};
    use fois_firmware::platform::clock_retry::HseRetry;
    use fois_firmware::platform::field_link;
    use fois_firmware::platform::flash_layout::OLD_CONFIG_STORE;
    use fois_firmware::platform::reply_time::{RESET_DRAIN_BYTES, drain_ms};
    use fois_firmware::platform::schedule::Schedule;
    use fois_firmware::platform::uptime::{self, Uptime};
    use fois_firmware::platform::watchdog::MAX_SLEEP_MS;
    use fois_firmware::storage::flash_store::FlashStore;
    use fois_firmware::storage::migrate::{self, Migration};
    use fois_firmware::storage::supply::{self, BOOT_SUPPLY_STEP_MS, BootRead};
    use static_cell::StaticCell;

    use crate::board::{self, BoardAdc, BoardFlash, HeldOutput};
    use crate::link;
    use crate::rtu;
    use crate::safety::{self, Watchdog};
    use crate::slots::DfuSlot;
    #[cfg(feature = "updater")]
    use crate::slots::StateSlot;
    #[cfg(feature = "updater")]
    use fois_firmware::platform::flash_layout::ACTIVE;
    #[cfg(feature = "updater")]
    use fois_firmware::update::transfer::UpdaterConfig;
    #[cfg(feature = "updater")]
    use fois_firmware::update::{FIRMWARE_VERSION, FlashUpdater, UpdateKey};

    bind_interrupts!(struct Irqs {
        EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
    });

    type BoardNode = Node<
        BoardAdc,
        Output<'static>,
        HeldOutput,
        HeldOutput,
        Delay,
        SkippableStorage<FlashStore<BoardFlash>>,
        BoardUpdates,
    >;

    #[cfg(feature = "updater")]
    type BoardUpdates = FlashUpdater<DfuSlot, StateSlot>;
    #[cfg(not(feature = "updater"))]
    type BoardUpdates = fois_firmware::update::NoUpdates;

    /// The public key images are verified with: the 32 bytes of the file
    /// named at build time (`firmware/board/build.rs`: `FOIS_UPDATE_PUBLIC_KEY`
    /// or `firmware/keys/fois-update.pub`), or none — then every image is
    /// refused (`UpdateKey::NONE`), never accepted.
    #[cfg(feature = "updater")]
    const UPDATE_KEY: UpdateKey = match include!(concat!(env!("OUT_DIR"), "/update_key.rs")) {
        Some(bytes) => UpdateKey::from_bytes(bytes),
        None => UpdateKey::NONE,
    };

    /// Copy the old layout's record into the new store if it has none
    /// (`fois_firmware::storage::migrate`), and log what happened. Not
    /// inlined: the boot's task holds it once, not copies of the store's
    /// code.
    #[inline(never)]
    fn migrate_store(store: &mut FlashStore<BoardFlash>, dfu: &mut DfuSlot) {
        match migrate::migrate(store, dfu, 0..OLD_CONFIG_STORE.bytes()) {
            Ok(Migration::NotNeeded) | Ok(Migration::NothingToMove) => {}
            Ok(Migration::Moved { layout, old_erased }) => defmt::info!(
                "store moved from sectors 6-7 (record layout {=u16}, old erased {=bool})",
                layout,
                old_erased
            ),
            Err(_) => {
                defmt::warn!("store move from sectors 6-7 failed: tried again at the next boot")
            }
        }
    }

    /// The node, once built: a reference into [`NODE_CELL`], so this static
    /// is all zeros (.bss). An `Option<BoardNode>` here would be `.data`: its
    /// `None` is a non-zero niche, and the linker would keep the node's whole
    /// 14 KiB initial image in flash to copy it at reset.
    static NODE: Mutex<ThreadModeRawMutex, Option<&'static mut BoardNode>> = Mutex::new(None);
    /// Where the node lives (.bss; written once, at boot).
    static NODE_CELL: StaticCell<BoardNode> = StaticCell::new();
    /// Encoded frames waiting for the UART (written in thread mode, read by
    /// the transmit task on the link executor).
    static TX: Pipe<CriticalSectionRawMutex, 1024> = Pipe::new();
    /// Raised by the link and the button after the node took a command: the
    /// measurement loop polls the schedule again at once, so a new stream
    /// period, a `StopStream`'s first `Hello`, a `Reset` and a save come
    /// due from now, not from the wake-up planned before the command.
    static COMMANDED: Signal<CriticalSectionRawMutex, ()> = Signal::new();
    /// When the last byte came in, µs of uptime (wrapping), and whether one
    /// has: the field link's transmitter waits for a quiet line.
    static LAST_RX_US: AtomicU32 = AtomicU32::new(0);
    static RX_SEEN: AtomicBool = AtomicBool::new(false);
    /// The link speaks Modbus RTU (set at boot from the node's link settings).
    static MODBUS: AtomicBool = AtomicBool::new(false);

    /// The executor of the transmit task, above thread mode and below the
    /// USART's interrupt, on an interrupt nothing else uses (UART5).
    static LINK_EXECUTOR: InterruptExecutor = InterruptExecutor::new();

    #[interrupt]
    #[allow(non_snake_case)]
    unsafe fn UART5() {
        // SAFETY: the executor's own interrupt, started in `main`.
        unsafe { LINK_EXECUTOR.on_interrupt() }
    }

    /// Queue one whole frame for the UART, or drop it whole if there is no room.
    fn queue(frame: &[u8]) {
        // On Modbus RTU the node's own frames stay off the link.
        if MODBUS.load(Ordering::Relaxed) || TX.free_capacity() < frame.len() {
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

    /// ms of uptime for commands and the button (wrap-safe: the measure
    /// loop resets the node a day before the raw tick wraps, so within a
    /// run the raw milliseconds equal `Uptime`'s).
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
        // Then the outputs, before the clock, the ADC and the flash: the
        // alarm as the backup registers left it (after any reset but a
        // power loss), DE/RE̅ low.
        let cause = safety::take_reset_cause();
        let snapshot = RuleSnapshot::resume(safety::rule_words(), cause.power_lost);
        board::hold_outputs_early(snapshot.alarm_on());
        // Probe the ST-LINK's 8 MHz (or a crystal at X3) before embassy's
        // clock setup, which would wait for it for ever; then run on it or
        // on HSI.
        let hse = safety::probe_hse();
        let p = embassy_stm32::init(safety::clock_config(hse));
        if hse.is_some() {
            safety::enable_css();
        }
        safety::enable_pvd();
        let plan = boot::plan_boot(safety::panic_words(), cause);
        safety::set_panic_words(plan.words);
        let bor_ok = safety::bor_level_set();

        let info = BoardInfo {
            board: board::BOARD_NAME,
            unique_id: board::unique_id(),
            reset_reason: cause.reason,
            cal: board::factory_cal(),
        };
        let mut adc = BoardAdc::new(p.ADC1, p.PA0, p.PA1, p.PA4);
        if let Some(cycles) = adc.measure_photo_pair_cycles() {
            // The conversion part of the settle gap Δ (firmware/README.md,
            // Measurement): ≈ 19 µs expected at 16 MHz.
            defmt::info!("photo pair: {=u32} cycles ({=u32} µs)", cycles, cycles / 16);
        }
        let led = Output::new(p.PB0, Level::Low, Speed::Low);
        let level = if snapshot.alarm_on() {
            Level::High
        } else {
            Level::Low
        };
        let alarm = HeldOutput::new(Output::new(p.PA9, level, Speed::Low));
        let ld2 = HeldOutput::new(Output::new(p.PA5, level, Speed::Low));
        // The store's read may repair (erase): only on a healthy supply,
        // waited for at most 10 s (fed), else skipped.
        let mut waited_ms = 0;
        let supply_ok = loop {
            let vdda_mv = vref::vdda_mv(&info.cal.or_typical(), adc.read_vrefint());
            board::LAST_VDDA_MV.store(vdda_mv, Ordering::Relaxed);
            match supply::boot_read(vdda_mv, safety::supply_low(), waited_ms) {
                BootRead::Read => break true,
                BootRead::Skip => break false,
                BootRead::Wait => {
                    wdg.pet();
                    embassy_time::block_for(embassy_time::Duration::from_millis(u64::from(
                        BOOT_SUPPLY_STEP_MS,
                    )));
                    waited_ms += BOOT_SUPPLY_STEP_MS;
                }
            }
        };
        let store_read = if plan.skip_store {
            StoreRead::Skip
        } else if !supply_ok {
            StoreRead::Defer
        } else {
            StoreRead::Read
        };
        defmt::info!(
            "fois-node up, reset reason {=str}{=str}, clock {=str}, BOR {=bool}, store {=str}",
            board::reset_reason_name(cause.reason),
            if cause.reason == fois_protocol::ResetReason::PowerOn && !cause.power_lost {
                " (brown-out)"
            } else {
                ""
            },
            match hse {
                Some(safety::HseSource::Bypass) => "HSE 8 MHz (ST-LINK MCO)",
                Some(safety::HseSource::Crystal) => "HSE 8 MHz (crystal)",
                None => "HSI (HSE missing)",
            },
            bor_ok,
            if plan.skip_store {
                "skipped (unhealthy resets)"
            } else if !supply_ok {
                "deferred (supply low)"
            } else {
                "flash"
            }
        );
        // Built and moved in within a block that ends before the first
        // await: a node whose storage lived across one (even moved out)
        // would sit in this task's future as well as in NODE (14 KiB of
        // static RAM twice with the growth history).
        let (link_settings, modbus, button) = {
            let regions = Flash::new_blocking(p.FLASH).into_blocking_regions();
            let flash = BoardFlash::new(regions.bank1_region1, wdg);
            let mut store = match FlashStore::new(flash, BoardFlash::RANGE) {
                Ok(s) => s,
                Err(_) => defmt::panic!("flash store: sectors 2-3 are not two equal pages"),
            };
            // The store of the layout before the bootloader (sectors 6-7,
            // now the DFU slot) moves once, before anything erases the slot.
            let mut dfu = DfuSlot::new(regions.bank1_region3, wdg);
            if store_read == StoreRead::Read {
                migrate_store(&mut store, &mut dfu);
            }
            let store = SkippableStorage::new(store, store_read);
            // The update slots: the DFU slot and embassy-boot's state (the
            // trial boot's mark), read once here.
            #[cfg(feature = "updater")]
            let updates = FlashUpdater::new(
                dfu,
                StateSlot::new(regions.bank1_region2, wdg),
                UpdaterConfig {
                    active_len: ACTIVE.bytes(),
                    running: FIRMWARE_VERSION,
                    key: UPDATE_KEY,
                },
            );
            #[cfg(not(feature = "updater"))]
            let updates = {
                // The DFU slot served the store's move only.
                let _ = dfu;
                fois_firmware::update::NoUpdates
            };
            let mut node =
                Node::new_with_updates(adc, led, alarm, ld2, Delay, store, info, updates);
            node.set_clock_fallback(hse.is_none());
            node.set_boot_faults(!bor_ok, store_read != StoreRead::Read);
            if let Some((line, resets)) = plan.panic_reset {
                node.report_panic_reset(line, resets);
            }
            // The outputs kept their early level through the store's read; the
            // node drives them from here, at the same level.
            board::release_outputs();
            node.resume_rule(snapshot);
            // B1 held at power-up: back to the framed protocol (the way back
            // when the host no longer speaks Modbus).
            let button = ExtiInput::new(p.PC13, p.EXTI13, Pull::None, Irqs);
            if button.is_low() && node.button_held_at_boot(now_ms()) {
                defmt::info!("button held at power-up: the link is framed again");
            }
            let link_settings = node.link_settings();
            let modbus = link_settings.protocol == fois_protocol::LinkProtocol::ModbusRtu;
            MODBUS.store(modbus, Ordering::Relaxed);
            if modbus {
                rtu::publish(node.modbus_view());
            }
            match NODE.try_lock() {
                Ok(mut slot) => *slot = Some(NODE_CELL.init(node)),
                Err(_) => defmt::panic!("the node's mutex is taken before the node exists"),
            }
            (link_settings, modbus, button)
        };

        let parity = modbus.then_some(link_settings.parity);
        #[cfg(not(feature = "field-link"))]
        let link = link::bench(p.USART2, p.PA3, p.PA2, parity);
        #[cfg(feature = "field-link")]
        let link = link::field(p.USART6, p.PC7, p.PC6, p.PA8, p.PC8, parity);
        defmt::info!(
            "link at {=u32} Bd, {=str}",
            link.baud,
            if modbus { "Modbus RTU" } else { "framed" }
        );

        interrupt::UART5.set_priority(Priority::P6);
        let link_spawner = LINK_EXECUTOR.start(interrupt::UART5);
        if modbus {
            // On the link's executor too: an answer (and its DE drop) does
            // not wait behind a frame or a calibration in the measure loop.
            match rtu::link_task(
                link.rx,
                link.tx,
                link.de,
                link.baud,
                link_settings,
                &COMMANDED,
            ) {
                Ok(t) => link_spawner.spawn(t),
                Err(e) => defmt::panic!("spawn: {}", e),
            }
        } else {
            match uart_tx(link.tx, link.de, link.baud) {
                Ok(t) => link_spawner.spawn(t),
                Err(e) => defmt::panic!("spawn: {}", e),
            }
            spawn(&spawner, uart_rx(link.rx));
        }
        spawn(&spawner, button_task(button));
        measure(
            wdg,
            link.baud,
            hse.is_none(),
            store_read == StoreRead::Defer,
        )
        .await
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
    /// virtual node runs) and `Uptime` (milliseconds that go on across the
    /// timer's wrap): `Hello` at boot and every second until streaming,
    /// frames on a fixed grid, pending saves when due. It feeds the
    /// watchdog at least every `MAX_SLEEP_MS` (periods go up to 10 min),
    /// and only while the schedule shows progress (`Schedule::on_track`: a
    /// frame within the last period, the next within one): a loop that
    /// runs on without frames ends in the watchdog. It also keeps the
    /// rule's state in the backup registers, tells the node about the
    /// supply and the clock, tries the HSE again on HSI
    /// (`clock_retry::HseRetry`), marks the boot healthy after
    /// `boot::HEALTHY_AFTER_MS`, resets the node a day before the raw
    /// timer wraps (`uptime::reset_before_wrap`), and, if the boot deferred
    /// the store's read for a low supply, resets it once the supply has
    /// been healthy for `boot::DEFERRED_READ_RESET_MS` (that boot reads it).
    async fn measure(wdg: Watchdog, baud: u32, hse_missing: bool, store_deferred: bool) -> ! {
        let mut schedule = Schedule::new();
        let mut uptime = Uptime::new();
        let mut hse_retry = HseRetry::new();
        if hse_missing {
            hse_retry.fell_back(0);
        }
        let mut kept = None;
        let mut healthy = false;
        let mut supply_healthy_since = None;
        loop {
            let before = uptime.now_ms(Instant::now().as_ticks());
            if safety::clock_failed() {
                hse_retry.fell_back(before);
            }
            if hse_retry.due(before) {
                match safety::try_restore_hse() {
                    Some(_) => {
                        defmt::info!("clock: back on the HSE");
                        hse_retry.restored(before);
                    }
                    None => hse_retry.failed(before),
                }
            }
            let (raw, now, wake_ms, reset, on_track) = {
                let mut guard = NODE.lock().await;
                let Some(node) = guard.as_mut() else {
                    defmt::panic!("node missing")
                };
                // The time after the lock: a command may have held the node
                // for a dark calibration meanwhile.
                let raw = Instant::now().as_ticks();
                let now = uptime.now_ms(raw);
                let modbus = MODBUS.load(Ordering::Relaxed);
                // A Modbus write's actions, after their answer went out.
                let mut acted = false;
                while let Some(action) = modbus.then(rtu::next_action).flatten() {
                    rtu::set_result(node.modbus_action(action, now));
                    acted = true;
                }
                if modbus && rtu::take_answered() {
                    // The trial boot's link check: reads count too.
                    node.link_answered();
                }
                node.set_supply_low(safety::supply_low());
                node.set_clock_fallback(safety::on_hsi());
                let streaming = node.is_streaming();
                let period_ms = node.frame_period_ms();
                let due = schedule.poll(now, streaming, period_ms);
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
                let on_track = schedule.on_track(now, period_ms);
                if modbus && (due.frame || acted) {
                    rtu::publish(node.modbus_view());
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
                if let Some(retry) = hse_retry.next_ms() {
                    wake = wake.min(retry);
                }
                (raw, now, wake, node.take_reset_request(), on_track)
            };
            if on_track {
                wdg.pet();
            } else {
                defmt::error!("measure loop without progress: the watchdog will reset");
            }
            let read_store_now = store_deferred
                && boot::deferred_read_due(
                    &mut supply_healthy_since,
                    supply::flash_write_allowed(
                        board::LAST_VDDA_MV.load(Ordering::Relaxed),
                        safety::supply_low(),
                    ),
                    now,
                );
            if reset || read_store_now || uptime::reset_before_wrap(raw) {
                reset_after_drain(baud).await;
            }
            let sleep_ms = wake_ms.saturating_sub(uptime.now_ms(Instant::now().as_ticks()));
            embassy_futures::select::select(Timer::after_millis(sleep_ms), COMMANDED.wait()).await;
        }
    }

    /// A commanded (or planned) reset: clear the booting marker (it is not
    /// an unhealthy reset), let everything queued leave — the pipe empty
    /// and the USART's transmission complete — bounded by `drain_ms` of a
    /// full pipe and UART buffer at the link's rate, then reset.
    async fn reset_after_drain(baud: u32) -> ! {
        safety::set_panic_words(boot::commanded_reset(safety::panic_words()));
        let start = Instant::now();
        let bound =
            embassy_time::Duration::from_millis(u64::from(drain_ms(RESET_DRAIN_BYTES, baud)));
        while (!TX.is_empty() || board::LINK_SENDING.load(Ordering::Acquire))
            && start.elapsed() < bound
        {
            Timer::after_millis(2).await;
        }
        cortex_m::peripheral::SCB::sys_reset()
    }

    /// Frames to the link, on the link executor (above thread mode). On the
    /// field link (`de` present): wait for a quiet line (two-wire RS-485 is
    /// half duplex; the RX pin itself sampled for the quiet bytes), raise
    /// DE, send what is queued, wait for transmission complete, drop DE.
    /// `board::LINK_SENDING` is set across each burst (a flash erase and a
    /// commanded reset wait for it).
    #[embassy_executor::task]
    async fn uart_tx(mut tx: BufferedUartTx<'static>, mut de: Option<Output<'static>>, baud: u32) {
        let mut buf = [0u8; 128];
        loop {
            let n = TX.read(&mut buf).await;
            board::LINK_SENDING.store(true, Ordering::Release);
            if let Some(de) = de.as_mut() {
                loop {
                    let quiet = RX_SEEN
                        .load(Ordering::Relaxed)
                        .then(|| now_us32().wrapping_sub(LAST_RX_US.load(Ordering::Relaxed)));
                    if field_link::line_free(quiet, baud) && line_idle(baud) {
                        break;
                    }
                    // Not free: wait as long as the quiet bytes before looking
                    // again, so a busy line leaves thread mode most of the CPU.
                    Timer::after_micros(u64::from(
                        field_link::IDLE_BYTES_BEFORE_TX * field_link::byte_time_us(baud),
                    ))
                    .await;
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
            // Whatever else is queued goes in the same burst.
            while let Ok(n) = TX.try_read(&mut buf) {
                if let Some(bytes) = buf.get(..n) {
                    let _ = tx.write_all(bytes).await;
                }
            }
            // TC: the last stop bit has left the shift register. embassy's
            // flush can return early: its interrupt handler sets `tx_done`
            // on a TC between two chunks (the ring buffer ran dry for a
            // moment) and then sends the next chunk; so the USART's own TC
            // flag must agree (cleared again by that next byte), bounded.
            let _ = tx.flush().await;
            let start = Instant::now();
            let bound =
                embassy_time::Duration::from_millis(u64::from(drain_ms(RESET_DRAIN_BYTES, baud)));
            while !board::link_tx_complete() && start.elapsed() < bound {
                Timer::after_micros(u64::from(field_link::byte_time_us(baud))).await;
            }
            if let Some(de) = de.as_mut() {
                de.set_low();
            }
            board::LINK_SENDING.store(false, Ordering::Release);
        }
    }

    /// The field link's RX pin stayed idle for the quiet bytes.
    #[cfg(feature = "field-link")]
    fn line_idle(baud: u32) -> bool {
        board::field_rx_idle_for(field_link::IDLE_BYTES_BEFORE_TX * field_link::byte_time_us(baud))
    }

    #[cfg(not(feature = "field-link"))]
    fn line_idle(_baud: u32) -> bool {
        true
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
