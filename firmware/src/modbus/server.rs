//! One Modbus RTU request → its answer, on the register map of
//! [`fois_protocol::registers`], with rmodbus parsing the request and
//! building the answer (its `ModbusFrame` with our own reads and writes:
//! the map has two blocks and writes that are commands, which its
//! context storage does not model).
//!
//! - A frame that fails its CRC, is shorter than 4 bytes, has a length that
//!   does not fit its function, or is for another address is dropped
//!   without an answer (Modbus over serial line §2.4.1: a slave answers only
//!   a correct frame addressed to it).
//! - Function codes 03 and 04 read either block (the measurement block
//!   `0..REGISTERS`, the node block `NODE_BASE..`); 06 and 16 write the
//!   writable registers; a broadcast (address 0) write is carried out and
//!   never answered, a broadcast read ignored.
//! - Exceptions: 01 a function other than 03, 04, 06, 16; 02 a register
//!   outside the blocks or (write) not writable; 03 a quantity of 0 or
//!   over 125 (read) / 123 (write), an FC 16 byte count other than twice
//!   the quantity, a value out of range (the config rule's, the link's);
//!   04 a write while writes are not enabled ([`registers::WRITE_ENABLE`]).
//!
//! Never panics, on any bytes (fuzzed: `firmware/fuzz`, target
//! `modbus_rtu`; a property test below).

use fois_protocol::registers::{
    self, ACK, ACK_VALUE, CLEAR_FRAMES, CommandResult, DARK_CALIBRATE, FREEZE_LIMIT, LAST_RESULT,
    LINK_PROTOCOL, MODBUS_ADDRESS, NODE_BASE, NODE_REGISTERS, NODE_TABLE, ONSET_FRAMES, PARITY,
    REGISTERS, THAW_LIMIT, WRITE_ENABLE, WRITE_ENABLE_KEY, WRITE_ENABLE_MS,
};
use fois_protocol::{LinkProtocol, Parity};
use rmodbus::consts::ModbusFunction;
use rmodbus::server::{ModbusFrame, Read};
use rmodbus::{ErrorKind, ModbusProto};

use super::silence::Adu;
use super::view::{Action, ModbusView};

/// CRC-16/MODBUS (polynomial 0xA001 reflected, init 0xFFFF), sent low byte first.
pub const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);

/// Most registers one read may ask for (§6.3).
pub const MAX_READ: u16 = 125;
/// Most registers one FC 16 may write (§6.12).
pub const MAX_WRITE: u16 = 123;

/// The actions one request may carry (an FC 16 over the node block: a
/// config, a link change and a command).
pub type Actions = heapless::Vec<Action, 4>;

/// What a request produced.
#[derive(Debug, Default)]
pub struct Answer {
    /// The bytes to send (CRC included); `None`: stay silent.
    pub reply: Option<Adu>,
    /// What the node is to do after the answer.
    pub actions: Actions,
}

/// The node's Modbus slave: its address, the write enable, the last
/// command's result.
#[derive(Debug, Clone)]
pub struct RtuServer {
    address: u8,
    write_until_ms: Option<u64>,
    last: CommandResult,
}

/// `frame` ends in the CRC of the bytes before it.
pub fn crc_ok(frame: &[u8]) -> bool {
    match frame.len().checked_sub(2) {
        Some(n) if n >= 2 => {
            let (body, crc) = frame.split_at(n);
            crc.get(..2) == Some(&CRC16.checksum(body).to_le_bytes()[..])
        }
        _ => false,
    }
}

/// Append the CRC to `frame`; false if it does not fit.
pub fn push_crc<const N: usize>(frame: &mut heapless::Vec<u8, N>) -> bool {
    let crc = CRC16.checksum(frame).to_le_bytes();
    frame.extend_from_slice(&crc).is_ok()
}

/// The length a request of this function must have, if the function is
/// one whose length is known from its header.
fn expected_len(adu: &[u8]) -> Option<usize> {
    match adu.get(1)? {
        0x01..=0x06 => Some(8),
        0x0F | 0x10 => adu.get(6).map(|n| 9 + usize::from(*n)),
        _ => None,
    }
}

