//! The fleet gateway behind `foisctl gateway`: many nodes to an MQTT broker.
//! The command's flags and its `run` live in [`crate::cmd::gateway`]; this is
//! the library it drives.
//!
//! | module | what lives there |
//! | --- | --- |
//! | [`config`] | the TOML file, the flags that override it, defaults, checks, [`config::Secret`] |
//! | [`node`] | the node reader: one thread per serial port, handshake, stream, reconnect |
//! | [`publisher`] | the MQTT client, matching PUBACKs to queued records, the run loop |
//! | [`queue`] | the bounded on-disk store-and-forward queue |
//! | [`discovery`] | Home Assistant MQTT discovery configs |
//! | [`topics`] | the topic layout |
//! | [`payload`] | the JSON payloads |

pub mod config;
pub mod discovery;
pub mod node;
pub mod payload;
pub mod publisher;
pub mod queue;
pub mod topics;
