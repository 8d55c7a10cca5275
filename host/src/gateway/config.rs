//! The gateway's configuration: the TOML file (`foisctl gateway --config
//! gateway.toml`), the flags that override it, defaults, and the checks that
//! refuse a bad value before anything is opened.
//!
//! Secrets (the broker password, the client key's path is not one) are held
//! in [`Secret`], whose `Debug` and `Display` print `***`: a config printed
//! with `{:?}` or `--print-config` never shows them.

use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;

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
    /// The nodes, one `[[node]]` table each.
    #[serde(default, rename = "node")]
    pub nodes: Vec<NodeFile>,
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
}

/// Values from the command line that override the file.
#[derive(Debug, Default, Clone)]
pub struct Overrides {
    /// Gateway name.
    pub name: Option<String>,
    /// The broker's host and port.
    pub broker: Option<BrokerAddr>,
    /// User name.
    pub username: Option<String>,
    /// Password file.
    pub password_file: Option<PathBuf>,
    /// CA file (turns TLS on).
    pub ca_file: Option<PathBuf>,
    /// Client certificate.
    pub client_cert_file: Option<PathBuf>,
    /// Client key.
    pub client_key_file: Option<PathBuf>,
    /// Extra nodes (`--node PATH[=NAME]`), after the file's.
    pub nodes: Vec<NodeSpec>,
    /// Measurement interval, ms.
    pub measurement_interval_ms: Option<u64>,
    /// Offline measurement interval, ms.
    pub offline_measurement_interval_ms: Option<u64>,
    /// Queue directory.
    pub queue_dir: Option<PathBuf>,
    /// Queue bound.
    pub queue_max_bytes: Option<u64>,
    /// Switch Home Assistant discovery off.
    pub no_homeassistant: bool,
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
    /// Command topic template with `{node}` (None: commands off).
    pub command_topic: Option<String>,
    /// The nodes.
    pub nodes: Vec<NodeSpec>,
}

/// Default queue bound: 256 MiB (a day of 200 nodes at one measurement per
/// 10 s is about 0.5 GiB of JSON; an outage of half a day fits).
pub const DEFAULT_QUEUE_MAX_BYTES: u64 = 256 * 1024 * 1024;
/// The smallest queue bound accepted.
pub const MIN_QUEUE_MAX_BYTES: u64 = 64 * 1024;
/// The longest publishing interval accepted, ms: one day.
pub const MAX_INTERVAL_MS: u64 = 86_400_000;

/// True for a name usable as one topic level and in Home Assistant ids.
pub fn is_valid_name(s: &str) -> bool {
    !s.is_empty()
        && s.len() <= 64
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

fn check_name(what: &str, s: &str) -> anyhow::Result<()> {
    if is_valid_name(s) {
        Ok(())
    } else {
        anyhow::bail!(
            "{what} `{s}` is not usable in topics: use 1 to 64 letters, digits, `-` or `_`"
        )
    }
}

fn check_topic(what: &str, s: &str) -> anyhow::Result<()> {
    if s.is_empty() || s.contains(['+', '#', '\0']) || s.starts_with('/') || s.ends_with('/') {
        anyhow::bail!("{what} `{s}` is not a valid topic (no +, #, leading or trailing /)");
    }
    Ok(())
}

/// This machine's host name, as a valid gateway name (`gateway` if none).
pub fn default_gateway_name() -> String {
    let raw = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .unwrap_or_default();
    let s: String = raw
        .trim()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '-'
            }
        })
        .take(64)
        .collect();
    if is_valid_name(&s) {
        s
    } else {
        "gateway".into()
    }
}

fn default_queue_dir(name: &str) -> PathBuf {
    let base = std::env::var_os("XDG_STATE_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/state")))
        .unwrap_or_else(|| PathBuf::from("."));
    base.join("fois").join(format!("gateway-{name}"))
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