/// Is the register range inside one of the two blocks?
fn readable(start: u16, count: u16) -> bool {
    let end = u32::from(start) + u32::from(count);
    let node = u32::from(NODE_BASE);
    end <= REGISTERS as u32 || (start >= NODE_BASE && end <= node + NODE_REGISTERS as u32)
}

fn writable(addr: u16) -> bool {
    addr == ACK || NODE_TABLE.iter().any(|f| f.address == addr && f.writable)
}

impl RtuServer {
    /// A slave at `address` with writes disabled.
    pub const fn new(address: u8) -> Self {
        RtuServer {
            address,
            write_until_ms: None,
            last: CommandResult::None,
        }
    }

    /// Its address.
    pub fn address(&self) -> u8 {
        self.address
    }

    /// Answer at another address from now on (after a write changed it).
    pub fn set_address(&mut self, address: u8) {
        self.address = address;
    }

    /// The last command's result, for [`registers::LAST_RESULT`].
    pub fn set_last_result(&mut self, r: CommandResult) {
        self.last = r;
    }

    /// Writes are enabled at `now_ms`.
    pub fn writes_enabled(&self, now_ms: u64) -> bool {
        self.write_until_ms.is_some_and(|t| now_ms < t)
    }

    /// One request (a frame the silence delimited) at `now_ms`.
    pub fn answer(&mut self, adu: &[u8], view: &ModbusView, now_ms: u64) -> Answer {
        let mut out = Answer::default();
        if adu.len() < 4 || !crc_ok(adu) {
            return out;
        }
        let unit = adu.first().copied().unwrap_or(0);
        if unit != 0 && unit != self.address {
            return out;
        }
        if expected_len(adu).is_some_and(|n| n != adu.len()) {
            return out;
        }
        let mut resp = Adu::new();
        let fc = adu.get(1).copied().unwrap_or(0);
        if fc >= 0x80 {
            // rmodbus 0.13 adds 0x80 to the code in a u8 (an overflow
            // panic in a debug build): an exception code can be no request's,
            // so answer 01 under the code itself, here.
            if unit != 0 && resp.extend_from_slice(&[unit, fc, 0x01]).is_ok() && push_crc(&mut resp)
            {
                out.reply = Some(resp);
            }
            return out;
        }
        let mut frame = ModbusFrame::new(self.address, adu, ModbusProto::Rtu, &mut resp);
        if frame.parse().is_err() {
            return out;
        }
        if frame.error.is_none() && frame.processing_required {
            let done = match frame.func {
                ModbusFunction::GetHoldings | ModbusFunction::GetInputs => {
                    self.read(&mut frame, view, now_ms)
                }
                ModbusFunction::SetHolding | ModbusFunction::SetHoldingsBulk => {
                    self.write(&mut frame, adu, view, now_ms, &mut out.actions)
                }
                _ => frame.set_modbus_error_if_unset(&ErrorKind::IllegalFunction),
            };
            if done.is_err() {
                out.actions.clear();
                return out;
            }
        }
        if !frame.response_required || frame.finalize_response().is_err() {
            return out;
        }
        out.reply = Some(resp);
        out
    }

    fn read(
        &self,
        frame: &mut ModbusFrame<'_, Adu>,
        view: &ModbusView,
        now_ms: u64,
    ) -> Result<(), ErrorKind> {
        let (start, count) = (frame.reg, frame.count);
        if count == 0 || count > MAX_READ {
            return frame.set_modbus_error_if_unset(&ErrorKind::IllegalDataValue);
        }
        if !readable(start, count) {
            return frame.set_modbus_error_if_unset(&ErrorKind::IllegalDataAddress);
        }
        let node = view.node_block(self.writes_enabled(now_ms), self.last);
        let Read::Words(w) = frame.get_external_read()? else {
            return Err(ErrorKind::ReadCallOnWriteFrame);
        };
        for (i, out) in w.buf.chunks_exact_mut(2).enumerate() {
            let addr = usize::from(start) + i;
            let v = if addr < REGISTERS {
                view.registers.get(addr).copied()
            } else {
                node.get(addr - usize::from(NODE_BASE)).copied()
            };
            out.copy_from_slice(&v.unwrap_or(0).to_be_bytes());
        }
        frame.process_external_read(Ok(()))
    }

