#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`cmd`]: one module per command, each owning its arguments and its `run`.
//! - [`link`]: the serial link (handshake, commands, sequence tracking).
//! - [`monitor`]: the live session behind `monitor` and `demo`; [`csvlog`] its durable CSV log.
//! - [`serve`]: a virtual node on a pseudo-terminal.
//! - [`estimate`]: a log or a simulated curve replayed through the node's ice estimator.
//! - [`compare`]: a log against the simulator's band; [`plot`]: every figure.
//! - [`exit`]: the exit codes; [`text`], [`timefmt`], [`mod@bench`]: helpers.

pub mod bench;
pub mod cmd;
pub mod compare;
pub mod csvlog;
pub mod estimate;
pub mod exit;
pub mod link;
pub mod monitor;
pub mod plot;
pub mod serve;
pub mod text;
pub mod timefmt;