fn read_password_file(p: &Path) -> anyhow::Result<Secret> {
    let text = std::fs::read_to_string(p)
        .map_err(|e| anyhow::anyhow!("cannot read the password file {}: {e}", p.display()))?;
    let line = text.lines().next().unwrap_or("").trim_end_matches('\r');
    if line.is_empty() {
        anyhow::bail!("the password file {} is empty", p.display());
    }
    Ok(Secret::new(line))
}

impl FileConfig {
    /// Read and parse a config file.
    pub fn load(path: &Path) -> anyhow::Result<FileConfig> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("cannot read the config {}: {e}", path.display()))?;
        Self::parse(&text).map_err(|e| anyhow::anyhow!("config {}: {e}", path.display()))
    }

    /// Parse config text.
    pub fn parse(text: &str) -> anyhow::Result<FileConfig> {
        // The toml error does not echo the password: it quotes only the
        // offending key's line number and column.
        toml::from_str(text).map_err(|e| anyhow::anyhow!("{}", e.message()))
    }

    /// Apply the flags, fill in defaults, check everything.
    pub fn resolve(self, o: &Overrides) -> anyhow::Result<GatewayConfig> {
        let name = o
            .name
            .clone()
            .or(self.name)
            .unwrap_or_else(default_gateway_name);
        check_name("gateway name", &name)?;
        let topic_prefix = self.topic_prefix.unwrap_or_else(|| "fois".into());
        check_topic("topic_prefix", &topic_prefix)?;

        let b = self.broker;
        let (mut host, mut port) = (b.host.unwrap_or_else(|| "127.0.0.1".into()), b.port);
        if let Some(addr) = &o.broker {
            host = addr.host.clone();
            port = addr.port.or(port);
        }
        if host.is_empty() {
            anyhow::bail!("the broker host is empty");
        }
        let tls_file = b.tls.unwrap_or_default();
        let ca = o.ca_file.clone().or(tls_file.ca_file);
        let cert = o.client_cert_file.clone().or(tls_file.client_cert_file);
        let key = o.client_key_file.clone().or(tls_file.client_key_file);
        let tls = match (ca, cert, key) {
            (None, None, None) => None,
            (None, _, _) => anyhow::bail!("a client certificate needs the broker's CA: ca_file"),
            (Some(ca), None, None) => Some(TlsConfig {
                ca_file: ca,
                client_auth: None,
            }),
            (Some(ca), Some(c), Some(k)) => Some(TlsConfig {
                ca_file: ca,
                client_auth: Some((c, k)),
            }),
            _ => anyhow::bail!("client_cert_file and client_key_file go together"),
        };
        let port = port.unwrap_or(if tls.is_some() { 8883 } else { 1883 });
        if port == 0 {
            anyhow::bail!("broker port 0 is not a port");
        }
        let username = o.username.clone().or(b.username);
        let password = match (&o.password_file, b.password_file, b.password) {
            (Some(f), _, _) => Some(read_password_file(f)?),
            (None, Some(f), _) => Some(read_password_file(&f)?),
            (None, None, p) => p,
        };
        if password.is_some() && username.is_none() {
            anyhow::bail!("a broker password needs a username");
        }
        let keep_alive_s = b.keep_alive_s.unwrap_or(5);
        if !(1..=3600).contains(&keep_alive_s) {
            anyhow::bail!("keep_alive_s must be within 1..=3600");
        }
        let client_id = b
            .client_id
            .unwrap_or_else(|| format!("fois-gateway-{name}"));
        if client_id.is_empty() || client_id.len() > 64 {
            anyhow::bail!("client_id must be 1 to 64 characters");
        }

        let p = self.publish;
        let measurement_interval_ms = o
            .measurement_interval_ms
            .or(p.measurement_interval_ms)
            .unwrap_or(1000);
        let offline_measurement_interval_ms = o
            .offline_measurement_interval_ms
            .or(p.offline_measurement_interval_ms)
            .unwrap_or(10_000);
        let state_interval_ms = p.state_interval_ms.unwrap_or(5000);
        let silence_ms = p
            .silence_timeout_ms
            .unwrap_or(fois_protocol::REPLY_TIMEOUT_MS);
        if !(500..=600_000).contains(&silence_ms) {
            anyhow::bail!("silence_timeout_ms must be within 500..=600000");
        }
        for (what, v) in [
            ("measurement_interval_ms", measurement_interval_ms),
            (
                "offline_measurement_interval_ms",
                offline_measurement_interval_ms,
            ),
            ("state_interval_ms", state_interval_ms),
        ] {
            if v > MAX_INTERVAL_MS {
                anyhow::bail!("{what} must be at most one day ({MAX_INTERVAL_MS})");
            }
        }

        let queue_max_bytes = o
            .queue_max_bytes
            .or(self.queue.max_bytes)
            .unwrap_or(DEFAULT_QUEUE_MAX_BYTES);
        if queue_max_bytes < MIN_QUEUE_MAX_BYTES {
            anyhow::bail!("queue max_bytes must be at least {MIN_QUEUE_MAX_BYTES}");
        }
        let queue_dir = o
            .queue_dir
            .clone()
            .or(self.queue.dir)
            .unwrap_or_else(|| default_queue_dir(&name));

        let homeassistant_prefix =
            if o.no_homeassistant || self.homeassistant.enabled == Some(false) {
                None
            } else {
                let p = self
                    .homeassistant
                    .prefix
                    .unwrap_or_else(|| "homeassistant".into());
                check_topic("homeassistant prefix", &p)?;
                Some(p)
            };

        let command_topic = if self.commands.enabled.unwrap_or(false) {
            let t = self
                .commands
                .topic
                .unwrap_or_else(|| format!("{topic_prefix}/{name}/{{node}}/command"));
            check_topic("commands topic", &t)?;
            if t.matches("{node}").count() != 1 {
                anyhow::bail!("the commands topic `{t}` must contain `{{node}}` exactly once");
            }
            Some(t)
        } else {
            if self.commands.topic.is_some() {
                anyhow::bail!(
                    "[commands] topic is set but commands are not enabled: add `enabled = true` \
                     or remove the topic"
                );
            }
            None
        };

        let mut nodes: Vec<NodeSpec> = self
            .nodes
            .into_iter()
            .map(|n| NodeSpec {
                port: n.port,
                name: n.name,
                baud: n.baud.unwrap_or(fois_protocol::BAUD_RATE),
            })
            .collect();
        nodes.extend(o.nodes.iter().cloned());
        if nodes.is_empty() {
            anyhow::bail!("no nodes: add [[node]] tables to the config or --node PATH[=NAME]");
        }
        let mut seen_ports = std::collections::HashSet::new();
        let mut seen_names = std::collections::HashSet::new();
        for n in &nodes {
            if n.port.is_empty() {
                anyhow::bail!("a [[node]] has an empty port");
            }
            if !seen_ports.insert(n.port.clone()) {
                anyhow::bail!("the port {} is listed twice", n.port);
            }
            if let Some(name) = &n.name {
                check_name("node name", name)?;
                if !seen_names.insert(name.clone()) {
                    anyhow::bail!("the node name `{name}` is used twice");
                }
            }
            if n.baud == 0 {
                anyhow::bail!("node {}: baud 0", n.port);
            }
        }

        Ok(GatewayConfig {
            name,
            topic_prefix,
            broker: BrokerConfig {
                host,
                port,
                client_id,
                username,
                password,
                keep_alive: Duration::from_secs(keep_alive_s),
                tls,
            },
            measurement_interval_ms,
            offline_measurement_interval_ms,
            state_interval_ms,
            silence_timeout: Duration::from_millis(silence_ms),
            queue_dir,
            queue_max_bytes,
            homeassistant_prefix,
            command_topic,
            nodes,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FULL: &str = r#"
name = "farm-7"
topic_prefix = "wind"
[broker]
host = "broker.local"
port = 8884
username = "gw"
password = "hunter2-secret"
keep_alive_s = 10
[broker.tls]
ca_file = "ca.pem"
client_cert_file = "gw.pem"
client_key_file = "gw.key"
[publish]
measurement_interval_ms = 2000
offline_measurement_interval_ms = 30000
[queue]
dir = "q"
max_bytes = 1000000
[homeassistant]
prefix = "ha"
[commands]
enabled = true
[[node]]
port = "/dev/ttyACM0"
name = "tower-3"
[[node]]
port = "/dev/ttyACM1"
baud = 57600
"#;

    #[test]
    fn full_file_resolves_with_every_value() {
        let c = FileConfig::parse(FULL)
            .unwrap()
            .resolve(&Overrides::default())
            .unwrap();
        assert_eq!(c.name, "farm-7");
        assert_eq!(c.topic_prefix, "wind");
        assert_eq!(c.broker.host, "broker.local");
        assert_eq!(c.broker.port, 8884);
        assert_eq!(c.broker.client_id, "fois-gateway-farm-7");
        assert_eq!(
            c.broker.password.as_ref().unwrap().expose(),
            "hunter2-secret"
        );
        assert_eq!(c.broker.keep_alive, Duration::from_secs(10));
        let tls = c.broker.tls.as_ref().unwrap();
        assert_eq!(tls.ca_file, PathBuf::from("ca.pem"));
        assert_eq!(
            tls.client_auth,
            Some((PathBuf::from("gw.pem"), PathBuf::from("gw.key")))
        );
        assert_eq!(c.measurement_interval_ms, 2000);
        assert_eq!(c.offline_measurement_interval_ms, 30000);
        assert_eq!(c.queue_max_bytes, 1_000_000);
        assert_eq!(c.homeassistant_prefix.as_deref(), Some("ha"));
        assert_eq!(
            c.command_topic.as_deref(),
            Some("wind/farm-7/{node}/command")
        );
        assert_eq!(c.nodes.len(), 2);
        assert_eq!(c.nodes[0].name.as_deref(), Some("tower-3"));
        assert_eq!(c.nodes[1].name, None);
        assert_eq!(c.nodes[1].baud, 57600);
    }

    #[test]
    fn debug_output_redacts_the_password() {
        let c = FileConfig::parse(FULL)
            .unwrap()
            .resolve(&Overrides::default())
            .unwrap();
        let text = format!("{c:?} {c:#?}");
        assert!(!text.contains("hunter2"), "{text}");
        assert!(text.contains("Secret(***)"), "{text}");
        let f = FileConfig::parse(FULL).unwrap();
        assert!(!format!("{f:?}").contains("hunter2"));
    }

    #[test]
    fn flags_override_the_file() {
        let o = Overrides {
            name: Some("gw2".into()),
            broker: Some(BrokerAddr::parse("10.0.0.5:1999").unwrap()),
            nodes: vec![NodeSpec::parse_flag("/dev/pts/9=extra").unwrap()],
            measurement_interval_ms: Some(0),
            no_homeassistant: true,
            ..Overrides::default()
        };
        let c = FileConfig::parse(FULL).unwrap().resolve(&o).unwrap();
        assert_eq!(c.name, "gw2");
        assert_eq!((c.broker.host.as_str(), c.broker.port), ("10.0.0.5", 1999));
        assert_eq!(c.measurement_interval_ms, 0);
        assert_eq!(c.homeassistant_prefix, None);
        assert_eq!(c.nodes.len(), 3);
        assert_eq!(c.nodes[2].port, "/dev/pts/9");
        assert_eq!(c.nodes[2].name.as_deref(), Some("extra"));
    }

    #[test]
    fn defaults_without_a_file() {
        let o = Overrides {
            nodes: vec![NodeSpec::parse_flag("/dev/ttyACM0").unwrap()],
            ..Overrides::default()
        };
        let c = FileConfig::default().resolve(&o).unwrap();
        assert_eq!(c.topic_prefix, "fois");
        assert_eq!((c.broker.host.as_str(), c.broker.port), ("127.0.0.1", 1883));
        assert_eq!(c.broker.tls, None);
        assert_eq!(c.measurement_interval_ms, 1000);
        assert_eq!(c.offline_measurement_interval_ms, 10_000);
        assert_eq!(c.queue_max_bytes, DEFAULT_QUEUE_MAX_BYTES);
        assert_eq!(c.homeassistant_prefix.as_deref(), Some("homeassistant"));
        assert_eq!(c.command_topic, None, "commands are off by default");
        assert!(is_valid_name(&c.name));
    }

    #[test]
    fn bad_values_are_refused_with_the_reason() {
        let bad = |text: &str, needle: &str| {
            let err = FileConfig::parse(text)
                .and_then(|f| f.resolve(&Overrides::default()))
                .unwrap_err()
                .to_string();
            assert!(err.contains(needle), "{text:?}: {err}");
        };
        let node = "[[node]]\nport = \"/dev/x\"\n";
        bad("", "no nodes");
        bad(&format!("name = \"a/b\"\n{node}"), "not usable in topics");
        bad(&format!("{node}name = \"x+y\""), "not usable in topics");
        bad(&format!("colour = 3\n{node}"), "unknown field");
        bad(
            &format!("[commands]\ntopic = \"x/{{node}}\"\n{node}"),
            "not enabled",
        );
        bad(
            &format!("[commands]\nenabled = true\ntopic = \"x/#\"\n{node}"),
            "not a valid topic",
        );
        bad(
            &format!("[commands]\nenabled = true\ntopic = \"x/cmd\"\n{node}"),
            "exactly once",
        );
        bad(
            &format!("[broker]\npassword = \"pw\"\n{node}"),
            "needs a username",
        );
        bad(
            &format!("[broker.tls]\nclient_cert_file = \"c\"\n{node}"),
            "needs the broker's CA",
        );
        bad(&format!("[queue]\nmax_bytes = 10\n{node}"), "at least");
        bad(&format!("{node}{node}"), "listed twice");
        bad(
            "[[node]]\nport = \"/a\"\nname = \"n\"\n[[node]]\nport = \"/b\"\nname = \"n\"\n",
            "used twice",
        );
    }

    #[test]
    fn broker_and_node_flags_parse_or_say_why() {
        let b = |s: &str| BrokerAddr::parse(s).map(|a| (a.host, a.port));
        assert_eq!(b("10.0.0.5").unwrap(), ("10.0.0.5".into(), None));
        assert_eq!(
            b("broker.local:8883").unwrap(),
            ("broker.local".into(), Some(8883))
        );
        assert_eq!(b("[::1]:1884").unwrap(), ("::1".into(), Some(1884)));
        assert_eq!(b("::1").unwrap(), ("::1".into(), None));
        for bad in ["", ":1883", "h:0", "h:65536", "h:x"] {
            assert!(b(bad).is_err(), "{bad}");
        }
        let n = NodeSpec::parse_flag("/dev/pts/3=tower-3").unwrap();
        assert_eq!(
            (n.port.as_str(), n.name.as_deref()),
            ("/dev/pts/3", Some("tower-3"))
        );
        assert_eq!(n.baud, fois_protocol::BAUD_RATE);
        assert_eq!(NodeSpec::parse_flag("/dev/ttyACM0").unwrap().name, None);
        for bad in ["", "=x", "/dev/x=a b", "/dev/x="] {
            assert!(NodeSpec::parse_flag(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_parse_error_does_not_echo_the_password() {
        let err = FileConfig::parse("[broker]\npassword = \"hunter2\"\nport = \"x\"\n")
            .unwrap_err()
            .to_string();
        assert!(!err.contains("hunter2"), "{err}");
    }
}
