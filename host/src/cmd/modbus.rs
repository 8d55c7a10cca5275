//! `foisctl modbus enable|read|write|framed`: a node that speaks Modbus
//! RTU on its link (protocol 5, `LinkSettings`). `enable` switches a node
//! from the framed protocol to Modbus (a framed `SetLinkSettings`); the
//! others are a small Modbus RTU master: FC 03/04 reads of the register map
//! (`fois_protocol::registers`, printed with names and scales), FC 06
//! writes behind the write enable, and `framed` the way back.
//!
//! The master is written here on the firmware's own CRC
//! (`fois_firmware::modbus::server::CRC16`): a Rust Modbus client crate
//! with RTU (tokio-modbus) would bring an async runtime into `foisctl`,
//! which holds none (ARCHITECTURE.md).

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use clap::{Args, Subcommand};
use fois_firmware::modbus::server::{CRC16, crc_ok};
use fois_protocol::registers::{self, Field, Kind, NODE_TABLE, TABLE};
use fois_protocol::{Command, LinkProtocol, LinkSettings, Parity};

use super::request::{RequestArgs, expect_ack};
use crate::exit::{self, Exit};

/// `foisctl modbus`.
#[derive(Debug, Args)]
pub struct ModbusArgs {
    /// What to do.
    #[command(subcommand)]
    pub cmd: ModbusCmd,
}

/// The `modbus` subcommands.
#[derive(Debug, Subcommand)]
pub enum ModbusCmd {
    /// Switch a node that speaks the framed protocol to Modbus RTU (saved;
    /// the node resets into it after its answer).
    #[command(after_help = exit::TABLE)]
    Enable(EnableArgs),
    /// Read registers (FC 03 or 04) and print them with their names and
    /// scales.
    #[command(after_help = exit::TABLE)]
    Read(ReadArgs),
    /// Write registers (FC 06, each), after enabling writes; prints the
    /// node's `last_result`.
    #[command(after_help = exit::TABLE)]
    Write(WriteArgs),
    /// Switch a Modbus node back to the framed protocol (writes 0 to
    /// `link_protocol`).
    #[command(after_help = exit::TABLE)]
    Framed(MasterArgs),
}

/// `foisctl modbus enable`.
#[derive(Debug, Args)]
pub struct EnableArgs {
    /// The framed link to the node.
    #[command(flatten)]
    pub request: RequestArgs,
    /// The node's Modbus address (1–247).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=247))]
    pub address: u8,
    /// Parity and stop bits: 8E1 (the Modbus default), 8N2 or 8N1.
    #[arg(long, default_value = "8E1", value_parser = parse_parity)]
    pub parity: Parity,
}

/// The Modbus link to a node.
#[derive(Debug, Clone, Args)]
pub struct MasterArgs {
    /// Serial port of the node (a `foisctl virtual-node --modbus-rtu` prints
    /// its /dev/pts/N).
    #[arg(long, short = 'p', value_name = "PATH")]
    pub port: String,
    /// Baud rate (the node's strap: 115 200 or 19 200).
    #[arg(long, default_value_t = 19_200, value_parser = clap::value_parser!(u32).range(1..))]
    pub baud: u32,
    /// Parity and stop bits: 8E1, 8N2 or 8N1.
    #[arg(long, default_value = "8E1", value_parser = parse_parity)]
    pub parity: Parity,
    /// The node's Modbus address.
    #[arg(long, short = 'a', value_name = "N", value_parser = clap::value_parser!(u8).range(1..=247))]
    pub address: u8,
    /// How long to wait for each answer, ms.
    #[arg(long, default_value_t = 1_000, value_name = "MS")]
    pub timeout_ms: u64,
}

/// `foisctl modbus read`.
#[derive(Debug, Args)]
pub struct ReadArgs {
    /// The link.
    #[command(flatten)]
    pub master: MasterArgs,
    /// First register (0-based address).
    #[arg(long, default_value_t = 0)]
    pub start: u16,
    /// How many registers (1–125).
    #[arg(long, default_value_t = registers::REGISTERS as u16,
          value_parser = clap::value_parser!(u16).range(1..=125))]
    pub count: u16,
    /// Function code: 3 (holding) or 4 (input registers).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u8).range(3..=4))]
    pub function: u8,
}

/// `foisctl modbus write`.
#[derive(Debug, Args)]
pub struct WriteArgs {
    /// The link.
    #[command(flatten)]
    pub master: MasterArgs,
    /// NAME=VALUE or ADDRESS=VALUE, the raw register value (e.g.
    /// `alarm_ack=1`, `freeze_limit=-150` for −1.50 °C, `104=5`).
    #[arg(required = true, value_name = "REG=VALUE")]
    pub writes: Vec<String>,
}

