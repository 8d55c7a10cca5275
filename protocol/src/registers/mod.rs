//! The Modbus register map: one definition for the node's own Modbus RTU
//! link (`fois_firmware::modbus`) and the gateway's Modbus TCP server
//! (`fois_gateway::modbus`).
//!
//! Addresses, types, scales, the "not available" values, the status bits
//! and which register is served where are defined here once;
//! [`measurement_registers`] writes the measurement block from the wire's
//! own integers, so a register read over TCP (gateway) and over RTU (node)
//! gives the same value for the same measurement.
//!
//! Conventions:
//! - function codes 03 (holding) and 04 (input registers) read the same table;
//! - a 32-bit value takes two registers, the high word first;
//! - a value not known (no measurement yet, no ice estimate, no gain, no
//!   icing rate) reads as "not available": [`NA_I16`], [`NA_U16`] (also
//!   enums), [`NA_I32`], [`NA_U32`]; the status word says which parts are
//!   present;
//! - the measurement block is addresses `0..REGISTERS`; registers are only
//!   ever appended, never renumbered. The node-only block (its config and
//!   commands) starts at [`NODE_BASE`].
//!
//! Files: [`table`] (the definition), [`mapping`] (a measurement as
//! registers); everything is re-exported here.

pub mod mapping;
pub mod table;

pub use mapping::*;
pub use table::*;
