//! Firmware updates over the node's own link (protocol version 6,
//! `protocol/src/update.rs`): the transfer into the update (DFU) slot, the
//! signature check, the commit into embassy-boot's trial boot, and the
//! trial boot's self-test with its confirmation or rollback.
//!
//! - [`transfer`]: [`FlashUpdater`], the begin / chunk / resume / verify /
//!   commit / abort state machine over a DFU and a boot-state partition
//!   (any `embedded_storage` NOR flash), on embassy-boot's boot state and
//!   its signature check;
//! - [`session`]: the transfer's record in the DFU slot (what survives a
//!   power cut, and the offset the node vouches for after one);
//! - [`trial`]: the trial boot's self-test, its deadline and what the node
//!   reports (image confirmed, rolled back);
//! - [`key`]: the public key the images are checked against;
//! - [`slots`]: the [`UpdateSlots`] seam, [`NoUpdates`], [`Refused`] and
//!   the running version.
//!
//! The node holds its updater as an [`UpdateSlots`] (its last type
//! parameter, [`NoUpdates`] by default: a node without update slots answers
//! the transfer's commands `UnknownCommand`, as before version 6).

pub mod key;
pub mod session;
pub mod slots;
pub mod transfer;
pub mod trial;

pub use key::UpdateKey;
pub use slots::{FIRMWARE_VERSION, NoUpdates, Refused, UpdateSlots};
pub use transfer::FlashUpdater;
pub use trial::{Trial, TrialAction};
