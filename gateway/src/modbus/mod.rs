//! Modbus TCP for SCADA: each node's latest state ([`crate::snapshot`]) as
//! a table of 16-bit registers, one Modbus unit id per node
//! ([`crate::config::ModbusConfig::units`]). The table is made by one pure
//! function, [`register_map`], from the node's [`fois_link::Reading`] (the
//! one mapping from the wire's integers to µA, °C, mm, fractions and gain
//! factors), scaled back to integers by the factors of [`TABLE`];
//! [`server`] serves it over TCP ([`pdu`]: the framing, [`units`]: the
//! answers, [`clients`]: the connected clients).
//!
//! Conventions (the README's "Modbus TCP" section has the table):
//! - function codes 03 (read holding registers) and 04 (read input
//!   registers) read the same table;
//! - a 32-bit value takes two registers, the high word first (big-endian
//!   words, as every register is big-endian on the wire);
//! - a value the node has not sent (no measurement yet, no ice estimate,
//!   no gain) reads as "not available": `0x8000` (i16), `0xFFFF` (u16 and
//!   enums), `0x8000_0000` (i32), `0xFFFF_FFFF` (u32); the status word says
//!   which parts are present.

pub mod clients;
pub mod log_limit;
pub mod pdu;
pub mod server;
pub mod units;

use std::time::{Duration, Instant};

use fois_link::Reading;
use fois_protocol::{DetectorState, Medium, flags};

use crate::snapshot::NodeSnapshot;

/// Registers in a node's table (addresses 0 to `REGISTERS - 1`).
pub const REGISTERS: usize = 24;

/// Address of the status bits ([`status`]).
pub const STATUS: u16 = 0;
/// Address of the detector state (0 dry, 1 wet, 2 ice).
pub const STATE: u16 = 1;
/// Address of the node's fault bits.
pub const FAULTS: u16 = 2;
/// Address of I1 (i32, nA = 0.001 µA).
pub const I1: u16 = 3;
/// Address of I2 (i32, nA).
pub const I2: u16 = 5;
/// Address of the air temperature (i16, 0.01 °C).
pub const TEMPERATURE: u16 = 7;
/// Address of the estimated thickness (u16, µm = 0.001 mm).
pub const THICKNESS: u16 = 8;
/// Address of its standard deviation (u16, µm).
pub const THICKNESS_SIGMA: u16 = 9;
/// Address of the estimated medium (0 dry, 1 water, 2 glazed, 3 rime).
pub const MEDIUM: u16 = 10;
/// Address of the medium's probability (u16, ‰).
pub const MEDIUM_PROBABILITY: u16 = 11;
/// Address of the optical gain estimate (u32, ppm).
pub const GAIN: u16 = 12;
/// Address of its standard deviation (u32, ppm).
pub const GAIN_SIGMA: u16 = 14;
/// Address of the data's age (u32, ms).
pub const DATA_AGE: u16 = 16;
/// Address of the latest frame's sequence number (u32).
pub const SEQ: u16 = 18;
/// Address of the node's analog supply (u16, mV).
pub const VDDA: u16 = 20;
/// Address of the frames lost on the serial link (u32).
pub const FRAMES_LOST: u16 = 21;
/// Address of the alarm-acknowledge register: reads 0; writing 1
/// acknowledges the node's alarm (only with `[modbus] commands = true`).
pub const ACK: u16 = 23;
/// The value that acknowledges the alarm when written to [`ACK`].
pub const ACK_VALUE: u16 = 1;

