//! `[modbus]`: the Modbus TCP server for SCADA ([`crate::modbus`]), as
//! written and resolved. Off unless `enabled = true`; read-only unless
//! `commands = true`; one unit id per node (`[[node]] modbus_unit`, by
//! default the node's position in the config, 1, 2, 3…).

use std::net::SocketAddr;
use std::time::Duration;

use serde::Deserialize;

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
        anyhow::anyhow!(
            "[modbus] listen `{listen_text}` is not an address and port (e.g. 127.0.0.1:5020, \
             0.0.0.0:502, [::1]:5020)"
        )
    })?;
    if listen.port() == 0 {
        anyhow::bail!("[modbus] listen `{listen_text}`: port 0 is not a port");
    }
    let stale_s = m.stale_after_s.unwrap_or(DEFAULT_STALE_AFTER_S);
    if !(0.1..=86_400.0).contains(&stale_s) {
        anyhow::bail!("[modbus] stale_after_s must be within 0.1..=86400 (not {stale_s})");
    }
    let max_clients = m.max_clients.unwrap_or(DEFAULT_MAX_CLIENTS);
    if !(1..=1024).contains(&max_clients) {
        anyhow::bail!("[modbus] max_clients must be within 1..=1024 (not {max_clients})");
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
            anyhow::bail!(
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
            );
        }
        if let Some(other) = units.iter().position(|&x| x == unit) {
            anyhow::bail!(
                "nodes {} and {} both have Modbus unit {unit} (`modbus_unit`, by default the \
                 node's position)",
                other + 1,
                k + 1
            );
        }
        units.push(unit);
    }
    Ok(Some(ModbusConfig {
        listen,
        commands: m.commands.unwrap_or(false),
        stale_after: Duration::from_secs_f64(stale_s),
        max_clients,
        units,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::file::{FileConfig, Overrides};

    fn resolve(text: &str) -> anyhow::Result<Option<ModbusConfig>> {
        FileConfig::parse(text)?
            .resolve(&Overrides::default())
            .map(|c| c.modbus)
    }

    const NODES: &str = "[[node]]\nport = \"/a\"\n[[node]]\nport = \"/b\"\nmodbus_unit = 7\n\
                         [[node]]\nport = \"/c\"\n";

    #[test]
    fn off_by_default_then_loopback_5020_read_only_units_by_position() {
        assert_eq!(resolve(NODES).unwrap(), None);
        let m = resolve(&format!("[modbus]\nenabled = true\n{NODES}"))
            .unwrap()
            .unwrap();
        assert_eq!(m.listen, "127.0.0.1:5020".parse().unwrap());
        assert!(!m.commands);
        assert_eq!(m.stale_after, Duration::from_secs(10));
        assert_eq!(m.max_clients, 64);
        assert_eq!(m.units, vec![1, 7, 3]);
        assert_eq!(m.node_of_unit(7), Some(1));
        assert_eq!(m.node_of_unit(2), None);
        assert_eq!(
            m.describe(),
            "Modbus TCP on 127.0.0.1:5020 (unit(s) 1,7,3, read-only, stale after 10 s, at most \
             64 clients)"
        );
    }

    #[test]
    fn every_key_is_read() {
        let m = resolve(&format!(
            "[modbus]\nenabled = true\nlisten = \"[::1]:1502\"\ncommands = true\n\
             stale_after_s = 2.5\nmax_clients = 100\n{NODES}"
        ))
        .unwrap()
        .unwrap();
        assert_eq!(m.listen, "[::1]:1502".parse().unwrap());
        assert!(m.commands);
        assert_eq!(m.stale_after, Duration::from_millis(2500));
        assert_eq!(m.max_clients, 100);
    }

    #[test]
    fn bad_values_are_refused_with_the_reason() {
        let bad = |text: &str, needle: &str| {
            let err = resolve(text).unwrap_err().to_string();
            assert!(err.contains(needle), "{text:?}: {err}");
        };
        let on = "[modbus]\nenabled = true\n";
        // The section is checked even while it is off.
        bad(
            "[modbus]\nlisten = \"x\"\n[[node]]\nport = \"/a\"\n",
            "not an address",
        );
        bad(
            &format!("{on}listen = \"localhost\"\n{NODES}"),
            "not an address and port",
        );
        bad(&format!("{on}listen = \"127.0.0.1:0\"\n{NODES}"), "port 0");
        bad(&format!("{on}stale_after_s = 0\n{NODES}"), "stale_after_s");
        bad(&format!("{on}max_clients = 0\n{NODES}"), "max_clients");
        bad(&format!("{on}colour = 1\n{NODES}"), "unknown field");
        // The third node's default unit is 3: taken by the first.
        bad(
            "[modbus]\nenabled = true\n[[node]]\nport = \"/a\"\nmodbus_unit = 3\n[[node]]\nport = \"/b\"\n\
             [[node]]\nport = \"/c\"\n",
            "nodes 1 and 3 both have Modbus unit 3",
        );
        bad(
            "[modbus]\nenabled = true\n[[node]]\nport = \"/a\"\nmodbus_unit = 248\n",
            "Modbus unit 248 is outside 1..=247",
        );
        bad(
            "[modbus]\nenabled = true\n[[node]]\nport = \"/a\"\nmodbus_unit = 0\n",
            "Modbus unit 0 is outside",
        );
    }

    #[test]
    fn the_packaged_example_with_its_modbus_lines_uncommented_is_the_default() {
        let example = include_str!("../../debian/gateway.toml");
        let mut in_section = false;
        let text: String = example
            .lines()
            .map(|l| {
                if l == "#[modbus]" {
                    in_section = true;
                } else if l.is_empty() {
                    in_section = false;
                }
                if in_section || l.starts_with("#modbus_unit") {
                    format!("{}\n", &l[1..])
                } else {
                    format!("{l}\n")
                }
            })
            .collect();
        let m = resolve(&text).unwrap().expect("enabled");
        assert_eq!(m.listen, DEFAULT_LISTEN.parse().unwrap());
        assert!(!m.commands);
        assert_eq!(m.stale_after.as_secs_f64(), DEFAULT_STALE_AFTER_S);
        assert_eq!(m.max_clients, DEFAULT_MAX_CLIENTS);
        assert_eq!(m.units, vec![1]);
        // As shipped, commented: off.
        assert_eq!(resolve(example).unwrap(), None);
    }
}
