//! The register map's definition: addresses, types, scales, the "not
//! available" values, the status bits, the node-only block, and the table
//! of every register (who serves it, writable or not) the READMEs show.

/// Registers in the measurement block (addresses 0 to `REGISTERS - 1`).
pub const REGISTERS: usize = 27;

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
/// Address of the data's age (u32, ms; gateway only).
pub const DATA_AGE: u16 = 16;
/// Address of the latest frame's sequence number (u32).
pub const SEQ: u16 = 18;
/// Address of the node's analog supply (u16, mV).
pub const VDDA: u16 = 20;
/// Address of the frames lost on the serial link (u32; gateway only).
pub const FRAMES_LOST: u16 = 21;
/// Address of the alarm-acknowledge register: reads 0; writing
/// [`ACK_VALUE`] acknowledges the node's alarm (gateway: with `[modbus]
/// commands = true`; node: with writes enabled, [`WRITE_ENABLE`]).
pub const ACK: u16 = 23;
/// The value that acknowledges the alarm when written to [`ACK`].
pub const ACK_VALUE: u16 = 1;
/// Address of the icing rate (i16, 0.01 mm/h), once the node reports it.
pub const ICING_RATE: u16 = 24;
/// Address of its standard deviation (u16, 0.01 mm/h).
pub const ICING_RATE_SIGMA: u16 = 25;
/// Address of the probability that ice is accreting (u16, ‰).
pub const ACCRETING_PROBABILITY: u16 = 26;

/// The status word's bits.
pub mod status {
    /// The node's ice alarm output is on.
    pub const ALARM: u16 = 1 << 0;
    /// The alarm was acknowledged (the output stays on while ice remains).
    pub const ALARM_ACKED: u16 = 1 << 1;
    /// The detector says ice.
    pub const ICE: u16 = 1 << 2;
    /// The serial link is up (gateway: handshake done, frames arriving;
    /// node: always, it is answering).
    pub const LINK_UP: u16 = 1 << 3;
    /// No measurement yet, or (gateway) the latest is older than `stale_after_s`.
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
    /// The node reported an icing rate (registers 24–26).
    pub const ICING_RATE: u16 = 1 << 11;
    /// The node says ice is accreting now.
    pub const ACCRETING: u16 = 1 << 12;
}

/// "Not available" of a u16 register (and of an enum).
pub const NA_U16: u16 = 0xFFFF;
/// "Not available" of an i16 register.
pub const NA_I16: u16 = 0x8000;
/// "Not available" of a u32 pair.
pub const NA_U32: u32 = 0xFFFF_FFFF;
/// "Not available" of an i32 pair.
pub const NA_I32: u32 = 0x8000_0000;

/// First address of the node-only block: the node's Modbus commands and
/// the config it lets a Modbus master change (holding registers; the
/// gateway does not serve them).
pub const NODE_BASE: u16 = 100;
/// Write enable: reads 1 while writes are enabled, else 0. Writing
/// [`WRITE_ENABLE_KEY`] enables writes for [`WRITE_ENABLE_MS`] (each
/// accepted write restarts the time), writing 0 disables them. Every other
/// writable register answers exception 04 while writes are disabled.
pub const WRITE_ENABLE: u16 = 100;
/// The value that enables writes ("WE").
pub const WRITE_ENABLE_KEY: u16 = 0x5745;
/// How long writes stay enabled after the key or an accepted write, ms.
pub const WRITE_ENABLE_MS: u64 = 60_000;
/// Dark calibration trigger: reads 0; writing 1 runs the guarded dark
/// calibration (as the button on a dry face).
pub const DARK_CALIBRATE: u16 = 101;
/// The result of the last command written ([`CommandResult`]).
pub const LAST_RESULT: u16 = 102;
/// The link protocol (0 framed, 1 Modbus RTU): writing 0 switches the node
/// back to the framed protocol (saved, in force after the answer).
pub const LINK_PROTOCOL: u16 = 103;
/// The node's Modbus address, 1–247 (in force after the answer).
pub const MODBUS_ADDRESS: u16 = 104;
/// The parity and stop bits: 0 8E1, 1 8N2, 2 8N1 (in force after the answer).
pub const PARITY: u16 = 105;
/// Config `freeze_limit_centi_c` (i16, 0.01 °C).
pub const FREEZE_LIMIT: u16 = 106;
/// Config `thaw_limit_centi_c` (i16, 0.01 °C).
pub const THAW_LIMIT: u16 = 107;
/// Config `onset_frames`.
pub const ONSET_FRAMES: u16 = 108;
/// Config `clear_frames`.
pub const CLEAR_FRAMES: u16 = 109;
/// Registers in the node-only block.
pub const NODE_REGISTERS: usize = 10;

/// What [`LAST_RESULT`] reads after a command written over Modbus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u16)]
pub enum CommandResult {
    /// No command yet.
    None = 0,
    /// Done (alarm acknowledged, calibrated, config changed).
    Done = 1,
    /// The alarm acknowledge found no alarm.
    NoAlarm = 2,
    /// The dark calibration was refused (face not dry, baseline shift,
    /// noise, step, trend, saturation).
    Refused = 3,
    /// The config rule refused the value.
    InvalidConfig = 4,
}

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