/// A parity name (8E1, 8N2, 8N1), for clap.
pub fn parse_parity(s: &str) -> Result<Parity, String> {
    [Parity::Even8E1, Parity::None8N2, Parity::None8N1]
        .into_iter()
        .find(|p| p.name().eq_ignore_ascii_case(s))
        .ok_or_else(|| format!("`{s}`: one of 8E1, 8N2, 8N1"))
}

/// Run `foisctl modbus`.
pub fn run(args: ModbusArgs) -> anyhow::Result<()> {
    match args.cmd {
        ModbusCmd::Enable(a) => {
            let settings = LinkSettings {
                protocol: LinkProtocol::ModbusRtu,
                modbus_address: a.address,
                parity: a.parity,
            };
            let (mut link, hello) = a.request.connect_hello()?;
            if hello.protocol_version < 5 {
                return Err(Exit::new(
                    exit::INCOMPATIBLE,
                    format!(
                        "the node speaks protocol {}; Modbus RTU needs 5",
                        hello.protocol_version
                    ),
                )
                .into());
            }
            let reply = link.request(Command::SetLinkSettings(settings), a.request.timeout())?;
            expect_ack(reply)?;
            println!(
                "the node resets into Modbus RTU, address {}, {}",
                a.address,
                a.parity.name()
            );
            Ok(())
        }
        ModbusCmd::Read(a) => {
            let mut m = Master::open(&a.master)?;
            let words = m.read(a.function, a.start, a.count)?;
            for (i, w) in words.iter().enumerate() {
                let addr = a.start + i as u16;
                println!("{}", describe(addr, &words[i..], *w));
            }
            Ok(())
        }
        ModbusCmd::Write(a) => {
            let mut m = Master::open(&a.master)?;
            let writes = a
                .writes
                .iter()
                .map(|w| parse_write(w))
                .collect::<Result<Vec<_>, _>>()?;
            m.write(registers::WRITE_ENABLE, registers::WRITE_ENABLE_KEY)?;
            for (addr, v) in writes {
                m.write(addr, v)?;
                println!("wrote {v} to {addr}");
            }
            // The node carries a write out after its answer.
            std::thread::sleep(Duration::from_millis(200));
            let r = m.read(3, registers::LAST_RESULT, 1)?;
            println!("{}", describe(registers::LAST_RESULT, &r, r[0]));
            Ok(())
        }
        ModbusCmd::Framed(a) => {
            let mut m = Master::open(&a)?;
            m.write(registers::WRITE_ENABLE, registers::WRITE_ENABLE_KEY)?;
            m.write(registers::LINK_PROTOCOL, 0)?;
            println!(
                "the node resets into the framed protocol: foisctl monitor --port {} --baud {}",
                a.port, a.baud
            );
            Ok(())
        }
    }
}

fn field(addr: u16) -> Option<&'static Field> {
    TABLE
        .iter()
        .chain(NODE_TABLE.iter())
        .find(|f| f.address == addr)
}

/// `NAME=VALUE` or `ADDRESS=VALUE` (a signed value for an i16 register).
fn parse_write(s: &str) -> anyhow::Result<(u16, u16)> {
    let bad = || Exit::new(exit::USAGE, format!("`{s}`: expected REG=VALUE"));
    let (k, v) = s.split_once('=').ok_or_else(bad)?;
    let addr = match k.parse::<u16>() {
        Ok(a) => a,
        Err(_) => field_named(k).ok_or_else(bad)?.address,
    };
    let v = match v.parse::<u16>() {
        Ok(v) => v,
        Err(_) => v.parse::<i16>().map_err(|_| bad())? as u16,
    };
    Ok((addr, v))
}

fn field_named(name: &str) -> Option<&'static Field> {
    TABLE
        .iter()
        .chain(NODE_TABLE.iter())
        .find(|f| f.name == name)
}

