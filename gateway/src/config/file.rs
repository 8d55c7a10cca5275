//! The config file as written: every key optional, unknown keys refused
//! (a misspelt key is an error, not a silent default), and the command
//! line's [`Overrides`] (its flags declared here, with their parsers, once).
//! [`FileConfig::resolve`] turns both into a checked
//! [`GatewayConfig`](super::GatewayConfig).

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::{BrokerAddr, MAX_INTERVAL_MS, MIN_QUEUE_MAX_BYTES, NodeSpec, Secret, is_valid_name};

/// The file as written (every field optional; unknown keys refused).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FileConfig {
    /// Gateway name: a topic level and part of every Home Assistant id.
    pub name: Option<String>,
    /// First topic level [default: fois].
    pub topic_prefix: Option<String>,
    /// The broker.
    #[serde(default)]
    pub broker: BrokerFile,
    /// What is published how often.
    #[serde(default)]
    pub publish: PublishFile,
    /// The on-disk store-and-forward queue.
    #[serde(default)]
    pub queue: QueueFile,
    /// Home Assistant MQTT discovery.
    #[serde(default)]
    pub homeassistant: HomeAssistantFile,
    /// Commands from MQTT to the nodes.
    #[serde(default)]
    pub commands: CommandsFile,
    /// The Modbus TCP server.
    #[serde(default)]
    pub modbus: super::modbus::ModbusFile,
    /// The daily logs of the nodes' frames.
    #[serde(default)]
    pub log: super::log::LogFile,
    /// The signed images a roll-out may name.
    #[serde(default)]
    pub firmware: super::firmware::FirmwareFile,
    /// The nodes, one `[[node]]` table each.
    #[serde(default, rename = "node")]
    pub nodes: Vec<NodeFile>,
    /// The text it was parsed from (to name the line of a bad value).
    #[serde(skip)]
    pub source: Option<super::located::Source>,
}

/// `[broker]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BrokerFile {
    /// Host name or address [default: 127.0.0.1].
    pub host: Option<String>,
    /// TCP port [default: 1883, 8883 with TLS].
    pub port: Option<u16>,
    /// MQTT client id [default: fois-gateway-<name>].
    pub client_id: Option<String>,
    /// User name.
    pub username: Option<String>,
    /// Password (prefer `password_file`).
    pub password: Option<Secret>,
    /// A file whose first line is the password.
    pub password_file: Option<PathBuf>,
    /// MQTT keep-alive, s [default: 5]: the broker publishes the gateway's
    /// last will about 1.5 × this after the gateway dies.
    pub keep_alive_s: Option<u64>,
    /// `[broker.tls]`: connect with TLS.
    pub tls: Option<TlsFile>,
}

/// `[broker.tls]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TlsFile {
    /// PEM file of the CA(s) that signed the broker's certificate.
    pub ca_file: Option<PathBuf>,
    /// PEM client certificate (mutual TLS), with `client_key_file`.
    pub client_cert_file: Option<PathBuf>,
    /// PEM private key of the client certificate.
    pub client_key_file: Option<PathBuf>,
}

/// `[publish]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PublishFile {
    /// At most one measurement per node per this many ms of node time while
    /// the broker is connected; 0 = every frame [default: 1000].
    pub measurement_interval_ms: Option<u64>,
    /// The same while the broker is unreachable (what goes to the disk
    /// queue) [default: 10000].
    pub offline_measurement_interval_ms: Option<u64>,
    /// A retained state message is re-published when only the thickness
    /// moved, at most this often, ms [default: 5000]; a change of detector
    /// state, alarm, acknowledgement, faults or medium goes out at once.
    pub state_interval_ms: Option<u64>,
    /// A node that sends nothing for this long is declared offline and
    /// reconnected, ms [default: 8000, the protocol's reply timeout: a
    /// healthy node can be silent ~6–7 s while it erases flash and calibrates].
    pub silence_timeout_ms: Option<u64>,
}

/// `[queue]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QueueFile {
    /// Directory of the queue's segment files [default:
    /// $XDG_STATE_HOME/fois/gateway-<name>, else ~/.local/state/...].
    pub dir: Option<PathBuf>,
    /// Upper bound of the queue on disk, bytes; the oldest records are
    /// dropped first (and counted) [default: 268435456 = 256 MiB].
    pub max_bytes: Option<u64>,
}

/// `[homeassistant]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HomeAssistantFile {
    /// Publish discovery configs [default: true].
    pub enabled: Option<bool>,
    /// Discovery prefix [default: homeassistant].
    pub prefix: Option<String>,
    /// The oldest Home Assistant release of the site, `YEAR.MONTH`: newer
    /// discovery keys only when it takes them [default: 2024.1].
    pub version: Option<String>,
}

/// `[commands]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandsFile {
    /// Accept `ack` and `calibrate-dark` from MQTT [default: false].
    pub enabled: Option<bool>,
    /// The topic per node, `{node}` standing for the node's name [default:
    /// <prefix>/<gateway>/{node}/command].
    pub topic: Option<String>,
    /// A node takes at most one command per this many ms; commands in
    /// between are refused (and answered so) [default: 5000].
    pub min_interval_ms: Option<u64>,
}

