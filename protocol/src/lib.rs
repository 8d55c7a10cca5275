#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`messages`]: every message of both directions, the flags.
//! - [`config`]: the node's configuration and its one validation rule.
//! - [`framing`]: COBS + CRC-32 frames, the streaming decoder.
//! - [`seq`]: the sequence-gap rule (lost frames, restarts) every host reader uses.

#![cfg_attr(not(any(feature = "std", test)), no_std)]

pub mod config;
pub mod framing;
pub mod messages;
pub mod seq;

pub use config::{Config, ConfigError, ConfigField, ConfigV1, FIELDS, FieldSpec, LOAD_R_MAX_OHM};
#[cfg(any(feature = "std", test))]
pub use framing::encode_to_vec;
pub use framing::{
    DecodeStats, EncodeError, FrameDecoder, FrameError, MAX_FRAME, MAX_PAYLOAD, encode,
};
pub use messages::*;
pub use seq::{SeqEvent, SeqTracker};

/// The protocol version this crate speaks (in [`Hello::protocol_version`]).
/// Bump it on any breaking change (see `protocol/README.md`, Compatibility).
pub const PROTOCOL_VERSION: u16 = 5;

/// The oldest protocol version a host built from this crate still reads.
/// Every version only adds variants at the end of its enums, so a frame of
/// an older version decodes with today's types (a fleet is never upgraded
/// at once).
pub const OLDEST_READABLE_VERSION: u16 = 1;

/// Baud rate of the node's UART link (ST-LINK virtual COM port), 8N1.
pub const BAUD_RATE: u32 = 115_200;

/// How long a host waits for the `Ack` or `Error` of a command, ms. The
/// node answers every command within its worst case (`fois_firmware::
/// platform::reply_time::WORST_REPLY_MS`, 5.829 s: the command lands just as the node
/// starts its longest frame and a save that erases a flash sector, and it
/// is a dark calibration of its longest averaging time behind a full
/// transmit pipe at the slowest link rate), which the firmware
/// checks at compile time to stay below this with 2 s to spare for the
/// host's own latency.
pub const REPLY_TIMEOUT_MS: u64 = 8_000;
