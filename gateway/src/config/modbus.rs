//! `[modbus]`: the Modbus TCP server for SCADA ([`crate::modbus`]), as
//! written and resolved. Off unless `enabled = true`; read-only unless
//! `commands = true`; one unit id per node (`[[node]] modbus_unit`, by
//! default the node's position in the config, 1, 2, 3…).

use std::net::SocketAddr;
use std::time::Duration;

use serde::Deserialize;

use super::located::KeyError;

/// The listening address when `[modbus]` names none: loopback only (a
/// SCADA on another machine needs `listen = "0.0.0.0:5020"` and a
/// firewall), and port 5020, not Modbus's 502: a port under 1024 needs a
/// privilege the service does not have.
pub const DEFAULT_LISTEN: &str = "127.0.0.1:5020";
/// A node's data is stale (status bit 4) after this long without a
/// measurement, s: above the reader's silence timeout (8 s), so a node
/// that is being reconnected turns stale only when it stays away.
pub const DEFAULT_STALE_AFTER_S: f64 = 10.0;
/// At most this many Modbus clients at once, by default; more are refused
/// (their connection closed at once).
pub const DEFAULT_MAX_CLIENTS: usize = 64;
/// A connection that sends no request for this long is closed, s, by
/// default (a SCADA master polls every few seconds; a silent connection
/// must not hold one of the `max_clients` places for ever).
pub const DEFAULT_IDLE_TIMEOUT_S: f64 = 60.0;
/// A request's bytes must all arrive within this long of its first byte,
/// s, by default (a half frame then silence closes the connection).
pub const DEFAULT_FRAME_TIMEOUT_S: f64 = 2.0;
/// The largest unit id a node can have (Modbus: 1–247; 0 is broadcast,
/// 248–255 reserved).
pub const MAX_UNIT: u8 = 247;

/// `[modbus]` as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModbusFile {
    /// Serve Modbus TCP [default: false].
    pub enabled: Option<bool>,
    /// Address and port to listen on [default: 127.0.0.1:5020].
    pub listen: Option<String>,
    /// Accept a write of the alarm-acknowledge register [default: false:
    /// read-only, writes answered with exception 01].
    pub commands: Option<bool>,
    /// The stale bit is set when the latest measurement is older than this,
    /// s [default: 10].
    pub stale_after_s: Option<f64>,
    /// Clients at once [default: 64].
    pub max_clients: Option<usize>,
    /// Close a connection silent for this long, s [default: 60].
    pub idle_timeout_s: Option<f64>,
    /// Close a connection whose request is not complete this long after
    /// its first byte, s [default: 2].
    pub frame_timeout_s: Option<f64>,
}

/// `[modbus]`, resolved (present only when enabled).
#[derive(Debug, Clone, PartialEq)]
pub struct ModbusConfig {
    /// Where the server listens.
    pub listen: SocketAddr,
    /// Writes of the acknowledge register are carried out.
    pub commands: bool,
    /// The stale bit's threshold.
    pub stale_after: Duration,
    /// Clients served at once.
    pub max_clients: usize,
    /// A connection silent this long is closed.
    pub idle_timeout: Duration,
    /// A request must be complete this long after its first byte.
    pub frame_timeout: Duration,
    /// The unit id of each node, in config order.
    pub units: Vec<u8>,
}

impl ModbusConfig {
    /// The node index of `unit` (None: no node has it).
    pub fn node_of_unit(&self, unit: u8) -> Option<usize> {
        self.units.iter().position(|&u| u == unit)
    }

    /// One line for logs and `--check-config`.
    pub fn describe(&self) -> String {
        let units: Vec<String> = self.units.iter().map(u8::to_string).collect();
        format!(
            "Modbus TCP on {} (unit(s) {}, {}, stale after {} s, at most {} clients)",
            self.listen,
            units.join(","),
            if self.commands {
                "alarm acknowledge writable"
            } else {
                "read-only"
            },
            self.stale_after.as_secs_f64(),
            self.max_clients
        )
    }
}

