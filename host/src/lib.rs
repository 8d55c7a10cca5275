#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`cmd`]: one module per command, each owning its arguments and its `run`.
//! - [`monitor`]: the live session behind `monitor` and `demo`; [`csvlog`] its durable CSV log;
//!   [`legend`] what its status lines mean; [`keys`] commands typed into it;
//!   [`status`] its status lines.
//! - [`estimate`]: a log or a simulated curve replayed through the node's ice estimator.
//! - [`icing`]: the icing report (`foisctl icing-report`): events, monthly totals, IEA ice class.
//! - [`compare`]: a log against the simulator's band; [`plot`]: every figure.
//! - [`signing`]: the update key pair's files, signing an application binary into a signed
//!   image, checking one (`keygen`, `sign`, `image-info`; `update` sends it with
//!   `fois_link::update`).
//! - [`exit`]: the exit codes; [`mod@bench`]: the decoder benchmark and the
//!   long-run check.
//!
//! The serial link, the message texts, the readings in SI units and the
//! timestamps are the `fois-link` crate's, shared with the fleet gateway
//! (`fois-gateway`); [`text`] is its message texts, re-exported.

pub mod bench;
pub mod cmd;
pub mod compare;
pub mod csvlog;
pub mod estimate;
pub mod exit;
pub mod icing;
pub mod keys;
pub mod legend;
pub mod monitor;
pub mod plot;
pub mod signing;
pub mod status;

pub use fois_link::text;