/// One register as a line: address, name, raw, value in its unit.
fn describe(addr: u16, rest: &[u16], raw: u16) -> String {
    let Some(f) = field(addr) else {
        return format!("{addr:>5}  {raw:>6}");
    };
    let value = match f.kind {
        Kind::U32 | Kind::I32 if rest.len() >= 2 => {
            let v = (u32::from(rest[0]) << 16) | u32::from(rest[1]);
            match f.kind {
                Kind::I32 if v == registers::NA_I32 => "n/a".into(),
                Kind::U32 if v == registers::NA_U32 => "n/a".into(),
                Kind::I32 => format!("{}", f64::from(v as i32) * f.scale),
                _ => format!("{}", f64::from(v) * f.scale),
            }
        }
        Kind::I16 if raw == registers::NA_I16 => "n/a".into(),
        Kind::I16 => format!("{}", f64::from(raw as i16) * f.scale),
        Kind::U16 | Kind::Enum if raw == registers::NA_U16 => "n/a".into(),
        Kind::Bits => format!("{raw:#06x}"),
        _ => format!("{}", f64::from(raw) * f.scale),
    };
    format!("{addr:>5}  {raw:>6}  {:<22} {value} {}", f.name, f.unit)
}

/// A Modbus RTU master on a serial port.
pub struct Master {
    port: Box<dyn serialport::SerialPort>,
    address: u8,
    timeout: Duration,
}

impl Master {
    /// Open the port with the link's parity.
    pub fn open(a: &MasterArgs) -> anyhow::Result<Master> {
        let (parity, stop) = match a.parity {
            Parity::Even8E1 => (serialport::Parity::Even, serialport::StopBits::One),
            Parity::None8N2 => (serialport::Parity::None, serialport::StopBits::Two),
            Parity::None8N1 => (serialport::Parity::None, serialport::StopBits::One),
        };
        let port = serialport::new(&a.port, a.baud)
            .parity(parity)
            .stop_bits(stop)
            .timeout(Duration::from_millis(20))
            .open()
            .map_err(|e| Exit::new(exit::PORT, format!("cannot open {}: {e}", a.port)))?;
        Ok(Master {
            port,
            address: a.address,
            timeout: Duration::from_millis(a.timeout_ms),
        })
    }

    /// FC 03/04: `count` registers from `start`.
    pub fn read(&mut self, function: u8, start: u16, count: u16) -> anyhow::Result<Vec<u16>> {
        let mut req = vec![self.address, function];
        req.extend(start.to_be_bytes());
        req.extend(count.to_be_bytes());
        let r = self.transact(&req)?;
        let data = r.get(3..r.len() - 2).unwrap_or(&[]);
        Ok(data
            .chunks_exact(2)
            .map(|w| u16::from_be_bytes([w[0], w[1]]))
            .collect())
    }

    /// FC 06: one register.
    pub fn write(&mut self, addr: u16, value: u16) -> anyhow::Result<()> {
        let mut req = vec![self.address, 6];
        req.extend(addr.to_be_bytes());
        req.extend(value.to_be_bytes());
        self.transact(&req).map(|_| ())
    }

    fn transact(&mut self, body: &[u8]) -> anyhow::Result<Vec<u8>> {
        let mut req = body.to_vec();
        req.extend(CRC16.checksum(body).to_le_bytes());
        let _ = self.port.clear(serialport::ClearBuffer::Input);
        self.port.write_all(&req)?;
        self.port.flush()?;
        let deadline = Instant::now() + self.timeout;
        let mut got = Vec::new();
        let mut buf = [0u8; 256];
        loop {
            if let Some(n) = answer_len(&got)
                && got.len() >= n
            {
                got.truncate(n);
                break;
            }
            if Instant::now() >= deadline {
                return Err(Exit::new(
                    exit::TIMEOUT,
                    format!(
                        "no answer from address {} within {:?}",
                        self.address, self.timeout
                    ),
                )
                .into());
            }
            match self.port.read(&mut buf) {
                Ok(n) => got.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => return Err(e.into()),
            }
        }
        if !crc_ok(&got) || got.first() != Some(&self.address) {
            anyhow::bail!("a garbled answer: {got:02x?}");
        }
        // The silence before the next request (3.5 characters).
        std::thread::sleep(Duration::from_millis(5));
        if got.get(1).is_some_and(|f| f & 0x80 != 0) {
            let code = got.get(2).copied().unwrap_or(0);
            return Err(Exit::new(
                exit::REFUSED,
                format!("exception {code:02}: {}", exception_text(code)),
            )
            .into());
        }
        Ok(got)
    }
}

/// The length of the answer whose first bytes are `got`, once known.
fn answer_len(got: &[u8]) -> Option<usize> {
    let fc = *got.get(1)?;
    if fc & 0x80 != 0 {
        return Some(5);
    }
    match fc {
        3 | 4 => got.get(2).map(|n| 5 + usize::from(*n)),
        _ => Some(8),
    }
}

fn exception_text(code: u8) -> &'static str {
    match code {
        1 => "illegal function",
        2 => "illegal data address",
        3 => "illegal data value",
        4 => "server device failure (writes not enabled?)",
        _ => "unknown",
    }
}