/// `[modbus]` with the nodes' `modbus_unit` (one entry per node, in config
/// order; `None`: its position, 1-based). `None` when Modbus is off.
pub fn resolve_modbus(
    m: ModbusFile,
    node_units: &[Option<u8>],
) -> anyhow::Result<Option<ModbusConfig>> {
    let listen_text = m.listen.as_deref().unwrap_or(DEFAULT_LISTEN);
    let listen: SocketAddr = listen_text.parse().map_err(|_| {
        KeyError::at(
            "modbus.listen",
            format!(
                "[modbus] listen `{listen_text}` is not an address and port (e.g. \
                 127.0.0.1:5020, 0.0.0.0:502, [::1]:5020)"
            ),
        )
    })?;
    if listen.port() == 0 {
        return Err(KeyError::at(
            "modbus.listen",
            format!("[modbus] listen `{listen_text}`: port 0 is not a port"),
        ));
    }
    let stale_s = m.stale_after_s.unwrap_or(DEFAULT_STALE_AFTER_S);
    if !(0.1..=86_400.0).contains(&stale_s) {
        return Err(KeyError::at(
            "modbus.stale_after_s",
            format!("[modbus] stale_after_s must be within 0.1..=86400 (not {stale_s})"),
        ));
    }
    let max_clients = m.max_clients.unwrap_or(DEFAULT_MAX_CLIENTS);
    if !(1..=1024).contains(&max_clients) {
        return Err(KeyError::at(
            "modbus.max_clients",
            format!("[modbus] max_clients must be within 1..=1024 (not {max_clients})"),
        ));
    }
    let idle_s = m.idle_timeout_s.unwrap_or(DEFAULT_IDLE_TIMEOUT_S);
    if !(1.0..=86_400.0).contains(&idle_s) {
        return Err(KeyError::at(
            "modbus.idle_timeout_s",
            format!("[modbus] idle_timeout_s must be within 1..=86400 (not {idle_s})"),
        ));
    }
    let frame_s = m.frame_timeout_s.unwrap_or(DEFAULT_FRAME_TIMEOUT_S);
    if !(0.1..=60.0).contains(&frame_s) {
        return Err(KeyError::at(
            "modbus.frame_timeout_s",
            format!("[modbus] frame_timeout_s must be within 0.1..=60 (not {frame_s})"),
        ));
    }
    if !m.enabled.unwrap_or(false) {
        return Ok(None);
    }
    let mut units = Vec::with_capacity(node_units.len());
    for (k, u) in node_units.iter().enumerate() {
        let unit = match u {
            Some(u) => *u,
            None => u8::try_from(k + 1).unwrap_or(u8::MAX),
        };
        if !(1..=MAX_UNIT).contains(&unit) {
            return Err(KeyError::at(
                format!("node[{k}].modbus_unit"),
                format!(
                    "node {}: Modbus unit {} is outside 1..={MAX_UNIT}{}",
                    k + 1,
                    if u.is_some() {
                        unit.to_string()
                    } else {
                        format!("{} (its position)", k + 1)
                    },
                    if u.is_none() {
                        ": give the nodes after the 247th a modbus_unit"
                    } else {
                        ""
                    }
                ),
            ));
        }
        if let Some(other) = units.iter().position(|&x| x == unit) {
            return Err(KeyError::at(
                format!("node[{k}].modbus_unit"),
                format!(
                    "nodes {} and {} both have Modbus unit {unit} (`modbus_unit`, by default \
                     the node's position)",
                    other + 1,
                    k + 1
                ),
            ));
        }
        units.push(unit);
    }
    Ok(Some(ModbusConfig {
        listen,
        commands: m.commands.unwrap_or(false),
        stale_after: Duration::from_secs_f64(stale_s),
        max_clients,
        idle_timeout: Duration::from_secs_f64(idle_s),
        frame_timeout: Duration::from_secs_f64(frame_s),
        units,
    }))
}

#[cfg(test)]
mod tests;