/// The status word's bits.
pub mod status {
    /// The node's ice alarm output is on.
    pub const ALARM: u16 = 1 << 0;
    /// The alarm was acknowledged (the output stays on while ice remains).
    pub const ALARM_ACKED: u16 = 1 << 1;
    /// The detector says ice.
    pub const ICE: u16 = 1 << 2;
    /// The serial link is up (handshake done, frames arriving).
    pub const LINK_UP: u16 = 1 << 3;
    /// No measurement yet, or the latest is older than `stale_after_s`.
    pub const STALE: u16 = 1 << 4;
    /// A measurement is present (registers 1–7 and 20 hold its values).
    pub const DATA: u16 = 1 << 5;
    /// The currents may be used (no channel saturated).
    pub const VALID: u16 = 1 << 6;
    /// The node sent an ice estimate (registers 8–11).
    pub const ESTIMATE: u16 = 1 << 7;
    /// The node sent an optical gain estimate (registers 12–15).
    pub const GAIN: u16 = 1 << 8;
    /// A dark baseline is stored on the node.
    pub const DARK_BASELINE: u16 = 1 << 9;
    /// At least one fault bit is set (register 2).
    pub const FAULT: u16 = 1 << 10;
}

/// "Not available" of a u16 register (and of an enum).
pub const NA_U16: u16 = 0xFFFF;
/// "Not available" of an i16 register.
pub const NA_I16: u16 = 0x8000;
/// "Not available" of a u32 pair.
pub const NA_U32: u32 = 0xFFFF_FFFF;
/// "Not available" of an i32 pair.
pub const NA_I32: u32 = 0x8000_0000;

/// A register's type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// 16 bits, each a flag.
    Bits,
    /// A number standing for a word.
    Enum,
    /// Unsigned 16 bits.
    U16,
    /// Signed 16 bits, two's complement.
    I16,
    /// Unsigned 32 bits in two registers, high word first.
    U32,
    /// Signed 32 bits in two registers, high word first.
    I32,
}

impl Kind {
    /// Registers it takes.
    pub const fn width(self) -> u16 {
        match self {
            Kind::U32 | Kind::I32 => 2,
            _ => 1,
        }
    }

    /// Its name in the table.
    pub const fn name(self) -> &'static str {
        match self {
            Kind::Bits => "bits",
            Kind::Enum => "enum u16",
            Kind::U16 => "u16",
            Kind::I16 => "i16",
            Kind::U32 => "u32",
            Kind::I32 => "i32",
        }
    }
}

/// One entry of the register table.
#[derive(Debug, Clone, Copy)]
pub struct Field {
    /// First register (0-based, as on the wire).
    pub address: u16,
    /// Its name.
    pub name: &'static str,
    /// Its type.
    pub kind: Kind,
    /// Register value × scale = the value in `unit`.
    pub scale: f64,
    /// The unit after scaling (`""`: none).
    pub unit: &'static str,
    /// What it is.
    pub what: &'static str,
}

