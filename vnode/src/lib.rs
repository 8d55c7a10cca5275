#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`clock`]: virtual time, the delay, output pins that record their edges.
//! - [`environment`]: segments, the timeline, what the face sees at each instant.
//! - [`frontend`]: light and temperature → ADC codes, with noise.
//! - [`adc`]: the simulated ADC ([`fois_firmware::PhotoAdc`]).
//! - [`node`]: the virtual node, its options and its storage.
//! - [`scenario`]: the TOML scenario format.

pub mod adc;
pub mod clock;
pub mod environment;
pub mod frontend;
pub mod node;
pub mod scenario;

pub use adc::SimAdc;
pub use clock::{VirtualClock, VirtualDelay, VirtualPin};
pub use environment::{Cover, Environment, Segment, Timeline, Truth};
pub use frontend::FrontEnd;
pub use node::{FirmwareNode, NodeOptions, SharedStorage, VirtualNode};
pub use scenario::Scenario;
