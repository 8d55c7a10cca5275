#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`messages`]: every message of both directions, the flags.
//! - [`config`]: the node's configuration and its one validation rule.
//! - [`framing`]: COBS + CRC-32 frames, the streaming decoder.
//! - [`seq`]: the sequence-gap rule (lost frames, restarts) every host reader uses.
//! - [`link_settings`]: version 5, the host link's protocol (framed or Modbus RTU) and its Modbus settings.
//! - [`registers`]: the Modbus register map the node (RTU) and the gateway (TCP) serve.
//! - [`update`]: version 6, a firmware image over the link: the transfer's messages and the signed image's trailer.

#![cfg_attr(not(any(feature = "std", test)), no_std)]

pub mod config;
pub mod framing;
pub mod link_settings;
pub mod messages;
pub mod registers;
pub mod seq;
pub mod update;

pub use config::{Config, ConfigError, ConfigField, ConfigV1, FIELDS, FieldSpec, LOAD_R_MAX_OHM};
#[cfg(any(feature = "std", test))]
pub use framing::encode_to_vec;
pub use framing::{
    DecodeStats, EncodeError, FrameDecoder, FrameError, MAX_FRAME, MAX_PAYLOAD, encode,
};
pub use link_settings::{LinkProtocol, LinkSettings, LinkSettingsError, Parity};
pub use messages::*;
pub use seq::{SeqEvent, SeqTracker};
pub use update::{
    ChunkData, FirmwareVersion, ImageInfo, ImageSignature, ImageState, ImageTrailer,
    UPDATE_CHUNK_MAX, UpdateBegin, UpdateChunk, UpdatePhase, UpdateRefusal, UpdateStatus,
};

/// The protocol version this crate speaks (in [`Hello::protocol_version`]).
/// Bump it on any breaking change (see `protocol/README.md`, Compatibility).
pub const PROTOCOL_VERSION: u16 = 6;

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
