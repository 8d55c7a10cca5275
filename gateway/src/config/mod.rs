//! The gateway's configuration: the TOML file (`fois-gateway --config
//! /etc/fois/gateway.toml`), the flags that override it, defaults, and the
//! checks that refuse a bad value before anything is opened.
//!
//! | module | what lives there |
//! | --- | --- |
//! | [`file`] | the file as written ([`file::FileConfig`]: every key optional, unknown keys refused) and the flags' [`file::Overrides`] |
//! | [`log`] | `[log]`: the directory and the days kept of the nodes' daily CSV logs |
//! | [`firmware`] | `[firmware]`: the directory of signed images a roll-out may name, the new image's confirm time, the image-name rule |
//! | [`modbus`] | `[modbus]`: the Modbus TCP server's address, commands, stale time, unit ids |
//! | [`resolve`] | [`file::FileConfig::resolve`]: flags over file over defaults, section by section, every check |
//! | here (reads only [`modbus`] and [`log`]) | the resolved [`GatewayConfig`], [`Secret`], names, [`BrokerAddr`], [`NodeSpec`] |
//!
//! The imports go one way: `modbus` and `log` read none of their siblings
//! (`firmware` reads only `located`, for its keys' lines)
//! (modbus's tests, which parse whole files, live in `modbus/tests.rs`),
//! this file reads them, `file` reads those and this, `resolve` reads all.
//!
//! Secrets (the broker password, the client key's path is not one) are held
//! in [`Secret`], whose `Debug` and `Display` print `***`: a config printed
//! with `{:?}` or `--print-config` never shows them.

pub mod file;
pub mod firmware;
pub mod located;
pub mod log;
pub mod modbus;
pub mod resolve;

use std::fmt;
use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;

pub use log::LogConfig;
pub use modbus::ModbusConfig;

/// A value that must never be printed (a password).
#[derive(Clone, Default, PartialEq, Eq, Deserialize)]
#[serde(transparent)]
pub struct Secret(String);

impl Secret {
    /// Wrap a secret.
    pub fn new(s: impl Into<String>) -> Secret {
        Secret(s.into())
    }

    /// The secret itself: call only where it is handed to the MQTT client.
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Secret(***)")
    }
}

impl fmt::Display for Secret {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("***")
    }
}

/// TLS settings, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct TlsConfig {
    /// CA PEM file.
    pub ca_file: PathBuf,
    /// Client certificate and key PEM files.
    pub client_auth: Option<(PathBuf, PathBuf)>,
}

/// The broker, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct BrokerConfig {
    /// Host.
    pub host: String,
    /// Port.
    pub port: u16,
    /// Client id.
    pub client_id: String,
    /// User name.
    pub username: Option<String>,
    /// Password (redacted in Debug).
    pub password: Option<Secret>,
    /// Keep-alive.
    pub keep_alive: Duration,
    /// TLS, if on.
    pub tls: Option<TlsConfig>,
}

impl BrokerConfig {
    /// `host:port`, and ` (TLS)` when TLS is on: how logs name the broker.
    pub fn describe(&self) -> String {
        format!(
            "{}:{}{}",
            self.host,
            self.port,
            if self.tls.is_some() { " (TLS)" } else { "" }
        )
    }
}

/// One node, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeSpec {
    /// Serial port path.
    pub port: String,
    /// Name from the config (None: from the unique id at connection).
    pub name: Option<String>,
    /// Baud rate.
    pub baud: u32,
}

/// Everything the gateway needs, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct GatewayConfig {
    /// Gateway name.
    pub name: String,
    /// Topic prefix.
    pub topic_prefix: String,
    /// Broker.
    pub broker: BrokerConfig,
    /// Measurement interval while connected (0 = every frame).
    pub measurement_interval_ms: u64,
    /// Measurement interval while the broker is unreachable.
    pub offline_measurement_interval_ms: u64,
    /// Minimum spacing of thickness-only state updates.
    pub state_interval_ms: u64,
    /// A silent node is declared offline after this.
    pub silence_timeout: Duration,
    /// Queue directory.
    pub queue_dir: PathBuf,
    /// Queue bound, bytes.
    pub queue_max_bytes: u64,
    /// Home Assistant discovery prefix (None: discovery off).
    pub homeassistant_prefix: Option<String>,
    /// The oldest Home Assistant release the discovery messages must suit.
    pub homeassistant_version: crate::discovery::HaVersion,
    /// Command topic template with `{node}` (None: commands off).
    pub command_topic: Option<String>,
    /// A node accepts a command from MQTT at most this often (each
    /// `calibrate-dark` is a flash save on the board).
    pub command_min_interval: Duration,
    /// The nodes.
    pub nodes: Vec<NodeSpec>,
    /// The Modbus TCP server (None: off).
    pub modbus: Option<ModbusConfig>,
    /// The daily logs of the nodes' frames (None: off).
    pub log: Option<LogConfig>,
    /// Roll-outs of signed images (None: off).
    pub firmware: Option<firmware::FirmwareConfig>,
}