/// The register table, in address order: what [`register_map`] writes and
/// the README shows.
pub const TABLE: [Field; 17] = [
    field(
        STATUS,
        "status",
        Kind::Bits,
        1.0,
        "",
        "bit 0 ice alarm output on, 1 alarm acknowledged, 2 ice, 3 link up, 4 stale, 5 measurement present, 6 currents valid, 7 ice estimate present, 8 gain present, 9 dark baseline stored, 10 any fault",
    ),
    field(
        STATE,
        "state",
        Kind::Enum,
        1.0,
        "",
        "detector state: 0 dry, 1 wet, 2 ice",
    ),
    field(
        FAULTS,
        "faults",
        Kind::Bits,
        1.0,
        "",
        "the node's fault bits: 2 ntc_open, 3 ntc_short, 4 config_defaulted, 8 vdda_out_of_range, 9 storage_failed, 10 clock_fallback, 11 bor_not_set, 12 store_skipped, 13 gain_out_of_band",
    ),
    field(
        I1,
        "i1",
        Kind::I32,
        0.001,
        "µA",
        "net photocurrent, channel 1",
    ),
    field(
        I2,
        "i2",
        Kind::I32,
        0.001,
        "µA",
        "net photocurrent, channel 2",
    ),
    field(
        TEMPERATURE,
        "temperature",
        Kind::I16,
        0.01,
        "°C",
        "air temperature",
    ),
    field(
        THICKNESS,
        "thickness",
        Kind::U16,
        0.001,
        "mm",
        "estimated thickness of the cover",
    ),
    field(
        THICKNESS_SIGMA,
        "thickness_sigma",
        Kind::U16,
        0.001,
        "mm",
        "its standard deviation",
    ),
    field(
        MEDIUM,
        "medium",
        Kind::Enum,
        1.0,
        "",
        "estimated medium: 0 dry, 1 water, 2 glazed, 3 rime",
    ),
    field(
        MEDIUM_PROBABILITY,
        "medium_probability",
        Kind::U16,
        0.001,
        "",
        "its probability, 0–1",
    ),
    field(
        GAIN,
        "gain",
        Kind::U32,
        0.000_001,
        "",
        "optical gain estimate (1 = the response table's gain)",
    ),
    field(
        GAIN_SIGMA,
        "gain_sigma",
        Kind::U32,
        0.000_001,
        "",
        "its standard deviation",
    ),
    field(
        DATA_AGE,
        "data_age",
        Kind::U32,
        0.001,
        "s",
        "age of the latest measurement (at the gateway)",
    ),
    field(
        SEQ,
        "seq",
        Kind::U32,
        1.0,
        "",
        "the latest measurement frame's sequence number",
    ),
    field(
        VDDA,
        "vdda",
        Kind::U16,
        1.0,
        "mV",
        "the node's analog supply",
    ),
    field(
        FRAMES_LOST,
        "frames_lost",
        Kind::U32,
        1.0,
        "",
        "frames lost on the serial link since the gateway started",
    ),
    field(
        ACK,
        "alarm_ack",
        Kind::U16,
        1.0,
        "",
        "reads 0; write 1 (FC 06 or 16) to acknowledge the alarm, with `commands = true`",
    ),
];

const fn field(
    address: u16,
    name: &'static str,
    kind: Kind,
    scale: f64,
    unit: &'static str,
    what: &'static str,
) -> Field {
    Field {
        address,
        name,
        kind,
        scale,
        unit,
        what,
    }
}

/// `x / scale`, rounded, as i64 (saturating; NaN is 0).
fn scaled(x: f64, scale: f64) -> i64 {
    (x / scale).round() as i64
}

/// The register table of one node at `now`: what a Modbus client reads
/// from the node's unit.
pub fn register_map(node: &NodeSnapshot, now: Instant, stale_after: Duration) -> [u16; REGISTERS] {
    let mut r = Registers([0; REGISTERS]);
    for f in &TABLE {
        r.na(f);
    }
    r.set(ACK, 0);
    let mut bits = 0;
    if node.link_up {
        bits |= status::LINK_UP;
    }
    let age = node.age(now);
    if age.is_none_or(|a| a > stale_after) {
        bits |= status::STALE;
    }
    if let Some(a) = age {
        r.set32(DATA_AGE, u32::try_from(a.as_millis()).unwrap_or(NA_U32 - 1));
    }
    if let Some(seq) = node.seq {
        r.set32(SEQ, seq);
    }
    r.set32(
        FRAMES_LOST,
        u32::try_from(node.frames_lost).unwrap_or(u32::MAX),
    );
    if let Some(m) = &node.reading {
        bits |= reading_bits(m);
        r.set(STATE, state_code(m.state));
        r.set(FAULTS, m.flags & flags::FAULT_MASK);
        r.num(I1, m.i1_ua);
        r.num(I2, m.i2_ua);
        r.num(TEMPERATURE, m.temperature_c);
        r.set(VDDA, m.vdda_mv);
        if let Some(e) = &m.estimate {
            r.num(THICKNESS, e.thickness_mm);
            r.num(THICKNESS_SIGMA, e.thickness_sigma_mm);
            r.set(MEDIUM, medium_code(e.medium));
            r.num(MEDIUM_PROBABILITY, e.medium_probability);
        }
        if let Some(g) = &m.gain {
            r.num(GAIN, g.gain);
            r.num(GAIN_SIGMA, g.gain_sigma);
        }
    }
    r.set(STATUS, bits);
    r.0
}

