#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`hal`]: the hardware seams ([`hal::PhotoAdc`], [`hal::Storage`], board info).
//! - [`node::Node`]: the whole node behind them.
//! - [`measure`], [`ntc`], [`vref`], [`rule`], [`persist`], [`dispatch`]: the pure parts.
//! - [`estimator`]: ice thickness ± σ and medium (grid Bayes filter on the simulator's table).
//! - `sim_board` (feature `sim-board`): a scripted simulated board for tests.

#![cfg_attr(not(test), no_std)]

pub mod dispatch;
pub mod estimator;
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
