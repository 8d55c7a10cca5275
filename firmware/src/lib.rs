#![doc = include_str!("../README.md")]
//!
//! ## Layout
//!
//! - [`node`]: the [`Node`] the board, the virtual node and the HIL suite all
//!   drive — [`node::dispatch`] (the host's commands and the button),
//!   [`node::frame`] (one output frame: measure, rule, estimate, report),
//!   [`node::saving`] (when the record is written), [`node::gain_keeping`]
//!   (the learned gain: prior, out-of-band flag, when it is kept).
//! - [`ice_rule`]: the ice rule (dry / wet / ice, debounce, hysteresis).
//! - [`estimator`]: ice thickness ± σ, medium and the sensor's optical gain
//!   (a bank of grid Bayes filters over gain hypotheses, on the simulator's
//!   table): its settings ([`estimator::params`]), the driver
//!   ([`estimator::filter`]), the gain hypotheses ([`estimator::gain_bank`]),
//!   one filter (`estimator::grid`) and the table ([`estimator::table`]).
//! - [`calibration`]: the dark baseline under noise ([`calibration::dark`])
//!   and the optical gain against a target ([`calibration::gain`]).
//! - [`storage`]: persistence — the [`Storage`] seam, the record's bytes
//!   ([`storage::record`]), the store on NOR flash
//!   ([`storage::flash_store`]), a NOR flash in RAM that can lose power
//!   mid-operation ([`storage::ram_flash`]), flash writes waiting for a
//!   healthy supply ([`storage::supply`]).
//! - [`measure`]: codes to physical values — synchronous detection
//!   ([`measure::photocurrent`]), the NTC ([`measure::ntc`]), V_DDA and the
//!   die temperature ([`measure::vref`]).
//! - [`platform`]: what the board runs the node on — boot and what survives
//!   a reset ([`platform::boot`]), when frames and `Hello` run
//!   ([`platform::schedule`]), the watchdog's timing
//!   ([`platform::watchdog`]), the link's baud rates and RS-485 turn-taking
//!   ([`platform::field_link`]), the worst time to answer a command
//!   ([`platform::reply_time`]).
//! - [`hal`]: the hardware seams ([`hal::PhotoAdc`], board info; the
//!   [`Storage`] seam lives in [`storage`]).
//! - `sim_board` (feature `sim-board`): a scripted simulated board for tests.

#![cfg_attr(not(test), no_std)]

pub mod calibration;
pub mod estimator;
pub mod hal;
pub mod ice_rule;
pub mod measure;
pub mod modbus;
pub mod node;
pub mod platform;
#[cfg(feature = "sim-board")]
pub mod sim_board;
pub mod storage;
pub mod update;

pub use hal::{BoardInfo, FactoryCal, PhotoAdc};
pub use node::Node;
pub use storage::{MemStorage, Storage, StorageError};