    fn write(
        &mut self,
        frame: &mut ModbusFrame<'_, Adu>,
        adu: &[u8],
        view: &ModbusView,
        now_ms: u64,
        actions: &mut Actions,
    ) -> Result<(), ErrorKind> {
        let start = frame.reg;
        let (count, values) = if frame.func == ModbusFunction::SetHolding {
            (1u16, adu.get(4..6).unwrap_or(&[]))
        } else {
            let count = frame.count;
            let bytes = usize::from(adu.get(6).copied().unwrap_or(0));
            if count == 0 || count > MAX_WRITE || bytes != 2 * usize::from(count) {
                return frame.set_modbus_error_if_unset(&ErrorKind::IllegalDataValue);
            }
            (count, adu.get(7..7 + bytes).unwrap_or(&[]))
        };
        let addrs = || (0..count).map(move |i| start.wrapping_add(i));
        if u32::from(start) + u32::from(count) > 0x1_0000 || !addrs().all(writable) {
            return frame.set_modbus_error_if_unset(&ErrorKind::IllegalDataAddress);
        }
        if !self.writes_enabled(now_ms) && addrs().any(|a| a != WRITE_ENABLE) {
            return frame.set_modbus_error_if_unset(&ErrorKind::SlaveDeviceFailure);
        }
        let mut config = view.config.clone();
        let mut link = view.link;
        let mut enable = None;
        let (mut ack, mut dark) = (false, false);
        for (addr, v) in addrs().zip(values.chunks_exact(2)) {
            let v = u16::from_be_bytes([v[0], v.get(1).copied().unwrap_or(0)]);
            let ok = match addr {
                ACK => {
                    ack = true;
                    v == ACK_VALUE
                }
                DARK_CALIBRATE => {
                    dark = true;
                    v == 1
                }
                WRITE_ENABLE => {
                    enable = Some(v == WRITE_ENABLE_KEY);
                    v == WRITE_ENABLE_KEY || v == 0
                }
                LINK_PROTOCOL => {
                    link.protocol = match v {
                        0 => LinkProtocol::Framed,
                        _ => LinkProtocol::ModbusRtu,
                    };
                    v <= 1
                }
                MODBUS_ADDRESS => {
                    link.modbus_address = u8::try_from(v).unwrap_or(0);
                    link.validate().is_ok()
                }
                PARITY => match Parity::from_code(v) {
                    Some(p) => {
                        link.parity = p;
                        true
                    }
                    None => false,
                },
                FREEZE_LIMIT => {
                    config.freeze_limit_centi_c = v as i16;
                    true
                }
                THAW_LIMIT => {
                    config.thaw_limit_centi_c = v as i16;
                    true
                }
                ONSET_FRAMES => {
                    config.onset_frames = v;
                    true
                }
                CLEAR_FRAMES => {
                    config.clear_frames = v;
                    true
                }
                _ => false,
            };
            if !ok {
                return frame.set_modbus_error_if_unset(&ErrorKind::IllegalDataValue);
            }
        }
        if config != view.config && config.validate().is_err() {
            return frame.set_modbus_error_if_unset(&ErrorKind::IllegalDataValue);
        }
        // Accepted: carried out after the answer, in this order.
        let mut queue = |a: Action| actions.push(a).map_err(|_| ErrorKind::OOB);
        if config != view.config {
            queue(Action::SetConfig(config))?;
        }
        if ack {
            queue(Action::AckAlarm)?;
        }
        if dark {
            queue(Action::CalibrateDark)?;
        }
        if link != view.link {
            queue(Action::SetLink(link))?;
        }
        self.write_until_ms = match enable {
            Some(false) => None,
            _ => Some(now_ms.saturating_add(WRITE_ENABLE_MS)),
        };
        frame.process_external_write(Ok(()))
    }
}

/// The value of a register in `view` as a master reads it (tests, tools).
pub fn register(view: &ModbusView, server: &RtuServer, addr: u16, now_ms: u64) -> Option<u16> {
    if usize::from(addr) < REGISTERS {
        return view.registers.get(usize::from(addr)).copied();
    }
    let i = usize::from(addr.checked_sub(NODE_BASE)?);
    view.node_block(server.writes_enabled(now_ms), server.last)
        .get(i)
        .copied()
}

// The node block's addresses are the table's, in order.
const _: () = assert!(LAST_RESULT == NODE_BASE + 2 && registers::NODE_REGISTERS == 10);
