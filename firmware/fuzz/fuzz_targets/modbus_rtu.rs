//! Fuzz the node's Modbus RTU request path: arbitrary bytes at arbitrary
//! times through the silence framer (`fois_firmware::modbus::silence`),
//! every frame it gives answered by the request server
//! (`fois_firmware::modbus::server`) over a node's register view, writes
//! enabled or not, the actions carried into node commands.
//!
//! Input: byte 0 picks the address (1–247), whether writes start enabled
//! (bit 7) and whether each frame's last two bytes are replaced by its
//! correct CRC (bit 6: so the server's paths past the CRC check are
//! reached, not only the drop of a bad CRC); then pairs (gap, byte): the
//! gap in units of 100 µs before the byte (so frames, 1.5-character breaks
//! and 3.5-character silences all occur at 19 200 Bd).
//!
//! It must never panic; an answer goes only to a frame with a good CRC
//! addressed to this node (never to a broadcast), carries a good CRC and
//! this address, and fits the 256-byte frame.
#![no_main]

use fois_firmware::modbus::server::crc_ok;
use fois_firmware::modbus::{ModbusView, RtuServer, SilenceFramer, Silences};
use fois_protocol::Parity;
use fois_protocol::registers::{WRITE_ENABLE_KEY, not_available};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&head, rest)) = data.split_first() else {
        return;
    };
    let address = 1 + head % 247;
    let mut server = RtuServer::new(address);
    let mut view = ModbusView::default();
    view.registers = not_available();
    view.registers[3] = u16::from(head);
    if head & 0x80 != 0 {
        let key = WRITE_ENABLE_KEY.to_be_bytes();
        let mut req = heapless::Vec::<u8, 8>::new();
        let _ = req.extend_from_slice(&[address, 6, 0, 100, key[0], key[1]]);
        let _ = fois_firmware::modbus::server::push_crc(&mut req);
        let _ = server.answer(&req, &view, 0);
    }
    let mut framer = SilenceFramer::new(Silences::at(19_200, Parity::Even8E1));
    let mut t_us = 0u64;
    let fix_crc = head & 0x40 != 0;
    let check = |frame: &[u8], server: &mut RtuServer, now_ms: u64| {
        let mut fixed = frame.to_vec();
        if fix_crc && fixed.len() >= 4 {
            let n = fixed.len() - 2;
            let crc = fois_firmware::modbus::server::CRC16.checksum(&fixed[..n]);
            fixed[n..].copy_from_slice(&crc.to_le_bytes());
        }
        let frame = &fixed[..];
        let a = server.answer(frame, &view, now_ms);
        if let Some(r) = &a.reply {
            assert!(crc_ok(frame), "answered a bad CRC");
            assert_eq!(frame[0], address, "answered another address or a broadcast");
            assert!(crc_ok(r) && r[0] == address && r.len() <= 256, "{r:02x?}");
        }
        for action in a.actions {
            let _ = action.command();
        }
    };
    for pair in rest.chunks(2) {
        let (gap, byte) = match pair {
            [g, b] => (*g, *b),
            [b] => (0, *b),
            _ => continue,
        };
        t_us += u64::from(gap) * 100;
        if let Some(frame) = framer.push(byte, t_us) {
            check(&frame, &mut server, t_us / 1_000);
        }
    }
    if let Some(frame) = framer.poll(t_us + 1_000_000) {
        check(&frame, &mut server, t_us / 1_000);
    }
});
