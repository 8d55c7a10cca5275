//! FOIS node logic, free of any HAL: measurement maths, the ice rule, config
//! handling and command dispatch. Runs on the board, in host tests, in the
//! host's virtual node, in the hardware-in-loop suite and on an emulated
//! Cortex-M4F (`firmware/qemu-test`).
//!
//! - [`hal`]: the hardware seams ([`hal::PhotoAdc`], [`hal::Storage`], board info).
//! - [`node::Node`]: the whole node behind them.
//! - [`measure`], [`ntc`], [`vref`], [`rule`], [`persist`], [`dispatch`]: the pure parts.
//! - [`estimator`]: ice thickness ± σ and medium (grid Bayes filter on the simulator's table).
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
#![deny(clippy::unwrap_used, clippy::expect_used)]

pub mod dispatch;
pub mod estimator;
pub mod hal;
pub mod measure;
pub mod node;
pub mod ntc;
pub mod persist;
pub mod rule;
pub mod vref;

pub use hal::{BoardInfo, FactoryCal, MemStorage, PhotoAdc, Storage, StorageError};
pub use node::Node;
