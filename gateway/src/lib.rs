#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! | module | what lives there |
//! | --- | --- |
//! | [`cli`] | the command line: flags, `--print-config`, `--check-config`, the run and its summary |
//! | [`config`] | the TOML file, the flags that override it ([`config::file::Overrides`], declared once), defaults, checks, [`config::Secret`] |
//! | [`command`] | the node command words, their parser, the front-end command: shared by the reader, the machine, MQTT and Modbus |
//! | [`reader`] | the node reader: one thread per serial port (`fois_link`), handshake, stream, reconnect |
//! | [`rollout`] | firmware roll-outs: the command, the readers' update slots, one node at a time, stop at the first failure |
//! | [`season_log`] | `[log] dir`: each node's frames as daily CSV files in the monitor's format, compressed after the day, pruned after the days kept (its own thread) |
//! | [`machine`] | the state machine, free of network IO: node reports and broker events in, publish/subscribe/command actions out |
//! | [`service`] | the runtime: tokio, rumqttc's event loop, the readers, the Modbus server, the machine's actions carried out |
//! | [`mqtt`] | connection set-up: client options, TLS (rustls, ring), words for connection errors |
//! | [`inflight`] | packet-id bookkeeping: which record a PUBACK acknowledges |
//! | [`queue`] | the bounded on-disk store-and-forward queue |
//! | [`snapshot`] | each node's one record, shared with other front ends; the naming rule |
//! | [`modbus`] | Modbus TCP for SCADA: the register table of a node's snapshot, the server (`tokio-modbus`) |
//! | [`topics`], [`payload`] | the topic layout, the JSON payloads |
//! | [`state_filter`] | when the retained state is published: discrete changes at once, continuous values deadbanded |
//! | [`discovery`] | Home Assistant MQTT discovery: the entities of a node, the messages for the configured release |
//! | [`logging`] | `tracing` set-up: levels, `RUST_LOG`, timestamps only on a terminal |

pub mod cli;
pub mod command;
pub mod config;
pub mod discovery;
pub mod inflight;
pub mod logging;
pub mod machine;
pub mod modbus;
pub mod mqtt;
pub mod net_runtime;
pub mod payload;
pub mod queue;
pub mod reader;
pub mod rollout;
pub mod season_log;
pub mod service;
pub mod snapshot;
pub mod state_filter;
#[cfg(test)]
mod test_log;
pub mod topics;
