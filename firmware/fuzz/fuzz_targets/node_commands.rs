//! Fuzz the node's command path: arbitrary bytes from the host link, in
//! arbitrary chunks, through `Node::handle_rx` on a fake board whose ADC
//! readings also come from the input, with frames, the button and the
//! coalesced saves (on a small RAM flash, so saves change pages) in between.
//!
//! It must never panic, every frame the node sends must decode, and every
//! complete frame from the host (a non-empty run of bytes ended by 0x00)
//! must get exactly one answer: an `Ack` or an `Error`.
#![no_main]

use std::cell::Cell;
use std::convert::Infallible;
use std::rc::Rc;

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::{ErrorType, OutputPin};
use fois_firmware::hal::{BoardInfo, PhotoAdc};
use fois_firmware::node::Node;
use fois_firmware::storage::flash_store::FlashStore;
use fois_firmware::storage::ram_flash::RamFlash;
use fois_protocol::{DeviceFrame, DeviceMsg, FrameDecoder, MAX_FRAME};
use libfuzzer_sys::fuzz_target;

/// ADC codes taken from the input: photo (off/on per channel), NTC, VREFINT.
struct FakeAdc {
    codes: [u16; 6],
    led: Rc<Cell<bool>>,
}

impl PhotoAdc for FakeAdc {
    fn read_photo(&mut self) -> [u16; 2] {
        if self.led.get() {
            [self.codes[1], self.codes[3]]
        } else {
            [self.codes[0], self.codes[2]]
        }
    }
    fn read_ntc(&mut self) -> u16 {
        self.codes[4]
    }
    fn read_vrefint(&mut self) -> u16 {
        self.codes[5]
    }
    fn read_internal_temp(&mut self) -> u16 {
        self.codes[4] ^ self.codes[5]
    }
}

struct Pin(Rc<Cell<bool>>);
impl ErrorType for Pin {
    type Error = Infallible;
}
impl OutputPin for Pin {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.0.set(false);
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        self.0.set(true);
        Ok(())
    }
}

struct NoDelay;
impl DelayNs for NoDelay {
    fn delay_ns(&mut self, _: u32) {}
}

type Flash = RamFlash<Vec<u8>, 512, 2>;

fuzz_target!(|data: &[u8]| {
    let Some((head, stream)) = data.split_at_checked(12) else {
        return;
    };
    let mut codes = [0u16; 6];
    for (c, pair) in codes.iter_mut().zip(head.chunks_exact(2)) {
        *c = u16::from_le_bytes([pair[0], pair[1]]);
    }
    let led = Rc::new(Cell::new(false));
    let store = FlashStore::new(Flash::new(vec![0xFF; 1024]), 0..1024).expect("two pages");
    let mut node = Node::new(
        FakeAdc {
            codes,
            led: led.clone(),
        },
        Pin(led),
        Pin(Rc::new(Cell::new(false))),
        Pin(Rc::new(Cell::new(false))),
        NoDelay,
        store,
        BoardInfo::simulated("fuzz"),
    );

    let mut out = Vec::new();
    let mut now_ms = 0u64;
    // Chunks: a length byte, then that many bytes of host traffic; after
    // each chunk a frame runs and the clock moves on by the length byte in
    // 100 ms steps (so pending saves come due).
    let mut rest = stream;
    let mut sent = Vec::new();
    while let Some((&len, tail)) = rest.split_first() {
        let n = usize::from(len).min(tail.len());
        let (chunk, tail) = tail.split_at(n);
        node.handle_rx(chunk, now_ms, &mut |b| out.extend_from_slice(b));
        sent.extend_from_slice(chunk);
        node.run_frame(now_ms, &mut |b| out.extend_from_slice(b));
        if len == 0xFF {
            node.button_pressed(now_ms, &mut |b| out.extend_from_slice(b));
        }
        let _ = node.take_reset_request();
        now_ms += 100 * u64::from(len);
        node.poll_storage(now_ms);
        rest = tail;
    }

    // Every complete host frame: a non-empty run ended by 0x00.
    let mut complete = 0usize;
    let mut run = 0usize;
    for &b in &sent {
        if b == 0 {
            if run > 0 {
                complete += 1;
            }
            run = 0;
        } else {
            run += 1;
        }
    }
    let mut answers = 0usize;
    let mut dec = FrameDecoder::<MAX_FRAME>::new();
    dec.feed::<DeviceFrame>(&out, |r| {
        let frame = r.expect("the node sent a frame its own protocol cannot read");
        if matches!(frame.msg, DeviceMsg::Ack(_) | DeviceMsg::Error(_)) {
            answers += 1;
        }
    });
    // Each button press is answered too (an unsolicited Ack or Error).
    let buttons = stream_buttons(stream);
    assert_eq!(
        answers,
        complete + buttons,
        "{complete} host frames and {buttons} button presses"
    );
});

/// The button presses the chunk loop made (length byte 0xFF).
fn stream_buttons(stream: &[u8]) -> usize {
    let mut rest = stream;
    let mut n = 0;
    while let Some((&len, tail)) = rest.split_first() {
        let k = usize::from(len).min(tail.len());
        if len == 0xFF {
            n += 1;
        }
        rest = &tail[k..];
    }
    n
}