/// Default queue bound: 256 MiB (a day of 200 nodes at one measurement per
/// 10 s is about 0.5 GiB of JSON; an outage of half a day fits).
pub const DEFAULT_QUEUE_MAX_BYTES: u64 = 256 * 1024 * 1024;
/// The smallest queue bound accepted.
pub const MIN_QUEUE_MAX_BYTES: u64 = 64 * 1024;
/// The longest publishing interval accepted, ms: one day.
pub const MAX_INTERVAL_MS: u64 = 86_400_000;
/// Default spacing of commands to one node, ms.
pub const DEFAULT_COMMAND_MIN_INTERVAL_MS: u64 = 5_000;

/// True for a name usable as one topic level and in Home Assistant ids.
pub fn is_valid_name(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

pub(crate) fn check_name(what: &str, s: &str) -> anyhow::Result<()> {
    if is_valid_name(s) {
        Ok(())
    } else {
        anyhow::bail!(
            "{what} `{s}` is not usable in topics: use 1 to 64 letters, digits, `-` or `_`"
        )
    }
}

pub(crate) fn check_topic(what: &str, s: &str) -> anyhow::Result<()> {
    if s.is_empty() || s.contains(['+', '#', '\0']) || s.starts_with('/') || s.ends_with('/') {
        anyhow::bail!("{what} `{s}` is not a valid topic (no +, #, leading or trailing /)");
    }
    if s.starts_with('$') {
        // `$SYS/...` and other `$` topics belong to the broker: clients
        // cannot publish there (Mosquitto drops such messages silently).
        anyhow::bail!(
            "{what} `{s}` starts with `$`: topics beginning with `$` are the broker's own \
             (e.g. $SYS), a client's messages there are never delivered"
        );
    }
    Ok(())
}

impl NodeSpec {
    /// Parse a `--node PATH[=NAME]` flag (the name checked as a topic
    /// level; the baud rate the node's 115200).
    pub fn parse_flag(s: &str) -> anyhow::Result<NodeSpec> {
        let (port, name) = match s.rsplit_once('=') {
            Some((p, n)) => (p, Some(n.to_string())),
            None => (s, None),
        };
        if port.is_empty() {
            anyhow::bail!("--node `{s}`: give PATH or PATH=NAME");
        }
        if let Some(n) = &name {
            check_name("node name", n)?;
        }
        Ok(NodeSpec {
            port: port.to_string(),
            name,
            baud: fois_protocol::BAUD_RATE,
        })
    }
}

/// A broker address from the command line: `HOST`, `HOST:PORT`, or
/// `[IPv6]:PORT` (a bare IPv6 address has no port).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BrokerAddr {
    /// Host name or address.
    pub host: String,
    /// TCP port, if given.
    pub port: Option<u16>,
}

impl BrokerAddr {
    /// Parse `HOST[:PORT]`; refuses an empty host and a port outside 1..=65535.
    pub fn parse(s: &str) -> anyhow::Result<BrokerAddr> {
        let (host, port) = match s.rsplit_once(':') {
            Some((h, p)) if !h.contains(':') || h.starts_with('[') => {
                let port = match p.parse::<u16>() {
                    Ok(0) | Err(_) => {
                        anyhow::bail!("`{s}`: `{p}` is not a port number (1..=65535)")
                    }
                    Ok(n) => n,
                };
                (h.trim_matches(['[', ']']), Some(port))
            }
            _ => (s, None),
        };
        if host.is_empty() {
            anyhow::bail!("`{s}`: the broker host is empty");
        }
        Ok(BrokerAddr {
            host: host.to_string(),
            port,
        })
    }
}
