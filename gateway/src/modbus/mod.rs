//! Modbus TCP for SCADA: each node's latest state ([`crate::snapshot`]) as
//! a table of 16-bit registers, one Modbus unit id per node
//! ([`crate::config::ModbusConfig::units`]). The table is defined once, in
//! [`fois_protocol::registers`] (shared with the node's own Modbus RTU
//! link); [`register_map`] fills it from the node's [`fois_link::Reading`]
//! taken back to the wire's integers, through the same mapping the node
//! uses;
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
use fois_protocol::registers::{self, Sample};
pub use fois_protocol::registers::{
    ACCRETING_PROBABILITY, ACK, ACK_VALUE, DATA_AGE, FAULTS, FRAMES_LOST, Field, GAIN, GAIN_SIGMA,
    I1, I2, ICING_RATE, ICING_RATE_SIGMA, Kind, MEDIUM, MEDIUM_PROBABILITY, NA_I16, NA_I32, NA_U16,
    NA_U32, REGISTERS, SEQ, STATE, STATUS, TABLE, TEMPERATURE, THICKNESS, THICKNESS_SIGMA, VDDA,
    medium_code, state_code, status,
};
use fois_protocol::{GainEstimate, IceEstimate, IcingEstimate, Measurement};

use crate::snapshot::NodeSnapshot;

/// The register table of one node at `now`: what a Modbus client reads
/// from the node's unit. The measurement block is written by the one
/// mapping the node's own Modbus RTU link uses
/// ([`fois_protocol::registers::measurement_registers`]), from the wire's
/// integers of the reading; the gateway adds its own registers (data age,
/// frames lost) and status bits (link up, stale).
pub fn register_map(node: &NodeSnapshot, now: Instant, stale_after: Duration) -> [u16; REGISTERS] {
    let mut r = registers::not_available();
    let mut bits = 0;
    if node.link_up {
        bits |= status::LINK_UP;
    }
    let age = node.age(now);
    if age.is_none_or(|a| a > stale_after) {
        bits |= status::STALE;
    }
    registers::set(&mut r, STATUS, bits);
    if let Some(a) = age {
        registers::set32(
            &mut r,
            DATA_AGE,
            u32::try_from(a.as_millis()).unwrap_or(NA_U32 - 1),
        );
    }
    registers::set32(
        &mut r,
        FRAMES_LOST,
        u32::try_from(node.frames_lost).unwrap_or(u32::MAX),
    );
    if let Some(reading) = &node.reading {
        let (m, estimate, gain) = wire_values(reading);
        let icing = wire_icing(reading);
        registers::measurement_registers(
            &mut r,
            &Sample {
                measurement: &m,
                seq: node.seq.unwrap_or(NA_U32),
                estimate: estimate.as_ref(),
                gain: gain.as_ref(),
                icing: icing.as_ref().map(registers::IcingRate::from),
            },
        );
        if node.seq.is_none() {
            registers::set32(&mut r, SEQ, NA_U32);
        }
    } else if let Some(seq) = node.seq {
        registers::set32(&mut r, SEQ, seq);
    }
    r
}

/// The wire's integers behind a reading: the inverse of
/// `fois_link::reading`'s unit conversions (exact for every value the wire
/// carries; a value beyond the wire's range is clamped to it).
fn wire_values(r: &Reading) -> (Measurement, Option<IceEstimate>, Option<GainEstimate>) {
    fn int(x: f64, per_unit: f64, lo: i64, hi: i64) -> i64 {
        ((x * per_unit).round() as i64).clamp(lo, hi)
    }
    let i32_of = |x: f64, k: f64| int(x, k, i32::MIN.into(), i32::MAX.into()) as i32;
    let u32_of = |x: f64, k: f64| int(x, k, 0, u32::MAX.into()) as u32;
    let u16_of = |x: f64, k: f64| int(x, k, 0, u16::MAX.into()) as u16;
    let m = Measurement {
        uptime_ms: r.uptime_ms,
        i1_na: i32_of(r.i1_ua, 1e3),
        i2_na: i32_of(r.i2_ua, 1e3),
        ambient1_na: u32_of(r.ambient1_ua, 1e3),
        ambient2_na: u32_of(r.ambient2_ua, 1e3),
        temperature_centi_c: int(r.temperature_c, 1e2, i16::MIN.into(), i16::MAX.into()) as i16,
        vdda_mv: r.vdda_mv,
        flags: r.flags,
        state: r.state,
    };
    let estimate = r.estimate.map(|e| IceEstimate {
        thickness_um: u16_of(e.thickness_mm, 1e3),
        sigma_um: u16_of(e.thickness_sigma_mm, 1e3),
        medium: e.medium,
        probability_permille: u16_of(e.medium_probability, 1e3),
    });
    let gain = r.gain.map(|g| GainEstimate {
        gain_ppm: u32_of(g.gain, 1e6),
        sigma_ppm: u32_of(g.gain_sigma, 1e6),
    });
    (m, estimate, gain)
}

/// The icing rate's wire integers back from the reading (µm/h, ‰): the
/// inverse of `fois_link::IcingReading`'s mapping.
fn wire_icing(r: &Reading) -> Option<IcingEstimate> {
    let u16_of = |x: f64, k: f64| (x * k).round().clamp(0.0, f64::from(u16::MAX)) as u16;
    r.icing.map(|i| IcingEstimate {
        rate_um_per_h: u16_of(i.rate_mm_per_h, 1e3),
        sigma_um_per_h: u16_of(i.rate_sigma_mm_per_h, 1e3),
        accreting_permille: u16_of(i.accreting_probability, 1e3),
        accreting: i.accreting,
    })
}

/// The register table as the README shows it (Markdown): the measurement
/// block, which the gateway serves.
pub fn markdown_table() -> String {
    registers::markdown_table(&TABLE)
}

#[cfg(test)]
mod tests;
