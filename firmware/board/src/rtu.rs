//! The board's Modbus RTU link (when the node's link settings say Modbus
//! RTU): one task feeds the firmware's silence framer with each byte and
//! its arrival time, answers every frame at once from the register view
//! the measure loop publishes after each frame and command (so an answer
//! never waits for a frame or a flash erase that holds the node), raises
//! DE around the answer as the framed link does, and hands a write's
//! actions to the measure loop, which carries them out on the node.
//!
//! The logic is the library's (`fois_firmware::modbus`, host-tested and
//! fuzzed); this file only moves bytes, times and the view.

use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, AtomicU16, Ordering};

use embassy_stm32::gpio::Output;
use embassy_stm32::usart::{BufferedUartRx, BufferedUartTx};
use embassy_sync::blocking_mutex::Mutex as BlockingMutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use embassy_time::{Instant, Timer};
use embedded_io_async::{Read, Write};
use fois_firmware::modbus::{Action, ModbusView, RtuServer, SilenceFramer, Silences};
use fois_firmware::platform::field_link;
use fois_protocol::LinkSettings;
use fois_protocol::registers::CommandResult;

/// The view the answers read (published by the measure loop). Behind a
/// critical section: the link task runs on the higher-priority executor.
static VIEW: BlockingMutex<CriticalSectionRawMutex, RefCell<Option<ModbusView>>> =
    BlockingMutex::new(RefCell::new(None));
/// Writes' actions for the measure loop.
static ACTIONS: Channel<CriticalSectionRawMutex, Action, 4> = Channel::new();
/// The last action's result (`CommandResult as u16`; `u16::MAX`: none new).
static LAST_RESULT: AtomicU16 = AtomicU16::new(u16::MAX);
/// An answer went out since the measure loop last looked: the trial boot's
/// link check (a PLC that only reads registers sends no command).
static ANSWERED: AtomicBool = AtomicBool::new(false);

/// True once after the link answered a request.
pub fn take_answered() -> bool {
    ANSWERED.swap(false, Ordering::Relaxed)
}

/// Publish the node's view (after a frame, after actions).
pub fn publish(view: ModbusView) {
    VIEW.lock(|v| *v.borrow_mut() = Some(view));
}

/// The next action a write asked for, if any.
pub fn next_action() -> Option<Action> {
    ACTIONS.try_receive().ok()
}

/// Record an action's result for the `last_result` register.
pub fn set_result(r: CommandResult) {
    LAST_RESULT.store(r as u16, Ordering::Relaxed);
}

fn result_of(code: u16) -> Option<CommandResult> {
    [
        CommandResult::None,
        CommandResult::Done,
        CommandResult::NoAlarm,
        CommandResult::Refused,
        CommandResult::InvalidConfig,
    ]
    .into_iter()
    .find(|r| *r as u16 == code)
}

/// The RTU link: receive, frame by silence, answer, hand actions over.
#[embassy_executor::task]
pub async fn link_task(
    mut rx: BufferedUartRx<'static>,
    mut tx: BufferedUartTx<'static>,
    mut de: Option<Output<'static>>,
    baud: u32,
    settings: LinkSettings,
    commanded: &'static Signal<CriticalSectionRawMutex, ()>,
) {
    let mut framer = SilenceFramer::new(Silences::at(baud, settings.parity));
    let mut server = RtuServer::new(settings.modbus_address);
    let mut buf = [0u8; 64];
    loop {
        let deadline = framer
            .deadline_us()
            .map_or(Instant::MAX, Instant::from_micros);
        let got = embassy_futures::select::select(rx.read(&mut buf), Timer::at(deadline)).await;
        let now_us = Instant::now().as_micros();
        let frame = match got {
            embassy_futures::select::Either::First(Ok(n)) => {
                let mut done = None;
                for &b in buf.get(..n).unwrap_or(&[]) {
                    if let Some(f) = framer.push(b, now_us) {
                        done = Some(f);
                    }
                }
                done
            }
            // A parity, framing or overrun error: the bytes are lost; the
            // frame they belonged to fails its CRC.
            embassy_futures::select::Either::First(Err(_)) => None,
            embassy_futures::select::Either::Second(()) => framer.poll(now_us),
        };
        let Some(frame) = frame else { continue };
        if let Some(r) = result_of(LAST_RESULT.swap(u16::MAX, Ordering::Relaxed)) {
            server.set_last_result(r);
        }
        let answer = VIEW.lock(|v| {
            v.borrow()
                .as_ref()
                .map(|view| server.answer(&frame, view, now_us / 1_000))
        });
        let Some(answer) = answer else { continue };
        if let Some(reply) = &answer.reply {
            if let Some(de) = de.as_mut() {
                de.set_high();
                embassy_time::block_for(embassy_time::Duration::from_micros(u64::from(
                    field_link::DE_LEAD_US,
                )));
            }
            let _ = tx.write_all(reply).await;
            let _ = tx.flush().await;
            if let Some(de) = de.as_mut() {
                de.set_low();
            }
            ANSWERED.store(true, Ordering::Relaxed);
        }
        let any = !answer.actions.is_empty();
        for a in answer.actions {
            let _ = ACTIONS.try_send(a);
        }
        if any {
            commanded.signal(());
        }
    }
}