/// Who serves a register.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Served {
    /// The gateway (Modbus TCP) and the node (Modbus RTU) alike.
    Both,
    /// Only the gateway; the node reads it as "not available".
    Gateway,
    /// Only the node (its config and commands).
    Node,
}

impl Served {
    /// Its name in the table.
    pub const fn name(self) -> &'static str {
        match self {
            Served::Both => "both",
            Served::Gateway => "gateway",
            Served::Node => "node",
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
    /// Who serves it.
    pub served: Served,
    /// Written by a master (function codes 06, 16).
    pub writable: bool,
    /// What it is.
    pub what: &'static str,
}

#[allow(clippy::too_many_arguments)]
const fn field(
    address: u16,
    name: &'static str,
    kind: Kind,
    scale: f64,
    unit: &'static str,
    served: Served,
    writable: bool,
    what: &'static str,
) -> Field {
    Field {
        address,
        name,
        kind,
        scale,
        unit,
        served,
        writable,
        what,
    }
}

use Served::{Both, Gateway, Node};

/// The measurement block, in address order: what [`measurement_registers`]
/// writes and both READMEs show.
pub const TABLE: [Field; 20] = [
    field(
        STATUS,
        "status",
        Kind::Bits,
        1.0,
        "",
        Both,
        false,
        "bit 0 ice alarm output on, 1 alarm acknowledged, 2 ice, 3 link up, 4 stale, 5 measurement present, 6 currents valid, 7 ice estimate present, 8 gain present, 9 dark baseline stored, 10 any fault, 11 icing rate present, 12 accreting",
    ),
    field(
        STATE,
        "state",
        Kind::Enum,
        1.0,
        "",
        Both,
        false,
        "detector state: 0 dry, 1 wet, 2 ice",
    ),
    field(
        FAULTS,
        "faults",
        Kind::Bits,
        1.0,
        "",
        Both,
        false,
        "the node's fault bits: 2 ntc_open, 3 ntc_short, 4 config_defaulted, 8 vdda_out_of_range, 9 storage_failed, 10 clock_fallback, 11 bor_not_set, 12 store_skipped, 13 gain_out_of_band",
    ),
    field(
        I1,
        "i1",
        Kind::I32,
        0.001,
        "µA",
        Both,
        false,
        "net photocurrent, channel 1",
    ),
    field(
        I2,
        "i2",
        Kind::I32,
        0.001,
        "µA",
        Both,
        false,
        "net photocurrent, channel 2",
    ),
    field(
        TEMPERATURE,
        "temperature",
        Kind::I16,
        0.01,
        "°C",
        Both,
        false,
        "air temperature",
    ),
    field(
        THICKNESS,
        "thickness",
        Kind::U16,
        0.001,
        "mm",
        Both,
        false,
        "estimated thickness of the cover",
    ),
    field(
        THICKNESS_SIGMA,
        "thickness_sigma",
        Kind::U16,
        0.001,
        "mm",
        Both,
        false,
        "its standard deviation",
    ),
    field(
        MEDIUM,
        "medium",
        Kind::Enum,
        1.0,
        "",
        Both,
        false,
        "estimated medium: 0 dry, 1 water, 2 glazed, 3 rime",
    ),
    field(
        MEDIUM_PROBABILITY,
        "medium_probability",
        Kind::U16,
        0.001,
        "",
        Both,
        false,
        "its probability, 0–1",
    ),
    field(
        GAIN,
        "gain",
        Kind::U32,
        0.000_001,
        "",
        Both,
        false,
        "optical gain estimate (1 = the response table's gain)",
    ),
    field(
        GAIN_SIGMA,
        "gain_sigma",
        Kind::U32,
        0.000_001,
        "",
        Both,
        false,
        "its standard deviation",
    ),
    field(
        DATA_AGE,
        "data_age",
        Kind::U32,
        0.001,
        "s",
        Gateway,
        false,
        "age of the latest measurement (at the gateway)",
    ),
    field(
        SEQ,
        "seq",
        Kind::U32,
        1.0,
        "",
        Both,
        false,
        "the latest measurement frame's sequence number",
    ),
    field(
        VDDA,
        "vdda",
        Kind::U16,
        1.0,
        "mV",
        Both,
        false,
        "the node's analog supply",
    ),
    field(
        FRAMES_LOST,
        "frames_lost",
        Kind::U32,
        1.0,
        "",
        Gateway,
        false,
        "frames lost on the serial link since the gateway started",
    ),
    field(
        ACK,
        "alarm_ack",
        Kind::U16,
        1.0,
        "",
        Both,
        true,
        "reads 0; write 1 (FC 06 or 16) to acknowledge the alarm (gateway: with `commands = true`; node: with writes enabled)",
    ),
    field(
        ICING_RATE,
        "icing_rate",
        Kind::I16,
        0.01,
        "mm/h",
        Both,
        false,
        "icing rate, once the node reports it",
    ),
    field(
        ICING_RATE_SIGMA,
        "icing_rate_sigma",
        Kind::U16,
        0.01,
        "mm/h",
        Both,
        false,
        "its standard deviation",
    ),
    field(
        ACCRETING_PROBABILITY,
        "accreting_probability",
        Kind::U16,
        0.001,
        "",
        Both,
        false,
        "probability that ice is accreting now, 0–1",
    ),
];

/// The node-only block (holding registers from [`NODE_BASE`]).
pub const NODE_TABLE: [Field; NODE_REGISTERS] = [
    field(
        WRITE_ENABLE,
        "write_enable",
        Kind::U16,
        1.0,
        "",
        Node,
        true,
        "reads 1 while writes are enabled; write 0x5745 to enable them for 60 s (each accepted write restarts the time), 0 to disable",
    ),
    field(
        DARK_CALIBRATE,
        "dark_calibrate",
        Kind::U16,
        1.0,
        "",
        Node,
        true,
        "reads 0; write 1 to run the guarded dark calibration (as the button on a dry face)",
    ),
    field(
        LAST_RESULT,
        "last_result",
        Kind::Enum,
        1.0,
        "",
        Node,
        false,
        "the last written command's result: 0 none, 1 done, 2 no alarm, 3 calibration refused, 4 config refused",
    ),
    field(
        LINK_PROTOCOL,
        "link_protocol",
        Kind::Enum,
        1.0,
        "",
        Node,
        true,
        "0 framed, 1 Modbus RTU; write 0 to switch back to the framed protocol",
    ),
    field(
        MODBUS_ADDRESS,
        "modbus_address",
        Kind::U16,
        1.0,
        "",
        Node,
        true,
        "the node's Modbus address, 1–247",
    ),
    field(
        PARITY,
        "parity",
        Kind::Enum,
        1.0,
        "",
        Node,
        true,
        "0 8E1, 1 8N2, 2 8N1",
    ),
    field(
        FREEZE_LIMIT,
        "freeze_limit",
        Kind::I16,
        0.01,
        "°C",
        Node,
        true,
        "config `freeze_limit_centi_c`",
    ),
    field(
        THAW_LIMIT,
        "thaw_limit",
        Kind::I16,
        0.01,
        "°C",
        Node,
        true,
        "config `thaw_limit_centi_c`",
    ),
    field(
        ONSET_FRAMES,
        "onset_frames",
        Kind::U16,
        1.0,
        "",
        Node,
        true,
        "config `onset_frames`",
    ),
    field(
        CLEAR_FRAMES,
        "clear_frames",
        Kind::U16,
        1.0,
        "",
        Node,
        true,
        "config `clear_frames`",
    ),
];

/// A register table as the READMEs show it (Markdown).
#[cfg(any(feature = "std", test))]
pub fn markdown_table(fields: &[Field]) -> std::string::String {
    use std::fmt::Write;
    let mut s = std::string::String::from(
        "| address | name | type | scale | unit | served by | what |\n| --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for f in fields {
        let addr = if f.kind.width() == 2 {
            std::format!("{}–{}", f.address, f.address + 1)
        } else {
            f.address.to_string()
        };
        let scale = if f.scale == 1.0 {
            "1".into()
        } else {
            std::format!("{}", f.scale)
        };
        let served = if f.writable {
            std::format!("{}, writable", f.served.name())
        } else {
            f.served.name().into()
        };
        let _ = writeln!(
            s,
            "| {addr} | `{}` | {} | {scale} | {} | {served} | {} |",
            f.name,
            f.kind.name(),
            if f.unit.is_empty() { "–" } else { f.unit },
            f.what
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_blocks_are_in_order_without_overlap_and_the_old_addresses_hold() {
        for table in [&TABLE[..], &NODE_TABLE[..]] {
            for w in table.windows(2) {
                assert!(w[0].address + w[0].kind.width() <= w[1].address, "{w:?}");
            }
        }
        let last = TABLE[TABLE.len() - 1];
        assert_eq!(usize::from(last.address + last.kind.width()), REGISTERS);
        let node_last = NODE_TABLE[NODE_REGISTERS - 1];
        assert_eq!(
            usize::from(node_last.address + 1 - NODE_BASE),
            NODE_REGISTERS
        );
        // The gateway's map before the icing rate: nothing renumbered.
        assert_eq!(
            [
                STATUS,
                STATE,
                FAULTS,
                I1,
                I2,
                TEMPERATURE,
                THICKNESS,
                THICKNESS_SIGMA
            ],
            [0, 1, 2, 3, 5, 7, 8, 9]
        );
        assert_eq!(
            [
                MEDIUM,
                MEDIUM_PROBABILITY,
                GAIN,
                GAIN_SIGMA,
                DATA_AGE,
                SEQ,
                VDDA,
                FRAMES_LOST,
                ACK
            ],
            [10, 11, 12, 14, 16, 18, 20, 21, 23]
        );
        assert_eq!(
            [ICING_RATE, ICING_RATE_SIGMA, ACCRETING_PROBABILITY],
            [24, 25, 26]
        );
    }
}
