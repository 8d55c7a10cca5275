#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`link`]: the serial link (open, handshake, commands, frames with their
//!   sequence events).
//! - [`log_row`]: one row of the monitor's CSV log (its columns), shared by
//!   `foisctl monitor` and the gateway's daily logs.
//! - [`reading`]: a measurement or event in µA, °C, mm, with fault names.
//! - [`text`]: one-line texts of protocol messages.
//! - [`advice`]: what to do after a calibration was refused.
//! - [`versioned`]: the dark-calibration and acknowledgement commands in the
//!   shape of the node's protocol version.
//! - [`timefmt`]: host timestamps (Unix ms, ISO 8601 UTC).
//! - [`numbers`]: finite-number parsers for command lines.
//! - `fixtures` (feature `fixtures`): test data, one iced node's measurement, estimate and
//!   gain.

pub mod advice;
#[cfg(any(test, feature = "fixtures"))]
pub mod fixtures;
pub mod link;
pub mod log_row;
pub mod numbers;
pub mod reading;
pub mod text;
pub mod timefmt;
pub mod versioned;

pub use link::{Incoming, Link, LinkError, Reply, open_port};
pub use reading::{EstimateReading, EventReading, GainReading, IcingReading, Reading};
