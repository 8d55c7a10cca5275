//! Modbus RTU on the node's host link (`LinkSettings::protocol` =
//! `ModbusRtu`): the register map of [`fois_protocol::registers`] — the
//! same the gateway serves over TCP — answered by the node itself, so a
//! PLC or an RTU on the RS-485 pair reads it without a gateway.
//!
//! - [`silence`]: frames delimited by 3.5 characters of silence (t1.5
//!   breaks a frame);
//! - [`server`]: one request → its answer (rmodbus parses and builds; the
//!   map, the exceptions, the write enable are ours);
//! - [`view`]: what the server reads of the node (a copy taken after each
//!   frame, [`crate::node::Node::modbus_view`]) and the actions a write
//!   asks of it ([`crate::node::Node::modbus_action`]).
//!
//! The board binary and the virtual node only move bytes and times: the
//! board's UART task feeds the framer with each byte's arrival time and
//! sends the answer (DE as the framed link does), the measure loop carries
//! out the actions and refreshes the view.

pub mod server;
pub mod silence;
pub mod view;

pub use server::{Answer, RtuServer};
pub use silence::{Adu, SilenceFramer, Silences};
pub use view::{Action, ModbusView};
