//! FOIS node logic, free of any HAL: measurement maths, the ice rule, config
//! handling and command dispatch. Runs on the board, in host tests, in the
//! host's virtual node, in the hardware-in-loop suite and on an emulated
//! Cortex-M4F (`firmware/qemu-test`).
//!
//! - [`hal`]: the hardware seams ([`hal::PhotoAdc`], [`hal::Storage`], board info).
//! - [`flash_store::FlashStore`]: the [`hal::Storage`] on NOR flash
//!   (sequential-storage); [`ram_flash::RamFlash`]: a NOR flash in RAM that
//!   can lose power mid-operation.
//! - [`node::Node`]: the whole node behind them; [`schedule::Schedule`]: when
//!   it sends `Hello` and runs its frames.
//! - [`measure`], [`ntc`], [`vref`], [`rule`], [`persist`], [`dispatch`]: the pure parts.
//! - [`watchdog`]: the IWDG prescaler, reload and timeout arithmetic the board
//!   programs.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
#![deny(clippy::unwrap_used, clippy::expect_used)]

pub mod dispatch;
pub mod flash_store;
pub mod hal;
pub mod measure;
pub mod node;
pub mod ntc;
pub mod persist;
pub mod ram_flash;
pub mod rule;
pub mod schedule;
pub mod vref;
pub mod watchdog;

pub use hal::{BoardInfo, FactoryCal, MemStorage, PhotoAdc, Storage, StorageError};
pub use node::Node;