/// One `[[node]]`.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeFile {
    /// Serial port (or pty, or a stable symlink to one).
    pub port: String,
    /// Node name in topics [default: the node's unique id, hex].
    pub name: Option<String>,
    /// Baud rate [default: 115200].
    pub baud: Option<u32>,
    /// Its Modbus unit id, 1–247 [default: its position among the nodes,
    /// 1, 2, 3…].
    pub modbus_unit: Option<u8>,
}

/// The command-line flags that override the file (flattened into the
/// gateway's command line; every one optional).
#[derive(Debug, Default, Clone, clap::Args)]
pub struct Overrides {
    /// Gateway name: a topic level (<prefix>/<name>/...) and part of every
    /// Home Assistant id; 1 to 64 letters, digits, - and _ [default: the
    /// host name].
    #[arg(long, value_name = "NAME", value_parser = topic_name)]
    pub name: Option<String>,
    /// The broker, HOST, HOST:PORT or [IPv6]:PORT [default: 127.0.0.1:1883,
    /// 8883 with TLS].
    #[arg(long, value_name = "HOST[:PORT]", value_parser = broker_addr)]
    pub broker: Option<BrokerAddr>,
    /// Broker user name.
    #[arg(long, value_name = "USER")]
    pub username: Option<String>,
    /// A file whose first line is the broker password (there is no password
    /// flag: other users can read a command line).
    #[arg(long, value_name = "FILE")]
    pub password_file: Option<PathBuf>,
    /// Connect with TLS, trusting the CA certificate(s) in this PEM file.
    #[arg(long, value_name = "FILE.pem")]
    pub ca_file: Option<PathBuf>,
    /// Client certificate (PEM) for mutual TLS, with --client-key.
    #[arg(
        long = "client-cert",
        value_name = "FILE.pem",
        requires = "client_key_file"
    )]
    pub client_cert_file: Option<PathBuf>,
    /// Private key (PEM) of the client certificate.
    #[arg(
        long = "client-key",
        value_name = "FILE.pem",
        requires = "client_cert_file"
    )]
    pub client_key_file: Option<PathBuf>,
    /// A node: serial port (or pty) path, optionally =NAME for its topics
    /// [default name: the node's unique id, hex]. Repeat for more nodes;
    /// added to the config file's [[node]] tables.
    #[arg(long = "node", value_name = "PATH[=NAME]", value_parser = gateway_node)]
    pub nodes: Vec<NodeSpec>,
    /// At most one measurement per node per this many ms of node time while
    /// the broker is connected; 0 publishes every frame (10 per second per
    /// node); at most 86400000 (a day) [default: 1000].
    #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(..=MAX_INTERVAL_MS))]
    pub measurement_interval_ms: Option<u64>,
    /// The same while the broker is unreachable: what goes to the disk
    /// queue [default: 10000].
    #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(..=MAX_INTERVAL_MS))]
    pub offline_measurement_interval_ms: Option<u64>,
    /// Directory of the store-and-forward queue [default:
    /// $XDG_STATE_HOME/fois/gateway-<name>, else ~/.local/state/fois/...].
    #[arg(long, value_name = "DIR")]
    pub queue_dir: Option<PathBuf>,
    /// Bound of the disk queue, bytes, at least 65536; the oldest records
    /// are dropped first and counted [default: 268435456 = 256 MiB].
    #[arg(long, value_name = "BYTES", value_parser = clap::value_parser!(u64).range(MIN_QUEUE_MAX_BYTES..))]
    pub queue_max_bytes: Option<u64>,
    /// Do not publish Home Assistant discovery configs.
    #[arg(long)]
    pub no_homeassistant: bool,
}

/// A gateway name usable as one MQTT topic level and in Home Assistant ids:
/// 1 to 64 letters, digits, `-` or `_`.
fn topic_name(s: &str) -> Result<String, String> {
    if is_valid_name(s) {
        Ok(s.to_string())
    } else {
        Err(format!(
            "`{s}` is not usable in topics: use 1 to 64 letters, digits, `-` or `_`"
        ))
    }
}

/// An MQTT broker, `HOST[:PORT]` ([`BrokerAddr::parse`]).
fn broker_addr(s: &str) -> Result<BrokerAddr, String> {
    BrokerAddr::parse(s).map_err(|e| format!("{e:#}"))
}

/// A gateway node, `PATH[=NAME]` ([`NodeSpec::parse_flag`]).
fn gateway_node(s: &str) -> Result<NodeSpec, String> {
    NodeSpec::parse_flag(s).map_err(|e| format!("{e:#}"))
}

impl FileConfig {
    /// Read and parse a config file.
    pub fn load(path: &Path) -> anyhow::Result<FileConfig> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("cannot read the config {}: {e}", path.display()))?;
        Self::parse(&text).map_err(|e| anyhow::anyhow!("config {}: {e}", path.display()))
    }

    /// Parse config text. An error names the line, column and key of the
    /// bad value ([`super::located`]; never the line itself: it may hold
    /// the password).
    pub fn parse(text: &str) -> anyhow::Result<FileConfig> {
        let mut c: FileConfig =
            toml::from_str(text).map_err(|e| super::located::parse_error(text, &e))?;
        c.source = Some(super::located::Source(text.to_string()));
        Ok(c)
    }
}
