//! The virtual node's Modbus RTU link: the firmware's own silence framer
//! and request server ([`fois_firmware::modbus`]) between the bytes of a
//! link and the [`VirtualNode`], as the board's link task runs them.
//!
//! Emulated link timing: every byte is time-stamped (µs, on the caller's
//! clock: real time on a pseudo-terminal) when it arrives; the bytes of one
//! read arrive together, as back-to-back characters on a UART; a frame
//! ends after 3.5 characters of silence at the link's rate and parity
//! ([`Silences::at`]: 2 006 µs at 19 200 Bd 8E1) and is answered then.
//! The node's own frames (it still measures and streams) go to a sink the
//! caller chooses (a log), never onto the Modbus link.

use fois_firmware::modbus::{Adu, RtuServer, SilenceFramer, Silences};
use fois_protocol::{LinkProtocol, LinkSettings};

use crate::VirtualNode;

/// The Modbus side of a virtual node's link.
pub struct ModbusLink {
    framer: SilenceFramer,
    server: RtuServer,
    baud: u32,
    settings: LinkSettings,
    /// Requests answered, frames dropped (bad CRC, another address, broken).
    pub answered: u64,
}

impl ModbusLink {
    /// A link at `baud` with the node's settings.
    pub fn new(baud: u32, settings: LinkSettings) -> Self {
        ModbusLink {
            framer: SilenceFramer::new(Silences::at(baud, settings.parity)),
            server: RtuServer::new(settings.modbus_address),
            baud,
            settings,
            answered: 0,
        }
    }

    /// True while the node speaks Modbus.
    pub fn active(node: &VirtualNode) -> bool {
        node.node().link_settings().protocol == LinkProtocol::ModbusRtu
    }

    /// The link's silences.
    pub fn silences(&self) -> Silences {
        self.framer.silences()
    }

    /// When the frame being received ends, µs (`None`: nothing pending).
    pub fn deadline_us(&self) -> Option<u64> {
        self.framer.deadline_us()
    }

    /// Bytes received at `now_us`; the answers of any frame they end go to
    /// `reply`, the node's own frames to `frames`.
    pub fn receive(
        &mut self,
        node: &mut VirtualNode,
        bytes: &[u8],
        now_us: u64,
        reply: &mut impl FnMut(&[u8]),
        frames: &mut impl FnMut(&[u8]),
    ) {
        for &b in bytes {
            if let Some(adu) = self.framer.push(b, now_us) {
                self.serve(node, &adu, reply, frames);
            }
        }
    }

    /// The time is `now_us`: answer a frame that the silence ended.
    pub fn poll(
        &mut self,
        node: &mut VirtualNode,
        now_us: u64,
        reply: &mut impl FnMut(&[u8]),
        frames: &mut impl FnMut(&[u8]),
    ) {
        if let Some(adu) = self.framer.poll(now_us) {
            self.serve(node, &adu, reply, frames);
        }
    }

    fn serve(
        &mut self,
        node: &mut VirtualNode,
        adu: &Adu,
        reply: &mut impl FnMut(&[u8]),
        frames: &mut impl FnMut(&[u8]),
    ) {
        let now_ms = node.clock().now_ms();
        let view = node.node().modbus_view();
        let answer = self.server.answer(adu, &view, now_ms);
        if let Some(r) = &answer.reply {
            reply(r);
            self.answered += 1;
        }
        for action in answer.actions {
            let result = node.modbus_action(action, frames);
            self.server.set_last_result(result);
        }
        // A changed address or parity is in force after the answer: the
        // node reset itself to apply it, as the board does (writes are
        // disabled again, as after any reset).
        let now = node.node().link_settings();
        if now != self.settings {
            let answered = self.answered;
            *self = ModbusLink::new(self.baud, now);
            self.answered = answered;
        }
    }
}
