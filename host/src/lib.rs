#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`cmd`]: one module per command, each owning its arguments and its `run`.
//! - [`link`]: the serial link (handshake, commands, sequence tracking).
//! - [`monitor`]: the live session behind `monitor` and `demo`; [`csvlog`] its durable CSV log.
//! - [`serve`]: a virtual node on a pseudo-terminal.
//! - [`estimate`]: a log or a simulated curve replayed through the node's ice estimator.
//! - [`gateway`]: the fleet gateway to an MQTT broker (node readers, publisher,
//!   disk queue, topics, payloads, Home Assistant discovery).
//! - [`compare`]: a log against the simulator's band; [`plot`]: every figure.
//! - [`exit`]: the exit codes; [`text`], [`timefmt`], [`mod@bench`]: helpers.

pub mod bench;
pub mod cmd;
pub mod compare;
pub mod csvlog;
pub mod estimate;
pub mod exit;
pub mod gateway;
pub mod link;
pub mod monitor;
pub mod plot;
pub mod serve;
pub mod text;
pub mod timefmt;
