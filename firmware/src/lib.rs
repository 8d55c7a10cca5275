#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`hal`]: the hardware seams ([`hal::PhotoAdc`], [`hal::Storage`], board info).
//! - [`flash_store::FlashStore`]: the [`hal::Storage`] on NOR flash
//!   (sequential-storage); [`ram_flash::RamFlash`]: a NOR flash in RAM that
//!   can lose power mid-operation.
//! - [`node::Node`]: the whole node behind them; [`schedule::Schedule`]: when
//!   it sends `Hello` and runs its frames.
//! - [`measure`], [`ntc`], [`vref`], [`rule`], [`persist`], [`dispatch`]: the pure parts.
//! - [`dark_cal`]: the dark calibration under noise (how long to average, trend and step tests).
//! - [`boot`]: what survives a reset (panic resets in a row, the rule's state) and what a boot does
//!   with it; [`supply`]: flash writes wait for a healthy supply; [`field_link`]: baud rates,
//!   their error against the node's clock, the RS-485 turn-taking.
//! - [`watchdog`]: the IWDG prescaler, reload and timeout arithmetic the board
//!   programs; [`reply_time`]: the worst time to answer a command (the
//!   host's timeout).
//! - [`estimator`]: ice thickness ± σ, medium and the sensor's optical gain (a bank of grid Bayes
//!   filters over gain hypotheses, on the simulator's table); [`gain_cal`]: the gain's
//!   calibration against a target, its kept prior, its saves and the out-of-band flag.
//! - `sim_board` (feature `sim-board`): a scripted simulated board for tests.

#![cfg_attr(not(test), no_std)]

pub mod boot;
pub mod dark_cal;
pub mod dispatch;
pub mod estimator;
pub mod field_link;
pub mod flash_store;
pub mod gain_cal;
pub mod hal;
pub mod measure;
pub mod node;
pub mod ntc;
pub mod persist;
pub mod ram_flash;
pub mod reply_time;
pub mod rule;
pub mod schedule;
#[cfg(feature = "sim-board")]
pub mod sim_board;
pub mod supply;
pub mod vref;
pub mod watchdog;

pub use hal::{BoardInfo, FactoryCal, MemStorage, PhotoAdc, Storage, StorageError};
pub use node::Node;
