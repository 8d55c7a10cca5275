//! The `foisctl` commands.

pub mod config;
pub mod scene;
pub mod sim;
