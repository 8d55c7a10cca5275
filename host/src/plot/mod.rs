//! The figures `foisctl` draws.

pub mod log;
pub mod series;

pub use log::*;
