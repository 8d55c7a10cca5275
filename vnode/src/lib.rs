#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`clock`]: virtual time, the delay, output pins that record their edges.
//! - [`environment`]: segments, the timeline, what the face sees at each instant.
//! - [`frontend`]: light and temperature → ADC codes, with noise.
//! - [`optics`]: the optical gain (LED, temperature coefficient, fouling).
//! - [`adc`]: the simulated ADC ([`fois_firmware::PhotoAdc`]).
//! - [`flash`]: the board's store flash in RAM, stalling the virtual clock.
//! - [`node`]: the virtual node and its options.
//! - [`shared_storage`]: its config store (the board's, on the virtual flash), a state file, the old layout's migration.
//! - [`update_slots`]: the boot state, active and DFU slots in RAM, embassy-boot's swap at a reset.
//! - [`scenario`]: the TOML scenario format.
//! - [`overlay`]: a scenario's temporary changes laid over its segments.
//! - [`rate_walk`]: a growth rate that varies (ln r a seeded random process).
//! - `pty` (feature `pty`): a virtual node served on a pseudo-terminal.
//! - [`line`]: the framed link's byte time at a baud rate (optional, `pty` serves with it).
//! - [`modbus_link`]: the node's Modbus RTU link (the firmware's framer and server) between a link's bytes and the node.

pub mod adc;
pub mod clock;
pub mod environment;
pub mod flash;
pub mod frontend;
pub mod line;
pub mod modbus_link;
pub mod node;
pub mod optics;
pub mod overlay;
#[cfg(feature = "pty")]
pub mod pty;
pub mod rate_walk;
pub mod scenario;
pub mod shared_storage;
pub mod update_slots;

pub use adc::SimAdc;
pub use clock::{VirtualClock, VirtualDelay, VirtualPin};
pub use environment::{Cover, Environment, NtcWiring, Segment, Timeline, Truth};
pub use flash::VirtualFlash;
pub use frontend::FrontEnd;
pub use node::{FirmwareNode, NodeOptions, SharedStorage, VirtualNode, instance_unique_id};
pub use optics::OpticalGain;
pub use scenario::Scenario;
