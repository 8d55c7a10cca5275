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
//! - [`signed_image`]: a signed firmware image file (body, trailer,
//!   signature), its digest and the transfer's begin.
//! - [`update`]: the firmware update driver (begin, chunks, verify, commit,
//!   the new image's confirmation), with retries and resume; its steps,
//!   events, report and errors (`update_error`); `update_trial` its wait
//!   for the new image's boot and verdict; [`update_timing`] its throughput
//!   model.
//! - `update_fake` (feature `fixtures`): a scripted node that follows the
//!   update protocol, for the driver's tests and the gateway's.
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
pub mod signed_image;
pub mod text;
pub mod timefmt;
pub mod update;
mod update_error;
#[cfg(any(test, feature = "fixtures"))]
pub mod update_fake;
#[cfg(test)]
mod update_tests;
pub mod update_timing;
mod update_trial;
pub mod versioned;

pub use link::{Incoming, Link, LinkError, Reply, open_port};
pub use reading::{EstimateReading, EventReading, GainReading, IcingReading, Reading};
