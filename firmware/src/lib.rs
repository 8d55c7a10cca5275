//! FOIS node logic, free of any HAL: measurement maths, the ice rule, config
//! handling and command dispatch. Runs on the board, in host tests, in the
//! host's virtual node, in the hardware-in-loop suite and on an emulated
//! Cortex-M4F (`firmware/qemu-test`).
//!
//! - [`hal`]: the hardware seams ([`hal::PhotoAdc`], [`hal::Storage`], board info).
//! - [`node::Node`]: the whole node behind them.
//! - [`measure`], [`ntc`], [`vref`], [`rule`], [`persist`], [`dispatch`]: the pure parts.
#![cfg_attr(not(test), no_std)]

pub mod dispatch;
pub mod hal;
pub mod measure;
pub mod node;
pub mod ntc;
pub mod persist;
pub mod rule;
#[cfg(feature = "sim-board")]
pub mod sim_board;
pub mod vref;

pub use hal::{BoardInfo, FactoryCal, MemStorage, PhotoAdc, Storage, StorageError};
pub use node::Node;