/// The status bits a measurement sets.
fn reading_bits(m: &Reading) -> u16 {
    let mut bits = status::DATA;
    for (on, bit) in [
        (m.alarm, status::ALARM),
        (m.alarm_acked, status::ALARM_ACKED),
        (m.ice(), status::ICE),
        (m.valid, status::VALID),
        (m.estimate.is_some(), status::ESTIMATE),
        (m.gain.is_some(), status::GAIN),
        (m.dark_baseline, status::DARK_BASELINE),
        (!m.faults.is_empty(), status::FAULT),
    ] {
        if on {
            bits |= bit;
        }
    }
    bits
}

/// The state register's code.
pub const fn state_code(s: DetectorState) -> u16 {
    match s {
        DetectorState::Dry => 0,
        DetectorState::Wet => 1,
        DetectorState::Ice => 2,
    }
}

/// The medium register's code.
pub const fn medium_code(m: Medium) -> u16 {
    match m {
        Medium::Dry => 0,
        Medium::Water => 1,
        Medium::Glazed => 2,
        Medium::Rime => 3,
    }
}

/// A table being filled in.
struct Registers([u16; REGISTERS]);

impl Registers {
    fn set(&mut self, addr: u16, v: u16) {
        self.0[usize::from(addr)] = v;
    }

    fn set32(&mut self, addr: u16, v: u32) {
        self.set(addr, (v >> 16) as u16);
        self.set(addr + 1, v as u16);
    }

    /// Field `f`'s "not available".
    fn na(&mut self, f: &Field) {
        match f.kind {
            Kind::Bits => self.set(f.address, 0),
            Kind::Enum | Kind::U16 => self.set(f.address, NA_U16),
            Kind::I16 => self.set(f.address, NA_I16),
            Kind::U32 => self.set32(f.address, NA_U32),
            Kind::I32 => self.set32(f.address, NA_I32),
        }
    }

    /// `x` in the field's own unit, scaled to the field's integer and
    /// clamped to its range (the "not available" value excluded).
    fn num(&mut self, addr: u16, x: f64) {
        let Some(f) = TABLE.iter().find(|f| f.address == addr) else {
            return;
        };
        let v = scaled(x, f.scale);
        match f.kind {
            Kind::Bits | Kind::Enum | Kind::U16 => {
                self.set(addr, v.clamp(0, i64::from(NA_U16) - 1) as u16)
            }
            Kind::I16 => self.set(
                addr,
                v.clamp(-i64::from(i16::MAX), i64::from(i16::MAX)) as i16 as u16,
            ),
            Kind::U32 => self.set32(addr, v.clamp(0, i64::from(NA_U32) - 1) as u32),
            Kind::I32 => self.set32(
                addr,
                v.clamp(-i64::from(i32::MAX), i64::from(i32::MAX)) as i32 as u32,
            ),
        }
    }
}

/// The register table as the README shows it (Markdown).
pub fn markdown_table() -> String {
    let mut s = String::from(
        "| address | name | type | scale | unit | what |\n| --- | --- | --- | --- | --- | --- |\n",
    );
    for f in &TABLE {
        let addr = if f.kind.width() == 2 {
            format!("{}–{}", f.address, f.address + 1)
        } else {
            f.address.to_string()
        };
        let scale = if f.scale == 1.0 {
            "1".to_string()
        } else {
            format!("{}", f.scale)
        };
        s.push_str(&format!(
            "| {addr} | `{}` | {} | {scale} | {} | {} |\n",
            f.name,
            f.kind.name(),
            if f.unit.is_empty() { "–" } else { f.unit },
            f.what
        ));
    }
    s
}

#[cfg(test)]
mod tests;
